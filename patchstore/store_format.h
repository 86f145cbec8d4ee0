// The patch store's on-disk format: the one place it is written down (after LevelDB's table and
// manifest formats). All integers are little-endian; checksums are XXH64 (seed 0).
//
// A store is a directory:
//   CURRENT            one line "MANIFEST-<n>\n": the live manifest. Replaced by writing
//                      CURRENT.tmp, fsync, rename (atomic), fsync of the directory.
//   MANIFEST-<n>       a log of records. Record = RecordHeader + payload. The first record is a
//                      Snapshot (the whole state); each later one is an Edit. Recovery replays
//                      records in order and stops at the first record that is short or fails its
//                      checksum (a torn append): everything before it is the store.
//   SEG-<n>.dat        segment files of blocks, appended to, never modified in place:
//                      BlockHeader + payload. A block is referenced from the manifest by a
//                      BlockHandle (segment, offset, size, checksum), so it is verified twice.
//   tmp/               scratch space for ingest and healing (deleted on success).
//   LOCK               while a writer has the store open: its PID, flock()ed (base/file_lock.h).
//                      Removed when it closes; one left by a killed writer is not held, so it is
//                      simply taken by the next one.
//
// Crash safety (the order every update follows): new blocks are appended to a segment and the
// segment is fsynced; then one Edit record listing every change of the update is appended to the
// manifest and fsynced: that fsync is the commit point. A crash before it leaves the old store
// (the orphan blocks are unreferenced); after it, the new one. Segments whose blocks are all dead
// are deleted only after the edit that killed them is durable. When the manifest log grows past
// twice its snapshot size, a new manifest is written (Snapshot only) and CURRENT is switched to it.
//
// Readers take no lock and change nothing: they replay the manifest as it is (a torn tail is
// ignored, not repaired) and open every segment the replayed version references at once, retrying
// when one vanished meanwhile (a newer version was committed). A writer holds LOCK from its first
// update, checks the store is still the version it opened, and only then repairs a torn tail and
// removes unreferenced files. Compaction (patch_store.cpp) copies the live blocks of segments that
// are less than half live to a new segment, commits, then unlinks them: a reader that opened an
// older version still holds them open, so their data goes only when it closes.
//
// Ingest builds a whole store in DIR.ingest-<pid> (holding DIR.ingest-<pid>/INGEST-LOCK) and
// renames it to DIR when complete; such a folder whose lock no process holds and whose PID is
// gone is a killed ingest's, and the next ingest beside it removes it.
#pragma once

#include <cstdint>

namespace mt::store_format {

// Version 2: geometry blocks may hold the packed forms (kGeomPackedTriangles, kGeomPackedPositions
// below), which a version-1 reader does not know; a version-1 store reads as it is.
constexpr uint32_t kVersion = 2, kOldestVersion = 1;

// ---- segments ----
constexpr uint32_t kBlockMagic = 0x4B42544D;  // "MTBK"
struct BlockHeader {
  uint32_t magic;     // kBlockMagic
  uint32_t size;      // payload bytes
  uint64_t checksum;  // XXH64 of the payload
};
static_assert(sizeof(BlockHeader) == 16);

struct BlockHandle {
  uint32_t segment = 0;  // SEG-<segment>.dat
  uint32_t size = 0;     // payload bytes
  uint64_t offset = 0;   // of the BlockHeader
  uint64_t checksum = 0; // XXH64 of the payload
};

// Geometry block payload (one per patch):
//   GeometryHeader
//   positions   vertexCount * 3 * (float32 | float64 if kGeomDouble), or with kGeomPackedPositions:
//               uint32 n, then n bytes of meshopt_encodeVertexBuffer (version 0) over those
//               vertices (12 or 24 bytes each; lossless)
//   normals     vertexCount * 3 * float32            (if kGeomNormals)
//   colors      vertexCount * 4 * uint8              (if kGeomColors)
//   texcoords   vertexCount * {float32 u, v, uint32 material}   (if kGeomTexcoords and kGeomVertexUV)
//   triangles   triangleCount * 3 * uint32 local vertex indices, or with kGeomPackedTriangles:
//               uint32 n, then n bytes of meshopt_encodeIndexSequence over the 3 * triangleCount
//               indices (exact: the same triangles, corners in the same order)
//   corners     (if kGeomTexcoords without kGeomVertexUV) triangleCount * uint32 material, then
//               triangleCount * 6 * float32 (u, v of each corner), then uint32 n and n bytes:
//               the patch's atlas image (JPEG or PNG; n = 0: none)
// A textured store (kGeomTexcoords in the layout) holds its texture coordinates per corner, so a
// seam survives the grid weld joining its two vertices; ingest writes them per vertex
// (kGeomVertexUV: its vertex records carry them, one vertex per wedge, readers' wedge split), and
// decoding turns that form into per-corner. Materials index the store's "materials" blob
// (store_textures.h); kAtlasMaterial is the patch's own atlas, kNoMaterial untextured.
// The layout flags stored in the manifest never include kGeomVertexUV or the packed forms.
// kGeomPackedTriangles: the triangles as an index sequence code, ~3 bytes a triangle where the
// plain indices take 12; kGeomPackedPositions: the positions through meshopt's vertex codec (byte
// deltas between consecutive vertices, which ingest's ascending input order keeps close), 12 ->
// 6.6-8.2 bytes a vertex on mtgen and scangen scans. Ingest and the level loop write and read the
// whole mesh through the store: at a billion triangles the plain blocks were ~18 GB written and
// read back by each of the ingest and the level loop. Readers take every form; writers pack.
constexpr uint32_t kGeomDouble = 1, kGeomNormals = 2, kGeomColors = 4, kGeomTexcoords = 8, kGeomVertexUV = 16,
                   kGeomPackedTriangles = 32, kGeomPackedPositions = 64;
struct GeometryHeader {
  uint32_t vertexCount;
  uint32_t triangleCount;
  uint32_t flags;
  uint32_t reserved;
};
// Boundary block payload (one per patch): uint32 count, then count * {uint32 local,
// uint32 neighbour patch id, uint32 remote index}, sorted by (local, neighbour).

// ---- manifest ----
constexpr uint32_t kManifestMagic = 0x464E4D4D;  // "MMNF", first 4 bytes of a Snapshot payload
enum RecordType : uint32_t { kSnapshot = 1, kEdit = 2 };
struct RecordHeader {
  uint32_t type;      // RecordType
  uint32_t size;      // payload bytes
  uint64_t checksum;  // XXH64 of the payload
};
static_assert(sizeof(RecordHeader) == 16);

// Snapshot payload: magic, version, VertexLayout flags (uint32), nextPatchId (uint32),
//   nextSegment (uint32), bounds (6 float64), blob count + {name, bytes} (length-prefixed),
//   patch count + PatchRecord each.
// Edit payload: nextPatchId, nextSegment, removed count + patch ids, added/updated count +
//   PatchRecord each, blob count + {name, bytes}.
// PatchRecord: id u32, cell u64, level u32, vertices u32, triangles u32, boundaryEntries u32,
//   bounds 6 x float64, geometry BlockHandle, boundary BlockHandle
//   (BlockHandle = segment u32, size u32, offset u64, checksum u64).

}  // namespace mt::store_format
