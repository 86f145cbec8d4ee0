// The sharp procedural colour field (see color_field.h).
#include "testing/color_field.h"

#include <algorithm>
#include <cmath>

namespace mt::testing {

namespace {

uint64_t mix(uint64_t x) {  // splitmix64's finalizer
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}
double unit(uint64_t h) { return double(h >> 11) * (1.0 / 9007199254740992.0); }

constexpr double kChecker = 4, kStripePeriod = 1.0 / 16, kSpotCell = 1.0 / 10;
constexpr double kSpotMin = 1.0 / 150, kSpotMax = 1.0 / 40;

}  // namespace

ColorField::ColorField(const double lo[3], const double hi[3], uint64_t seed) : seed_(seed) {
  double side = 0;
  for (int a = 0; a < 3; ++a) lo_[a] = lo[a], side = std::max(side, hi[a] - lo[a]);
  scale_ = side > 0 ? 1 / side : 1;
}

void ColorField::colorAt(const double p[3], uint8_t out[4], double shade) const {
  double u[3];
  for (int a = 0; a < 3; ++a) u[a] = (p[a] - lo_[a]) * scale_;
  // Spots first: the nearest lattice cells' spheres (a sphere stays within its cell's neighbours).
  int64_t c[3];
  for (int a = 0; a < 3; ++a) c[a] = int64_t(std::floor(u[a] / kSpotCell));
  double rgb[3] = {0, 0, 0};
  bool spot = false;
  double bestD = 1e300;
  for (int dz = -1; dz <= 1; ++dz)
    for (int dy = -1; dy <= 1; ++dy)
      for (int dx = -1; dx <= 1; ++dx) {
        const int64_t k[3] = {c[0] + dx, c[1] + dy, c[2] + dz};
        uint64_t h = mix(seed_ ^ mix(uint64_t(k[0]) * 73856093u ^ mix(uint64_t(k[1]) * 19349663u ^ uint64_t(k[2]) * 83492791u)));
        double centre[3], d2 = 0;
        for (int a = 0; a < 3; ++a) {
          h = mix(h);
          centre[a] = (double(k[a]) + 0.15 + 0.7 * unit(h)) * kSpotCell;
          d2 += (u[a] - centre[a]) * (u[a] - centre[a]);
        }
        h = mix(h);
        const double r = kSpotMin + (kSpotMax - kSpotMin) * unit(h);
        if (d2 <= r * r && d2 < bestD) {
          bestD = d2;
          spot = true;
          for (int a = 0; a < 3; ++a) {
            h = mix(h);
            rgb[a] = unit(h) < 0.5 ? 30 + 40 * unit(mix(h)) : 200 + 55 * unit(mix(h));  // vivid: each channel low or high
          }
        }
      }
  if (!spot) {
    static const double kHue[4][3] = {{205, 80, 60}, {70, 140, 210}, {225, 200, 90}, {90, 180, 110}};
    const int64_t cell = int64_t(std::floor(u[0] * kChecker)) + int64_t(std::floor(u[1] * kChecker)) * 3 +
                         int64_t(std::floor(u[2] * kChecker)) * 5;
    const double* hue = kHue[((cell % 4) + 4) % 4];
    // A tilted stripe direction (not along an axis, so stripes cross the scan's rows).
    const double s = (0.48 * u[0] + 0.64 * u[1] + 0.6 * u[2]) / kStripePeriod;
    const bool dark = s - std::floor(s) < 1.0 / 3;
    for (int a = 0; a < 3; ++a) rgb[a] = dark ? hue[a] * 0.35 : hue[a];
  }
  const double f = 0.85 + 0.15 * std::clamp(shade, 0.0, 1.0);
  for (int a = 0; a < 3; ++a) out[a] = uint8_t(std::lround(std::clamp(rgb[a] * f, 0.0, 255.0)));
  out[3] = 255;
}

}  // namespace mt::testing
