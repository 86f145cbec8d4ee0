// Healing support for the patch store: in-place rewrites of a few patches and staged position
// updates (declared at the end of PatchStore in patch_store.h). Both follow the crash-safety rule
// of store_format.h: new blocks are appended first, then one manifest edit commits them.
#include <algorithm>
#include <map>
#include <set>
#include <tuple>

#include "patchstore/store_impl.h"

namespace mt {

using namespace store_format;

struct StagedUpdate::Entries {
  struct Entry {
    PatchId id;
    BlockHandle oldGeometry;  // what the patch pointed at when staged: detects conflicts
    BlockHandle newGeometry;
    Box3 bounds;
  };
  std::vector<Entry> list;
};

StagedUpdate::StagedUpdate() : entries_(std::make_unique<Entries>()) {}
StagedUpdate::~StagedUpdate() = default;
size_t StagedUpdate::size() const { return entries_->list.size(); }

namespace {

bool entryLess(const BoundaryEntry& a, const BoundaryEntry& b) {
  return std::tie(a.local, a.neighbour, a.remote) < std::tie(b.local, b.neighbour, b.remote);
}
bool sameHandle(const BlockHandle& a, const BlockHandle& b) {
  return a.segment == b.segment && a.offset == b.offset && a.size == b.size && a.checksum == b.checksum;
}

// The rewrites as the patches will be (`after`: rewritten, new content, geometry read for
// boundaryOnly) and as they are (`outside`: their outside neighbours, old and new), validated.
struct RewriteSet {
  std::map<PatchId, Patch> after;
  std::map<PatchId, bool> onlyBoundary;
  std::map<PatchId, Patch> outside;
};

[[noreturn]] void badRewrite(const std::string& dir, const std::string& what) { fail(dir, "rewrite: " + what); }

RewriteSet readRewrites(const PatchStore& store, const std::vector<PatchRewrite>& rewrites) {
  const std::string& dir = store.dir();
  auto bad = [&](const std::string& what) { badRewrite(dir, what); };
  RewriteSet set;
  std::set<PatchId> outsideIds;
  for (const PatchRewrite& rw : rewrites) {
    PatchId id = rw.patch.id;
    if (set.after.count(id)) bad("patch " + std::to_string(id) + " rewritten twice");
    Patch old = store.patch(id);  // throws for a patch that does not exist
    for (const BoundaryEntry& e : old.boundary) outsideIds.insert(e.neighbour);
    Patch next;
    if (rw.boundaryOnly) {
      next = std::move(old);
      next.boundary = rw.patch.boundary;
    } else {
      next = rw.patch;
      next.cell = old.cell;
      next.level = old.level;
      const VertexLayout& l = store.layout();
      if ((l.normals && next.normals.size() != next.positions.size()) ||
          (l.colors && next.colors.size() != next.positions.size() / 3 * 4))
        bad("patch " + std::to_string(id) + ": normals or colours missing");
      if (l.texcoords && (next.cornerUV.size() != 6 * size_t(next.triangleCount()) ||
                          next.triangleMaterial.size() != next.triangleCount()))
        bad("patch " + std::to_string(id) + ": texture coordinates missing");
      for (uint32_t i : next.triangles)
        if (i >= next.vertexCount()) bad("patch " + std::to_string(id) + ": triangle index out of range");
    }
    std::sort(next.boundary.begin(), next.boundary.end(), entryLess);
    for (size_t i = 0; i < next.boundary.size(); ++i) {
      const BoundaryEntry& e = next.boundary[i];
      if (e.local >= next.vertexCount()) bad("patch " + std::to_string(id) + ": boundary entry past its vertices");
      if (e.neighbour == id) bad("patch " + std::to_string(id) + ": boundary entry points at itself");
      if (i > 0 && !entryLess(next.boundary[i - 1], e)) bad("patch " + std::to_string(id) + ": repeated boundary entry");
      outsideIds.insert(e.neighbour);
    }
    set.onlyBoundary[id] = rw.boundaryOnly;
    set.after.emplace(id, std::move(next));
  }
  for (PatchId q : outsideIds)
    if (!set.after.count(q)) set.outside.emplace(q, store.patch(q));  // throws when a neighbour does not exist
  return set;
}

// Every entry between the two groups, in both directions: it names a kept patch, within its
// vertices, is mirrored there, and the two copies of the vertex have one position.
void checkMirrors(const RewriteSet& set, const std::string& dir) {
  auto find = [&](PatchId q) -> const Patch* {
    auto a = set.after.find(q);
    if (a != set.after.end()) return a->second.triangles.empty() ? nullptr : &a->second;
    auto o = set.outside.find(q);
    return o == set.outside.end() ? nullptr : &o->second;
  };
  auto checkEntry = [&](const Patch& p, const BoundaryEntry& e) {
    std::string name = "patch " + std::to_string(p.id) + " entry (" + std::to_string(e.local) + ", " +
                       std::to_string(e.neighbour) + ", " + std::to_string(e.remote) + ")";
    const Patch* q = find(e.neighbour);
    if (!q) badRewrite(dir, name + " names a patch that is removed or was not read");
    if (e.remote >= q->vertexCount()) badRewrite(dir, name + " points past the neighbour's vertices");
    if (!std::binary_search(q->boundary.begin(), q->boundary.end(), BoundaryEntry{e.remote, p.id, e.local}, entryLess))
      badRewrite(dir, name + " is not mirrored");
    for (int a = 0; a < 3; ++a)
      if (p.positions[3 * e.local + a] != q->positions[3 * e.remote + a]) badRewrite(dir, name + ": the copies differ in position");
  };
  for (auto& [id, p] : set.after) {
    if (p.triangles.empty() && !p.boundary.empty())
      badRewrite(dir, "patch " + std::to_string(id) + " is emptied but still shares vertices");
    for (const BoundaryEntry& e : p.boundary) checkEntry(p, e);
  }
  for (auto& [id, q] : set.outside)
    for (const BoundaryEntry& e : q.boundary)
      if (set.after.count(e.neighbour)) checkEntry(q, e);
}

}  // namespace

void PatchStore::rewritePatches(const std::vector<PatchRewrite>& rewrites, bool syncNow) {
  std::lock_guard<std::mutex> writer(impl_->writeMutex);
  impl_->startUpdate(dir_);
  RewriteSet set = readRewrites(*this, rewrites);
  checkMirrors(set, dir_);
  std::map<PatchId, Patch>& after = set.after;
  std::map<PatchId, bool>& onlyBoundary = set.onlyBoundary;

  // Blocks first, then the records: the commit (now, or with the next sync) is the edit.
  std::vector<PatchRecord> updated;
  std::vector<PatchId> removed;
  for (auto& [id, p] : after) {
    if (p.triangles.empty()) {
      removed.push_back(id);
      continue;
    }
    PatchRecord rec;
    {
      std::shared_lock lock(impl_->stateMutex);
      rec = impl_->patches.at(id);
    }
    if (!onlyBoundary[id]) {
      rec.geometry = impl_->appendBlock(encodeGeometry(p, impl_->layout));
      rec.meta.vertices = p.vertexCount();
      rec.meta.triangles = p.triangleCount();
      rec.meta.bounds = boundsOf(p.positions);
    }
    rec.boundary = impl_->appendBlock(encodeBoundary(p.boundary));
    rec.meta.boundaryEntries = uint32_t(p.boundary.size());
    updated.push_back(rec);
  }
  {
    std::unique_lock lock(impl_->stateMutex);
    for (PatchId id : removed) impl_->removeRecord(impl_->patches.find(id));
    for (const PatchRecord& rec : updated) impl_->replaceRecord(rec);
    impl_->pendingDirty = true;
    if (syncNow || impl_->pendingIsLarge()) impl_->commitPending();
  }
}

void PatchStore::stageGeometry(StagedUpdate& staged, const Patch& p) {
  std::lock_guard<std::mutex> writer(impl_->writeMutex);
  impl_->startUpdate(dir_);
  PatchRecord rec;
  {
    std::shared_lock lock(impl_->stateMutex);
    auto it = impl_->patches.find(p.id);
    if (it == impl_->patches.end()) fail(dir_, "stage: no patch " + std::to_string(p.id));
    rec = it->second;
  }
  if (rec.meta.vertices != p.vertexCount() || rec.meta.triangles != p.triangleCount())
    fail(dir_, "stage: patch " + std::to_string(p.id) + " changed its vertex or triangle count");
  StagedUpdate::Entries::Entry e{p.id, rec.geometry, impl_->appendBlock(encodeGeometry(p, impl_->layout)), boundsOf(p.positions)};
  {
    // Count the staged block as live at once, so that no commit in between can delete its
    // segment as dead before commitStaged references it.
    std::unique_lock lock(impl_->stateMutex);
    impl_->liveBytes[e.newGeometry.segment] += e.newGeometry.size + sizeof(BlockHeader);
    ++impl_->stagedBlocks;
  }
  staged.entries_->list.push_back(e);
}

void PatchStore::commitStaged(StagedUpdate& staged) {
  std::lock_guard<std::mutex> writer(impl_->writeMutex);
  std::unique_lock lock(impl_->stateMutex);
  auto& list = staged.entries_->list;
  for (const auto& e : list) {
    auto it = impl_->patches.find(e.id);
    if (it == impl_->patches.end() || !sameHandle(it->second.geometry, e.oldGeometry))
      fail(dir_, "commit staged: patch " + std::to_string(e.id) + " was changed after it was staged");
  }
  for (const auto& e : list) {
    PatchRecord& rec = impl_->patches[e.id];
    impl_->liveBytes[rec.geometry.segment] -= rec.geometry.size + sizeof(BlockHeader);
    rec.geometry = e.newGeometry;  // its live bytes were counted when it was staged
    rec.meta.bounds = e.bounds;
    impl_->pendingUpserted[e.id] = rec;
  }
  impl_->stagedBlocks -= std::min(impl_->stagedBlocks, list.size());
  list.clear();
  impl_->pendingDirty = true;
  impl_->commitPending();  // one manifest edit for the whole iteration
}

}  // namespace mt
