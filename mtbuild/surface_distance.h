// Measured distance between two triangle meshes (a one-sided Hausdorff estimate by sampling).
// The builder's node errors are accumulated from these measurements (BMT 4.1 asks for an error
// that bounds the distance of a fragment from the surface it replaces); this is "measured", not
// an analytic bound: the max is taken over samples, so a deviation between samples is missed.
#pragma once

#include <cstddef>
#include <cstdint>

namespace mt {

// A uniform-grid index over the triangles of a mesh for nearest-point queries.
class TriangleGrid {
 public:
  // positions: 3 doubles per vertex. The mesh must outlive the grid.
  TriangleGrid(const double* positions, size_t vertexCount, const uint32_t* triangles, size_t triangleCount);
  ~TriangleGrid();
  TriangleGrid(const TriangleGrid&) = delete;
  TriangleGrid& operator=(const TriangleGrid&) = delete;
  // Distance from p to the nearest triangle (exact, not sampled); +inf when the mesh is empty.
  double distance(const double p[3]) const;

  struct Impl;
 private:
  Impl* impl_;
};

// Max over samples of the mesh (positions, triangles) -- every vertex that a triangle uses, except
// those with skipVertex[v] != 0 (known to lie on `to`, e.g. kept vertices), and every triangle
// centroid -- of the distance to the surface indexed by `to`.
double sampledDistance(const double* positions, const uint32_t* triangles, size_t triangleCount,
                       const TriangleGrid& to, const uint8_t* skipVertex = nullptr);

}  // namespace mt
