#include "mtrender/occlusion.h"

#include <algorithm>
#include <cmath>

namespace mt::render {

void DepthPyramid::build(const std::vector<float>& depth, int width, int height, const View& view) {
  view_ = view;
  levels_.clear();
  if (width <= 0 || height <= 0 || depth.size() < size_t(width) * height) return;
  levels_.push_back({width, height, depth});
  while (levels_.back().width > 1 || levels_.back().height > 1) {
    const Level& lo = levels_.back();
    Level hi;
    hi.width = (lo.width + 1) / 2;
    hi.height = (lo.height + 1) / 2;
    hi.depth.resize(size_t(hi.width) * hi.height);
    for (int y = 0; y < hi.height; ++y) {
      const int y0 = 2 * y, y1 = std::min(2 * y + 1, lo.height - 1);
      for (int x = 0; x < hi.width; ++x) {
        const int x0 = 2 * x, x1 = std::min(2 * x + 1, lo.width - 1);
        hi.depth[size_t(y) * hi.width + x] =
            std::max(std::max(lo.depth[size_t(y0) * lo.width + x0], lo.depth[size_t(y0) * lo.width + x1]),
                     std::max(lo.depth[size_t(y1) * lo.width + x0], lo.depth[size_t(y1) * lo.width + x1]));
      }
    }
    levels_.push_back(std::move(hi));
  }
}

bool DepthPyramid::occluded(const double center[3], double radius) const {
  if (levels_.empty()) return false;
  // In eye space (double: a georeferenced centre is millions of units out).
  const glm::dvec4 c = view_.viewD * glm::dvec4(center[0], center[1], center[2], 1.0);
  const double nearest = -c.z - radius;  // distance along the view axis of the sphere's nearest point
  if (nearest <= view_.nearPlane) return false;
  // The screen rectangle: the projections of the eye-space box around the sphere (its corners
  // nearest the eye bound x/y on the near face, but taking all 8 is simply conservative).
  double x0 = 1e300, y0 = 1e300, x1 = -1e300, y1 = -1e300;
  for (int k = 0; k < 8; ++k) {
    const glm::dvec4 p(c.x + ((k & 1) ? radius : -radius), c.y + ((k & 2) ? radius : -radius),
                       c.z + ((k & 4) ? radius : -radius), 1.0);
    const glm::dvec4 q = view_.projD * p;
    if (q.w <= 0) return false;
    x0 = std::min(x0, q.x / q.w), x1 = std::max(x1, q.x / q.w);
    y0 = std::min(y0, q.y / q.w), y1 = std::max(y1, q.y / q.w);
  }
  const Level& base = levels_[0];
  // NDC -> pixels, clamped to the image (outside it the frustum test decides).
  double px0 = (x0 * 0.5 + 0.5) * base.width, px1 = (x1 * 0.5 + 0.5) * base.width;
  double py0 = (y0 * 0.5 + 0.5) * base.height, py1 = (y1 * 0.5 + 0.5) * base.height;
  if (px1 < 0 || py1 < 0 || px0 > base.width || py0 > base.height) return false;
  px0 = std::clamp(px0, 0.0, double(base.width - 1)), px1 = std::clamp(px1, 0.0, double(base.width - 1));
  py0 = std::clamp(py0, 0.0, double(base.height - 1)), py1 = std::clamp(py1, 0.0, double(base.height - 1));
  // The sphere's nearest depth in window space (the projection of the point on the view axis).
  const glm::dvec4 nq = view_.projD * glm::dvec4(0, 0, -nearest, 1.0);
  const double sphereDepth = (nq.z / nq.w) * 0.5 + 0.5;
  // Start at the level where the rectangle spans at most ~2 texels each way (at most 3 x 3 reads),
  // and descend into a texel only where its farthest depth does not hide the sphere: the answer is
  // that of every pixel of the rectangle (a coarse texel that also covers a window in the occluder
  // would otherwise make every sphere near the window visible), at a cost that grows with the
  // occluder's edges inside the rectangle, not with its area. Past kMaxVisits texels the sphere is
  // taken as visible (conservative).
  const double extent = std::max(px1 - px0, py1 - py0);
  int level = extent <= 1 ? 0 : int(std::ceil(std::log2(extent / 2)));
  level = std::clamp(level, 0, int(levels_.size()) - 1);
  const int rx0 = int(px0), rx1 = int(px1), ry0 = int(py0), ry1 = int(py1);
  // Behind everything drawn there (a margin for the 24-bit depth buffer's rounding).
  const float limit = float(sphereDepth - 1e-6);
  constexpr int kMaxVisits = 4096;
  int visits = 0;
  struct Texel {
    int level, x, y;
  };
  std::vector<Texel> stack;
  const Level& top = levels_[size_t(level)];
  for (int y = ry0 >> level; y <= std::min(ry1 >> level, top.height - 1); ++y)
    for (int x = rx0 >> level; x <= std::min(rx1 >> level, top.width - 1); ++x) stack.push_back({level, x, y});
  while (!stack.empty()) {
    const Texel t = stack.back();
    stack.pop_back();
    if (++visits > kMaxVisits) return false;
    const Level& l = levels_[size_t(t.level)];
    if (l.depth[size_t(t.y) * l.width + t.x] < limit) continue;  // this texel hides the sphere
    if (t.level == 0) return false;                              // a pixel where the sphere may show
    // The children of the texel that overlap the rectangle.
    const int cl = t.level - 1;
    const Level& c = levels_[size_t(cl)];
    for (int dy = 0; dy < 2; ++dy)
      for (int dx = 0; dx < 2; ++dx) {
        const int cx = 2 * t.x + dx, cy = 2 * t.y + dy;
        if (cx >= c.width || cy >= c.height) continue;
        if (((cx + 1) << cl) - 1 < rx0 || (cx << cl) > rx1 || ((cy + 1) << cl) - 1 < ry0 || (cy << cl) > ry1) continue;
        stack.push_back({cl, cx, cy});
      }
  }
  return true;
}

}  // namespace mt::render
