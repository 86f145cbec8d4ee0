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
inline V3 at(const double* p, uint32_t i) { return {p[size_t(i) * 3], p[size_t(i) * 3 + 1], p[size_t(i) * 3 + 2]}; }

// Squared distance from p to triangle abc (Ericson, Real-Time Collision Detection, 5.1.5).
inline double pointTriangle2(V3 p, V3 a, V3 b, V3 c) {
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

// Relative slack on every pruning bound (cell boxes, bounding spheres): rounding in the bounds is
// ~1e-16 relative, so a triangle is never skipped unless it is clearly farther than the best.
constexpr double kSlack = 1e-9;
// Cell side in mean triangle circumradii (about the centroid), tuned with callgrind on scan-like
// regions: smaller cells list each triangle more often (build cost), larger ones hold more
// triangles to filter per query.
constexpr double kCellPerRadius = 2.0;

}  // namespace

double squaredPointTriangleDistance(const double p[3], const double a[3], const double b[3], const double c[3]) {
  return pointTriangle2({p[0], p[1], p[2]}, {a[0], a[1], a[2]}, {b[0], b[1], b[2]}, {c[0], c[1], c[2]});
}

// The same regions as pointTriangle2 (Ericson 5.1.5), returning the nearest point's barycentrics.
void nearestPointBarycentric(const double p3[3], const double a3[3], const double b3[3], const double c3[3], double bary[3]) {
  const V3 p{p3[0], p3[1], p3[2]}, a{a3[0], a3[1], a3[2]}, b{b3[0], b3[1], b3[2]}, c{c3[0], c3[1], c3[2]};
  auto set = [&](double u, double v, double w) { bary[0] = u, bary[1] = v, bary[2] = w; };
  V3 ab = sub(b, a), ac = sub(c, a), ap = sub(p, a);
  double d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return set(1, 0, 0);
  V3 bp = sub(p, b);
  double d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return set(0, 1, 0);
  double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    double v = d1 / (d1 - d3);
    return set(1 - v, v, 0);
  }
  V3 cp = sub(p, c);
  double d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return set(0, 0, 1);
  double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    double w = d2 / (d2 - d6);
    return set(1 - w, 0, w);
  }
  double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return set(0, 1 - w, w);
  }
  const double sum = va + vb + vc;
  if (!(sum > 0)) return set(1, 0, 0);  // degenerate (only reached through rounding)
  double v = vb / sum, w = vc / sum;
  set(1 - v - w, v, w);
}

// A dense grid of cubic cells (side `cell`) over the bounding box of the triangles, with the
// triangle lists in CSR form built by counting sort (two linear passes, no sort, no hashing).
// Each triangle is listed in every cell its bounding box touches. The cell side is a small
// multiple of the mean triangle size; it is enlarged when the box would need more than ~8 cells
// per triangle (a thin curved region in a big box), so memory stays linear.
// Per triangle a bounding sphere (centroid, radius) gives a cheap lower bound of its distance.
struct TriangleGrid::Impl {
  const double* positions;
  const uint32_t* triangles;
  size_t triangleCount;
  double lo[3] = {0, 0, 0};
  double cell = 1, inv = 1;
  int32_t n[3] = {0, 0, 0};
  std::vector<uint32_t> start;  // n0*n1*n2 + 1 offsets into items
  std::vector<uint32_t> items;  // triangle ids, ascending within a cell
  std::vector<double> sphere;   // 4 per triangle: center xyz, radius
  mutable std::vector<uint32_t> stamp;  // per triangle: last query that reached it
  mutable uint32_t query = 0;

  size_t cellIndex(int32_t x, int32_t y, int32_t z) const { return (size_t(z) * size_t(n[1]) + size_t(y)) * size_t(n[0]) + size_t(x); }

  // The query state: point, best squared distance so far and its square root.
  struct Q {
    V3 p;
    double best2, best;
    double floor2;
    uint32_t bestTriangle = ~0u;
  };
  // First look for an early exit: among the triangles of cell `c` whose bounding sphere reaches
  // within `floor` of p, test the one with the nearest center first (usually the triangle p
  // projects onto), then the others. Triangles that cannot be within floor stay unstamped for
  // scan(). True once best2 <= floor2.
  bool scanNear(size_t c, Q& q, double floor) const {
    const uint32_t i0 = start[c], i1 = start[c + 1];
    uint32_t cand = ~0u;
    double candD2 = std::numeric_limits<double>::infinity();
    for (uint32_t i = i0; i < i1; ++i) {
      uint32_t t = items[i];
      const double* s = &sphere[size_t(t) * 4];
      double dx = q.p.x - s[0], dy = q.p.y - s[1], dz = q.p.z - s[2];
      double d2 = dx * dx + dy * dy + dz * dz, lim = floor + s[3];
      if (d2 < candD2 && d2 <= lim * lim * (1 + kSlack)) candD2 = d2, cand = t;
    }
    if (cand == ~0u) return false;
    if (test(cand, q)) return true;
    for (uint32_t i = i0; i < i1; ++i) {
      uint32_t t = items[i];
      const double* s = &sphere[size_t(t) * 4];
      double dx = q.p.x - s[0], dy = q.p.y - s[1], dz = q.p.z - s[2];
      double lim = floor + s[3];
      if (dx * dx + dy * dy + dz * dz > lim * lim * (1 + kSlack)) continue;  // cannot be within floor
      if (stamp[t] != query && test(t, q)) return true;
    }
    return false;
  }
  // Stamps and tests triangle t; true once best2 <= floor2.
  bool test(uint32_t t, Q& q) const {
    stamp[t] = query;
    const uint32_t* tri = triangles + size_t(t) * 3;
    double d2 = pointTriangle2(q.p, at(positions, tri[0]), at(positions, tri[1]), at(positions, tri[2]));
    if (d2 < q.best2) {
      q.best2 = d2;
      q.best = std::sqrt(d2);
      q.bestTriangle = t;
      return d2 <= q.floor2;
    }
    return false;
  }
  // Tests the (not yet tested) triangles of cell `c`; true once best2 <= floor2 (the caller may stop).
  bool scan(size_t c, Q& q) const {
    for (uint32_t i = start[c], e = start[c + 1]; i < e; ++i) {
      uint32_t t = items[i];
      if (stamp[t] == query) continue;
      stamp[t] = query;
      const double* s = &sphere[size_t(t) * 4];
      double dx = q.p.x - s[0], dy = q.p.y - s[1], dz = q.p.z - s[2];
      double lim = q.best + s[3];
      if (dx * dx + dy * dy + dz * dz > lim * lim * (1 + kSlack)) continue;  // sphere is farther
      const uint32_t* tri = triangles + size_t(t) * 3;
      double d2 = pointTriangle2(q.p, at(positions, tri[0]), at(positions, tri[1]), at(positions, tri[2]));
      if (d2 < q.best2) {
        q.best2 = d2;
        q.best = std::sqrt(d2);
        q.bestTriangle = t;
        if (d2 <= q.floor2) return true;
      }
    }
    return false;
  }
};

TriangleGrid::TriangleGrid(const double* positions, size_t vertexCount, const uint32_t* triangles,
                           size_t triangleCount)
    : impl_(new Impl{positions, triangles, triangleCount}) {
  Impl& g = *impl_;
  if (triangleCount == 0 || vertexCount == 0) return;
  // Box: over all vertices (a superset of the triangles' corners is fine: cells are clamped).
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  for (size_t v = 0; v < vertexCount; ++v)
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], positions[v * 3 + a]), hi[a] = std::max(hi[a], positions[v * 3 + a]);
  // Cell side from the mean circumradius (about the centroid) of up to ~1000 evenly spread triangles.
  const size_t step = std::max<size_t>(1, triangleCount / 1024);
  double radiusSum = 0;
  size_t sampled = 0;
  for (size_t t = 0; t < triangleCount; t += step, ++sampled) {
    V3 a = at(positions, triangles[t * 3]), b = at(positions, triangles[t * 3 + 1]), c = at(positions, triangles[t * 3 + 2]);
    V3 m = {(a.x + b.x + c.x) / 3, (a.y + b.y + c.y) / 3, (a.z + b.z + c.z) / 3};
    radiusSum += std::sqrt(std::max({dot(sub(a, m), sub(a, m)), dot(sub(b, m), sub(b, m)), dot(sub(c, m), sub(c, m))}));
  }
  double meanRadius = radiusSum / double(sampled);
  double extent = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
  double cell = meanRadius > 0 ? meanRadius * kCellPerRadius : (extent > 0 ? extent : 1.0);
  const double maxCells = 8.0 * double(triangleCount) + 64;
  for (;;) {
    double cells = 1;
    for (int a = 0; a < 3; ++a) cells *= std::floor((hi[a] - lo[a]) / cell) + 1;
    if (cells <= maxCells) break;
    cell *= std::max(1.01, std::cbrt(cells / maxCells));
  }
  g.cell = cell;
  g.inv = 1 / cell;
  for (int a = 0; a < 3; ++a) {
    g.lo[a] = lo[a];
    g.n[a] = int32_t(std::floor((hi[a] - lo[a]) * g.inv)) + 1;
  }
  const double nMax[3] = {double(g.n[0] - 1), double(g.n[1] - 1), double(g.n[2] - 1)};
  // Cell coordinates per vertex, once: clamp, then truncate (== floor on [0, n-1]). Monotone in x,
  // so a triangle's cell box is the min/max of its corners' cells, and a point of the triangle
  // always falls in a cell of that box.
  std::vector<int32_t> vertexCell(vertexCount * 3);
  for (size_t v = 0; v < vertexCount; ++v)
    for (int a = 0; a < 3; ++a)
      vertexCell[v * 3 + a] = int32_t(std::min(std::max((positions[v * 3 + a] - g.lo[a]) * g.inv, 0.0), nMax[a]));
  const size_t cellCount = size_t(g.n[0]) * size_t(g.n[1]) * size_t(g.n[2]);
  // One pass: bounding spheres, and (cell, triangle) entries with per-cell counts at [cell + 2].
  // Any center works for a sphere (its radius is measured from it): the centroid, by a multiply.
  g.sphere.resize(triangleCount * 4);
  g.start.assign(cellCount + 2, 0);
  struct Entry {
    uint32_t cell, tri;
  };
  std::vector<Entry> entries;
  entries.reserve(triangleCount * 4);  // ~3.3 cells per triangle measured on scan regions
  for (size_t t = 0; t < triangleCount; ++t) {
    V3 a = at(positions, triangles[t * 3]), b = at(positions, triangles[t * 3 + 1]), c = at(positions, triangles[t * 3 + 2]);
    constexpr double third = 1.0 / 3.0;
    V3 m = {(a.x + b.x + c.x) * third, (a.y + b.y + c.y) * third, (a.z + b.z + c.z) * third};
    double r2 = std::max(std::max(dot(sub(a, m), sub(a, m)), dot(sub(b, m), sub(b, m))), dot(sub(c, m), sub(c, m)));
    double* s = &g.sphere[t * 4];
    s[0] = m.x, s[1] = m.y, s[2] = m.z, s[3] = std::sqrt(r2) * (1 + kSlack);
    const int32_t *ca = &vertexCell[size_t(triangles[t * 3]) * 3], *cb = &vertexCell[size_t(triangles[t * 3 + 1]) * 3],
                  *cc = &vertexCell[size_t(triangles[t * 3 + 2]) * 3];
    int32_t lo[3], hi[3];
    for (int k = 0; k < 3; ++k) lo[k] = std::min({ca[k], cb[k], cc[k]}), hi[k] = std::max({ca[k], cb[k], cc[k]});
    for (int32_t z = lo[2]; z <= hi[2]; ++z)
      for (int32_t y = lo[1]; y <= hi[1]; ++y) {
        uint32_t row = uint32_t(g.cellIndex(0, y, z));
        for (int32_t x = lo[0]; x <= hi[0]; ++x) {
          entries.push_back({row + uint32_t(x), uint32_t(t)});
          ++g.start[row + size_t(x) + 2];
        }
      }
  }
  for (size_t k = 2; k < cellCount + 2; ++k) g.start[k] += g.start[k - 1];
  // counting sort: start[k + 1] runs from the begin to the end of cell k; triangles ascending
  g.items.resize(entries.size());
  for (const Entry& e : entries) g.items[g.start[e.cell + 1]++] = e.tri;
  g.start.pop_back();
  g.stamp.assign(triangleCount, 0);
}

TriangleGrid::~TriangleGrid() { delete impl_; }

double TriangleGrid::distance(const double p[3]) const { return std::sqrt(distance2Above(p, -1.0)); }

namespace {
// A query's result: its squared distance, and the triangle it was measured to.
double found(const TriangleGrid::Impl::Q& q, uint32_t& triangle) {
  triangle = q.bestTriangle;
  return q.best2;
}
}  // namespace

double TriangleGrid::distance2Above(const double p[3], double floor2) const {
  uint32_t triangle = ~0u;
  return search(p, floor2, triangle);
}

uint32_t TriangleGrid::nearest(const double p[3], double* distance2) const {
  uint32_t triangle = ~0u;
  const double d2 = search(p, -1.0, triangle);
  if (distance2) *distance2 = d2;
  return triangle;
}

double TriangleGrid::search(const double p[3], double floor2, uint32_t& triangle) const {
  const Impl& g = *impl_;
  constexpr double inf = std::numeric_limits<double>::infinity();
  if (g.items.empty()) return inf;
  if (++g.query == 0) {  // stamp wrap-around
    std::fill(g.stamp.begin(), g.stamp.end(), 0);
    g.query = 1;
  }
  Impl::Q q{{p[0], p[1], p[2]}, inf, inf, floor2};
  // Cell coordinates: u in cell units; c = the (clamped) cell holding p.
  double u[3];
  int32_t c[3];
  for (int a = 0; a < 3; ++a) {
    u[a] = (p[a] - g.lo[a]) * g.inv;
    // clamp, then truncate (== floor on [0, n-1]); NaN -> 0
    c[a] = int32_t(std::min(std::max(u[a], 0.0), double(g.n[a] - 1)));
  }
  const size_t home = g.cellIndex(c[0], c[1], c[2]);
  if (floor2 > 0 && g.scanNear(home, q, std::sqrt(floor2))) return found(q, triangle);
  if (g.scan(home, q)) return found(q, triangle);
  if (q.best2 == inf) {
    // Empty home cell: visit growing shells of cells (clamped to the grid) until a triangle is
    // found; the ball pass below then settles the exact nearest one.
    int32_t rmax = 0;
    for (int a = 0; a < 3; ++a) rmax = std::max({rmax, c[a], g.n[a] - 1 - c[a]});
    for (int32_t r = 1; r <= rmax && q.best2 == inf; ++r) {
      int32_t z0 = std::max(c[2] - r, 0), z1 = std::min(c[2] + r, g.n[2] - 1);
      int32_t y0 = std::max(c[1] - r, 0), y1 = std::min(c[1] + r, g.n[1] - 1);
      int32_t x0 = std::max(c[0] - r, 0), x1 = std::min(c[0] + r, g.n[0] - 1);
      for (int32_t z = z0; z <= z1; ++z)
        for (int32_t y = y0; y <= y1; ++y) {
          if (std::abs(z - c[2]) == r || std::abs(y - c[1]) == r) {  // a whole row of the shell
            for (int32_t x = x0; x <= x1; ++x)
              if (g.scan(g.cellIndex(x, y, z), q)) return found(q, triangle);
          } else {  // only the row's two ends belong to the shell
            if (c[0] - r >= 0 && g.scan(g.cellIndex(c[0] - r, y, z), q)) return found(q, triangle);
            if (c[0] + r < g.n[0] && g.scan(g.cellIndex(c[0] + r, y, z), q)) return found(q, triangle);
          }
        }
    }
  }
  // Ball pass: every cell within the best distance (in cell units b, with slack) of p. A cell is
  // skipped when its box is farther than b; b shrinks as better triangles are found.
  auto radius = [&] { return q.best * g.inv * (1 + kSlack) + kSlack; };
  double b = radius();
  int32_t r0[3], r1[3];
  for (int a = 0; a < 3; ++a) {
    double l = std::floor(u[a] - b), h = std::floor(u[a] + b);
    r0[a] = int32_t(std::min(std::max(l, 0.0), double(g.n[a] - 1)));
    r1[a] = int32_t(std::min(std::max(h, 0.0), double(g.n[a] - 1)));
  }
  auto gap = [](double u, int32_t i) {
    double g = std::max(double(i) - u, u - double(i + 1));
    return g > 0 ? g * g : 0.0;
  };
  for (int32_t z = r0[2]; z <= r1[2]; ++z) {
    double gz = gap(u[2], z);
    if (gz > b * b) continue;
    for (int32_t y = r0[1]; y <= r1[1]; ++y) {
      double gyz = gz + gap(u[1], y);
      if (gyz > b * b) continue;
      for (int32_t x = r0[0]; x <= r1[0]; ++x) {
        if (gyz + gap(u[0], x) > b * b) continue;
        size_t cell = g.cellIndex(x, y, z);
        if (cell == home) continue;
        double before = q.best2;
        if (g.scan(cell, q)) return found(q, triangle);
        if (q.best2 != before) b = radius();
      }
    }
  }
  return found(q, triangle);
}

double sampledDistance(const double* positions, const uint32_t* triangles, size_t triangleCount,
                       const TriangleGrid& to, const uint8_t* skipVertex) {
  double worst2 = 0;
  // vertices: each once (the first triangle corner that uses it tests it)
  std::vector<uint8_t> seen;
  uint32_t maxIndex = 0;
  for (size_t i = 0; i < triangleCount * 3; ++i) maxIndex = std::max(maxIndex, triangles[i]);
  seen.assign(triangleCount ? size_t(maxIndex) + 1 : 0, 0);
  for (size_t i = 0; i < triangleCount * 3; ++i) {
    uint32_t v = triangles[i];
    if (seen[v] || (skipVertex && skipVertex[v])) continue;
    seen[v] = 1;
    worst2 = std::max(worst2, to.distance2Above(positions + size_t(v) * 3, worst2));
  }
  for (size_t t = 0; t < triangleCount; ++t) {
    double c[3];
    for (int a = 0; a < 3; ++a)
      c[a] = (positions[size_t(triangles[t * 3]) * 3 + a] + positions[size_t(triangles[t * 3 + 1]) * 3 + a] +
              positions[size_t(triangles[t * 3 + 2]) * 3 + a]) / 3;
    worst2 = std::max(worst2, to.distance2Above(c, worst2));
  }
  return std::sqrt(worst2);
}

}  // namespace mt
