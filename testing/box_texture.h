// A parametrization and a texture for a mesh made elsewhere (mtgen --paint IN --texture box), so
// the textured pipeline is measured on scan-derived shapes (the scangen scans) and not only on
// mtgen's tori.
//
// Charts: the mesh's bounding box is cut into blocks x blocks x blocks blocks; a triangle goes to
// the chart of (the block of its centroid, the axis and sign of its normal's largest component),
// and its corners take the planar projection along that axis (box mapping). So the charts meet
// along the block planes and where the normal's dominant axis changes: seams, with the two sides
// naming texels far apart. The charts' boxes are packed in one page at one texel size (the
// largest whose charts fit the page, at most `texelsPerTriangle` texels per triangle on average).
// Parts of a chart that fold over their projection plane share texels (the last triangle drawn
// wins): the texture is then what it is, as a real scan's can be, and renderings of the input and
// of the MT file both use it.
//
// Texels: each triangle's texels show the colour field (testing/color_field.h: checks, stripes,
// spots) at the 3D point they map to, so the pattern is continuous across seams; the gutter
// around each chart repeats its border texels.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "testing/color_field.h"
#include "texture/image_codec.h"

namespace mt::testing {

struct BoxTextureOptions {
  int blocks = 2;                  // blocks per box side (charts: up to 6 * blocks^3)
  int pageSide = 4096;             // the page's largest side
  double texelsPerTriangle = 2.0;  // the texel density asked for (less when the page is full)
  int gutter = 2;                  // texels around each chart
};

struct BoxTexture {
  tex::RgbImage page;
  std::vector<float> cornerUV;  // 6 per triangle, over the page, v = 0 at the bottom
  uint32_t charts = 0;          // charts with at least one triangle
  double texelSize = 0;         // world units per texel
};

// positions: 3 per vertex; triangles: 3 per triangle.
BoxTexture boxTexture(const double* positions, size_t vertexCount, const uint32_t* triangles, size_t triangleCount,
                      const ColorField& field, const BoxTextureOptions& options);

}  // namespace mt::testing
