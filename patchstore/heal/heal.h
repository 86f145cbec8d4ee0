// Healing passes on the patch store, out of core (BMT section 6: "with this scheme it is rather
// simple to perform out of core mesh healing processes like smoothing and small hole filling").
//
// Every pass streams over the patches, keeping at most a small group of patches in memory plus
// tables of size O(patches) or O(shared vertices) (or an external sort within the memory cap).
// Patch borders are treated by loading, for each edit, every patch that holds a vertex the edit
// touches (so no vertex that is edited is "locked" by an unloaded patch), and by committing the
// result through PatchStore::rewritePatches, which checks that every shared vertex stays mirrored
// in all its copies at one position. So no pass leaves a seam untreated or opens a crack.
//
// What "a vertex" is across patches: the copies of a shared vertex are one vertex; its global key
// is (owner patch, index there), the owner being the lowest-numbered patch holding it (the rule
// exportPly uses), computed from any holder's boundary list.
//
// Depends on: patchstore (store, external sort). CGAL is used only in hole_filling_cgal.cpp.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "patchstore/patch_store.h"

namespace mt::heal {

struct HealOptions {
  uint64_t memoryBytes = 256ull << 20;  // the --memory cap (external sorts and tables)
  bool progress = false;                // progress lines on stderr
  std::string tempDir;                  // scratch files; default STORE/tmp
  bool force = false;                   // run parameters refused as nonsense for the model (--force)
};

// Refused unless forced: a weld epsilon above this fraction of the store's bounding-box diagonal
// (it would merge distant parts of the model into one vertex), and a component threshold that
// removes every component.
constexpr double kMaxWeldFraction = 0.01;
constexpr uint32_t kMaxSmoothIterations = 1000000;
constexpr uint32_t kMinHoleEdges = 3, kMaxHoleEdges = 1000000;

// What a pass changed: named counts, in a fixed order, and one summary line.
struct PassReport {
  std::string pass;
  std::vector<std::pair<std::string, uint64_t>> counts;
  double seconds = 0;
  uint64_t get(const std::string& name) const;
  std::string line() const;  // "weld: 12 vertices merged in 5 clusters (0.3 s)"-like
};

// --weld EPS: merge vertices closer than eps (eps 0: exactly equal positions) into one, across
// patches too. A cluster is a connected set of the "closer than eps" graph; it becomes its member
// with the lexicographically smallest position. Triangles that become degenerate are kept (run
// --remove-degenerate after). Counts: "merged" (vertices removed), "clusters". Throws when eps is
// above kMaxWeldFraction of the bounding-box diagonal, unless options.force.
PassReport weld(PatchStore& store, double eps, const HealOptions& options);
// The cells of a quantization grid: position p is in cell floor((p - origin) / step + 0.5) per
// axis, the rounding every quantized coordinate of an MT file uses.
struct GridCells {
  double origin[3] = {0, 0, 0};
  double step = 1;
};
// Merges all vertices that fall in one grid cell into one (the member with the smallest position),
// across patches: after it, distinct vertices have distinct quantized positions, so a cut welded
// by quantized position has the same topology as the store; the triangles that become degenerate
// are removed, and so are the triangles with a repeated vertex the input had. Counts "merged"
// (vertices removed), "clusters", "degenerate" (triangles removed),
// "vertices" (dropped as unused).
PassReport weldToGrid(PatchStore& store, const GridCells& grid, const HealOptions& options);
// --remove-degenerate: triangles with a repeated vertex. Counts "triangles", "vertices" (that no
// triangle uses any more and that were dropped).
PassReport removeDegenerate(PatchStore& store, const HealOptions& options);
// --remove-duplicate-faces: triangles with the same vertex set as an earlier one (earlier: lower
// patch, then lower index, which is the order exportPly writes). Counts "triangles", "vertices".
PassReport removeDuplicateFaces(PatchStore& store, const HealOptions& options);
// --remove-unreferenced: vertices no triangle uses. Counts "vertices".
PassReport removeUnreferenced(PatchStore& store, const HealOptions& options);
// --remove-small-components N: connected components (sharing a vertex) of fewer than n triangles.
// Counts "components", "triangles", "vertices". Throws, with nothing changed, when every component
// is smaller than n (the whole surface would go), unless options.force.
PassReport removeSmallComponents(PatchStore& store, uint64_t minTriangles, const HealOptions& options);
// --fix-nonmanifold: every edge with more than two triangles stops connecting them, and every
// vertex whose triangles then form several fans is split into one vertex per fan. Decided on the
// mesh as it is before the pass (so the result does not depend on the order patches are visited).
// Counts "edges" (non-manifold edges found), "vertices" (vertices split), "added" (new vertices).
PassReport fixNonManifold(PatchStore& store, const HealOptions& options);
// --fill-holes MAXEDGES: boundary loops of at most maxEdges edges are triangulated, refined and
// faired (CGAL triangulate_refine_and_fair_hole; Liepa 2003). Counts "holes" (boundary loops
// found), "filled", "across-patches" (filled holes whose border lies in several patches), "larger" (left open: more than maxEdges), "skipped" (not a simple loop, or
// CGAL refused), "triangles" and "vertices" added.
PassReport fillHoles(PatchStore& store, uint32_t maxEdges, const HealOptions& options);
// --smooth ITER: Taubin lambda/mu smoothing (Taubin 1995) with the uniform umbrella operator over
// each vertex's whole 1-ring, borders included, as Jacobi iterations. Counts "iterations",
// "vertices".
PassReport smooth(PatchStore& store, uint32_t iterations, const HealOptions& options, double lambda = 0.5,
                  double mu = -0.53);

// ---- In-core pieces, shared with the tests' references ----

// One hole for CGAL: a band of triangles (every triangle that touches the loop), and the loop as
// band vertex indices, in the order of the band triangles' edges along it (loop[i] -> loop[i+1]
// is an edge of a band triangle with no triangle on its other side).
struct HoleBand {
  std::vector<double> positions;
  std::vector<uint32_t> triangles;
  std::vector<uint32_t> loop;
};
struct HoleFill {
  bool ok = false;     // false: the band is not a manifold CGAL accepts; nothing to add
  bool faired = false;
  std::vector<double> newPositions;     // new vertices (3 each)
  std::vector<uint32_t> newTriangles;   // indices < band vertex count: band vertices, else new
};
// In hole_filling_cgal.cpp.
HoleFill fillHoleBand(const HoleBand& band);

// The in-core reference for tests: the whole mesh as one CGAL Surface_mesh, every border cycle of
// at most maxEdges edges filled with triangulate_refine_and_fair_hole. Returns (holes, filled)
// and the filled mesh in positions/triangles. ok=false when the mesh is not a manifold.
struct ReferenceFill {
  bool ok = false;
  uint64_t holes = 0, filled = 0, larger = 0;
  std::vector<double> positions;
  std::vector<uint32_t> triangles;
};
ReferenceFill referenceFillHoles(const std::vector<double>& positions, const std::vector<uint32_t>& triangles,
                                 uint32_t maxEdges);

}  // namespace mt::heal
