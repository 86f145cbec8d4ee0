// The batched MT builder (BMT sections 4 and 6): from a scan (or a patch store) to one MT file.
//
//   ingest (V-partitioned, patchstore) -> for level i = 0, 1, ...: for each region R of V(i+1):
//   load the V*i patches inside R, simplify to about half (1/k: the partition's level ratio) with
//   R's border locked, split by V*(i+1), write back -> one DAG node per region; the floor patches
//   become the payloads of the arcs into that node. Regions run in parallel and commit in region
//   order, so the file does not depend on the thread count; every step is deterministic, so it
//   does not depend on the memory cap either.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "base/error.h"
#include "mtfile/mt_format.h"
#include "mtfile/patch_codec.h"
#include "mtbuild/simplify_region.h"
#include "patchstore/patch_store.h"
#include "vpartition/vpartition.h"

namespace mt {

// mtbuild's patch size when --patch-triangles is not given. Twice the store's default
// (kDefaultPatchTriangles, which suits healing): the per-patch overhead of the MT file is ~190 bytes,
// so 2000 is the smallest size that meets both file-size targets (m10 scan: meshopt 2.53, Draco 1.73
// bytes per input triangle; 1000 gives 2.92 / 2.12) at no extra build CPU; 4000 costs 40-60% more
// CPU (docs/mt-format.md has the sweep).
constexpr uint32_t kDefaultMtPatchTriangles = 2000;
// The --patch-triangles range. Below 100 the per-patch cost (a ~190-byte record and payload
// header, the region bookkeeping) outweighs the geometry: 1 made a file 106x the default's. Above
// 100000 a region (its V*i patches, ~6 of them, assembled, simplified and kept twice) needs
// hundreds of MiB and a level has too few regions to use the threads or ranks.
constexpr uint32_t kMinPatchTriangles = 100, kMaxPatchTriangles = 100000;
// The least --memory the build honours: the ingest's and the V-partition's fixed buffers (a 200k
// scan needs 6 MiB for the partition alone); below it a build either fails late or exceeds the cap.
constexpr uint64_t kMinBuildMemory = 16ull << 20;
// The default --color-weight (docs/appearance.md, "Per-vertex colour").
constexpr double kDefaultColorWeight = 1.0;
// The work directory marker: a directory holding it was made by mtbuild/mtcluster, and is the
// only kind they ever empty or remove.
constexpr char kWorkMarker[] = ".mtbuild-work";

struct BuildOptions {
  uint64_t memoryBytes = 1ull << 30;  // --memory: the cap for the whole build (ingest included)
  // The level loop's share: regions in flight (loaded, processed, waiting for their commit) are
  // admitted in region order while the sum of their estimateRegionBytes() fits; one region is
  // always admitted, alone if it is larger. 0: no byte bound (2 x threads regions in flight).
  // Does not change the bytes of the file.
  uint64_t levelLoopBytes = 0;
  uint32_t threads = 0;               // 0: all cores
  PartitionKind partition = PartitionKind::Irregular;
  uint32_t patchTriangles = 0;        // 0: kDefaultMtPatchTriangles (ignored for a store input)
  // --level-ratio k: each level keeps 1/k of the triangles of the one below (the irregular
  // partition's levels aim at 1/k of the cells, each region is simplified to 1/k). 0: 2 for a mesh,
  // the store's own for a store input (another value than the store's is refused).
  uint32_t levelRatio = 0;
  format::Codec codec = format::Codec::Meshopt;
  bool strips = false;                // meshopt patches as tri-strips (--index-order strip)
  bool normals = false;               // store normals (else the renderer computes them)
  RegionSimplifier simplifier = RegionSimplifier::Meshopt;  // --simplifier
  // --simplifier auto (the tools' default): the quadric simplifier when the input has per-vertex
  // colours (only it keeps colour edges: mtbuild/attribute_quadric.h), meshopt otherwise; decided
  // once the level-0 store exists. `simplifier` is then ignored.
  bool simplifierByInput = false;
  // --color-weight: with colours and the quadric simplifier, a full-range colour difference costs
  // as much as a distance of colorWeight x the region's mean edge length (0: colours are carried
  // but do not steer the collapses). docs/appearance.md has the measurements behind the default.
  double colorWeight = kDefaultColorWeight;
  // Continue a killed build from the checkpoint in its work directory (the last finished level).
  bool resume = false;
  bool progress = true;
  // default OUT.work. A DIR that exists and was not made by a build (no kWorkMarker) is left
  // alone: the build uses DIR/<output's file name>.work instead.
  std::string workDir;
  // Stop adding levels once the top level has at most this many triangles (0: 2 x patch size),
  // or when a level removes less than 10% of the triangles (such a level is not added when it is
  // a further root level: LevelBuilder::commitRegion).
  uint64_t rootTriangles = 0;
  // When set, one CSV line per region (level, region, triangles, seconds of load/process/commit,
  // bytes a cluster would move) is written here: the input of the scaling model in docs/cluster.md.
  std::string taskTimesPath;
  // The coordinate reference system of the input's positions (--crs), stored in the MT file's
  // metadata block (mtfile/mt_format.h); empty: none. Not interpreted by the build.
  std::string crs;
  // The tool's name in messages ("mtbuild", "mtcluster").
  std::string toolName = "mtbuild";
  // Textured inputs: the JPEG quality of the atlases in the file (--texture-quality).
  int textureQuality = 90;
};

struct LevelReport {
  uint32_t level = 0;
  uint32_t regions = 0;
  uint64_t trianglesIn = 0, trianglesOut = 0;
  double maxError = 0;
  double seconds = 0;
  // The CPU the process used over the same span as `seconds` (every thread; mtcluster: rank 0's
  // process), user and kernel: where the level's CPU went.
  double userSeconds = 0, sysSeconds = 0;
  // Simplifier runs over the level's regions: one per region, plus one per retry after the result
  // broke a rule of the builder (simplify_region.cpp, findBrokenRules). Runs above the region count
  // are CPU spent on results thrown away (scan-derived meshes: 1.3-1.9 runs per region).
  uint64_t simplifierRuns = 0;
};

struct BuildReport {
  uint64_t inputTriangles = 0;
  uint64_t storedTriangles = 0;
  uint64_t nodes = 0, arcs = 0, patches = 0;
  uint64_t fileBytes = 0;
  double gridStep = 0;
  uint32_t levelRatio = 2;            // the partition's: each level keeps about 1/levelRatio of the one below
  uint64_t weldedVertices = 0, weldedTriangles = 0;  // by the grid weld (vertices closer than the grid step)
  double ingestSeconds = 0, buildSeconds = 0, totalSeconds = 0;
  // CPU seconds (user, kernel): the ingest's (the span of ingestSeconds) and the whole run's (this
  // process, from the start of the build to the file; the grid weld, the sink and the file's index
  // are the part of it in neither the ingest nor a level; after --resume the ingest and the
  // earlier levels are the stopped run's figures).
  double ingestUserSeconds = 0, ingestSysSeconds = 0, cpuUserSeconds = 0, cpuSysSeconds = 0;
  uint64_t peakRssBytes = 0;
  uint64_t ingestPeakRssBytes = 0;    // the peak RSS when the ingest ended (0 after --resume past it)
  uint32_t resumedAtLevel = 0;        // 0: built from the start; k: continued after level k
  uint64_t peakTempBytes = 0;         // largest OUT.work + OUT.mt.tmp seen (sampled in the level loop)
  uint64_t checkpointBytes = 0;       // largest checkpoint record kept in the store (RAM while built)
  // The level loop's regions in flight (this run's levels): the byte bound it had, the largest sum
  // of estimateRegionBytes() and the most regions in flight at once, and the largest region's
  // estimate (the bound is max(levelLoopBytes, that) when levelLoopBytes is not 0).
  uint64_t levelLoopBytes = 0, levelLoopPeakBytes = 0, levelLoopLargestRegionBytes = 0;
  uint32_t levelLoopPeakRegions = 0;
  // Textured builds: bytes of the texture payloads (their images), texels baked above the finest level.
  uint64_t textureBytes = 0, textureImageBytes = 0;
  std::vector<LevelReport> levels;
  std::string extraJson;              // more members (",\n  \"name\": value" ...), e.g. cluster stats
  std::string toJson() const;
};

// SIGINT/SIGTERM stopped the build at a safe point (between regions or levels). The message says
// what was kept (the work directory and temporary file, for --resume) or removed; the tools exit
// with 128 + signal().
class BuildInterrupted : public Error {
 public:
  BuildInterrupted(const std::string& message, int signal) : Error(message), signal_(signal) {}
  int signal() const { return signal_; }

 private:
  int signal_;
};

// input: a mesh file (PLY/OBJ/OFF/STL) or a patch store directory made with a V-partition.
// Writes `output` under a temporary name unique to the process and renames it when complete.
// Before any work: the input must be a regular file or a store, `output` may not be the input or
// a directory, and `output` (OUT.lock) and the work directory (WORK/LOCK) are locked for the whole
// build, so a second build of the same output or in the same work directory is refused naming the
// first one's PID. Throws mt::Error; BuildInterrupted after SIGINT/SIGTERM (when
// installInterruptHandlers() was called).
BuildReport buildMt(const std::string& input, const std::string& output, const BuildOptions& options);

// The bytes a region of the level loop holds, estimated from its floor's counts (known from the
// store's manifest before it is loaded): `working` while it is loaded and processed (the floor
// patches as read and assembled, the simplifier's working set: meshoptimizer's tables, the error
// measurement's triangle grid; the result), `held` from then until its commit (the assembled floor
// and the result). Conservative fits of measured heap peaks (docs/mtbuild.md, "Regions in flight").
struct RegionBytes {
  uint64_t working = 0, held = 0;
};
// With per-vertex colours (`colors`) a region holds more: the colours (4 bytes a vertex in each
// copy) and, while simplified, the attribute quadrics (216 bytes a vertex, attribute_quadric.h)
// and the colour error's face index (color_error.cpp).
RegionBytes estimateRegionBytes(uint64_t triangles, uint64_t vertices, bool colors = false);

// ---- The per-region work, as one pure function (BMT section 4, "the i-th simplification step") --
// mtbuild runs it on threads, mtcluster on MPI ranks; both commit the results in region order with
// LevelBuilder, so the file is the same bytes either way.

// What every worker needs for a whole build (fixed once the level-0 store exists).
struct TextureContext;  // region_texture.h (textured builds)

struct RegionContext {
  QuantizationGrid grid;
  PatchCodecOptions codec;
  const PartitionSequence* sequence = nullptr;
  uint32_t partitionLevels = 0;       // sequence->levels()
  uint64_t rootTriangles = 0;
  RegionSimplifier simplifier = RegionSimplifier::Meshopt;
  const TextureContext* texture = nullptr;  // textured stores: the input's images and the atlas options
  double colorWeight = 0;             // SimplifyRegionOptions::colorWeight (0 without colours)
};

// One region of V(level): its floor (the V*(level-1) patches inside it) assembled into one mesh,
// with the vertices that patches outside the region hold locked (LoadedMesh::locked).
struct RegionTask {
  uint32_t level = 0;                 // the level being built (1 = first simplification)
  uint32_t region = 0;                // the V(level) cell
  bool root = false;                  // the last partition level: one region, everything
  // Root levels only: the largest deviation a root step past the first root level may add (four
  // times the previous level's largest node error); 0: none. See settleRoot (region_work.cpp).
  double rootDeviationLimit = 0;
  // The largest error of the nodes whose fragments hold the floor patches: the new node's error
  // is this plus the measured deviation (textured builds tie the atlases' texel size to it).
  double floorError = 0;
  LoadedMesh mesh;
  double loadSeconds = 0;             // measured by whoever loaded it
};

// One floor patch, encoded for the MT file.
struct EncodedPatch {
  PatchId storeId = 0;
  std::vector<uint8_t> payload;
  uint32_t triangles = 0, vertices = 0;
  // Textured builds: the texture payload (mt_format.h "Textures"; empty: none) and its atlas size.
  std::vector<uint8_t> texture;
  uint16_t textureWidth = 0, textureHeight = 0;
  uint32_t imageBytes = 0;
};

struct RegionResult {
  std::vector<EncodedPatch> encoded;  // the floor patches, in task.mesh.patches order
  ReplacementMesh replacement;        // the simplified region, split by V*(level)
  double deviation = 0;               // measured distance simplified <-> floor
  double colorDeviation = 0;          // measured colour deviation simplified <-> floor (color_error.h)
  double textureError = 0;            // textured builds: the node error its atlases' texels need (region_texture.h)
  double sphere[4] = {0, 0, 0, 0};    // centre, radius of the simplified region
  float coneAxis[3] = {0, 0, 1};
  float coneCutoff = -1;
  double seconds = 0;                 // time spent in processRegion
  uint32_t simplifierRuns = 0;        // simplifyRegion's runs (SimplifiedRegion::attempts)
};

// Encodes the floor patches (rebuilt exactly from task.mesh via unifiedOf), simplifies the region
// to about half (1/k: the partition's level ratio) with its border locked, and keys the result's
// triangles by V*(level) cell.
// Deterministic: depends on its arguments only. Thread-safe.
RegionResult processRegion(const RegionTask& task, const RegionContext& context);

// The level loop's state and its checkpoints: ingest (or resume), then for each level the regions
// to process, committed in region order, then the sink and the file. Checkpoint (after each level,
// atomically with the store's level sync; store blob "mtbuild.checkpoint"): the MT writer's length
// and patch records, the DAG so far, which node produced each live patch, the level reports, and
// a fingerprint of the input and of every option that changes the bytes.
class LevelBuilder {
 public:
  LevelBuilder(const std::string& input, const std::string& output, const BuildOptions& options);
  ~LevelBuilder();
  LevelBuilder(const LevelBuilder&) = delete;
  LevelBuilder& operator=(const LevelBuilder&) = delete;

  const RegionContext& context() const;
  const std::string& sequenceBytes() const;  // PartitionSequence::serialize() of the build
  const BuildOptions& options() const;
  const std::string& workDir() const;        // the work directory in use
  const std::string& tempPath() const;       // the MT file being written (renamed by finish())
  // For a stop after an error or a signal: what is kept and how to continue, e.g. "after level 3;
  // kept OUT.work and OUT.mt.tmp.123.ab12; run the same command with --resume to continue". The
  // destructor then says nothing more.
  std::string stopNote();

  // Plans the next level; false once the build needs no more levels.
  bool beginLevel();
  uint32_t level() const;                    // the level being built (1-based)
  size_t regionCount() const;
  uint64_t regionTriangles(size_t i) const;  // floor triangles of region i (from the manifest)
  uint64_t regionVertices(size_t i) const;   // floor vertices of region i (shared ones once per patch)
  bool hasColors() const;                    // the input has per-vertex colours
  // Reads region i's floor patches and assembles them. Thread-safe between commits.
  RegionTask loadRegion(size_t i) const;
  // Commits region i; must be called for i = 0, 1, ... in order. `moveBytes`: what a cluster
  // moved for it (0 for threads), logged in the task times.
  void commitRegion(size_t i, RegionTask task, RegionResult result, uint64_t moveBytes = 0);
  // Syncs the store and the MT file and writes the checkpoint.
  void endLevel();
  // The sink, the DAG, the file; removes the work directory.
  BuildReport finish();

  struct State;

 private:
  std::unique_ptr<State> s_;
};

}  // namespace mt
