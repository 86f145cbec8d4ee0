#include "mtrender/scene.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>

#include "base/error.h"
#include "mtrender/patch_cache.h"

namespace mt::render {

Scene::Scene(const std::vector<std::string>& paths) {
  if (paths.empty()) throw Error("mtrender: no MT file given");
  for (int a = 0; a < 3; ++a) {
    boundsMin[a] = std::numeric_limits<double>::infinity();
    boundsMax[a] = -std::numeric_limits<double>::infinity();
  }
  // Every file opened first, so the arrays are sized once (a billion-triangle file has 1.2 M
  // patches and 624 k arcs: growing by doubling copied them and faulted their pages in again).
  std::vector<std::unique_ptr<MtFileReader>> opened;
  size_t nodeTotal = 0, arcTotal = 0, refTotal = 0;
  for (const std::string& path : paths) {
    opened.push_back(MtFileReader::open(path));
    nodeTotal += opened.back()->nodes().size();
    arcTotal += opened.back()->arcs().size();
    refTotal += opened.back()->patchRefs().size();
  }
  nodes_.reserve(nodeTotal);
  arcs_.reserve(arcTotal);
  inArcs_.reserve(arcTotal);
  arcPatches_.reserve(refTotal);
  for (auto& reader : opened) {
    const std::string& path = reader->path();
    const auto& h = reader->header();
    const uint32_t file = uint32_t(readers_.size());
    const uint32_t nodeBase = uint32_t(nodes_.size()), arcBase = uint32_t(arcs_.size());
    const uint32_t patchBase = patchCount_;
    if (uint64_t(nodeBase) + h.nodeCount > UINT32_MAX || uint64_t(patchBase) + h.patchCount > UINT32_MAX)
      fail(path, "the scene has more than 2^32 nodes or patches");
    patchBase_.push_back(patchBase);
    arcBase_.push_back(arcBase);
    if (h.vertexFlags & format::kHasColors) hasColors_ = true;
    for (int a = 0; a < 3; ++a) {
      boundsMin[a] = std::min(boundsMin[a], h.boundsMin[a]);
      boundsMax[a] = std::max(boundsMax[a], h.boundsMax[a]);
    }
    const auto& rn = reader->nodes();
    const auto& ra = reader->arcs();
    for (size_t i = 0; i < rn.size(); ++i) {
      const auto& n = rn[i];
      SceneNode s{};
      for (int a = 0; a < 3; ++a) s.center[a] = n.center[a], s.coneAxis[a] = n.coneAxis[a];
      s.radius = n.radius;
      s.error = n.error;
      s.coneCutoff = n.coneCutoff;
      s.level = n.level;
      s.file = file;
      s.firstArc = arcBase + n.firstArc;
      s.arcCount = n.arcCount;
      s.firstInArc = uint32_t(inArcs_.size()) + n.firstBackArc;
      s.inArcCount = n.backArcCount;
      s.source = i == 0;
      s.sink = i + 1 == rn.size();
      if (s.sink) s.error = std::numeric_limits<float>::infinity();
      nodes_.push_back(s);
    }
    sources_.push_back(nodeBase);
    sinks_.push_back(nodeBase + uint32_t(rn.size()) - 1);
    for (uint32_t b : reader->backArcs()) inArcs_.push_back(arcBase + b);
    const auto& refs = reader->patchRefs();
    for (const auto& a : ra) {
      SceneArc s{};
      s.from = nodeBase + a.from;
      s.to = nodeBase + a.to;
      s.firstPatch = uint32_t(arcPatches_.size());
      s.patchCount = a.patchCount;
      for (uint32_t k = 0; k < a.patchCount; ++k) {
        uint32_t p = refs[a.firstPatchRef + k];
        arcPatches_.push_back(patchBase + p);
        s.triangles += reader->patches()[p].triangles;
      }
      // The source's sphere has radius 0 (it is never refined past); its patches lie in `to`'s
      // floor, which `to`'s sphere encloses. Otherwise `from`'s sphere and cone bound its fragment.
      s.cullNode = a.from == 0 ? s.to : s.from;
      arcs_.push_back(s);
    }
    patchCount_ += uint32_t(reader->patches().size());
    surfaces_.push_back(ClosedSurface::ofFile(*reader));
    readers_.push_back(std::move(reader));
  }
  for (auto& n : nodes_) {
    for (uint32_t k = 0; k < n.arcCount; ++k) n.outTriangles += arcs_[n.firstArc + k].triangles;
    for (uint32_t k = 0; k < n.inArcCount; ++k) n.inTriangles += arcs_[inArcs_[n.firstInArc + k]].triangles;
  }
}

void Scene::boundingSphere(double c[3], double& r) const {
  double d2 = 0;
  for (int a = 0; a < 3; ++a) {
    c[a] = 0.5 * (boundsMin[a] + boundsMax[a]);
    d2 += (boundsMax[a] - c[a]) * (boundsMax[a] - c[a]);
  }
  r = std::max(std::sqrt(d2), 1e-9);
}

}  // namespace mt::render

namespace mt::render {

void Scene::forEachMoveGroup(const std::function<void(const uint32_t* ids, size_t count)>& group) const {
  // The sink is never moved either, but its in-patches are the coarsest cut: resident together.
  std::vector<uint32_t> ids;
  auto add = [&](const SceneArc& a) {
    ids.insert(ids.end(), arcPatches_.begin() + a.firstPatch, arcPatches_.begin() + a.firstPatch + a.patchCount);
  };
  for (const SceneNode& n : nodes_) {
    if (n.source) continue;  // never moved (its out-arcs are every finest patch)
    ids.clear();
    for (uint32_t k = 0; k < n.arcCount; ++k) add(arcs_[n.firstArc + k]);
    for (uint32_t k = 0; k < n.inArcCount; ++k) add(arcs_[inArcs_[n.firstInArc + k]]);
    group(ids.data(), ids.size());
  }
}

namespace {
// The bound of decodedBytesBound for one patch record of a file.
uint64_t boundOf(const MtFileReader& r, bool textures, uint32_t local) {
  const format::PatchRecord& p = r.patches()[local];
  uint64_t v = p.vertices;
  // Draco may split non-manifold vertices on decode (mt_format.h); allow a quarter more.
  if (r.codec() == format::Codec::Draco) v = std::min<uint64_t>(3ull * p.triangles, v + v / 4 + 64);
  uint64_t bytes = uint64_t(v) * 20 + uint64_t(p.triangles) * 12;
  // A textured patch's corner coordinates and texels share its place holder (patch_cache.h).
  if (textures && r.textures()[local].size != 0)
    bytes += renderTextureBytes(p.triangles, r.textures()[local].width, r.textures()[local].height);
  return bytes;
}
}  // namespace

uint64_t Scene::decodedBytesBound(uint32_t patch) const {
  const uint32_t file = fileOfPatch(patch);
  return boundOf(*readers_[file], loadsTextures(file), patch - patchBase_[file]);
}

std::vector<uint64_t> Scene::decodedBytesBounds() const {
  // File by file, without a file lookup per patch: 1.2 M patches of a billion-triangle file are
  // sized at open, before the first frame.
  std::vector<uint64_t> out(patchCount_);
  for (uint32_t f = 0; f < readers_.size(); ++f) {
    const MtFileReader& r = *readers_[f];
    const bool textures = loadsTextures(f);
    const uint32_t n = uint32_t(r.patches().size());
    uint64_t* to = out.data() + patchBase_[f];
    for (uint32_t local = 0; local < n; ++local) to[local] = boundOf(r, textures, local);
  }
  return out;
}

}  // namespace mt::render
