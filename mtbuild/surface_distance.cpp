// Sampled surface distance with a uniform grid over triangles (see surface_distance.h).
#include "mtbuild/surface_distance.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace mt {

namespace {

struct V3 {
  double x, y, z;
};
inline V3 sub(V3 a, V3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
inline double dot(V3 a, V3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline V3 at(const double* p, uint32_t i) { return {p[i * 3], p[i * 3 + 1], p[i * 3 + 2]}; }

// Squared distance from p to triangle abc (Ericson, Real-Time Collision Detection, 5.1.5).
double pointTriangle2(V3 p, V3 a, V3 b, V3 c) {
  V3 ab = sub(b, a), ac = sub(c, a), ap = sub(p, a);
  double d1 = dot(ab, ap), d2 = dot(ac, ap);
  auto len2 = [](V3 v) { return dot(v, v); };
  if (d1 <= 0 && d2 <= 0) return len2(ap);
  V3 bp = sub(p, b);
  double d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return len2(bp);
  double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    double v = d1 / (d1 - d3);
    return len2(sub(ap, {ab.x * v, ab.y * v, ab.z * v}));
  }
  V3 cp = sub(p, c);
  double d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return len2(cp);
  double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    double w = d2 / (d2 - d6);
    return len2(sub(ap, {ac.x * w, ac.y * w, ac.z * w}));
  }
  double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    V3 bc = sub(c, b);
    return len2(sub(bp, {bc.x * w, bc.y * w, bc.z * w}));
  }
  double denom = 1 / (va + vb + vc);
  double v = vb * denom, w = vc * denom;
  V3 q = {a.x + ab.x * v + ac.x * w, a.y + ab.y * v + ac.y * w, a.z + ab.z * v + ac.z * w};
  return len2(sub(p, q));
}

inline uint64_t hashKey(int64_t x, int64_t y, int64_t z) {
  uint64_t h = uint64_t(x) * 0x9E3779B97F4A7C15ull ^ uint64_t(y) * 0xC2B2AE3D27D4EB4Full ^
               uint64_t(z) * 0x165667B19E3779F9ull;
  return h ^ (h >> 29);
}

}  // namespace

// Cells are cubes of side `cell`; each triangle is listed in every cell its bounding box touches.
// Cells live in an open-addressing table keyed by their integer coordinates, with the triangle
// lists stored CSR-style (one sort, no per-cell allocation).
struct TriangleGrid::Impl {
  const double* positions;
  const uint32_t* triangles;
  size_t triangleCount;
  double origin[3] = {0, 0, 0};
  double cell = 1;
  struct Slot {
    int32_t x, y, z;
    uint32_t begin, end;  // into items; begin == end means empty slot
  };
  std::vector<Slot> table;
  uint64_t mask = 0;
  std::vector<uint32_t> items;
  mutable std::vector<uint32_t> stamp;  // per triangle: last query that tested it
  mutable uint32_t query = 0;

  const Slot* find(int32_t x, int32_t y, int32_t z) const {
    for (uint64_t i = hashKey(x, y, z) & mask;; i = (i + 1) & mask) {
      const Slot& s = table[i];
      if (s.begin == s.end) return nullptr;
      if (s.x == x && s.y == y && s.z == z) return &s;
    }
  }
};

TriangleGrid::TriangleGrid(const double* positions, size_t vertexCount, const uint32_t* triangles,
                           size_t triangleCount)
    : impl_(new Impl{positions, triangles, triangleCount}) {
  Impl& g = *impl_;
  if (triangleCount == 0 || vertexCount == 0) return;
  double lo[3] = {1e300, 1e300, 1e300};
  double edge = 0;
  for (size_t t = 0; t < triangleCount; ++t)
    for (int k = 0; k < 3; ++k) {
      V3 a = at(positions, triangles[t * 3 + k]), b = at(positions, triangles[t * 3 + (k + 1) % 3]);
      edge += std::sqrt(dot(sub(a, b), sub(a, b)));
      lo[0] = std::min(lo[0], a.x), lo[1] = std::min(lo[1], a.y), lo[2] = std::min(lo[2], a.z);
    }
  edge /= double(triangleCount * 3);
  // ~2 mean edges per cell side: a triangle touches ~1-4 cells, a cell holds ~10 triangles, and
  // most queries end in their own cell.
  g.cell = edge > 0 ? edge * 2.0 : 1.0;
  for (int k = 0; k < 3; ++k) g.origin[k] = lo[k];

  struct Entry {
    uint64_t key;
    int32_t x, y, z;
    uint32_t tri;
  };
  std::vector<Entry> entries;
  entries.reserve(triangleCount * 3);
  for (size_t t = 0; t < triangleCount; ++t) {
    int32_t mn[3] = {INT32_MAX, INT32_MAX, INT32_MAX}, mx[3] = {INT32_MIN, INT32_MIN, INT32_MIN};
    for (int k = 0; k < 3; ++k) {
      const double* p = positions + size_t(triangles[t * 3 + k]) * 3;
      for (int a = 0; a < 3; ++a) {
        int32_t c = int32_t(std::floor((p[a] - g.origin[a]) / g.cell));
        mn[a] = std::min(mn[a], c), mx[a] = std::max(mx[a], c);
      }
    }
    for (int32_t z = mn[2]; z <= mx[2]; ++z)
      for (int32_t y = mn[1]; y <= mx[1]; ++y)
        for (int32_t x = mn[0]; x <= mx[0]; ++x) entries.push_back({hashKey(x, y, z), x, y, z, uint32_t(t)});
  }
  std::sort(entries.begin(), entries.end(), [](const Entry& a, const Entry& b) {
    if (a.key != b.key) return a.key < b.key;
    if (a.x != b.x) return a.x < b.x;
    if (a.y != b.y) return a.y < b.y;
    if (a.z != b.z) return a.z < b.z;
    return a.tri < b.tri;
  });
  size_t cells = 0;
  for (size_t i = 0; i < entries.size(); ++i)
    if (i == 0 || entries[i].key != entries[i - 1].key || entries[i].x != entries[i - 1].x ||
        entries[i].y != entries[i - 1].y || entries[i].z != entries[i - 1].z)
      ++cells;
  size_t slots = 16;
  while (slots < cells * 2) slots *= 2;
  g.table.assign(slots, Impl::Slot{0, 0, 0, 0, 0});
  g.mask = slots - 1;
  g.items.resize(entries.size());
  for (size_t i = 0; i < entries.size();) {
    size_t j = i;
    while (j < entries.size() && entries[j].key == entries[i].key && entries[j].x == entries[i].x &&
           entries[j].y == entries[i].y && entries[j].z == entries[i].z) {
      g.items[j] = entries[j].tri;
      ++j;
    }
    uint64_t s = entries[i].key & g.mask;
    while (g.table[s].begin != g.table[s].end) s = (s + 1) & g.mask;
    g.table[s] = {entries[i].x, entries[i].y, entries[i].z, uint32_t(i), uint32_t(j)};
    i = j;
  }
  g.stamp.assign(triangleCount, 0);
}

TriangleGrid::~TriangleGrid() { delete impl_; }

double TriangleGrid::distance(const double p[3]) const {
  const Impl& g = *impl_;
  if (g.items.empty()) return std::numeric_limits<double>::infinity();
  if (++g.query == 0) {  // stamp wrap-around
    std::fill(g.stamp.begin(), g.stamp.end(), 0);
    g.query = 1;
  }
  V3 q = {p[0], p[1], p[2]};
  int32_t c[3];
  double inner = g.cell;
  for (int a = 0; a < 3; ++a) {
    double u = (p[a] - g.origin[a]) / g.cell;
    c[a] = int32_t(std::floor(u));
    double f = u - std::floor(u);
    inner = std::min(inner, std::min(f, 1 - f) * g.cell);
  }
  double best2 = std::numeric_limits<double>::infinity();
  // Visit growing shells of cells; after shell r every unvisited triangle is farther than
  // r * cell, so stop once the best distance found is within that.
  for (int32_t r = 0; r < 64; ++r) {
    for (int32_t dz = -r; dz <= r; ++dz)
      for (int32_t dy = -r; dy <= r; ++dy)
        for (int32_t dx = -r; dx <= r; ++dx) {
          if (std::max({std::abs(dx), std::abs(dy), std::abs(dz)}) != r) continue;
          const Impl::Slot* s = g.find(c[0] + dx, c[1] + dy, c[2] + dz);
          if (!s) continue;
          for (uint32_t i = s->begin; i < s->end; ++i) {
            uint32_t t = g.items[i];
            if (g.stamp[t] == g.query) continue;
            g.stamp[t] = g.query;
            const uint32_t* tri = g.triangles + size_t(t) * 3;
            best2 = std::min(best2, pointTriangle2(q, at(g.positions, tri[0]), at(g.positions, tri[1]),
                                                    at(g.positions, tri[2])));
          }
        }
    // every unvisited cell is beyond the query cell's faces plus r whole cells
    double reach = inner + double(r) * g.cell;
    if (best2 <= reach * reach) break;
  }
  if (std::isinf(best2)) {  // farther than 64 cells from everything: brute force
    for (size_t t = 0; t < g.triangleCount; ++t) {
      const uint32_t* tri = g.triangles + t * 3;
      best2 = std::min(best2, pointTriangle2(q, at(g.positions, tri[0]), at(g.positions, tri[1]),
                                              at(g.positions, tri[2])));
    }
  }
  return std::sqrt(best2);
}

double sampledDistance(const double* positions, const uint32_t* triangles, size_t triangleCount,
                       const TriangleGrid& to, const uint8_t* skipVertex) {
  double worst = 0;
  // vertices: each once (the first triangle corner that uses it tests it)
  std::vector<uint8_t> seen;
  uint32_t maxIndex = 0;
  for (size_t i = 0; i < triangleCount * 3; ++i) maxIndex = std::max(maxIndex, triangles[i]);
  seen.assign(triangleCount ? size_t(maxIndex) + 1 : 0, 0);
  for (size_t i = 0; i < triangleCount * 3; ++i) {
    uint32_t v = triangles[i];
    if (seen[v] || (skipVertex && skipVertex[v])) continue;
    seen[v] = 1;
    worst = std::max(worst, to.distance(positions + size_t(v) * 3));
  }
  for (size_t t = 0; t < triangleCount; ++t) {
    double c[3];
    for (int a = 0; a < 3; ++a)
      c[a] = (positions[size_t(triangles[t * 3]) * 3 + a] + positions[size_t(triangles[t * 3 + 1]) * 3 + a] +
              positions[size_t(triangles[t * 3 + 2]) * 3 + a]) / 3;
    worst = std::max(worst, to.distance(c));
  }
  return worst;
}

}  // namespace mt
