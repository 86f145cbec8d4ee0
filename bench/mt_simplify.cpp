// Region simplification throughput (mtbuild/simplify_region.h): input triangles per second on a
// 20k-triangle scan-like region with ~5% locked vertices and holes, halved as in the level loop,
// for both simplifiers (simplifier:0 quadric, 1 meshopt), with and without the error measurement.
// For instruction counts of the simplifier alone: valgrind --tool=callgrind
// --toggle-collect='mt::quadricSimplify*' bench_mt_simplify --benchmark_filter='measure:0/simplifier:0'
// --benchmark_min_time=0 (one iteration).
#include <benchmark/benchmark.h>

#include "mtbuild/simplify_region.h"
#include "testing/scan_grid.h"

using namespace mt;

namespace {

struct Region {
  ScanGrid g;
  std::vector<uint8_t> locked;
};

Region makeRegion() {
  Region r;
  ScanGridOptions o;
  o.nx = o.ny = 101;
  o.holes = 3;
  o.holeRadius = 5;
  r.g = makeScanGrid(o);
  r.locked.assign(r.g.vertexCount(), 0);
  for (uint32_t v = 0; v < r.g.vertexCount(); ++v) {
    double x = r.g.positions[v * 3], y = r.g.positions[v * 3 + 1];
    if (x < 0.5 || y < 0.5 || x > 99.5 || y > 99.5 || v % 97 == 0) r.locked[v] = 1;
  }
  return r;
}

void BM_SimplifyRegion(benchmark::State& state) {
  static Region r = makeRegion();
  SimplifyRegionOptions opt;
  opt.targetTriangles = r.g.triangleCount() / 2;
  opt.measureError = state.range(0) != 0;
  opt.simplifier = state.range(1) ? RegionSimplifier::Meshopt : RegionSimplifier::Quadric;
  // The builder's grid for the quadric simplifier (1/11 of the mean edge, about 0.11 spacings
  // here), to which it snaps moved vertices.
  opt.gridStep = 0.11;
  double error = 0;
  for (auto _ : state) {
    SimplifiedRegion s = simplifyRegion(r.g.positions.data(), r.g.vertexCount(), r.g.triangles.data(),
                                        r.g.triangleCount(), r.locked.data(), opt);
    error = s.error;
    benchmark::DoNotOptimize(s.triangles.data());
  }
  state.counters["in_tris/s"] =
      benchmark::Counter(double(r.g.triangleCount()) * double(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["error"] = error;
}
BENCHMARK(BM_SimplifyRegion)
    ->ArgsProduct({{0, 1}, {0, 1}})
    ->ArgNames({"measure", "simplifier"})
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
