// Region simplification with per-vertex locks on meshoptimizer 0.18 (see simplify_region.h).
#include "mtbuild/simplify_region.h"

#include <meshoptimizer.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <string>

#include "base/error.h"
#include "mtbuild/surface_distance.h"
#include "patchstore/patch_store.h"

namespace mt {

namespace {

// Runs meshopt_simplify with `lock` frozen; returns the kept triangle list (input indices) in `out`.
// `pos` holds the vertexCount float positions; it is extended in place (and trimmed back on the
// next call) with the lock duplicates, so retries reuse its storage.
void simplifyLocked(std::vector<float>& pos, size_t vertexCount, const uint32_t* triangles, size_t indexCount,
                    const std::vector<uint8_t>& lock, size_t targetIndexCount, float* relError,
                    std::vector<uint32_t>& out) {
  // One unreferenced duplicate per locked vertex: meshopt 0.18 then sees a position shared by two
  // vertices without a matching attribute seam and classifies it Kind_Locked (never collapsed,
  // but still a valid collapse target). Vertices are compared by float position, so two input
  // vertices that round to the same float are also kept: conservative, never wrong.
  pos.resize(vertexCount * 3);
  for (size_t v = 0; v < vertexCount; ++v)
    if (lock[v]) pos.push_back(pos[v * 3]), pos.push_back(pos[v * 3 + 1]), pos.push_back(pos[v * 3 + 2]);
  out.resize(indexCount);
  // Error limit: none (FLT_MAX); the target count decides, the error is measured afterwards.
  size_t n = meshopt_simplify(out.data(), triangles, indexCount, pos.data(), pos.size() / 3, 12, targetIndexCount,
                              FLT_MAX, 0, relError);
  out.resize(n);
}

}  // namespace

SimplifiedRegion simplifyRegion(const double* positions, size_t vertexCount, const uint32_t* triangles,
                                size_t triangleCount, const uint8_t* locked, const SimplifyRegionOptions& options) {
  size_t indexCount = triangleCount * 3;
  std::vector<uint8_t> used(vertexCount, 0);
  for (size_t i = 0; i < indexCount; ++i) {
    if (triangles[i] >= vertexCount)
      throw Error("simplifyRegion: triangle " + std::to_string(i / 3) + " uses vertex " +
                  std::to_string(triangles[i]) + " of " + std::to_string(vertexCount));
    used[triangles[i]] = 1;
  }

  // meshopt works in float: center the region first so far-from-origin scans keep their precision
  // (positions are only used to rank collapses; the output copies the double input positions).
  double lo[3] = {DBL_MAX, DBL_MAX, DBL_MAX}, hi[3] = {-DBL_MAX, -DBL_MAX, -DBL_MAX};
  for (size_t v = 0; v < vertexCount; ++v)
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], positions[v * 3 + a]), hi[a] = std::max(hi[a], positions[v * 3 + a]);
  std::vector<uint8_t> lock(vertexCount, 0);
  if (locked)
    for (size_t v = 0; v < vertexCount; ++v) lock[v] = locked[v] ? 1 : 0;
  std::vector<float> pos;
  pos.reserve(vertexCount * 6);  // room for a duplicate of every vertex (locks and their first ring)
  pos.resize(vertexCount * 3);
  for (size_t v = 0; v < vertexCount; ++v)
    for (int a = 0; a < 3; ++a) pos[v * 3 + a] = float(positions[v * 3 + a] - 0.5 * (lo[a] + hi[a]));

  size_t targetIndexCount = std::min(options.targetTriangles, triangleCount) * 3;
  float relError = 0;
  std::vector<uint32_t> out;
  // Things meshopt 0.18 does not promise and the builder needs: (1) a locked vertex can vanish
  // when all its triangles collapse away (a locked corner whose other two vertices merge); (2) a
  // border collapse can create a non-manifold edge (two hole borders pinched together), which a
  // cut would show as a crack-like defect the input did not have. Either way: lock the input
  // triangles around the offending vertices and redo. Deterministic; usually runs once.
  // Input adjacency, both directions, in CSR form (counting sort: two linear passes). Entries
  // are not deduplicated: the number of times w appears in v's list is the number of input
  // triangles that use edge v-w (each triangle lists each of its edges once per direction).
  std::vector<uint32_t> adjStart(vertexCount + 1, 0), adj(indexCount * 2);
  for (size_t i = 0; i < indexCount; ++i) adjStart[triangles[i] + 1] += 2;
  for (size_t v = 0; v < vertexCount; ++v) adjStart[v + 1] += adjStart[v];
  {
    std::vector<uint32_t> fill(adjStart.begin(), adjStart.end() - 1);
    for (size_t t = 0; t < indexCount; t += 3)
      for (int k = 0; k < 3; ++k) {
        uint32_t a = triangles[t + k], b = triangles[t + (k + 1) % 3];
        adj[fill[a]++] = b;
        adj[fill[b]++] = a;
      }
  }
  auto inputUses = [&](uint32_t a, uint32_t b) {
    if (adjStart[a + 1] - adjStart[a] > adjStart[b + 1] - adjStart[b]) std::swap(a, b);
    size_t n = 0;
    for (uint32_t i = adjStart[a]; i < adjStart[a + 1]; ++i) n += adj[i] == b;
    return n;
  };
  // Rule (3) below (no new edge between two locked vertices) is what made most regions run
  // meshopt two or three times (measured on level-1 regions of a 1M scan: 2.7 runs per region,
  // ~44 such chords per region on the first run): collapsing a free vertex onto a locked
  // neighbour joins that locked vertex to the free vertex's other neighbours. So every free
  // vertex with a locked neighbour is locked up front (the region border's first ring). Then no
  // locked vertex has a free neighbour, and since a collapse only adds neighbours to its target,
  // no locked vertex ever gains one: no chord can appear and no locked vertex can lose its
  // triangles (rules 1 and 3 hold by construction; 1.00 runs per region). The ring is not
  // simplified at this level; it lies inside the next level's regions (BMT 4: the borders of
  // V(i+1) and V(i+2) differ), which simplify it. Measured: same output count, same error.
  // Only when the ring is cheap: locked vertices and their ring all survive, so when together
  // they would take more than half of the target's vertices (~targetTriangles / 2; only for
  // reductions far beyond the level loop's halving) the rest of the region would pay for them,
  // and the retry loop alone is used instead.
  if (locked) {
    std::vector<uint32_t> ring;
    size_t lockedUsed = 0;
    for (size_t v = 0; v < vertexCount; ++v) {
      if (!used[v]) continue;
      if (locked[v]) {
        ++lockedUsed;
        continue;
      }
      for (uint32_t i = adjStart[v]; i < adjStart[v + 1]; ++i)
        if (locked[adj[i]]) {
          ring.push_back(uint32_t(v));
          break;
        }
    }
    if ((lockedUsed + ring.size()) * 4 <= targetIndexCount / 3)
      for (uint32_t v : ring) lock[v] = 1;
  }
  // Output edges bucketed by their smaller vertex (counting sort), to find edges with 3+ triangles.
  std::vector<uint32_t> edgeStart, edgeOther, edgeFill;
  std::vector<uint8_t> kept(vertexCount), bad(vertexCount), multiplicity(vertexCount, 0);
  int attempt = 0;
  for (;; ++attempt) {
    simplifyLocked(pos, vertexCount, triangles, indexCount, lock, targetIndexCount, &relError, out);
    std::fill(kept.begin(), kept.end(), 0);
    std::fill(bad.begin(), bad.end(), 0);
    for (uint32_t v : out) kept[v] = 1;
    bool problem = false;
    for (size_t v = 0; v < vertexCount; ++v)
      if (lock[v] && used[v] && !kept[v]) bad[v] = 1, problem = true;
    edgeStart.assign(vertexCount + 1, 0);
    for (size_t t = 0; t < out.size(); t += 3)
      for (int k = 0; k < 3; ++k) ++edgeStart[std::min(out[t + k], out[t + (k + 1) % 3]) + 1];
    for (size_t v = 0; v < vertexCount; ++v) edgeStart[v + 1] += edgeStart[v];
    edgeFill.assign(edgeStart.begin(), edgeStart.end() - 1);
    edgeOther.resize(out.size());
    for (size_t t = 0; t < out.size(); t += 3)
      for (int k = 0; k < 3; ++k) {
        uint32_t a = out[t + k], b = out[t + (k + 1) % 3];
        edgeOther[edgeFill[std::min(a, b)]++] = std::max(a, b);
      }
    for (size_t v = 0; v < vertexCount; ++v) {
      uint32_t e0 = edgeStart[v], e1 = edgeStart[v + 1];
      if (e1 - e0 < 3) continue;
      for (uint32_t e = e0; e < e1; ++e) ++multiplicity[edgeOther[e]];
      for (uint32_t e = e0; e < e1; ++e) {
        uint32_t w = edgeOther[e];
        if (multiplicity[w] >= 3 && inputUses(uint32_t(v), w) <= 2) {
          bad[v] = bad[w] = 1;
          problem = true;
        }
      }
      for (uint32_t e = e0; e < e1; ++e) multiplicity[edgeOther[e]] = 0;
    }
    // (3) A new edge between two locked vertices (a chord across the region's border) can
    // duplicate an edge an outside patch already has: the two sheets would touch along it, a
    // non-manifold edge in the cut. The region cannot see outside edges, so no new locked-locked
    // edge is allowed.
    if (locked)
      for (size_t t = 0; t < out.size(); t += 3)
        for (int k = 0; k < 3; ++k) {
          uint32_t a = out[t + k], b = out[t + (k + 1) % 3];
          if (locked[a] && locked[b] && inputUses(a, b) == 0) {
            bad[a] = bad[b] = 1;
            problem = true;
          }
        }
    if (!problem) break;
    if (attempt == 16) {
      // Rare (seen on inputs that are non-manifold already): keep the region as it is. An
      // unsimplified region is always a valid fragment; the level above simplifies it.
      out.assign(triangles, triangles + indexCount);
      std::fill(kept.begin(), kept.end(), 0);
      for (uint32_t v : out) kept[v] = 1;
      break;
    }
    for (size_t t = 0; t < indexCount; t += 3)
      if (bad[triangles[t]] || bad[triangles[t + 1]] || bad[triangles[t + 2]])
        lock[triangles[t]] = lock[triangles[t + 1]] = lock[triangles[t + 2]] = 1;
  }

  SimplifiedRegion r;
  r.attempts = uint32_t(attempt + 1);
  std::vector<uint32_t>& remap = edgeFill;  // reuse: vertexCount entries
  remap.assign(vertexCount, ~0u);
  size_t keptCount = 0;
  for (size_t v = 0; v < vertexCount; ++v) keptCount += kept[v];
  r.origin.reserve(keptCount);
  r.positions.resize(keptCount * 3);
  for (size_t v = 0; v < vertexCount; ++v)
    if (kept[v]) {
      uint32_t i = uint32_t(r.origin.size());
      remap[v] = i;
      r.origin.push_back(uint32_t(v));
      for (int a = 0; a < 3; ++a) r.positions[size_t(i) * 3 + a] = positions[v * 3 + a];
    }
  r.triangles.resize(out.size());
  for (size_t i = 0; i < out.size(); ++i) r.triangles[i] = remap[out[i]];
  if (vertexCount) r.quadricError = double(relError) * double(meshopt_simplifyScale(pos.data(), vertexCount, 12));

  if (options.measureError && out.size() < indexCount) {
    // max over samples of the exact distance to the other surface, squared:
    //   (a) input -> result: removed vertices (kept vertices are result vertices: distance 0);
    //   (b) result -> input: result triangle centroids (result vertices are input vertices),
    //       except for the result triangles that are input triangles.
    // Each query only has to decide whether its sample is farther than the worst so far
    // (TriangleGrid::distance2Above), which most samples are not; the value is the same as
    // computing every sample's distance exactly. A strided subset of both directions goes first
    // so the running worst is large early and the other queries stop at their first close triangle.
    TriangleGrid resultGrid(r.positions.data(), r.origin.size(), r.triangles.data(), r.triangleCount());
    TriangleGrid inputGrid(positions, vertexCount, triangles, triangleCount);
    // Result triangles that are input triangles (all three corners kept) lie on the input: their
    // centroids need no query (a third of the result triangles at the level loop's halving: 20%
    // of the query time). meshopt keeps the survivors in input order, so one merge-like walk
    // finds them; a survivor out of order would only be queried like the others.
    std::vector<uint8_t> onInput(out.size() / 3, 0);
    for (size_t t = 0, i = 0; t < out.size(); t += 3) {
      while (i < indexCount && !(kept[triangles[i]] && kept[triangles[i + 1]] && kept[triangles[i + 2]])) i += 3;
      if (i < indexCount && out[t] == triangles[i] && out[t + 1] == triangles[i + 1] && out[t + 2] == triangles[i + 2])
        onInput[t / 3] = 1, i += 3;
    }
    std::vector<uint64_t> edges;  // (lower, higher) input vertex ids of the queried triangles' edges
    edges.reserve(out.size());
    for (size_t t = 0; t < out.size() / 3; ++t)
      if (!onInput[t])
        for (int e = 0; e < 3; ++e) {
          const uint64_t a = out[t * 3 + e], b = out[t * 3 + (e + 1) % 3];
          edges.push_back(a < b ? a << 32 | b : b << 32 | a);
        }
    std::sort(edges.begin(), edges.end());
    edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
    constexpr size_t kStride = 16;
    double worst2 = 0;
    for (int pass = 0; pass < 2; ++pass) {
      size_t k = 0;
      for (size_t v = 0; v < vertexCount; ++v)
        if (used[v] && !kept[v] && ((k++ % kStride == 0) == (pass == 0)))
          worst2 = std::max(worst2, resultGrid.distance2Above(positions + v * 3, worst2));
      for (size_t t = 0; t < out.size() / 3; ++t) {
        if ((t % kStride == 0) != (pass == 0) || onInput[t]) continue;
        const double *p0 = positions + size_t(out[t * 3]) * 3, *p1 = positions + size_t(out[t * 3 + 1]) * 3,
                     *p2 = positions + size_t(out[t * 3 + 2]) * 3;
        double c[3];
        for (int a = 0; a < 3; ++a) c[a] = (p0[a] + p1[a] + p2[a]) / 3;
        worst2 = std::max(worst2, inputGrid.distance2Above(c, worst2));
      }
      // The midpoint of every edge of those triangles, each once: on noisy scans the farthest
      // point of a large result triangle from the input is often near an edge, and centroids
      // alone left the stored error up to 11% below MeshLab's Hausdorff (0.3 M dragon scan,
      // level 1). The edges of input triangles lie on the input.
      for (size_t k = 0; k < edges.size(); ++k) {
        if ((k % kStride == 0) != (pass == 0)) continue;
        const double *a0 = positions + size_t(edges[k] >> 32) * 3, *a1 = positions + size_t(edges[k] & 0xffffffffu) * 3;
        double m[3];
        for (int a = 0; a < 3; ++a) m[a] = 0.5 * (a0[a] + a1[a]);
        worst2 = std::max(worst2, inputGrid.distance2Above(m, worst2));
      }
    }
    r.error = std::sqrt(worst2);
  }
  return r;
}

SimplifiedRegion simplifyRegion(const LoadedMesh& mesh, const SimplifyRegionOptions& options) {
  return simplifyRegion(mesh.positions.data(), mesh.vertexCount(), mesh.triangles.data(), mesh.triangleCount(),
                        mesh.locked.empty() ? nullptr : mesh.locked.data(), options);
}

}  // namespace mt
