// The measured colour deviation between a simplified region and its input, the colour half of a
// node's error (the geometric half is SimplifiedRegion::error, measured the same way).
//
// A point's colour on a mesh with per-vertex colours is the linear interpolation of its triangle's
// corner colours (what the renderers draw). The deviation is the max, over samples, of the RGBA
// distance (Euclidean, in 8-bit levels: 0..510) between the colour of a sample on one mesh and the
// colour of the nearest point of the other:
//   (a) input -> result: every input vertex that no result vertex reproduces exactly (same
//       position, same colour): removed, moved and recoloured vertices;
//   (b) result -> input: every result vertex that moved or changed colour, and the centroid of
//       every result triangle that is not an input triangle with reproduced corners.
// Sampled, like the geometric error: a colour feature smaller than the samples' spacing can be
// missed; the input's own vertices are all checked, so a lost colour spot of one vertex is not.
#pragma once

#include <cstddef>
#include <cstdint>

namespace mt {

struct ColorErrorInput {
  // The input region: positions (3 per vertex), colours (RGBA8, 4 per vertex), triangles.
  const double* positions = nullptr;
  const uint8_t* colors = nullptr;
  size_t vertexCount = 0;
  const uint32_t* triangles = nullptr;
  size_t triangleCount = 0;
  // The result: positions and colours per result vertex, triangles in result ids, and for every
  // result vertex the input vertex whose identity it keeps (origin).
  const double* resultPositions = nullptr;
  const uint8_t* resultColors = nullptr;
  const uint32_t* origin = nullptr;
  size_t resultVertexCount = 0;
  const uint32_t* resultTriangles = nullptr;
  size_t resultTriangleCount = 0;
};

// The max RGBA distance (8-bit levels) over the samples above; 0 when the result reproduces the
// input (or either is empty).
double measureColorError(const ColorErrorInput& in);

}  // namespace mt
