// The patch store: opening, blocks and segments, and the read API (patch, meta, info, load,
// assemble). The other jobs of the class are in the files store_impl.h lists. Format and
// crash-safety rules: store_format.h.
#include <algorithm>
#include <cinttypes>
#include <cstdio>
#include <cstring>
#include <unordered_map>

#include "base/fuzzing.h"
#include "patchstore/store_impl.h"

namespace mt {

using namespace store_format;

namespace {

constexpr uint64_t kSegmentRollBytes = 256ull << 20;

std::string numbered(const std::string& dir, const char* prefix, uint64_t n, const char* suffix) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%s%06" PRIu64 "%s", prefix, n, suffix);
  return dir + "/" + buf;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Blocks and segments

std::string PatchStore::Impl::segmentPath(uint32_t n) const { return numbered(dir, "SEG-", n, ".dat"); }
std::string PatchStore::Impl::manifestPath(uint64_t n) const { return numbered(dir, "MANIFEST-", n, ""); }

void PatchStore::Impl::startSegment() {
  std::lock_guard<std::mutex> lock(appendMutex);
  startSegmentLocked();
}

void PatchStore::Impl::startSegmentLocked() {
  if (activeWriter) {
    flushAppendsLocked(true);
    activeWriter->close();
  }
  activeSegment = nextSegment++;
  activeWriter = std::make_unique<BufferedWritableFile>(env->newWritableFile(segmentPath(activeSegment)));
  liveBytes[activeSegment] += 0;
  segmentBytes[activeSegment] = 0;
}

void PatchStore::Impl::flushAppendsLocked(bool sync) const {
  if (!activeWriter) return;
  try {
    if (sync)
      activeWriter->sync();
    else
      activeWriter->flush();
  } catch (const Error& e) {
    appendError = e.what();
    throw;
  }
}

BlockHandle PatchStore::Impl::appendBlock(const std::string& payload) {
  std::lock_guard<std::mutex> lock(appendMutex);
  if (!appendError.empty()) fail(dir, "store refuses updates after a failed write (" + appendError + "); reopen it");
  if (!activeWriter || activeWriter->size() >= kSegmentRollBytes) startSegmentLocked();
  BlockHeader h{kBlockMagic, uint32_t(payload.size()), blockChecksum(payload.data(), payload.size())};
  BlockHandle handle{activeSegment, h.size, activeWriter->size(), h.checksum};
  try {
    activeWriter->append(&h, sizeof h);
    activeWriter->append(payload.data(), payload.size());
  } catch (const Error& e) {
    appendError = e.what();
    throw;
  }
  segmentBytes[activeSegment] = activeWriter->size();
  return handle;
}

std::string PatchStore::Impl::readBlock(const BlockHandle& h, const std::string& what) const {
  std::shared_ptr<RandomAccessFile> file;
  {
    // A block still in the active segment's buffer is written out first.
    std::lock_guard<std::mutex> lock(appendMutex);
    if (activeWriter && h.segment == activeSegment && h.offset + sizeof(BlockHeader) + h.size > activeWriter->flushedSize())
      flushAppendsLocked(false);
  }
  {
    std::lock_guard<std::mutex> lock(readersMutex);
    auto it = readers.find(h.segment);
    // The segment being appended to grows: reopen a reader opened before the block was written.
    if (it != readers.end() && h.offset + sizeof(BlockHeader) + h.size > it->second->size()) {
      readers.erase(it);
      it = readers.end();
    }
    if (it == readers.end())
      it = readers.emplace(h.segment, std::shared_ptr<RandomAccessFile>(env->newRandomAccessFile(segmentPath(h.segment)))).first;
    file = it->second;
  }
  std::string where = segmentPath(h.segment);
  std::string at = what + " at byte offset " + std::to_string(h.offset);
  if (h.offset + sizeof(BlockHeader) + h.size > file->size()) fail(where, at + ": block extends past the end of the file");
  std::string bytes(sizeof(BlockHeader) + h.size, '\0');
  file->read(h.offset, bytes.size(), bytes.data());
  BlockHeader header;
  std::memcpy(&header, bytes.data(), sizeof header);
  if (header.magic != kBlockMagic) failCorrupt(where, at + ": bad block magic");
  if (header.size != h.size) failCorrupt(where, at + ": block size does not match the manifest");
  uint64_t sum = blockChecksum(bytes.data() + sizeof header, h.size);
  if (kChecksumsChecked && (sum != header.checksum || sum != h.checksum)) failCorrupt(where, at + ": checksum mismatch (corrupted block)");
  // In place: substr would allocate and copy the block again (a fresh allocation of a large block
  // is page-faulted in, ~3% of a level loop's CPU).
  bytes.erase(0, sizeof header);
  return bytes;
}

void PatchStore::Impl::addLive(const PatchRecord& r, int sign) {
  liveBytes[r.geometry.segment] += uint64_t(int64_t(sign) * int64_t(r.geometry.size + sizeof(BlockHeader)));
  liveBytes[r.boundary.segment] += uint64_t(int64_t(sign) * int64_t(r.boundary.size + sizeof(BlockHeader)));
}

void PatchStore::Impl::dropDeadSegments() {
  retiredReaders.clear();
  for (auto it = liveBytes.begin(); it != liveBytes.end();) {
    if (it->second == 0 && it->first != activeSegment) {
      {
        std::lock_guard<std::mutex> lock(readersMutex);
        auto r = readers.find(it->first);
        if (r != readers.end()) {
          retiredReaders.push_back(r->second);
          readers.erase(r);
        }
      }
      // Unlinked, not overwritten: a reader in another process opened every segment of the
      // version it reads when it opened the store, so it keeps reading this one until it closes.
      env->removeFile(segmentPath(it->first));
      segmentBytes.erase(it->first);
      it = liveBytes.erase(it);
    } else {
      ++it;
    }
  }
}

// ---------------------------------------------------------------------------------------------
// PatchStore

PatchStore::PatchStore(std::unique_ptr<Impl> impl, std::string dir) : impl_(std::move(impl)), dir_(std::move(dir)) {}

PatchStore::~PatchStore() {
  // With autoCommit off only sync() commits (a checkpointed build's pending write-backs are part
  // of a level that is not finished; committing them here would leave a store its checkpoint
  // does not describe). Their blocks are unreferenced and reclaimed by the next writer.
  if (!impl_->failedCommit.empty() || !impl_->autoCommit) return;
  try {
    sync();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s\n", e.what());
  }
}

std::unique_ptr<PatchStore> PatchStore::open(const std::string& dir, Env* env) {
  auto impl = std::make_unique<Impl>();
  impl->env = env;
  impl->dir = dir;
  impl->recover();
  return std::unique_ptr<PatchStore>(new PatchStore(std::move(impl), dir));
}

void PatchStore::lockForWriting() {
  std::lock_guard<std::mutex> w(impl_->writeMutex);
  impl_->lockForWriting();
}

bool PatchStore::lockedForWriting() const { return impl_->writeLock != nullptr; }

const VertexLayout& PatchStore::layout() const { return impl_->layout; }

std::vector<PatchId> PatchStore::patchIds() const {
  std::shared_lock lock(impl_->stateMutex);
  std::vector<PatchId> ids;
  ids.reserve(impl_->patches.size());
  for (auto& [id, rec] : impl_->patches) ids.push_back(id);
  return ids;
}

PatchMeta PatchStore::meta(PatchId id) const {
  std::shared_lock lock(impl_->stateMutex);
  auto it = impl_->patches.find(id);
  if (it == impl_->patches.end()) fail(dir_, "no patch " + std::to_string(id));
  return it->second.meta;
}

std::string PatchStore::blob(const std::string& name) const {
  std::shared_lock lock(impl_->stateMutex);
  auto it = impl_->blobs.find(name);
  return it == impl_->blobs.end() ? std::string() : it->second;
}



Patch PatchStore::patch(PatchId id) const {
  PatchRecord rec;
  {
    std::shared_lock lock(impl_->stateMutex);
    auto it = impl_->patches.find(id);
    if (it == impl_->patches.end()) fail(dir_, "no patch " + std::to_string(id));
    rec = it->second;
  }
  Patch p;
  p.id = id;
  p.cell = rec.meta.cell;
  p.level = rec.meta.level;
  std::string what = "patch " + std::to_string(id);
  decodeGeometry(impl_->readBlock(rec.geometry, what + " geometry"), impl_->layout, p,
                 impl_->segmentPath(rec.geometry.segment) + ": " + what);
  p.boundary = decodeBoundary(impl_->readBlock(rec.boundary, what + " boundary list"),
                              impl_->segmentPath(rec.boundary.segment) + ": " + what);
  for (const BoundaryEntry& e : p.boundary)
    if (e.local >= p.vertexCount())
      fail(impl_->segmentPath(rec.boundary.segment), what + ": boundary entry names vertex " +
                                                         std::to_string(e.local) + " of " + std::to_string(p.vertexCount()));
  return p;
}

StoreInfo PatchStore::info() const {
  StoreInfo s;
  std::shared_lock lock(impl_->stateMutex);
  s.layout = impl_->layout;
  s.bounds = impl_->bounds;
  s.patches = impl_->patches.size();
  s.minPatchTriangles = s.patches ? UINT32_MAX : 0;
  for (auto& [id, rec] : impl_->patches) {
    s.triangles += rec.meta.triangles;
    s.vertices += rec.meta.vertices;
    s.boundaryEntries += rec.meta.boundaryEntries;
    s.minPatchTriangles = std::min(s.minPatchTriangles, rec.meta.triangles);
    s.maxPatchTriangles = std::max(s.maxPatchTriangles, rec.meta.triangles);
    s.liveBytes += rec.geometry.size + rec.boundary.size + 2 * sizeof(BlockHeader);
    // Healing passes move and add vertices (a filled hole's fairing bulges past the input's box,
    // smoothing shifts borders): the box holds every live patch's, so that the MT grid built from
    // it contains every vertex. An unhealed store's patches lie within the input's box already.
    for (int a = 0; a < 3; ++a) {
      s.bounds.lo[a] = std::min(s.bounds.lo[a], rec.meta.bounds.lo[a]);
      s.bounds.hi[a] = std::max(s.bounds.hi[a], rec.meta.bounds.hi[a]);
    }
  }
  s.meanPatchTriangles = s.patches ? double(s.triangles) / double(s.patches) : 0;
  for (const std::string& name : impl_->env->listDir(dir_))
    if (name != "tmp") s.bytesOnDisk += impl_->env->fileSize(dir_ + "/" + name);
  return s;
}

LoadedMesh PatchStore::load(const std::vector<PatchId>& idsIn) const {
  std::vector<PatchId> ids = idsIn;
  std::sort(ids.begin(), ids.end());
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  std::vector<Patch> patches;
  patches.reserve(ids.size());
  for (PatchId id : ids) patches.push_back(patch(id));
  return assemble(patches);
}

LoadedMesh PatchStore::assemble(const std::vector<Patch>& patchesIn) const {
  std::vector<const Patch*> sorted;
  for (const Patch& p : patchesIn) sorted.push_back(&p);
  std::sort(sorted.begin(), sorted.end(), [](const Patch* a, const Patch* b) { return a->id < b->id; });
  std::vector<PatchId> ids;
  for (const Patch* p : sorted) {
    if (!ids.empty() && ids.back() == p->id) fail(dir_, "assemble: patch " + std::to_string(p->id) + " given twice");
    ids.push_back(p->id);
  }
  LoadedMesh m;
  m.patches = ids;
  const VertexLayout& layout = impl_->layout;
  // Unify vertex indices through the boundary lists (BMT section 6): a vertex of patch p that a
  // loaded patch q < p also holds takes the index q's copy already got.
  std::unordered_map<PatchId, std::vector<uint32_t>> unified;
  auto loaded = [&](PatchId q) { return std::binary_search(ids.begin(), ids.end(), q); };
  for (const Patch* patchPtr : sorted) {
    const Patch& p = *patchPtr;
    const PatchId id = p.id;
    std::vector<uint32_t>& map = unified[id];
    map.assign(p.vertexCount(), kNoVertex);
    for (const BoundaryEntry& e : p.boundary)
      if (e.neighbour < id && loaded(e.neighbour) && map[e.local] == kNoVertex) {
        const std::vector<uint32_t>& other = unified[e.neighbour];
        if (e.remote >= other.size())
          fail(dir_, "patch " + std::to_string(id) + ": boundary entry points past patch " + std::to_string(e.neighbour));
        map[e.local] = other[e.remote];
      }
    for (uint32_t v = 0; v < p.vertexCount(); ++v) {
      if (map[v] != kNoVertex) continue;
      map[v] = m.vertexCount();
      m.positions.insert(m.positions.end(), &p.positions[3 * v], &p.positions[3 * v] + 3);
      if (layout.normals) m.normals.insert(m.normals.end(), &p.normals[3 * v], &p.normals[3 * v] + 3);
      if (layout.colors) m.colors.insert(m.colors.end(), &p.colors[4 * v], &p.colors[4 * v] + 4);
      m.locked.push_back(0);
    }
    for (const BoundaryEntry& e : p.boundary)
      if (!loaded(e.neighbour)) {
        m.locked[map[e.local]] = 1;
        m.external.push_back({map[e.local], e.neighbour, e.remote});
      }
    for (uint32_t i : p.triangles) m.triangles.push_back(map[i]);
    m.trianglePatch.insert(m.trianglePatch.end(), p.triangleCount(), id);
    if (layout.texcoords) {
      m.cornerUV.insert(m.cornerUV.end(), p.cornerUV.begin(), p.cornerUV.end());
      m.triangleMaterial.insert(m.triangleMaterial.end(), p.triangleMaterial.begin(), p.triangleMaterial.end());
      m.atlases.push_back(p.atlas);
    }
  }
  for (PatchId id : ids) m.unifiedOf.push_back(std::move(unified[id]));
  std::sort(m.external.begin(), m.external.end());
  m.external.erase(std::unique(m.external.begin(), m.external.end()), m.external.end());
  return m;
}

void PatchStore::setAutoCommit(bool on) {
  std::lock_guard<std::mutex> writer(impl_->writeMutex);
  impl_->autoCommit = on;
}

void PatchStore::sync() {
  if (!impl_) return;
  std::lock_guard<std::mutex> writer(impl_->writeMutex);
  std::unique_lock lock(impl_->stateMutex);
  impl_->commitPending();
}

}  // namespace mt
