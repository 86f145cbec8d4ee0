// Patch codec size and speed (mtfile/patch_codec.h): bytes per triangle and encode/decode rates
// for both codecs, with and without normals, on ~2k-triangle scan-like patches: a regular grid
// (level 0 of a range scan) and the same surface simplified 2x and 4x (coarser levels).
// Grid step = 1/16 of the sample spacing (quantization error 0.054 spacing).
#include <benchmark/benchmark.h>

#include "mtfile/patch_codec.h"
#include "mtbuild/simplify_region.h"
#include "testing/scan_grid.h"

using namespace mt;

namespace {

struct Patch {
  std::vector<double> positions;
  std::vector<uint32_t> triangles;
};

// level 0: 33x33 grid (2048 triangles); level k: a (33*sqrt(2)^k)^2 grid simplified 2^k x.
Patch makePatch(int level, double jitter) {
  ScanGridOptions o;
  o.nx = o.ny = level == 0 ? 33 : level == 1 ? 47 : 65;
  o.jitter = jitter;
  o.seed = 7;
  ScanGrid g = makeScanGrid(o);
  if (level == 0) return {g.positions, g.triangles};
  SimplifyRegionOptions so;
  so.targetTriangles = g.triangleCount() >> level;
  so.measureError = false;
  SimplifiedRegion s = simplifyRegion(g.positions.data(), g.vertexCount(), g.triangles.data(), g.triangleCount(),
                                      nullptr, so);
  return {s.positions, s.triangles};
}

QuantizationGrid grid() {
  double lo[3] = {-10, -10, -100}, hi[3] = {1000, 1000, 100};
  return QuantizationGrid::fromBounds(lo, hi, 1.0 / 16);
}

// args: codec (1 meshopt, 2 draco), normals, level, jitter x10
void BM_Encode(benchmark::State& state) {
  Patch p = makePatch(int(state.range(2)), double(state.range(3)) / 10);
  QuantizationGrid g = grid();
  PatchCodecOptions opt;
  opt.codec = format::Codec(state.range(0));
  opt.normals = state.range(1) != 0;
  PatchInput in{p.positions.data(), p.positions.size() / 3, p.triangles.data(), p.triangles.size() / 3, nullptr, nullptr};
  size_t bytes = 0;
  for (auto _ : state) bytes = encodePatch(in, g, opt).size();
  double tris = double(in.triangleCount);
  state.counters["B/tri"] = double(bytes) / tris;
  state.counters["tris/s"] = benchmark::Counter(tris * double(state.iterations()), benchmark::Counter::kIsRate);
}

void BM_Decode(benchmark::State& state) {
  Patch p = makePatch(int(state.range(2)), double(state.range(3)) / 10);
  QuantizationGrid g = grid();
  PatchCodecOptions opt;
  opt.codec = format::Codec(state.range(0));
  opt.normals = state.range(1) != 0;
  PatchInput in{p.positions.data(), p.positions.size() / 3, p.triangles.data(), p.triangles.size() / 3, nullptr, nullptr};
  std::vector<uint8_t> payload = encodePatch(in, g, opt);
  for (auto _ : state) benchmark::DoNotOptimize(decodePatch(payload.data(), payload.size(), opt.codec, g).q.data());
  state.counters["tris/s"] =
      benchmark::Counter(double(in.triangleCount) * double(state.iterations()), benchmark::Counter::kIsRate);
}

void args(benchmark::internal::Benchmark* b) {
  b->ArgNames({"codec", "normals", "level", "jitter10"});
  for (int codec : {1, 2})
    for (int normals : {0, 1})
      for (int level : {0, 1, 2})
        for (int jitter : {0, 1}) b->Args({codec, normals, level, jitter});
}
BENCHMARK(BM_Encode)->Apply(args)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_Decode)->Apply(args)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
