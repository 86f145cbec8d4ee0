// The patch store's manifest log (store_format.h): the snapshot, the commit of pending edits,
// compaction of mostly-dead segments, recovery at open, and the writer's lock. LevelDB's
// VersionSet in small: CURRENT names the manifest, a snapshot record starts it, edit records
// follow, and the last valid record is the committed version.
#include <chrono>
#include <cinttypes>
#include <cstdio>
#include <set>
#include <thread>

#include "base/fuzzing.h"
#include "base/byte_io.h"
#include "patchstore/store_impl.h"

namespace mt {

using namespace store_format;

namespace {

// Compaction starts when the segment files exceed twice the live blocks by more than this (so a
// small store is not rewritten for a few KiB of dead blocks).
constexpr uint64_t kCompactSlackBytes = 1ull << 20;

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

void appendRecord(WritableFile& file, RecordType type, const std::string& payload) {
  RecordHeader h{type, uint32_t(payload.size()), blockChecksum(payload.data(), payload.size())};
  if (payload.size() > 0xFFFFFFF0ull) fail("manifest", "record too large");
  std::string bytes(reinterpret_cast<const char*>(&h), sizeof h);
  bytes += payload;
  file.append(bytes.data(), bytes.size());  // one append: a torn record fails its checksum
}

// Blobs as encodeSnapshot and commitPendingUnchecked write them: a count, then (name, bytes).
void readBlobs(ByteReader& r, std::map<std::string, std::string>& blobs) {
  uint64_t nb = r.get<uint64_t>();
  for (uint64_t i = 0; i < nb; ++i) {
    std::string name = r.getString();
    blobs[name] = r.getString();
  }
}

// The snapshot record that starts a manifest (encodeSnapshot's layout).
void readSnapshot(PatchStore::Impl& s, ByteReader& r, const std::string& mpath, uint64_t offset) {
  if (r.get<uint32_t>() != kManifestMagic) fail(mpath, "bad magic at byte offset " + std::to_string(offset));
  uint32_t version = r.get<uint32_t>();
  if (version < kOldestVersion || version > kVersion)
    fail(mpath, "unsupported store version " + std::to_string(version) + " (this build reads versions " +
                    std::to_string(kOldestVersion) + " to " + std::to_string(kVersion) + ")");
  uint32_t flags = r.get<uint32_t>();
  s.layout.doublePrecision = flags & kGeomDouble;
  s.layout.normals = flags & kGeomNormals;
  s.layout.colors = flags & kGeomColors;
  s.layout.texcoords = flags & kGeomTexcoords;
  s.nextPatchId = r.get<uint32_t>();
  s.nextSegment = r.get<uint32_t>();
  s.bounds = getBox(r);
  readBlobs(r, s.blobs);
  uint64_t np = r.get<uint64_t>();
  for (uint64_t i = 0; i < np; ++i) {
    PatchRecord rec = getRecord(r);
    s.patches[rec.meta.id] = rec;
  }
}

// An edit record (commitPendingUnchecked's layout) applied to the replayed state.
void applyEdit(PatchStore::Impl& s, ByteReader& r) {
  s.nextPatchId = r.get<uint32_t>();
  s.nextSegment = r.get<uint32_t>();
  uint64_t nr = r.get<uint64_t>();
  for (uint64_t i = 0; i < nr; ++i) s.patches.erase(r.get<uint32_t>());
  uint64_t nu = r.get<uint64_t>();
  for (uint64_t i = 0; i < nu; ++i) {
    PatchRecord rec = getRecord(r);
    s.patches[rec.meta.id] = rec;
  }
  readBlobs(r, s.blobs);
}

}  // namespace

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
  {
    std::lock_guard<std::mutex> lock(appendMutex);
    if (!appendError.empty()) fail(dir, "store refuses to commit after a failed write (" + appendError + "); reopen it");
    flushAppendsLocked(true);  // blocks before the record that references them
  }
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
    if (kChecksumsChecked && blockChecksum(payload.data(), payload.size()) != h.checksum) break;  // torn tail
    ByteReader r(payload, mpath, offset + sizeof h);
    if (first) {
      if (h.type != kSnapshot) fail(mpath, "first record is not a snapshot");
      readSnapshot(*this, r, mpath, offset);
      snapshotBytes = h.size;
      first = false;
    } else {
      if (h.type != kEdit) fail(mpath, "unexpected snapshot at byte offset " + std::to_string(offset));
      applyEdit(*this, r);
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

}  // namespace mt
