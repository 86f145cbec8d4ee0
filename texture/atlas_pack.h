// Rectangles packed into one atlas image of bounded size: shelves, tallest first (a few dozen to a
// few thousand rectangles per patch; the shelf packer wastes ~10-20% and is deterministic).
#pragma once

#include <cstdint>
#include <vector>

namespace mt::tex {

struct PackedRect {
  int w = 0, h = 0;  // in: size in texels (padding included)
  int x = 0, y = 0;  // out: top-left corner in the atlas
};

// Places every rectangle; the atlas is `width` x `height` (each <= maxSide, multiples of 4).
// False when they do not fit in maxSide x maxSide.
bool packRects(std::vector<PackedRect>& rects, int maxSide, int& width, int& height);

}  // namespace mt::tex
