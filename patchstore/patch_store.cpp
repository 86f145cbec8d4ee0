// The patch store: manifest log, segment blocks, load, write-back, export and check.
// Format and crash-safety rules: store_format.h.
#include <malloc.h>
#include <xxhash.h>

#include <algorithm>
#include <cctype>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <set>
#include <thread>
#include <unordered_map>

#include "base/byte_io.h"
#include "patchstore/io/ply_writer.h"
#include "patchstore/store_impl.h"

namespace mt {

using namespace store_format;

namespace {

constexpr uint64_t kSegmentRollBytes = 256ull << 20;
constexpr uint64_t kPendingCommitBytes = 32ull << 20;  // auto-commit large unsynced batches
// Compaction starts when the segment files exceed twice the live blocks by more than this (so a
// small store is not rewritten for a few KiB of dead blocks).
constexpr uint64_t kCompactSlackBytes = 1ull << 20;

uint64_t hash(const void* data, size_t size) { return XXH64(data, size, 0); }

std::string numbered(const std::string& dir, const char* prefix, uint64_t n, const char* suffix) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%s%06" PRIu64 "%s", prefix, n, suffix);
  return dir + "/" + buf;
}

void putHandle(ByteWriter& w, const BlockHandle& h) {
  w.put(h.segment);
  w.put(h.size);
  w.put(h.offset);
  w.put(h.checksum);
}
BlockHandle getHandle(ByteReader& r) {
  BlockHandle h;
  h.segment = r.get<uint32_t>();
  h.size = r.get<uint32_t>();
  h.offset = r.get<uint64_t>();
  h.checksum = r.get<uint64_t>();
  return h;
}
void putBox(ByteWriter& w, const Box3& b) {
  for (double v : b.lo) w.put(v);
  for (double v : b.hi) w.put(v);
}
Box3 getBox(ByteReader& r) {
  Box3 b;
  for (double& v : b.lo) v = r.get<double>();
  for (double& v : b.hi) v = r.get<double>();
  return b;
}
void putRecord(ByteWriter& w, const PatchRecord& p) {
  w.put(p.meta.id);
  w.put(p.meta.cell);
  w.put(p.meta.level);
  w.put(p.meta.vertices);
  w.put(p.meta.triangles);
  w.put(p.meta.boundaryEntries);
  putBox(w, p.meta.bounds);
  putHandle(w, p.geometry);
  putHandle(w, p.boundary);
}
PatchRecord getRecord(ByteReader& r) {
  PatchRecord p;
  p.meta.id = r.get<uint32_t>();
  p.meta.cell = r.get<uint64_t>();
  p.meta.level = r.get<uint32_t>();
  p.meta.vertices = r.get<uint32_t>();
  p.meta.triangles = r.get<uint32_t>();
  p.meta.boundaryEntries = r.get<uint32_t>();
  p.meta.bounds = getBox(r);
  p.geometry = getHandle(r);
  p.boundary = getHandle(r);
  return p;
}
uint32_t layoutFlags(const VertexLayout& l) {
  return (l.doublePrecision ? kGeomDouble : 0) | (l.normals ? kGeomNormals : 0) | (l.colors ? kGeomColors : 0);
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Patch payloads

Box3 boundsOf(const std::vector<double>& positions) {
  Box3 b;
  for (int a = 0; a < 3; ++a) {
    b.lo[a] = std::numeric_limits<double>::infinity();
    b.hi[a] = -std::numeric_limits<double>::infinity();
  }
  for (size_t i = 0; i < positions.size(); i += 3)
    for (int a = 0; a < 3; ++a) {
      b.lo[a] = std::min(b.lo[a], positions[i + a]);
      b.hi[a] = std::max(b.hi[a], positions[i + a]);
    }
  return b;
}

std::string encodeGeometry(const Patch& p, const VertexLayout& layout) {
  GeometryHeader h{p.vertexCount(), p.triangleCount(), layoutFlags(layout), 0};
  ByteWriter w;
  w.put(h);
  if (layout.doublePrecision) {
    w.putRaw(p.positions.data(), p.positions.size() * sizeof(double));
  } else {
    std::vector<float> f(p.positions.begin(), p.positions.end());
    w.putRaw(f.data(), f.size() * sizeof(float));
  }
  if (layout.normals) w.putRaw(p.normals.data(), p.normals.size() * sizeof(float));
  if (layout.colors) w.putRaw(p.colors.data(), p.colors.size());
  w.putRaw(p.triangles.data(), p.triangles.size() * sizeof(uint32_t));
  return std::move(w.bytes());
}

void decodeGeometry(const std::string& payload, const VertexLayout& layout, Patch& out,
                    const std::string& source) {
  ByteReader r(payload, source);
  auto h = r.get<GeometryHeader>();
  if (h.flags != layoutFlags(layout)) fail(source, "geometry block has the wrong vertex layout");
  size_t nv = h.vertexCount, nt = h.triangleCount;
  out.positions.resize(nv * 3);
  if (layout.doublePrecision) {
    std::memcpy(out.positions.data(), r.getRaw(nv * 3 * sizeof(double)), nv * 3 * sizeof(double));
  } else {
    const char* raw = r.getRaw(nv * 3 * sizeof(float));
    for (size_t i = 0; i < nv * 3; ++i) {
      float f;
      std::memcpy(&f, raw + i * sizeof(float), sizeof f);
      out.positions[i] = f;
    }
  }
  out.normals.clear();
  out.colors.clear();
  if (layout.normals) {
    out.normals.resize(nv * 3);
    std::memcpy(out.normals.data(), r.getRaw(nv * 3 * sizeof(float)), nv * 3 * sizeof(float));
  }
  if (layout.colors) {
    out.colors.resize(nv * 4);
    std::memcpy(out.colors.data(), r.getRaw(nv * 4), nv * 4);
  }
  out.triangles.resize(nt * 3);
  std::memcpy(out.triangles.data(), r.getRaw(nt * 3 * sizeof(uint32_t)), nt * 3 * sizeof(uint32_t));
  if (!r.atEnd()) fail(source, "geometry block has trailing bytes");
  for (size_t i = 0; i < out.triangles.size(); ++i)
    if (out.triangles[i] >= nv)
      fail(source, "triangle " + std::to_string(i / 3) + " references vertex " +
                       std::to_string(out.triangles[i]) + " of " + std::to_string(nv));
}

std::string encodeBoundary(const std::vector<BoundaryEntry>& entries) {
  ByteWriter w;
  w.put<uint32_t>(uint32_t(entries.size()));
  w.putRaw(entries.data(), entries.size() * sizeof(BoundaryEntry));
  return std::move(w.bytes());
}

std::vector<BoundaryEntry> decodeBoundary(const std::string& payload, const std::string& source) {
  ByteReader r(payload, source);
  uint32_t n = r.get<uint32_t>();
  std::vector<BoundaryEntry> entries(n);
  std::memcpy(entries.data(), r.getRaw(size_t(n) * sizeof(BoundaryEntry)), size_t(n) * sizeof(BoundaryEntry));
  if (!r.atEnd()) fail(source, "boundary block has trailing bytes");
  return entries;
}

// ---------------------------------------------------------------------------------------------
// Blocks and segments

std::string PatchStore::Impl::segmentPath(uint32_t n) const { return numbered(dir, "SEG-", n, ".dat"); }
std::string PatchStore::Impl::manifestPath(uint64_t n) const { return numbered(dir, "MANIFEST-", n, ""); }

void PatchStore::Impl::startSegment() {
  if (activeWriter) {
    activeWriter->sync();
    activeWriter->close();
  }
  activeSegment = nextSegment++;
  activeWriter = env->newWritableFile(segmentPath(activeSegment));
  liveBytes[activeSegment] += 0;
  segmentBytes[activeSegment] = 0;
}

BlockHandle PatchStore::Impl::appendBlock(const std::string& payload) {
  if (!activeWriter || activeWriter->size() >= kSegmentRollBytes) startSegment();
  BlockHeader h{kBlockMagic, uint32_t(payload.size()), hash(payload.data(), payload.size())};
  BlockHandle handle{activeSegment, h.size, activeWriter->size(), h.checksum};
  activeWriter->append(&h, sizeof h);
  activeWriter->append(payload.data(), payload.size());
  segmentBytes[activeSegment] = activeWriter->size();
  return handle;
}

std::string PatchStore::Impl::readBlock(const BlockHandle& h, const std::string& what) const {
  std::shared_ptr<RandomAccessFile> file;
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
  uint64_t sum = hash(bytes.data() + sizeof header, h.size);
  if (sum != header.checksum || sum != h.checksum) failCorrupt(where, at + ": checksum mismatch (corrupted block)");
  return bytes.substr(sizeof header);
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
// Manifest

std::string PatchStore::Impl::encodeSnapshot() const {
  ByteWriter w;
  w.put(kManifestMagic);
  w.put(kVersion);
  w.put(layoutFlags(layout));
  w.put(nextPatchId);
  w.put(nextSegment);
  putBox(w, bounds);
  w.put<uint64_t>(blobs.size());
  for (auto& [name, bytes] : blobs) {
    w.putString(name);
    w.putString(bytes);
  }
  w.put<uint64_t>(patches.size());
  for (auto& [id, rec] : patches) putRecord(w, rec);
  return std::move(w.bytes());
}

namespace {
void appendRecord(WritableFile& file, RecordType type, const std::string& payload) {
  RecordHeader h{type, uint32_t(payload.size()), hash(payload.data(), payload.size())};
  if (payload.size() > 0xFFFFFFF0ull) fail("manifest", "record too large");
  std::string bytes(reinterpret_cast<const char*>(&h), sizeof h);
  bytes += payload;
  file.append(bytes.data(), bytes.size());  // one append: a torn record fails its checksum
}
}  // namespace

void PatchStore::Impl::writeNewManifest() {
  uint64_t number = manifestNumber + 1;
  std::string path = manifestPath(number);
  std::string snapshot = encodeSnapshot();
  auto writer = env->newWritableFile(path);
  appendRecord(*writer, kSnapshot, snapshot);
  writer->sync();
  // Switch CURRENT atomically: write a temp file, fsync, rename, fsync the directory.
  std::string currentTmp = dir + "/CURRENT.tmp";
  {
    auto cur = env->newWritableFile(currentTmp);
    std::string line = path.substr(dir.size() + 1) + "\n";
    cur->append(line.data(), line.size());
    cur->sync();
    cur->close();
  }
  env->renameFile(currentTmp, dir + "/CURRENT");
  env->syncDir(dir);
  if (manifestNumber != 0) env->removeFile(manifestPath(manifestNumber));
  manifestNumber = number;
  manifestWriter = std::move(writer);
  snapshotBytes = snapshot.size();
}

void PatchStore::Impl::commitPending() {
  if (!failedCommit.empty()) fail(dir, "store refuses updates after a failed commit (" + failedCommit + "); reopen it");
  if (!pendingDirty) return;
  try {
    commitPendingUnchecked();
  } catch (const Error& e) {
    failedCommit = e.what();
    throw;
  }
}

void PatchStore::Impl::commitPendingUnchecked() {
  if (activeWriter) activeWriter->sync();  // blocks before the record that references them
  ByteWriter w;
  w.put(nextPatchId);
  w.put(nextSegment);
  w.put<uint64_t>(pendingRemoved.size());
  for (PatchId id : pendingRemoved) w.put(id);
  w.put<uint64_t>(pendingUpserted.size());
  for (auto& [id, rec] : pendingUpserted) putRecord(w, rec);
  w.put<uint64_t>(pendingBlobs.size());
  for (auto& [name, bytes] : pendingBlobs) {
    w.putString(name);
    w.putString(bytes);
  }
  appendRecord(*manifestWriter, kEdit, w.bytes());
  manifestWriter->sync();  // the commit point
  pendingRemoved.clear();
  pendingUpserted.clear();
  pendingBlobs.clear();
  pendingDirty = false;
  dropDeadSegments();
  compact();
  if (manifestWriter->size() > 2 * snapshotBytes + (1 << 20)) writeNewManifest();
}

// Segments are append-only, so blocks replaced by later updates stay on disk until every block of
// their segment is dead; a pass that rewrites every patch (smoothing) would grow the store by its
// size on every step. When the segment files exceed twice the live blocks, the live blocks of
// every segment that is less than half live are copied to the end of a new segment and the
// records repointed in one edit (same patch ids, same bytes); those segments are then dead and
// dropped as usual. Afterwards every remaining segment is at least half live, so the files are
// at most twice the live data. A checkpointed build (autoCommit off) is left alone: it commits
// whole levels, which kill whole segments, and loads patches on other threads while it writes.
void PatchStore::Impl::compact() {
  if (compacting || stagedBlocks > 0 || !autoCommit) return;
  uint64_t live = 0, total = 0;
  auto liveOf = [&](uint32_t seg) {
    auto it = liveBytes.find(seg);
    return it == liveBytes.end() ? uint64_t(0) : it->second;
  };
  for (auto& [seg, size] : segmentBytes) {
    total += size;
    live += liveOf(seg);
  }
  if (total <= 2 * live + kCompactSlackBytes) return;
  std::set<uint32_t> victims;
  for (auto& [seg, size] : segmentBytes)
    if (2 * liveOf(seg) < size) victims.insert(seg);
  if (victims.empty()) return;
  compacting = true;
  try {
    if (victims.count(activeSegment)) startSegment();
    for (auto& [id, rec] : patches) {
      bool g = victims.count(rec.geometry.segment) > 0, b = victims.count(rec.boundary.segment) > 0;
      if (!g && !b) continue;
      PatchRecord next = rec;
      std::string what = "patch " + std::to_string(id);
      if (g) next.geometry = appendBlock(readBlock(rec.geometry, what + " geometry"));
      if (b) next.boundary = appendBlock(readBlock(rec.boundary, what + " boundary list"));
      addLive(rec, -1);
      addLive(next, +1);
      rec = next;
      pendingUpserted[id] = next;
    }
    pendingDirty = true;
    commitPendingUnchecked();
  } catch (...) {
    compacting = false;
    throw;
  }
  compacting = false;
}

// One attempt at opening the committed version: false (with the path) when a file it names has
// vanished, which happens when a writer commits a newer version meanwhile.
bool PatchStore::Impl::recoverOnce(std::string& missing) {
  patches.clear();
  blobs.clear();
  liveBytes.clear();
  segmentBytes.clear();
  {
    std::lock_guard<std::mutex> lock(readersMutex);
    readers.clear();
  }
  auto tryOpen = [&](const std::string& path) -> std::shared_ptr<RandomAccessFile> {
    try {
      return std::shared_ptr<RandomAccessFile>(env->newRandomAccessFile(path));
    } catch (const Error&) {
      if (env->exists(path)) throw;
      missing = path;
      return nullptr;
    }
  };
  std::string currentPath = dir + "/CURRENT";
  if (!env->exists(currentPath)) fail(dir, "not a patch store (no CURRENT file)");
  auto cur = env->newRandomAccessFile(currentPath);
  std::string line(cur->size(), '\0');
  cur->read(0, line.size(), line.data());
  if (line.size() < 10 || line.compare(0, 9, "MANIFEST-") != 0 || line.back() != '\n')
    fail(currentPath, "corrupted (expected MANIFEST-<n>)");
  manifestNumber = std::stoull(line.substr(9));
  std::string mpath = manifestPath(manifestNumber);
  auto file = tryOpen(mpath);
  if (!file) return false;
  uint64_t size = file->size(), offset = 0;
  bool first = true;
  while (offset + sizeof(RecordHeader) <= size) {
    RecordHeader h;
    file->read(offset, sizeof h, &h);
    if ((h.type != kSnapshot && h.type != kEdit) || offset + sizeof h + h.size > size) break;  // torn tail
    std::string payload(h.size, '\0');
    file->read(offset + sizeof h, h.size, payload.data());
    if (hash(payload.data(), payload.size()) != h.checksum) break;  // torn tail
    ByteReader r(payload, mpath, offset + sizeof h);
    if (first) {
      if (h.type != kSnapshot) fail(mpath, "first record is not a snapshot");
      if (r.get<uint32_t>() != kManifestMagic) fail(mpath, "bad magic at byte offset " + std::to_string(offset));
      uint32_t version = r.get<uint32_t>();
      if (version != kVersion) fail(mpath, "unsupported store version " + std::to_string(version));
      uint32_t flags = r.get<uint32_t>();
      layout.doublePrecision = flags & kGeomDouble;
      layout.normals = flags & kGeomNormals;
      layout.colors = flags & kGeomColors;
      nextPatchId = r.get<uint32_t>();
      nextSegment = r.get<uint32_t>();
      bounds = getBox(r);
      uint64_t nb = r.get<uint64_t>();
      for (uint64_t i = 0; i < nb; ++i) {
        std::string name = r.getString();
        blobs[name] = r.getString();
      }
      uint64_t np = r.get<uint64_t>();
      for (uint64_t i = 0; i < np; ++i) {
        PatchRecord rec = getRecord(r);
        patches[rec.meta.id] = rec;
      }
      snapshotBytes = h.size;
      first = false;
    } else {
      if (h.type != kEdit) fail(mpath, "unexpected snapshot at byte offset " + std::to_string(offset));
      nextPatchId = r.get<uint32_t>();
      nextSegment = r.get<uint32_t>();
      uint64_t nr = r.get<uint64_t>();
      for (uint64_t i = 0; i < nr; ++i) patches.erase(r.get<uint32_t>());
      uint64_t nu = r.get<uint64_t>();
      for (uint64_t i = 0; i < nu; ++i) {
        PatchRecord rec = getRecord(r);
        patches[rec.meta.id] = rec;
      }
      uint64_t nb = r.get<uint64_t>();
      for (uint64_t i = 0; i < nb; ++i) {
        std::string name = r.getString();
        blobs[name] = r.getString();
      }
    }
    offset += sizeof h + h.size;
  }
  if (first) fail(mpath, "no valid snapshot record");
  for (auto& [id, rec] : patches) addLive(rec, +1);
  manifestFileBytes = size;
  manifestValidBytes = offset;
  // Every segment this version references is opened now, so that a writer deleting it later
  // (compaction, dead segments) only unlinks it: this store reads it until it is closed.
  for (auto& [seg, bytes] : liveBytes) {
    auto f = tryOpen(segmentPath(seg));
    if (!f) return false;
    segmentBytes[seg] = f->size();
    std::lock_guard<std::mutex> lock(readersMutex);
    readers[seg] = f;
  }
  return true;
}

// Opening reads only: no lock, nothing written or removed, so any number of readers may open a
// store while one writer updates it; each sees the last version committed when it opened.
void PatchStore::Impl::recover() {
  std::string currentPath = dir + "/CURRENT";
  auto readCurrent = [&]() {
    try {
      auto cur = env->newRandomAccessFile(currentPath);
      std::string line(cur->size(), '\0');
      cur->read(0, line.size(), line.data());
      return line;
    } catch (const Error&) {
      return std::string();
    }
  };
  for (int attempt = 0;; ++attempt) {
    std::string before = readCurrent();
    std::string missing;
    if (recoverOnce(missing)) return;
    // Unchanged CURRENT and manifest: nobody committed meanwhile, the file is really missing.
    bool moved = readCurrent() != before || !env->exists(manifestPath(manifestNumber)) ||
                 env->fileSize(manifestPath(manifestNumber)) != manifestFileBytes;
    if (!moved || attempt >= 50) fail(missing, "missing (the store's manifest references it)");
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

void PatchStore::Impl::lockForWriting() {
  if (writeLock) return;
  auto lock = std::make_unique<FileLock>(dir + "/LOCK", dir);
  // The version this store opened must still be the last one: another writer may have committed
  // between our open and our lock.
  std::string line;
  {
    auto cur = env->newRandomAccessFile(dir + "/CURRENT");
    line.assign(cur->size(), '\0');
    cur->read(0, line.size(), line.data());
  }
  std::string mpath = manifestPath(manifestNumber);
  if (line != mpath.substr(dir.size() + 1) + "\n" || !env->exists(mpath) || env->fileSize(mpath) != manifestFileBytes)
    fail(dir, "was changed by another process after it was opened here; open it again");
  if (manifestValidBytes != manifestFileBytes) {
    // A torn tail from an interrupted commit: start a fresh manifest from the recovered state.
    writeNewManifest();
  } else {
    manifestWriter = env->newAppendableFile(mpath);
  }
  // Files no committed state references: segments of uncommitted updates, stale manifests.
  for (const std::string& name : env->listDir(dir)) {
    unsigned n = 0;
    if (std::sscanf(name.c_str(), "SEG-%u.dat", &n) == 1 && !liveBytes.count(n)) env->removeFile(dir + "/" + name);
    unsigned long long m = 0;
    if (std::sscanf(name.c_str(), "MANIFEST-%llu", &m) == 1 && m != manifestNumber) env->removeFile(dir + "/" + name);
  }
  writeLock = std::move(lock);
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

void PatchStore::putBlob(const std::string& name, const std::string& bytes) {
  std::lock_guard<std::mutex> w(impl_->writeMutex);
  impl_->lockForWriting();
  std::unique_lock lock(impl_->stateMutex);
  impl_->blobs[name] = bytes;
  impl_->pendingBlobs[name] = bytes;
  impl_->pendingDirty = true;
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
  }
  for (PatchId id : ids) m.unifiedOf.push_back(std::move(unified[id]));
  std::sort(m.external.begin(), m.external.end());
  m.external.erase(std::unique(m.external.begin(), m.external.end()), m.external.end());
  return m;
}

std::vector<PatchId> PatchStore::writeBack(const LoadedMesh& loadedIn, const ReplacementMesh& r, bool syncNow) {
  std::lock_guard<std::mutex> writer(impl_->writeMutex);
  if (!impl_->failedCommit.empty()) fail(dir_, "store refuses updates after a failed commit; reopen it");
  impl_->lockForWriting();
  // The outside patches may have been replaced since the load (a neighbouring region written back
  // in between): re-read where they hold our vertices from the loaded patches' current lists.
  LoadedMesh refreshed;
  const LoadedMesh* current = &loadedIn;
  if (loadedIn.unifiedOf.size() == loadedIn.patches.size()) {
    refreshed.patches = loadedIn.patches;
    for (size_t k = 0; k < loadedIn.patches.size(); ++k) {
      PatchRecord rec;
      {
        std::shared_lock lock(impl_->stateMutex);
        auto it = impl_->patches.find(loadedIn.patches[k]);
        if (it == impl_->patches.end()) fail(dir_, "write back: loaded patch " + std::to_string(loadedIn.patches[k]) + " no longer exists");
        rec = it->second;
      }
      auto entries = decodeBoundary(impl_->readBlock(rec.boundary, "patch " + std::to_string(rec.meta.id) + " boundary list"), dir_);
      for (const BoundaryEntry& e : entries)
        if (!std::binary_search(loadedIn.patches.begin(), loadedIn.patches.end(), e.neighbour)) {
          uint32_t v = loadedIn.unifiedOf[k].at(e.local);
          if (!loadedIn.locked[v]) fail(dir_, "write back: vertex " + std::to_string(v) + " became shared after the load");
          refreshed.external.push_back({v, e.neighbour, e.remote});
        }
    }
    std::sort(refreshed.external.begin(), refreshed.external.end());
  refreshed.external.erase(std::unique(refreshed.external.begin(), refreshed.external.end()), refreshed.external.end());
    current = &refreshed;
  }
  const LoadedMesh& loaded = *current;
  auto vertexCountOf = [&]() { return loadedIn.vertexCount(); };
  const VertexLayout& layout = impl_->layout;
  const size_t nv = r.positions.size() / 3, nt = r.triangles.size() / 3;
  auto bad = [&](const std::string& what) { fail(dir_, "write back: " + what); };
  if (r.origin.size() != nv) bad("origin has " + std::to_string(r.origin.size()) + " entries for " + std::to_string(nv) + " vertices");
  if (r.triangleCell.size() != nt) bad("triangleCell has the wrong size");
  if (layout.normals && r.normals.size() != nv * 3) bad("normals missing");
  if (layout.colors && r.colors.size() != nv * 4) bad("colours missing");
  for (size_t i = 0; i < r.triangles.size(); ++i)
    if (r.triangles[i] >= nv) bad("triangle " + std::to_string(i / 3) + " references vertex out of range");

  // Where each loaded vertex went, and which replacement vertices are referenced.
  std::vector<uint32_t> newOf(vertexCountOf(), kNoVertex);
  for (uint32_t v = 0; v < nv; ++v) {
    uint32_t o = r.origin[v];
    if (o == kNoVertex) continue;
    if (o >= vertexCountOf()) bad("origin of vertex " + std::to_string(v) + " out of range");
    if (newOf[o] != kNoVertex) bad("loaded vertex " + std::to_string(o) + " appears twice");
    newOf[o] = v;
  }
  // The crack-free rule: every vertex an outside patch holds must survive, unmoved.
  for (const auto& ext : loaded.external) {
    uint32_t v = newOf[ext.vertex];
    if (v == kNoVertex) bad("locked vertex " + std::to_string(ext.vertex) + " was removed");
    for (int a = 0; a < 3; ++a)
      if (r.positions[3 * v + a] != loadedIn.positions[3 * ext.vertex + a]) bad("locked vertex " + std::to_string(ext.vertex) + " was moved");
  }

  // Group triangles by cell key -> new patches, in key order (a region splits into a handful of
  // cells: sort the distinct keys, then bucket the triangles in their original order).
  std::vector<uint64_t> cells(r.triangleCell.begin(), r.triangleCell.end());
  std::sort(cells.begin(), cells.end());
  cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
  struct NewPatch {
    uint64_t cell;
    std::vector<uint32_t> tris;      // replacement triangle ids
    std::vector<uint32_t> vertices;  // replacement vertex ids, ascending = local order
    Patch patch;
  };
  std::vector<NewPatch> out(cells.size());
  {
    std::vector<uint32_t> patchOfTriangle(nt);
    for (size_t k = 0; k < cells.size(); ++k) out[k].cell = cells[k];
    for (uint32_t t = 0; t < nt; ++t) {
      const uint32_t k = t > 0 && r.triangleCell[t] == r.triangleCell[t - 1]
                             ? patchOfTriangle[t - 1]
                             : uint32_t(std::lower_bound(cells.begin(), cells.end(), r.triangleCell[t]) - cells.begin());
      patchOfTriangle[t] = k;
      out[k].tris.push_back(t);
    }
  }
  // Vertex -> new patches holding it, as CSR over replacement vertices (most vertices are in one
  // patch). Holders of a vertex are in ascending patch order, and each patch's vertices come out
  // ascending with their local index: linear time, no per-corner searches.
  std::vector<uint32_t> holderStart(nv + 1, 0), mark(nv, ~0u);
  for (uint32_t k = 0; k < out.size(); ++k)
    for (uint32_t t : out[k].tris)
      for (int c = 0; c < 3; ++c) {
        uint32_t v = r.triangles[3 * t + c];
        if (mark[v] != k) mark[v] = k, ++holderStart[v + 1];
      }
  for (size_t v = 0; v < nv; ++v) holderStart[v + 1] += holderStart[v];
  std::vector<uint32_t> holderPatch(holderStart[nv]), holderLocal(holderStart[nv]);
  {
    std::vector<uint32_t> fill(holderStart.begin(), holderStart.end() - 1);
    std::fill(mark.begin(), mark.end(), ~0u);
    for (uint32_t k = 0; k < out.size(); ++k)
      for (uint32_t t : out[k].tris)
        for (int c = 0; c < 3; ++c) {
          uint32_t v = r.triangles[3 * t + c];
          if (mark[v] != k) mark[v] = k, holderPatch[fill[v]++] = k;
        }
  }
  for (uint32_t v = 0; v < nv; ++v)
    for (uint32_t h = holderStart[v]; h < holderStart[v + 1]; ++h) {
      auto& vs = out[holderPatch[h]].vertices;
      holderLocal[h] = uint32_t(vs.size());
      vs.push_back(v);
    }
  for (const auto& ext : loaded.external)
    if (holderStart[newOf[ext.vertex]] == holderStart[newOf[ext.vertex] + 1])
      bad("locked vertex " + std::to_string(ext.vertex) + " is used by no triangle");

  std::vector<PatchId> newIds(out.size());
  {
    std::unique_lock lock(impl_->stateMutex);
    for (auto& id : newIds) id = impl_->nextPatchId++;
  }
  auto localIndex = [&](uint32_t k, uint32_t v) {
    for (uint32_t h = holderStart[v];; ++h)
      if (holderPatch[h] == k) return holderLocal[h];
  };
  // Boundary entries: between new patches, and from new patches to the outside ones.
  std::map<PatchId, std::vector<std::pair<uint32_t, BoundaryEntry>>> outsideAdds;  // q -> (remote->entry)
  for (uint32_t v = 0; v < nv; ++v) {
    const uint32_t i = holderStart[v], j = holderStart[v + 1];
    if (j - i < 2) continue;
    for (uint32_t a = i; a < j; ++a)
      for (uint32_t b = i; b < j; ++b)
        if (a != b) out[holderPatch[a]].patch.boundary.push_back({holderLocal[a], newIds[holderPatch[b]], holderLocal[b]});
  }
  for (const auto& ext : loaded.external) {
    uint32_t v = newOf[ext.vertex];
    for (uint32_t h = holderStart[v]; h < holderStart[v + 1]; ++h) {
      out[holderPatch[h]].patch.boundary.push_back({holderLocal[h], ext.patch, ext.remote});
      outsideAdds[ext.patch].push_back({ext.remote, {ext.remote, newIds[holderPatch[h]], holderLocal[h]}});
    }
  }

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
      for (int c = 0; c < 3; ++c) p.triangles.push_back(localIndex(k, r.triangles[3 * t + c]));
    std::sort(p.boundary.begin(), p.boundary.end());
    PatchRecord rec;
    rec.meta = {p.id, p.cell, p.level, p.vertexCount(), p.triangleCount(), uint32_t(p.boundary.size()), boundsOf(p.positions)};
    rec.geometry = impl_->appendBlock(encodeGeometry(p, layout));
    rec.boundary = impl_->appendBlock(encodeBoundary(p.boundary));
    records.push_back(rec);
  }
  // Outside patches: drop their entries into the loaded set, add entries to the new patches.
  std::vector<PatchRecord> updated;
  for (auto& [q, adds] : outsideAdds) {
    PatchRecord rec;
    {
      std::shared_lock lock(impl_->stateMutex);
      auto it = impl_->patches.find(q);
      if (it == impl_->patches.end()) bad("outside patch " + std::to_string(q) + " does not exist");
      rec = it->second;
    }
    auto entries = decodeBoundary(impl_->readBlock(rec.boundary, "patch " + std::to_string(q) + " boundary list"), dir_);
    entries.erase(std::remove_if(entries.begin(), entries.end(),
                                 [&](const BoundaryEntry& e) { return std::binary_search(loaded.patches.begin(), loaded.patches.end(), e.neighbour); }),
                  entries.end());
    for (auto& a : adds) entries.push_back(a.second);
    std::sort(entries.begin(), entries.end());
    entries.erase(std::unique(entries.begin(), entries.end()),
                  entries.end());
    PatchRecord next = rec;
    next.boundary = impl_->appendBlock(encodeBoundary(entries));
    next.meta.boundaryEntries = uint32_t(entries.size());
    updated.push_back(next);
  }

  {
    std::unique_lock lock(impl_->stateMutex);
    for (PatchId id : loaded.patches) {
      auto it = impl_->patches.find(id);
      if (it == impl_->patches.end()) bad("loaded patch " + std::to_string(id) + " no longer exists");
      impl_->addLive(it->second, -1);
      impl_->patches.erase(it);
      impl_->pendingRemoved.push_back(id);
      impl_->pendingUpserted.erase(id);
    }
    for (auto& rec : updated) {
      impl_->addLive(impl_->patches[rec.meta.id], -1);
      impl_->patches[rec.meta.id] = rec;
      impl_->addLive(rec, +1);
      impl_->pendingUpserted[rec.meta.id] = rec;
    }
    for (auto& rec : records) {
      impl_->patches[rec.meta.id] = rec;
      impl_->addLive(rec, +1);
      impl_->pendingUpserted[rec.meta.id] = rec;
    }
    impl_->pendingDirty = true;
  }
  if (syncNow || (impl_->autoCommit && impl_->pendingUpserted.size() * 128 > kPendingCommitBytes)) {
    std::unique_lock lock(impl_->stateMutex);
    impl_->commitPending();
  }
  return newIds;
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

// ---------------------------------------------------------------------------------------------
// Export: every vertex is written once, by the lowest-numbered patch holding it (its owner), so
// the exported mesh is welded exactly as the input was; memory is O(patches), not O(vertices).

void PatchStore::exportPly(const std::string& path, bool progress) const {
  std::vector<PatchId> ids = patchIds();
  const VertexLayout& layout = impl_->layout;
  PlyWriteOptions options{layout.doublePrecision, layout.normals, layout.colors};
  PlyWriter writer(path, options);
  auto isOwned = [](const Patch& p, std::vector<uint8_t>& owned) {
    owned.assign(p.vertexCount(), 1);
    for (const BoundaryEntry& e : p.boundary)
      if (e.neighbour < p.id) owned[e.local] = 0;
  };
  // Pass 1: owned vertices, and each patch's first global index.
  std::unordered_map<PatchId, uint64_t> base;
  std::vector<uint8_t> owned;
  uint64_t next = 0;
  size_t done = 0;
  for (PatchId id : ids) {
    Patch p = patch(id);
    isOwned(p, owned);
    base[id] = next;
    for (uint32_t v = 0; v < p.vertexCount(); ++v)
      if (owned[v]) {
        writer.addVertex(&p.positions[3 * v], layout.normals ? &p.normals[3 * v] : nullptr,
                         layout.colors ? &p.colors[4 * v] : nullptr);
        ++next;
      }
    if (progress && ++done % 4096 == 0) std::fprintf(stderr, "\rexport: vertices %zu/%zu patches", done, ids.size());
  }
  if (next > kMaxVertices) fail(path, "too many vertices for 32-bit indices");
  // Pass 2: triangles. A non-owned vertex's global index is its owner's base plus its rank among
  // the owner's owned vertices, found from the owner's boundary list alone.
  std::unordered_map<PatchId, std::vector<uint32_t>> notOwnedCache;  // sorted non-owned locals
  auto notOwnedOf = [&](PatchId q) -> const std::vector<uint32_t>& {
    auto it = notOwnedCache.find(q);
    if (it != notOwnedCache.end()) return it->second;
    if (notOwnedCache.size() > 4096) notOwnedCache.clear();
    PatchRecord rec;
    {
      std::shared_lock lock(impl_->stateMutex);
      rec = impl_->patches.at(q);
    }
    auto entries = decodeBoundary(impl_->readBlock(rec.boundary, "patch " + std::to_string(q) + " boundary list"), dir_);
    std::vector<uint32_t> no;
    for (auto& e : entries)
      if (e.neighbour < q) no.push_back(e.local);
    std::sort(no.begin(), no.end());
    no.erase(std::unique(no.begin(), no.end()), no.end());
    return notOwnedCache[q] = std::move(no);
  };
  done = 0;
  std::vector<uint64_t> global;
  for (PatchId id : ids) {
    Patch p = patch(id);
    const std::vector<uint32_t>& mine = notOwnedOf(id);
    global.assign(p.vertexCount(), 0);
    for (uint32_t v = 0; v < p.vertexCount(); ++v)
      global[v] = base[id] + v - uint64_t(std::lower_bound(mine.begin(), mine.end(), v) - mine.begin());
    // Entries to lower patches: the lowest neighbour is the owner.
    std::vector<std::pair<uint32_t, std::pair<PatchId, uint32_t>>> owner;  // local -> (q, remote)
    for (const BoundaryEntry& e : p.boundary)
      if (e.neighbour < id) owner.push_back({e.local, {e.neighbour, e.remote}});
    std::sort(owner.begin(), owner.end());
    for (size_t i = 0; i < owner.size(); ++i) {
      if (i > 0 && owner[i].first == owner[i - 1].first) continue;  // first = lowest neighbour
      PatchId q = owner[i].second.first;
      uint32_t remote = owner[i].second.second;
      const std::vector<uint32_t>& theirs = notOwnedOf(q);
      global[owner[i].first] = base[q] + remote - uint64_t(std::lower_bound(theirs.begin(), theirs.end(), remote) - theirs.begin());
    }
    for (size_t t = 0; t < p.triangles.size(); t += 3)
      writer.addTriangle(uint32_t(global[p.triangles[t]]), uint32_t(global[p.triangles[t + 1]]), uint32_t(global[p.triangles[t + 2]]));
    if (progress && ++done % 4096 == 0) std::fprintf(stderr, "\rexport: triangles %zu/%zu patches", done, ids.size());
  }
  writer.finish();
  if (progress) std::fprintf(stderr, "\rexport: %" PRIu64 " vertices, %" PRIu64 " triangles -> %s\n",
                             writer.vertexCount(), writer.triangleCount(), path.c_str());
}

// ---------------------------------------------------------------------------------------------
// Check: checksums (every block is read and verified), indices in range, and every boundary entry
// mirrored by its neighbour with the same position.

CheckReport PatchStore::check() const {
  CheckReport report;
  std::vector<PatchId> ids = patchIds();
  std::unordered_map<PatchId, Patch> cache;
  auto get = [&](PatchId q) -> const Patch* {
    auto it = cache.find(q);
    if (it != cache.end()) return &it->second;
    if (cache.size() > 2048) cache.clear();
    try {
      return &(cache[q] = patch(q));
    } catch (const Error& e) {
      report.problems.push_back(e.what());
      return nullptr;
    }
  };
  for (PatchId id : ids) {
    ++report.patchesChecked;
    const Patch* p = get(id);
    if (!p) continue;
    PatchMeta m = meta(id);
    std::string name = dir_ + ": patch " + std::to_string(id);
    if (m.triangles != p->triangleCount() || m.vertices != p->vertexCount() || m.boundaryEntries != p->boundary.size())
      report.problems.push_back(name + ": counts in the manifest do not match the blocks");
    Patch self = *p;  // get() may evict
    for (const BoundaryEntry& e : self.boundary) {
      ++report.entriesChecked;
      std::string entry = name + ": boundary entry (" + std::to_string(e.local) + ", " + std::to_string(e.neighbour) +
                          ", " + std::to_string(e.remote) + ")";
      if (e.neighbour == id) {
        report.problems.push_back(entry + " points at its own patch");
        continue;
      }
      if (!std::binary_search(ids.begin(), ids.end(), e.neighbour)) {
        report.problems.push_back(entry + " names a patch that does not exist");
        continue;
      }
      const Patch* q = get(e.neighbour);
      if (!q) continue;
      if (e.remote >= q->vertexCount()) {
        report.problems.push_back(entry + " points past the neighbour's vertices");
        continue;
      }
      bool mirrored = std::binary_search(q->boundary.begin(), q->boundary.end(), BoundaryEntry{e.remote, id, e.local});
      if (!mirrored) report.problems.push_back(entry + " is not mirrored by patch " + std::to_string(e.neighbour));
      for (int a = 0; a < 3; ++a)
        if (self.positions[3 * e.local + a] != q->positions[3 * e.remote + a]) {
          report.problems.push_back(entry + ": the two copies of the vertex differ in position");
          break;
        }
    }
  }
  report.ok = report.problems.empty();
  return report;
}

}  // namespace mt
