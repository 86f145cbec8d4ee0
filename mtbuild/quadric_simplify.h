// Quadric edge collapse with optimal placement and per-vertex locks (Garland & Heckbert 1997,
// "Surface Simplification Using Quadric Error Metrics").
//
// Why not meshoptimizer's simplifier: meshopt 0.18 collapses half-edges only, so every kept vertex
// is an input sample and a coarse surface runs through the samples, on one side of every chord of
// a curved surface. G&H section 4 places the merged vertex at the minimum of the summed quadrics,
// which straddles the surface; ranking each collapse by the error AT that point (not at an
// endpoint) is what lowers the mean distance (docs/mtbuild.md, "Quality at equal size").
//
// What the batched MT (BMT section 4) needs on top of G&H:
//   * locked vertices (region borders) never move and never disappear; an edge between two locked
//     vertices is never collapsed, and no collapse creates an edge between two locked vertices
//     that was not there (it could duplicate an edge of a patch outside the region);
//   * topology safety: the link condition (Dey et al.; no non-manifold edge or vertex results),
//     no face flips, no sliver faces made from good ones, no vertex left without triangles;
//   * open borders (scan holes) kept in shape by G&H section 6.2's perpendicular boundary planes;
//   * optionally, moved vertices put on the MT's quantization grid (the corner of least quadric
//     error of the grid cube around the optimum, not the nearest grid point, which is a quarter
//     step off the surface on average) and kept out of any grid cell another vertex of the mesh
//     already occupies (cuts are welded by grid position);
//   * deterministic: one heap (4-ary) ordered by (cost, lower id, higher id).
#pragma once

#include <cstddef>
#include <cstdint>

namespace mt {

struct QuadricSimplifyOptions {
  // The quantization grid moved vertices are snapped to (step 0: no grid). A point p is in cell
  // floor((p - origin) / step + 0.5) on each axis, as QuantizationGrid::quantize rounds it.
  double gridStep = 0;
  double gridOrigin[3] = {0, 0, 0};
  // Weight of the boundary planes relative to the face planes (G&H 6.2 "a large penalty factor").
  double boundaryWeight = 10;
  // Per-vertex colour (mtbuild/attribute_quadric.h, Hoppe 1999): colors, 4 bytes (RGBA8) per
  // vertex, enter the collapse cost with a full-range colour difference weighing as much as a
  // distance of colorScale (model units); survivors take the colour of least error at their new
  // position, except locked vertices, which keep theirs. destinationColors (4 bytes per vertex)
  // receives every vertex's colour. Null colors or colorScale 0: geometry alone.
  const uint8_t* colors = nullptr;
  double colorScale = 0;
  uint8_t* destinationColors = nullptr;
  // How many runs the reduction is split into, each to the geometric interpolation of the counts
  // (2: the input's triangles -> sqrt(input x target) -> target), with the quadrics rebuilt from
  // the current surface before each run. 1: one run on the input's quadrics. Two runs of about
  // sqrt(2) each end closer to the input at a halving than one: a quadric summed over many
  // collapses keeps the planes of faces already far from the surface that replaced them, and
  // prices a collapse by them; rebuilt ones price it against the surface it really changes
  // (docs/mtbuild.md, "Fifth pass"). Carrying the summed quadrics into the second run instead
  // measured worse than rebuilding them.
  int passes = 1;
};

struct QuadricSimplifyStats {
  size_t collapses = 0;
  size_t rejected = 0;      // popped collapses refused by a rule (topology, locks, flips, grid)
  double maxCost = 0;       // largest quadric error of a performed collapse (squared units x area)
};

// positions: vertexCount points of 3 doubles, positionStride bytes apart. indices: indexCount
// (a multiple of 3) vertex ids < vertexCount. locked: 1 byte per vertex (non-zero = frozen) or
// null. Collapses until at most targetIndexCount indices remain or no collapse is allowed.
// destination: room for indexCount indices; receives the kept triangles (input vertex ids, in input
// order). destinationPositions: 3 doubles per vertex; receives every vertex's position (a locked
// or unmoved vertex: its input position bit for bit). moved (optional, 1 byte per vertex): set to
// 1 for vertices whose position changed (in any pass). Returns the number of indices written.
size_t quadricSimplify(uint32_t* destination, double* destinationPositions, uint8_t* moved, const uint32_t* indices,
                       size_t indexCount, const double* positions, size_t vertexCount, size_t positionStride,
                       const uint8_t* locked, size_t targetIndexCount, const QuadricSimplifyOptions& options,
                       QuadricSimplifyStats* stats = nullptr);

}  // namespace mt
