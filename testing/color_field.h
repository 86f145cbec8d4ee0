// A procedural colour field with sharp features, for coloured test scans (mtgen --colors, and
// mtgen --paint for meshes made elsewhere, e.g. the scangen scans): colour is a pure function of
// the position, so any mesh of a shape can be painted, in any order, with the same result.
//
// Over the box it is given, in units of the box's largest side L:
//   * a coarse 3D checker (cells of L/4) of four base hues: colour edges along planes;
//   * dark stripes, 1/3 of each period of L/16, along a tilted direction: parallel sharp edges;
//   * spots: one sphere per cell of a jittered lattice of side L/10, radius L/150 to L/40, each a
//     vivid colour of its own: small isolated features, the smallest a few edges across on a 1 M
//     triangle scan, so a coarse level loses them and its colour error must say so;
//   * optionally, the stone shading of a displacement (mtgen's scans: hollows darker).
// Every edge is a step (no blending), so a renderer's and a simplifier's colour errors show.
#pragma once

#include <cstdint>

namespace mt::testing {

class ColorField {
 public:
  // lo, hi: the box the features are laid out in (the mesh's bounding box); seed: the spots'
  // layout and colours.
  ColorField(const double lo[3], const double hi[3], uint64_t seed = 1);
  // RGBA8 at p; shade in [0, 1] darkens a little (0: 85% as bright, 1: as is). Only a little: the
  // displacement it comes from varies down to two edges, far below a pixel on a large scan, and a
  // strong speckle there would make every rendering of the full resolution a noisy reference.
  void colorAt(const double p[3], uint8_t out[4], double shade = 1.0) const;

 private:
  double lo_[3], scale_ = 1;  // scale_ = 1 / L
  uint64_t seed_;
};

}  // namespace mt::testing
