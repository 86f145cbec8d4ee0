// Whole-store passes over every patch: exportPly (the store as one welded mesh) and check (every
// block verified, every boundary entry mirrored).
#include <algorithm>
#include <cinttypes>
#include <cstdio>
#include <unordered_map>

#include "patchstore/io/ply_writer.h"
#include "patchstore/store_impl.h"
#include "patchstore/store_textures.h"

namespace mt {

using namespace store_format;

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
  if (next > kMaxVertices) fail(path, "too many vertices for 32-bit indices", ErrorKind::Resource);
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
  // Textured stores: the tiled images' checksums, and every triangle's material and texture
  // coordinates in range.
  if (impl_->layout.texcoords) {
    for (std::string& p : checkTextures(*this)) report.problems.push_back(std::move(p));
    const size_t materials = storeMaterials(*this).size();
    for (PatchId id : ids) {
      const Patch* p = get(id);
      if (!p) continue;
      for (size_t t = 0; t < p->triangleMaterial.size(); ++t) {
        const uint32_t m = p->triangleMaterial[t];
        if (m != kNoMaterial && m != kAtlasMaterial && m >= materials) {
          report.problems.push_back(dir_ + ": patch " + std::to_string(id) + ": triangle " + std::to_string(t) + " names material " +
                                    std::to_string(m) + " of " + std::to_string(materials));
          break;
        }
        if (m == kAtlasMaterial && p->atlas.empty()) {
          report.problems.push_back(dir_ + ": patch " + std::to_string(id) + ": triangle " + std::to_string(t) +
                                    " names the patch's atlas, which it has not");
          break;
        }
      }
      for (float x : p->cornerUV)
        if (!(x >= 0.0f && x <= 1.0f)) {
          report.problems.push_back(dir_ + ": patch " + std::to_string(id) + ": a texture coordinate is outside [0, 1]");
          break;
        }
    }
  }
  report.ok = report.problems.empty();
  return report;
}

}  // namespace mt
