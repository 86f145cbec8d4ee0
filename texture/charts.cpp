// Charts by normal cones and planar projection: see charts.h.
#include "texture/charts.h"

#include <algorithm>
#include <cmath>
#include <deque>
#include <unordered_map>

namespace mt::tex {

namespace {

void normalOf(const double* a, const double* b, const double* c, double n[3]) {
  const double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
  n[0] = e1[1] * e2[2] - e1[2] * e2[1];
  n[1] = e1[2] * e2[0] - e1[0] * e2[2];
  n[2] = e1[0] * e2[1] - e1[1] * e2[0];
  const double l = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  if (l > 0) n[0] /= l, n[1] /= l, n[2] /= l;
}

}  // namespace

Charts makeCharts(const double* p, size_t nv, const uint32_t* tri, size_t nt, double maxAngle) {
  (void)nv;
  Charts out;
  out.chartOf.assign(nt, UINT32_MAX);
  out.corner2D.assign(6 * nt, 0.0);
  std::vector<double> normals(3 * nt);
  for (size_t t = 0; t < nt; ++t) normalOf(&p[3 * tri[3 * t]], &p[3 * tri[3 * t + 1]], &p[3 * tri[3 * t + 2]], &normals[3 * t]);
  // Edge -> triangles (both directions), for growth across edges.
  std::unordered_map<uint64_t, std::vector<uint32_t>> edge;
  edge.reserve(3 * nt);
  auto key = [](uint32_t a, uint32_t b) { return a < b ? uint64_t(a) << 32 | b : uint64_t(b) << 32 | a; };
  for (size_t t = 0; t < nt; ++t)
    for (int c = 0; c < 3; ++c) edge[key(tri[3 * t + size_t(c)], tri[3 * t + size_t(c + 1) % 3])].push_back(uint32_t(t));
  const double cosMax = std::cos(maxAngle * M_PI / 180.0);
  std::deque<uint32_t> queue;
  for (size_t seed = 0; seed < nt; ++seed) {
    if (out.chartOf[seed] != UINT32_MAX) continue;
    const uint32_t chart = out.count++;
    const double* n = &normals[3 * seed];
    // The projection plane: (u, v) across the seed's normal (a degenerate seed gets z).
    double nn[3] = {n[0], n[1], n[2]};
    if (nn[0] == 0 && nn[1] == 0 && nn[2] == 0) nn[2] = 1;
    const int least = std::fabs(nn[0]) <= std::fabs(nn[1]) && std::fabs(nn[0]) <= std::fabs(nn[2]) ? 0 : std::fabs(nn[1]) <= std::fabs(nn[2]) ? 1 : 2;
    double a[3] = {0, 0, 0};
    a[least] = 1;
    double u[3] = {nn[1] * a[2] - nn[2] * a[1], nn[2] * a[0] - nn[0] * a[2], nn[0] * a[1] - nn[1] * a[0]};
    const double ul = std::sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
    for (double& x : u) x /= ul;
    const double v[3] = {nn[1] * u[2] - nn[2] * u[1], nn[2] * u[0] - nn[0] * u[2], nn[0] * u[1] - nn[1] * u[0]};
    const double* o = &p[3 * tri[3 * seed]];
    out.chartOf[seed] = chart;
    queue.push_back(uint32_t(seed));
    while (!queue.empty()) {
      const uint32_t t = queue.front();
      queue.pop_front();
      for (int c = 0; c < 3; ++c) {
        const double* q = &p[3 * tri[3 * size_t(t) + size_t(c)]];
        const double d[3] = {q[0] - o[0], q[1] - o[1], q[2] - o[2]};
        out.corner2D[6 * size_t(t) + 2 * size_t(c)] = d[0] * u[0] + d[1] * u[1] + d[2] * u[2];
        out.corner2D[6 * size_t(t) + 2 * size_t(c) + 1] = d[0] * v[0] + d[1] * v[1] + d[2] * v[2];
      }
      for (int c = 0; c < 3; ++c)
        for (uint32_t s : edge[key(tri[3 * size_t(t) + size_t(c)], tri[3 * size_t(t) + size_t(c + 1) % 3])]) {
          if (out.chartOf[s] != UINT32_MAX) continue;
          const double* m = &normals[3 * size_t(s)];
          if (m[0] * nn[0] + m[1] * nn[1] + m[2] * nn[2] < cosMax) continue;
          out.chartOf[s] = chart;
          queue.push_back(s);
        }
    }
  }
  return out;
}

}  // namespace mt::tex
