// The geometry of one DAG node: see dag_node.h.
#include "mtbuild/dag_node.h"

#include <algorithm>
#include <cmath>

namespace mt {

namespace {

double distance(const double a[3], const double b[3]) {
  double d2 = 0;
  for (int k = 0; k < 3; ++k) d2 += (a[k] - b[k]) * (a[k] - b[k]);
  return std::sqrt(d2);
}

}  // namespace

Sphere sphereOf(const std::vector<double>& positions) {
  Sphere s;
  if (positions.empty()) return s;
  double lo[3] = {positions[0], positions[1], positions[2]}, hi[3] = {lo[0], lo[1], lo[2]};
  for (size_t i = 0; i < positions.size(); i += 3)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], positions[i + a]);
      hi[a] = std::max(hi[a], positions[i + a]);
    }
  for (int a = 0; a < 3; ++a) s.c[a] = 0.5 * (lo[a] + hi[a]);
  double r2 = 0;
  for (size_t i = 0; i < positions.size(); i += 3) {
    double d2 = 0;
    for (int a = 0; a < 3; ++a) d2 += (positions[i + a] - s.c[a]) * (positions[i + a] - s.c[a]);
    r2 = std::max(r2, d2);
  }
  s.r = std::sqrt(r2);
  return s;
}

// The nesting the renderer relies on (BMT 5.1: "each bounding sphere encloses the bounding sphere
// of all the arcs in the subgraph"): keeping the centre, the radius grows to reach t's far side.
void enclose(Sphere& s, const Sphere& t) {
  double d2 = 0;
  for (int a = 0; a < 3; ++a) d2 += (t.c[a] - s.c[a]) * (t.c[a] - s.c[a]);
  s.r = std::max(s.r, std::sqrt(d2) + t.r);
}

bool contains(const Sphere& s, const Sphere& t) {
  const double reach = distance(s.c, t.c) + t.r;
  return reach <= s.r * (1 + 1e-12) + 1e-300;
}

void normalCone(const std::vector<double>& p, const std::vector<uint32_t>& t, float axis[3], float& cutoff) {
  std::vector<double> normals;
  double sum[3] = {0, 0, 0};
  for (size_t i = 0; i < t.size(); i += 3) {
    const double *a = &p[3 * t[i]], *b = &p[3 * t[i + 1]], *c = &p[3 * t[i + 2]];
    double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
    double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (int k = 0; k < 3; ++k) sum[k] += n[k];
    if (len > 0)
      for (int k = 0; k < 3; ++k) normals.push_back(n[k] / len);
  }
  double len = std::sqrt(sum[0] * sum[0] + sum[1] * sum[1] + sum[2] * sum[2]);
  if (len == 0 || normals.empty()) {
    axis[0] = 0, axis[1] = 0, axis[2] = 1;
    cutoff = -1;
    return;
  }
  double minDot = 1;
  for (size_t i = 0; i < normals.size(); i += 3)
    minDot = std::min(minDot, (normals[i] * sum[0] + normals[i + 1] * sum[1] + normals[i + 2] * sum[2]) / len);
  for (int k = 0; k < 3; ++k) axis[k] = float(sum[k] / len);
  // Conservative: widen a little for the float axis; a cone past 90 degrees culls nothing useful.
  cutoff = minDot <= 0.01 ? -1.0f : float(minDot - 1e-4);
}

}  // namespace mt
