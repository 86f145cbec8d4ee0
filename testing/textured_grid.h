// A small textured test mesh: a wavy n x n height field split into charts x charts UV charts,
// each mapped to a cell of the texture in a shuffled order, so every chart border is a real seam
// (the two sides name texels far apart). The texture shows a colour function of the surface
// position (texturedColor), so any re-parametrization can be checked against it.
#pragma once

#include <cstdint>
#include <string>

namespace mt::testing {

struct TexturedGridOptions {
  int n = 40;            // quads per side
  int charts = 2;        // charts per side
  int textureSize = 64;  // texels per side
  bool ply = false;      // PLY with per-face texcoord lists (else OBJ + MTL)
  bool jpeg = false;     // the texture as JPEG (else PNG)
};

// Writes DIR/NAME.obj (+ NAME.mtl) or DIR/NAME.ply, and the texture DIR/NAME.png|jpg; returns
// the mesh's path.
std::string writeTexturedGrid(const std::string& dir, const std::string& name, const TexturedGridOptions& options);

// The grid's surface: z = height(x, y) over [0, 1]^2.
double texturedGridHeight(double x, double y);
// The colour of surface point (x, y) (sharp-edged stripes and checks).
void texturedColor(double x, double y, uint8_t rgb[3]);

}  // namespace mt::testing
