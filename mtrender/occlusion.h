// mtrender/occlusion.h: occlusion culling with a hierarchical depth map (a max-depth pyramid) of
// a drawn frame, tested on the CPU against bounding spheres (Derzapf et al. 4.2 use hardware
// occlusion queries on node boxes; docs/mtrender.md says why a depth pyramid is used here: on
// llvmpipe a query rasterizes its box, the pyramid test is a few texel reads).
//
// Level 0 is the depth buffer (window depth in [0, 1], 1 = background); each level above keeps the
// farthest depth of 2x2 texels below. A sphere is hidden when its nearest depth lies behind the
// farthest depth of every pixel its screen rectangle covers: a conservative test (the rectangle
// bounds the sphere's projection, the texels read cover the rectangle), so nothing visible is ever
// reported hidden. A sphere that reaches the near plane is never hidden.
#pragma once

#include <cstdint>
#include <vector>

#include "mtrender/camera.h"

namespace mt::render {

class DepthPyramid {
 public:
  // `depth`: width x height window depths, rows bottom to top (glReadPixels order), drawn with
  // `view` (its matrices are used by the tests).
  void build(const std::vector<float>& depth, int width, int height, const View& view);
  bool empty() const { return levels_.empty(); }
  // True when the sphere (world centre, radius) is certainly hidden in the frame.
  bool occluded(const double center[3], double radius) const;

 private:
  struct Level {
    int width = 0, height = 0;
    std::vector<float> depth;
  };
  std::vector<Level> levels_;
  View view_;
};

}  // namespace mt::render
