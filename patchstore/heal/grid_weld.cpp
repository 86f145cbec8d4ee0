// The grid weld: every vertex that falls in one cell of a quantization grid becomes one vertex.
//
// Why: an MT file stores positions on one global grid and its cuts are welded by grid position
// (mt_format.h), so two distinct store vertices in one cell are one vertex in every cut. If the
// store keeps them distinct, the simplifier treats them as two (it may keep both and connect them
// to the same neighbour, or collapse one of them only on one side of a region border), and cuts
// that mix levels gain non-manifold or boundary edges that the finest cut does not have. Real
// scans have such pairs everywhere (vertices closer than the grid step, needles, overlapping
// passes, duplicated seam vertices). After this pass the store's topology is the grid's: distinct
// vertices have distinct cells at every level, since simplification only keeps store vertices.
//
// How, out of core: one parallel read of every patch gives a (cell key, vertex) record per
// vertex (each once, from its owner patch), sorted by key with the radix external sort; equal
// keys are the clusters. Clusters are few (a fraction of a percent of the vertices), so they are
// applied like weld()'s: groups of clusters loaded with every patch around their vertices, each
// member replaced by the member with the smallest position, and the triangles that become
// degenerate dropped in the same edit; then the scan is repeated until it finds no cluster.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <map>
#include <set>

#include <xxhash.h>

#include "base/external_sort.h"
#include "base/memory_plan.h"
#include "base/progress.h"
#include "patchstore/heal/region.h"

namespace mt::heal {

namespace {

using Cell = std::array<int64_t, 3>;
using Pos = std::array<double, 3>;

struct CellRecord {
  uint64_t key;  // the packed cell, or its hash when the cells need more than 64 bits
  uint64_t gid;
};
struct CellKey {
  uint64_t operator()(const CellRecord& r) const { return r.key; }
};

Cell cellOf(const GridCells& g, const double* p) {
  Cell c;
  for (int a = 0; a < 3; ++a) c[a] = int64_t(std::floor((p[a] - g.origin[a]) / g.step + 0.5));
  return c;
}

// Cell keys over the store's box, relative to its lowest cell: packed exactly when 3 x bits <= 64,
// else hashed (then equal keys may be different cells: step 3 regroups by exact cell).
struct CellKeys {
  Cell lo;
  unsigned bits = 1;
  bool packed = false;
  uint64_t operator()(const Cell& c) const {
    if (!packed) return uint64_t(XXH64(c.data(), sizeof c, 0));
    uint64_t k = 0;
    for (int a = 0; a < 3; ++a) k = (k << bits) | uint64_t(c[a] - lo[a]);
    return k;
  }
};

using CellSorter = StableKeySorter<CellRecord, CellKey>;

// Step 1: one record per vertex, read in parallel, added in patch order (deterministic runs).
// Returns the patches that have a triangle with a repeated vertex.
std::vector<PatchId> scanVertices(const PatchStore& store, const GridCells& grid, const CellKeys& keyOf,
                                  uint64_t vertices, bool progressOn, CellSorter& sorter) {
  std::vector<PatchId> ids = store.patchIds();
  Progress progress(progressOn, "grid weld: scan", vertices, "vertices");
  uint64_t scanned = 0;
  constexpr size_t kBatch = 256;
  std::vector<std::vector<CellRecord>> batch(kBatch);
  std::vector<uint8_t> repeated(kBatch);  // the patch has a triangle with a repeated vertex
  std::vector<PatchId> withRepeated;
  for (size_t first = 0; first < ids.size(); first += kBatch) {
    const size_t n = std::min(kBatch, ids.size() - first);
    tbb::parallel_for(size_t(0), n, [&](size_t i) {
      const PatchId id = ids[first + i];
      Patch p = store.patch(id);
      std::vector<uint64_t> key = ownerKeys(p);
      std::vector<CellRecord>& out = batch[i];
      out.clear();
      for (uint32_t v = 0; v < p.vertexCount(); ++v)
        if (gidPatch(key[v]) == id) out.push_back({keyOf(cellOf(grid, &p.positions[3 * size_t(v)])), key[v]});
      repeated[i] = 0;
      for (size_t t = 0; t < p.triangles.size(); t += 3) {
        const uint32_t* f = &p.triangles[t];
        repeated[i] |= f[0] == f[1] || f[1] == f[2] || f[0] == f[2];
      }
    });
    for (size_t i = 0; i < n; ++i) {
      if (repeated[i]) withRepeated.push_back(ids[first + i]);
      sorter.addBatch(batch[i].data(), batch[i].size());
      scanned += batch[i].size();
    }
    progress.update(scanned);
  }
  progress.finish(scanned);
  return withRepeated;
}

// Step 2: equal keys are candidate clusters (ascending key, members in patch order); the sorter
// is consumed.
std::vector<std::vector<uint64_t>> candidateClusters(CellSorter& sorter) {
  sorter.finish();
  std::vector<std::vector<uint64_t>> candidates;
  CellRecord r{}, prev{};
  bool have = false, open = false;
  while (sorter.next(r)) {
    if (have && r.key == prev.key) {
      if (!open) candidates.push_back({prev.gid}), open = true;
      candidates.back().push_back(r.gid);
    } else {
      open = false;
    }
    prev = r, have = true;
  }
  sorter.release();
  return candidates;
}

struct Cluster {
  Cell cell;
  uint32_t members = 0;
  std::set<PatchId> patches;  // the members' owners
};

// Step 3: the clusters' exact cells, read before anything is committed (commits move
// patch-local indices, so a member's gid is only good until then). A hashed key may join
// vertices of different cells: members are regrouped by their exact cell.
std::vector<Cluster> exactClusters(const PatchStore& store, const GridCells& grid,
                                   std::vector<std::vector<uint64_t>>& candidates) {
  std::sort(candidates.begin(), candidates.end());
  std::map<PatchId, std::vector<std::pair<uint32_t, size_t>>> byPatch;  // owner -> (local, candidate)
  for (size_t c = 0; c < candidates.size(); ++c)
    for (uint64_t m : candidates[c]) byPatch[gidPatch(m)].push_back({gidLocal(m), c});
  std::map<std::pair<size_t, Cell>, Cluster> found;  // (candidate, cell) -> cluster
  for (auto& [id, list] : byPatch) {
    Patch p = store.patch(id);
    for (auto [local, c] : list) {
      const double* q = &p.positions[3 * size_t(local)];
      Cell cell = cellOf(grid, q);
      auto [it, fresh] = found.try_emplace({c, cell}, Cluster{cell, 0, {}});
      ++it->second.members;
      it->second.patches.insert(id);
    }
  }
  std::vector<Cluster> list;
  for (auto& [key, cluster] : found)
    if (cluster.members >= 2) list.push_back(std::move(cluster));
  return list;
}

struct WeldCounts {
  uint64_t merged = 0, degenerate = 0, dropped = 0;
};

// The edit of a region with its vertices renamed by `to`, less the triangles that become
// degenerate (counted).
RegionEdit withoutDegenerate(const Region& r, const std::vector<uint32_t>& to, uint64_t& degenerate) {
  RegionEdit out = identityEdit(r);
  out.clearTriangles();
  for (size_t t = 0; t < r.triangles.size() / 3; ++t) {
    const uint32_t v[3] = {to[r.triangles[3 * t]], to[r.triangles[3 * t + 1]], to[r.triangles[3 * t + 2]]};
    if (v[0] == v[1] || v[1] == v[2] || v[0] == v[2]) {
      ++degenerate;
      continue;
    }
    // A seam (two vertices with one position, made by the readers' wedge split) closes here:
    // its triangles keep their own texture coordinates per corner.
    out.keepTriangle(r, t, v);
  }
  return out;
}

// Step 4 for one group: every region vertex in a cluster's cell becomes the cluster's target
// vertex, the one with the smallest position (the first in region order among equals; the member
// copies of one store vertex, shared between loaded patches, are one region vertex already). The
// target is chosen here, from what the store holds now, not in step 3: an earlier group's edit
// can remove a member (its only triangles became degenerate when a neighbouring cluster merged),
// and a target chosen before would then be missing (scans of CGAL's joint, pinion and pipe models).
void mergeGroup(PatchStore& store, const GridCells& grid, const std::set<PatchId>& patches,
                const std::set<Cell>& cells, WeldCounts& counts) {
  auto wanted = [&](const Region& r, uint32_t u) { return cells.count(cellOf(grid, &r.positions[3 * size_t(u)])) != 0; };
  Region r = loadUnlocked(store, {patches.begin(), patches.end()}, wanted);
  auto pos = [&](uint32_t u) {
    const double* q = &r.positions[3 * size_t(u)];
    return Pos{q[0], q[1], q[2]};
  };
  std::map<Cell, uint32_t> targetVertex;
  std::vector<uint32_t> to(r.vertexCount());
  for (uint32_t u = 0; u < r.vertexCount(); ++u) {
    to[u] = u;
    const Cell cell = cellOf(grid, &r.positions[3 * size_t(u)]);
    if (!cells.count(cell)) continue;
    if (r.locked[u]) fail(store.dir(), "grid weld: a cluster spans too many patches to load together");
    auto [it, fresh] = targetVertex.try_emplace(cell, u);
    if (!fresh && pos(u) < pos(it->second)) it->second = u;
  }
  for (uint32_t u = 0; u < r.vertexCount(); ++u) {
    auto it = targetVertex.find(cellOf(grid, &r.positions[3 * size_t(u)]));
    if (it != targetVertex.end()) to[u] = it->second;
    counts.merged += to[u] != u;
  }
  counts.dropped += commitRegion(store, r, withoutDegenerate(r, to, counts.degenerate)).droppedVertices;
}

// Step 4: apply in groups of clusters that need few patches; every vertex in a cluster's cell is
// that cluster's, which stays true as groups are committed.
void mergeClusters(PatchStore& store, const GridCells& grid, const std::vector<Cluster>& list, bool progressOn,
                   WeldCounts& counts) {
  Progress apply(progressOn, "grid weld: merge", list.size(), "clusters");
  for (size_t i = 0; i < list.size();) {
    std::set<PatchId> patches;
    std::set<Cell> cells;
    size_t j = i;
    while (j < list.size() && (patches.size() < 32 || j == i)) {
      patches.insert(list[j].patches.begin(), list[j].patches.end());
      cells.insert(list[j].cell);
      ++j;
    }
    if (!cells.empty()) mergeGroup(store, grid, patches, cells, counts);
    apply.update(j);
    i = j;
  }
  apply.finish(list.size());
}

// Step 5: triangles the input itself had with a repeated vertex, in patches no cluster touched:
// removed too, so that the finest cut has exactly the store's triangles less those counted.
void dropRepeated(PatchStore& store, const std::vector<PatchId>& withRepeated, WeldCounts& counts) {
  for (PatchId id : withRepeated) {
    Region r = loadRegion(store, {id});
    std::vector<uint32_t> to(r.vertexCount());
    for (uint32_t u = 0; u < r.vertexCount(); ++u) to[u] = u;
    RegionEdit out = withoutDegenerate(r, to, counts.degenerate);
    if (out.triangles.size() != r.triangles.size()) counts.dropped += commitRegion(store, r, out).droppedVertices;
  }
}

}  // namespace

PassReport weldToGrid(PatchStore& store, const GridCells& grid, const HealOptions& options) {
  auto start = std::chrono::steady_clock::now();
  if (!(grid.step > 0) || !std::isfinite(grid.step)) fail(store.dir(), "grid weld: the step must be a finite number > 0");
  const StoreInfo info = store.info();
  CellKeys keyOf;
  keyOf.lo = cellOf(grid, info.bounds.lo);
  const Cell hi = cellOf(grid, info.bounds.hi);
  unsigned bits = 1;
  for (int a = 0; a < 3; ++a)
    while (bits < 63 && (uint64_t(hi[a] - keyOf.lo[a]) >> bits) != 0) ++bits;
  const bool packed = 3 * bits <= 64;
  keyOf.bits = bits;
  keyOf.packed = packed;

  // Until a scan finds no cluster. A group loads the patches that owned its clusters' members at
  // the scan, and an earlier group's edit can move a member's triangles to other patches, so a
  // cell can keep two vertices (two degenerate triangles in the finest cut of a noisy scan of
  // CGAL's pipe model, `scangen pipe.off 5 --holes 0.5 --amp 0.03 --shuffle 2`); the next pass
  // merges what is left. On every other input tried the second scan finds nothing (the same bytes).
  WeldCounts counts;
  uint64_t clusters = 0;
  constexpr int kMaxPasses = 8;
  for (int pass = 0;; ++pass) {
    StableKeySorter<CellRecord, CellKey> sorter(scratchPrefix(store, options, "gridweld"), planMemory(options.memoryBytes, 1).healSorter,
                                                CellKey{}, packed ? 3 * bits : 64);
    const std::vector<PatchId> withRepeated = scanVertices(store, grid, keyOf, store.info().vertices, options.progress, sorter);
    std::vector<std::vector<uint64_t>> candidates = candidateClusters(sorter);
    const std::vector<Cluster> list = exactClusters(store, grid, candidates);
    if (!list.empty() && pass == kMaxPasses)
      fail(store.dir(), "grid weld: " + std::to_string(list.size()) + " cells still hold two vertices after " +
                            std::to_string(kMaxPasses) + " passes");
    clusters += list.size();
    if (!list.empty()) mergeClusters(store, grid, list, options.progress, counts);
    dropRepeated(store, withRepeated, counts);
    if (list.empty()) break;
  }
  store.sync();
  double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return {"grid-weld",
          {{"merged", counts.merged}, {"clusters", clusters}, {"degenerate", counts.degenerate},
           {"vertices", counts.dropped}},
          seconds};
}

}  // namespace mt::heal
