// The finest level's atlases: a patch keeps the input's texels (BMT's finest patches are the
// input's own triangles, so their texture is the input's too), re-packed per patch: the texels
// each UV island of the patch covers are cut out of the input images (with a gutter of the
// image's own neighbouring texels) and packed into one atlas; the corners' coordinates move by
// whole texels, so no texel is resampled. Only when the cut-outs do not fit maxSide x maxSide are
// they scaled by 1/2, 1/4, ... (a box filter), which the result says.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "texture/image_codec.h"

namespace mt::tex {

// Where texels come from: materials with an image (width > 0) or a flat colour.
class TexelSource {
 public:
  virtual ~TexelSource() = default;
  virtual int width(uint32_t material) const = 0;   // 0: the material has no image
  virtual int height(uint32_t material) const = 0;
  // The colour of a material without an image (or of kNoMaterial: any material index the source
  // does not know).
  virtual void flatColor(uint32_t material, uint8_t rgb[3]) const = 0;
  // Texels [x0, x0 + w) x [y0, y0 + h) of the material's image (rows top first), clamped to its
  // edges, into out (w * 3 bytes a row).
  virtual void copyRect(uint32_t material, int x0, int y0, int w, int h, uint8_t* out) const = 0;
};

struct CropResult {
  RgbImage image;
  std::vector<float> cornerUV;  // 6 per triangle, over the atlas (v = 0 at its bottom row)
  int scale = 1;                // 1: the input's texels; 2^k: cut-outs scaled by 1/2^k to fit
  uint64_t inputTexels = 0;     // texels cut out of the inputs (before scaling)
};

// triangles: 3 per triangle (vertex indices < vertexCount), cornerUV: 6 per triangle in [0, 1]
// over the triangle's material image (v = 0 at the bottom), material: 1 per triangle.
CropResult cropAtlas(const uint32_t* triangles, size_t triangleCount, size_t vertexCount, const float* cornerUV,
                     const uint32_t* material, const TexelSource& source, int maxSide = 2048, int padding = 2);

}  // namespace mt::tex
