// The level loop's state machine (LevelBuilder, build.h): the level-0 store and the file's
// header, the levels' regions, the commits in region order that grow the DAG (BMT sections 3.1,
// 4), and the sink and the file at the end. Checkpoints: checkpoint.cpp.
#include <algorithm>
#include <cassert>
#include <cinttypes>
#include <csignal>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <thread>

#include <malloc.h>
#include <unistd.h>

#include "base/interrupt.h"
#include "base/memory_plan.h"
#include "base/output_path.h"
#include "base/process.h"
#include "mtbuild/level_state.h"
#include "mtbuild/region_work.h"
#include "mtbuild/work_dir.h"
#include "patchstore/heal/heal.h"

namespace mt {

namespace {

namespace fs = std::filesystem;

// The quantization step: a fraction of the mean edge length (estimated from a sample of patches),
// so the quantization error (step * sqrt(3)/2) stays a fraction of an edge. 1/8 for the meshopt
// simplifier (/16 measured 0.2 bytes per input triangle more, docs/mtbuild.md). 1/11 for the
// quadric simplifier, whose moved vertices are snapped to the grid at every level: there the step
// is the main difference between its 1/8 cut and an unquantized one (2-4% of the mean distance
// per halving of the step), and its files are smaller; 1/11 is the finest step that kept four
// scan-derived meshes at or under 2.4 bytes per input triangle (docs/mtbuild.md, "Quality at
// equal size").
double chooseGridStep(const PatchStore& store, RegionSimplifier simplifier) {
  std::vector<PatchId> ids = store.patchIds();
  double sum = 0;
  uint64_t edges = 0;
  size_t stride = std::max<size_t>(1, ids.size() / 64);
  for (size_t i = 0; i < ids.size(); i += stride) {
    Patch p = store.patch(ids[i]);
    for (size_t t = 0; t < p.triangles.size(); t += 3)
      for (int k = 0; k < 3; ++k) {
        const double *a = &p.positions[3 * p.triangles[t + k]], *b = &p.positions[3 * p.triangles[t + (k + 1) % 3]];
        sum += std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]));
        ++edges;
      }
  }
  double mean = edges ? sum / double(edges) : 0;
  const double fraction = simplifier == RegionSimplifier::Quadric ? 11 : 8;
  return mean > 0 ? mean / fraction : 1e-6;
}

// The simplifier a build runs: the explicit choice, or under `auto` the quadric for coloured input
// (colour-aware) and meshopt otherwise. One rule for the grid step and the regions, so an `auto`
// build of coloured input gets the quadric's grid, as an explicit `--simplifier quadric` does.
RegionSimplifier resolvedSimplifier(const BuildOptions& options, bool colors) {
  if (!options.simplifierByInput) return options.simplifier;
  return colors ? RegionSimplifier::Quadric : RegionSimplifier::Meshopt;
}

// A level gains when it keeps at most 90% of the triangles it was given: the one rule that ends
// the level loop (endLevel) and that refuses a further root level before it is written
// (commitRegion).
bool gains(uint64_t in, uint64_t out) { return out * 10 <= in * 9; }

// `mtbuild STORE --level-ratio K`: the store's partition fixed its ratio at ingest, so another K
// is refused, read from the store as it is (no lock, nothing changes) before anything is copied.
void requireStoreLevelRatio(const std::string& input, uint32_t ratio) {
  PartitionSequence sequence;
  if (!loadStoreSequence(*PatchStore::open(input), sequence) || sequence.levelRatio() == ratio) return;
  const std::string kind = partitionKindName(sequence.kind());
  fail(input, "--level-ratio " + std::to_string(ratio) + ": the patch store's " + kind + " V-partition has level ratio " +
                  std::to_string(sequence.levelRatio()) + "; omit --level-ratio to build with it" +
                  (sequence.kind() == PartitionKind::Irregular
                       ? ", or ingest the mesh again with `mtstore ingest --level-ratio " + std::to_string(ratio) + "`"
                       : ""));
}

double largestMagnitude(const Box3& box) {
  double m = 0;
  for (int a = 0; a < 3; ++a) m = std::max({m, std::abs(box.lo[a]), std::abs(box.hi[a])});
  return m;
}

// Spacing of float32 values at magnitude m: the finest detail a float32 input can hold there (0.5
// at 6e6, so a float PLY of UTM metres has lost its centimetres before it is read).
double float32Spacing(double m) {
  const float f = float(m);
  return double(std::nextafter(f, std::numeric_limits<float>::infinity())) - double(f);
}

}  // namespace

void LevelBuilder::State::startFresh(bool storeInput) {
  std::error_code ec;
  // An earlier build's work (ours by its marker, locked by us now) and its temporary file.
  if (std::string old = recordedTempPath(work, output); !old.empty()) fs::remove(old, ec);
  clearWorkDir(work);
  ingestLevelZero(storeInput);
  report.ingestSeconds = secondsSince(t0);
  const CpuSeconds ingestCpu = processCpuSeconds();
  report.ingestUserSeconds = ingestCpu.user - cpu0.user;
  report.ingestSysSeconds = ingestCpu.sys - cpu0.sys;
  report.ingestPeakRssBytes = peakRssBytes();
  StoreInfo info = store->info();
  report.inputTriangles = info.triangles;
  liveTriangles = info.triangles;
  // 2. The global quantization grid (mt_format.h): shared vertices quantize identically.
  QuantizationGrid grid = QuantizationGrid::fromBounds(info.bounds.lo, info.bounds.hi, chooseGridStep(*store, resolvedSimplifier(options, info.layout.colors)));
  report.gridStep = grid.step;
  const double magnitude = largestMagnitude(info.bounds);
  if (weldToGrid(grid)) {
    info = store->info();
    liveTriangles = info.triangles;
  }
  // float32 positions coarser than the grid, and vertices merged: float rounding has put distinct
  // points of the model on one position before the file was read (a float PLY of UTM metres with
  // centimetre detail). Said even with --quiet: it is data lost, and double or text input keeps it.
  // (Without merges the float values may well be exact, as a 0.5 m grid at 4e6 is: nothing said.)
  if (!info.layout.doublePrecision && report.weldedVertices && float32Spacing(magnitude) > grid.step)
    std::fprintf(stderr,
                 "%s: warning: %s: float32 positions are only %.3g apart at coordinates up to %.9g, coarser than "
                 "the grid step %.3g: the file cannot hold finer detail (the grid weld merged %" PRIu64
                 " vertices and removed %" PRIu64 " triangles); write the positions as double to keep it\n",
                 options.toolName.c_str(), input.c_str(), float32Spacing(magnitude), magnitude, grid.step, report.weldedVertices, report.weldedTriangles);
  // Every triangle degenerate (a repeated vertex, or all within one grid cell once welded): the
  // file would have no patch, which no reader accepts.
  if (store->info().triangles == 0)
    fail(input, "every triangle is degenerate (zero area at the grid step " + std::to_string(grid.step) +
                    "); nothing to build");
  startFile(info, grid);
  // 3. The DAG. Node 0 is the source: the full-resolution fragment (BMT 3.1).
  nodes.assign(1, format::NodeRecord{});
  spheres.assign(1, Sphere{});
  format::NodeRecord& source = nodes[0];
  for (int a = 0; a < 3; ++a) source.center[a] = 0.5 * (info.bounds.lo[a] + info.bounds.hi[a]);
  source.radius = 0;  // never refined past, so its sphere is not part of the nesting
  source.error = float(grid.maxError());
  source.coneCutoff = -1;
  source.coneAxis[2] = 1;
  source.level = 0;
  for (PatchId id : store->patchIds()) producer[id] = 0;
  // Checkpoint 0: a build killed from here on resumes without ingesting again.
  writeCheckpoint();
}

void LevelBuilder::State::ingestLevelZero(bool storeInput) {
  std::error_code ec;
  // 1. The level-0 patch store, partitioned by V*0 (BMT 4: "the mesh partitioned according to V*0").
  // Nothing to resume from yet: a failure (or a signal) here leaves no work directory behind.
  try {
    if (storeInput) {
      // The store's writer lock while its files are copied: the build is refused (with the
      // PID) while a heal writes it, and a heal started during the copy is refused, so no copy is
      // half one version, half another (a heal may compact, replacing segment files).
      FileLock inputLock(input + "/LOCK", input);
      fs::copy(input, storeDir, fs::copy_options::recursive, ec);
      if (ec) fail(input, "cannot copy the store into " + work + ": " + ec.message());
      fs::remove(storeDir + "/LOCK", ec);
    } else {
      VPartitionOptions vp;
      vp.kind = options.partition;
      vp.patchTriangles = options.patchTriangles ? options.patchTriangles : kDefaultMtPatchTriangles;
      vp.levelRatio = options.levelRatio ? options.levelRatio : kDefaultLevelRatio;
      VPartitionAssigner assigner(vp);
      IngestOptions io;
      io.memoryBytes = options.memoryBytes;
      io.progress = options.progress;
      PatchStore::ingest(input, storeDir, assigner, io);
    }
    store = PatchStore::open(storeDir);
    store->setAutoCommit(false);
    if (!loadStoreSequence(*store, sequence))
      fail(input, "the patch store was not made with a V-partition (ingest it with --partition irregular or regular)");
    // An empty surface (e.g. a heal removed every component) would give an MT file without
    // patches, which no reader accepts.
    if (store->info().triangles == 0)
      fail(input, storeInput ? "the patch store holds no triangles; nothing to build" : "has no triangles; nothing to build");
  } catch (...) {
    store.reset();
    fs::remove_all(work, ec);
    throw;
  }
}

// The grid weld (patchstore/heal/grid_weld.cpp): the vertices of each grid cell become one, so no
// two vertices of a cut quantize to one position. True when it merged any.
bool LevelBuilder::State::weldToGrid(const QuantizationGrid& grid) {
  heal::GridCells cells;
  for (int a = 0; a < 3; ++a) cells.origin[a] = grid.origin[a];
  cells.step = grid.step;
  heal::HealOptions ho;
  // Its heal cap comes from what the store's patch records, the V-partition and the process leave
  // of --memory (MemoryPlan::besides; the whole cap's half took a 100 M build to 110 MiB at 96M).
  malloc_trim(0);
  ho.memoryBytes = planMemory(options.memoryBytes, 1).besides(currentRssBytes()).gridWeld;
  ho.progress = options.progress;
  heal::PassReport w = heal::weldToGrid(*store, cells, ho);
  report.weldedVertices = w.get("merged");
  report.weldedTriangles = w.get("degenerate");
  if (report.weldedVertices)
    say("grid weld: " + std::to_string(report.weldedVertices) + " vertices closer than the grid step (" +
        std::to_string(grid.step) + ") merged, " + std::to_string(report.weldedTriangles) +
        " triangles that became degenerate removed");
  return report.weldedVertices != 0;
}

void LevelBuilder::State::startFile(const StoreInfo& info, const QuantizationGrid& grid) {
  const double qError = grid.maxError();
  header = format::FileHeader{};
  header.codec = uint32_t(options.codec);
  header.vertexFlags = (options.normals ? format::kHasNormals : 0) | (info.layout.colors ? format::kHasColors : 0) |
                       (info.layout.texcoords ? format::kHasTextures : 0);
  header.payloadAlignment = format::kDefaultPayloadAlignment;
  header.inputTriangles = report.inputTriangles;
  header.inputVertices = info.vertices;  // (copies of shared vertices counted once per patch)
  header.weldedVertices = report.weldedVertices;
  header.weldedTriangles = report.weldedTriangles;
  for (int a = 0; a < 3; ++a) {
    header.boundsMin[a] = info.bounds.lo[a];
    header.boundsMax[a] = info.bounds.hi[a];
    header.gridOrigin[a] = grid.origin[a];
  }
  header.gridStep = grid.step;
  header.quantizationError = qError;
  header.gridBits = grid.bits;
  tempPath = uniqueTempName(output);
  recordTempPath(work, tempPath);
  writer = std::make_unique<MtFileWriter>(output, header, tempPath);
  header = writer->header();
}

// A build continues only from a work directory of an earlier build holding a finished ingest, a
// checkpoint, and the temporary file that checkpoint describes; otherwise it says why it starts over.
bool LevelBuilder::State::tryResume() {
  if (workCreated) {
    if (options.resume) say("--resume: no work directory " + work + "; starting from the input");
    return false;
  }
  if (!options.resume) {
    say("removing the work in " + work + " of an earlier build and starting over (--resume continues it)");
    return false;
  }
  if (!fs::exists(storeDir + "/CURRENT")) {
    say("--resume: " + work + " holds no finished ingest; starting from the input");
    return false;
  }
  const std::string recorded = recordedTempPath(work, output);
  store = PatchStore::open(storeDir);
  std::string bytes = store->blob(kCheckpointBlob);
  if (bytes.empty()) {
    say("--resume: " + work + " has no checkpoint yet; starting from the input");
    store.reset();
    return false;
  }
  if (recorded.empty() || !fs::exists(recorded)) {
    say("--resume: the temporary file " + (recorded.empty() ? output + ".tmp.*" : recorded) +
        " of the stopped build is gone; starting from the input");
    store.reset();
    return false;
  }
  store->setAutoCommit(false);
  if (!loadStoreSequence(*store, sequence)) fail(storeDir, "work store has no V-partition");
  tempPath = recorded;
  restore(bytes);
  report.resumedAtLevel = builtLevels;
  say("--resume: continuing after level " + std::to_string(builtLevels) + " from " + work + " and " + recorded);
  return true;
}

// ---- LevelBuilder -------------------------------------------------------------------------------

LevelBuilder::LevelBuilder(const std::string& input, const std::string& output, const BuildOptions& options)
    : s_(std::make_unique<State>()) {
  State& s = *s_;
  s.t0 = Clock::now();
  s.cpu0 = processCpuSeconds();
  s.options = options;
  s.input = input;
  s.output = output;
  if (options.patchTriangles != 0 && (options.patchTriangles < kMinPatchTriangles || options.patchTriangles > kMaxPatchTriangles))
    throw Error("--patch-triangles " + std::to_string(options.patchTriangles) + ": out of range (accepted " +
                std::to_string(kMinPatchTriangles) + " to " + std::to_string(kMaxPatchTriangles) + ")");
  if (options.levelRatio != 0) checkLevelRatio(options.levelRatio, options.partition);
  // Nothing is touched before the input and the output are known to be what they should.
  const bool storeInput = isStoreDir(input);
  if (!storeInput) requireRegularFile(input, "a mesh file (PLY, OBJ, OFF, STL) or a patch store");
  if (storeInput && options.levelRatio != 0) requireStoreLevelRatio(input, options.levelRatio);
  checkOutputPath(output, {input});
  // One build per output, one per work directory: a second one is refused (naming the first's
  // PID) before it removes or writes anything.
  s.outputLock = std::make_unique<FileLock>(output + ".lock", output);
  WorkChoice choice = chooseWorkDir(output, options.workDir);
  s.work = choice.dir;
  s.workCreated = choice.created;
  try {
    s.workLock = std::make_unique<FileLock>(s.work + "/" + kWorkLock, "work directory " + s.work);
  } catch (...) {
    std::error_code ec;
    if (s.workCreated) fs::remove_all(s.work, ec);
    throw;
  }
  s.workLock->keepFile();  // the directory goes as a whole, or stays for --resume
  s.storeDir = s.work + "/store";
  s.say("work directory " + s.work + (s.workCreated ? " (new)" : ""));
  // The level loop frees and allocates region buffers all the time; from a patch store (no
  // ingest, which sets the same) glibc's defaults returned and re-faulted them: 10M store, level
  // loop 12.5-14.2 s -> 11.4-12.4 s, sys 1.8 -> 0.7 s.
  useStreamingAllocator();
  if (const char* k = std::getenv("MT_TEST_KILL_AFTER_LEVEL")) s.killAfterLevel = std::atol(k);
  if (const char* k = std::getenv("MT_TEST_KILL_AFTER_REGIONS")) s.killAfterRegions = std::atol(k);
  if (const char* k = std::getenv("MT_TEST_PAUSE_MS_PER_REGION")) s.regionPauseMs = std::atol(k);
  s.fingerprint = fingerprint(input, options, storeInput);

  const bool resumed = s.tryResume();
  if (!resumed) {
    try {
      s.startFresh(storeInput);
    } catch (const Interrupted& e) {
      throw BuildInterrupted(std::string("interrupted by ") + signalName(e.signal()) + " during the ingest; removed " + s.work +
                                 " (nothing to resume yet)",
                             e.signal());
    }
  }

  s.buildStart = Clock::now();
  s.sequenceBytes = s.sequence.serialize();
  const uint32_t patchTriangles = options.patchTriangles ? options.patchTriangles : kDefaultMtPatchTriangles;
  s.ctx.grid.step = s.header.gridStep;
  s.ctx.grid.bits = s.header.gridBits;
  for (int a = 0; a < 3; ++a) s.ctx.grid.origin[a] = s.header.gridOrigin[a];
  s.ctx.codec.codec = options.codec;
  s.ctx.codec.normals = options.normals;
  s.ctx.codec.strips = options.strips;
  s.ctx.sequence = &s.sequence;
  s.ctx.partitionLevels = s.sequence.levels();
  s.report.levelRatio = s.sequence.levelRatio();
  const bool colors = s.header.vertexFlags & format::kHasColors;
  s.ctx.simplifier = resolvedSimplifier(options, colors);
  s.ctx.colorWeight = colors ? options.colorWeight : 0;
  if (options.simplifierByInput && colors)
    s.say("the input has per-vertex colours: simplifying with the quadric simplifier, colour-aware (--simplifier meshopt "
          "ignores colours)");
  s.ctx.rootTriangles = options.rootTriangles ? options.rootTriangles : 2ull * patchTriangles;
  if (s.store->layout().texcoords) {
    // Textured store: the input's tiled images through one cache of decoded tiles (a fixed share:
    // 1/16 of --memory, at least 8 MiB), and the atlas options.
    s.texture = std::make_unique<TextureContext>();
    s.texture->materials = storeMaterials(*s.store);
    s.texture->tiles = openTextureCache(*s.store, s.texture->materials, std::max<uint64_t>(8ull << 20, options.memoryBytes / 16));
    s.texture->quality = options.textureQuality;
    s.ctx.texture = s.texture.get();
  }
  if (!options.taskTimesPath.empty()) {
    s.taskTimes = std::fopen(options.taskTimesPath.c_str(), resumed ? "a" : "w");
    if (!s.taskTimes) fail(options.taskTimesPath, "cannot write");
    if (!resumed)
      std::fprintf(s.taskTimes,
                   "level,region,floor_patches,triangles_in,triangles_out,load_s,process_s,commit_s,task_bytes,result_bytes,moved_bytes\n");
  }
}

LevelBuilder::~LevelBuilder() {
  if (!s_) return;
  if (s_->taskTimes) std::fclose(s_->taskTimes);
  // Stopped by an error after a checkpoint: keep the temporary file beside the work directory so
  // that --resume can continue from the last finished level (the final name is never written).
  if (!s_->completed && s_->writer && s_->store) {
    if (!s_->noted) s_->say("stopped " + stopNote());
  }
}

std::string LevelBuilder::stopNote() {
  State& s = *s_;
  if (s.completed || !s.writer || !s.store) return "; nothing to resume";
  s.writer->detach();
  s.noted = true;
  const bool inLevel = s.progress && s.nextCommit < s.regionIds.size() && s.nextCommit > 0;
  std::string where = s.builtLevels == 0 ? "after the ingest" : "after level " + std::to_string(s.builtLevels);
  if (inLevel) where = "during level " + std::to_string(s.builtLevels + 1) + " (the checkpoint " + where + " is kept)";
  return where + "; kept " + s.work + " and " + s.tempPath + "; run the same command with --resume to continue";
}

const RegionContext& LevelBuilder::context() const { return s_->ctx; }
const std::string& LevelBuilder::sequenceBytes() const { return s_->sequenceBytes; }
const BuildOptions& LevelBuilder::options() const { return s_->options; }
const std::string& LevelBuilder::workDir() const { return s_->work; }
const std::string& LevelBuilder::tempPath() const { return s_->tempPath; }
uint32_t LevelBuilder::level() const { return s_->builtLevels + 1; }
size_t LevelBuilder::regionCount() const { return s_->regionIds.size(); }
uint64_t LevelBuilder::regionTriangles(size_t i) const { return s_->floorTriangles.at(i); }
uint64_t LevelBuilder::regionVertices(size_t i) const { return s_->floorVertices.at(i); }
bool LevelBuilder::hasColors() const { return s_->header.vertexFlags & format::kHasColors; }

bool LevelBuilder::beginLevel() {
  State& s = *s_;
  if (s.finished) return false;
  const uint32_t level = s.builtLevels;  // building level + 1 from V*level
  // Regions of V(level+1): patches grouped by the low half of their V*level key.
  std::map<uint32_t, std::vector<PatchId>> regions;
  std::map<uint32_t, std::pair<uint64_t, uint64_t>> counts;  // triangles, vertices
  for (PatchId id : s.store->patchIds()) {
    PatchMeta m = s.store->meta(id);
    regions[PartitionSequence::crossLow(m.cell)].push_back(id);
    counts[PartitionSequence::crossLow(m.cell)].first += m.triangles;
    counts[PartitionSequence::crossLow(m.cell)].second += m.vertices;
  }
  s.root = level + 1 >= s.ctx.partitionLevels;
  if (s.liveTriangles <= s.ctx.rootTriangles && level > 0) {
    s.finished = true;
    return false;
  }
  s.regionIds.clear();
  s.floors.clear();
  s.floorTriangles.clear();
  s.floorVertices.clear();
  s.floorErrors.clear();
  for (auto& [r, ids] : regions) {
    s.regionIds.push_back(r);
    float floorError = 0;  // here, not in loadRegion: commits change `producer` while regions load
    for (PatchId id : ids) floorError = std::max(floorError, s.nodes.at(s.producer.at(id)).error);
    s.floorErrors.push_back(floorError);
    s.floors.push_back(std::move(ids));
    s.floorTriangles.push_back(counts[r].first);
    s.floorVertices.push_back(counts[r].second);
  }
  s.levelStart = Clock::now();
  s.levelCpu0 = processCpuSeconds();
  s.lr = LevelReport{};
  s.lr.level = level + 1;
  s.lr.regions = uint32_t(s.regionIds.size());
  s.lr.trianglesIn = s.liveTriangles;
  s.nextCommit = 0;
  s.doneTriangles = s.outTriangles = 0;
  // Past the partition's levels come further root levels (the whole model in one region, while
  // each gains 10%; docs/mtbuild.md "The root"): "level 7/6" would read as a miscount.
  const std::string label = level + 1 <= s.ctx.partitionLevels
                                ? "level " + std::to_string(level + 1) + "/" + std::to_string(s.ctx.partitionLevels)
                                : "level " + std::to_string(level + 1) + " (a further root level)";
  s.progress = std::make_unique<Progress>(s.options.progress, s.options.toolName + ": " + label, s.liveTriangles);
  return true;
}

RegionTask LevelBuilder::loadRegion(size_t i) const {
  const State& s = *s_;
  auto start = Clock::now();
  RegionTask task;
  task.level = s.builtLevels + 1;
  task.region = s.regionIds.at(i);
  task.root = s.root;
  // A further root step may deviate up to 4x the previous level's largest error (settleRoot): an
  // ordinary level grows it 1.5-2.5x (the m10 scan's levels), a step that folds the model far more
  // (the 53 M armadillo scan's refused halving: 15x). At 2x, scans with strong noise stopped with
  // 40-45% of the input at the root (a halving of 2.3x refused).
  if (s.root && !s.report.levels.empty()) task.rootDeviationLimit = 4 * s.report.levels.back().maxError;
  task.floorError = s.floorErrors.at(i);
  std::vector<Patch> floor;
  for (PatchId id : s.floors[i]) floor.push_back(s.store->patch(id));
  task.mesh = s.store->assemble(floor);
  task.loadSeconds = secondsSince(start);
  return task;
}

void LevelBuilder::State::appendPatchOf(const EncodedPatch& e, uint32_t& mtPatch) {
  mtPatch = writer->appendPatch(e.payload.data(), e.payload.size(), e.triangles, e.vertices);
  if (!e.texture.empty()) {
    writer->appendTexture(mtPatch, e.texture.data(), e.texture.size(), e.textureWidth, e.textureHeight, e.imageBytes);
    report.textureBytes += e.texture.size();
    report.textureImageBytes += e.imageBytes;
  }
}

// Appends the region's node to the DAG (BMT 3.1, 4.1): the floor patches become the payloads of
// the arcs from the nodes that produced them; the error and the sphere are bounds over those
// predecessors. Returns the node's id.
uint32_t LevelBuilder::State::addNode(const RegionTask& task, const RegionResult& result) {
  const uint32_t node = uint32_t(nodes.size());
  const size_t patchesBefore = writer->patchCount();
  format::NodeRecord rec{};
  float predecessorError = 0, predecessorColorError = 0;
  Sphere sphere;
  for (int a = 0; a < 3; ++a) sphere.c[a] = result.sphere[a];
  sphere.r = result.sphere[3];
  if (result.encoded.size() != task.mesh.patches.size()) fail(output, "region result has the wrong number of floor patches");
  for (size_t k = 0; k < result.encoded.size(); ++k) {
    const EncodedPatch& e = result.encoded[k];
    if (e.storeId != task.mesh.patches[k]) fail(output, "region result names the wrong floor patch");
    uint32_t from = producer.at(e.storeId);
    assert(from < node && "a floor patch comes from an earlier node");
    uint32_t mtPatch;
    appendPatchOf(e, mtPatch);
    arcPatches[{from, node}].push_back(mtPatch);
    predecessorError = std::max(predecessorError, nodes[from].error);
    predecessorColorError = std::max(predecessorColorError, nodes[from].colorError);
    if (from != 0) enclose(sphere, spheres[from]);
    // The centre stays and the radius only grows from here, so containment now is containment in
    // the node's final sphere (BMT 5.1's nesting).
    assert((from == 0 || contains(sphere, spheres[from])) && "a node's sphere contains each predecessor's");
    producer.erase(e.storeId);
  }
  assert(writer->patchCount() == patchesBefore + task.mesh.patches.size() && "one MT patch per floor patch");
  (void)patchesBefore;
  // A real, monotone bound: the floor is within predecessorError of the input,
  // the new fragment within `deviation` of the floor.
  rec.error = std::nextafter(float(predecessorError + result.deviation), std::numeric_limits<float>::infinity());
  // Textured builds: the error also covers the new patches' texel size (region_texture.h), so a
  // cut at a screen tolerance shows texels no wider than it.
  if (result.textureError > rec.error)
    rec.error = std::nextafter(float(result.textureError), std::numeric_limits<float>::infinity());
  assert(rec.error >= predecessorError && "a node's error is at least each predecessor's");
  // The colour error accumulates the same way (0 throughout without colours).
  rec.colorError = result.colorDeviation > 0
                       ? std::nextafter(float(predecessorColorError + result.colorDeviation), std::numeric_limits<float>::infinity())
                       : predecessorColorError;
  assert(rec.colorError >= predecessorColorError && "a node's colour error is at least each predecessor's");
  for (int a = 0; a < 3; ++a) rec.center[a] = sphere.c[a];
  rec.radius = std::nextafter(float(sphere.r), std::numeric_limits<float>::infinity());
  for (int a = 0; a < 3; ++a) rec.coneAxis[a] = result.coneAxis[a];
  rec.coneCutoff = result.coneCutoff;
  rec.level = task.level;
  rec.region = task.region;
  nodes.push_back(rec);
  spheres.push_back(sphere);
  return node;
}

void LevelBuilder::commitRegion(size_t i, RegionTask task, RegionResult result, uint64_t moveBytes) {
  State& s = *s_;
  if (i != s.nextCommit) fail(s.output, "region " + std::to_string(i) + " committed out of order");
  auto start = Clock::now();
  const uint64_t in = task.mesh.triangleCount(), out = result.replacement.triangles.size() / 3;
  // A further root level (the whole model in one region, after the first level) that removes
  // less than a tenth of the triangles is not added: it would be a copy of the level below or
  // next to one (settleRoot keeps the region whole when every step is over its deviation limit),
  // with a larger error and nothing a cut could gain from. The store and the DAG stay as the
  // previous level left them, and endLevel ends the loop; the sink takes the previous level's
  // patches.
  if (s.root && s.builtLevels > 0 && s.regionIds.size() == 1 && !gains(in, out)) {
    s.levelDropped = true;
    s.doneTriangles += in;
    s.outTriangles += in;
    ++s.nextCommit;
    return;
  }
  // Commit in region order: ids, payload order and node numbers do not depend on which worker
  // finished first.
  const uint32_t node = s.addNode(task, result);
  const format::NodeRecord& rec = s.nodes.back();
  std::vector<PatchId> created = s.store->writeBack(task.mesh, result.replacement);
  for (PatchId id : created) s.producer[id] = node;
  s.lr.maxError = std::max(s.lr.maxError, double(rec.error));
  s.lr.simplifierRuns += result.simplifierRuns;
  s.doneTriangles += in;
  s.outTriangles += out;
  s.progress->update(s.doneTriangles);
  ++s.nextCommit;
  if (s.taskTimes)
    std::fprintf(s.taskTimes, "%u,%u,%zu,%" PRIu64 ",%" PRIu64 ",%.6f,%.6f,%.6f,%" PRIu64 ",%" PRIu64 ",%" PRIu64 "\n", task.level,
                 task.region, task.mesh.patches.size(), in, out, task.loadSeconds, result.seconds, secondsSince(start),
                 taskBytes(task.mesh), resultBytes(result), moveBytes);
  // Temporary disk peaks inside a level too (new patches appended before the old ones' space is
  // reclaimed): sample it now and then.
  if (s.nextCommit % 32 == 0)
    s.report.peakTempBytes = std::max(s.report.peakTempBytes, treeBytes(s.work) + treeBytes(s.tempPath));
  if (s.killAfterRegions >= 0 && ++s.committedRegions > s.killAfterRegions) std::raise(SIGKILL);  // test hook
  if (s.regionPauseMs > 0) ::usleep(useconds_t(s.regionPauseMs) * 1000);                            // test hook
}

void LevelBuilder::endLevel() {
  State& s = *s_;
  if (s.nextCommit != s.regionIds.size()) fail(s.output, "level ended before all regions were committed");
  s.progress->finish(s.doneTriangles);
  if (s.levelDropped) {  // commitRegion refused the level: the previous one is the root
    s.finished = true;
    return;
  }
  s.lr.trianglesOut = s.outTriangles;
  s.lr.seconds = secondsSince(s.levelStart);
  const CpuSeconds cpu = processCpuSeconds();
  s.lr.userSeconds = cpu.user - s.levelCpu0.user;
  s.lr.sysSeconds = cpu.sys - s.levelCpu0.sys;
  s.report.levels.push_back(s.lr);
  s.liveTriangles = s.outTriangles;
  ++s.builtLevels;
  // A root level simplifies the whole model to 1/k while that keeps more than rootTriangles, then
  // to rootTriangles / 2 (processRegion's rootTarget; settleRoot halves it where that step fails):
  // another root level follows while the root is over rootTriangles and each level gains (a
  // further root level that does not gain is not even added: commitRegion).
  if (s.outTriangles <= s.ctx.rootTriangles || !gains(s.lr.trianglesIn, s.outTriangles))
    s.finished = true;
  // The level is durable: the checkpoint a resumed build restarts from.
  s.writeCheckpoint();
  if (s.taskTimes) std::fflush(s.taskTimes);
  if (s.killAfterLevel >= 0 && long(s.builtLevels) >= s.killAfterLevel) std::raise(SIGKILL);  // test hook
}

BuildReport LevelBuilder::finish() {
  State& s = *s_;
  const uint32_t level = s.builtLevels;
  // 4. The sink: every remaining patch is on an arc from its producer to the sink (BMT 3.1: "all
  // the leaf nodes ... are connected through an arc to a dummy sink node").
  const uint32_t sink = uint32_t(s.nodes.size());
  {
    std::vector<PatchId> ids = s.store->patchIds();
    std::vector<Patch> top;
    for (PatchId id : ids) top.push_back(s.store->patch(id));
    PatchCodecOptions codec = s.ctx.codec;
    codec.simplified = isSimplifiedOutput(level);
    std::vector<EncodedPatch> encoded = encodePatches(top, s.ctx.grid, codec);
    if (s.texture) encodeTextures(top, floorAtlases(top, *s.texture), s.ctx.grid, *s.texture, codec.codec, encoded);
    for (const EncodedPatch& e : encoded) {
      uint32_t mtPatch;
      s.appendPatchOf(e, mtPatch);
      s.arcPatches[{s.producer.at(e.storeId), sink}].push_back(mtPatch);
    }
    format::NodeRecord rec{};
    Sphere all;
    for (int a = 0; a < 3; ++a) all.c[a] = 0.5 * (s.header.boundsMin[a] + s.header.boundsMax[a]);
    for (size_t n = 1; n < s.nodes.size(); ++n) enclose(all, s.spheres[n]);
    for (int a = 0; a < 3; ++a) rec.center[a] = all.c[a];
    rec.radius = std::nextafter(float(all.r), std::numeric_limits<float>::infinity());
    rec.error = std::numeric_limits<float>::infinity();
    rec.colorError = s.header.vertexFlags & format::kHasColors ? std::numeric_limits<float>::infinity() : 0.0f;
    rec.coneCutoff = -1;
    rec.coneAxis[2] = 1;
    rec.level = level + 1;
    s.nodes.push_back(rec);
  }
  // The arcs' patch lists are moved out of the map, which is freed as it goes, and what only the
  // levels needed goes too: the file's index is built next, beside whatever is still held (at a
  // billion triangles, 624 k arcs and 171 k nodes).
  std::vector<DagArc> arcs;
  arcs.reserve(s.arcPatches.size());
  for (auto it = s.arcPatches.begin(); it != s.arcPatches.end(); it = s.arcPatches.erase(it))
    arcs.push_back({it->first.first, it->first.second, std::move(it->second)});
  std::unordered_map<PatchId, uint32_t>().swap(s.producer);
  std::vector<Sphere>().swap(s.spheres);
  BuildReport& report = s.report;
  s.writer->header().levelCount = level + 1;
  report.nodes = s.nodes.size();
  report.arcs = arcs.size();
  report.patches = s.writer->patchCount();
  report.peakTempBytes = std::max(report.peakTempBytes, treeBytes(s.work) + treeBytes(s.tempPath));
#ifndef NDEBUG
  size_t onArcs = 0;
  for (const DagArc& a : arcs) onArcs += a.patches.size();
  assert(onArcs == s.writer->patchCount() && "every MT patch is on exactly one arc");
#endif
  if (!s.options.crs.empty()) s.writer->setMetadata(format::kMetadataCrs, s.options.crs);
  s.writer->finish(std::move(s.nodes), std::move(arcs));
  report.fileBytes = fs::file_size(s.output);
  s.store.reset();
  // The work directory is ours (created by a build, marked): it goes as a whole.
  std::error_code ec;
  fs::remove_all(s.work, ec);
  report.buildSeconds = secondsSince(s.buildStart);
  report.totalSeconds = secondsSince(s.t0);
  const CpuSeconds cpu = processCpuSeconds();
  report.cpuUserSeconds = cpu.user - s.cpu0.user;
  report.cpuSysSeconds = cpu.sys - s.cpu0.sys;
  report.peakRssBytes = peakRssBytes();
  const unsigned threads = s.options.threads ? s.options.threads : std::max(1u, std::thread::hardware_concurrency());
  report.extraJson += ",\n  \"memory_plan\": " + toJson(planMemory(s.options.memoryBytes, threads));
  // From the file's header (checked against its footer), not a whole reader: that would read the
  // index back (78 MB at a billion triangles) for one number.
  report.storedTriangles = MtFileReader::readHeader(s.output).storedTriangles;
  s.completed = true;
  return report;
}

}  // namespace mt
