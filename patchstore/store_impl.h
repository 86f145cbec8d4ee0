// Internal to patchstore: the state behind PatchStore, shared by the store's files and ingest
// (ingest.cpp), which writes a new store's blocks and first snapshot directly. The store is one
// class in several files, one job each:
//   patch_store.cpp     opening, blocks and segments, the read API (patch, load, assemble)
//   store_manifest.cpp  the manifest log: snapshot, commit, compaction, recovery, the write lock
//   store_write.cpp     writeBack (a simplified region back as new patches), putBlob
//   heal_support.cpp    in-place rewrites and staged position updates (healing)
//   store_export.cpp    exportPly and check, each a pass over every patch
//   patch_codec.cpp     the geometry and boundary payloads (encode/decode)
#pragma once

#include <xxhash.h>

#include <map>
#include <memory>
#include <mutex>
#include <shared_mutex>
#include <string>
#include <vector>

#include "base/buffered_file.h"
#include "base/file_lock.h"
#include "patchstore/patch_store.h"
#include "patchstore/store_format.h"

namespace mt {

// A write-back or rewrite commits by itself once its pending records reach this size.
constexpr uint64_t kPendingCommitBytes = 32ull << 20;

// The checksum of blocks and manifest records (store_format.h).
inline uint64_t blockChecksum(const void* data, size_t size) { return XXH64(data, size, 0); }

inline uint32_t layoutFlags(const VertexLayout& l) {
  return (l.doublePrecision ? store_format::kGeomDouble : 0) | (l.normals ? store_format::kGeomNormals : 0) |
         (l.colors ? store_format::kGeomColors : 0) | (l.texcoords ? store_format::kGeomTexcoords : 0);
}

struct PatchRecord {
  PatchMeta meta;
  store_format::BlockHandle geometry;
  store_format::BlockHandle boundary;
};

struct PatchStore::Impl {
  // Held from the first update until the store is closed (declared first: released last, after
  // the manifest and segment writers are closed).
  std::unique_ptr<FileLock> writeLock;
  Env* env = nullptr;
  std::string dir;
  VertexLayout layout;
  Box3 bounds;
  uint32_t nextPatchId = 1;
  uint32_t nextSegment = 1;
  std::map<PatchId, PatchRecord> patches;
  std::map<std::string, std::string> blobs;

  // Segments: the one being appended to, and lazily opened readers for all.
  // The active segment's appends are buffered into large sequential writes (BufferedWritableFile);
  // appendMutex guards the buffer, so that a reader of a block still in it has it flushed first.
  // A failed flush leaves records pointing at bytes that never reached the file: appendError then
  // refuses every later update and commit, as a failed commit does.
  uint32_t activeSegment = 0;
  std::unique_ptr<BufferedWritableFile> activeWriter;
  mutable std::mutex appendMutex;
  mutable std::string appendError;
  std::map<uint32_t, uint64_t> liveBytes;  // per segment, of blocks referenced by live patches
  std::map<uint32_t, uint64_t> segmentBytes;  // per segment, its file size (live and dead blocks)
  mutable std::mutex readersMutex;
  mutable std::map<uint32_t, std::shared_ptr<RandomAccessFile>> readers;

  // Segments deleted by the last commit, still open here: a load() that copied a patch record
  // before that commit reads the (identical) old copy of a relocated block. Closed by the next
  // commit.
  std::vector<std::shared_ptr<RandomAccessFile>> retiredReaders;
  // Staged geometry blocks not yet committed (they are referenced by no record, so compaction
  // waits until they are committed).
  size_t stagedBlocks = 0;
  bool compacting = false;

  // Manifest log.
  uint64_t manifestNumber = 0;
  uint64_t manifestFileBytes = 0;  // size of the manifest file when it was replayed at open
  uint64_t manifestValidBytes = 0; // the records replayed (less than the file after a torn append)
  std::unique_ptr<WritableFile> manifestWriter;
  uint64_t snapshotBytes = 0;

  // Changes not yet committed to the manifest (write-backs without syncNow).
  std::vector<PatchId> pendingRemoved;
  std::map<PatchId, PatchRecord> pendingUpserted;
  std::map<std::string, std::string> pendingBlobs;
  bool pendingDirty = false;
  // Set when a commit failed half-way: the in-memory state is ahead of the disk, so every later
  // update is refused until the store is reopened (after LevelDB's background error).
  std::string failedCommit;
  bool autoCommit = true;

  mutable std::shared_mutex stateMutex;  // guards the maps above against concurrent readers
  std::mutex writeMutex;                 // serializes writeBack/sync/putBlob

  // ---- file names ----
  std::string segmentPath(uint32_t n) const;
  std::string manifestPath(uint64_t n) const;

  // ---- blocks ----
  store_format::BlockHandle appendBlock(const std::string& payload);
  std::string readBlock(const store_format::BlockHandle& h, const std::string& what) const;
  void startSegment();
  void startSegmentLocked();  // under appendMutex
  // Under appendMutex: writes (and with `sync`, fsyncs) the active segment's buffered blocks.
  void flushAppendsLocked(bool sync) const;

  // ---- manifest ----
  std::string encodeSnapshot() const;
  void writeNewManifest();  // snapshot into MANIFEST-(n+1), then switch CURRENT
  void commitPending();     // segment fsync, edit append, manifest fsync (the commit point)
  void commitPendingUnchecked();
  void recover();           // open: CURRENT -> manifest replay -> every referenced segment opened
  bool recoverOnce(std::string& missing);
  void lockForWriting();    // the store's LOCK, then the writer's part of recovery
  void dropDeadSegments();
  void compact();           // relocates live blocks out of mostly-dead segments

  void addLive(const PatchRecord& r, int sign);

  // ---- updates (callers hold writeMutex) ----
  // Refuses after a failed commit, then takes the write lock (`where` names the store in errors).
  void startUpdate(const std::string& where);
  // The in-memory side of an update, to be committed by the next commitPending (callers hold
  // stateMutex exclusively): a live record dropped, replaced, or a new one added.
  void removeRecord(std::map<PatchId, PatchRecord>::iterator it);
  void replaceRecord(const PatchRecord& rec);
  void insertRecord(const PatchRecord& rec);
  bool pendingIsLarge() const { return pendingUpserted.size() * 128 > kPendingCommitBytes; }
};

// Patch payload coding, shared by ingest and write-back.
std::string encodeGeometry(const Patch& p, const VertexLayout& layout);
// A geometry block's packed triangles (kGeomPackedTriangles), appended: the byte count, the code.
void appendPackedTriangles(std::string& block, const uint32_t* indices, size_t indexCount, uint32_t vertexCount);
// ... and its packed positions (kGeomPackedPositions): vertexCount records of vertexSize bytes.
void appendPackedPositions(std::string& block, const void* positions, size_t vertexCount, size_t vertexSize);
void decodeGeometry(const std::string& payload, const VertexLayout& layout, Patch& out,
                    const std::string& source);
std::string encodeBoundary(const std::vector<BoundaryEntry>& entries);
std::vector<BoundaryEntry> decodeBoundary(const std::string& payload, const std::string& source);
Box3 boundsOf(const std::vector<double>& positions);

}  // namespace mt
