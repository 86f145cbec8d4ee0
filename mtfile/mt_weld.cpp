// Welding a cut by exact grid position (see mt_cut.h, "Assembling a cut"): the patches on the
// cut's arcs, decoded in parallel, become one mesh whose vertices are the distinct grid points.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cassert>
#include <cmath>

#include "mtfile/mt_cut_internal.h"
#include "mtfile/mt_cut.h"

namespace mt {

using cut_internal::cutPatchIds;

namespace {

struct GridKeyHash {
  size_t operator()(const GridKey& k) const {
    uint64_t h = uint64_t(k[0]) * 0x9E3779B97F4A7C15ull ^ uint64_t(k[1]) * 0xC2B2AE3D27D4EB4Full ^
                 uint64_t(k[2]) * 0x165667B19E3779F9ull;
    return size_t(h ^ (h >> 29));
  }
};

// Grid point -> welded vertex id: open addressing with linear probing, at most 2/3 full (grown
// when it would be fuller). 16-byte slots instead of std::unordered_map's node per vertex, a
// malloc each: the 53M finest cut took 48.6 s and 4.0 GB with it, 12.4 s and 2.75 GB with this
// (with the batched decode below).
class WeldIndex {
 public:
  explicit WeldIndex(uint64_t expected) : slots_(std::max<uint64_t>(1024, expected + expected / 2)) {}
  // The id of point k, inserting `next` when it is new (then *inserted is true).
  uint32_t findOrInsert(const GridKey& k, uint32_t next, bool* inserted) {
    if (3 * (used_ + 1) > 2 * slots_.size()) grow();
    for (size_t i = home(k);; i = i + 1 == slots_.size() ? 0 : i + 1) {
      Slot& s = slots_[i];
      if (s.id == kEmpty) {
        s.key = k, s.id = next, ++used_;
        assert(3 * used_ <= 2 * slots_.size() && "at most 2/3 full");
        *inserted = true;
        return next;
      }
      if (s.key == k) {
        *inserted = false;
        return s.id;
      }
    }
  }

 private:
  static constexpr uint32_t kEmpty = ~0u;
  struct Slot {
    GridKey key{};
    uint32_t id = kEmpty;
  };
  size_t home(const GridKey& k) const { return cut_internal::slotOf(GridKeyHash{}(k), slots_.size()); }
  void grow() {
    std::vector<Slot> old(slots_.size() * 2);
    old.swap(slots_);
    for (const Slot& s : old)
      if (s.id != kEmpty)
        for (size_t i = home(s.key);; i = i + 1 == slots_.size() ? 0 : i + 1)
          if (slots_[i].id == kEmpty) {
            slots_[i] = s;
            break;
          }
  }
  std::vector<Slot> slots_;
  size_t used_ = 0;
};

}  // namespace

std::vector<uint32_t> cutPatchIdsOf(const MtFileReader& r, const std::vector<uint32_t>& arcs) { return cutPatchIds(r, arcs); }

WeldedMesh assembleCut(const MtFileReader& r, const std::vector<uint32_t>& arcs) {
  const std::vector<uint32_t> patchIds = cutPatchIds(r, arcs);
  const QuantizationGrid grid = r.grid();
  const bool normals = r.header().vertexFlags & format::kHasNormals;
  const bool colors = r.header().vertexFlags & format::kHasColors;
  WeldedMesh m;
  m.patches = patchIds.size();
  // Sizes from the patch index (a guess only: a damaged record cannot overrun anything).
  uint64_t vertexGuess = 0, triangleGuess = 0;
  for (uint32_t id : patchIds) {
    const format::PatchRecord& record = r.patches().at(id);
    vertexGuess += record.vertices, triangleGuess += record.triangles;
  }
  WeldIndex index(std::min<uint64_t>(vertexGuess, uint64_t(1) << 32));
  m.triangles.reserve(size_t(std::min<uint64_t>(3 * triangleGuess, uint64_t(1) << 34)));
  m.trianglePatch.reserve(size_t(std::min<uint64_t>(triangleGuess, uint64_t(1) << 32)));
  std::vector<uint32_t> normalUses;
  std::vector<uint32_t> local;
  // Decoded in parallel a batch at a time (so only one batch of decoded patches is held), welded
  // in order so the result does not depend on thread timing. TBB rethrows the first damaged
  // patch's error in this thread.
  constexpr size_t kBatch = 1024;
  std::vector<DecodedPatch> decoded;
  for (size_t first = 0; first < patchIds.size(); first += kBatch) {
    const size_t count = std::min(kBatch, patchIds.size() - first);
    decoded.assign(count, DecodedPatch{});
    tbb::parallel_for(size_t(0), count, [&](size_t i) { decoded[i] = r.readPatch(patchIds[first + i]); });
    for (size_t i = 0; i < count; ++i) {
      DecodedPatch& d = decoded[i];
      const bool hasN = normals && d.normals.size() == d.q.size();
      const bool hasC = colors && d.colors.size() == size_t(d.vertexCount()) * 4;
      local.resize(d.vertexCount());
      for (uint32_t v = 0; v < d.vertexCount(); ++v) {
        GridKey k = {d.q[3 * v], d.q[3 * v + 1], d.q[3 * v + 2]};
        bool inserted;
        const uint32_t w = index.findOrInsert(k, m.vertexCount(), &inserted);
        if (inserted) {
          for (int a = 0; a < 3; ++a) {
            m.q.push_back(k[a]);
            m.positions.push_back(grid.dequantize(a, k[a]));
          }
          if (normals) m.normals.insert(m.normals.end(), 3, 0.f), normalUses.push_back(0);
          if (colors) {
            for (int c = 0; c < 4; ++c) m.colors.push_back(hasC ? d.colors[4 * v + c] : 255);
          }
        }
        if (hasN) {
          for (int a = 0; a < 3; ++a) m.normals[3 * w + a] += d.normals[3 * v + a];
          ++normalUses[w];
        }
        local[v] = w;
      }
      for (uint32_t t = 0; t < d.triangleCount(); ++t) {
        uint32_t a = local[d.triangles[3 * t]], b = local[d.triangles[3 * t + 1]], c = local[d.triangles[3 * t + 2]];
        if (a == b || b == c || a == c) {
          ++m.degenerateTriangles;
          continue;
        }
        m.triangles.insert(m.triangles.end(), {a, b, c});
        m.trianglePatch.push_back(patchIds[first + i]);
      }
      d = DecodedPatch{};  // release as we go
    }
  }
  assert(m.trianglePatch.size() == m.triangleCount() && m.positions.size() == m.q.size());
  assert(m.normals.empty() || m.normals.size() == m.q.size());
  // Shared vertices get the mean of the patches' normals (patches computed them independently).
  for (uint32_t v = 0; v < normalUses.size(); ++v) {
    float* n = &m.normals[3 * v];
    float len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (len > 0)
      for (int a = 0; a < 3; ++a) n[a] /= len;
  }
  return m;
}

}  // namespace mt
