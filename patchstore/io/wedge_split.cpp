// The wedge split: a reader that gives texture coordinates per face corner (OBJ "f v/vt", PLY
// texcoord lists) becomes one that gives them per vertex, by making one vertex per distinct
// (vertex, texture coordinate, material) - a "wedge" - in bounded memory, so every sink (ingest
// first) sees per-vertex attributes only. A seam thus becomes two vertices with one position; the
// store's grid weld joins them again and keeps the seam in per-corner texture coordinates.
//
// Out of core, with two external sorts (base/external_sort.h) and one scratch file:
//   1. the source is read: vertices to pos.bin (in order), every corner (vertex, u, v, material,
//      corner number) into a stable sort by vertex;
//   2. the corners come back by vertex, each vertex's corners in corner order; pos.bin is read
//      alongside. A vertex's distinct (u, v, material), in the order its corners name them, get
//      the next wedge numbers; each wedge goes to the sink as a vertex (so vertices arrive in
//      wedge order, which is input vertex order), and each corner's wedge into a sort by corner.
//      A vertex no corner uses stays, as one wedge without a material (ingest counts it);
//   3. the corners come back in corner order: the triangles, in face order, to the sink.
// Deterministic (stable sorts, first-use order); memory: the sorts' budget and two batches.
#include <unistd.h>

#include <cstdlib>
#include <filesystem>

#include "base/external_sort.h"
#include "base/temp_file.h"
#include "patchstore/io/reader_util.h"

namespace mt::io {
namespace {

struct CornerRec {
  uint32_t vertex;
  uint32_t material;
  float u, v;
  uint64_t corner;
};
struct ByVertex {
  uint64_t operator()(const CornerRec& r) const { return r.vertex; }
};
struct WedgeRec {
  uint64_t corner;
  uint32_t wedge;
  uint32_t pad;
};
struct ByCorner {
  uint64_t operator()(const WedgeRec& r) const { return r.corner; }
};

// Pass 1: what the source gives, into scratch.
class CollectSink final : public MeshSink {
 public:
  CollectSink(TempWriter& pos, StableKeySorter<CornerRec, ByVertex>& corners) : pos_(pos), corners_(corners) {}
  void begin(const MeshHeader& h) override { header = h; }
  void vertices(const InputVertex* v, size_t count, uint64_t) override { pos_.write(v, count * sizeof(InputVertex)); }
  void triangles(const uint32_t* indices, size_t count) override {
    pending_.assign(indices, indices + 3 * count);
  }
  void cornerTexcoords(const float* uv, const uint32_t* materials, size_t count) override {
    if (pending_.size() != 3 * count) throw Error("wedge split: corner batch does not match its triangles");
    batch_.resize(3 * count);
    for (size_t t = 0; t < count; ++t)
      for (int k = 0; k < 3; ++k) {
        const size_t c = 3 * t + size_t(k);
        batch_[c] = {pending_[c], materials[t], uv[2 * c], uv[2 * c + 1], corners + c};
      }
    corners_.addBatch(batch_.data(), batch_.size());
    corners += 3 * count;
    pending_.clear();
  }
  MeshHeader header;
  uint64_t corners = 0;

 private:
  TempWriter& pos_;
  StableKeySorter<CornerRec, ByVertex>& corners_;
  std::vector<uint32_t> pending_;
  std::vector<CornerRec> batch_;
};

class WedgeSplitReader final : public MeshReader {
 public:
  WedgeSplitReader(std::unique_ptr<MeshReader> source, std::string path, MeshOpenOptions options)
      : source_(std::move(source)), path_(std::move(path)), options_(std::move(options)) {
    header_ = source_->header();
    header_.cornerTexcoords = false;
    header_.hasTexcoords = true;
    header_.splitAtSeams = true;
    header_.declaredVertices = -1;  // known once split
  }
  const MeshHeader& header() const override { return header_; }

  ReadStats read(MeshSink& sink) override {
    std::string dir = options_.scratchDir;
    if (dir.empty()) {
      const char* t = std::getenv("TMPDIR");
      dir = t && *t ? t : "/tmp";
    }
    const std::string prefix = dir + "/wedges-" + std::to_string(::getpid()) + "-" + std::to_string(uintptr_t(this));
    struct Cleanup {
      std::string pos;
      ~Cleanup() { std::remove(pos.c_str()); }
    } cleanup{prefix + "-pos.bin"};
    const uint64_t budget = std::max<uint64_t>(16 << 20, options_.memoryBytes / 4);

    // 1. Source into scratch.
    StableKeySorter<CornerRec, ByVertex> byVertex(prefix + "-v", budget, ByVertex{}, 32);
    ReadStats stats;
    uint64_t vertices = 0;
    {
      TempWriter pos(cleanup.pos);
      CollectSink collect(pos, byVertex);
      stats = source_->read(collect);
      pos.close();
      vertices = stats.vertices;
    }
    // 2. Wedges, by vertex.
    sink.begin(header_);
    StableKeySorter<WedgeRec, ByCorner> byCorner(prefix + "-c", budget, ByCorner{}, 64);
    uint64_t wedges = 0;
    {
      byVertex.finish();
      TempReader pos(cleanup.pos);
      std::vector<InputVertex> out;
      out.reserve(kBatch);
      uint64_t emitted = 0;
      auto flush = [&] {
        if (out.empty()) return;
        sink.vertices(out.data(), out.size(), emitted);
        emitted += out.size();
        out.clear();
      };
      auto emit = [&](const InputVertex& v) {
        if (wedges >= kMaxVertices)
          fail(path_, "more vertices than the supported " + std::to_string(kMaxVertices) + " once split at texture seams",
               ErrorKind::Resource);
        out.push_back(v);
        ++wedges;
        if (out.size() == kBatch) flush();
      };
      CornerRec r;
      bool have = byVertex.next(r);
      struct Seen {
        float u, v;
        uint32_t material, wedge;
      };
      std::vector<Seen> seen;
      std::vector<WedgeRec> batch;
      for (uint64_t i = 0; i < vertices; ++i) {
        InputVertex base;
        if (pos.read(&base, sizeof base) != sizeof base) fail(path_, "wedge split: vertex scratch file is short");
        if (!have || r.vertex != i) {
          InputVertex v = base;
          v.uv[0] = v.uv[1] = 0;
          v.material = kNoMaterial;
          emit(v);
          continue;
        }
        seen.clear();
        for (; have && r.vertex == i; have = byVertex.next(r)) {
          uint32_t wedge = UINT32_MAX;
          for (const Seen& s : seen)
            if (s.u == r.u && s.v == r.v && s.material == r.material) wedge = s.wedge;
          if (wedge == UINT32_MAX) {
            wedge = uint32_t(wedges);
            seen.push_back({r.u, r.v, r.material, wedge});
            InputVertex v = base;
            v.uv[0] = r.u;
            v.uv[1] = r.v;
            v.material = r.material;
            emit(v);
          }
          batch.push_back({r.corner, wedge, 0});
          if (batch.size() == kBatch) {
            byCorner.addBatch(batch.data(), batch.size());
            batch.clear();
          }
        }
      }
      if (have) fail(path_, "wedge split: a corner names a vertex past the last one");
      byCorner.addBatch(batch.data(), batch.size());
      flush();
      byVertex.release();
    }
    // 3. Triangles, in corner order.
    {
      byCorner.finish();
      std::vector<uint32_t> tri;
      tri.reserve(3 * kBatch);
      WedgeRec w;
      uint64_t next = 0;
      while (byCorner.next(w)) {
        if (w.corner != next++) fail(path_, "wedge split: corners lost in the sort");
        tri.push_back(w.wedge);
        if (tri.size() == 3 * kBatch) {
          sink.triangles(tri.data(), kBatch);
          tri.clear();
        }
      }
      if (!tri.empty()) sink.triangles(tri.data(), tri.size() / 3);
      if (next != 3 * stats.triangles) fail(path_, "wedge split: corners lost in the sort");
    }
    stats.vertices = wedges;
    sink.end(stats);
    return stats;
  }

 private:
  std::unique_ptr<MeshReader> source_;
  std::string path_;
  MeshOpenOptions options_;
  MeshHeader header_;
};

}  // namespace

std::unique_ptr<MeshReader> splitWedges(std::unique_ptr<MeshReader> source, const std::string& path,
                                        const MeshOpenOptions& options) {
  return std::make_unique<WedgeSplitReader>(std::move(source), path, options);
}

}  // namespace mt::io
