// Internal to patchstore/heal: a group of patches loaded as one mesh that keeps each patch's
// identity, edited in core, and written back in place (same patch ids) through
// PatchStore::rewritePatches. The loader is BMT section 6's unification ("we exploit these lists
// to efficiently unify vertex indexes and to mark the vertices that are referred by not loaded
// patches"); the commit is its write-back, except that patches keep their ids and a vertex that
// unloaded patches hold may leave the group (its other holders keep it).
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "patchstore/heal/heal.h"

namespace mt::heal {

inline uint64_t gidOf(PatchId p, uint32_t local) { return (uint64_t(p) << 32) | local; }
inline PatchId gidPatch(uint64_t g) { return PatchId(g >> 32); }
inline uint32_t gidLocal(uint64_t g) { return uint32_t(g); }

// Global key of every vertex of p: (owner patch, index there), owner = lowest holder.
std::vector<uint64_t> ownerKeys(const Patch& p);

struct Region {
  std::vector<PatchId> patches;                 // ascending
  std::vector<Patch> original;                  // as read, parallel to patches
  std::vector<std::vector<uint32_t>> unifiedOf; // per patch: local index -> region vertex
  std::vector<double> positions;                // 3 per region vertex
  std::vector<float> normals;                   // 3 per vertex or empty
  std::vector<uint8_t> colors;                  // 4 per vertex or empty
  std::vector<uint32_t> triangles;              // region vertex ids
  std::vector<uint32_t> trianglePatch;          // index into patches
  std::vector<float> cornerUV;                  // textured stores: 6 per triangle
  std::vector<uint32_t> triangleMaterial;       // textured stores: 1 per triangle
  std::vector<uint8_t> locked;                  // 1: an unloaded patch holds it
  struct External { uint32_t vertex; PatchId patch; uint32_t remote; };
  std::vector<External> external;               // sorted by vertex
  uint32_t vertexCount() const { return uint32_t(positions.size() / 3); }
  int indexOf(PatchId id) const;                // -1 when not loaded
  // The region vertex a patch's local index maps to, or kNoVertex when the patch is not loaded.
  uint32_t vertexOf(PatchId id, uint32_t local) const;
};

Region loadRegion(const PatchStore& store, std::vector<PatchId> ids);

// Loads `ids` and keeps adding the unloaded patches that hold any vertex `wanted` selects until
// none of those is locked (so the edit sees every triangle around them). Stops growing at
// maxPatches (then some wanted vertices may stay locked: the caller checks).
Region loadUnlocked(const PatchStore& store, std::vector<PatchId> ids,
                    const std::function<bool(const Region&, uint32_t vertex)>& wanted, size_t maxPatches = 4096);

// The edited region: a new mesh whose vertices keep their identity through origin (a region
// vertex, or kNoVertex for a new one) and whose triangles say which loaded patch they go to.
struct RegionEdit {
  std::vector<double> positions;
  std::vector<float> normals;
  std::vector<uint8_t> colors;
  std::vector<uint32_t> origin;
  std::vector<uint32_t> triangles;
  std::vector<uint32_t> trianglePatch;  // index into Region::patches
  std::vector<float> cornerUV;          // textured stores: 6 per triangle (kept with the triangles)
  std::vector<uint32_t> triangleMaterial;
  uint32_t vertexCount() const { return uint32_t(positions.size() / 3); }
  uint32_t addVertexCopy(const Region& r, uint32_t regionVertex);  // same position/attributes, new identity
  // Appends region triangle t (its corners renamed to v when given) with its patch and texture
  // coordinates; appends a new triangle (untextured) to loaded patch k.
  void keepTriangle(const Region& r, size_t t, const uint32_t* v = nullptr);
  void addTriangle(const uint32_t v[3], uint32_t k, bool textured);
  void clearTriangles();
};
RegionEdit identityEdit(const Region& r);

struct CommitStats {
  uint64_t droppedVertices = 0;  // region vertices that no triangle uses any more and no unloaded patch holds
  uint64_t changedPatches = 0;
};
// Writes the edit back: each loaded patch gets its triangles, the vertices they use (original
// ones first, in their old order, so unchanged patches are not rewritten), and boundary entries
// to every other holder; unloaded patches that shared vertices with the group get their entries
// into it rebuilt. A locked vertex that is still used must keep its position (it is checked).
CommitStats commitRegion(PatchStore& store, const Region& r, const RegionEdit& edit);

// Undirected edges with their triangle counts over the whole store, streamed once: edges interior
// to a patch are counted there; edges whose two ends are shared are gathered with an external
// sort by global key, so an edge split between patches is counted once with its full count.
struct EdgeUse {
  uint64_t a, b;       // global keys, a < b
  uint32_t count;      // triangles using the edge, whole mesh
  // For count == 1 (a border edge): its direction in its triangle and the patch holding it.
  bool forward;        // the triangle has a -> b (else b -> a)
  PatchId patch;
};
// Calls fn for every edge whose count passes `want` (e.g. count != 2). Memory: the sort's budget.
void edgeCensus(const PatchStore& store, const HealOptions& options, const std::function<bool(uint32_t count)>& want,
                const std::function<void(const EdgeUse&)>& fn, const char* task);

std::string scratchPrefix(const PatchStore& store, const HealOptions& options, const std::string& name);

}  // namespace mt::heal
