// vpartition: V-partition sequences V0 (finest) .. V(L-1) (coarsest) and their crossings
// V*i = Vi x V(i+1) (BMT section 4). Owns: seed placement (regular, section 4.2.1; irregular,
// section 4.2.2), triangle -> cell assignment by centroid, the V*0 cell key that patchstore's ingest
// sorts by, shape metrics. Depends on patchstore only (CentroidSource/CellAssigner contracts and,
// for the connected-component metric, PatchStore); mtbuild and cluster depend on it.
//
// A triangle belongs to the cell of the seed nearest to its centroid (ties: lower seed index), so
// a partition is a pure function of (seeds, centroid): ingest, mtbuild's split and any MPI rank get
// the same cells from the same serialized sequence.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include "patchstore/cell_assigner.h"
#include "patchstore/patch_store.h"

namespace mt {

enum class PartitionKind : uint8_t {
  Irregular = 0,  // streamed Poisson-disk seeds + one Lloyd step (4.2.2); the default
  Regular = 1,    // 3D grid: cube centres, edge centres, face centres -> cubes and octahedra (4.2.1)
  Regular2D = 2,  // the 2D analogue (squares and 45-degree diamonds: the bintree of Figure 6),
                  // in the plane of the two largest bounding-box extents; for terrains and tests
};

// "irregular" | "regular" | "regular2d" (case-sensitive). Throws mt::Error on anything else.
PartitionKind parsePartitionKind(const std::string& text);
const char* partitionKindName(PartitionKind kind);

// Default mean triangles per patch (= per V*0 cell); see docs/vpartition.md for the measurements.
constexpr uint32_t kDefaultPatchTriangles = 1000;
// "--patch-triangles N": a positive integer in [16, 1<<24]. Throws mt::Error otherwise.
uint32_t parsePatchTriangles(const std::string& text);

// The level ratio k: V(i+1) aims at 1/k of Vi's cells, and mtbuild simplifies each region to 1/k
// of its triangles, so every level keeps about 1/k of the one below (BMT halves: k = 2). Irregular
// partitions only; the regular sequences' ratios are fixed by their geometry (docs/vpartition.md).
constexpr uint32_t kDefaultLevelRatio = 2;
constexpr uint32_t kMinLevelRatio = 2;
constexpr uint32_t kMaxLevelRatio = 8;
// "--level-ratio K" for a partition of this kind: throws mt::Error naming K when it is outside
// [kMinLevelRatio, kMaxLevelRatio], or is not 2 for a regular kind. The one check every caller
// (the tools' options, BuildOptions, VPartitionOptions) goes through, so the messages agree.
void checkLevelRatio(int64_t ratio, PartitionKind kind);

struct VPartitionOptions {
  PartitionKind kind = PartitionKind::Irregular;
  uint32_t patchTriangles = 0;    // target mean triangles per V*0 cell (a patch); 0: default
  uint32_t levelRatio = kDefaultLevelRatio;  // irregular: level i aims at N / (T0 * ratio^i) cells
  uint64_t seed = 0;              // regular kinds: 0 puts the grid origin at the bounding box
                                  // corner, otherwise it is shifted by a hash of the seed (avoids
                                  // grid planes through axis-aligned CAD faces); irregular: unused
  uint32_t maxCoarsestCells = 8;  // add levels until the coarsest has at most this many cells
  uint32_t maxLevels = 40;
  double regularCellSize = 0;     // regular kinds: finest spacing; 0 derives it from patchTriangles
  uint64_t lookupTableBytes = 256ull << 20;  // irregular: budget for the precomputed candidate
                                  // tables (finest levels first; the others use a per-thread cache)
  uint32_t threads = 0;           // irregular build: threads over levels; 0 = hardware. Results do
                                  // not depend on it (each level is scanned in order on one thread)
};

// What building cost, for logs and the report.
struct PartitionBuildStats {
  uint32_t passes = 0;          // streaming passes over the input centroids
  uint32_t samplePasses = 0;    // irregular: passes over the in-memory sample (area, seeding,
                                // Lloyd, recounts)
  uint64_t sampleStride = 1;    // irregular: every sampleStride-th centroid was sampled
  uint64_t sampleBytes = 0;     // irregular: bytes of that sample (not in seedBytes)
  uint32_t calibrationPasses = 0;  // of which re-seeding passes to hit the cell-count targets
  uint64_t removedSeeds = 0;    // irregular: seeds dropped because their cells were too small
  uint64_t splitSeeds = 0;      // irregular: cells split in two because they were too big
  uint64_t seedBytes = 0;       // peak bytes of seeds + hash grids while building
  double seconds = 0;
};

// One level's cell function. Opaque; PartitionSequence owns them.
namespace vp { struct PartitionLevel; }
using vp::PartitionLevel;

class PartitionSequence {
 public:
  PartitionSequence();
  ~PartitionSequence();
  PartitionSequence(PartitionSequence&&) noexcept;
  PartitionSequence& operator=(PartitionSequence&&) noexcept;

  // Streams over the centroids (a few passes, memory = seeds + hash grids; see stats()).
  static PartitionSequence build(const CentroidSource& centroids, const VPartitionOptions& options);

  PartitionKind kind() const { return kind_; }
  uint32_t levels() const { return uint32_t(levels_.size()); }
  // Cell ids of a level are < cellCount(level). Irregular: the number of seeds (every cell is
  // non-empty for the built-from centroids). Regular: the size of the grid's id space (cells that
  // miss the surface are empty).
  uint32_t cellCount(uint32_t level) const;
  // The Vi cell of a centroid. Deterministic and thread-safe.
  uint32_t cellOf(uint32_t level, const float c[3]) const;
  // The V*i cell key: (uint64(Vi cell) << 32) | V(i+1) cell; for the coarsest level V(i+1) is the
  // one cell covering everything, id 0. Ingest keys patches by crossKey(0, c).
  uint64_t crossKey(uint32_t level, const float c[3]) const;
  static uint32_t crossHigh(uint64_t key) { return uint32_t(key >> 32); }  // the Vi cell
  static uint32_t crossLow(uint64_t key) { return uint32_t(key); }         // the V(i+1) cell
  // The seed (site) of a cell: irregular seeds, or the regular cell centres.
  void seedOf(uint32_t level, uint32_t cell, float out[3]) const;
  // Irregular: the seeds of a level, xyz per seed (empty for regular kinds).
  const std::vector<float>& seeds(uint32_t level) const;
  // Irregular: the level's seed spacing radius r_i; regular: the grid spacing.
  double levelScale(uint32_t level) const;
  // Irregular: the cell count the level aimed for (N / (kCrossPerCell * patchTriangles * k^i),
  // k = levelRatio()); 0 for regular kinds.
  uint64_t levelTarget(uint32_t level) const;
  // How many times fewer cells each level aims for than the one before (2 unless the irregular
  // sequence was built with another VPartitionOptions::levelRatio); mtbuild simplifies each
  // region by the same factor.
  uint32_t levelRatio() const { return levelRatio_; }

  // Bytes the sequence keeps in core (seeds, grids, candidate tables).
  uint64_t memoryBytes() const;

  std::string describe() const;
  std::string serialize() const;
  // Throws mt::Error on bad bytes (wrong magic/version, truncated, checksum mismatch).
  static PartitionSequence deserialize(const std::string& bytes);

  const PartitionBuildStats& stats() const { return stats_; }
  PartitionBuildStats& mutableStats() { return stats_; }

  // Used by the builders.
  void addLevel(std::unique_ptr<PartitionLevel> level);
  void setKind(PartitionKind kind) { kind_ = kind; }
  void setLevelRatio(uint32_t ratio);  // after setKind; throws mt::Error as checkLevelRatio

 private:
  PartitionKind kind_ = PartitionKind::Irregular;
  uint32_t levelRatio_ = kDefaultLevelRatio;
  std::vector<std::unique_ptr<PartitionLevel>> levels_;
  PartitionBuildStats stats_;
};

// The centroid every user of a partition must compute the same way (ingest, mtbuild's split, the
// metrics), so that a triangle on a Voronoi boundary lands in the same cell everywhere: the mean
// of the three corners in double, rounded once to float.
inline void triangleCentroid(const double* a, const double* b, const double* c, float out[3]) {
  for (int k = 0; k < 3; ++k) out[k] = float((a[k] + b[k] + c[k]) / 3.0);
}

// The builders behind PartitionSequence::build (one per file: regular.cpp, irregular.cpp).
PartitionSequence buildRegularSequence(const CentroidSource& centroids, const VPartitionOptions& o);
PartitionSequence buildIrregularSequence(const CentroidSource& centroids,
                                         const VPartitionOptions& o);
namespace vp { struct CentroidSample; }
// The irregular builder on a sample taken by vp::sampleCentroids (level.h); the level targets
// come from the sample's input count.
PartitionSequence buildIrregularFromSample(const vp::CentroidSample& sample, const VPartitionOptions& o);

// The ingest-side CellAssigner: prepare() builds the sequence, cellKey() = crossKey(0, c),
// serialize() = the sequence bytes (stored as blob "assigner"; mtbuild rebuilds the same sequence
// with PartitionSequence::deserialize).
class VPartitionAssigner : public CellAssigner {
 public:
  // Throws mt::Error for a level ratio the kind does not take (checkLevelRatio), before any pass.
  explicit VPartitionAssigner(const VPartitionOptions& options) : options_(options) {
    checkLevelRatio(options.levelRatio, options.kind);
  }
  void prepare(const CentroidSource& centroids, uint64_t memoryBytes) override;
  // crossKey(0, c), balanced: V*0 slivers join their V0 cell's largest piece, oversized pieces
  // are cut into slabs (assign.cpp). The V1 half, the region the level loop reads, is kept
  // except for merged slivers.
  uint64_t cellKey(const float c[3]) const override;
  std::string describe() const override;
  std::string serialize() const override { return released_ ? serialized_ : sequence_.serialize(); }
  // Keeps the sequence's bytes and description and frees the rest: at a billion triangles in
  // ~1.2 M patches the seed grids, candidate tables and key maps are ~200 MiB, which the
  // ingest's join, patch and boundary stages then have for their sorters.
  void releaseLookups() override;
  // The sequence; empty after releaseLookups().
  const PartitionSequence& sequence() const { return sequence_; }

 private:
  void mergeSlivers(const vp::CentroidSample& sample);
  uint64_t joinedKey(uint64_t key) const;  // the key a piece ends up with, before slab cuts
  void buildKeyTable();
  VPartitionOptions options_;
  PartitionSequence sequence_;
  std::unordered_map<uint64_t, uint64_t> remap_;  // sliver V*0 key -> the key it joins
  struct Slabs {
    int axis = 0;
    std::vector<float> bounds;  // ascending: slab k is [bounds[k-1], bounds[k])
  };
  std::unordered_map<uint64_t, Slabs> slabs_;  // oversized V*0 key -> its cut into slabs
  // Sampled inputs only: the pieces the sample saw, and per V0 cell the key its largest piece
  // ends up with. A piece the sample missed holds a few triangles (< ~stride): it joins that.
  bool sampled_ = false;
  std::unordered_map<uint64_t, uint64_t> seen_;      // piece key -> final key (itself or joined)
  std::unordered_map<uint32_t, uint64_t> largest_;   // V0 cell -> final key of its largest piece
  // cellKey()'s fast path: every V*0 key the sample saw, with its final key and slab cut, in one
  // open-addressing table (the maps above answer keys the sample missed).
  struct KeyEntry {
    uint64_t raw = 0, final = 0;
    int32_t slabs = -1;  // index into slabList_, -1: not cut
    uint32_t used = 0;
  };
  std::vector<uint64_t> sampleKeys_;
  std::vector<KeyEntry> keyTable_;
  uint64_t keyMask_ = 0;
  std::vector<Slabs> slabList_;
  bool released_ = false;
  std::string serialized_, described_;  // after releaseLookups()
};

std::unique_ptr<CellAssigner> makeVPartitionAssigner(const VPartitionOptions& options);

// ---- Shape metrics (BMT section 3.2 conditions: log path length, constant backward star) ----

struct LevelMetrics {
  uint32_t level = 0;
  uint64_t cells = 0;                 // non-empty Vi cells
  uint64_t target = 0;                // irregular: the cell count aimed for (0 for regular)
  uint32_t minTriangles = 0, maxTriangles = 0;  // input triangles per Vi cell
  double meanTriangles = 0;
  uint64_t crossCells = 0;            // non-empty V*i cells
  uint32_t crossMin = 0, crossMax = 0;
  double crossMean = 0;
  // Backward star of the V(i+1) cells over Vi: how many Vi cells each one overlaps (for the
  // coarsest level, V(i+1) is the root covering everything).
  double backwardStarMean = 0;
  uint32_t backwardStarMax = 0;
  double multiComponentShare = -1;    // share of Vi cells with > 1 connected component; -1: unknown
};

struct PartitionMetrics {
  PartitionKind kind = PartitionKind::Irregular;
  uint64_t triangles = 0;
  std::vector<LevelMetrics> levels;
  PartitionBuildStats build;
};

// One streaming pass over the centroids; memory ~ number of V*i cells over all levels.
PartitionMetrics computeMetrics(const PartitionSequence& sequence, const CentroidSource& centroids);

// Share of Vi cells (per level) whose triangles form more than one connected component (sharing a
// vertex connects). Patches are V*0 cells; for each level the patches are grouped by the Vi cells
// their triangles fall in and each cell is solved alone with a union-find over (patch, local
// vertex) ids joined through the boundary lists, so memory is one cell's patches at a time.
// `loadPatch` must return patch(id) with triangles, positions and boundary.
std::vector<double> computeComponentShare(const PartitionSequence& sequence,
                                          const std::vector<PatchId>& patchIds,
                                          const std::function<Patch(PatchId)>& loadPatch);
// The same over a PatchStore (inline, below, so linking PatchStore is only needed when called).
// Fills metrics.levels[i].multiComponentShare.
void addComponentShare(PartitionMetrics& metrics, const std::vector<double>& share);

std::string formatMetricsText(const PartitionMetrics& metrics);
std::string formatMetricsJson(const PartitionMetrics& metrics);

// ---- Over a patch store (store_metrics.cpp) ----

// The centroids (+ areas) of a store's live patches, patch by patch in id order, computed with
// triangleCentroid(). One pass reads every patch once.
class StoreCentroids : public CentroidSource {
 public:
  explicit StoreCentroids(const PatchStore& store);
  uint64_t count() const override { return triangles_; }
  Box3 bounds() const override { return bounds_; }
  void forEach(const std::function<void(const float* xyza, size_t count)>& fn) const override;

 private:
  const PatchStore& store_;
  std::vector<PatchId> ids_;
  uint64_t triangles_ = 0;
  Box3 bounds_;
};

// The sequence ingest stored as blob "assigner"; false when the store was not partitioned by a
// V-partition (e.g. the grid assigner) or has no blob.
bool loadStoreSequence(const PatchStore& store, PartitionSequence& out);

// The partition section of `mtstore info`: per-level metrics (text table or one JSON object),
// with the connected-component share when `components` (reads every patch ~2x per level).
// Returns "" when the store has no V-partition.
std::string storePartitionMetrics(const PatchStore& store, bool json, bool components = true);

}  // namespace mt

namespace mt {
inline std::vector<double> computeComponentShare(const PartitionSequence& sequence,
                                                 const PatchStore& store) {
  return computeComponentShare(sequence, store.patchIds(),
                               [&store](PatchId id) { return store.patch(id); });
}
}  // namespace mt
