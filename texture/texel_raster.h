// The texels a triangle covers in an atlas: the one rasterization rule that the atlas baker
// (bake.cpp) and the box-texture generator (testing/box_texture.cpp) both paint by, so a texel
// near a chart's edge is painted by both or by neither.
//
// A texel (x, y) belongs to the triangle when its centre (x + 0.5, y + 0.5) is inside it, or within
// half a texel of an edge (so a thin triangle still gets the texels it crosses, and the chart's
// border texels hold the surface's colour rather than the gutter's). Corners are in texels, y
// down (the atlas' rows top first).
#pragma once

#include <algorithm>
#include <cmath>

namespace mt::tex {

struct TexelTriangle {
  const double* c;  // 6: the corners (x, y) in texels
  double det;       // twice the signed area

  explicit TexelTriangle(const double* corners)
      : c(corners), det((c[2] - c[0]) * (c[5] - c[1]) - (c[4] - c[0]) * (c[3] - c[1])) {}

  // Too thin to hold a texel's centre (its barycentric coordinates would not be finite).
  bool degenerate() const { return std::fabs(det) < 1e-12; }

  // The barycentric coordinates of (px, py) (the plane of the triangle extended past its edges).
  void barycentric(double px, double py, double b[3]) const {
    b[1] = ((px - c[0]) * (c[5] - c[1]) - (c[4] - c[0]) * (py - c[1])) / det;
    b[2] = ((c[2] - c[0]) * (py - c[1]) - (px - c[0]) * (c[3] - c[1])) / det;
    b[0] = 1 - b[1] - b[2];
  }
};

// Calls f(x, y, b) for every texel of the triangle inside [0, width) x [0, height), row by row,
// b the barycentric coordinates of the texel's centre; nothing for a degenerate triangle.
template <class F>
void forEachTexel(const TexelTriangle& t, int width, int height, F&& f) {
  if (t.degenerate()) return;
  const double* C = t.c;
  const int x0 = std::max(0, int(std::floor(std::min({C[0], C[2], C[4]})))), x1 = std::min(width - 1, int(std::ceil(std::max({C[0], C[2], C[4]}))));
  const int y0 = std::max(0, int(std::floor(std::min({C[1], C[3], C[5]})))), y1 = std::min(height - 1, int(std::ceil(std::max({C[1], C[3], C[5]}))));
  // Half a texel measured in barycentric units (about: the triangle's size in texels).
  const double eps = 0.5 / std::max(1.0, std::sqrt(std::fabs(t.det)));
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x) {
      double b[3];
      t.barycentric(x + 0.5, y + 0.5, b);
      if (b[0] < -eps || b[1] < -eps || b[2] < -eps) continue;
      f(x, y, static_cast<const double*>(b));
    }
}

}  // namespace mt::tex
