// Cuts of an MT file: choosing them, assembling them into one welded mesh, and checking that the
// result is conforming. Used by the inspection tools (mtverify, mtextract), by the build tests and
// as the reference the renderer's ExtractRender is tested against. One job per file: node sets and
// cut selection (mt_cut.cpp), welding by grid position (mt_weld.cpp), the conformity check
// (mt_conformity.cpp) and the bounded edge counting it uses (mt_edge_count.h/.cpp).
//
// Vocabulary (BMT section 3.1, mt_format.h "DAG orientation"): a cut is given by a node SET that
// contains the source (node 0, full resolution), not the sink (last node), and is closed under
// predecessors (if a node is in, every `from` of its backward star is in). The rendered mesh is
// the union of the patches on the arcs LEAVING the set. Refining removes a node from the set
// (towards the source), coarsening adds one. The set {source} is the finest cut (the input at
// full resolution), the set "all but the sink" is the coarsest.
//
// Crack-free rule (what `checkConforming` decides; BRIEF "Invariants": a cut "welded by exact
// vertex position, is a conforming mesh: no boundary or non-manifold edge that the input did not
// have"). Simplification changes the edges, so the input's edges cannot be compared one for one.
// What simplification with locked region borders (BMT section 4) does NOT change is WHERE the
// mesh has borders: a boundary edge of any cut can only run along a real boundary of the input
// (scan holes, outer rim), whose vertices may be collapsed along the rim but never off it. So:
//
//   a cut is conforming iff
//     (1) every boundary edge (used by one triangle) joins two vertices that are boundary vertices
//         of the finest cut, and
//     (2) every non-manifold edge (used by three or more triangles) joins two vertices that are
//         endpoints of non-manifold edges of the finest cut.
//
// Vertices are compared by exact grid coordinate q, so the rule is sensitive to exactly the
// failures that matter: a missing patch leaves a hole bordered by vertices that are interior in
// the input (1); a shared vertex stored at a different q in two patches splits into two vertices,
// at least one of them not an input boundary vertex (1); a patch present twice or two
// overlapping fragments make edges used three or more times away from the input's own
// non-manifold edges (2). It stays true for any simplifier that keeps the input's boundary on the
// input's boundary vertices (half-edge collapse, as simplify_region.h does), and it does not
// depend on how many edges simplification left along a hole. Edge counts are reported too
// (EdgeReport) for information.
//
// Cost: the finest cut is the whole input. checkConforming(WeldedMesh) and
// makeConformityReference(WeldedMesh) need the cut assembled (about 52 bytes per triangle); the
// overloads taking a reader and the cut's arcs (section "Conformity in bounded memory") decide
// exactly the same from the patches, in parts that fit a memory budget, for any file size.
#pragma once

#include <array>
#include <cstdint>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "mtfile/mt_file.h"

namespace mt {

// ---- Node sets -----------------------------------------------------------------------------

struct Cut {
  std::vector<uint8_t> inSet;  // per node: non-zero = in the closed set
  // cutByError only: nodes whose error is within E but that were left out because one of their
  // ancestors is not (the file's errors are not monotone there). 0 on a well-formed file.
  uint32_t excludedByClosure = 0;
};

// The DAG in topological order (every arc goes from an earlier to a later node). Throws mt::Error
// "PATH: the DAG has a cycle through node N" when there is none.
std::vector<uint32_t> topologicalOrder(const MtFileReader& reader);

// Contains the source, not the sink, right size, closed under predecessors. `why` (optional)
// receives the first reason it is not.
bool isValidCut(const MtFileReader& reader, const std::vector<uint8_t>& inSet, std::string* why = nullptr);

// Adds every ancestor of every node in the set (and the source); returns how many were added.
uint32_t closeUnderPredecessors(const MtFileReader& reader, std::vector<uint8_t>& inSet);

// Arc ids leaving the set (from inside to outside), ascending.
std::vector<uint32_t> cutArcs(const MtFileReader& reader, const std::vector<uint8_t>& inSet);

Cut finestCut(const MtFileReader& reader);    // {source}
Cut coarsestCut(const MtFileReader& reader);  // every node but the sink

// A random valid cut, for testing: one of (chosen by rng) the closure of a random node subset
// (coarse-leaning), the closure of one random node (a single fragment pasted on the full
// resolution), or the coarsest cut with random nodes refined away together with their
// descendants (fine-leaning). Deterministic for a given rng state.
Cut randomCut(const MtFileReader& reader, std::mt19937_64& rng);

// The coarsest cut whose every rendered node has error <= E: the largest closed set inside
// {source} + {nodes with error <= E}. With monotone errors that is exactly the nodes with
// error <= E; on a non-monotone file the nodes below an over-E ancestor are left out (counted in
// excludedByClosure) so the bound still holds. The source is always in (error E below the
// source's error gives the finest cut).
Cut cutByError(const MtFileReader& reader, double maxError);

// The cut of at most maxTriangles triangles reached by greedy refinement from the coarsest cut,
// largest node error first (a node is refined once all its successors are), stopping at the first
// refinement that would exceed the budget. When the coarsest cut alone exceeds it, the coarsest
// cut is returned (the caller can compare cutTriangles() with the budget).
Cut cutByTriangles(const MtFileReader& reader, uint64_t maxTriangles);

// View-dependent cut (BMT 5.1): a node's screen-space error is its object-space error seen at the
// nearest point of its bounding sphere,
//     error / max(|center - eye| - radius, nearDistance) * widthPixels / (2 tan(fov/2)),
// and nodes are refined (greedily, largest first, as cutByTriangles) while it exceeds
// pixelTolerance and the budget allows. Nested spheres and monotone errors make it monotone
// along the DAG. With cullOutsideView, a sphere entirely outside the view cone (axis eye->target,
// half angle atan(sqrt(2) tan(fov/2)): covers the screen's corners for any aspect >= 1) has
// screen-space error 0, so off-screen parts stay coarse.
struct ViewParams {
  double eye[3] = {0, 0, 0};
  double target[3] = {0, 0, -1};
  double fovDegrees = 60;          // horizontal field of view
  double widthPixels = 1920;
  double pixelTolerance = 1;
  double nearDistance = 1e-9;      // object units; keeps the eye-inside-a-sphere case finite
  uint64_t maxTriangles = std::numeric_limits<uint64_t>::max();
  bool cullOutsideView = true;
};
double screenSpaceError(const format::NodeRecord& node, const ViewParams& view);
Cut cutViewDependent(const MtFileReader& reader, const ViewParams& view);

struct CutStats {
  uint32_t nodes = 0;       // in the set
  uint32_t frontNodes = 0;  // nodes of the set with an arc leaving it (whose patches are rendered)
  uint32_t arcs = 0;
  uint64_t patches = 0;
  uint64_t triangles = 0;
  double maxError = 0;      // max error over the front nodes
};
CutStats cutStats(const MtFileReader& reader, const std::vector<uint8_t>& inSet);

// ---- Assembling a cut ----------------------------------------------------------------------

struct WeldedMesh {
  std::vector<uint32_t> q;            // 3 per vertex: the global grid coordinates (the weld key)
  std::vector<double> positions;      // 3 per vertex: gridOrigin + gridStep * q
  std::vector<uint32_t> triangles;    // 3 per triangle
  std::vector<uint32_t> trianglePatch;  // 1 per triangle: the patch it came from
  std::vector<float> normals;         // 3 per vertex (mean of the patches' normals), or empty
  std::vector<uint8_t> colors;        // 4 per vertex (first patch's), or empty
  uint64_t degenerateTriangles = 0;   // dropped: two corners at one grid point
  uint64_t patches = 0;
  uint32_t vertexCount() const { return uint32_t(q.size() / 3); }
  uint32_t triangleCount() const { return uint32_t(triangles.size() / 3); }
};

// Decodes the arcs' patches in parallel (TBB), 1024 at a time, and welds them by exact grid
// coordinate, in arc order then patchRefs order (deterministic). A damaged patch throws its
// readPatch error. Peak memory: the welded mesh, its weld index (16 bytes per slot, at most 2/3
// full) and one batch of decoded patches: 2.75 GB for the 53M finest cut, written by mtextract.
WeldedMesh assembleCut(const MtFileReader& reader, const std::vector<uint32_t>& arcs);
// The arcs' patches in that order (assembleCut's).
std::vector<uint32_t> cutPatchIdsOf(const MtFileReader& reader, const std::vector<uint32_t>& arcs);

// ---- Conformity -----------------------------------------------------------------------------

struct EdgeReport {
  uint64_t edges = 0;             // undirected
  uint64_t boundaryEdges = 0;     // used by exactly one triangle
  uint64_t nonManifoldEdges = 0;  // used by three or more
  EdgeReport& operator+=(const EdgeReport& o) {
    edges += o.edges, boundaryEdges += o.boundaryEdges, nonManifoldEdges += o.nonManifoldEdges;
    return *this;
  }
};
EdgeReport countEdges(const WeldedMesh& mesh);

using GridKey = std::array<uint32_t, 3>;

// What the input (the finest cut) allows; built once per file.
struct ConformityReference {
  EdgeReport edges;
  std::vector<GridKey> boundaryVertices;     // sorted: endpoints of the finest cut's boundary edges
  std::vector<GridKey> nonManifoldVertices;  // sorted: endpoints of its non-manifold edges
};
ConformityReference makeConformityReference(const WeldedMesh& finest);

struct ConformityReport {
  EdgeReport edges;
  uint64_t newBoundaryEdges = 0;     // boundary edges violating rule (1) above
  uint64_t newNonManifoldEdges = 0;  // non-manifold edges violating rule (2)
  // The first violation, e.g. "boundary edge (x,y,z)-(x,y,z) of patch 12 (node 3) is not on the
  // input's boundary"; empty when conforming.
  std::string firstProblem;
  bool conforming() const { return newBoundaryEdges == 0 && newNonManifoldEdges == 0; }
};
// `reader` (optional) only adds node ids to firstProblem.
ConformityReport checkConforming(const WeldedMesh& cut, const ConformityReference& reference,
                                 const MtFileReader* reader = nullptr);

// ---- Conformity in bounded memory -----------------------------------------------------------
//
// The same reference and the same report as above (equal EdgeReport and violation counts; the
// firstProblem may name another violating edge), computed from the cut's arcs without assembling
// it. The cut's edge uses (per non-degenerate triangle of every patch on the arcs, in assembleCut's
// patch order; an edge is the unordered pair of its endpoints' q) are counted in one in-memory
// hash table per PART, a part being the edges whose smaller endpoint (lexicographic q) lies in a
// box of the grid and whose hash lies in a range. The parts are planned so that each fits the
// table: a k-d split of the grid at weighted quantiles of the patches' box centres into as many
// parts as the estimate needs (patch triangle counts from the index, edgesPerTriangle distinct
// edges each). A part's pass decodes, in parallel,
// only the patches whose grid box meets the part's box, so a cut costs about one decode of its
// patches however many parts it has. A part that holds more distinct edges than the table allows
// (the estimate was low: many non-manifold edges, a triangle soup) is split in two (its box at
// the middle of the longest side of its patches' extent inside it, or its hash range when that
// extent is one grid point) and counted again. Everything depends only on the file, the arcs and the options, never on thread timing:
// the counts are sums, the problem reported is the violating edge with the smallest key (its
// lowest patch id).
//
// Memory: the table takes at most EdgeCountOptions::memoryBytes minus the reference's vertex
// lists (while the reference is being built, a quarter of the budget is kept for the lists; the
// lists must fit in it, else mt::Error says so). Slots are 32 bytes, filled to at most 3/4, at
// least 4096 of them; a cut that fits one part gets a table for its estimate only. Besides the budget: up to ~60 bytes
// per patch of the cut (ids, grid boxes, the plan), one decoded patch per thread, and the file's
// own arrays. Time: about one decode of the cut's patches plus one hash-table access per distinct
// edge of each patch (a patch's uses of an edge are added up before the table sees them).

// A box of the grid, inclusive; empty (lo > hi) for a patch without vertices.
struct GridBox {
  std::array<uint32_t, 3> lo = {UINT32_MAX, UINT32_MAX, UINT32_MAX};
  std::array<uint32_t, 3> hi = {0, 0, 0};
  bool empty() const { return lo[0] > hi[0]; }
  // What a damaged patch should be given: it then meets every part and is read (and throws), as
  // assembleCut would.
  static GridBox everything() { return {{0, 0, 0}, {UINT32_MAX, UINT32_MAX, UINT32_MAX}}; }
};
GridBox patchBox(const DecodedPatch& patch);

struct EdgeCountOptions {
  uint64_t memoryBytes = uint64_t(1) << 30;  // table + reference lists (mtverify --memory)
  // Optional grid boxes of the file's patches, indexed by patch id (mtverify gathers them while
  // checkAllPatches decodes everything anyway). Without them a cut that needs more than one part
  // costs one extra decode pass to compute them.
  const std::vector<GridBox>* patchBoxes = nullptr;
  // Distinct edges per triangle assumed when planning (a closed manifold mesh has 1.5). Lower
  // values only cost passes (parts overflow and are split); tests lower it to exercise splitting.
  double edgesPerTriangle = 1.5;
  // false: parts are hash ranges only (every pass decodes every patch of the cut); for tests.
  bool spatialParts = true;
};

struct EdgeCountStats {
  uint64_t triangles = 0;      // triangles of the cut's patches, from the index
  uint32_t parts = 0;          // parts counted
  uint32_t splitParts = 0;     // parts that overflowed the table and were split (a pass wasted)
  uint64_t patchReads = 0;     // patch decodes over all passes (the cut has stats.patches)
  uint64_t patches = 0;        // patches on the cut's arcs
  uint64_t tableBytes = 0;     // the hash table's size
  double seconds = 0;
};

// The reference from the finest cut's arcs (any arcs, in fact): equal to
// makeConformityReference(assembleCut(reader, arcs)). A damaged patch throws its readPatch error.
ConformityReference makeConformityReference(const MtFileReader& reader, const std::vector<uint32_t>& arcs,
                                            const EdgeCountOptions& options = {}, EdgeCountStats* stats = nullptr);
// Equal to checkConforming(assembleCut(reader, arcs), reference, &reader) up to which violating
// edge firstProblem names. A damaged patch throws its readPatch error.
ConformityReport checkConforming(const MtFileReader& reader, const std::vector<uint32_t>& arcs,
                                 const ConformityReference& reference, const EdgeCountOptions& options = {},
                                 EdgeCountStats* stats = nullptr);
// The bytes the reference's vertex lists hold (what the table cannot have).
uint64_t referenceBytes(const ConformityReference& reference);

// ---- Payload check --------------------------------------------------------------------------

struct PatchDamage {
  uint32_t patch = 0;
  std::string message;  // readPatch's one-line error ("PATH: patch N ...")
};
// Reads and decodes every payload (in parallel) and returns the damaged ones, ascending. onPatch,
// when given, is called concurrently with every good patch.
std::vector<PatchDamage> checkAllPatches(const MtFileReader& reader,
                                         const std::function<void(uint32_t, const DecodedPatch&)>& onPatch = {});

}  // namespace mt
