// mtrender/patch_cache.h: the RAM cache of decoded patches, with a hard byte cap.
//
// Managed as in El-Sana & Chiang, "External memory view-dependent simplification", section 3.3.3:
//   - ONE arena of fixed-size "place holders", allocated once, so the cache can never exceed its
//     cap and never fragments. The paper sizes every place holder for the largest meta-node,
//     assuming sizes "do not differ too much"; MT patches do (the largest decodes to ~4.5x the
//     mean on a 10 M-triangle build), so place holders come in a few size classes (the largest
//     patch / 2^k), and the cap is split among the classes in proportion to the bytes the file's
//     patches of each class would need. Each class has its own free list; one hash table;
//   - a hash table patch id -> place holder: a patch found there is in "physical" memory;
//   - a free list of place holders whose usage count (patches of the current cut, kept by the
//     render thread only, 3.3.4) and reference count (wanted this frame: refinement candidates and
//     prefetch) are both 0. A place holder that goes free is appended at the END of the free list
//     but keeps its hash entry and content ("second chance"): asking for it again takes it off the
//     free list without a disk read. New loads take the FIRST free-list entry;
//   - urgent prefetching (3.3.2): when the free list is empty, an urgent request evicts the first
//     place holder that is only prefetched (in real memory, not used by the cut). A "switch down"
//     (refinement) request may do so only while at least 3 such place holders remain, a "switch
//     up" (coarsening) request always may, so navigation can never get stuck with memory full of
//     patches in use.
// All methods are thread-safe (one mutex, held briefly): the render thread pins/touches, the
// PatchServer thread reserves, fills and commits.
#pragma once

#include <cstdint>
#include <functional>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

namespace mt::render {

// The renderer's vertex: 20 bytes, the layout the GL backend draws directly.
struct RenderVertex {
  float position[3];
  uint32_t normal;    // GL_INT_2_10_10_10_REV, signed normalized, w = 0
  uint8_t color[4];   // RGBA8 (white when the file has no colours)
};
static_assert(sizeof(RenderVertex) == 20, "RenderVertex layout");

uint32_t packNormal(const float n[3]);

// Bytes a decoded patch takes in a place holder.
inline uint64_t renderPatchBytes(uint64_t vertices, uint64_t triangles) {
  return vertices * sizeof(RenderVertex) + triangles * 3 * sizeof(uint32_t);
}
// Bytes a patch's texture adds after its geometry (textured files, mt_format.h "Textures"): the
// corner coordinates (6 unorm16 per triangle, in the order of the indices) and the atlas's texels
// (RGB8, bottom row first: GL's order, v = 0 at the bottom).
inline uint64_t renderTextureBytes(uint64_t triangles, uint64_t width, uint64_t height) {
  return width && height ? triangles * 6 * sizeof(uint16_t) + width * height * 3 : 0;
}

// A patch's own bounds, measured when it is decoded (relative to Scene::patchOrigin): its
// bounding sphere and its normal cone (axis, cos of the half angle; cutoff <= -1: no cone). The
// finest patches (on arcs leaving a source node) have no DAG node of their own to carry a cone;
// these give them back-face culling too.
struct PatchBound {
  float center[3] = {0, 0, 0};
  float radius = 0;
  float coneAxis[3] = {0, 0, 1};
  float coneCutoff = -2;
};

// A patch in the cache: vertices (positions relative to Scene::patchOrigin) then 32-bit triangle
// indices, in one place holder; a textured patch then has its corner coordinates and its atlas's
// texels in the same place holder (renderTextureBytes), so the cache's cap counts them.
struct PatchView {
  PatchBound bound;
  const RenderVertex* vertices = nullptr;
  uint32_t vertexCount = 0;
  const uint32_t* indices = nullptr;
  uint32_t indexCount = 0;
  // Textured patches only (texWidth 0 otherwise): (u, v) unorm16 per corner, 2 per index.
  const uint16_t* cornerUV = nullptr;
  const uint8_t* texels = nullptr;  // RGB8, texWidth * texHeight, bottom row first
  uint16_t texWidth = 0, texHeight = 0;
  bool textured() const { return texWidth != 0 && cornerUV != nullptr; }
  uint64_t bytes() const { return renderPatchBytes(vertexCount, indexCount / 3) + renderTextureBytes(indexCount / 3, texWidth, texHeight); }
};

// Where a patch's texture starts in its place holder: after the geometry (a multiple of 4).
inline uint64_t textureOffset(uint64_t vertices, uint64_t triangles) { return renderPatchBytes(vertices, triangles); }
// Its texels: after the corner coordinates (a multiple of 4).
inline uint64_t texelOffset(uint64_t vertices, uint64_t triangles) {
  return textureOffset(vertices, triangles) + triangles * 6 * sizeof(uint16_t);
}

enum class Urgency : uint8_t { Prefetch = 0, Needed = 1, UrgentDown = 2, UrgentUp = 3 };

struct CacheStats {
  uint64_t capBytes = 0, slotBytes = 0, arenaBytes = 0;  // slotBytes: the largest class
  uint32_t slots = 0;          // K place holders
  uint32_t physical = 0;       // place holders holding a patch (hash entries)
  uint32_t real = 0;           // ... of which not on the free list
  uint32_t pinned = 0;         // ... of which used by the cut
  uint64_t usedBytes = 0;      // place holders holding a patch, in bytes (<= arenaBytes <= cap)
  uint32_t classes = 0;
  uint64_t secondChance = 0;   // revived from the free list without a read
  uint64_t evictions = 0;      // a patch's content overwritten
  uint64_t urgentEvictions = 0;
  uint64_t givenUp = 0;        // reserve() refused: no room
};

// The groups of patches one cut move needs resident together (for each DAG node, its in- and
// out-patches; Scene::forEachMoveGroup): calls `group` once per group, with ids valid during the
// call only (one buffer reused: a billion-triangle file has 171 k groups, and a vector each took
// ~50 ms of its opening).
using MoveGroups = std::function<void(const std::function<void(const uint32_t* ids, size_t count)>& group)>;

class PatchCache {
 public:
  enum class State : uint8_t { Absent, Loading, Ready, Bad };

  // patchBytes[id]: an upper bound of patch id's decoded size (renderPatchBytes). Throws
  // mt::Error when the cap cannot give every size class a few place holders.
  PatchCache(uint64_t capBytes, const std::vector<uint64_t>& patchBytes);
  // The same, knowing which patches one cut move needs resident together (`moves`: for each DAG
  // node, its in- and out-patches; Scene::forEachMoveGroup): each size class gets at least the place
  // holders the largest move needs in it, plus 3. Without that floor a class sized by its share
  // of the bytes alone could be smaller than one refinement of the coarse levels (whose patches
  // are the largest), and the cut stayed at the coarsest for ever.
  PatchCache(uint64_t capBytes, const std::vector<uint64_t>& patchBytes, const MoveGroups& moves);
  ~PatchCache();

  // ---- render thread ----
  State state(uint32_t id) const;
  // True when every patch is Ready (in physical memory); revives nothing.
  bool allReady(const uint32_t* ids, size_t n) const;
  // If every patch is Ready: takes each off the free list (second chance), usage += 1, true.
  // Otherwise changes nothing and returns false.
  bool pinAll(const uint32_t* ids, size_t n);
  void unpinAll(const uint32_t* ids, size_t n);
  // Reference for this frame: keeps Ready patches in real memory (reviving them from the free
  // list) until endFrame(frame + 1).
  void touch(const uint32_t* ids, size_t n, uint64_t frame);
  // Flushes (to the free list's end, content kept) every Ready place holder with usage 0 that
  // was not touched in `frame`.
  void endFrame(uint64_t frame);
  // A pinned patch's data (valid while pinned).
  PatchView view(uint32_t id) const;
  bool isBad(uint32_t id) const;
  // Patches not used by the cut: what a refinement may still load without evicting the cut.
  uint32_t unpinnedSlots() const;
  CacheStats stats() const;
  uint64_t largestSlotBytes() const { return classBytes_.empty() ? 0 : classBytes_[0]; }

  // ---- PatchServer thread ----
  // A place holder for `id` (state Loading), or -1: already present/bad, or no room.
  int reserve(uint32_t id, Urgency urgency, uint64_t frame);
  uint8_t* slotData(int slot) { return arena_.get() + slots_[slot].offset; }
  uint64_t slotBytes(int slot) const { return classBytes_[slots_[slot].cls]; }
  // texWidth, texHeight: the patch's atlas when its place holder holds one (0: untextured).
  void commit(int slot, uint32_t vertexCount, uint32_t indexCount, const PatchBound& bound = {}, uint16_t texWidth = 0,
              uint16_t texHeight = 0);
  // Loading failed: frees the place holder; bad = never try this patch again.
  void abort(int slot, bool bad);

 private:
  struct Slot {
    uint32_t id = UINT32_MAX;  // UINT32_MAX: empty
    State state = State::Absent;
    uint32_t usage = 0;
    uint64_t touched = 0;      // last frame referenced (+1; 0 = never)
    uint32_t vertexCount = 0, indexCount = 0;
    uint16_t texWidth = 0, texHeight = 0;
    PatchBound bound;
    bool onFree = false;
    uint8_t cls = 0;           // size class
    uint64_t offset = 0;       // in the arena
    std::list<uint32_t>::iterator freeIt;
  };
  void takeOffFree(Slot& s);
  void putOnFree(uint32_t slot);
  void evictContent(uint32_t slot);

  mutable std::mutex mu_;
  uint64_t capBytes_, arenaBytes_ = 0;
  std::vector<uint64_t> classBytes_;   // place holder size per class, largest first
  std::vector<uint8_t> patchClass_;    // per patch id
  std::unique_ptr<uint8_t[]> arena_;
  std::vector<Slot> slots_;
  std::unordered_map<uint32_t, uint32_t> hash_;  // patch id -> place holder
  std::vector<std::list<uint32_t>> free_;        // per class: place holders; take front, append back
  std::unordered_map<uint32_t, bool> bad_;
  uint32_t physical_ = 0, pinned_ = 0;
  uint64_t secondChance_ = 0, evictions_ = 0, urgentEvictions_ = 0, givenUp_ = 0;
  std::vector<uint32_t> urgentScan_, classFirst_, classCount_;
  uint64_t usedBytes_ = 0;
};

}  // namespace mt::render
