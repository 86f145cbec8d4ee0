// The per-region work of the level loop (mtbuild/build.cpp), isolated on real regions: the first
// --regions regions of level 1 of a patch store made by `mtstore ingest` are read into memory once,
// then each phase is timed on one thread, so the figures do not depend on disk or on the other
// builds sharing the machine as much as a whole mtbuild run does:
//   encode   every floor patch with the file's codec (meshopt and draco, bytes per triangle too),
//   simplify simplifyRegion to half, locks as in the level loop (attempts = meshopt runs),
//   measure  the same with the error measurement on (measure - simplify = its cost).
// Usage: bench_mt_level STORE [--regions N] [--repeat R] [--step S] [--simplified]. Not a Google
// Benchmark: the inputs are a store on disk, and what matters is the split between phases.
// --simplified: the floor is a level's output, not the input's patches (a build stopped after level
// L keeps its store in OUT.work/store): encoded as the level loop encodes the floors of levels 2 and
// up (PatchCodecOptions::simplified: fan order, one payload coding).
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <string>
#include <vector>

#include "mtfile/patch_codec.h"
#include "mtbuild/simplify_region.h"
#include "patchstore/patch_store.h"
#include "vpartition/vpartition.h"

using namespace mt;
using Clock = std::chrono::steady_clock;

namespace {

double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

struct Region {
  std::vector<Patch> floor;
  LoadedMesh mesh;
};

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s STORE [--regions N] [--repeat R] [--step S] [--simplified]\n", argv[0]);
    return 2;
  }
  std::string dir = argv[1];
  size_t maxRegions = 64;
  int repeat = 1;
  double step = 0;
  bool simplified = false;
  for (int i = 2; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--simplified")) simplified = true;
    else if (i + 1 < argc && !std::strcmp(argv[i], "--regions")) maxRegions = std::strtoul(argv[++i], nullptr, 10);
    else if (i + 1 < argc && !std::strcmp(argv[i], "--repeat")) repeat = std::atoi(argv[++i]);
    else if (i + 1 < argc && !std::strcmp(argv[i], "--step")) step = std::atof(argv[++i]);
    else {
      std::fprintf(stderr, "bench_mt_level: unknown or incomplete option %s\n", argv[i]);
      return 2;
    }
  }
  try {
    auto store = PatchStore::open(dir);
    std::map<uint32_t, std::vector<PatchId>> regions;
    for (PatchId id : store->patchIds()) regions[PartitionSequence::crossLow(store->meta(id).cell)].push_back(id);
    std::vector<Region> rs;
    size_t triangles = 0, patches = 0;
    double edgeSum = 0;
    size_t edges = 0;
    for (auto& [r, ids] : regions) {
      if (rs.size() == maxRegions) break;
      Region reg;
      for (PatchId id : ids) reg.floor.push_back(store->patch(id));
      reg.mesh = store->assemble(reg.floor);
      triangles += reg.mesh.triangleCount();
      patches += reg.floor.size();
      const LoadedMesh& m = reg.mesh;
      for (size_t t = 0; t < m.triangles.size(); t += 3)
        for (int k = 0; k < 3; ++k) {
          const double *a = &m.positions[3 * m.triangles[t + k]], *b = &m.positions[3 * m.triangles[t + (k + 1) % 3]];
          edgeSum += std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]));
          ++edges;
        }
      rs.push_back(std::move(reg));
    }
    StoreInfo info = store->info();
    if (step <= 0) step = edgeSum / double(edges) / 8;  // build.cpp's choice (mean edge / 8)
    QuantizationGrid grid = QuantizationGrid::fromBounds(info.bounds.lo, info.bounds.hi, step);
    std::printf("%zu regions, %zu patches, %zu triangles, grid step %.4g (mean edge / %.2f)\n", rs.size(), patches,
                triangles, step, edgeSum / double(edges) / step);

    for (format::Codec codec : {format::Codec::Meshopt, format::Codec::Draco}) {
      PatchCodecOptions co;
      co.codec = codec;
      co.simplified = simplified;
      size_t bytes = 0;
      auto t = Clock::now();
      for (int rep = 0; rep < repeat; ++rep)
        for (const Region& reg : rs)
          for (const Patch& p : reg.floor) {
            PatchInput in;
            in.positions = p.positions.data();
            in.vertexCount = p.vertexCount();
            in.triangles = p.triangles.data();
            in.triangleCount = p.triangleCount();
            in.colors = p.colors.empty() ? nullptr : p.colors.data();
            if (rep == 0) bytes += encodePatch(in, grid, co).size();
            else encodePatch(in, grid, co);
          }
      double s = since(t) / repeat;
      std::printf("encode %-7s %7.3f s  %6.2f M tri/s  %.3f bytes/tri (payloads only)\n",
                  codec == format::Codec::Meshopt ? "meshopt" : "draco", s, triangles / s * 1e-6,
                  double(bytes) / double(triangles));
    }
    for (int measure = 0; measure < 2; ++measure) {
      SimplifyRegionOptions so;
      so.measureError = measure != 0;
      size_t out = 0, attempts = 0;
      double maxError = 0;
      auto t = Clock::now();
      for (int rep = 0; rep < repeat; ++rep)
        for (const Region& reg : rs) {
          so.targetTriangles = reg.mesh.triangleCount() / 2;
          SimplifiedRegion sr = simplifyRegion(reg.mesh, so);
          if (rep == 0) out += sr.triangleCount(), attempts += sr.attempts, maxError = std::max(maxError, sr.error);
        }
      double s = since(t) / repeat;
      std::printf("simplify%s %7.3f s  %6.2f M tri/s  out %.3f of in, %.2f meshopt runs/region, max error %.4g\n",
                  measure ? "+measure" : "        ", s, triangles / s * 1e-6, double(out) / double(triangles),
                  double(attempts) / double(rs.size()), maxError);
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_mt_level: %s\n", e.what());
    return 1;
  }
  return 0;
}
