#include "testing/scan_grid.h"

#include <cmath>

namespace mt {

static uint64_t splitmix(uint64_t& s) {
  uint64_t z = (s += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}
static double uniform(uint64_t& s) { return double(splitmix(s) >> 11) * 0x1.0p-53; }  // [0,1)

ScanGrid makeScanGrid(const ScanGridOptions& o) {
  uint64_t rng = o.seed;
  ScanGrid g;
  uint32_t nx = o.nx < 2 ? 2 : o.nx, ny = o.ny < 2 ? 2 : o.ny;
  std::vector<double> pos(size_t(nx) * ny * 3);
  for (uint32_t y = 0; y < ny; ++y)
    for (uint32_t x = 0; x < nx; ++x) {
      double jx = (uniform(rng) - 0.5) * 2 * o.jitter, jy = (uniform(rng) - 0.5) * 2 * o.jitter;
      double fx = x + jx, fy = y + jy;
      double h = o.relief * (std::sin(fx * 0.11) * std::cos(fy * 0.07) + 0.5 * std::sin(fx * 0.031 + fy * 0.043));
      h += o.noise * (uniform(rng) - 0.5) * 2;
      double* p = &pos[(size_t(y) * nx + x) * 3];
      p[0] = fx * o.spacing + o.offset[0];
      p[1] = fy * o.spacing + o.offset[1];
      p[2] = h * o.spacing + o.offset[2];
    }
  std::vector<double> hc;  // hole centres (grid units)
  for (uint32_t i = 0; i < o.holes; ++i) {
    double m = o.holeRadius + 2;
    hc.push_back(m + uniform(rng) * (nx - 1 - 2 * m));
    hc.push_back(m + uniform(rng) * (ny - 1 - 2 * m));
  }
  std::vector<uint32_t> remap(size_t(nx) * ny, ~0u);
  auto use = [&](uint32_t v) {
    if (remap[v] == ~0u) {
      remap[v] = uint32_t(g.positions.size() / 3);
      g.positions.insert(g.positions.end(), &pos[size_t(v) * 3], &pos[size_t(v) * 3 + 3]);
    }
    return remap[v];
  };
  for (uint32_t y = 0; y + 1 < ny; ++y)
    for (uint32_t x = 0; x + 1 < nx; ++x) {
      bool inHole = false;
      for (size_t h = 0; h < hc.size(); h += 2) {
        double dx = x + 0.5 - hc[h], dy = y + 0.5 - hc[h + 1];
        if (dx * dx + dy * dy < o.holeRadius * o.holeRadius) inHole = true;
      }
      if (inHole) continue;
      uint32_t a = y * nx + x, b = a + 1, c = a + nx, d = c + 1;
      // alternate the diagonal so the triangulation has no preferred direction
      if ((x + y) & 1) {
        uint32_t t[6] = {a, b, d, a, d, c};
        for (uint32_t v : t) g.triangles.push_back(use(v));
      } else {
        uint32_t t[6] = {a, b, c, b, d, c};
        for (uint32_t v : t) g.triangles.push_back(use(v));
      }
    }
  return g;
}

}  // namespace mt
