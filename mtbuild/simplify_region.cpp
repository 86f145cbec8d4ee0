// Region simplification with per-vertex locks (see simplify_region.h): the simplifier run, the
// builder's rules checked on its result, and the measured error.
#include "mtbuild/simplify_region.h"

#include <meshoptimizer.h>

#include <algorithm>
#include <array>
#include <cassert>
#include <cfloat>
#include <cmath>
#include <string>

#include "base/error.h"
#include "base/external_sort.h"
#include "mtbuild/color_error.h"
#include "mtbuild/quadric_simplify.h"
#include "mtbuild/surface_distance.h"
#include "patchstore/patch_store.h"

namespace mt {

namespace {

// Input adjacency, both directions, in CSR form (counting sort: two linear passes). Entries are
// not deduplicated: the number of times w appears in v's list is the number of input triangles
// that use edge v-w (each triangle lists each of its edges once per direction).
struct Adjacency {
  std::vector<uint32_t> start, adj;
  Adjacency(const uint32_t* triangles, size_t indexCount, size_t vertexCount)
      : start(vertexCount + 1, 0), adj(indexCount * 2) {
    for (size_t i = 0; i < indexCount; ++i) start[triangles[i] + 1] += 2;
    for (size_t v = 0; v < vertexCount; ++v) start[v + 1] += start[v];
    std::vector<uint32_t> fill(start.begin(), start.end() - 1);
    for (size_t t = 0; t < indexCount; t += 3)
      for (int k = 0; k < 3; ++k) {
        uint32_t a = triangles[t + k], b = triangles[t + (k + 1) % 3];
        adj[fill[a]++] = b;
        adj[fill[b]++] = a;
      }
  }
  size_t uses(uint32_t a, uint32_t b) const {
    if (start[a + 1] - start[a] > start[b + 1] - start[b]) std::swap(a, b);
    size_t n = 0;
    for (uint32_t i = start[a]; i < start[a + 1]; ++i) n += adj[i] == b;
    return n;
  }
  // v is on an open border of the input that is not the region's: some edge at v is used by one
  // input triangle and its ends are not both `locked` (such an edge between two locked vertices
  // may be the region's border, which the region cannot tell from a hole's edge; null: none).
  bool onOpenBorder(uint32_t v, const uint8_t* locked) const {
    for (uint32_t i = start[v]; i < start[v + 1]; ++i) {
      if (locked && locked[v] && locked[adj[i]]) continue;
      size_t n = 0;
      for (uint32_t j = start[v]; j < start[v + 1]; ++j) n += adj[j] == adj[i];
      if (n == 1) return true;
    }
    return false;
  }
};

// One simplifier run with `lock` frozen: the kept triangle list (input ids) in `out`, and for the
// quadric simplifier every vertex's position (`moved`: which changed).
struct Run {
  std::vector<uint32_t> out;
  std::vector<double> positions;  // Quadric only: 3 per input vertex
  std::vector<uint8_t> moved;     // Quadric only: 1 per input vertex
  bool isMoved(uint32_t v) const { return !moved.empty() && moved[v]; }
  std::vector<uint8_t> colors;    // Quadric with colours only: 4 per input vertex
  float relError = 0;             // Meshopt only
  std::vector<float> pos;         // Meshopt only: centred float positions (+ lock duplicates)
};

// meshopt 0.18 with locks: one unreferenced duplicate per locked vertex makes meshopt see a
// position shared by two vertices without a matching attribute seam and classify it Kind_Locked
// (never collapsed, but still a valid collapse target). Vertices are compared by float position,
// so two input vertices that round to the same float are also kept: conservative, never wrong.
void runMeshopt(Run& run, size_t vertexCount, const uint32_t* triangles, size_t indexCount,
                const std::vector<uint8_t>& lock, size_t targetIndexCount) {
  std::vector<float>& pos = run.pos;
  pos.resize(vertexCount * 3);
  for (size_t v = 0; v < vertexCount; ++v)
    if (lock[v]) pos.push_back(pos[v * 3]), pos.push_back(pos[v * 3 + 1]), pos.push_back(pos[v * 3 + 2]);
  run.out.resize(indexCount);
  // Error limit: none (FLT_MAX); the target count decides, the error is measured afterwards.
  size_t n = meshopt_simplify(run.out.data(), triangles, indexCount, pos.data(), pos.size() / 3, 12, targetIndexCount,
                              FLT_MAX, 0, &run.relError);
  run.out.resize(n);
}

// meshopt works in float: centre the region first so far-from-origin scans keep their precision
// (positions are only used to rank collapses; the output copies the double input positions).
void prepareMeshopt(Run& run, const double* positions, size_t vertexCount) {
  double lo[3] = {DBL_MAX, DBL_MAX, DBL_MAX}, hi[3] = {-DBL_MAX, -DBL_MAX, -DBL_MAX};
  for (size_t v = 0; v < vertexCount; ++v)
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], positions[v * 3 + a]), hi[a] = std::max(hi[a], positions[v * 3 + a]);
  run.pos.reserve(vertexCount * 6);  // room for a duplicate of every vertex
  run.pos.resize(vertexCount * 3);
  for (size_t v = 0; v < vertexCount; ++v)
    for (int a = 0; a < 3; ++a) run.pos[v * 3 + a] = float(positions[v * 3 + a] - 0.5 * (lo[a] + hi[a]));
}

// Meshopt only. Rule (3) of findBrokenRules (no new edge between locked vertices) made most regions
// run meshopt two or three times (level-1 regions of a 1M scan: 2.7 runs per region, ~44 such
// chords per region on the first run): collapsing a free vertex onto a locked neighbour joins that
// locked vertex to the free vertex's other neighbours. So every free vertex with a locked
// neighbour is locked up front (the region border's first ring). Then no locked vertex has a free
// neighbour, and since a half-edge collapse only adds neighbours to its target, no locked vertex
// ever gains one. The ring lies inside the next level's regions (BMT 4: the borders of V(i+1) and
// V(i+2) differ), which simplify it. Only when the ring is cheap: locked vertices and their ring
// all survive, so when together they would take more than half of the target's vertices the rest
// of the region would pay for them, and the retry loop alone is used instead. (The quadric
// simplifier checks the rule per collapse and needs no ring.)
void lockBorderRing(std::vector<uint8_t>& lock, const uint8_t* locked, const std::vector<uint8_t>& used,
                    const Adjacency& adjacency, size_t targetIndexCount) {
  std::vector<uint32_t> ring;
  size_t lockedUsed = 0;
  for (size_t v = 0; v < lock.size(); ++v) {
    if (!used[v]) continue;
    if (locked[v]) {
      ++lockedUsed;
      continue;
    }
    for (uint32_t i = adjacency.start[v]; i < adjacency.start[v + 1]; ++i)
      if (locked[adjacency.adj[i]]) {
        ring.push_back(uint32_t(v));
        break;
      }
  }
  if ((lockedUsed + ring.size()) * 4 <= targetIndexCount / 3)
    for (uint32_t v : ring) lock[v] = 1;
}

}  // namespace

// Meshopt only. Rule (2) of findBrokenRules (no new edge used by 3+ triangles) made regions of
// scan-derived meshes run meshopt 1.3-1.9 times on average (generated meshes: ~1.0), each retry a
// whole run thrown away. The broken edges are interior and new, mostly shared by exactly four
// triangles: a thin part of the surface (a fin, the tip of a tube; the input around it is flat and
// manifold, so no lock up front can foresee it) collapsed flat into two triangles with the same
// corners and opposite orientation, glued to the surface on either side. Such a pair encloses
// nothing; removing both leaves every one of its edges with the two triangles of the surface
// around it. Pairs are removed only where that holds: each edge of the pair is used by the pair
// alone (the whole flattened piece goes) or by exactly two other triangles; any other rule break
// still triggers the retry. The error is measured on the result afterwards, the removal included.
// A pair whose removal would leave a vertex of `keep` without a triangle stays: a double-sided
// triangle the input already has (scan debris, or a sliver the grid weld folded) at a locked
// vertex would otherwise be removed from every run, the vertex vanish each time (rule 1), and the
// region be run 17 times and kept whole, at every level (a 5.7 M scan-derived elephant: 33
// regions so, the level loop 2.5x as long, the root level refused). Returns the number of
// triangles removed.
size_t removeFlattenedPairs(std::vector<uint32_t>& out, const uint8_t* keep, const uint8_t* pinned) {
  const size_t triangleCount = out.size() / 3;
  // Triangles keyed by their sorted corners, in an open-addressing table (most results have no
  // pair at all, so one linear pass, not a sort of every triangle); a pair is a key held by exactly
  // two triangles of opposite orientation.
  struct Slot {
    std::array<uint32_t, 3> key;
    uint32_t first, second, count;
  };
  size_t capacity = 16;
  while (capacity < 2 * triangleCount) capacity *= 2;
  std::vector<Slot> table(capacity, Slot{{0, 0, 0}, 0, 0, 0});
  for (size_t t = 0; t < triangleCount; ++t) {
    std::array<uint32_t, 3> k = {out[t * 3], out[t * 3 + 1], out[t * 3 + 2]};
    std::sort(k.begin(), k.end());
    const uint64_t hash = (k[0] * 0x9E3779B97F4A7C15ull) ^ (k[1] * 0xC2B2AE3D27D4EB4Full) ^ (k[2] * 0x165667B19E3779F9ull);
    for (size_t h = size_t(hash >> 17) & (capacity - 1);; h = (h + 1) & (capacity - 1)) {
      Slot& s = table[h];
      if (s.count == 0) {
        s = {k, uint32_t(t), 0, 1};
        break;
      }
      if (s.key == k) {
        if (++s.count == 2) s.second = uint32_t(t);
        break;
      }
    }
  }
  auto orientation = [&](uint32_t t) {  // even (+1) or odd (-1) permutation of the sorted corners
    const uint32_t a = out[t * 3], b = out[t * 3 + 1], c = out[t * 3 + 2];
    return (a < b) + (b < c) + (c < a) == 2 ? 1 : -1;
  };
  std::vector<std::pair<uint32_t, uint32_t>> pairs;
  for (const Slot& s : table)
    if (s.count == 2 && orientation(s.first) != orientation(s.second)) pairs.push_back({s.first, s.second});
  if (pairs.empty()) return 0;
  // Uses of the pairs' edges over the whole output.
  std::vector<uint64_t> edges;
  auto key = [](uint64_t a, uint64_t b) { return a < b ? a << 32 | b : b << 32 | a; };
  for (auto& p : pairs)
    for (int k = 0; k < 3; ++k) edges.push_back(key(out[p.first * 3 + k], out[p.first * 3 + (k + 1) % 3]));
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  std::vector<uint32_t> uses(edges.size(), 0);
  for (size_t t = 0; t < triangleCount; ++t)
    for (int k = 0; k < 3; ++k) {
      const uint64_t e = key(out[t * 3 + k], out[t * 3 + (k + 1) % 3]);
      auto it = std::lower_bound(edges.begin(), edges.end(), e);
      if (it != edges.end() && *it == e) ++uses[it - edges.begin()];
    }
  // Triangles per vertex of `keep`, for the pairs' corners only (counted down as pairs go).
  std::vector<uint32_t> fanSize;
  if (keep) {
    uint32_t maxId = 0;
    for (uint32_t v : out) maxId = std::max(maxId, v);
    fanSize.assign(size_t(maxId) + 1, 0);
    for (uint32_t v : out) fanSize[v] += keep[v] != 0;
  }
  std::vector<uint8_t> drop(triangleCount, 0);
  for (auto& p : pairs) {
    bool ok = true;
    for (int k = 0; k < 3; ++k) {
      uint32_t u = uses[std::lower_bound(edges.begin(), edges.end(), key(out[p.first * 3 + k], out[p.first * 3 + (k + 1) % 3])) - edges.begin()];
      ok &= u == 2 || u == 4;
      if (keep && keep[out[p.first * 3 + k]]) ok &= fanSize[out[p.first * 3 + k]] > 2;
      if (pinned) ok &= !pinned[out[p.first * 3 + k]];
    }
    if (!ok) continue;
    drop[p.first] = drop[p.second] = 1;
    if (keep)
      for (int k = 0; k < 3; ++k) fanSize[out[p.first * 3 + k]] -= keep[out[p.first * 3 + k]] ? 2 : 0;
  }
  size_t w = 0;
  for (size_t t = 0; t < triangleCount; ++t)
    if (!drop[t])
      for (int k = 0; k < 3; ++k) out[w++] = out[t * 3 + k];
  const size_t removed = triangleCount - w / 3;
  out.resize(w);
  return removed;
}

namespace {

// What the builder needs and neither simplifier promises for every input (the quadric one checks
// the same per collapse, but inputs that are non-manifold already can defeat a local check):
// (1) a locked vertex vanished (all its triangles collapsed away); (2) an output edge is used by 3+
// triangles that the input did not have so (two hole borders pinched together: a crack-like
// defect in a cut); (3) an edge between two locked vertices changed its count of triangles other
// than from 3+ down to no fewer than 2. The region cannot see the edge's triangles outside it, so
// it keeps its own share: a new edge (a chord across the region's border can duplicate an edge an
// outside patch already has, and the two sheets touch along it: found on a closed torus), or a
// share that drops to 0 or 1, can leave the edge with one triangle (a crack) or with 3+ where the
// finest cut had neither. On a manifold input a collapse keeps every edge's count (a border edge
// keeps its triangle in the neighbouring one); on a non-manifold one an edge shared by three
// triangles of two regions lost the two of one region (a scan of CGAL's boeing with strong noise:
// 1 of 10 cuts conforming); (4) an output edge used by one triangle that is not such an edge of
// the input joins a vertex that is not on an open border of the input (Adjacency::onOpenBorder;
// mtverify's rule, mt_cut.h: a cut's boundary edges join boundary vertices of the finest cut). On a
// manifold input neither simplifier breaks it: a border vertex only collapses along its border, so
// the ends of a new border edge each had an open edge to the free vertex that went. On a
// non-manifold one both can: the sheets around an edge used by three triangles, or two fans
// pinched at one vertex, look manifold to a local check, and a collapse there can leave an edge
// with one triangle in the middle of the surface (a hole in every cut that holds it: 1-6 of 10
// cuts of scans of CGAL's bull, boeing and ALSTOM models), also from a vertex that is on the
// region's border only (boeing, regular partition).
// Marks the vertices involved in `bad`; returns whether any rule was broken.
bool findBrokenRules(const std::vector<uint32_t>& out, const std::vector<uint8_t>& lock,
                     const std::vector<uint8_t>& used, const uint8_t* locked, const Adjacency& adjacency,
                     std::vector<uint8_t>& kept, std::vector<uint8_t>& bad) {
  const size_t vertexCount = lock.size();
  std::fill(kept.begin(), kept.end(), 0);
  std::fill(bad.begin(), bad.end(), 0);
  for (uint32_t v : out) kept[v] = 1;
  bool problem = false;
  for (size_t v = 0; v < vertexCount; ++v)
    if (lock[v] && used[v] && !kept[v]) bad[v] = 1, problem = true;
  // Output edges bucketed by their smaller vertex (counting sort), to count each edge's triangles.
  std::vector<uint32_t> edgeStart(vertexCount + 1, 0), edgeOther(out.size());
  for (size_t t = 0; t < out.size(); t += 3)
    for (int k = 0; k < 3; ++k) ++edgeStart[std::min(out[t + k], out[t + (k + 1) % 3]) + 1];
  for (size_t v = 0; v < vertexCount; ++v) edgeStart[v + 1] += edgeStart[v];
  std::vector<uint32_t> edgeFill(edgeStart.begin(), edgeStart.end() - 1);
  for (size_t t = 0; t < out.size(); t += 3)
    for (int k = 0; k < 3; ++k) {
      uint32_t a = out[t + k], b = out[t + (k + 1) % 3];
      edgeOther[edgeFill[std::min(a, b)]++] = std::max(a, b);
    }
  std::vector<uint32_t> count(vertexCount, 0);
  for (size_t v = 0; v < vertexCount; ++v) {
    uint32_t e0 = edgeStart[v], e1 = edgeStart[v + 1];
    for (uint32_t e = e0; e < e1; ++e) ++count[edgeOther[e]];
    for (uint32_t e = e0; e < e1; ++e) {
      const uint32_t w = edgeOther[e], n = count[w];
      const bool between = locked && locked[v] && locked[w];
      if (n == 2 && !between) continue;  // no rule looks at the input's count then
      const size_t was = adjacency.uses(uint32_t(v), w);
      bool broken = n >= 3 && was <= 2;                              // rule 2
      broken |= between && n != was && (n <= 1 || n > was);         // rule 3
      // Rule 4; an input boundary edge kept as it is (the region's border, a hole's) is the
      // common case and is settled by the count.
      broken |= n == 1 && was != 1 &&
                !(adjacency.onOpenBorder(uint32_t(v), locked) && adjacency.onOpenBorder(w, locked));
      if (broken) bad[v] = bad[w] = 1, problem = true;
    }
    for (uint32_t e = e0; e < e1; ++e) count[edgeOther[e]] = 0;
  }
  // Rule 3 for the edges between locked vertices that the output no longer has.
  if (locked)
    for (uint32_t a = 0; a < vertexCount; ++a) {
      if (!locked[a]) continue;
      for (uint32_t i = adjacency.start[a]; i < adjacency.start[a + 1]; ++i) {
        const uint32_t b = adjacency.adj[i];
        if (b <= a || !locked[b]) continue;
        bool present = false;
        for (uint32_t e = edgeStart[a]; e < edgeStart[a + 1] && !present; ++e) present = edgeOther[e] == b;
        if (!present) bad[a] = bad[b] = 1, problem = true;
      }
    }
  return problem;
}

// The mean length of the triangles' edges (each edge once per triangle that uses it).
double meanEdgeLength(const double* positions, const uint32_t* triangles, size_t indexCount) {
  double sum = 0;
  for (size_t t = 0; t + 2 < indexCount; t += 3)
    for (int k = 0; k < 3; ++k) {
      const double *a = positions + size_t(triangles[t + k]) * 3, *b = positions + size_t(triangles[t + (k + 1) % 3]) * 3;
      sum += std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]));
    }
  return indexCount ? sum / double(indexCount) : 0;
}

// Runs the chosen simplifier until its result keeps the builder's rules (findBrokenRules): after a
// broken rule the input triangles around the offending vertices are locked and the run redone.
// Deterministic; usually runs once. Fills `kept`; returns the number of runs.
int simplifyWithRules(Run& run, const double* positions, size_t vertexCount, const uint32_t* triangles,
                      size_t indexCount, const uint8_t* locked, const std::vector<uint8_t>& used,
                      const Adjacency& adjacency, const SimplifyRegionOptions& options, std::vector<uint8_t>& kept) {
  const bool quadric = options.simplifier == RegionSimplifier::Quadric;
  const size_t targetIndexCount = std::min(options.targetTriangles * 3, indexCount);
  std::vector<uint8_t> lock(vertexCount, 0), bad(vertexCount), pinned(vertexCount, 0);
  if (locked)
    for (size_t v = 0; v < vertexCount; ++v) lock[v] = locked[v] ? 1 : 0;
  if (!quadric) {
    prepareMeshopt(run, positions, vertexCount);
    if (locked) lockBorderRing(lock, locked, used, adjacency, targetIndexCount);
  }
  QuadricSimplifyOptions qo;
  // Two runs of about sqrt(2) each per halving, the quadrics rebuilt between them: closer to the
  // input at equal size than one run (quadric_simplify.h, QuadricSimplifyOptions::passes).
  qo.passes = 2;
  qo.gridStep = options.gridStep;
  for (int a = 0; a < 3; ++a) qo.gridOrigin[a] = options.gridOrigin[a];
  if (quadric && options.colors && options.colorWeight > 0) {
    qo.colors = options.colors;
    qo.colorScale = options.colorWeight * meanEdgeLength(positions, triangles, indexCount);
    run.colors.resize(vertexCount * 4);
    qo.destinationColors = run.colors.data();
  }
  for (int attempt = 0;; ++attempt) {
    if (quadric) {
      run.out.resize(indexCount);
      run.positions.resize(vertexCount * 3);
      run.moved.resize(vertexCount);
      size_t n = quadricSimplify(run.out.data(), run.positions.data(), run.moved.data(), triangles, indexCount,
                                 positions, vertexCount, 3 * sizeof(double), lock.data(), targetIndexCount, qo);
      run.out.resize(n);
    } else {
      runMeshopt(run, vertexCount, triangles, indexCount, lock, targetIndexCount);
      removeFlattenedPairs(run.out, lock.data(), pinned.data());
    }
    const bool broken = findBrokenRules(run.out, lock, used, locked, adjacency, kept, bad);
    // A region that had triangles keeps some: a closed component alone in its region (a
    // tetrahedron, a speck of scan debris) can collapse to nothing below any target, and an empty
    // fragment would leave its node without patches, without an arc to the sink and with an
    // unbounded error (no surface to measure against) that every node above it inherits.
    const bool vanished = run.out.empty() && indexCount > 0;
    if (!broken && !vanished) return attempt + 1;
    // The next run sees what this one saw plus the offending vertices: their triangles locked, and
    // the flattened pairs at them kept (a pair of the input removed at the region's border takes an
    // edge between two locked vertices with it, which rule 3 refuses; with every triangle around
    // already locked, only keeping the pair lets the run pass: scans with strong noise ran 17 times
    // and were kept whole). A run that would see nothing new would repeat this one: stop then.
    bool progress = false;
    if (broken && !vanished) {
      for (size_t v = 0; v < vertexCount; ++v)
        if (bad[v] && !pinned[v]) pinned[v] = 1, progress |= !quadric;
      for (size_t t = 0; t < indexCount; t += 3)
        if (bad[triangles[t]] || bad[triangles[t + 1]] || bad[triangles[t + 2]])
          for (int k = 0; k < 3; ++k)
            if (!lock[triangles[t + k]]) lock[triangles[t + k]] = 1, progress = true;
    }
    if (attempt == 16 || !progress) {
      // Rare (seen on inputs that are non-manifold already, and on closed components that
      // vanish): keep the region as it is. An unsimplified region is always a valid fragment; the
      // level above simplifies it.
      run.out.assign(triangles, triangles + indexCount);
      run.moved.assign(run.moved.size(), 0);
      run.positions.assign(positions, positions + run.positions.size());
      if (!run.colors.empty()) run.colors.assign(options.colors, options.colors + run.colors.size());
      std::fill(kept.begin(), kept.end(), 0);
      for (uint32_t v : run.out) kept[v] = 1;
      return attempt + 1;
    }
  }
}

// Fills r.origin, r.positions and r.triangles from the run (kept vertices in input order), and
// r.colors when the input has colours.
void assembleResult(SimplifiedRegion& r, const Run& run, const double* positions, const std::vector<uint8_t>& kept,
                    const uint8_t* colors) {
  const size_t vertexCount = kept.size();
  std::vector<uint32_t> remap(vertexCount, ~0u);
  size_t keptCount = 0;
  for (size_t v = 0; v < vertexCount; ++v) keptCount += kept[v];
  r.origin.reserve(keptCount);
  r.positions.resize(keptCount * 3);
  const double* from = run.positions.empty() ? positions : run.positions.data();
  for (size_t v = 0; v < vertexCount; ++v)
    if (kept[v]) {
      uint32_t i = uint32_t(r.origin.size());
      remap[v] = i;
      r.origin.push_back(uint32_t(v));
      for (int a = 0; a < 3; ++a) r.positions[size_t(i) * 3 + a] = from[v * 3 + a];
      r.movedVertices += run.isMoved(uint32_t(v));
      if (colors) {
        const uint8_t* c = run.colors.empty() ? colors + v * 4 : &run.colors[v * 4];
        r.colors.insert(r.colors.end(), c, c + 4);
      }
    }
  r.triangles.resize(run.out.size());
  for (size_t i = 0; i < run.out.size(); ++i) r.triangles[i] = remap[run.out[i]];
}

// What measureError can leave out, per result triangle, marked while the rules' adjacency exists
// (it is freed before the result and the grids are built). Samples on the input are at distance 0
// from it and cannot raise the max:
//  - kOnInput: the triangle is an input triangle with unmoved corners (a third of the result
//    triangles at the level loop's halving). Both simplifiers keep the survivors in input order,
//    so one merge-like walk finds them; a survivor out of order would only be queried like the
//    others.
//  - bit e, for the other triangles: the edge from corner e to corner e + 1 is an edge of the
//    input between unmoved vertices, so it lies on an input triangle (a half-edge collapse keeps
//    the edges opposite the removed vertex, so many result edges are such).
constexpr uint8_t kOnInput = 8;
std::vector<uint8_t> samplesOnInput(const Run& run, const std::vector<uint8_t>& kept, const uint32_t* triangles,
                                    size_t indexCount, const Adjacency& adjacency) {
  const std::vector<uint32_t>& out = run.out;
  auto still = [&](uint32_t v) { return kept[v] && !run.isMoved(v); };
  std::vector<uint8_t> mask(out.size() / 3, 0);
  for (size_t t = 0, i = 0; t < out.size(); t += 3) {
    while (i < indexCount && !(still(triangles[i]) && still(triangles[i + 1]) && still(triangles[i + 2]))) i += 3;
    if (i < indexCount && out[t] == triangles[i] && out[t + 1] == triangles[i + 1] && out[t + 2] == triangles[i + 2])
      mask[t / 3] = kOnInput, i += 3;
  }
  for (size_t t = 0; t < mask.size(); ++t)
    if (!mask[t])
      for (int e = 0; e < 3; ++e) {
        const uint32_t a = out[t * 3 + e], b = out[t * 3 + (e + 1) % 3];
        if (still(a) && still(b) && adjacency.uses(a, b) > 0) mask[t] |= uint8_t(1u << e);
      }
  return mask;
}

// The measured error (SimplifiedRegion::error): the max over samples of the exact distance to the
// other surface:
//   (a) input -> result: every input vertex no result vertex sits on (removed or moved);
//   (b) result -> input: moved vertices, and the centroids and edge midpoints of result triangles,
//       except for the result triangles that are input triangles with unmoved corners, and for
//       the edges that are input edges between unmoved vertices (samplesOnInput): both lie on
//       the input. Their true distance is 0; the value a query computed for them could exceed it
//       only by rounding, or on a (near-)degenerate input triangle (pointTriangle2's interior
//       case), so leaving them out never raises the error.
// Each query only has to decide whether its sample is farther than the worst so far
// (TriangleGrid::distance2Above), which most samples are not; the value is the same as computing
// every sample's distance exactly. A strided subset of all samples goes first so the running worst
// is large early and the other queries stop at their first close triangle.
double measureError(const SimplifiedRegion& r, const Run& run, const double* positions, size_t vertexCount,
                    const uint32_t* triangles, size_t indexCount, const std::vector<uint8_t>& used,
                    const std::vector<uint8_t>& kept, const std::vector<uint8_t>& onInput) {
  const std::vector<uint32_t>& out = run.out;
  const double* at = run.positions.empty() ? positions : run.positions.data();  // result positions by input id
  TriangleGrid resultGrid(r.positions.data(), r.origin.size(), r.triangles.data(), r.triangleCount());
  TriangleGrid inputGrid(positions, vertexCount, triangles, indexCount / 3);
  auto still = [&](uint32_t v) { return kept[v] && !run.isMoved(v); };
  // (lower, higher) input vertex ids of the queried triangles' edges, less the input edges
  // between unmoved vertices (samplesOnInput), packed in 2 * idBits bits for a radix sort of a few
  // passes (std::sort's unpredictable compares were ~1% of a build's samples, the radix ~0.3%).
  const unsigned idBits = vertexCount > 1 ? 64 - unsigned(__builtin_clzll(uint64_t(vertexCount - 1))) : 1;
  const uint64_t idMask = (uint64_t(1) << idBits) - 1;
  std::vector<uint64_t> edges;
  edges.reserve(out.size());
  for (size_t t = 0; t < out.size() / 3; ++t)
    if (!(onInput[t] & kOnInput))
      for (int e = 0; e < 3; ++e) {
        if ((onInput[t] >> e) & 1) continue;
        const uint32_t a = out[t * 3 + e], b = out[t * 3 + (e + 1) % 3];
        assert(a < vertexCount && b < vertexCount);
        edges.push_back(a < b ? uint64_t(a) << idBits | b : uint64_t(b) << idBits | a);
      }
  {
    std::vector<uint64_t> tmp(edges.size());
    const uint64_t* sorted = radixSort(edges.data(), tmp.data(), edges.size(), [](uint64_t x) { return x; }, 2 * idBits);
    if (sorted != edges.data()) edges.swap(tmp);
  }
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  constexpr size_t kStride = 16;
  double worst2 = 0;
  for (int pass = 0; pass < 2; ++pass) {
    size_t k = 0;
    for (size_t v = 0; v < vertexCount; ++v)
      if (used[v] && !still(uint32_t(v)) && ((k++ % kStride == 0) == (pass == 0)))
        worst2 = std::max(worst2, resultGrid.distance2Above(positions + v * 3, worst2));
    k = 0;
    for (size_t v = 0; v < vertexCount; ++v)
      if (kept[v] && run.isMoved(uint32_t(v)) && ((k++ % kStride == 0) == (pass == 0)))
        worst2 = std::max(worst2, inputGrid.distance2Above(at + v * 3, worst2));
    for (size_t t = 0; t < out.size() / 3; ++t) {
      if ((t % kStride == 0) != (pass == 0) || (onInput[t] & kOnInput)) continue;
      const double *p0 = at + size_t(out[t * 3]) * 3, *p1 = at + size_t(out[t * 3 + 1]) * 3,
                   *p2 = at + size_t(out[t * 3 + 2]) * 3;
      double c[3];
      for (int a = 0; a < 3; ++a) c[a] = (p0[a] + p1[a] + p2[a]) / 3;
      worst2 = std::max(worst2, inputGrid.distance2Above(c, worst2));
    }
    // The midpoint of every edge of those triangles, each once: on noisy scans the farthest point
    // of a large result triangle from the input is often near an edge, and centroids alone left
    // the stored error up to 11% below MeshLab's Hausdorff (0.3 M dragon scan, level 1).
    for (size_t e = 0; e < edges.size(); ++e) {
      if ((e % kStride == 0) != (pass == 0)) continue;
      const double *a0 = at + size_t(edges[e] >> idBits) * 3, *a1 = at + size_t(edges[e] & idMask) * 3;
      double m[3];
      for (int a = 0; a < 3; ++a) m[a] = 0.5 * (a0[a] + a1[a]);
      worst2 = std::max(worst2, inputGrid.distance2Above(m, worst2));
    }
  }
  return std::sqrt(worst2);
}

}  // namespace

SimplifiedRegion simplifyRegion(const double* positions, size_t vertexCount, const uint32_t* triangles,
                                size_t triangleCount, const uint8_t* locked, const SimplifyRegionOptions& options) {
  const size_t indexCount = triangleCount * 3;
  std::vector<uint8_t> used(vertexCount, 0);
  for (size_t i = 0; i < indexCount; ++i) {
    if (triangles[i] >= vertexCount)
      throw Error("simplifyRegion: triangle " + std::to_string(i / 3) + " uses vertex " +
                  std::to_string(triangles[i]) + " of " + std::to_string(vertexCount));
    used[triangles[i]] = 1;
  }
  Run run;
  std::vector<uint8_t> kept(vertexCount);
  SimplifiedRegion r;
  std::vector<uint8_t> onInput;  // per result triangle (samplesOnInput), for measureError
  {
    const Adjacency adjacency(triangles, indexCount, vertexCount);
    r.attempts = uint32_t(simplifyWithRules(run, positions, vertexCount, triangles, indexCount, locked, used, adjacency, options, kept));
    if (options.measureError) onInput = samplesOnInput(run, kept, triangles, indexCount, adjacency);
  }
  assembleResult(r, run, positions, kept, options.colors);
  if (options.simplifier == RegionSimplifier::Meshopt && vertexCount)
    r.quadricError = double(run.relError) * double(meshopt_simplifyScale(run.pos.data(), vertexCount, 12));
  if (options.measureError && (run.out.size() < indexCount || r.movedVertices))
    r.error = measureError(r, run, positions, vertexCount, triangles, indexCount, used, kept, onInput);
  if (options.measureError && options.colors && (run.out.size() < indexCount || r.movedVertices || !run.colors.empty())) {
    ColorErrorInput ce;
    ce.positions = positions;
    ce.colors = options.colors;
    ce.vertexCount = vertexCount;
    ce.triangles = triangles;
    ce.triangleCount = triangleCount;
    ce.resultPositions = r.positions.data();
    ce.resultColors = r.colors.data();
    ce.origin = r.origin.data();
    ce.resultVertexCount = r.origin.size();
    ce.resultTriangles = r.triangles.data();
    ce.resultTriangleCount = r.triangleCount();
    r.colorError = measureColorError(ce);
  }
  return r;
}

SimplifiedRegion simplifyRegion(const LoadedMesh& mesh, const SimplifyRegionOptions& options) {
  SimplifyRegionOptions o = options;
  if (!mesh.colors.empty()) o.colors = mesh.colors.data();
  return simplifyRegion(mesh.positions.data(), mesh.vertexCount(), mesh.triangles.data(), mesh.triangleCount(),
                        mesh.locked.empty() ? nullptr : mesh.locked.data(), o);
}

}  // namespace mt
