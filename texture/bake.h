// Atlases of the levels above the finest: a coarser patch gets its own charts (charts.h), packed
// at a texel size the caller ties to the node's error (atlas_pack.h), and each texel takes the
// colour of the finer surface's nearest point (the floor the patch was simplified from, textured by
// its own atlases), sampled bilinearly, or the mean of several such points across the texel when
// it is wider than the finer surface's texels. Texels around the charts (the gutter) are filled from their
// neighbours so that filtering across a chart's border does not bring in black.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "texture/image_codec.h"

namespace mt::tex {

// The finer surface: triangles with corner coordinates over their own image.
struct TexturedSurface {
  const double* positions = nullptr;  // 3 per vertex
  size_t vertexCount = 0;
  const uint32_t* triangles = nullptr;  // 3 per triangle
  size_t triangleCount = 0;
  const float* cornerUV = nullptr;    // 6 per triangle, over images[image[t]] (v = 0 at the bottom)
  const uint32_t* image = nullptr;    // 1 per triangle
  std::vector<const RgbImage*> images;
};

// Nearest-point queries on a TexturedSurface: triangles in a uniform grid.
class SurfaceIndex {
 public:
  explicit SurfaceIndex(const TexturedSurface& surface);
  // The surface's colour at its point nearest to p, among the triangles whose boxes meet the box
  // [lo, hi] (gathered once for many points); false when there is none.
  void gather(const double lo[3], const double hi[3], std::vector<uint32_t>& out) const;
  bool colorAt(const double p[3], const std::vector<uint32_t>& candidates, uint8_t rgb[3]) const;
  const TexturedSurface& surface() const { return s_; }

 private:
  const TexturedSurface& s_;
  double lo_[3], cell_;
  int dims_[3];
  std::vector<uint32_t> start_, items_;  // CSR: cell -> triangles
  std::vector<float> sphere_;            // 4 per triangle: centre, radius (pruning)
};

// Bilinear lookup, (u, v) over the image with v = 0 at the bottom, clamped at the edges.
void sampleBilinear(const RgbImage& image, double u, double v, uint8_t rgb[3]);

struct BakeResult {
  RgbImage image;
  std::vector<float> cornerUV;  // 6 per triangle, over the atlas
  double texelSize = 0;         // the one used (grown from the one asked for when it did not fit)
  uint32_t charts = 0;
};

// The atlas of triangles (positions, 3 per vertex) baked from `fine`. texelSize: world units per
// texel asked for; grown by 1.25x until the charts fit maxSide x maxSide. margin: how far the
// finer surface may be from these triangles (the simplification's measured deviation).
// fineTexelSize: the finer surface's texel size (meanTexelSize); a texel k times wider takes the
// mean of round(k) x round(k) samples (up to 4 x 4; one below 1.5 x, where the bilinear lookup
// already spans the finer texels under it), one sample when 0.
BakeResult bakeAtlas(const double* positions, size_t vertexCount, const uint32_t* triangles, size_t triangleCount,
                     const SurfaceIndex& fine, double texelSize, double margin, int maxSide = 2048, int padding = 2,
                     double fineTexelSize = 0);

// The gutter around baked charts (so bilinear lookups and mipmaps near a chart's edge do not
// mix in unrelated texels): `passes` times, each unfilled texel next to filled ones takes their
// mean and becomes filled. filled: one flag per texel, row-major, updated.
void fillGutter(RgbImage& image, std::vector<uint8_t>& filled, int passes);

// The texel size of a textured surface: sqrt(area / texel area) over all its triangles.
double meanTexelSize(const TexturedSurface& surface);

}  // namespace mt::tex
