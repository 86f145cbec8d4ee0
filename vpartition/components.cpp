// Connected components of V-partition cells (BMT 4.2: "it is not required for these patches to be
// composed of a single connected component" -- but cells that split into pieces hurt the
// simplification of a region, so we measure how often it happens).
//
// The store holds the V*0 cells as patches with their own vertices; the same mesh vertex appears
// in several patches, tied by the boundary lists (vp, q, vq). For a level i the patches are grouped
// by the Vi cells their triangles fall in (a patch may straddle Vi cells for i >= 2, since the
// partitions do not nest), then each cell is solved alone: a union-find over the (patch, local
// vertex) ids of that cell's patches, joined along triangles in the cell and along boundary
// entries between the cell's patches. Memory is the patch -> cells table plus one cell's patches.
#include <algorithm>
#include <cassert>
#include <map>
#include <numeric>
#include <unordered_map>

#include "vpartition/vpartition.h"

namespace mt {

namespace {

struct UnionFind {
  std::vector<uint32_t> parent;
  explicit UnionFind(size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
  uint32_t find(uint32_t x) {
    while (parent[x] != x) { parent[x] = parent[parent[x]]; x = parent[x]; }
    return x;
  }
  void unite(uint32_t a, uint32_t b) {
    a = find(a); b = find(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);
  }
};

uint32_t triangleCell(const PartitionSequence& seq, uint32_t level, const Patch& p, uint32_t t) {
  const uint32_t* v = &p.triangles[3 * size_t(t)];
  float c[3];
  triangleCentroid(&p.positions[3 * size_t(v[0])], &p.positions[3 * size_t(v[1])],
                   &p.positions[3 * size_t(v[2])], c);
  return seq.cellOf(level, c);
}

}  // namespace

std::vector<double> computeComponentShare(const PartitionSequence& seq,
                                          const std::vector<PatchId>& patchIds,
                                          const std::function<Patch(PatchId)>& loadPatch) {
  const uint32_t L = seq.levels();
  std::vector<double> share(L, 0.0);
  for (uint32_t level = 0; level < L; ++level) {
    // Which patches each Vi cell draws triangles from (ordered: deterministic work order).
    std::map<uint32_t, std::vector<PatchId>> cellPatches;
    for (PatchId id : patchIds) {
      Patch p = loadPatch(id);
      std::vector<uint32_t> cells;
      for (uint32_t t = 0; t < p.triangleCount(); ++t) cells.push_back(triangleCell(seq, level, p, t));
      std::sort(cells.begin(), cells.end());
      cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
      for (uint32_t c : cells) cellPatches[c].push_back(id);
    }
    uint64_t multi = 0;
    for (const auto& [cell, ids] : cellPatches) {
      std::vector<Patch> patches;
      std::unordered_map<PatchId, uint32_t> slot;
      std::vector<uint32_t> base;
      uint32_t total = 0;
      for (PatchId id : ids) {
        slot[id] = uint32_t(patches.size());
        patches.push_back(loadPatch(id));
        base.push_back(total);
        total += patches.back().vertexCount();
      }
      UnionFind uf(total);
      std::vector<uint8_t> used(total, 0);
      for (size_t k = 0; k < patches.size(); ++k) {
        const Patch& p = patches[k];
        for (uint32_t t = 0; t < p.triangleCount(); ++t) {
          if (triangleCell(seq, level, p, t) != cell) continue;
          const uint32_t* v = &p.triangles[3 * size_t(t)];
          for (int j = 0; j < 3; ++j) used[base[k] + v[j]] = 1;
          uf.unite(base[k] + v[0], base[k] + v[1]);
          uf.unite(base[k] + v[0], base[k] + v[2]);
        }
        // A vertex shared with another patch of this cell is one vertex, used or not here (a
        // vertex held by three patches links the two that use it through the third's copy).
        for (const BoundaryEntry& e : p.boundary) {
          auto it = slot.find(e.neighbour);
          if (it == slot.end()) continue;
          assert(e.remote < patches[it->second].vertexCount());
          uf.unite(base[k] + e.local, base[it->second] + e.remote);
        }
      }
      uint32_t root = UINT32_MAX;
      bool split = false;
      for (uint32_t v = 0; v < total && !split; ++v) {
        if (!used[v]) continue;
        uint32_t r = uf.find(v);
        if (root == UINT32_MAX) root = r;
        else if (r != root) split = true;
      }
      multi += split ? 1 : 0;
    }
    share[level] = cellPatches.empty() ? 0.0 : double(multi) / cellPatches.size();
  }
  return share;
}

}  // namespace mt
