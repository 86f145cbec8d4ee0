// Measured distance between two triangle meshes (a one-sided Hausdorff estimate by sampling).
// The builder's node errors are accumulated from these measurements (BMT 4.1 asks for an error
// that bounds the distance of a fragment from the surface it replaces); this is "measured", not
// an analytic bound: the max is taken over samples, so a deviation between samples is missed.
#pragma once

#include <cstddef>
#include <cstdint>

namespace mt {

// A uniform-grid index over the triangles of a mesh for nearest-point queries.
//
// Queries are exact: the grid only decides which triangles are tested, and a triangle is skipped
// only when a lower bound of its distance (its cell's box, its bounding sphere, both with a
// relative safety margin) already exceeds the best distance found. So distance() returns exactly
// the minimum over all triangles of the point-triangle distance, bit for bit the same as a brute
// force loop with the same point-triangle routine (squaredPointTriangleDistance below).
//
// Not thread-safe: a query updates per-triangle stamps (use one grid per thread).
class TriangleGrid {
 public:
  // positions: 3 doubles per vertex. The mesh must outlive the grid.
  TriangleGrid(const double* positions, size_t vertexCount, const uint32_t* triangles, size_t triangleCount);
  ~TriangleGrid();
  TriangleGrid(const TriangleGrid&) = delete;
  TriangleGrid& operator=(const TriangleGrid&) = delete;
  // Distance from p to the nearest triangle (exact, not sampled); +inf when the mesh is empty.
  double distance(const double p[3]) const;
  // For max-of-min computations ("is this sample farther than the worst so far?"): returns the
  // exact squared distance d2 from p to the nearest triangle when d2 > floor2; otherwise stops at
  // the first triangle found within sqrt(floor2) and returns its squared distance, some value in
  // [d2, floor2]. Either way max(floor2, result) == max(floor2, d2) exactly.
  double distance2Above(const double p[3], double floor2) const;
  // The nearest triangle to p (its index; the first found among equally near ones, the same for
  // the same grid and point) and, when distance2 is given, its exact squared distance. ~0u when
  // the mesh is empty.
  uint32_t nearest(const double p[3], double* distance2 = nullptr) const;

  struct Impl;
 private:
  double search(const double p[3], double floor2, uint32_t& triangle) const;
  Impl* impl_;
};

// The point-triangle routine every query uses (Ericson, Real-Time Collision Detection 5.1.5):
// squared distance from p to triangle abc. Exposed for brute-force references in tests.
double squaredPointTriangleDistance(const double p[3], const double a[3], const double b[3], const double c[3]);
// The barycentric coordinates (of a, b, c) of the point of triangle abc nearest to p (the same
// point squaredPointTriangleDistance measures to); a degenerate triangle gets its nearest corner's.
void nearestPointBarycentric(const double p[3], const double a[3], const double b[3], const double c[3], double bary[3]);

// Max over samples of the mesh (positions, triangles) -- every vertex that a triangle uses, except
// those with skipVertex[v] != 0 (known to lie on `to`, e.g. kept vertices), and every triangle
// centroid -- of the distance to the surface indexed by `to`. Exact over those samples (each
// sample's distance is exact or provably below the running max).
double sampledDistance(const double* positions, const uint32_t* triangles, size_t triangleCount,
                       const TriangleGrid& to, const uint8_t* skipVertex = nullptr);

}  // namespace mt
