// A small scan-like test surface: a height field on a jittered grid with smooth relief plus
// sensor-like noise, optionally with round holes (missing scan data). Deterministic. Used by the
// mtbuild tests and benchmarks (not by the builder itself).
#pragma once

#include <cstdint>
#include <vector>

namespace mt {

struct ScanGridOptions {
  uint32_t nx = 64, ny = 64;   // vertices per side; triangles = 2 (nx-1)(ny-1) minus holes
  double spacing = 1.0;        // grid spacing (object units)
  double offset[3] = {0, 0, 0};  // added to every position (e.g. to test far-from-origin data)
  double relief = 4.0;         // amplitude of the smooth relief, in spacings
  double noise = 0.05;         // amplitude of the per-vertex noise (normal direction), in spacings
  double jitter = 0.1;         // tangential jitter of the sample positions, in spacings
  uint32_t holes = 0;          // round holes of radius holeRadius spacings, placed inside
  double holeRadius = 4.0;
  uint64_t seed = 1;
};

struct ScanGrid {
  std::vector<double> positions;   // 3 per vertex
  std::vector<uint32_t> triangles; // 3 per triangle; vertices no triangle uses are removed
  uint32_t vertexCount() const { return uint32_t(positions.size() / 3); }
  uint32_t triangleCount() const { return uint32_t(triangles.size() / 3); }
};

ScanGrid makeScanGrid(const ScanGridOptions& options);

}  // namespace mt
