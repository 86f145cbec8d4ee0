// The finest level's atlases: see atlas_crop.h.
//
// 1. UV islands: triangles joined through corners that share a vertex, a material and the same
//    texture coordinates (union-find); triangles of a material without an image form one flat
//    block per colour.
// 2. Each island's texel rectangle in its image (corner coordinates to texel space, outward to
//    whole texels, plus the gutter), split while mostly empty; overlapping rectangles of one
//    image are merged when that stores fewer texels (fragmented charts of a few triangles).
// 3. The rectangles are packed (atlas_pack.h) and copied; scaled by 1/2 and packed again while
//    they do not fit.
#include "texture/atlas_crop.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <numeric>

#include "texture/atlas_pack.h"
#include "texture/block_fill.h"

namespace mt::tex {

namespace {

struct UnionFind {
  std::vector<uint32_t> parent;
  explicit UnionFind(size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
  uint32_t find(uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  }
  void unite(uint32_t a, uint32_t b) {
    a = find(a), b = find(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);
  }
};

struct Rect {
  uint32_t material;
  int x0, y0, x1, y1;  // texels [x0, x1) x [y0, y1) of the image, gutter included
  bool flat = false;
  uint8_t color[3] = {0, 0, 0};
};

// Two cut-outs of one image are stored as one when their box is no larger than the two apart
// (fragmented charts of a few triangles each mostly overlap), never when that would store more.
bool mergeable(const Rect& a, const Rect& b) {
  if (a.material != b.material || a.flat || b.flat || !(a.x0 < b.x1 && b.x0 < a.x1 && a.y0 < b.y1 && b.y0 < a.y1)) return false;
  auto area = [](int x0, int y0, int x1, int y1) { return double(x1 - x0) * double(y1 - y0); };
  return area(std::min(a.x0, b.x0), std::min(a.y0, b.y0), std::max(a.x1, b.x1), std::max(a.y1, b.y1)) <=
         area(a.x0, a.y0, a.x1, a.y1) + area(b.x0, b.y0, b.x1, b.y1);
}

}  // namespace

CropResult cropAtlas(const uint32_t* triangles, size_t nt, size_t nv, const float* cornerUV, const uint32_t* material,
                     const TexelSource& source, int maxSide, int padding) {
  CropResult out;
  auto textured = [&](size_t t) { return source.width(material[t]) > 0; };
  // 1. Islands.
  UnionFind uf(nt);
  {
    std::map<std::tuple<uint32_t, uint32_t, float, float>, uint32_t> corner;  // (vertex, material, u, v) -> triangle
    for (size_t t = 0; t < nt; ++t) {
      if (!textured(t)) continue;
      for (int c = 0; c < 3; ++c) {
        auto key = std::make_tuple(triangles[3 * t + size_t(c)], material[t], cornerUV[6 * t + 2 * size_t(c)], cornerUV[6 * t + 2 * size_t(c) + 1]);
        auto [it, fresh] = corner.emplace(key, uint32_t(t));
        if (!fresh) uf.unite(uint32_t(t), it->second);
      }
    }
  }
  (void)nv;
  // 2. Rectangles: per island (textured), split where its box is mostly empty; per flat colour.
  std::vector<Rect> rects;
  std::vector<uint32_t> rectOfTriangle(nt, UINT32_MAX);
  std::map<uint32_t, uint32_t> rectOfFlat;  // packed colour -> rect
  std::map<uint32_t, std::vector<uint32_t>> islands;  // root -> triangles, in order
  for (size_t t = 0; t < nt; ++t) {
    if (textured(t)) {
      islands[uf.find(uint32_t(t))].push_back(uint32_t(t));
      continue;
    }
    uint8_t rgb[3];
    source.flatColor(material[t], rgb);
    const uint32_t key = uint32_t(rgb[0]) << 16 | uint32_t(rgb[1]) << 8 | rgb[2];
    auto it = rectOfFlat.find(key);
    if (it == rectOfFlat.end()) {
      rects.push_back(Rect{material[t], 0, 0, 4, 4, true, {rgb[0], rgb[1], rgb[2]}});
      it = rectOfFlat.emplace(key, uint32_t(rects.size() - 1)).first;
    }
    rectOfTriangle[t] = it->second;
  }
  // A triangle's corners in texel space (y down, as the image rows).
  auto texelCorner = [&](uint32_t t, int c, double& x, double& y) {
    const int W = source.width(material[t]), H = source.height(material[t]);
    x = double(cornerUV[6 * t + 2 * size_t(c)]) * W;
    y = (1.0 - double(cornerUV[6 * t + 2 * size_t(c) + 1])) * H;
  };
  // Places the triangles of one island (or of a part of one): its padded box is cut out, unless
  // that box is mostly texels no triangle of it shows (a patch is an irregular cell of the
  // partition, its part of a chart an irregular blob): then it is split in two at the median
  // centroid along the box's longer side, each half cut out on its own (the texels along the
  // cut are stored twice; their gutters overlap).
  std::vector<uint32_t> scratch;
  std::function<void(std::vector<uint32_t>&)> place = [&](std::vector<uint32_t>& tris) {
    int x0 = INT32_MAX, y0 = INT32_MAX, x1 = INT32_MIN, y1 = INT32_MIN;
    double covered = 0;
    const uint32_t m = material[tris[0]];
    const int W = source.width(m), H = source.height(m);
    for (uint32_t t : tris) {
      double x[3], y[3];
      for (int c = 0; c < 3; ++c) {
        texelCorner(t, c, x[c], y[c]);
        x0 = std::min(x0, int(std::floor(x[c])) - padding), x1 = std::max(x1, int(std::ceil(x[c])) + padding);
        y0 = std::min(y0, int(std::floor(y[c])) - padding), y1 = std::max(y1, int(std::ceil(y[c])) + padding);
      }
      covered += 0.5 * std::fabs((x[1] - x[0]) * (y[2] - y[0]) - (x[2] - x[0]) * (y[1] - y[0]));
    }
    x0 = std::max(x0, -padding), y0 = std::max(y0, -padding);
    x1 = std::min(x1, W + padding), y1 = std::min(y1, H + padding);
    const double box = double(x1 - x0) * double(y1 - y0);
    const double needed = covered + 2.0 * padding * double((x1 - x0) + (y1 - y0));
    if (tris.size() >= 16 && box > 1.35 * needed) {
      const bool alongX = x1 - x0 >= y1 - y0;
      std::vector<std::pair<double, uint32_t>> keyed;
      for (uint32_t t : tris) {
        double c = 0, x, y;
        for (int k = 0; k < 3; ++k) texelCorner(t, k, x, y), c += alongX ? x : y;
        keyed.push_back({c, t});
      }
      std::stable_sort(keyed.begin(), keyed.end());
      std::vector<uint32_t> a, b;
      for (size_t i = 0; i < keyed.size(); ++i) (i < keyed.size() / 2 ? a : b).push_back(keyed[i].second);
      std::sort(a.begin(), a.end());
      std::sort(b.begin(), b.end());
      place(a);
      place(b);
      return;
    }
    rects.push_back({m, x0, y0, x1, y1});
    for (uint32_t t : tris) rectOfTriangle[t] = uint32_t(rects.size() - 1);
  };
  for (auto& [root, tris] : islands) place(tris);
  (void)scratch;
  // Overlapping rectangles of one image merged (to a fixed point), so no texel is stored twice.
  std::vector<uint32_t> alias(rects.size());
  std::iota(alias.begin(), alias.end(), 0u);
  for (bool changed = true; changed;) {
    changed = false;
    for (size_t a = 0; a < rects.size(); ++a) {
      if (alias[a] != a) continue;
      for (size_t b = a + 1; b < rects.size(); ++b) {
        if (alias[b] != b || !mergeable(rects[a], rects[b])) continue;
        Rect& r = rects[a];
        r.x0 = std::min(r.x0, rects[b].x0), r.y0 = std::min(r.y0, rects[b].y0);
        r.x1 = std::max(r.x1, rects[b].x1), r.y1 = std::max(r.y1, rects[b].y1);
        alias[b] = uint32_t(a);
        changed = true;
      }
    }
  }
  auto root = [&](uint32_t r) {
    while (alias[r] != r) r = alias[r];
    return r;
  };
  std::vector<uint32_t> live;  // rects that remain, in order
  std::vector<uint32_t> packedOf(rects.size(), UINT32_MAX);
  for (uint32_t r = 0; r < rects.size(); ++r)
    if (alias[r] == r) packedOf[r] = uint32_t(live.size()), live.push_back(r);
  for (uint32_t r : live)
    if (!rects[r].flat) out.inputTexels += uint64_t(rects[r].x1 - rects[r].x0) * uint64_t(rects[r].y1 - rects[r].y0);
  // 3. Pack, scaling by 1/2 until it fits.
  std::vector<PackedRect> packed(live.size());
  int scale = 1, aw = 0, ah = 0;
  for (;; scale *= 2) {
    for (size_t i = 0; i < live.size(); ++i) {
      const Rect& r = rects[live[i]];
      packed[i].w = r.flat ? 4 : (r.x1 - r.x0 + scale - 1) / scale;
      packed[i].h = r.flat ? 4 : (r.y1 - r.y0 + scale - 1) / scale;
    }
    if (packRects(packed, maxSide, aw, ah)) break;
    if (scale >= 1024) throw Error("atlas: the texture cut-outs do not fit a " + std::to_string(maxSide) + " atlas");
  }
  out.scale = scale;
  out.image = RgbImage(aw, ah);
  std::vector<uint8_t> filled(size_t(aw) * size_t(ah), 0);  // the texels the cut-outs cover
  std::vector<uint8_t> buf;
  for (size_t i = 0; i < live.size(); ++i) {
    const Rect& r = rects[live[i]];
    const PackedRect& p = packed[i];
    if (r.flat) {
      for (int y = 0; y < 4; ++y)
        for (int x = 0; x < 4; ++x) std::copy_n(r.color, 3, out.image.pixel(p.x + x, p.y + y)), filled[size_t(p.y + y) * size_t(aw) + size_t(p.x + x)] = 1;
      continue;
    }
    const int w = r.x1 - r.x0, h = r.y1 - r.y0;
    buf.resize(size_t(w) * size_t(h) * 3);
    source.copyRect(r.material, r.x0, r.y0, w, h, buf.data());
    for (int y = 0; y < p.h; ++y)
      for (int x = 0; x < p.w; ++x) {
        uint32_t acc[3] = {0, 0, 0}, n = 0;
        for (int dy = 0; dy < scale; ++dy)
          for (int dx = 0; dx < scale; ++dx) {
            const int sx = x * scale + dx, sy = y * scale + dy;
            if (sx >= w || sy >= h) continue;
            const uint8_t* s = &buf[(size_t(sy) * size_t(w) + size_t(sx)) * 3];
            acc[0] += s[0], acc[1] += s[1], acc[2] += s[2], ++n;
          }
        uint8_t* d = out.image.pixel(p.x + x, p.y + y);
        for (int c = 0; c < 3; ++c) d[c] = uint8_t((acc[c] + n / 2) / n);
        filled[size_t(p.y + y) * size_t(aw) + size_t(p.x + x)] = 1;
      }
  }
  // The texels between the cut-outs: flat per JPEG block, nearly free (block_fill.h).
  fillEmptyBlocks(out.image, filled);
  // Corner coordinates over the atlas.
  out.cornerUV.resize(6 * nt);
  for (size_t t = 0; t < nt; ++t) {
    const uint32_t ri = root(rectOfTriangle[t]);
    const Rect& r = rects[ri];
    const PackedRect& p = packed[packedOf[ri]];
    for (int c = 0; c < 3; ++c) {
      double ax, ay;
      if (r.flat) {
        ax = p.x + 2.0, ay = p.y + 2.0;
      } else {
        const int W = source.width(material[t]), H = source.height(material[t]);
        const double x = double(cornerUV[6 * t + 2 * size_t(c)]) * W, y = (1.0 - double(cornerUV[6 * t + 2 * size_t(c) + 1])) * H;
        ax = p.x + (x - r.x0) / scale, ay = p.y + (y - r.y0) / scale;
      }
      out.cornerUV[6 * t + 2 * size_t(c)] = float(ax / aw);
      out.cornerUV[6 * t + 2 * size_t(c) + 1] = float(1.0 - ay / ah);
    }
  }
  return out;
}

}  // namespace mt::tex
