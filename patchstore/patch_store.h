// The out-of-core patch store (BMT section 6): the whole mesh kept on disk as a collection of
// small independent patches. Each patch holds its own copy of the vertices it uses (positions,
// and normals/colours when the input has them), its triangles in local indices, and a boundary
// list with one entry (vp, q, vq) per vertex vp it shares: patch q holds the same vertex at its
// local index vq. Boundary lists are symmetric: (vp, q, vq) in p <=> (vq, p, vp) in q.
//
// load(P) assembles patches P into one in-core mesh with unified vertex indices, flagging every
// vertex that a patch outside P also uses as locked; writeBack() replaces the loaded patches by a
// new partition of the (modified) mesh and rewrites the boundary lists of the outside patches that
// point into it. The on-disk format and its crash-safety rules are in store_format.h.
//
// Thread safety: load(), patch(), info() may run concurrently with each other and with writeBack()
// of disjoint patch sets; writeBack()/sync() serialize internally.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <tuple>
#include <vector>

#include "base/env.h"
#include "patchstore/cell_assigner.h"
#include "patchstore/io/mesh_reader.h"

namespace mt {

using PatchId = uint32_t;
constexpr uint32_t kNoVertex = 0xFFFFFFFFu;

// What a store's vertices carry. Fixed at ingest for the whole store.
struct VertexLayout {
  bool doublePrecision = false;  // positions stored as double (input needed it), else float
  bool normals = false;
  bool colors = false;
  bool texcoords = false;  // texture coordinates per triangle corner and a material per triangle
};

// Triangle materials (store_format.h): an index into the store's materials
// (store_textures.h), or one of these.
constexpr uint32_t kAtlasMaterial = 0xFFFFFFFEu;  // the patch's own atlas (Patch::atlas)
// kNoMaterial (mesh_reader.h, 0xFFFFFFFF): untextured.

struct BoundaryEntry {
  uint32_t local;      // vp: vertex index inside this patch
  PatchId neighbour;   // q
  uint32_t remote;     // vq: the same vertex's index inside q
  // Lists are kept sorted by (local, neighbour, remote).
  friend bool operator<(const BoundaryEntry& a, const BoundaryEntry& b) {
    return std::tie(a.local, a.neighbour, a.remote) < std::tie(b.local, b.neighbour, b.remote);
  }
  friend bool operator==(const BoundaryEntry& a, const BoundaryEntry& b) {
    return a.local == b.local && a.neighbour == b.neighbour && a.remote == b.remote;
  }
};

// One patch, decoded.
struct Patch {
  PatchId id = 0;
  uint64_t cell = 0;     // the cell key it was made for (assigner's key, or caller's in writeBack)
  uint32_t level = 0;    // caller-defined (mtbuild: the level that wrote it); 0 at ingest
  std::vector<double> positions;   // 3 per vertex
  std::vector<float> normals;      // 3 per vertex, empty when the layout has none
  std::vector<uint8_t> colors;     // 4 per vertex, empty when the layout has none
  std::vector<uint32_t> triangles; // 3 per triangle, local indices
  // Textured stores: texture coordinates of every corner (6 per triangle) and a material per
  // triangle; the atlas image the patch's kAtlasMaterial triangles use (empty: none). Ingest
  // fills the per-vertex form instead (2 per vertex, 1 per vertex), which is what its vertex
  // records carry; patch() always returns the per-corner form.
  std::vector<float> cornerUV;
  std::vector<uint32_t> triangleMaterial;
  std::string atlas;
  std::vector<float> texcoords;
  std::vector<uint32_t> vertexMaterial;
  std::vector<BoundaryEntry> boundary;  // sorted by (local, neighbour)
  uint32_t vertexCount() const { return uint32_t(positions.size() / 3); }
  uint32_t triangleCount() const { return uint32_t(triangles.size() / 3); }
};

// Summary of one live patch, kept in RAM (from the manifest).
struct PatchMeta {
  PatchId id = 0;
  uint64_t cell = 0;
  uint32_t level = 0;
  uint32_t vertices = 0;
  uint32_t triangles = 0;
  uint32_t boundaryEntries = 0;
  Box3 bounds;
};

// Several patches loaded as one mesh (BMT section 6: "we exploit these lists to efficiently unify
// vertex indexes and to mark the vertices that are referred by not loaded patches").
struct LoadedMesh {
  std::vector<PatchId> patches;    // the loaded set, ascending
  std::vector<double> positions;   // 3 per vertex
  std::vector<float> normals;      // 3 per vertex or empty
  std::vector<uint8_t> colors;     // 4 per vertex or empty
  std::vector<uint32_t> triangles; // 3 per triangle, unified indices
  std::vector<float> cornerUV;     // textured stores: 6 per triangle
  std::vector<uint32_t> triangleMaterial;  // textured stores: 1 per triangle
  std::vector<std::string> atlases;        // per loaded patch (as `patches`): its atlas or ""
  std::vector<PatchId> trianglePatch;  // the loaded patch each triangle came from
  std::vector<uint8_t> locked;     // 1 per vertex: used by a patch outside the loaded set
  // For each locked vertex, where outside patches hold it: (vertex, outside patch, index there).
  struct ExternalRef {
    uint32_t vertex;
    PatchId patch;
    uint32_t remote;
    friend bool operator<(const ExternalRef& a, const ExternalRef& b) {
      return std::tie(a.vertex, a.patch, a.remote) < std::tie(b.vertex, b.patch, b.remote);
    }
    friend bool operator==(const ExternalRef& a, const ExternalRef& b) {
      return a.vertex == b.vertex && a.patch == b.patch && a.remote == b.remote;
    }
  };
  std::vector<ExternalRef> external;  // sorted by vertex
  // Per loaded patch (same order as `patches`), its local vertex -> unified index. writeBack()
  // uses it to re-read where outside patches hold the locked vertices at commit time, since a
  // neighbouring region written back after this load has replaced those outside patches.
  std::vector<std::vector<uint32_t>> unifiedOf;
  uint32_t vertexCount() const { return uint32_t(positions.size() / 3); }
  uint32_t triangleCount() const { return uint32_t(triangles.size() / 3); }
};

// The new content for a loaded region. Vertices that existed in the LoadedMesh keep their
// identity through `origin` (index into LoadedMesh's vertices, kNoVertex for new vertices).
// Every locked vertex that is still referenced from outside must appear with its origin and its
// exact original position: the store checks this, since it is what keeps the mesh crack-free.
struct ReplacementMesh {
  std::vector<double> positions;
  std::vector<float> normals;      // empty, or 3 per vertex when the layout has normals
  std::vector<uint8_t> colors;     // empty, or 4 per vertex when the layout has colours
  std::vector<uint32_t> triangles;
  std::vector<uint32_t> origin;    // 1 per vertex
  std::vector<uint64_t> triangleCell;  // the new partition: triangles with equal key form a patch
  // Textured stores: per triangle (6 and 1), and the atlas of the new patch of each cell key
  // (none: the patch has no atlas).
  std::vector<float> cornerUV;
  std::vector<uint32_t> triangleMaterial;
  std::map<uint64_t, std::string> cellAtlas;
  uint32_t level = 0;              // recorded in every new patch
};

struct IngestOptions {
  uint64_t memoryBytes = 256ull << 20;  // the --memory cap for the whole ingest
  uint32_t patchTriangles = 0;          // 0: the assigner's own default
  std::string tempDir;                  // default: STORE/tmp
  bool progress = true;                 // progress lines on stderr
  // Tests: the chunked path's vertex positions in RAM, its windows and chunks (0: the memory
  // plan's share), to make small inputs take every branch of the join (ingest_join.h).
  uint64_t positionBytes = 0;
  // Once every face has its cell the ingest calls the assigner's releaseLookups(), so its later
  // stages have that memory; true keeps the assigner answering cellKey() after the ingest (tests
  // that check the stored keys against it).
  bool keepAssignerLookups = false;
};

// Figures that ingest measured, kept in the store and printed by `mtstore info`.
struct IngestReport {
  std::string input;
  std::string format;
  uint64_t inputVertices = 0, inputTriangles = 0, inputBytes = 0;
  uint64_t polygons = 0;              // faces with more than 3 corners (triangulated)
  uint64_t degenerateTriangles = 0;   // a repeated vertex index
  uint64_t duplicateTriangles = 0;    // same vertex set as an earlier triangle
  uint64_t unreferencedVertices = 0;
  uint64_t nonManifoldEdges = 0;      // undirected edges used by more than two triangles
  uint64_t weldedVertices = 0;        // STL soups: exact-position duplicates merged
  std::string assigner;
  double seconds = 0;
  uint64_t peakBytes = 0;             // RSS high-water mark at the end of ingest
  // Not kept in the store: how the chunked path found the corners' positions (faces joined in
  // the windows of its sweep, or through the buckets of vertex chunks; per join, summed), and
  // whether it read the input's vertex and face records in place. Zero on the resident path.
  uint64_t sweptFaces = 0, bucketedFaces = 0;
  bool verticesInPlace = false, facesInPlace = false;
};

struct StoreInfo {
  uint64_t patches = 0, triangles = 0, vertices = 0, boundaryEntries = 0, bytesOnDisk = 0;
  uint64_t liveBytes = 0;  // of the blocks live patches reference (bytesOnDisk less dead blocks)
  uint32_t minPatchTriangles = 0, maxPatchTriangles = 0;
  double meanPatchTriangles = 0;
  VertexLayout layout;
  Box3 bounds;  // the input's at ingest, grown to contain every live patch's (healed vertices too)
  IngestReport ingest;
};

struct CheckReport {
  bool ok = true;
  std::vector<std::string> problems;  // one line each, naming the patch (and file/offset)
  uint64_t patchesChecked = 0, entriesChecked = 0;
};

// One patch's new content for PatchStore::rewritePatches (healing support).
struct PatchRewrite {
  Patch patch;                // id names the live patch to replace; cell and level are kept
  bool boundaryOnly = false;  // keep the geometry block, replace only the boundary list
};

// Positions staged by PatchStore::stageGeometry, made live by commitStaged (healing support).
class StagedUpdate {
 public:
  StagedUpdate();
  ~StagedUpdate();
  StagedUpdate(const StagedUpdate&) = delete;
  StagedUpdate& operator=(const StagedUpdate&) = delete;
  size_t size() const;
  struct Entries;

 private:
  friend class PatchStore;
  std::unique_ptr<Entries> entries_;
};

class PatchStore {
 public:
  // Builds a new store at `dir` (which must not exist or be empty) from a mesh file. The store is
  // built in a temporary directory next to `dir` and renamed into place when complete.
  static IngestReport ingest(const std::string& input, const std::string& dir,
                             CellAssigner& assigner, const IngestOptions& options,
                             Env* env = Env::Default());
  // Opens the last committed version for reading: no lock, nothing on disk changes, so it may
  // run while another process writes the store (it keeps seeing the version it opened). The first
  // update (writeBack, rewritePatches, stageGeometry, putBlob) takes the store's write lock.
  static std::unique_ptr<PatchStore> open(const std::string& dir, Env* env = Env::Default());
  ~PatchStore();
  // Takes the exclusive lock STORE/LOCK now (updates take it by themselves), held until the store
  // is closed. Throws mt::Error "STORE: in use by process PID (lock STORE/LOCK)..." when another
  // writer holds it, or "...was changed by another process after it was opened here" when a
  // writer committed after this open. Also finishes recovery (a torn manifest tail, files of
  // uncommitted updates), which only a writer may do.
  void lockForWriting();
  bool lockedForWriting() const;

  const std::string& dir() const { return dir_; }
  const VertexLayout& layout() const;
  std::vector<PatchId> patchIds() const;          // live patches, ascending
  PatchMeta meta(PatchId id) const;
  StoreInfo info() const;
  // Opaque bytes stored with the store (e.g. V-partition seeds), by name.
  std::string blob(const std::string& name) const;
  void putBlob(const std::string& name, const std::string& bytes);

  Patch patch(PatchId id) const;                  // reads and verifies one patch
  LoadedMesh load(const std::vector<PatchId>& ids) const;
  // load() from patches the caller has already read with patch() (e.g. to encode them too), so
  // they are not read and decoded twice. The patches must be current and distinct.
  LoadedMesh assemble(const std::vector<Patch>& patches) const;
  // Replaces the loaded patches by the replacement's partition; returns the new patch ids in
  // ascending cell-key order. Durable once sync() returns (or at once with syncNow). Regions with
  // disjoint patch sets may be loaded concurrently and written back in any order.
  // With autoCommit off, write-backs are committed only by sync(), never by the destructor (so a
  // checkpointed build can resume from exactly its last sync); on by default, large batches commit
  // by themselves and the destructor commits the rest.
  std::vector<PatchId> writeBack(const LoadedMesh& loaded, const ReplacementMesh& replacement,
                                 bool syncNow = false);
  void sync();
  void setAutoCommit(bool on);
  // Streams every triangle (welded by vertex identity across patches) to a binary PLY.
  void exportPly(const std::string& path, bool progress = false) const;
  CheckReport check() const;

  // ---- Healing support (heal_support.cpp; used by patchstore/heal) ----
  // writeBack() gives the loaded patches new ids and refuses to drop a vertex an outside patch
  // holds. Healing needs finer edits: change a few patches in place (same ids, so later passes
  // and their precomputed tables stay valid), drop a shared vertex from one patch while its other
  // holders keep it, and move every copy of a shared vertex at once (smoothing).
  //
  // Replaces the content of existing patches in place, in one update: geometry and boundary list
  // of each rewrite (or only the boundary list when boundaryOnly). A rewrite with no triangles
  // removes the patch. The update is checked before anything is written: every boundary entry of
  // a rewritten patch, and every entry of an outside patch that points into the rewritten set,
  // must be mirrored with an equal position (the crack-free rule of writeBack, stated on the
  // result instead of the edit). Throws mt::Error and writes nothing when it is not.
  void rewritePatches(const std::vector<PatchRewrite>& rewrites, bool syncNow = false);
  // A staged update of positions (same topology): stageGeometry() appends a patch's new geometry
  // block at once but leaves the manifest alone, so every later patch()/load() still reads the
  // old positions (Jacobi iterations read the old mesh while writing the new one).
  // commitStaged() then makes all staged blocks live in ONE manifest edit (the commit point of
  // store_format.h). Vertex and triangle counts must equal the live patch's; a patch written by
  // anything else after staging is a conflict (mt::Error, nothing committed).
  void stageGeometry(StagedUpdate& staged, const Patch& p);
  void commitStaged(StagedUpdate& staged);

  struct Impl;
 private:
  explicit PatchStore(std::unique_ptr<Impl> impl, std::string dir);
  std::unique_ptr<Impl> impl_;
  std::string dir_;
};

}  // namespace mt
