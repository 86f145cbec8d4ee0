// Box-mapped charts and a colour-field texture for any mesh: see box_texture.h.
#include "testing/box_texture.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstring>
#include <map>

#include "base/error.h"
#include "texture/atlas_pack.h"
#include "texture/bake.h"
#include "texture/texel_raster.h"

namespace mt::testing {

BoxTexture boxTexture(const double* pos, size_t nv, const uint32_t* tri, size_t nt, const ColorField& field,
                      const BoxTextureOptions& o) {
  BoxTexture out;
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (size_t v = 0; v < nv; ++v)
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], pos[3 * v + a]), hi[a] = std::max(hi[a], pos[3 * v + a]);
  const int B = std::max(1, o.blocks);
  // Each triangle's chart key and its corners' projected coordinates (world units).
  std::vector<uint32_t> key(nt);
  std::vector<double> proj(6 * nt);
  for (size_t t = 0; t < nt; ++t) {
    const double* P[3] = {&pos[3 * size_t(tri[3 * t])], &pos[3 * size_t(tri[3 * t + 1])], &pos[3 * size_t(tri[3 * t + 2])]};
    const double e1[3] = {P[1][0] - P[0][0], P[1][1] - P[0][1], P[1][2] - P[0][2]};
    const double e2[3] = {P[2][0] - P[0][0], P[2][1] - P[0][1], P[2][2] - P[0][2]};
    const double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
    int axis = 0;
    for (int a = 1; a < 3; ++a)
      if (std::fabs(n[a]) > std::fabs(n[axis])) axis = a;
    uint32_t block = 0;
    for (int a = 0; a < 3; ++a) {
      const double c = (P[0][a] + P[1][a] + P[2][a]) / 3, extent = hi[a] - lo[a];
      const int b = extent > 0 ? std::clamp(int((c - lo[a]) / extent * B), 0, B - 1) : 0;
      block = block * uint32_t(B) + uint32_t(b);
    }
    key[t] = block * 6 + uint32_t(2 * axis + (n[axis] < 0));
    // The two other axes, the first mirrored on the negative side (the chart is seen from outside).
    const int ua = (axis + 1) % 3, va = (axis + 2) % 3;
    for (int k = 0; k < 3; ++k) {
      proj[6 * t + 2 * size_t(k)] = n[axis] < 0 ? -P[k][ua] : P[k][ua];
      proj[6 * t + 2 * size_t(k) + 1] = P[k][va];
    }
  }
  // Charts: dense ids in key order, and their boxes.
  std::map<uint32_t, uint32_t> chartOf;
  for (size_t t = 0; t < nt; ++t) chartOf.emplace(key[t], 0);
  uint32_t next = 0;
  for (auto& [k, id] : chartOf) id = next++;
  out.charts = next;
  std::vector<double> box(4 * size_t(next));
  for (uint32_t c = 0; c < next; ++c) box[4 * c] = box[4 * c + 1] = INFINITY, box[4 * c + 2] = box[4 * c + 3] = -INFINITY;
  std::vector<uint32_t> chart(nt);
  double area = 0;
  for (size_t t = 0; t < nt; ++t) {
    chart[t] = chartOf[key[t]];
    double* b = &box[4 * size_t(chart[t])];
    for (int k = 0; k < 3; ++k) {
      const double x = proj[6 * t + 2 * size_t(k)], y = proj[6 * t + 2 * size_t(k) + 1];
      b[0] = std::min(b[0], x), b[1] = std::min(b[1], y), b[2] = std::max(b[2], x), b[3] = std::max(b[3], y);
    }
  }
  for (uint32_t c = 0; c < next; ++c) area += (box[4 * c + 2] - box[4 * c]) * (box[4 * c + 3] - box[4 * c + 1]);
  // The texel size: the density asked for, grown until the charts fit the page.
  double texel = std::sqrt(std::max(area, 1e-300) / std::max(1.0, o.texelsPerTriangle * double(nt)));
  std::vector<tex::PackedRect> rects(next);
  int W = 0, H = 0;
  for (int tries = 0;; ++tries) {
    for (uint32_t c = 0; c < next; ++c) {
      rects[c].w = int(std::ceil((box[4 * c + 2] - box[4 * c]) / texel)) + 1 + 2 * o.gutter;
      rects[c].h = int(std::ceil((box[4 * c + 3] - box[4 * c + 1]) / texel)) + 1 + 2 * o.gutter;
    }
    if (tex::packRects(rects, o.pageSide, W, H)) break;
    if (tries > 200) throw Error("box texture: the charts do not fit a " + std::to_string(o.pageSide) + " page");
    texel *= 1.1;
  }
  out.texelSize = texel;
  // Corners in page texels (y down), then the texels each triangle covers.
  std::vector<double> corner(6 * nt);
  for (size_t t = 0; t < nt; ++t) {
    const uint32_t c = chart[t];
    for (int k = 0; k < 3; ++k) {
      corner[6 * t + 2 * size_t(k)] = rects[c].x + o.gutter + 0.5 + (proj[6 * t + 2 * size_t(k)] - box[4 * c]) / texel;
      corner[6 * t + 2 * size_t(k) + 1] = rects[c].y + o.gutter + 0.5 + (proj[6 * t + 2 * size_t(k) + 1] - box[4 * c + 1]) / texel;
    }
  }
  out.page = tex::RgbImage(W, H);
  std::vector<uint8_t> filled(size_t(W) * size_t(H), 0);
  for (size_t t = 0; t < nt; ++t) {
    const double* P[3] = {&pos[3 * size_t(tri[3 * t])], &pos[3 * size_t(tri[3 * t + 1])], &pos[3 * size_t(tri[3 * t + 2])]};
    const double* C = &corner[6 * t];
    tex::forEachTexel(tex::TexelTriangle(C), W, H, [&](int x, int y, const double* b) {
      double p[3];
      for (int a = 0; a < 3; ++a) p[a] = b[0] * P[0][a] + b[1] * P[1][a] + b[2] * P[2][a];
      uint8_t rgba[4];
      field.colorAt(p, rgba);
      std::memcpy(out.page.pixel(x, y), rgba, 3);
      filled[size_t(y) * size_t(W) + size_t(x)] = 1;
    });
  }
  tex::fillGutter(out.page, filled, o.gutter + 1);
  out.cornerUV.resize(6 * nt);
  for (size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      const float u = float(corner[6 * t + 2 * size_t(k)] / W), v = float(1.0 - corner[6 * t + 2 * size_t(k) + 1] / H);
      assert(u >= 0 && u <= 1 && v >= 0 && v <= 1 && "a corner inside the page");
      out.cornerUV[6 * t + 2 * size_t(k)] = std::clamp(u, 0.0f, 1.0f);
      out.cornerUV[6 * t + 2 * size_t(k) + 1] = std::clamp(v, 0.0f, 1.0f);
    }
  return out;
}

}  // namespace mt::testing
