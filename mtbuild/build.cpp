// The level loop of the batched MT (BMT section 4, "the i-th simplification step"), the DAG it
// defines (sections 3.1, 4.1) and the MT file it streams (section 6). See build.h.
#include "mtbuild/build.h"

#include <tbb/global_control.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <map>
#include <memory>
#include <sstream>
#include <unordered_map>

#include "mtbuild/mt_file.h"
#include "mtbuild/patch_codec.h"
#include "mtbuild/simplify_region.h"
#include "patchstore/patch_store.h"
#include "patchstore/progress.h"

namespace mt {

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

struct Sphere {
  double c[3] = {0, 0, 0};
  double r = 0;
};

// Smallest-enough sphere around points: the box centre and the farthest point from it.
Sphere sphereOf(const std::vector<double>& positions) {
  Sphere s;
  if (positions.empty()) return s;
  double lo[3] = {positions[0], positions[1], positions[2]}, hi[3] = {lo[0], lo[1], lo[2]};
  for (size_t i = 0; i < positions.size(); i += 3)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], positions[i + a]);
      hi[a] = std::max(hi[a], positions[i + a]);
    }
  for (int a = 0; a < 3; ++a) s.c[a] = 0.5 * (lo[a] + hi[a]);
  double r2 = 0;
  for (size_t i = 0; i < positions.size(); i += 3) {
    double d2 = 0;
    for (int a = 0; a < 3; ++a) d2 += (positions[i + a] - s.c[a]) * (positions[i + a] - s.c[a]);
    r2 = std::max(r2, d2);
  }
  s.r = std::sqrt(r2);
  return s;
}

// Grows s (keeping its centre) to contain t: the nesting the renderer relies on (BMT 5.1: "each
// bounding sphere encloses the bounding sphere of all the arcs in the subgraph").
void enclose(Sphere& s, const Sphere& t) {
  double d2 = 0;
  for (int a = 0; a < 3; ++a) d2 += (t.c[a] - s.c[a]) * (t.c[a] - s.c[a]);
  s.r = std::max(s.r, std::sqrt(d2) + t.r);
}

// Normal cone of a fragment's triangles: the mean normal and cos of the widest deviation; -1 when
// the triangles face every way (no back-face culling possible).
void normalCone(const std::vector<double>& p, const std::vector<uint32_t>& t, float axis[3], float& cutoff) {
  std::vector<double> normals;
  double sum[3] = {0, 0, 0};
  for (size_t i = 0; i < t.size(); i += 3) {
    const double *a = &p[3 * t[i]], *b = &p[3 * t[i + 1]], *c = &p[3 * t[i + 2]];
    double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
    double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (int k = 0; k < 3; ++k) sum[k] += n[k];
    if (len > 0)
      for (int k = 0; k < 3; ++k) normals.push_back(n[k] / len);
  }
  double len = std::sqrt(sum[0] * sum[0] + sum[1] * sum[1] + sum[2] * sum[2]);
  if (len == 0 || normals.empty()) {
    axis[0] = 0, axis[1] = 0, axis[2] = 1;
    cutoff = -1;
    return;
  }
  double minDot = 1;
  for (size_t i = 0; i < normals.size(); i += 3)
    minDot = std::min(minDot, (normals[i] * sum[0] + normals[i + 1] * sum[1] + normals[i + 2] * sum[2]) / len);
  for (int k = 0; k < 3; ++k) axis[k] = float(sum[k] / len);
  // Conservative: widen a little for the float axis; a cone past 90 degrees culls nothing useful.
  cutoff = minDot <= 0.01 ? -1.0f : float(minDot - 1e-4);
}

// One floor patch, encoded for the MT file by a worker.
struct EncodedPatch {
  PatchId storeId = 0;
  std::vector<uint8_t> payload;
  uint32_t triangles = 0, vertices = 0;
};

struct RegionJob {
  uint32_t region = 0;
  std::vector<PatchId> floor;
  // Filled by the worker:
  std::vector<EncodedPatch> encoded;
  LoadedMesh loaded;
  ReplacementMesh replacement;
  double deviation = 0;
  Sphere sphere;
  float coneAxis[3] = {0, 0, 1};
  float coneCutoff = -1;
};

std::vector<EncodedPatch> encodePatches(const std::vector<Patch>& patches, const QuantizationGrid& grid,
                                        const PatchCodecOptions& codec) {
  std::vector<EncodedPatch> out;
  for (const Patch& p : patches) {
    PatchInput in;
    in.positions = p.positions.data();
    in.vertexCount = p.vertexCount();
    in.triangles = p.triangles.data();
    in.triangleCount = p.triangleCount();
    in.normals = p.normals.empty() ? nullptr : p.normals.data();
    in.colors = p.colors.empty() ? nullptr : p.colors.data();
    EncodedPatch e;
    e.storeId = p.id;
    e.payload = encodePatch(in, grid, codec);
    e.triangles = p.triangleCount();
    e.vertices = p.vertexCount();
    out.push_back(std::move(e));
  }
  return out;
}

bool isStoreDir(const std::string& path) { return fs::is_directory(path) && fs::exists(path + "/CURRENT"); }

// The quantization step: 1/8 of the mean edge length (estimated from a sample of patches): the
// quantization error (step * sqrt(3)/2) stays a fraction of an edge, and /16 measured 0.2 bytes
// per input triangle more (docs/mtbuild.md).
double chooseGridStep(const PatchStore& store) {
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
  return mean > 0 ? mean / 8 : 1e-6;
}

}  // namespace

std::string BuildReport::toJson() const {
  std::ostringstream s;
  s.precision(10);
  s << "{\n  \"input_triangles\": " << inputTriangles << ",\n  \"stored_triangles\": " << storedTriangles
    << ",\n  \"nodes\": " << nodes << ",\n  \"arcs\": " << arcs << ",\n  \"patches\": " << patches
    << ",\n  \"file_bytes\": " << fileBytes << ",\n  \"bytes_per_input_triangle\": "
    << (inputTriangles ? double(fileBytes) / double(inputTriangles) : 0) << ",\n  \"grid_step\": " << gridStep
    << ",\n  \"ingest_seconds\": " << ingestSeconds << ",\n  \"build_seconds\": " << buildSeconds
    << ",\n  \"total_seconds\": " << totalSeconds << ",\n  \"input_triangles_per_second\": "
    << (totalSeconds > 0 ? double(inputTriangles) / totalSeconds : 0) << ",\n  \"peak_rss_bytes\": " << peakRssBytes
    << ",\n  \"levels\": [";
  for (size_t i = 0; i < levels.size(); ++i) {
    const LevelReport& l = levels[i];
    s << (i ? "," : "") << "\n    {\"level\": " << l.level << ", \"regions\": " << l.regions << ", \"triangles_in\": "
      << l.trianglesIn << ", \"triangles_out\": " << l.trianglesOut << ", \"max_error\": " << l.maxError
      << ", \"seconds\": " << l.seconds << "}";
  }
  s << "\n  ]\n}\n";
  return s.str();
}

BuildReport buildMt(const std::string& input, const std::string& output, const BuildOptions& options) {
  auto t0 = Clock::now();
  BuildReport report;
  std::string work = options.workDir.empty() ? output + ".work" : options.workDir;
  std::string storeDir = work + "/store";
  std::error_code ec;
  // The MT writer's state is not checkpointed yet, so a store left by a killed build cannot be
  // continued from: a DAG restarted on it would credit later levels' patches to the source.
  if (options.resume && fs::exists(work) && options.progress)
    std::fprintf(stderr, "mtbuild: --resume cannot continue a build yet (no checkpoint format); rebuilding from the input\n");
  fs::remove_all(work, ec);
  fs::create_directories(work, ec);
  if (ec) fail(work, "cannot create the work directory: " + ec.message());

  std::unique_ptr<tbb::global_control> threadLimit;
  if (options.threads > 0)
    threadLimit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, options.threads);

  // 1. The level-0 patch store, partitioned by V*0 (BMT 4: "the mesh partitioned according to V*0").
  if (!fs::exists(storeDir + "/CURRENT")) {
    // Nothing to resume from yet: a failure here leaves no work directory behind.
    try {
      fs::remove_all(storeDir, ec);
      if (isStoreDir(input)) {
        fs::copy(input, storeDir, fs::copy_options::recursive, ec);
        if (ec) fail(input, "cannot copy the store into " + work + ": " + ec.message());
      } else {
        VPartitionOptions vp;
        vp.kind = options.partition;
        vp.patchTriangles = options.patchTriangles;
        VPartitionAssigner assigner(vp);
        IngestOptions io;
        io.memoryBytes = options.memoryBytes;
        io.progress = options.progress;
        PatchStore::ingest(input, storeDir, assigner, io);
      }
    } catch (...) {
      fs::remove_all(work, ec);
      throw;
    }
  }
  report.ingestSeconds = secondsSince(t0);
  auto buildStart = Clock::now();
  auto store = PatchStore::open(storeDir);
  store->setAutoCommit(false);
  PartitionSequence sequence;
  if (!loadStoreSequence(*store, sequence))
    fail(input, "the patch store was not made with a V-partition (ingest it with --partition irregular or regular)");
  const uint32_t L = sequence.levels();
  StoreInfo info = store->info();
  report.inputTriangles = info.triangles;
  const uint32_t patchTriangles = options.patchTriangles ? options.patchTriangles : kDefaultPatchTriangles;
  const uint64_t rootTriangles = options.rootTriangles ? options.rootTriangles : 2ull * patchTriangles;

  // 2. The global quantization grid (mt_format.h): shared vertices quantize identically.
  QuantizationGrid grid = QuantizationGrid::fromBounds(info.bounds.lo, info.bounds.hi, chooseGridStep(*store));
  report.gridStep = grid.step;
  const double qError = grid.maxError();
  PatchCodecOptions codec;
  codec.codec = options.codec;
  codec.normals = options.normals;

  format::FileHeader header{};
  header.codec = uint32_t(options.codec);
  header.vertexFlags = (options.normals ? format::kHasNormals : 0) | (info.layout.colors ? format::kHasColors : 0);
  header.payloadAlignment = format::kDefaultPayloadAlignment;
  header.inputTriangles = info.triangles;
  header.inputVertices = info.vertices;  // (copies of shared vertices counted once per patch)
  for (int a = 0; a < 3; ++a) {
    header.boundsMin[a] = info.bounds.lo[a];
    header.boundsMax[a] = info.bounds.hi[a];
    header.gridOrigin[a] = grid.origin[a];
  }
  header.gridStep = grid.step;
  header.quantizationError = qError;
  header.gridBits = grid.bits;
  MtFileWriter writer(output, header);

  // 3. The DAG. Node 0 is the source: the full-resolution fragment (BMT 3.1).
  std::vector<format::NodeRecord> nodes(1);
  std::vector<Sphere> spheres(1);
  {
    format::NodeRecord& source = nodes[0];
    for (int a = 0; a < 3; ++a) source.center[a] = 0.5 * (info.bounds.lo[a] + info.bounds.hi[a]);
    source.radius = 0;  // never refined past, so its sphere is not part of the nesting
    source.error = float(qError);
    source.coneCutoff = -1;
    source.coneAxis[2] = 1;
    source.level = 0;
  }
  std::map<std::pair<uint32_t, uint32_t>, std::vector<uint32_t>> arcPatches;  // (from, to) -> MT patch ids
  std::unordered_map<PatchId, uint32_t> producer;
  for (PatchId id : store->patchIds()) producer[id] = 0;

  uint64_t liveTriangles = info.triangles;
  uint32_t level = 0;
  for (;; ++level) {
    // Regions of V(level+1): patches grouped by the low half of their V*level key.
    std::map<uint32_t, std::vector<PatchId>> regions;
    for (PatchId id : store->patchIds()) regions[PartitionSequence::crossLow(store->meta(id).cell)].push_back(id);
    const bool root = level + 1 >= L;  // the last partition level: one region, everything
    if (liveTriangles <= rootTriangles && level > 0) break;
    auto levelStart = Clock::now();
    LevelReport lr;
    lr.level = level + 1;
    lr.regions = uint32_t(regions.size());
    lr.trianglesIn = liveTriangles;
    std::vector<RegionJob*> order;
    std::vector<std::unique_ptr<RegionJob>> jobs;
    for (auto& [r, ids] : regions) {
      auto job = std::make_unique<RegionJob>();
      job->region = r;
      job->floor = ids;
      order.push_back(job.get());
      jobs.push_back(std::move(job));
    }
    Progress progress(options.progress, "mtbuild: level " + std::to_string(level + 1) + "/" + std::to_string(L), liveTriangles);
    uint64_t doneTriangles = 0, outTriangles = 0;
    size_t next = 0;
    const size_t tokens = 2 * size_t(options.threads ? options.threads : tbb::this_task_arena::max_concurrency());
    tbb::parallel_pipeline(
        tokens,
        tbb::make_filter<void, RegionJob*>(tbb::filter_mode::serial_in_order,
                                           [&](tbb::flow_control& fc) -> RegionJob* {
                                             if (next == order.size()) {
                                               fc.stop();
                                               return nullptr;
                                             }
                                             return order[next++];
                                           }) &
            tbb::make_filter<RegionJob*, RegionJob*>(
                tbb::filter_mode::parallel,
                [&](RegionJob* job) {
                  // Load the floor, simplify with the region's border locked, split by V*(level+1).
                  // Each floor patch is read once: encoded for the file, then assembled.
                  std::vector<Patch> floor;
                  for (PatchId id : job->floor) floor.push_back(store->patch(id));
                  job->encoded = encodePatches(floor, grid, codec);
                  job->loaded = store->assemble(floor);
                  const LoadedMesh& lm = job->loaded;
                  SimplifyRegionOptions so;
                  so.targetTriangles = root ? std::min<size_t>(lm.triangleCount() / 2, rootTriangles / 2) : lm.triangleCount() / 2;
                  SimplifiedRegion sr = simplifyRegion(lm, so);
                  job->deviation = sr.error;
                  ReplacementMesh& rep = job->replacement;
                  rep.level = level + 1;
                  rep.origin = sr.origin;
                  rep.triangles = sr.triangles;
                  for (uint32_t o : sr.origin) {
                    if (!lm.normals.empty()) rep.normals.insert(rep.normals.end(), &lm.normals[3 * o], &lm.normals[3 * o] + 3);
                    if (!lm.colors.empty()) rep.colors.insert(rep.colors.end(), &lm.colors[4 * o], &lm.colors[4 * o] + 4);
                  }
                  rep.triangleCell.resize(sr.triangleCount());
                  for (uint32_t t = 0; t < sr.triangleCount(); ++t) {
                    uint64_t low = 0;
                    if (level + 2 < L) {
                      float c[3];
                      triangleCentroid(&sr.positions[3 * sr.triangles[3 * t]], &sr.positions[3 * sr.triangles[3 * t + 1]],
                                       &sr.positions[3 * sr.triangles[3 * t + 2]], c);
                      low = sequence.cellOf(level + 2, c);
                    }
                    // The triangle belongs to region R by construction (BMT 4: "this simplified
                    // mesh portion ... corresponds to a blue patch"), whatever its new centroid.
                    rep.triangleCell[t] = uint64_t(root ? 0 : job->region) << 32 | low;
                  }
                  job->sphere = sphereOf(sr.positions);
                  normalCone(sr.positions, sr.triangles, job->coneAxis, job->coneCutoff);
                  rep.positions = std::move(sr.positions);
                  return job;
                }) &
            tbb::make_filter<RegionJob*, void>(tbb::filter_mode::serial_in_order, [&](RegionJob* job) {
              // Commit in region order: ids, payload order and node numbers do not depend on
              // which worker finished first.
              const uint32_t node = uint32_t(nodes.size());
              format::NodeRecord rec{};
              float predecessorError = 0;
              Sphere sphere = job->sphere;
              for (const EncodedPatch& e : job->encoded) {
                uint32_t from = producer.at(e.storeId);
                uint32_t mtPatch = writer.appendPatch(e.payload.data(), e.payload.size(), e.triangles, e.vertices);
                arcPatches[{from, node}].push_back(mtPatch);
                predecessorError = std::max(predecessorError, nodes[from].error);
                if (from != 0) enclose(sphere, spheres[from]);
                producer.erase(e.storeId);
              }
              // A real, monotone bound (issue 4 item 2): the floor is within predecessorError of
              // the input, the new fragment within `deviation` of the floor.
              rec.error = std::nextafter(float(predecessorError + job->deviation), std::numeric_limits<float>::infinity());
              for (int a = 0; a < 3; ++a) rec.center[a] = sphere.c[a];
              rec.radius = std::nextafter(float(sphere.r), std::numeric_limits<float>::infinity());
              for (int a = 0; a < 3; ++a) rec.coneAxis[a] = job->coneAxis[a];
              rec.coneCutoff = job->coneCutoff;
              rec.level = level + 1;
              rec.region = job->region;
              nodes.push_back(rec);
              spheres.push_back(sphere);
              std::vector<PatchId> created = store->writeBack(job->loaded, job->replacement);
              for (PatchId id : created) producer[id] = node;
              lr.maxError = std::max(lr.maxError, double(rec.error));
              doneTriangles += job->loaded.triangleCount();
              outTriangles += job->replacement.triangles.size() / 3;
              progress.update(doneTriangles);
              // Free the job's memory now; the pipeline keeps the pointer only.
              *job = RegionJob();
            }));
    store->sync();  // the level is durable: the checkpoint a resumed build restarts from
    progress.finish(doneTriangles);
    lr.trianglesOut = outTriangles;
    lr.seconds = secondsSince(levelStart);
    report.levels.push_back(lr);
    liveTriangles = outTriangles;
    if (root || outTriangles <= rootTriangles || outTriangles * 10 > lr.trianglesIn * 9) {
      ++level;
      break;
    }
  }

  // 4. The sink: every remaining patch is on an arc from its producer to the sink (BMT 3.1:
  // "all the leaf nodes ... are connected through an arc to a dummy sink node").
  const uint32_t sink = uint32_t(nodes.size());
  {
    std::vector<PatchId> ids = store->patchIds();
    std::vector<Patch> top;
    for (PatchId id : ids) top.push_back(store->patch(id));
    std::vector<EncodedPatch> encoded = encodePatches(top, grid, codec);
    for (const EncodedPatch& e : encoded) {
      uint32_t mtPatch = writer.appendPatch(e.payload.data(), e.payload.size(), e.triangles, e.vertices);
      arcPatches[{producer.at(e.storeId), sink}].push_back(mtPatch);
    }
    format::NodeRecord rec{};
    Sphere all;
    for (int a = 0; a < 3; ++a) all.c[a] = 0.5 * (info.bounds.lo[a] + info.bounds.hi[a]);
    for (size_t n = 1; n < nodes.size(); ++n) enclose(all, spheres[n]);
    for (int a = 0; a < 3; ++a) rec.center[a] = all.c[a];
    rec.radius = std::nextafter(float(all.r), std::numeric_limits<float>::infinity());
    rec.error = std::numeric_limits<float>::infinity();
    rec.coneCutoff = -1;
    rec.coneAxis[2] = 1;
    rec.level = level + 1;
    nodes.push_back(rec);
  }
  std::vector<DagArc> arcs;
  for (auto& [key, patches] : arcPatches) arcs.push_back({key.first, key.second, patches});
  writer.header().levelCount = level + 1;
  report.nodes = nodes.size();
  report.arcs = arcs.size();
  report.patches = writer.patchCount();
  writer.finish(std::move(nodes), std::move(arcs));
  report.fileBytes = fs::file_size(output);
  store.reset();
  fs::remove_all(work, ec);
  report.buildSeconds = secondsSince(buildStart);
  report.totalSeconds = secondsSince(t0);
  report.peakRssBytes = peakRssBytes();
  auto reader = MtFileReader::open(output);
  report.storedTriangles = reader->header().storedTriangles;
  return report;
}

}  // namespace mt
