// Simplify one region of the level loop (BMT section 4: "we simplify them without touching the
// borders of Vi+1 patches") to about a target triangle count.
//
// Rules the builder relies on:
//   * a locked vertex (used by a patch outside the loaded region) is never moved or removed;
//   * every other vertex may go, including vertices on real mesh boundaries (scan holes), so a
//     scan with holes still reaches a small coarsest level; borders between patches inside the
//     region are not borders of the loaded mesh at all, hence free;
//   * a free vertex may move (quadric simplifier) and keeps the id of one input vertex it
//     replaces (origin[]), whose attributes it takes; locked vertices keep id and position bit
//     for bit, so shared vertices keep their identity and position;
//   * the returned error is MEASURED on the result (see SimplifiedRegion::error), so the builder
//     can accumulate a real, monotone error bound level by level (BMT 4.1).
//
// Two simplifiers (SimplifyRegionOptions::simplifier):
//   * Quadric: mtbuild/quadric_simplify.h, G&H 1997 edge collapse with optimal placement,
//     locks and the rules below built in. Moved vertices are put on the MT's quantization grid
//     (gridStep/gridOrigin), on the corner of least quadric error around the optimum, in a cell no
//     other vertex of the region occupies, so the quantized patches keep every vertex distinct, as
//     the grid weld left them.
//   * Meshopt (default): meshoptimizer 0.18's half-edge collapse (every output vertex is an input
//     vertex).
//     It has no per-vertex lock argument, and meshopt_SimplifyLockBorder would freeze scan holes
//     too; but it classifies a vertex that shares its position with another vertex and has no
//     matching seam as "locked": so every locked vertex gets one unreferenced duplicate appended
//     to the position array, which makes it keep that vertex exactly.
// Either result is checked against the rules the builder needs (locked vertices kept, no new
// non-manifold edge, each edge between locked vertices keeps its share of triangles, no edge with
// one triangle inside the surface) and redone with more locks if broken.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace mt {

struct LoadedMesh;

enum class RegionSimplifier : uint8_t { Quadric, Meshopt };

struct SimplifyRegionOptions {
  size_t targetTriangles = 0;  // aim; the result may stop above it (topology, locks)
  RegionSimplifier simplifier = RegionSimplifier::Meshopt;
  // The MT's quantization grid (QuantizationGrid's origin and step); step 0: none. Quadric only.
  double gridStep = 0;
  double gridOrigin[3] = {0, 0, 0};
  // Measure SimplifiedRegion::error (exact over its samples; ~0.6x the cost of meshopt_simplify).
  bool measureError = true;
  // Per-vertex colours (RGBA8, 4 per input vertex) or null. Both simplifiers carry them to the
  // result and measure SimplifiedRegion::colorError; the quadric one also weighs them in its
  // collapse costs (attribute_quadric.h) when colorWeight > 0: a full-range colour difference
  // weighs as much as a distance of colorWeight x the region's mean edge length.
  const uint8_t* colors = nullptr;
  double colorWeight = 0;
};

struct SimplifiedRegion {
  std::vector<double> positions;   // 3 per vertex: the input position, or the moved one
  std::vector<uint32_t> triangles; // 3 per triangle, indices into positions
  std::vector<uint32_t> origin;    // 1 per vertex: its index in the input (ascending)
  // Measured symmetric deviation between the result and the input region, a sampled Hausdorff
  // estimate: max of (a) the exact distance from every removed input vertex to the result and
  // (b) the distance from every moved vertex and every result triangle's centroid and edge
  // midpoints to the input; unmoved kept vertices, and the result triangles that are input
  // triangles (not queried), lie on both surfaces. Every input vertex a result vertex does not
  // sit on exactly counts as removed. Sampled, so a deviation between samples can be missed. It
  // bounds the distance to the region's INPUT (the previous level); the builder adds the
  // previous level's bound.
  double error = 0;
  double quadricError = 0;  // meshoptimizer's own estimate (absolute units), for reference (Meshopt)
  uint32_t attempts = 0;    // simplifier runs (retries after a rule was broken; for profiling)
  uint32_t movedVertices = 0;  // result vertices not at their input position
  // With SimplifyRegionOptions::colors: 4 per result vertex (the quadric simplifier's best colour
  // for a survivor of a collapse, else the input vertex's), and the measured colour deviation
  // against the input (mtbuild/color_error.h; RGBA distance in 8-bit levels).
  std::vector<uint8_t> colors;
  double colorError = 0;
  uint32_t vertexCount() const { return uint32_t(origin.size()); }
  uint32_t triangleCount() const { return uint32_t(triangles.size() / 3); }
};

// positions: 3 doubles per vertex; triangles: 3 indices per triangle; locked: 1 byte per vertex
// (non-zero = frozen) or null. Vertices no triangle uses are dropped from the result. Every
// locked vertex that a triangle uses appears in the result. Throws mt::Error on bad indices.
SimplifiedRegion simplifyRegion(const double* positions, size_t vertexCount, const uint32_t* triangles,
                                size_t triangleCount, const uint8_t* locked,
                                const SimplifyRegionOptions& options);

// The same for a region loaded from the patch store (its `locked` flags; its colours, when it has
// them, replace options.colors).
SimplifiedRegion simplifyRegion(const LoadedMesh& mesh, const SimplifyRegionOptions& options);

// Removes from a triangle list (3 vertex ids each) every pair of triangles with the same corners and
// opposite orientation whose three edges are each used by the pair alone or by exactly two other
// triangles: a thin part collapsed flat (simplify_region.cpp), unless that would leave a vertex v
// with keep[v] != 0 (when given) without a triangle, or a corner of the pair is pinned (pinned[v]
// != 0, when given: a retry keeps the pairs where the run before broke a rule). Keeps the order of
// the rest; returns the number of triangles removed.
size_t removeFlattenedPairs(std::vector<uint32_t>& triangles, const uint8_t* keep = nullptr, const uint8_t* pinned = nullptr);

}  // namespace mt
