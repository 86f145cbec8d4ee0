// --weld EPS: merge vertices closer than eps, across patches.
//
// Candidates come from an external sort of the vertices (each once, from its owner patch) by
// grid cell. Two points closer than eps share a cell of side 2*eps in at least one of the eight
// grids shifted by 0 or eps along each axis (along one axis, the cell walls of the two shifts
// alternate every eps, so an interval shorter than eps crosses at most one of them), so eight
// sorts find every pair while comparing only points in one cell. eps = 0 sorts by exact position.
// The pairs are few (duplicates along scan seams), so clusters are a union-find in RAM, and each
// cluster is applied to a group holding every patch that holds one of its vertices.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <set>
#include <tuple>
#include <unordered_map>

#include "base/external_sort.h"
#include "base/memory_plan.h"
#include "base/progress.h"
#include "patchstore/heal/region.h"

namespace mt::heal {

namespace {

struct Point {
  int64_t cell[3];
  double p[3];
  uint64_t gid;
};
struct PointLess {
  bool operator()(const Point& a, const Point& b) const {
    return std::tie(a.cell[0], a.cell[1], a.cell[2], a.p[0], a.p[1], a.p[2], a.gid) <
           std::tie(b.cell[0], b.cell[1], b.cell[2], b.p[0], b.p[1], b.p[2], b.gid);
  }
};
using Pos = std::array<double, 3>;
using Sorters = std::vector<std::unique_ptr<ExternalSorter<Point, PointLess>>>;

// An epsilon near the model's size merges distant parts into one vertex, and puts most points in
// a handful of cells (quadratic candidate pairs): refuse it unless asked for.
void checkEpsilon(const PatchStore& store, double eps, const HealOptions& options) {
  if (!(eps >= 0) || !std::isfinite(eps)) fail(store.dir(), "weld: epsilon must be a finite number >= 0");
  const Box3 b = store.info().bounds;
  double d2 = 0;
  for (int a = 0; a < 3; ++a) d2 += (b.hi[a] - b.lo[a]) * (b.hi[a] - b.lo[a]);
  const double diagonal = std::sqrt(d2), limit = kMaxWeldFraction * diagonal;
  char msg[256];
  std::snprintf(msg, sizeof msg,
                "weld: epsilon %g is above %g%% of the bounding-box diagonal (%g), the most --weld accepts (%g): "
                "it would merge distant parts of the model; choose a smaller epsilon, or --force",
                eps, kMaxWeldFraction * 100, diagonal, limit);
  if (eps > limit && !options.force) fail(store.dir(), msg);
}

// Every vertex once (from its owner patch) into each grid's sorter, with its cell there.
void addVertices(const PatchStore& store, double eps, const HealOptions& options, Sorters& sorters) {
  const int grids = int(sorters.size());
  std::vector<PatchId> ids = store.patchIds();
  Progress progress(options.progress, "weld: sort", ids.size(), "patches");
  size_t done = 0;
  for (PatchId id : ids) {
    Patch p = store.patch(id);
    std::vector<uint64_t> key = ownerKeys(p);
    for (uint32_t v = 0; v < p.vertexCount(); ++v) {
      if (gidPatch(key[v]) != id) continue;  // written once, by its owner
      Point pt{{0, 0, 0}, {p.positions[3 * v], p.positions[3 * v + 1], p.positions[3 * v + 2]}, key[v]};
      for (int g = 0; g < grids; ++g) {
        if (eps > 0)
          for (int a = 0; a < 3; ++a) pt.cell[a] = int64_t(std::floor((pt.p[a] - ((g >> a) & 1) * eps) / (2 * eps)));
        sorters[g]->add(pt);
      }
    }
    progress.update(++done);
  }
  progress.finish(done);
}

// Pairs -> clusters: a union-find over the few vertices that have a partner (roots are the
// smallest key), with each member's position.
struct Clusters {
  std::unordered_map<uint64_t, uint64_t> parent;
  std::unordered_map<uint64_t, Pos> position;
  uint64_t find(uint64_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  }
  void pair(const Point& a, const Point& b) {
    for (const Point* q : {&a, &b})
      if (!parent.count(q->gid)) parent[q->gid] = q->gid, position[q->gid] = {q->p[0], q->p[1], q->p[2]};
    uint64_t x = find(a.gid), y = find(b.gid);
    if (x != y) parent[std::max(x, y)] = std::min(x, y);
  }
};

// The pairs closer than eps (equal positions for eps = 0) among the points of each cell of each
// grid; the sorters are consumed.
void pairNeighbours(Sorters& sorters, double eps, Clusters& clusters) {
  const double eps2 = eps * eps;
  std::vector<Point> cell;
  for (auto& sorter : sorters) {
    sorter->finish();
    Point pt;
    auto flush = [&]() {
      // A cell is sorted by x (PointLess): past eps along x no later point is closer than eps,
      // which keeps a crowded cell (a large eps) from comparing every pair.
      for (size_t i = 0; i < cell.size(); ++i)
        for (size_t j = i + 1; j < cell.size(); ++j) {
          if (eps > 0 && cell[j].p[0] - cell[i].p[0] >= eps) break;
          if (eps == 0) {
            if (cell[i].p[0] != cell[j].p[0] || cell[i].p[1] != cell[j].p[1] || cell[i].p[2] != cell[j].p[2]) break;
            clusters.pair(cell[i], cell[j]);
          } else {
            double d2 = 0;
            for (int a = 0; a < 3; ++a) d2 += (cell[i].p[a] - cell[j].p[a]) * (cell[i].p[a] - cell[j].p[a]);
            if (d2 < eps2) clusters.pair(cell[i], cell[j]);
          }
        }
      cell.clear();
    };
    while (sorter->next(pt)) {
      bool same = !cell.empty() && std::equal(pt.cell, pt.cell + 3, cell.back().cell) &&
                  (eps > 0 || std::equal(pt.p, pt.p + 3, cell.back().p));
      if (!same) flush();
      cell.push_back(pt);
    }
    flush();
    sorter.reset();
  }
}

struct Cluster {
  std::vector<uint64_t> members;  // ascending
  Pos target;                     // the member with the smallest position
};

// Each cluster becomes its member with the smallest position; sorted by first member.
std::vector<Cluster> clusterList(Clusters& clusters, uint64_t& merged) {
  std::map<uint64_t, std::vector<uint64_t>> byRoot;  // root -> members
  for (auto& [g, par] : clusters.parent) byRoot[clusters.find(g)].push_back(g);
  std::vector<Cluster> list;
  for (auto& [root, members] : byRoot) {
    std::sort(members.begin(), members.end());
    Pos target = clusters.position[members[0]];
    for (uint64_t m : members) target = std::min(target, clusters.position[m]);
    merged += members.size() - 1;
    list.push_back({members, target});
  }
  std::sort(list.begin(), list.end(), [](const Cluster& a, const Cluster& b) { return a.members[0] < b.members[0]; });
  return list;
}

// A group of clusters applied in one region (`clusterAt`: member position -> cluster in list):
// every vertex at a member's position becomes the cluster's target vertex.
void mergeGroup(PatchStore& store, const std::vector<Cluster>& list, const std::set<PatchId>& patches,
                const std::map<Pos, size_t>& clusterAt) {
  auto at = [&](const Region& r, uint32_t u) {
    return clusterAt.find(Pos{r.positions[3 * u], r.positions[3 * u + 1], r.positions[3 * u + 2]});
  };
  Region r = loadUnlocked(store, {patches.begin(), patches.end()},
                          [&](const Region& rr, uint32_t u) { return at(rr, u) != clusterAt.end(); });
  std::map<size_t, uint32_t> targetVertex;
  for (uint32_t u = 0; u < r.vertexCount(); ++u) {
    auto it = at(r, u);
    if (it == clusterAt.end()) continue;
    if (r.locked[u]) fail(store.dir(), "weld: a cluster spans too many patches to load together");
    if (Pos{r.positions[3 * u], r.positions[3 * u + 1], r.positions[3 * u + 2]} == list[it->second].target &&
        !targetVertex.count(it->second))
      targetVertex[it->second] = u;
  }
  RegionEdit e = identityEdit(r);
  std::vector<uint32_t> to(r.vertexCount());
  for (uint32_t u = 0; u < r.vertexCount(); ++u) {
    auto it = at(r, u);
    to[u] = it == clusterAt.end() ? u : targetVertex.at(it->second);
  }
  for (uint32_t& v : e.triangles) v = to[v];
  commitRegion(store, r, e);
}

}  // namespace

PassReport weld(PatchStore& store, double eps, const HealOptions& options) {
  auto start = std::chrono::steady_clock::now();
  checkEpsilon(store, eps, options);
  const int grids = eps > 0 ? 8 : 1;
  Sorters sorters;
  for (int g = 0; g < grids; ++g)
    sorters.push_back(std::make_unique<ExternalSorter<Point, PointLess>>(
        scratchPrefix(store, options, "weld" + std::to_string(g)), planMemory(options.memoryBytes, 1).healSorter / grids));
  addVertices(store, eps, options, sorters);
  Clusters clusters;
  pairNeighbours(sorters, eps, clusters);
  uint64_t merged = 0;
  const std::vector<Cluster> list = clusterList(clusters, merged);
  // Apply in groups of clusters that need few patches; every vertex at a member's position is
  // that cluster's (equal positions are always in one cluster), which stays true as groups are
  // committed and patch-local indices move.
  Progress apply(options.progress, "weld: merge", list.size(), "clusters");
  for (size_t i = 0; i < list.size();) {
    std::set<PatchId> patches;
    std::map<Pos, size_t> clusterAt;
    size_t j = i;
    while (j < list.size() && (patches.size() < 32 || j == i)) {
      for (uint64_t m : list[j].members) {
        patches.insert(gidPatch(m));
        clusterAt[clusters.position[m]] = j;
      }
      ++j;
    }
    mergeGroup(store, list, patches, clusterAt);
    apply.update(j);
    i = j;
  }
  store.sync();
  double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return {"weld", {{"merged", merged}, {"clusters", uint64_t(list.size())}}, seconds};
}

}  // namespace mt::heal
