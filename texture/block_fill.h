// The texels of an atlas that no chart covers (between the charts' rectangles, inside them off the
// triangles; about half a baked atlas) are never drawn at full size, but they are stored: as JPEG
// they cost what their content costs. fillEmptyBlocks makes them nearly free: each 8 x 8 block
// of the JPEG grid (blocks aligned at the image's corner, the DCT's blocks at quality >= 90 where
// chroma is not subsampled) that holds no covered texel is painted flat with a colour grown from
// its covered neighbours' blocks (one DC coefficient, coded as the difference from the block
// before), and the uncovered texels of a block that holds some take the mean of its covered
// ones (a flat run next to the chart, not a step to black). The covered texels are left as they
// are; the coarse mip levels the renderer builds from the atlas mix in neighbours' colours rather
// than black.
#pragma once

#include <cstdint>
#include <vector>

#include "texture/image_codec.h"

namespace mt::tex {

// filled: one flag per texel, row-major (the baker's, after fillGutter), all set on return. An
// image without a filled texel is left as it is.
void fillEmptyBlocks(RgbImage& image, std::vector<uint8_t>& filled, int block = 8);

}  // namespace mt::tex
