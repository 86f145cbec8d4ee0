// V-partition throughput: seed computation (all streaming passes) and triangle -> V*0 cell
// assignment, on a synthetic 4 M-triangle scan-like surface (a bumpy torus with holes) held in
// memory, so the figures are CPU cost, not disk.
//   build/bin/bench_vpartition [--benchmark_filter=...]
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <numeric>
#include <unordered_map>

#include "testing/memory_centroids.h"
#include "testing/scan_generator.h"
#include "vpartition/vpartition.h"

namespace {

using mt::test::MemoryCentroids;

const MemoryCentroids& source() {
  static MemoryCentroids* src = [] {
    mt::test::TestMesh mesh = mt::test::holedTorus(2400, 900);  // ~4.2 M triangles
    return new MemoryCentroids(mesh, 1 << 16);
  }();
  return *src;
}

const mt::PartitionSequence& sequence(mt::PartitionKind kind) {
  static mt::PartitionSequence seqs[3];
  static bool built[3] = {false, false, false};
  int k = int(kind);
  if (!built[k]) {
    mt::VPartitionOptions o;
    o.kind = kind;
    seqs[k] = mt::PartitionSequence::build(source(), o);
    built[k] = true;
  }
  return seqs[k];
}

void BM_Build(benchmark::State& state) {
  mt::VPartitionOptions o;
  o.kind = mt::PartitionKind(state.range(0));
  o.patchTriangles = uint32_t(state.range(1));
  o.threads = uint32_t(state.range(2));
  const MemoryCentroids& src = source();
  mt::PartitionBuildStats stats;
  for (auto _ : state) {
    mt::PartitionSequence seq = mt::PartitionSequence::build(src, o);
    stats = seq.stats();
    benchmark::DoNotOptimize(seq.levels());
  }
  state.SetItemsProcessed(int64_t(state.iterations() * src.count()));
  state.counters["passes"] = stats.passes;
  state.counters["seedMiB"] = stats.seedBytes / 1048576.0;
  state.counters["tris/s/pass"] = benchmark::Counter(
      double(state.iterations()) * src.count() * stats.passes, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_Build)
    ->ArgNames({"kind", "patch", "threads"})
    ->Args({0, 1000, 1})
    ->Args({0, 1000, 2})
    ->Args({0, 250, 1})
    ->Args({1, 1000, 1})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// One crossKey (= two nearest-seed lookups, V0 and V1) per triangle, in stream order (what ingest
// does) or in a shuffled order (worst case for the per-thread candidate cache).
void BM_AssignV0Key(benchmark::State& state) {
  const MemoryCentroids& src = source();
  const mt::PartitionSequence& seq = sequence(mt::PartitionKind(state.range(0)));
  std::vector<uint32_t> order(src.count());
  std::iota(order.begin(), order.end(), 0u);
  if (state.range(1)) {
    mt::test::Lcg rng(5);
    for (size_t i = order.size(); i > 1; --i) std::swap(order[i - 1], order[size_t(rng.next() * i)]);
  }
  const float* c = src.data().data();
  for (auto _ : state) {
    uint64_t acc = 0;
    for (uint32_t t : order) acc += seq.crossKey(0, c + 4 * size_t(t));
    benchmark::DoNotOptimize(acc);
  }
  state.SetItemsProcessed(int64_t(state.iterations() * src.count()));
}
BENCHMARK(BM_AssignV0Key)
    ->ArgNames({"kind", "shuffled"})
    ->Args({0, 0})
    ->Args({0, 1})
    ->Args({1, 0})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// A single nearest-seed lookup (one level), stream order.
void BM_CellOfLevel0(benchmark::State& state) {
  const MemoryCentroids& src = source();
  const mt::PartitionSequence& seq = sequence(mt::PartitionKind::Irregular);
  const float* c = src.data().data();
  for (auto _ : state) {
    uint64_t acc = 0;
    for (size_t t = 0; t < src.count(); ++t) acc += seq.cellOf(0, c + 4 * t);
    benchmark::DoNotOptimize(acc);
  }
  state.SetItemsProcessed(int64_t(state.iterations() * src.count()));
}
BENCHMARK(BM_CellOfLevel0)->Unit(benchmark::kMillisecond)->UseRealTime();

// Patch-size survey on an mtgen mesh (1 M triangles, 3 components, 20 holes, varying density):
// what --patch-triangles does to cell shape and per-patch overhead (docs/vpartition.md).
//   crossMean   mean triangles per V*0 cell (patch);  v0MaxMean  max/mean triangles of V0 cells
//   sliver      share of patches under 1/8 of the mean (tiny patches: pure overhead)
//   bstar       mean backward star of V1 cells over V0; border  share of vertices on patch borders
//   levels      partitions in the sequence (DAG depth)
// VP_SURVEY_TABLE=1 also prints each run's per-level metrics table on stderr.
struct SurveyMesh {
  MemoryCentroids centroids;
  std::vector<uint32_t> triangles;  // global vertex ids
  uint64_t vertices = 0;
};
const SurveyMesh& surveyMesh() {
  static SurveyMesh* m = [] {
    auto* s = new SurveyMesh;
    mtgen::GeneratorOptions g;
    g.triangles = 1'000'000;
    g.components = 3;
    g.holes = 20;
    g.varyingDensity = true;
    mtgen::ScanGenerator gen(g);
    s->vertices = gen.vertexCount();
    for (uint64_t f = 0; f < gen.gridFaceCount(); ++f) {
      uint32_t v[3], corners[3][3];
      if (!gen.gridTriangle(f, v, corners)) continue;
      double p[3][3];
      for (int k = 0; k < 3; ++k) gen.position(corners[k][0], corners[k][1], corners[k][2], p[k]);
      float c[3];
      mt::triangleCentroid(p[0], p[1], p[2], c);
      double e1[3], e2[3];
      for (int k = 0; k < 3; ++k) { e1[k] = p[1][k] - p[0][k]; e2[k] = p[2][k] - p[0][k]; }
      double x = e1[1] * e2[2] - e1[2] * e2[1], y = e1[2] * e2[0] - e1[0] * e2[2],
             z = e1[0] * e2[1] - e1[1] * e2[0];
      s->centroids.add(c, float(0.5 * std::sqrt(x * x + y * y + z * z)));
      s->triangles.insert(s->triangles.end(), v, v + 3);
    }
    return s;
  }();
  return *m;
}

void BM_PatchSizeSurvey(benchmark::State& state) {
  const SurveyMesh& mesh = surveyMesh();
  mt::VPartitionOptions o;
  o.patchTriangles = uint32_t(state.range(0));
  mt::PartitionSequence seq;
  for (auto _ : state) seq = mt::PartitionSequence::build(mesh.centroids, o);
  mt::PartitionMetrics m = mt::computeMetrics(seq, mesh.centroids);
  if (std::getenv("VP_SURVEY_TABLE")) std::fprintf(stderr, "%s", mt::formatMetricsText(m).c_str());
  // Border vertices: used by triangles of more than one V*0 cell.
  std::vector<uint64_t> first(mesh.vertices, ~0ull);
  std::vector<uint8_t> border(mesh.vertices, 0);
  const float* c = mesh.centroids.data().data();
  for (size_t t = 0; t < mesh.triangles.size() / 3; ++t) {
    uint64_t key = seq.crossKey(0, c + 4 * t);
    for (int k = 0; k < 3; ++k) {
      uint32_t v = mesh.triangles[3 * t + k];
      if (first[v] == ~0ull) first[v] = key;
      else if (first[v] != key) border[v] = 1;
    }
  }
  uint64_t borderCount = 0, used = 0;
  for (size_t v = 0; v < first.size(); ++v) { used += first[v] != ~0ull; borderCount += border[v]; }
  // Slivers: recount the V*0 cells.
  std::unordered_map<uint64_t, uint32_t> cross;
  for (size_t t = 0; t < mesh.centroids.count(); ++t) ++cross[seq.crossKey(0, c + 4 * t)];
  uint64_t slivers = 0;
  double mean = m.levels[0].crossMean;
  for (const auto& [key, n] : cross) slivers += n < mean / 8;
  state.counters["patches"] = double(m.levels[0].crossCells);
  state.counters["crossMean"] = mean;
  state.counters["v0MaxMean"] = m.levels[0].maxTriangles / m.levels[0].meanTriangles;
  state.counters["sliver"] = double(slivers) / cross.size();
  state.counters["bstar"] = m.levels[0].backwardStarMean;
  state.counters["bstarMax"] = m.levels[0].backwardStarMax;
  state.counters["border"] = double(borderCount) / std::max<uint64_t>(1, used);
  state.counters["levels"] = seq.levels();
  state.counters["passes"] = seq.stats().passes;
}
BENCHMARK(BM_PatchSizeSurvey)
    ->ArgName("patch")
    ->Arg(250)->Arg(500)->Arg(1000)->Arg(2000)->Arg(4000)
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
