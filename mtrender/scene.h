// mtrender/scene.h: one or more MT files flattened into ONE DAG held in RAM (BMT section 5: "the
// DAG in RAM, patches on demand"). Node, arc and patch ids are global across the files (each file
// contributes a contiguous range), so every file shares one cut machinery, one patch cache and one
// budget. Payloads are not read here: PatchServer reads them on demand through the readers.
//
// mtrender depends on mtfile/mt_file.h (the MT file format and its reader, library mt_mtfile)
// and base/error.h only.
#pragma once

#include <algorithm>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "mtfile/mt_file.h"
#include "mtrender/closed_surface.h"

namespace mt::render {

struct SceneNode {
  double center[3];   // double: georeferenced models sit millions of units from the origin
  float radius;
  float error;        // object-space error (BMT 5.1); +inf for a sink
  float coneAxis[3];
  float coneCutoff;   // cos(half angle); -1 = no back-face culling
  uint32_t level;
  uint32_t file;
  uint32_t firstArc, arcCount;      // out-arcs: arcs[firstArc, +arcCount)
  uint32_t firstInArc, inArcCount;  // in-arcs: inArcs[firstInArc, +inArcCount)
  uint32_t outTriangles;            // triangles on the out-arcs (the node's fragment)
  uint32_t inTriangles;             // triangles on the in-arcs (what replaces it when refined)
  bool source, sink;
};

struct SceneArc {
  uint32_t from, to;
  uint32_t firstPatch, patchCount;  // into Scene::arcPatches
  uint32_t triangles;
  uint32_t cullNode;  // node whose sphere/cone bounds the arc's patches (from, or to for a source)
};

// A patch as the scene sees it (Scene::patch), made from its file's record when asked for: a
// billion-triangle file has 1.2 M patches, and a copy of them all was 29 MB of fresh memory to
// fault in at open.
struct ScenePatch {
  uint32_t file;
  uint32_t local;      // patch id inside its file
  uint32_t arc;        // global arc id
  uint32_t triangles, vertices;
  uint32_t fileBytes;  // payload size on disk
};

class Scene {
 public:
  // Opens every file (MtFileReader::open validates it); throws mt::Error naming the bad file.
  explicit Scene(const std::vector<std::string>& paths);

  const std::vector<SceneNode>& nodes() const { return nodes_; }
  const std::vector<SceneArc>& arcs() const { return arcs_; }
  const std::vector<uint32_t>& inArcs() const { return inArcs_; }
  const std::vector<uint32_t>& arcPatches() const { return arcPatches_; }
  size_t patchCount() const { return patchCount_; }
  ScenePatch patch(uint32_t id) const {
    const uint32_t file = fileOfPatch(id), local = id - patchBase_[file];
    const format::PatchRecord& r = readers_[file]->patches()[local];
    return {file, local, arcBase_[file] + r.arc, r.triangles, r.vertices, r.size};
  }
  const std::vector<uint32_t>& sources() const { return sources_; }
  const std::vector<uint32_t>& sinks() const { return sinks_; }
  size_t fileCount() const { return readers_.size(); }
  const MtFileReader& reader(uint32_t file) const { return *readers_[file]; }
  bool hasColors() const { return hasColors_; }
  // The file's coarsest cut as a surface: whether it is closed and an eye outside it (when normal
  // cones may cull, closed_surface.h). Read at open.
  const ClosedSurface& surface(uint32_t file) const { return surfaces_[file]; }

  // Bounding box of all files (object space; the files share one world space).
  double boundsMin[3], boundsMax[3];
  void boundingSphere(double c[3], double& r) const;

  // Decoded size of a patch in the renderer's layout (RenderPatch in patch_cache.h), an upper
  // bound the cache sizes its place holders with; a textured patch's coordinates and texels included.
  uint64_t decodedBytesBound(uint32_t patch) const;
  // decodedBytesBound of every patch, by global id.
  std::vector<uint64_t> decodedBytesBounds() const;
  // Whether textured files' atlases are loaded (the default); off when nothing will be drawn
  // textured (mtrender --headless with --color other than texture): then no texture byte is read,
  // decoded, or counted in the caches. Set before the caches are sized.
  void setLoadTextures(bool load) { loadTextures_ = load; }
  bool loadsTextures(uint32_t file) const { return loadTextures_ && readers_[file]->hasTextures(); }
  // The double-precision origin a patch's vertices are stored relative to (camera-relative
  // drawing: floats hold small offsets from it, so a model millions of units from the origin keeps
  // its centimetres; the GL backend composes the model-view matrix in double). It is the centre
  // of the sphere that bounds the patch (the arc's cull node).
  const double* patchOrigin(uint32_t patch) const { return nodes_[arcs_[this->patch(patch).arc].cullNode].center; }
  // For each node but the sources, the patches one move on it needs resident together (its in- and
  // out-patches; for a sink, the coarsest cut), for PatchCache's per-class floor (MoveGroups).
  void forEachMoveGroup(const std::function<void(const uint32_t* ids, size_t count)>& group) const;
  // A patch's id within the scene from (file, local patch id).
  uint32_t globalPatch(uint32_t file, uint32_t local) const { return patchBase_[file] + local; }
  // The file a scene patch comes from.
  uint32_t fileOfPatch(uint32_t global) const {
    return uint32_t(std::upper_bound(patchBase_.begin(), patchBase_.end(), global) - patchBase_.begin()) - 1;
  }

 private:
  bool loadTextures_ = true;
  std::vector<std::unique_ptr<MtFileReader>> readers_;
  std::vector<SceneNode> nodes_;
  std::vector<SceneArc> arcs_;
  std::vector<uint32_t> inArcs_, arcPatches_, patchBase_, arcBase_;
  uint32_t patchCount_ = 0;
  std::vector<uint32_t> sources_, sinks_;
  bool hasColors_ = false;
  std::vector<ClosedSurface> surfaces_;
};

}  // namespace mt::render
