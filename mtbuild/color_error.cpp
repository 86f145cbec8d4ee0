// The measured colour deviation of a simplified region (see color_error.h).
#include "mtbuild/color_error.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <vector>

#include "mtbuild/surface_distance.h"

namespace mt {

namespace {

// The colour at the point of `grid`'s mesh nearest to p: its triangle's corner colours weighted by
// the nearest point's barycentrics.
void colorAt(const TriangleGrid& grid, const double* positions, const uint8_t* colors, const uint32_t* triangles,
             const double p[3], double out[4]) {
  const uint32_t t = grid.nearest(p);
  const uint32_t* f = triangles + size_t(t) * 3;
  double bary[3];
  nearestPointBarycentric(p, positions + size_t(f[0]) * 3, positions + size_t(f[1]) * 3, positions + size_t(f[2]) * 3, bary);
  for (int k = 0; k < 4; ++k)
    out[k] = bary[0] * colors[size_t(f[0]) * 4 + k] + bary[1] * colors[size_t(f[1]) * 4 + k] + bary[2] * colors[size_t(f[2]) * 4 + k];
}

double distance(const double a[4], const double b[4]) {
  double s = 0;
  for (int k = 0; k < 4; ++k) s += (a[k] - b[k]) * (a[k] - b[k]);
  return std::sqrt(s);
}

}  // namespace

double measureColorError(const ColorErrorInput& in) {
  if (!in.vertexCount || !in.triangleCount || !in.resultVertexCount || !in.resultTriangleCount) return 0;
  // Which input vertices a result vertex reproduces exactly (same position bit for bit, same colour).
  std::vector<uint8_t> same(in.vertexCount, 0);
  std::vector<uint8_t> resultSame(in.resultVertexCount, 0);
  for (size_t v = 0; v < in.resultVertexCount; ++v) {
    const uint32_t o = in.origin[v];
    if (std::memcmp(in.resultPositions + v * 3, in.positions + size_t(o) * 3, 3 * sizeof(double)) == 0 &&
        std::memcmp(in.resultColors + v * 4, in.colors + size_t(o) * 4, 4) == 0)
      same[o] = 1, resultSame[v] = 1;
  }
  std::vector<uint8_t> used(in.vertexCount, 0);
  for (size_t i = 0; i < in.triangleCount * 3; ++i) used[in.triangles[i]] = 1;
  // Input triangles as sorted corner triples, to know the result triangles that are input triangles.
  std::vector<std::array<uint32_t, 3>> inputFaces(in.triangleCount);
  for (size_t t = 0; t < in.triangleCount; ++t) {
    std::array<uint32_t, 3> f = {in.triangles[t * 3], in.triangles[t * 3 + 1], in.triangles[t * 3 + 2]};
    std::sort(f.begin(), f.end());
    inputFaces[t] = f;
  }
  std::sort(inputFaces.begin(), inputFaces.end());
  TriangleGrid inputGrid(in.positions, in.vertexCount, in.triangles, in.triangleCount);
  TriangleGrid resultGrid(in.resultPositions, in.resultVertexCount, in.resultTriangles, in.resultTriangleCount);
  double worst = 0, a[4], b[4];
  // (a) input -> result
  for (size_t v = 0; v < in.vertexCount; ++v) {
    if (!used[v] || same[v]) continue;
    colorAt(resultGrid, in.resultPositions, in.resultColors, in.resultTriangles, in.positions + v * 3, a);
    for (int k = 0; k < 4; ++k) b[k] = in.colors[v * 4 + k];
    worst = std::max(worst, distance(a, b));
  }
  // (b) result -> input: changed vertices, then centroids of new triangles
  for (size_t v = 0; v < in.resultVertexCount; ++v) {
    if (resultSame[v]) continue;
    colorAt(inputGrid, in.positions, in.colors, in.triangles, in.resultPositions + v * 3, a);
    for (int k = 0; k < 4; ++k) b[k] = in.resultColors[v * 4 + k];
    worst = std::max(worst, distance(a, b));
  }
  for (size_t t = 0; t < in.resultTriangleCount; ++t) {
    const uint32_t* f = in.resultTriangles + t * 3;
    if (resultSame[f[0]] && resultSame[f[1]] && resultSame[f[2]]) {
      std::array<uint32_t, 3> key = {in.origin[f[0]], in.origin[f[1]], in.origin[f[2]]};
      std::sort(key.begin(), key.end());
      if (std::binary_search(inputFaces.begin(), inputFaces.end(), key)) continue;
    }
    double c[3];
    for (int k = 0; k < 3; ++k)
      c[k] = (in.resultPositions[size_t(f[0]) * 3 + k] + in.resultPositions[size_t(f[1]) * 3 + k] +
              in.resultPositions[size_t(f[2]) * 3 + k]) / 3;
    colorAt(inputGrid, in.positions, in.colors, in.triangles, c, a);
    for (int k = 0; k < 4; ++k)
      b[k] = (double(in.resultColors[size_t(f[0]) * 4 + k]) + in.resultColors[size_t(f[1]) * 4 + k] +
              in.resultColors[size_t(f[2]) * 4 + k]) / 3;
    worst = std::max(worst, distance(a, b));
  }
  return worst;
}

}  // namespace mt
