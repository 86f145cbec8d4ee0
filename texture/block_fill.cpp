// Flat fill of an atlas' uncovered texels by JPEG blocks: see block_fill.h.
#include "texture/block_fill.h"

#include <algorithm>
#include <cassert>

namespace mt::tex {

void fillEmptyBlocks(RgbImage& image, std::vector<uint8_t>& filled, int block) {
  const int w = image.width, h = image.height;
  assert(block >= 1 && filled.size() == size_t(w) * size_t(h));
  const int bw = (w + block - 1) / block, bh = (h + block - 1) / block;
  const size_t blocks = size_t(bw) * size_t(bh);
  // Per block: the mean of its covered texels (known), or nothing yet.
  std::vector<uint8_t> colour(3 * blocks, 0), known(blocks, 0);
  bool any = false;
  for (int by = 0; by < bh; ++by)
    for (int bx = 0; bx < bw; ++bx) {
      uint64_t acc[3] = {0, 0, 0}, n = 0;
      const int x1 = std::min(w, (bx + 1) * block), y1 = std::min(h, (by + 1) * block);
      for (int y = by * block; y < y1; ++y)
        for (int x = bx * block; x < x1; ++x) {
          if (!filled[size_t(y) * size_t(w) + size_t(x)]) continue;
          const uint8_t* p = image.pixel(x, y);
          acc[0] += p[0], acc[1] += p[1], acc[2] += p[2], ++n;
        }
      if (!n) continue;
      const size_t b = size_t(by) * size_t(bw) + size_t(bx);
      for (int c = 0; c < 3; ++c) colour[3 * b + size_t(c)] = uint8_t((acc[c] + n / 2) / n);
      known[b] = 1;
      any = true;
    }
  if (!any) return;
  // The empty blocks, grown ring by ring from the known ones: each takes the mean of its known
  // 8-neighbours of the ring before (so the colours change smoothly away from the charts).
  std::vector<uint8_t> next = known;
  for (bool grew = true; grew;) {
    grew = false;
    for (int by = 0; by < bh; ++by)
      for (int bx = 0; bx < bw; ++bx) {
        const size_t b = size_t(by) * size_t(bw) + size_t(bx);
        if (known[b]) continue;
        uint32_t acc[3] = {0, 0, 0}, n = 0;
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const int x = bx + dx, y = by + dy;
            if (x < 0 || y < 0 || x >= bw || y >= bh) continue;
            const size_t o = size_t(y) * size_t(bw) + size_t(x);
            if (!known[o]) continue;
            for (int c = 0; c < 3; ++c) acc[c] += colour[3 * o + size_t(c)];
            ++n;
          }
        if (!n) continue;
        for (int c = 0; c < 3; ++c) colour[3 * b + size_t(c)] = uint8_t((acc[c] + n / 2) / n);
        next[b] = 1;
        grew = true;
      }
    known = next;
  }
  // Every uncovered texel takes its block's colour.
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      uint8_t& f = filled[size_t(y) * size_t(w) + size_t(x)];
      if (f) continue;
      const size_t b = size_t(y / block) * size_t(bw) + size_t(x / block);
      uint8_t* p = image.pixel(x, y);
      for (int c = 0; c < 3; ++c) p[c] = colour[3 * b + size_t(c)];
      f = 1;
    }
}

}  // namespace mt::tex
