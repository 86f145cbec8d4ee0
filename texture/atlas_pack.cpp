// Shelf packing (see atlas_pack.h): rectangles by decreasing height, left to right on shelves
// whose height is their first rectangle's; the atlas width is the smallest of a few candidates
// (the square root of the area, rounded up to a multiple of 4, and wider) whose height fits.
#include "texture/atlas_pack.h"

#include <algorithm>
#include <cmath>
#include <numeric>

namespace mt::tex {

namespace {

// Packs at a fixed width; returns the height used (INT32_MAX when a rectangle is wider).
int packAt(std::vector<PackedRect>& rects, const std::vector<uint32_t>& order, int width) {
  int x = 0, y = 0, shelf = 0;
  for (uint32_t i : order) {
    PackedRect& r = rects[i];
    if (r.w > width) return INT32_MAX;
    if (x + r.w > width) {
      y += shelf;
      x = 0;
      shelf = 0;
    }
    r.x = x;
    r.y = y;
    x += r.w;
    shelf = std::max(shelf, r.h);
  }
  return y + shelf;
}

int roundUp4(int v) { return (v + 3) & ~3; }

}  // namespace

bool packRects(std::vector<PackedRect>& rects, int maxSide, int& width, int& height) {
  width = height = 0;
  if (rects.empty()) {
    width = height = 4;
    return true;
  }
  std::vector<uint32_t> order(rects.size());
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
    return rects[a].h != rects[b].h ? rects[a].h > rects[b].h : rects[a].w > rects[b].w;
  });
  double area = 0;
  int widest = 0;
  for (const PackedRect& r : rects) area += double(r.w) * r.h, widest = std::max(widest, r.w);
  if (widest > maxSide) return false;
  // Widths from the widest rectangle (or the square's side) up to twice the square's side, in
  // steps of 4 (about 30 tries): the smallest area wins, ties the squarer (the first).
  const int side = int(std::ceil(std::sqrt(area)));
  const int from = roundUp4(std::max(widest, side * 3 / 4)), to = std::min(maxSide, roundUp4(std::max(from, 2 * side)));
  const int step = std::max(4, roundUp4((to - from) / 32));
  int bestW = 0, bestH = 0;
  double bestArea = INFINITY;
  for (int w = std::min(from, maxSide);; w = std::min(maxSide, w + step)) {
    const int h = packAt(rects, order, w);
    if (h <= maxSide) {
      const double a = double(w) * double(roundUp4(h));
      if (a < bestArea) bestArea = a, bestW = w, bestH = roundUp4(h);
    }
    if (w >= to) break;
  }
  if (bestW == 0) {
    // Nothing fit at up to twice the square's width: the widest allowed.
    const int h = packAt(rects, order, maxSide);
    if (h > maxSide) return false;
    bestW = maxSide, bestH = roundUp4(h);
  }
  packAt(rects, order, bestW);
  width = bestW;
  height = std::max(4, bestH);
  return true;
}

}  // namespace mt::tex
