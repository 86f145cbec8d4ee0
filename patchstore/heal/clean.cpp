// Cleaning passes: degenerate and duplicate faces, unreferenced vertices, small components,
// non-manifold vertices and edges. Each visits the patches once (ascending id, the order
// exportPly writes, so "earlier" means the same as in an in-core run on the exported mesh) and
// edits only the patches that need it, loading with them the neighbours whose triangles the
// decision depends on.
#include <algorithm>
#include <array>
#include <chrono>
#include <map>
#include <numeric>
#include <set>
#include <tuple>
#include <unordered_set>

#include "base/external_sort.h"
#include "base/memory_plan.h"
#include "base/progress.h"
#include "patchstore/heal/region.h"

namespace mt::heal {

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// Removes the triangles of patch index k that `drop` selects (by the triangle's index inside the
// patch) and commits; returns (triangles removed, vertices dropped).
std::pair<uint64_t, uint64_t> dropTriangles(PatchStore& store, PatchId id, const std::vector<uint8_t>& drop) {
  Region r = loadRegion(store, {id});
  RegionEdit e = identityEdit(r);
  e.clearTriangles();
  uint64_t removed = 0;
  for (size_t t = 0; t < r.trianglePatch.size(); ++t) {
    if (drop[t]) {
      ++removed;
      continue;
    }
    e.keepTriangle(r, t);
  }
  CommitStats s = commitRegion(store, r, e);
  return {removed, s.droppedVertices};
}

struct UnionFind {
  std::vector<uint32_t> parent;
  explicit UnionFind(size_t n = 0) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
  uint32_t find(uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  }
  void unite(uint32_t a, uint32_t b) {
    a = find(a);
    b = find(b);
    if (a != b) parent[std::max(a, b)] = std::min(a, b);
  }
};

// Vertex-connected components of one patch: a label per triangle, labels 0..count-1 in order of
// first triangle (deterministic, so the labelling and the removal pass agree).
uint32_t triangleComponents(const Patch& p, std::vector<uint32_t>& label, std::vector<uint32_t>& vertexLabel) {
  UnionFind uf(p.vertexCount());
  for (size_t t = 0; t < p.triangles.size(); t += 3) {
    uf.unite(p.triangles[t], p.triangles[t + 1]);
    uf.unite(p.triangles[t], p.triangles[t + 2]);
  }
  std::vector<uint32_t> rootLabel(p.vertexCount(), kNoVertex);
  uint32_t n = 0;
  label.assign(p.triangleCount(), 0);
  for (uint32_t t = 0; t < p.triangleCount(); ++t) {
    uint32_t root = uf.find(p.triangles[3 * t]);
    if (rootLabel[root] == kNoVertex) rootLabel[root] = n++;
    label[t] = rootLabel[root];
  }
  vertexLabel.assign(p.vertexCount(), kNoVertex);
  for (uint32_t v = 0; v < p.vertexCount(); ++v) vertexLabel[v] = rootLabel[uf.find(v)];
  return n;
}

}  // namespace

PassReport removeDegenerate(PatchStore& store, const HealOptions& options) {
  auto start = Clock::now();
  uint64_t triangles = 0, vertices = 0;
  std::vector<PatchId> ids = store.patchIds();
  Progress progress(options.progress, "remove-degenerate", ids.size(), "patches");
  size_t done = 0;
  for (PatchId id : ids) {
    Patch p = store.patch(id);
    std::vector<uint8_t> drop(p.triangleCount(), 0);
    bool any = false;
    for (uint32_t t = 0; t < p.triangleCount(); ++t) {
      const uint32_t* f = &p.triangles[3 * t];
      if (f[0] == f[1] || f[1] == f[2] || f[0] == f[2]) drop[t] = 1, any = true;
    }
    if (any) {
      auto [t, v] = dropTriangles(store, id, drop);
      triangles += t;
      vertices += v;
    }
    progress.update(++done);
  }
  store.sync();
  return {"remove-degenerate", {{"triangles", triangles}, {"vertices", vertices}}, since(start)};
}

PassReport removeUnreferenced(PatchStore& store, const HealOptions& options) {
  auto start = Clock::now();
  uint64_t vertices = 0;
  std::vector<PatchId> ids = store.patchIds();
  Progress progress(options.progress, "remove-unreferenced", ids.size(), "patches");
  size_t done = 0;
  for (PatchId id : ids) {
    Patch p = store.patch(id);
    std::vector<uint8_t> used(p.vertexCount(), 0);
    for (uint32_t i : p.triangles) used[i] = 1;
    // A vertex this patch does not use leaves it; it is gone from the mesh when no other patch
    // holds it (commitRegion counts exactly those).
    if (std::find(used.begin(), used.end(), 0) != used.end()) {
      Region r = loadRegion(store, {id});
      vertices += commitRegion(store, r, identityEdit(r)).droppedVertices;
    }
    progress.update(++done);
  }
  store.sync();
  return {"remove-unreferenced", {{"vertices", vertices}}, since(start)};
}

PassReport removeDuplicateFaces(PatchStore& store, const HealOptions& options) {
  auto start = Clock::now();
  uint64_t triangles = 0, vertices = 0;
  std::vector<PatchId> ids = store.patchIds();
  Progress progress(options.progress, "remove-duplicate-faces", ids.size(), "patches");
  size_t done = 0;
  for (PatchId id : ids) {
    Patch p = store.patch(id);
    // Duplicates inside the patch, and lower patches that hold all three corners of one of its
    // triangles (only there can an earlier copy of that triangle live).
    std::vector<std::vector<PatchId>> holders(p.vertexCount());
    for (const BoundaryEntry& e : p.boundary)
      if (e.neighbour < id) holders[e.local].push_back(e.neighbour);
    std::set<PatchId> lower;
    std::set<std::array<uint32_t, 3>> seen;
    bool internal = false;
    for (uint32_t t = 0; t < p.triangleCount(); ++t) {
      std::array<uint32_t, 3> f{p.triangles[3 * t], p.triangles[3 * t + 1], p.triangles[3 * t + 2]};
      std::sort(f.begin(), f.end());
      if (!seen.insert(f).second) internal = true;
      for (PatchId q : holders[f[0]])
        if (std::count(holders[f[1]].begin(), holders[f[1]].end(), q) && std::count(holders[f[2]].begin(), holders[f[2]].end(), q))
          lower.insert(q);
    }
    if (internal || !lower.empty()) {
      std::vector<PatchId> group(lower.begin(), lower.end());
      group.push_back(id);
      Region r = loadRegion(store, group);
      int self = r.indexOf(id);
      std::set<std::array<uint32_t, 3>> earlier;
      for (size_t t = 0; t < r.trianglePatch.size(); ++t)
        if (int(r.trianglePatch[t]) != self) {
          std::array<uint32_t, 3> f{r.triangles[3 * t], r.triangles[3 * t + 1], r.triangles[3 * t + 2]};
          std::sort(f.begin(), f.end());
          earlier.insert(f);
        }
      RegionEdit e = identityEdit(r);
      e.clearTriangles();
      uint64_t removed = 0;
      for (size_t t = 0; t < r.trianglePatch.size(); ++t) {
        if (int(r.trianglePatch[t]) == self) {
          std::array<uint32_t, 3> f{r.triangles[3 * t], r.triangles[3 * t + 1], r.triangles[3 * t + 2]};
          std::sort(f.begin(), f.end());
          if (!earlier.insert(f).second) {
            ++removed;
            continue;
          }
        }
        e.keepTriangle(r, t);
      }
      if (removed) {
        triangles += removed;
        vertices += commitRegion(store, r, e).droppedVertices;
      }
    }
    progress.update(++done);
  }
  store.sync();
  return {"remove-duplicate-faces", {{"triangles", triangles}, {"vertices", vertices}}, since(start)};
}

// Per-patch component labels joined over the boundary entries at the (patch, component) level,
// so the union-find holds one node per patch component, not one per vertex.
PassReport removeSmallComponents(PatchStore& store, uint64_t minTriangles, const HealOptions& options) {
  auto start = Clock::now();
  std::vector<PatchId> ids = store.patchIds();
  struct Link {
    uint64_t key;
    uint32_t node, pad;
  };
  struct LinkLess {
    bool operator()(const Link& a, const Link& b) const { return std::tie(a.key, a.node) < std::tie(b.key, b.node); }
  };
  ExternalSorter<Link, LinkLess> sorter(scratchPrefix(store, options, "components"), planMemory(options.memoryBytes, 1).healSorter);
  std::vector<uint32_t> base(ids.size() + 1, 0);
  std::vector<uint64_t> nodeTriangles;
  std::vector<uint32_t> label, vertexLabel;
  Progress progress(options.progress, "remove-small-components: label", ids.size(), "patches");
  for (size_t i = 0; i < ids.size(); ++i) {
    Patch p = store.patch(ids[i]);
    uint32_t n = triangleComponents(p, label, vertexLabel);
    base[i + 1] = base[i] + n;
    nodeTriangles.resize(base[i + 1], 0);
    for (uint32_t l : label) ++nodeTriangles[base[i] + l];
    std::vector<uint64_t> key = ownerKeys(p);
    uint32_t last = kNoVertex;
    for (const BoundaryEntry& e : p.boundary) {  // sorted by local: one link per shared vertex
      if (e.local == last || vertexLabel[e.local] == kNoVertex) continue;
      last = e.local;
      sorter.add({key[e.local], base[i] + vertexLabel[e.local], 0});
    }
    progress.update(i + 1);
  }
  progress.finish(ids.size());
  sorter.finish();
  UnionFind uf(base.back());
  Link link, prev{};
  bool have = false;
  while (sorter.next(link)) {
    if (have && link.key == prev.key) uf.unite(link.node, prev.node);
    prev = link;
    have = true;
  }
  std::vector<uint64_t> total(base.back(), 0);
  for (uint32_t n = 0; n < base.back(); ++n) total[uf.find(n)] += nodeTriangles[n];
  uint64_t components = 0, triangles = 0, vertices = 0, allComponents = 0, allTriangles = 0, largest = 0;
  for (uint32_t n = 0; n < base.back(); ++n)
    if (uf.find(n) == n) {
      ++allComponents;
      allTriangles += total[n];
      largest = std::max(largest, total[n]);
      if (total[n] < minTriangles) ++components, triangles += total[n];
    }
  if (triangles == allTriangles && allTriangles > 0 && !options.force)
    fail(store.dir(), "remove-small-components " + std::to_string(minTriangles) + " would remove every component (" +
                          std::to_string(components) + " components, " + std::to_string(triangles) +
                          " triangles: the whole surface; the largest has " + std::to_string(largest) +
                          " triangles); nothing was changed: choose N at most " + std::to_string(largest) + ", or --force");
  Progress drop(options.progress, "remove-small-components: drop", ids.size(), "patches");
  for (size_t i = 0; i < ids.size(); ++i) {
    bool any = false;
    for (uint32_t n = base[i]; n < base[i + 1]; ++n) any |= total[uf.find(n)] < minTriangles;
    if (any) {
      Patch p = store.patch(ids[i]);
      triangleComponents(p, label, vertexLabel);
      std::vector<uint8_t> gone(p.triangleCount(), 0);
      for (uint32_t t = 0; t < p.triangleCount(); ++t) gone[t] = total[uf.find(base[i] + label[t])] < minTriangles;
      vertices += dropTriangles(store, ids[i], gone).second;
    }
    drop.update(i + 1);
  }
  store.sync();
  return {"remove-small-components", {{"components", components}, {"triangles", triangles}, {"vertices", vertices}}, since(start)};
}

namespace {
using PositionPair = std::array<double, 6>;
PositionPair positionPair(const double* a, const double* b) {
  PositionPair k;
  bool swap = std::lexicographical_compare(b, b + 3, a, a + 3);
  std::copy(swap ? b : a, (swap ? b : a) + 3, k.begin());
  std::copy(swap ? a : b, (swap ? a : b) + 3, k.begin() + 3);
  return k;
}
}  // namespace

PassReport fixNonManifold(PatchStore& store, const HealOptions& options) {
  auto start = Clock::now();
  // 1. The non-manifold edges of the mesh as it is now, by the positions of their ends (positions
  //    survive the splits below; patch-local indices do not).
  std::map<PatchId, std::vector<std::pair<uint32_t, uint32_t>>> byOwner;  // owner of a -> (local a, index)
  std::vector<std::pair<uint64_t, uint64_t>> edges;
  edgeCensus(store, options, [](uint32_t c) { return c > 2; },
             [&](const EdgeUse& e) { edges.push_back({e.a, e.b}); }, "fix-nonmanifold: edges");
  std::vector<std::array<double, 3>> endPos(edges.size() * 2);
  std::map<PatchId, std::vector<std::pair<uint32_t, size_t>>> wantPos;
  for (size_t i = 0; i < edges.size(); ++i) {
    wantPos[gidPatch(edges[i].first)].push_back({gidLocal(edges[i].first), 2 * i});
    wantPos[gidPatch(edges[i].second)].push_back({gidLocal(edges[i].second), 2 * i + 1});
  }
  for (auto& [q, list] : wantPos) {
    Patch p = store.patch(q);
    for (auto& [local, slot] : list) std::copy(&p.positions[3 * local], &p.positions[3 * local] + 3, endPos[slot].begin());
  }
  std::set<PositionPair> nonManifold;
  for (size_t i = 0; i < edges.size(); ++i) nonManifold.insert(positionPair(endPos[2 * i].data(), endPos[2 * i + 1].data()));

  // 2. Each patch splits the vertices it owns, with every patch around them loaded.
  uint64_t split = 0, added = 0;
  std::vector<PatchId> ids = store.patchIds();
  Progress progress(options.progress, "fix-nonmanifold: split", ids.size(), "patches");
  size_t done = 0;
  for (PatchId id : ids) {
    Patch p = store.patch(id);
    std::vector<PatchId> group{id};
    for (const BoundaryEntry& e : p.boundary) group.push_back(e.neighbour);
    Region r = loadRegion(store, group);
    int self = r.indexOf(id);
    // Owned: p holds it and no lower patch does (all its holders are p's neighbours: loaded).
    std::vector<uint8_t> owned(r.vertexCount(), 0);
    for (uint32_t u : r.unifiedOf[self]) owned[u] = 1;
    for (int k = 0; k < self; ++k)
      for (uint32_t u : r.unifiedOf[k]) owned[u] = 0;
    std::vector<std::vector<uint32_t>> around(r.vertexCount());
    for (uint32_t t = 0; t < r.trianglePatch.size(); ++t) {
      const uint32_t* f = &r.triangles[3 * t];
      if (f[0] == f[1] || f[1] == f[2] || f[0] == f[2]) continue;  // degenerate: stays with the vertex
      for (int c = 0; c < 3; ++c)
        if (owned[f[c]]) around[f[c]].push_back(t);
    }
    RegionEdit e = identityEdit(r);
    bool changed = false;
    for (uint32_t u = 0; u < r.vertexCount(); ++u) {
      const auto& ts = around[u];
      if (ts.size() < 2) continue;
      // Fans: triangles around u joined across an edge (u, x) used by exactly two triangles that
      // was not non-manifold before the pass.
      std::map<uint32_t, std::vector<uint32_t>> byPartner;
      for (uint32_t i = 0; i < ts.size(); ++i)
        for (int c = 0; c < 3; ++c) {
          uint32_t x = r.triangles[3 * ts[i] + c];
          if (x != u) byPartner[x].push_back(i);
        }
      UnionFind uf(ts.size());
      for (auto& [x, list] : byPartner)
        if (list.size() == 2 && !nonManifold.count(positionPair(&r.positions[3 * u], &r.positions[3 * x])))
          uf.unite(list[0], list[1]);
      std::map<uint32_t, uint32_t> copyOfRoot;
      for (uint32_t i = 0; i < ts.size(); ++i) {
        uint32_t root = uf.find(i);
        if (root == 0) continue;  // the fan of the first triangle keeps the vertex
        auto it = copyOfRoot.find(root);
        if (it == copyOfRoot.end()) it = copyOfRoot.emplace(root, e.addVertexCopy(r, u)).first;
        for (int c = 0; c < 3; ++c)
          if (e.triangles[3 * ts[i] + c] == u) e.triangles[3 * ts[i] + c] = it->second;
      }
      if (!copyOfRoot.empty()) {
        ++split;
        added += copyOfRoot.size();
        changed = true;
      }
    }
    if (changed) commitRegion(store, r, e);
    progress.update(++done);
  }
  store.sync();
  return {"fix-nonmanifold", {{"edges", uint64_t(edges.size())}, {"vertices", split}, {"added", added}}, since(start)};
}

}  // namespace mt::heal
