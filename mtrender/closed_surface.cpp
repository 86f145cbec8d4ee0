#include "mtrender/closed_surface.h"

#include <algorithm>
#include <cmath>

#include "base/error.h"
#include "mtfile/mt_cut.h"

namespace mt::render {

namespace {

struct V3 {
  double x, y, z;
};
V3 at(const std::vector<double>& p, uint32_t i) { return {p[3 * i], p[3 * i + 1], p[3 * i + 2]}; }
V3 sub(V3 a, V3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
V3 add(V3 a, V3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
V3 mul(V3 a, double s) { return {a.x * s, a.y * s, a.z * s}; }
double dot(V3 a, V3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
V3 cross(V3 a, V3 b) { return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x}; }

// The point of triangle abc closest to p (Ericson, Real-Time Collision Detection 5.1.5).
V3 closestOnTriangle(V3 p, V3 a, V3 b, V3 c) {
  const V3 ab = sub(b, a), ac = sub(c, a), ap = sub(p, a);
  const double d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const V3 bp = sub(p, b);
  const double d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return add(a, mul(ab, d1 / (d1 - d3)));
  const V3 cp = sub(p, c);
  const double d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return add(a, mul(ac, d2 / (d2 - d6)));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return add(b, mul(sub(c, b), (d4 - d3) / ((d4 - d3) + (d5 - d6))));
  const double denom = 1.0 / (va + vb + vc);
  return add(a, add(mul(ab, vb * denom), mul(ac, vc * denom)));
}

}  // namespace

ClosedSurface ClosedSurface::ofFile(const MtFileReader& reader) {
  const auto& nodes = reader.nodes();
  const auto& arcs = reader.arcs();
  if (nodes.size() < 2) return ClosedSurface();
  const auto& sink = nodes.back();
  std::vector<uint32_t> coarsest;
  double margin = 0;
  for (uint32_t k = 0; k < sink.backArcCount; ++k) {
    const uint32_t a = reader.backArcs()[sink.firstBackArc + k];
    coarsest.push_back(a);
    margin = std::max(margin, double(nodes[arcs[a].from].error));
  }
  std::sort(coarsest.begin(), coarsest.end());
  try {
    WeldedMesh m = assembleCut(reader, coarsest);
    return ofMesh(std::move(m.positions), std::move(m.triangles), margin);
  } catch (const Error&) {
    return ClosedSurface();
  }
}

ClosedSurface ClosedSurface::ofMesh(std::vector<double> positions, std::vector<uint32_t> triangles, double margin) {
  ClosedSurface s;
  s.pos_ = std::move(positions);
  s.tri_ = std::move(triangles);
  s.margin_ = margin;
  const size_t nv = s.pos_.size() / 3, nt = s.tri_.size() / 3;
  if (nt == 0) return s;
  for (int a = 0; a < 3; ++a) s.boxMin_[a] = s.boxMax_[a] = s.pos_[a];
  for (size_t v = 0; v < nv; ++v)
    for (int a = 0; a < 3; ++a) {
      s.boxMin_[a] = std::min(s.boxMin_[a], s.pos_[3 * v + a]);
      s.boxMax_[a] = std::max(s.boxMax_[a], s.pos_[3 * v + a]);
    }
  // Closed and consistently oriented: every directed edge once, and its reverse once.
  std::vector<uint64_t> edges;
  edges.reserve(3 * nt);
  for (size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) edges.push_back(uint64_t(s.tri_[3 * t + k]) << 32 | s.tri_[3 * t + (k + 1) % 3]);
  std::sort(edges.begin(), edges.end());
  if (std::adjacent_find(edges.begin(), edges.end()) != edges.end()) return s;
  for (uint64_t e : edges)
    if (!std::binary_search(edges.begin(), edges.end(), e << 32 | e >> 32)) return s;
  // Outward: positive volume (relative to the box centre, for precision far from the origin).
  const V3 o{(s.boxMin_[0] + s.boxMax_[0]) / 2, (s.boxMin_[1] + s.boxMax_[1]) / 2, (s.boxMin_[2] + s.boxMax_[2]) / 2};
  double volume = 0;
  for (size_t t = 0; t < nt; ++t) {
    const V3 a = sub(at(s.pos_, s.tri_[3 * t]), o), b = sub(at(s.pos_, s.tri_[3 * t + 1]), o), c = sub(at(s.pos_, s.tri_[3 * t + 2]), o);
    volume += dot(a, cross(b, c));
  }
  s.closed_ = volume > 0;
  return s;
}

bool ClosedSurface::eyeOutside(const double eye[3]) const {
  if (!closed_) return false;
  const V3 p{eye[0], eye[1], eye[2]};
  bool inBox = true;
  for (int a = 0; a < 3; ++a) inBox = inBox && eye[a] >= boxMin_[a] - margin_ && eye[a] <= boxMax_[a] + margin_;
  if (!inBox) return true;
  const size_t nt = tri_.size() / 3;
  // Not within the margin of the surface (the fine surface might put the eye on its other side).
  const double m2 = margin_ * margin_;
  for (size_t t = 0; t < nt; ++t) {
    const V3 a = at(pos_, tri_[3 * t]), b = at(pos_, tri_[3 * t + 1]), c = at(pos_, tri_[3 * t + 2]);
    if (p.x < std::min({a.x, b.x, c.x}) - margin_ || p.x > std::max({a.x, b.x, c.x}) + margin_ ||
        p.y < std::min({a.y, b.y, c.y}) - margin_ || p.y > std::max({a.y, b.y, c.y}) + margin_ ||
        p.z < std::min({a.z, b.z, c.z}) - margin_ || p.z > std::max({a.z, b.z, c.z}) + margin_)
      continue;
    const V3 d = sub(p, closestOnTriangle(p, a, b, c));
    if (dot(d, d) <= m2) return false;
  }
  // Ray parity (Moller-Trumbore). A ray grazing an edge or a vertex is ambiguous: try another
  // direction; after three ambiguous directions, answer "not outside" (no culling: always sound).
  const V3 dirs[3] = {{0.8017837, 0.5345225, 0.2672612}, {-0.3015113, 0.9045340, -0.3015113}, {0.2357023, -0.2357023, -0.9428090}};
  for (const V3& dir : dirs) {
    uint32_t hits = 0;
    bool ambiguous = false;
    for (size_t t = 0; t < nt && !ambiguous; ++t) {
      const V3 a = at(pos_, tri_[3 * t]), b = at(pos_, tri_[3 * t + 1]), c = at(pos_, tri_[3 * t + 2]);
      const V3 e1 = sub(b, a), e2 = sub(c, a), h = cross(dir, e2);
      const double det = dot(e1, h);
      const double scale = std::sqrt(dot(e1, e1) * dot(e2, e2));
      if (std::fabs(det) <= 1e-12 * scale) continue;  // parallel to the plane: no proper crossing
      const double inv = 1.0 / det;
      const V3 s = sub(p, a);
      const double u = dot(s, h) * inv;
      if (u < -1e-9 || u > 1 + 1e-9) continue;
      const V3 q = cross(s, e1);
      const double v = dot(dir, q) * inv;
      if (v < -1e-9 || u + v > 1 + 1e-9) continue;
      const double tt = dot(e2, q) * inv;
      if (tt <= 0) continue;
      if (u < 1e-9 || v < 1e-9 || u + v > 1 - 1e-9) ambiguous = true;
      ++hits;
    }
    if (!ambiguous) return hits % 2 == 0;
  }
  return false;
}

}  // namespace mt::render
