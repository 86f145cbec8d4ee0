// The patch store's write path: PatchStore::writeBack, BMT section 6's write-back of an edited
// region ("the simplified region is split into new patches ... and the boundary lists of the
// adjacent patches are updated"), and putBlob. Crash safety (store_format.h): the new blocks are
// appended first, the records change in memory, and one manifest edit commits them.
#include <algorithm>
#include <cassert>
#include <map>
#include <shared_mutex>

#include "patchstore/store_impl.h"

namespace mt {

using namespace store_format;

void PatchStore::Impl::startUpdate(const std::string& where) {
  if (!failedCommit.empty()) fail(where, "store refuses updates after a failed commit; reopen it");
  {
    std::lock_guard<std::mutex> lock(appendMutex);
    if (!appendError.empty()) fail(where, "store refuses updates after a failed write (" + appendError + "); reopen it");
  }
  lockForWriting();
}

void PatchStore::Impl::removeRecord(std::map<PatchId, PatchRecord>::iterator it) {
  assert(it != patches.end());
  const PatchId id = it->first;
  addLive(it->second, -1);
  patches.erase(it);
  pendingRemoved.push_back(id);
  pendingUpserted.erase(id);
}

void PatchStore::Impl::replaceRecord(const PatchRecord& rec) {
  assert(patches.count(rec.meta.id));
  addLive(patches[rec.meta.id], -1);
  patches[rec.meta.id] = rec;
  addLive(rec, +1);
  pendingUpserted[rec.meta.id] = rec;
}

void PatchStore::Impl::insertRecord(const PatchRecord& rec) {
  assert(!patches.count(rec.meta.id));
  patches[rec.meta.id] = rec;
  addLive(rec, +1);
  pendingUpserted[rec.meta.id] = rec;
}

void PatchStore::putBlob(const std::string& name, const std::string& bytes) {
  std::lock_guard<std::mutex> w(impl_->writeMutex);
  impl_->lockForWriting();
  std::unique_lock lock(impl_->stateMutex);
  impl_->blobs[name] = bytes;
  impl_->pendingBlobs[name] = bytes;
  impl_->pendingDirty = true;
}

namespace {

[[noreturn]] void bad(const std::string& dir, const std::string& what) { fail(dir, "write back: " + what); }

// A copy of patch id's record (`ifMissing`: the error when it does not exist).
PatchRecord recordOf(const PatchStore::Impl& impl, PatchId id, const std::string& dir, const std::string& ifMissing) {
  std::shared_lock lock(impl.stateMutex);
  auto it = impl.patches.find(id);
  if (it == impl.patches.end()) bad(dir, ifMissing);
  return it->second;
}

std::vector<BoundaryEntry> boundaryOf(const PatchStore::Impl& impl, const PatchRecord& rec, const std::string& dir) {
  return decodeBoundary(impl.readBlock(rec.boundary, "patch " + std::to_string(rec.meta.id) + " boundary list"), dir);
}

// The outside patches may have been replaced since the load (a neighbouring region written back
// in between): where they hold our vertices is re-read from the loaded patches' current lists.
LoadedMesh refreshExternal(const PatchStore::Impl& impl, const std::string& dir, const LoadedMesh& loadedIn) {
  assert(loadedIn.unifiedOf.size() == loadedIn.patches.size());
  LoadedMesh refreshed;
  refreshed.patches = loadedIn.patches;
  for (size_t k = 0; k < loadedIn.patches.size(); ++k) {
    const PatchRecord rec = recordOf(impl, loadedIn.patches[k], dir,
                                     "loaded patch " + std::to_string(loadedIn.patches[k]) + " no longer exists");
    for (const BoundaryEntry& e : boundaryOf(impl, rec, dir))
      if (!std::binary_search(loadedIn.patches.begin(), loadedIn.patches.end(), e.neighbour)) {
        uint32_t v = loadedIn.unifiedOf[k].at(e.local);
        if (!loadedIn.locked[v]) bad(dir, "vertex " + std::to_string(v) + " became shared after the load");
        refreshed.external.push_back({v, e.neighbour, e.remote});
      }
  }
  std::sort(refreshed.external.begin(), refreshed.external.end());
  refreshed.external.erase(std::unique(refreshed.external.begin(), refreshed.external.end()), refreshed.external.end());
  return refreshed;
}

void checkReplacement(const ReplacementMesh& r, const VertexLayout& layout, const std::string& dir) {
  const size_t nv = r.positions.size() / 3, nt = r.triangles.size() / 3;
  if (r.origin.size() != nv) bad(dir, "origin has " + std::to_string(r.origin.size()) + " entries for " + std::to_string(nv) + " vertices");
  if (r.triangleCell.size() != nt) bad(dir, "triangleCell has the wrong size");
  if (layout.normals && r.normals.size() != nv * 3) bad(dir, "normals missing");
  if (layout.colors && r.colors.size() != nv * 4) bad(dir, "colours missing");
  if (layout.texcoords && (r.cornerUV.size() != nt * 6 || r.triangleMaterial.size() != nt))
    bad(dir, "texture coordinates missing");
  for (size_t i = 0; i < r.triangles.size(); ++i)
    if (r.triangles[i] >= nv) bad(dir, "triangle " + std::to_string(i / 3) + " references vertex out of range");
}

// Where each loaded vertex went (kNoVertex: removed), checking the crack-free rule: every vertex
// an outside patch holds must survive, unmoved.
std::vector<uint32_t> placeLoadedVertices(const LoadedMesh& loadedIn, const LoadedMesh& loaded, const ReplacementMesh& r,
                                          const std::string& dir) {
  const uint32_t nv = uint32_t(r.positions.size() / 3);
  std::vector<uint32_t> newOf(loadedIn.vertexCount(), kNoVertex);
  for (uint32_t v = 0; v < nv; ++v) {
    uint32_t o = r.origin[v];
    if (o == kNoVertex) continue;
    if (o >= loadedIn.vertexCount()) bad(dir, "origin of vertex " + std::to_string(v) + " out of range");
    if (newOf[o] != kNoVertex) bad(dir, "loaded vertex " + std::to_string(o) + " appears twice");
    newOf[o] = v;
  }
  for (const auto& ext : loaded.external) {
    uint32_t v = newOf[ext.vertex];
    if (v == kNoVertex) bad(dir, "locked vertex " + std::to_string(ext.vertex) + " was removed");
    for (int a = 0; a < 3; ++a)
      if (r.positions[3 * v + a] != loadedIn.positions[3 * ext.vertex + a])
        bad(dir, "locked vertex " + std::to_string(ext.vertex) + " was moved");
  }
  return newOf;
}

// A new patch: the replacement's triangles of one cell key.
struct NewPatch {
  uint64_t cell;
  std::vector<uint32_t> tris;      // replacement triangle ids
  std::vector<uint32_t> vertices;  // replacement vertex ids, ascending = local order
  Patch patch;
};

// Triangles grouped by cell key into new patches, in key order (a region splits into a handful of
// cells: sort the distinct keys, then bucket the triangles in their original order).
std::vector<NewPatch> groupByCell(const ReplacementMesh& r) {
  const size_t nt = r.triangles.size() / 3;
  // The distinct keys, kept sorted as they are met: a handful, and the triangles come in runs of
  // one key (sorting a copy of every triangle's key was ~0.3% of a build's samples). Past 64 keys
  // the inserts would cost more than that sort, which then runs instead.
  std::vector<uint64_t> cells;
  for (size_t t = 0; t < r.triangleCell.size() && cells.size() <= 64; ++t) {
    const uint64_t c = r.triangleCell[t];
    if (t > 0 && c == r.triangleCell[t - 1]) continue;
    const auto at = std::lower_bound(cells.begin(), cells.end(), c);
    if (at == cells.end() || *at != c) cells.insert(at, c);
  }
  if (cells.size() > 64) {
    cells.assign(r.triangleCell.begin(), r.triangleCell.end());
    std::sort(cells.begin(), cells.end());
    cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
  }
  std::vector<NewPatch> out(cells.size());
  std::vector<uint32_t> patchOfTriangle(nt);
  for (size_t k = 0; k < cells.size(); ++k) out[k].cell = cells[k];
  for (uint32_t t = 0; t < nt; ++t) {
    const uint32_t k = t > 0 && r.triangleCell[t] == r.triangleCell[t - 1]
                           ? patchOfTriangle[t - 1]
                           : uint32_t(std::lower_bound(cells.begin(), cells.end(), r.triangleCell[t]) - cells.begin());
    patchOfTriangle[t] = k;
    out[k].tris.push_back(t);
  }
  return out;
}

// Vertex -> new patches holding it, as CSR over replacement vertices (most vertices are in one
// patch). Holders of a vertex are in ascending patch order, and each patch's vertices come out
// ascending with their local index: linear time, no per-corner searches.
struct Holders {
  std::vector<uint32_t> start;         // per replacement vertex, + 1
  std::vector<uint32_t> patch, local;  // per holding: the new patch, the vertex's index there
  bool unused(uint32_t v) const { return start[v] == start[v + 1]; }
  uint32_t localIndex(uint32_t k, uint32_t v) const {
    for (uint32_t h = start[v];; ++h) {
      assert(h < start[v + 1]);  // k holds v
      if (patch[h] == k) return local[h];
    }
  }
};

// Fills every new patch's vertex list too.
Holders findHolders(std::vector<NewPatch>& out, const ReplacementMesh& r) {
  const size_t nv = r.positions.size() / 3;
  Holders h;
  h.start.assign(nv + 1, 0);
  std::vector<uint32_t> mark(nv, ~0u);
  for (uint32_t k = 0; k < out.size(); ++k)
    for (uint32_t t : out[k].tris)
      for (int c = 0; c < 3; ++c) {
        uint32_t v = r.triangles[3 * t + c];
        if (mark[v] != k) mark[v] = k, ++h.start[v + 1];
      }
  for (size_t v = 0; v < nv; ++v) h.start[v + 1] += h.start[v];
  h.patch.resize(h.start[nv]);
  h.local.resize(h.start[nv]);
  std::vector<uint32_t> fill(h.start.begin(), h.start.end() - 1);
  std::fill(mark.begin(), mark.end(), ~0u);
  for (uint32_t k = 0; k < out.size(); ++k)
    for (uint32_t t : out[k].tris)
      for (int c = 0; c < 3; ++c) {
        uint32_t v = r.triangles[3 * t + c];
        if (mark[v] != k) mark[v] = k, h.patch[fill[v]++] = k;
      }
  for (uint32_t v = 0; v < nv; ++v)
    for (uint32_t i = h.start[v]; i < h.start[v + 1]; ++i) {
      auto& vs = out[h.patch[i]].vertices;
      h.local[i] = uint32_t(vs.size());
      vs.push_back(v);
    }
  return h;
}

// Per outside patch, the entries to add to it: (its local index, the entry).
using OutsideAdds = std::map<PatchId, std::vector<std::pair<uint32_t, BoundaryEntry>>>;

// Boundary entries: between new patches, and from new patches to the outside ones (whose
// mirrored entries are returned).
OutsideAdds linkBoundaries(std::vector<NewPatch>& out, const Holders& h, const LoadedMesh& loaded,
                           const std::vector<uint32_t>& newOf, const std::vector<PatchId>& newIds) {
  const uint32_t nv = uint32_t(h.start.size() - 1);
  for (uint32_t v = 0; v < nv; ++v) {
    const uint32_t i = h.start[v], j = h.start[v + 1];
    if (j - i < 2) continue;
    for (uint32_t a = i; a < j; ++a)
      for (uint32_t b = i; b < j; ++b)
        if (a != b) out[h.patch[a]].patch.boundary.push_back({h.local[a], newIds[h.patch[b]], h.local[b]});
  }
  OutsideAdds adds;
  for (const auto& ext : loaded.external) {
    uint32_t v = newOf[ext.vertex];
    for (uint32_t i = h.start[v]; i < h.start[v + 1]; ++i) {
      out[h.patch[i]].patch.boundary.push_back({h.local[i], ext.patch, ext.remote});
      adds[ext.patch].push_back({ext.remote, {ext.remote, newIds[h.patch[i]], h.local[i]}});
    }
  }
  return adds;
}

// The new patches' contents, appended as blocks; their records.
std::vector<PatchRecord> writeNewPatches(PatchStore::Impl& impl, std::vector<NewPatch>& out, const Holders& h,
                                         const ReplacementMesh& r, const std::vector<PatchId>& newIds) {
  const VertexLayout& layout = impl.layout;
  std::vector<PatchRecord> records;
  for (uint32_t k = 0; k < out.size(); ++k) {
    NewPatch& np = out[k];
    Patch& p = np.patch;
    p.id = newIds[k];
    p.cell = np.cell;
    p.level = r.level;
    for (uint32_t v : np.vertices) {
      p.positions.insert(p.positions.end(), &r.positions[3 * v], &r.positions[3 * v] + 3);
      if (layout.normals) p.normals.insert(p.normals.end(), &r.normals[3 * v], &r.normals[3 * v] + 3);
      if (layout.colors) p.colors.insert(p.colors.end(), &r.colors[4 * v], &r.colors[4 * v] + 4);
    }
    for (uint32_t t : np.tris)
      for (int c = 0; c < 3; ++c) p.triangles.push_back(h.localIndex(k, r.triangles[3 * t + c]));
    if (layout.texcoords) {
      for (uint32_t t : np.tris) {
        p.cornerUV.insert(p.cornerUV.end(), &r.cornerUV[6 * size_t(t)], &r.cornerUV[6 * size_t(t)] + 6);
        p.triangleMaterial.push_back(r.triangleMaterial[t]);
      }
      auto it = r.cellAtlas.find(np.cell);
      if (it != r.cellAtlas.end()) p.atlas = it->second;
    }
    std::sort(p.boundary.begin(), p.boundary.end());
    PatchRecord rec;
    rec.meta = {p.id, p.cell, p.level, p.vertexCount(), p.triangleCount(), uint32_t(p.boundary.size()), boundsOf(p.positions)};
    rec.geometry = impl.appendBlock(encodeGeometry(p, layout));
    rec.boundary = impl.appendBlock(encodeBoundary(p.boundary));
    records.push_back(rec);
  }
  return records;
}

// Outside patches: their entries into the loaded set dropped, entries to the new patches added;
// the new boundary blocks appended, the records returned.
std::vector<PatchRecord> relinkOutside(PatchStore::Impl& impl, const std::string& dir, const OutsideAdds& outsideAdds,
                                       const LoadedMesh& loaded) {
  std::vector<PatchRecord> updated;
  for (auto& [q, adds] : outsideAdds) {
    const PatchRecord rec = recordOf(impl, q, dir, "outside patch " + std::to_string(q) + " does not exist");
    auto entries = boundaryOf(impl, rec, dir);
    entries.erase(std::remove_if(entries.begin(), entries.end(),
                                 [&](const BoundaryEntry& e) { return std::binary_search(loaded.patches.begin(), loaded.patches.end(), e.neighbour); }),
                  entries.end());
    for (auto& a : adds) entries.push_back(a.second);
    std::sort(entries.begin(), entries.end());
    entries.erase(std::unique(entries.begin(), entries.end()), entries.end());
    PatchRecord next = rec;
    next.boundary = impl.appendBlock(encodeBoundary(entries));
    next.meta.boundaryEntries = uint32_t(entries.size());
    updated.push_back(next);
  }
  return updated;
}

}  // namespace

std::vector<PatchId> PatchStore::writeBack(const LoadedMesh& loadedIn, const ReplacementMesh& r, bool syncNow) {
  std::lock_guard<std::mutex> writer(impl_->writeMutex);
  impl_->startUpdate(dir_);
  LoadedMesh refreshed;
  const bool refresh = loadedIn.unifiedOf.size() == loadedIn.patches.size();
  if (refresh) refreshed = refreshExternal(*impl_, dir_, loadedIn);
  const LoadedMesh& loaded = refresh ? refreshed : loadedIn;
  checkReplacement(r, impl_->layout, dir_);
  const std::vector<uint32_t> newOf = placeLoadedVertices(loadedIn, loaded, r, dir_);

  std::vector<NewPatch> out = groupByCell(r);
  const Holders holders = findHolders(out, r);
  for (const auto& ext : loaded.external)
    if (holders.unused(newOf[ext.vertex])) bad(dir_, "locked vertex " + std::to_string(ext.vertex) + " is used by no triangle");
  std::vector<PatchId> newIds(out.size());
  {
    std::unique_lock lock(impl_->stateMutex);
    for (auto& id : newIds) id = impl_->nextPatchId++;
  }
  const OutsideAdds outsideAdds = linkBoundaries(out, holders, loaded, newOf, newIds);
  const std::vector<PatchRecord> records = writeNewPatches(*impl_, out, holders, r, newIds);
  const std::vector<PatchRecord> updated = relinkOutside(*impl_, dir_, outsideAdds, loaded);

  {
    std::unique_lock lock(impl_->stateMutex);
    for (PatchId id : loaded.patches) {
      auto it = impl_->patches.find(id);
      if (it == impl_->patches.end()) bad(dir_, "loaded patch " + std::to_string(id) + " no longer exists");
      impl_->removeRecord(it);
    }
    for (const PatchRecord& rec : updated) impl_->replaceRecord(rec);
    for (const PatchRecord& rec : records) impl_->insertRecord(rec);
    impl_->pendingDirty = true;
  }
  if (syncNow || (impl_->autoCommit && impl_->pendingIsLarge())) {
    std::unique_lock lock(impl_->stateMutex);
    impl_->commitPending();
  }
  return newIds;
}

}  // namespace mt
