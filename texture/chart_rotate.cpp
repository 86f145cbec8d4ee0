// Minimum-area rectangles of charts: see chart_rotate.h.
#include "texture/chart_rotate.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <vector>

namespace mt::tex {

namespace {

struct Pt {
  double x, y;
};

double cross(const Pt& o, const Pt& a, const Pt& b) { return (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x); }

// Andrew's monotone chain: the convex hull, counter-clockwise, without collinear points.
std::vector<Pt> hull(std::vector<Pt> p) {
  std::sort(p.begin(), p.end(), [](const Pt& a, const Pt& b) { return a.x != b.x ? a.x < b.x : a.y < b.y; });
  if (p.size() < 3) return p;
  std::vector<Pt> h(2 * p.size());
  size_t k = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    while (k >= 2 && cross(h[k - 2], h[k - 1], p[i]) <= 0) --k;
    h[k++] = p[i];
  }
  for (size_t i = p.size() - 1, t = k + 1; i-- > 0;) {
    while (k >= t && cross(h[k - 2], h[k - 1], p[i]) <= 0) --k;
    h[k++] = p[i];
  }
  h.resize(k - 1);
  return h;
}

double areaIn(const std::vector<Pt>& h, double c, double s) {
  double lo[2] = {INFINITY, INFINITY}, hi[2] = {-INFINITY, -INFINITY};
  for (const Pt& q : h) {
    const double u = q.x * c + q.y * s, v = -q.x * s + q.y * c;
    lo[0] = std::min(lo[0], u), hi[0] = std::max(hi[0], u), lo[1] = std::min(lo[1], v), hi[1] = std::max(hi[1], v);
  }
  return (hi[0] - lo[0]) * (hi[1] - lo[1]);
}

}  // namespace

BoxFrame minAreaBox(const double* xy, size_t n) {
  BoxFrame best;
  if (n == 0) return best;
  std::vector<Pt> p(n);
  for (size_t i = 0; i < n; ++i) p[i] = {xy[2 * i], xy[2 * i + 1]};
  const std::vector<Pt> h = hull(std::move(p));
  best.area = areaIn(h, 1, 0);
  for (size_t i = 0; h.size() >= 3 && i < h.size(); ++i) {
    const Pt& a = h[i];
    const Pt& b = h[(i + 1) % h.size()];
    const double dx = b.x - a.x, dy = b.y - a.y, l = std::sqrt(dx * dx + dy * dy);
    if (!(l > 0)) continue;
    const double c = dx / l, s = dy / l;
    const double area = areaIn(h, c, s);
    // Strictly smaller by more than rounding: an axis-aligned chart keeps its frame.
    if (area < best.area * (1 - 1e-9)) best.c = c, best.s = s, best.area = area;
  }
  return best;
}

void rotateChartsToMinAreaBoxes(Charts& charts) {
  const size_t nt = charts.chartOf.size();
  assert(charts.corner2D.size() == 6 * nt);
  // Triangles by chart (CSR), the charts' corners gathered in triangle order.
  std::vector<size_t> start(size_t(charts.count) + 1, 0);
  for (size_t t = 0; t < nt; ++t) ++start[size_t(charts.chartOf[t]) + 1];
  for (size_t c = 0; c < charts.count; ++c) start[c + 1] += start[c];
  std::vector<uint32_t> order(nt);
  std::vector<size_t> fill(start.begin(), start.end() - 1);
  for (size_t t = 0; t < nt; ++t) order[fill[charts.chartOf[t]]++] = uint32_t(t);
  std::vector<double> xy;
  for (size_t c = 0; c < charts.count; ++c) {
    xy.clear();
    for (size_t i = start[c]; i < start[c + 1]; ++i) xy.insert(xy.end(), &charts.corner2D[6 * size_t(order[i])], &charts.corner2D[6 * size_t(order[i])] + 6);
    const BoxFrame f = minAreaBox(xy.data(), xy.size() / 2);
    if (f.c == 1 && f.s == 0) continue;
    for (size_t i = start[c]; i < start[c + 1]; ++i) {
      double* q = &charts.corner2D[6 * size_t(order[i])];
      for (int k = 0; k < 3; ++k) {
        const double x = q[2 * k], y = q[2 * k + 1];
        q[2 * k] = x * f.c + y * f.s;
        q[2 * k + 1] = -x * f.s + y * f.c;
      }
    }
  }
}

}  // namespace mt::tex
