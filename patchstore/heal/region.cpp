// Regions (load in place, edit, commit in place), global vertex keys, the edge census, reports.
#include "patchstore/heal/region.h"

#include <algorithm>
#include <cassert>
#include <cinttypes>
#include <cstdio>
#include <filesystem>
#include <map>
#include <set>
#include <tuple>

#include "base/external_sort.h"
#include "base/memory_plan.h"
#include "base/progress.h"

namespace mt::heal {

uint64_t PassReport::get(const std::string& name) const {
  for (auto& [k, v] : counts)
    if (k == name) return v;
  return 0;
}

std::string PassReport::line() const {
  std::string s = pass + ":";
  for (size_t i = 0; i < counts.size(); ++i)
    s += (i ? ", " : " ") + counts[i].first + " " + std::to_string(counts[i].second);
  char t[32];
  std::snprintf(t, sizeof t, " (%.2f s)", seconds);
  return s + t;
}

std::string scratchPrefix(const PatchStore& store, const HealOptions& options, const std::string& name) {
  std::string dir = options.tempDir.empty() ? store.dir() + "/tmp" : options.tempDir;
  std::filesystem::create_directories(dir);
  return dir + "/heal-" + name;
}

std::vector<uint64_t> ownerKeys(const Patch& p) {
  std::vector<uint64_t> key(p.vertexCount());
  for (uint32_t v = 0; v < p.vertexCount(); ++v) key[v] = gidOf(p.id, v);
  for (const BoundaryEntry& e : p.boundary)
    if (e.neighbour < gidPatch(key[e.local])) key[e.local] = gidOf(e.neighbour, e.remote);
  return key;
}

int Region::indexOf(PatchId id) const {
  auto it = std::lower_bound(patches.begin(), patches.end(), id);
  return it != patches.end() && *it == id ? int(it - patches.begin()) : -1;
}

uint32_t Region::vertexOf(PatchId id, uint32_t local) const {
  int k = indexOf(id);
  if (k < 0 || local >= unifiedOf[k].size()) return kNoVertex;
  return unifiedOf[k][local];
}

Region loadRegion(const PatchStore& store, std::vector<PatchId> ids) {
  std::sort(ids.begin(), ids.end());
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  Region r;
  r.patches = ids;
  const VertexLayout& layout = store.layout();
  auto loaded = [&](PatchId q) { return std::binary_search(ids.begin(), ids.end(), q); };
  for (size_t k = 0; k < ids.size(); ++k) {
    Patch p = store.patch(ids[k]);
    std::vector<uint32_t> map(p.vertexCount(), kNoVertex);
    // A vertex a lower loaded patch also holds takes the index that patch's copy got.
    for (const BoundaryEntry& e : p.boundary)
      if (e.neighbour < p.id && loaded(e.neighbour) && map[e.local] == kNoVertex)
        map[e.local] = r.unifiedOf[r.indexOf(e.neighbour)].at(e.remote);
    for (uint32_t v = 0; v < p.vertexCount(); ++v) {
      if (map[v] != kNoVertex) continue;
      map[v] = r.vertexCount();
      r.positions.insert(r.positions.end(), &p.positions[3 * v], &p.positions[3 * v] + 3);
      if (layout.normals) r.normals.insert(r.normals.end(), &p.normals[3 * v], &p.normals[3 * v] + 3);
      if (layout.colors) r.colors.insert(r.colors.end(), &p.colors[4 * v], &p.colors[4 * v] + 4);
      r.locked.push_back(0);
    }
    for (const BoundaryEntry& e : p.boundary)
      if (!loaded(e.neighbour)) {
        r.locked[map[e.local]] = 1;
        r.external.push_back({map[e.local], e.neighbour, e.remote});
      }
    for (uint32_t i : p.triangles) r.triangles.push_back(map[i]);
    r.trianglePatch.insert(r.trianglePatch.end(), p.triangleCount(), uint32_t(k));
    if (layout.texcoords) {
      r.cornerUV.insert(r.cornerUV.end(), p.cornerUV.begin(), p.cornerUV.end());
      r.triangleMaterial.insert(r.triangleMaterial.end(), p.triangleMaterial.begin(), p.triangleMaterial.end());
    }
    r.unifiedOf.push_back(std::move(map));
    r.original.push_back(std::move(p));
  }
  std::sort(r.external.begin(), r.external.end(),
            [](const auto& a, const auto& b) { return std::tie(a.vertex, a.patch, a.remote) < std::tie(b.vertex, b.patch, b.remote); });
  // Two loaded holders of one vertex both list the unloaded third: keep one entry.
  r.external.erase(std::unique(r.external.begin(), r.external.end(),
                               [](const auto& a, const auto& b) { return a.vertex == b.vertex && a.patch == b.patch && a.remote == b.remote; }),
                   r.external.end());
  return r;
}

Region loadUnlocked(const PatchStore& store, std::vector<PatchId> ids,
                    const std::function<bool(const Region&, uint32_t)>& wanted, size_t maxPatches) {
  for (;;) {
    Region r = loadRegion(store, ids);
    std::set<PatchId> more;
    for (const auto& e : r.external)
      if (wanted(r, e.vertex)) more.insert(e.patch);
    if (more.empty() || r.patches.size() + more.size() > maxPatches) return r;
    ids = r.patches;
    ids.insert(ids.end(), more.begin(), more.end());
  }
}

uint32_t RegionEdit::addVertexCopy(const Region& r, uint32_t v) {
  uint32_t id = vertexCount();
  positions.insert(positions.end(), &r.positions[3 * v], &r.positions[3 * v] + 3);
  if (!r.normals.empty()) normals.insert(normals.end(), &r.normals[3 * v], &r.normals[3 * v] + 3);
  if (!r.colors.empty()) colors.insert(colors.end(), &r.colors[4 * v], &r.colors[4 * v] + 4);
  origin.push_back(kNoVertex);
  return id;
}

void RegionEdit::keepTriangle(const Region& r, size_t t, const uint32_t* v) {
  if (v) triangles.insert(triangles.end(), v, v + 3);
  else triangles.insert(triangles.end(), &r.triangles[3 * t], &r.triangles[3 * t] + 3);
  trianglePatch.push_back(r.trianglePatch[t]);
  if (!r.cornerUV.empty()) {
    cornerUV.insert(cornerUV.end(), &r.cornerUV[6 * t], &r.cornerUV[6 * t] + 6);
    triangleMaterial.push_back(r.triangleMaterial[t]);
  }
}

void RegionEdit::addTriangle(const uint32_t v[3], uint32_t k, bool textured) {
  triangles.insert(triangles.end(), v, v + 3);
  trianglePatch.push_back(k);
  if (textured) {
    cornerUV.insert(cornerUV.end(), 6, 0.0f);
    triangleMaterial.push_back(kNoMaterial);
  }
}

void RegionEdit::clearTriangles() {
  triangles.clear();
  trianglePatch.clear();
  cornerUV.clear();
  triangleMaterial.clear();
}

RegionEdit identityEdit(const Region& r) {
  RegionEdit e;
  e.cornerUV = r.cornerUV;
  e.triangleMaterial = r.triangleMaterial;
  e.positions = r.positions;
  e.normals = r.normals;
  e.colors = r.colors;
  e.origin.resize(r.vertexCount());
  for (uint32_t v = 0; v < r.vertexCount(); ++v) e.origin[v] = v;
  e.triangles = r.triangles;
  e.trianglePatch = r.trianglePatch;
  return e;
}

namespace {
bool entryLess(const BoundaryEntry& a, const BoundaryEntry& b) {
  return std::tie(a.local, a.neighbour, a.remote) < std::tie(b.local, b.neighbour, b.remote);
}
bool samePatch(const Patch& a, const Patch& b) {
  return a.positions == b.positions && a.triangles == b.triangles && a.normals == b.normals && a.colors == b.colors &&
         a.cornerUV == b.cornerUV && a.triangleMaterial == b.triangleMaterial;
}
bool sameBoundary(const std::vector<BoundaryEntry>& a, const std::vector<BoundaryEntry>& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i)
    if (entryLess(a[i], b[i]) || entryLess(b[i], a[i])) return false;
  return true;
}
// Where each region vertex went in the edit (kNoVertex: dropped).
std::vector<uint32_t> editVertexOf(const PatchStore& store, const Region& r, const RegionEdit& e) {
  std::vector<uint32_t> newOf(r.vertexCount(), kNoVertex);
  for (uint32_t v = 0; v < e.vertexCount(); ++v)
    if (e.origin[v] != kNoVertex) {
      if (newOf[e.origin[v]] != kNoVertex) fail(store.dir(), "heal: region vertex kept twice (internal error)");
      newOf[e.origin[v]] = v;
    }
  return newOf;
}

// Which loaded patch holds which edit vertex, and at which local index.
struct PatchVertices {
  std::vector<std::vector<uint32_t>> tris;   // per patch: its edit triangles
  std::vector<std::vector<uint32_t>> verts;  // per patch: edit vertex of each local index
  std::vector<std::pair<uint32_t, uint32_t>> holders;  // (edit vertex, patch index), sorted
  std::vector<std::vector<std::pair<uint32_t, uint32_t>>> localPairs;  // per patch: (edit vertex, local), sorted
  std::vector<uint8_t> used;                 // per edit vertex: some triangle uses it
  uint32_t localIn(size_t k, uint32_t v) const {
    auto it = std::lower_bound(localPairs[k].begin(), localPairs[k].end(), std::make_pair(v, 0u));
    assert(it != localPairs[k].end() && it->first == v);  // patch k holds v
    return it->second;
  }
};

// Each patch's vertex list: its surviving original vertices in their old order, then the
// vertices it newly uses in edit order (so an unchanged patch comes out identical).
PatchVertices patchVertices(const Region& r, const RegionEdit& e, const std::vector<uint32_t>& newOf) {
  const size_t np = r.patches.size();
  const uint32_t nv = e.vertexCount();
  PatchVertices pv;
  pv.tris.resize(np);
  for (size_t t = 0; t < e.trianglePatch.size(); ++t) pv.tris[e.trianglePatch[t]].push_back(uint32_t(t));
  pv.used.assign(nv, 0);
  pv.verts.resize(np);
  pv.localPairs.resize(np);
  // Per patch in turn, the edit vertices its triangles use (1), those placed already (2); cleared
  // after each patch, so the work is the patch's, not the region's (a scan of every edit vertex per
  // patch made grid weld groups of 32 patches quadratic).
  std::vector<uint8_t> mine(nv, 0);
  std::vector<uint32_t> usedBy;
  for (size_t k = 0; k < np; ++k) {
    usedBy.clear();
    for (uint32_t t : pv.tris[k])
      for (int c = 0; c < 3; ++c) {
        const uint32_t v = e.triangles[3 * t + c];
        if (!mine[v]) mine[v] = 1, usedBy.push_back(v);
      }
    for (uint32_t u : r.unifiedOf[k]) {
      uint32_t v = newOf[u];
      if (v != kNoVertex && mine[v] == 1) {
        pv.verts[k].push_back(v);
        mine[v] = 2;
      }
    }
    std::sort(usedBy.begin(), usedBy.end());
    for (uint32_t v : usedBy) {
      if (mine[v] == 1) pv.verts[k].push_back(v);
      mine[v] = 0;
    }
    for (uint32_t l = 0; l < pv.verts[k].size(); ++l) {
      pv.holders.push_back({pv.verts[k][l], uint32_t(k)});
      pv.localPairs[k].push_back({pv.verts[k][l], l});
      pv.used[pv.verts[k][l]] = 1;
    }
    std::sort(pv.localPairs[k].begin(), pv.localPairs[k].end());
  }
  std::sort(pv.holders.begin(), pv.holders.end());
  return pv;
}

// The loaded patches as they will be: vertices, attributes, triangles, and the boundary entries
// between the loaded patches (every pair of holders of a vertex).
std::vector<Patch> editedPatches(const PatchStore& store, const Region& r, const RegionEdit& e, const PatchVertices& pv) {
  const bool normals = store.layout().normals, colors = store.layout().colors;
  std::vector<Patch> out(r.patches.size());
  // Edit vertex -> local index in the patch being written (a binary search per corner was half of
  // the grid weld's time on scans with many close vertices); reset after each patch.
  std::vector<uint32_t> localOf(e.vertexCount(), kNoVertex);
  for (size_t k = 0; k < out.size(); ++k) {
    Patch& p = out[k];
    p.id = r.patches[k];
    for (uint32_t l = 0; l < pv.verts[k].size(); ++l) {
      const uint32_t v = pv.verts[k][l];
      localOf[v] = l;
      p.positions.insert(p.positions.end(), &e.positions[3 * v], &e.positions[3 * v] + 3);
      if (normals) p.normals.insert(p.normals.end(), &e.normals[3 * v], &e.normals[3 * v] + 3);
      if (colors) p.colors.insert(p.colors.end(), &e.colors[4 * v], &e.colors[4 * v] + 4);
    }
    p.triangles.reserve(3 * pv.tris[k].size());
    for (uint32_t t : pv.tris[k])
      for (int c = 0; c < 3; ++c) {
        const uint32_t l = localOf[e.triangles[3 * t + c]];
        assert(l != kNoVertex && "patch k holds every corner of its triangles");
        p.triangles.push_back(l);
      }
    for (uint32_t v : pv.verts[k]) localOf[v] = kNoVertex;
    if (store.layout().texcoords) {
      if (e.cornerUV.size() != 6 * e.trianglePatch.size() || e.triangleMaterial.size() != e.trianglePatch.size())
        fail(store.dir(), "heal: an edit lost its texture coordinates (internal error)");
      for (uint32_t t : pv.tris[k]) {
        p.cornerUV.insert(p.cornerUV.end(), &e.cornerUV[6 * size_t(t)], &e.cornerUV[6 * size_t(t)] + 6);
        p.triangleMaterial.push_back(e.triangleMaterial[t]);
      }
      p.atlas = r.original[k].atlas;
    }
  }
  const auto& holders = pv.holders;
  for (size_t i = 0; i < holders.size();) {
    size_t j = i;
    while (j < holders.size() && holders[j].first == holders[i].first) ++j;
    for (size_t a = i; a < j; ++a)
      for (size_t b = i; b < j; ++b)
        if (a != b) {
          uint32_t ka = holders[a].second, kb = holders[b].second;
          out[ka].boundary.push_back({pv.localIn(ka, holders[a].first), r.patches[kb], pv.localIn(kb, holders[b].first)});
        }
    i = j;
  }
  return out;
}

// The unloaded patches the region shared vertices with, and the entries they get into it.
struct OutsideLinks {
  std::set<PatchId> ids;
  std::map<PatchId, std::vector<BoundaryEntry>> adds;
};

// Entries between the loaded patches that still use a shared vertex and its unloaded holders.
OutsideLinks linkOutside(const Region& r, const std::vector<uint32_t>& newOf, const PatchVertices& pv,
                         std::vector<Patch>& out) {
  OutsideLinks links;
  for (const auto& x : r.external) {
    links.ids.insert(x.patch);
    uint32_t v = newOf[x.vertex];
    if (v == kNoVertex || !pv.used[v]) continue;
    auto lo = std::lower_bound(pv.holders.begin(), pv.holders.end(), std::make_pair(v, 0u));
    for (auto it = lo; it != pv.holders.end() && it->first == v; ++it) {
      uint32_t local = pv.localIn(it->second, v);
      out[it->second].boundary.push_back({local, x.patch, x.remote});
      links.adds[x.patch].push_back({x.remote, r.patches[it->second], local});
    }
  }
  return links;
}

// The patches that changed: loaded ones (geometry, or only their lists), and unloaded ones whose
// entries into the region are rebuilt.
std::vector<PatchRewrite> changedPatches(const PatchStore& store, const Region& r, std::vector<Patch>& out,
                                         OutsideLinks& links) {
  std::vector<PatchRewrite> rewrites;
  for (size_t k = 0; k < out.size(); ++k) {
    std::sort(out[k].boundary.begin(), out[k].boundary.end(), entryLess);
    const Patch& old = r.original[k];
    bool geometry = !samePatch(out[k], old);
    bool boundary = !sameBoundary(out[k].boundary, old.boundary);
    if (!geometry && !boundary) continue;
    rewrites.push_back({std::move(out[k]), !geometry});
  }
  for (PatchId q : links.ids) {
    Patch old = store.patch(q);
    std::vector<BoundaryEntry> list;
    for (const BoundaryEntry& b : old.boundary)
      if (r.indexOf(b.neighbour) < 0) list.push_back(b);
    auto& adds = links.adds[q];
    list.insert(list.end(), adds.begin(), adds.end());
    std::sort(list.begin(), list.end(), entryLess);
    if (sameBoundary(list, old.boundary)) continue;
    Patch p;
    p.id = q;
    p.boundary = std::move(list);
    rewrites.push_back({std::move(p), true});
  }
  return rewrites;
}

}  // namespace

CommitStats commitRegion(PatchStore& store, const Region& r, const RegionEdit& e) {
  CommitStats stats;
  const std::vector<uint32_t> newOf = editVertexOf(store, r, e);
  const PatchVertices pv = patchVertices(r, e, newOf);
  // The crack-free rule: a vertex unloaded patches hold keeps its position while it is used.
  for (const auto& x : r.external) {
    uint32_t v = newOf[x.vertex];
    if (v == kNoVertex || !pv.used[v]) continue;
    for (int a = 0; a < 3; ++a)
      if (e.positions[3 * v + a] != r.positions[3 * x.vertex + a])
        fail(store.dir(), "heal: a vertex shared with an unloaded patch was moved (internal error)");
  }
  for (uint32_t u = 0; u < r.vertexCount(); ++u)
    if (!r.locked[u] && (newOf[u] == kNoVertex || !pv.used[newOf[u]])) ++stats.droppedVertices;

  std::vector<Patch> out = editedPatches(store, r, e, pv);
  OutsideLinks links = linkOutside(r, newOf, pv, out);
  std::vector<PatchRewrite> rewrites = changedPatches(store, r, out, links);
  stats.changedPatches = rewrites.size();
  if (!rewrites.empty()) store.rewritePatches(rewrites);
  return stats;
}

// ---------------------------------------------------------------------------------------------

namespace {
struct EdgeRecord {
  uint64_t a, b;
  uint32_t count, patch, forward, pad;
};
struct EdgeLess {
  bool operator()(const EdgeRecord& x, const EdgeRecord& y) const {
    return std::tie(x.a, x.b, x.patch) < std::tie(y.a, y.b, y.patch);
  }
};
}  // namespace

void edgeCensus(const PatchStore& store, const HealOptions& options, const std::function<bool(uint32_t)>& want,
                const std::function<void(const EdgeUse&)>& fn, const char* task) {
  ExternalSorter<EdgeRecord, EdgeLess> sorter(scratchPrefix(store, options, "edges"), planMemory(options.memoryBytes, 1).healSorter);
  std::vector<PatchId> ids = store.patchIds();
  Progress progress(options.progress, task, ids.size(), "patches");
  std::vector<EdgeRecord> local;
  size_t done = 0;
  for (PatchId id : ids) {
    Patch p = store.patch(id);
    std::vector<uint64_t> key = ownerKeys(p);
    std::vector<uint8_t> shared(p.vertexCount(), 0);
    for (const BoundaryEntry& e : p.boundary) shared[e.local] = 1;
    local.clear();
    for (size_t t = 0; t < p.triangles.size(); t += 3)
      for (int c = 0; c < 3; ++c) {
        uint32_t u = p.triangles[t + c], v = p.triangles[t + (c + 1) % 3];
        if (u == v) continue;
        uint64_t ku = key[u], kv = key[v];
        bool fwd = ku < kv;
        local.push_back({std::min(ku, kv), std::max(ku, kv), 1, id, fwd ? 1u : 0u, (shared[u] && shared[v]) ? 1u : 0u});
      }
    std::sort(local.begin(), local.end(), [](const EdgeRecord& x, const EdgeRecord& y) { return std::tie(x.a, x.b) < std::tie(y.a, y.b); });
    for (size_t i = 0; i < local.size();) {
      size_t j = i;
      while (j < local.size() && local[j].a == local[i].a && local[j].b == local[i].b) ++j;
      EdgeRecord rec = local[i];
      rec.count = uint32_t(j - i);
      if (rec.pad) {
        rec.pad = 0;
        sorter.add(rec);
      } else if (want(rec.count)) {
        fn({rec.a, rec.b, rec.count, rec.forward != 0, rec.patch});
      }
      i = j;
    }
    progress.update(++done);
  }
  sorter.finish();
  EdgeRecord rec, cur{};
  bool have = false;
  uint32_t total = 0;
  auto flush = [&]() {
    if (have && want(total)) fn({cur.a, cur.b, total, cur.forward != 0, cur.patch});
  };
  while (sorter.next(rec)) {
    if (have && rec.a == cur.a && rec.b == cur.b) {
      total += rec.count;
      continue;
    }
    flush();
    cur = rec;
    total = rec.count;
    have = true;
  }
  flush();
  progress.finish(done);
}

}  // namespace mt::heal
