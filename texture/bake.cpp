// Baking coarser atlases from a finer textured surface: see bake.h.
#include "texture/bake.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstring>

#include "base/error.h"
#include "texture/atlas_pack.h"
#include "texture/block_fill.h"
#include "texture/chart_rotate.h"
#include "texture/charts.h"
#include "texture/texel_raster.h"

namespace mt::tex {

namespace {

double dot3(const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

// The point of triangle abc nearest to p, as barycentric coordinates (Ericson, Real-Time
// Collision Detection, 5.1.5); returns the squared distance.
double nearestOnTriangle(const double* p, const double* a, const double* b, const double* c, double bary[3]) {
  const double ab[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, ac[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
  const double ap[3] = {p[0] - a[0], p[1] - a[1], p[2] - a[2]};
  const double d1 = dot3(ab, ap), d2 = dot3(ac, ap);
  auto dist = [&](double u, double v, double w) {
    bary[0] = u, bary[1] = v, bary[2] = w;
    double q[3];
    for (int k = 0; k < 3; ++k) q[k] = u * a[k] + v * b[k] + w * c[k] - p[k];
    return dot3(q, q);
  };
  if (d1 <= 0 && d2 <= 0) return dist(1, 0, 0);
  const double bp[3] = {p[0] - b[0], p[1] - b[1], p[2] - b[2]};
  const double d3 = dot3(ab, bp), d4 = dot3(ac, bp);
  if (d3 >= 0 && d4 <= d3) return dist(0, 1, 0);
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    return dist(1 - v, v, 0);
  }
  const double cp[3] = {p[0] - c[0], p[1] - c[1], p[2] - c[2]};
  const double d5 = dot3(ab, cp), d6 = dot3(ac, cp);
  if (d6 >= 0 && d5 <= d6) return dist(0, 0, 1);
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    return dist(1 - w, 0, w);
  }
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return dist(0, 1 - w, w);
  }
  const double denom = 1.0 / (va + vb + vc);
  const double v = vb * denom, w = vc * denom;
  return dist(1 - v - w, v, w);
}

}  // namespace

void sampleBilinear(const RgbImage& img, double u, double v, uint8_t rgb[3]) {
  const double x = u * img.width - 0.5, y = (1.0 - v) * img.height - 0.5;
  const int x0 = int(std::floor(x)), y0 = int(std::floor(y));
  const double fx = x - x0, fy = y - y0;
  auto at = [&](int xx, int yy) { return img.pixel(std::clamp(xx, 0, img.width - 1), std::clamp(yy, 0, img.height - 1)); };
  const uint8_t *p00 = at(x0, y0), *p10 = at(x0 + 1, y0), *p01 = at(x0, y0 + 1), *p11 = at(x0 + 1, y0 + 1);
  for (int c = 0; c < 3; ++c) {
    const double top = p00[c] + (p10[c] - p00[c]) * fx, bottom = p01[c] + (p11[c] - p01[c]) * fx;
    rgb[c] = uint8_t(std::clamp(std::lround(top + (bottom - top) * fy), 0l, 255l));
  }
}

SurfaceIndex::SurfaceIndex(const TexturedSurface& s) : s_(s) {
  const size_t nt = s.triangleCount;
  double hi[3];
  for (int a = 0; a < 3; ++a) lo_[a] = INFINITY, hi[a] = -INFINITY;
  double edges = 0;
  sphere_.resize(4 * nt);
  for (size_t t = 0; t < nt; ++t) {
    const double* v[3] = {&s.positions[3 * s.triangles[3 * t]], &s.positions[3 * s.triangles[3 * t + 1]], &s.positions[3 * s.triangles[3 * t + 2]]};
    double c[3];
    for (int a = 0; a < 3; ++a) {
      c[a] = (v[0][a] + v[1][a] + v[2][a]) / 3;
      for (int k = 0; k < 3; ++k) lo_[a] = std::min(lo_[a], v[k][a]), hi[a] = std::max(hi[a], v[k][a]);
    }
    double r = 0;
    for (int k = 0; k < 3; ++k) {
      const double d[3] = {v[k][0] - c[0], v[k][1] - c[1], v[k][2] - c[2]};
      r = std::max(r, std::sqrt(dot3(d, d)));
      const double e[3] = {v[k][0] - v[(k + 1) % 3][0], v[k][1] - v[(k + 1) % 3][1], v[k][2] - v[(k + 1) % 3][2]};
      edges += std::sqrt(dot3(e, e));
    }
    for (int a = 0; a < 3; ++a) sphere_[4 * t + size_t(a)] = float(c[a]);
    sphere_[4 * t + 3] = float(r * (1 + 1e-5) + 1e-12);
  }
  if (nt == 0) {
    cell_ = 1;
    dims_[0] = dims_[1] = dims_[2] = 1;
    start_.assign(2, 0);
    for (double& x : lo_) x = 0;
    return;
  }
  // Cells of about two mean edges, at most ~64 per axis... and at most 4 cells per triangle.
  cell_ = std::max(2 * edges / double(3 * nt), 1e-12);
  for (int a = 0; a < 3; ++a) cell_ = std::max(cell_, (hi[a] - lo_[a]) / 256);
  for (int a = 0; a < 3; ++a) dims_[a] = std::max(1, int(std::ceil((hi[a] - lo_[a]) / cell_)) + 1);
  const size_t cells = size_t(dims_[0]) * size_t(dims_[1]) * size_t(dims_[2]);
  start_.assign(cells + 1, 0);
  auto range = [&](size_t t, int lo[3], int hi2[3]) {
    for (int a = 0; a < 3; ++a) {
      const double c = sphere_[4 * t + size_t(a)], r = sphere_[4 * t + 3];
      lo[a] = std::clamp(int(std::floor((c - r - lo_[a]) / cell_)), 0, dims_[a] - 1);
      hi2[a] = std::clamp(int(std::floor((c + r - lo_[a]) / cell_)), 0, dims_[a] - 1);
    }
  };
  for (int pass = 0; pass < 2; ++pass) {
    std::vector<uint32_t> fill;
    if (pass == 1) {
      for (size_t i = 0; i < cells; ++i) start_[i + 1] += start_[i];
      items_.resize(start_[cells]);
      fill.assign(start_.begin(), start_.end() - 1);
    }
    for (size_t t = 0; t < nt; ++t) {
      int a[3], b[3];
      range(t, a, b);
      for (int z = a[2]; z <= b[2]; ++z)
        for (int y = a[1]; y <= b[1]; ++y)
          for (int x = a[0]; x <= b[0]; ++x) {
            const size_t cell = (size_t(z) * size_t(dims_[1]) + size_t(y)) * size_t(dims_[0]) + size_t(x);
            if (pass == 0) ++start_[cell + 1];
            else items_[fill[cell]++] = uint32_t(t);
          }
    }
  }
}

void SurfaceIndex::gather(const double lo[3], const double hi[3], std::vector<uint32_t>& out) const {
  out.clear();
  int a[3], b[3];
  for (int k = 0; k < 3; ++k) {
    a[k] = std::clamp(int(std::floor((lo[k] - lo_[k]) / cell_)), 0, dims_[k] - 1);
    b[k] = std::clamp(int(std::floor((hi[k] - lo_[k]) / cell_)), 0, dims_[k] - 1);
  }
  for (int z = a[2]; z <= b[2]; ++z)
    for (int y = a[1]; y <= b[1]; ++y)
      for (int x = a[0]; x <= b[0]; ++x) {
        const size_t cell = (size_t(z) * size_t(dims_[1]) + size_t(y)) * size_t(dims_[0]) + size_t(x);
        out.insert(out.end(), items_.begin() + start_[cell], items_.begin() + start_[cell + 1]);
      }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
}

bool SurfaceIndex::colorAt(const double p[3], const std::vector<uint32_t>& candidates, uint8_t rgb[3]) const {
  double best = INFINITY, bary[3], bestBary[3] = {1, 0, 0};
  uint32_t bestT = UINT32_MAX;
  for (uint32_t t : candidates) {
    const float* sp = &sphere_[4 * size_t(t)];
    const double d[3] = {p[0] - sp[0], p[1] - sp[1], p[2] - sp[2]};
    const double far = std::sqrt(dot3(d, d)) - sp[3];
    if (far > 0 && far * far >= best) continue;  // its sphere is farther than the best so far
    const double dd = nearestOnTriangle(p, &s_.positions[3 * s_.triangles[3 * size_t(t)]], &s_.positions[3 * s_.triangles[3 * size_t(t) + 1]],
                                        &s_.positions[3 * s_.triangles[3 * size_t(t) + 2]], bary);
    if (dd < best || (dd == best && t < bestT)) best = dd, bestT = t, std::memcpy(bestBary, bary, sizeof bary);
  }
  if (bestT == UINT32_MAX) return false;
  const float* uv = &s_.cornerUV[6 * size_t(bestT)];
  const double u = bestBary[0] * uv[0] + bestBary[1] * uv[2] + bestBary[2] * uv[4];
  const double v = bestBary[0] * uv[1] + bestBary[1] * uv[3] + bestBary[2] * uv[5];
  sampleBilinear(*s_.images[s_.image[bestT]], u, v, rgb);
  return true;
}

double meanTexelSize(const TexturedSurface& s) {
  double area = 0, texels = 0;
  for (size_t t = 0; t < s.triangleCount; ++t) {
    const double* a = &s.positions[3 * s.triangles[3 * t]];
    const double* b = &s.positions[3 * s.triangles[3 * t + 1]];
    const double* c = &s.positions[3 * s.triangles[3 * t + 2]];
    const double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    const double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
    area += 0.5 * std::sqrt(dot3(n, n));
    const RgbImage& img = *s.images[s.image[t]];
    const float* uv = &s.cornerUV[6 * t];
    const double du1 = (uv[2] - uv[0]) * img.width, dv1 = (uv[3] - uv[1]) * img.height;
    const double du2 = (uv[4] - uv[0]) * img.width, dv2 = (uv[5] - uv[1]) * img.height;
    texels += 0.5 * std::fabs(du1 * dv2 - du2 * dv1);
  }
  return texels > 0 ? std::sqrt(area / texels) : 0;
}

void fillGutter(RgbImage& image, std::vector<uint8_t>& filled, int passes) {
  const int w = image.width, h = image.height;
  assert(filled.size() == size_t(w) * size_t(h));
  for (int pass = 0; pass < passes; ++pass) {
    std::vector<uint8_t> next = filled;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        if (filled[size_t(y) * size_t(w) + size_t(x)]) continue;
        uint32_t acc[3] = {0, 0, 0}, n = 0;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int xx = x + dx, yy = y + dy;
            if (xx < 0 || yy < 0 || xx >= w || yy >= h || !filled[size_t(yy) * size_t(w) + size_t(xx)]) continue;
            const uint8_t* s = image.pixel(xx, yy);
            acc[0] += s[0], acc[1] += s[1], acc[2] += s[2], ++n;
          }
        if (!n) continue;
        uint8_t* d = image.pixel(x, y);
        for (int c = 0; c < 3; ++c) d[c] = uint8_t((acc[c] + n / 2) / n);
        next[size_t(y) * size_t(w) + size_t(x)] = 1;
      }
    filled.swap(next);
  }
}

BakeResult bakeAtlas(const double* positions, size_t nv, const uint32_t* tri, size_t nt, const SurfaceIndex& fine,
                     double texelSize, double margin, int maxSide, int padding, double fineTexelSize) {
  BakeResult out;
  Charts charts = makeCharts(positions, nv, tri, nt);
  rotateChartsToMinAreaBoxes(charts);  // tighter rectangles to pack
  out.charts = charts.count;
  // Chart boxes in world units.
  std::vector<double> box(4 * charts.count);
  for (uint32_t c = 0; c < charts.count; ++c) box[4 * c] = box[4 * c + 1] = INFINITY, box[4 * c + 2] = box[4 * c + 3] = -INFINITY;
  for (size_t t = 0; t < nt; ++t) {
    double* b = &box[4 * size_t(charts.chartOf[t])];
    for (int k = 0; k < 3; ++k) {
      const double x = charts.corner2D[6 * t + 2 * size_t(k)], y = charts.corner2D[6 * t + 2 * size_t(k) + 1];
      b[0] = std::min(b[0], x), b[1] = std::min(b[1], y), b[2] = std::max(b[2], x), b[3] = std::max(b[3], y);
    }
  }
  if (!(texelSize > 0)) texelSize = 1;
  std::vector<PackedRect> rects(charts.count);
  int aw = 0, ah = 0;
  for (int tries = 0;; ++tries) {
    for (uint32_t c = 0; c < charts.count; ++c) {
      rects[c].w = int(std::ceil((box[4 * c + 2] - box[4 * c]) / texelSize)) + 1 + 2 * padding;
      rects[c].h = int(std::ceil((box[4 * c + 3] - box[4 * c + 1]) / texelSize)) + 1 + 2 * padding;
    }
    if (packRects(rects, maxSide, aw, ah)) break;
    if (tries > 200) throw Error("bake: the charts do not fit a " + std::to_string(maxSide) + " atlas");
    texelSize *= 1.25;
  }
  out.texelSize = texelSize;
  // Samples per texel side: a texel wider than the finer surface's averages its texels under it
  // (a box filter) instead of point-sampling one of them, which would drop thin lines (aliasing).
  const int n = fineTexelSize > 0 ? std::clamp(int(std::lround(texelSize / fineTexelSize)), 1, 4) : 1;
  // Corner coordinates in atlas texels: chart origin + padding, y down.
  std::vector<double> corner(6 * nt);
  for (size_t t = 0; t < nt; ++t) {
    const uint32_t c = charts.chartOf[t];
    for (int k = 0; k < 3; ++k) {
      corner[6 * t + 2 * size_t(k)] = rects[c].x + padding + 0.5 + (charts.corner2D[6 * t + 2 * size_t(k)] - box[4 * c]) / texelSize;
      corner[6 * t + 2 * size_t(k) + 1] = rects[c].y + padding + 0.5 + (charts.corner2D[6 * t + 2 * size_t(k) + 1] - box[4 * c + 1]) / texelSize;
    }
  }
  out.image = RgbImage(aw, ah);
  std::vector<uint8_t> filled(size_t(aw) * size_t(ah), 0);
  std::vector<uint32_t> candidates;
  for (size_t t = 0; t < nt; ++t) {
    const double* P[3] = {&positions[3 * tri[3 * t]], &positions[3 * tri[3 * t + 1]], &positions[3 * tri[3 * t + 2]]};
    const double* C = &corner[6 * t];
    // The finer triangles near this one: its box grown by the margin and two texels.
    double lo[3], hi[3];
    const double grow = margin + 2 * texelSize;
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min({P[0][a], P[1][a], P[2][a]}) - grow;
      hi[a] = std::max({P[0][a], P[1][a], P[2][a]}) + grow;
    }
    fine.gather(lo, hi, candidates);
    const TexelTriangle texels(C);
    forEachTexel(texels, aw, ah, [&](int x, int y, const double*) {
      // The mean of n x n samples over the texel's square (the plane of the triangle extended
      // past its edges for the border texels' outer samples).
      uint32_t acc[3] = {0, 0, 0}, found = 0;
      for (int sy = 0; sy < n; ++sy)
        for (int sx = 0; sx < n; ++sx) {
          double q[3];
          texels.barycentric(x + (sx + 0.5) / n, y + (sy + 0.5) / n, q);
          double p[3];
          for (int a = 0; a < 3; ++a) p[a] = q[0] * P[0][a] + q[1] * P[1][a] + q[2] * P[2][a];
          uint8_t rgb[3];
          if (!fine.colorAt(p, candidates, rgb)) continue;
          for (int c = 0; c < 3; ++c) acc[c] += rgb[c];
          ++found;
        }
      if (!found) return;
      uint8_t* texel = out.image.pixel(x, y);
      for (int c = 0; c < 3; ++c) texel[c] = uint8_t((acc[c] + found / 2) / found);
      filled[size_t(y) * size_t(aw) + size_t(x)] = 1;
    });
  }
  fillGutter(out.image, filled, padding + 1);
  fillEmptyBlocks(out.image, filled);  // the texels between the charts, nearly free as JPEG
  out.cornerUV.resize(6 * nt);
  for (size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      out.cornerUV[6 * t + 2 * size_t(k)] = float(corner[6 * t + 2 * size_t(k)] / aw);
      out.cornerUV[6 * t + 2 * size_t(k) + 1] = float(1.0 - corner[6 * t + 2 * size_t(k) + 1] / ah);
    }
  return out;
}

}  // namespace mt::tex
