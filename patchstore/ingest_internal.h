// Internal to ingest: what its common part (ingest.cpp, ingest_parse.cpp) and its two paths
// (ingest_resident.cpp, ingest_chunked.cpp) share. The stages and the two paths are described at
// the top of ingest.cpp. Nothing outside patchstore/ingest*.cpp includes this header.
#pragma once

#include <sys/resource.h>

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "base/external_sort.h"
#include "base/interrupt.h"
#include "base/memory_plan.h"
#include "base/process.h"
#include "base/temp_file.h"
#include "patchstore/store_impl.h"

namespace mt {
namespace ingest {

// The vertex record layout in vert.bin, fixed by the input's header.
struct VertexRecordLayout {
  bool doublePrecision, normals, colors;
  bool texcoords = false;  // u, v (float32) and the material (uint32) last: the geometry block's per-vertex form
  size_t size() const { return (doublePrecision ? 24 : 12) + (normals ? 12 : 0) + (colors ? 4 : 0) + (texcoords ? 12 : 0); }
  size_t texcoordOffset() const { return size() - 12; }
  void encode(const InputVertex& v, char* out) const {
    if (doublePrecision) {
      std::memcpy(out, v.p, 24);
      out += 24;
    } else {
      float f[3] = {float(v.p[0]), float(v.p[1]), float(v.p[2])};
      std::memcpy(out, f, 12);
      out += 12;
    }
    if (normals) {
      std::memcpy(out, v.n, 12);
      out += 12;
    }
    if (colors) {
      std::memcpy(out, v.c, 4);
      out += 4;
    }
    if (texcoords) {
      std::memcpy(out, v.uv, 8);
      std::memcpy(out + 8, &v.material, 4);
    }
  }
  void position(const char* rec, double p[3]) const {
    if (doublePrecision) {
      std::memcpy(p, rec, 24);
    } else {
      float f[3];
      std::memcpy(f, rec, 12);
      for (int a = 0; a < 3; ++a) p[a] = f[a];
    }
  }
};

// Where the chunked path reads the vertex records from: scratch/vert.bin, or, for a binary PLY
// whose vertex records are byte for byte what vert.bin would hold (VertexRecordLayout), the input
// itself (no copy of the vertices into fresh page cache).
struct VertexFile {
  std::string path;
  uint64_t offset = 0;  // byte offset of vertex 0
  uint64_t count = 0;
  bool ply = false;  // the input, in place
};

struct Centroid {
  float x, y, z, area;
};

// Centroid and area of a triangle, independent of corner order (corners summed in ascending
// index order), so that duplicate faces always land in the same cell.
inline Centroid centroidOf(const uint32_t v[3], const float* const p[3]) {
  // Three compare-exchanges (corners with equal indices have equal positions, so their order
  // does not show in the sums).
  int order[3] = {0, 1, 2};
  if (v[order[1]] < v[order[0]]) std::swap(order[0], order[1]);
  if (v[order[2]] < v[order[1]]) std::swap(order[1], order[2]);
  if (v[order[1]] < v[order[0]]) std::swap(order[0], order[1]);
  double c[3], e1[3], e2[3];
  for (int a = 0; a < 3; ++a) {
    c[a] = (double(p[order[0]][a]) + double(p[order[1]][a]) + double(p[order[2]][a])) / 3.0;
    e1[a] = double(p[order[1]][a]) - double(p[order[0]][a]);
    e2[a] = double(p[order[2]][a]) - double(p[order[0]][a]);
  }
  double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
  return {float(c[0]), float(c[1]), float(c[2]), float(0.5 * std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]))};
}

// The centroid alone, computed exactly as centroidOf computes it (the Morton and assign passes
// need no area).
inline void centroidPoint(const uint32_t v[3], const float* const p[3], float out[3]) {
  int order[3] = {0, 1, 2};
  if (v[order[1]] < v[order[0]]) std::swap(order[0], order[1]);
  if (v[order[2]] < v[order[1]]) std::swap(order[1], order[2]);
  if (v[order[1]] < v[order[0]]) std::swap(order[0], order[1]);
  for (int a = 0; a < 3; ++a)
    out[a] = float((double(p[order[0]][a]) + double(p[order[1]][a]) + double(p[order[2]][a])) / 3.0);
}

// 21 bits per axis interleaved: the Morton (Z-order) code of a point in the box. Each axis is
// quantized as uint32((c - lo) / extent clamped to [0, 1] * (2^21 - 1)); the division is done as
// a multiplication by the reciprocal (several times cheaper) except when the product lands within
// 1e-7 of an integer, where the two could round to different sides: then it is redone exactly.
// (The two quotients differ by a few ulps, ~1e-9 after scaling, so the codes are the same.)
class MortonBox {
 public:
  explicit MortonBox(const Box3& box) : box_(box) {
    for (int a = 0; a < 3; ++a) {
      extent_[a] = box.hi[a] - box.lo[a];
      inverse_[a] = extent_[a] > 0 ? 1.0 / extent_[a] : 0;
    }
  }
  uint64_t code(const float c[3]) const {
    constexpr double kScale = double((1u << 21) - 1);
    uint32_t q[3];
    for (int a = 0; a < 3; ++a) {
      if (!(extent_[a] > 0)) {
        q[a] = 0;
        continue;
      }
      const double d = double(c[a]) - box_.lo[a];
      const double v = std::clamp(d * inverse_[a], 0.0, 1.0) * kScale;
      const uint32_t fast = uint32_t(v);
      const double frac = v - double(fast);
      q[a] = frac > 1e-7 && frac < 1 - 1e-7 ? fast : uint32_t(std::clamp(d / extent_[a], 0.0, 1.0) * kScale);
    }
    // Bit b of axis a goes to bit 3b + 2 - a (axis 0 most significant of each triple), spread
    // with the usual magic masks instead of a 63-step loop.
    auto spread = [](uint64_t x) {
      x &= 0x1fffff;
      x = (x | x << 32) & 0x1f00000000ffffull;
      x = (x | x << 16) & 0x1f0000ff0000ffull;
      x = (x | x << 8) & 0x100f00f00f00f00full;
      x = (x | x << 4) & 0x10c30c30c30c30c3ull;
      x = (x | x << 2) & 0x1249249249249249ull;
      return x;
    };
    return spread(q[0]) << 2 | spread(q[1]) << 1 | spread(q[2]);
  }

 private:
  Box3 box_;
  double extent_[3], inverse_[3];
};

struct LocalRec {
  uint64_t key;  // vertex << 32 | patch
  uint32_t local;
  uint32_t pad;
};
struct EntryRec {
  uint64_t key;  // patch << 32 | local
  uint32_t neighbour, remote;
};
struct EdgeRec {
  uint64_t key;  // lower vertex << 32 | higher vertex
  uint32_t count, pad;
};
// The boundary stage's sorts are radix sorts by key, stable: (vertex, patch) keys are unique;
// edge uses are summed per key, in any order; a (patch, local) key's entries are added
// together, in ascending neighbour order (stage 7), which a stable sort keeps: the lists come
// out sorted by (local, neighbour, remote).
template <class T>
struct KeyOf {
  uint64_t operator()(const T& r) const { return r.key; }
};
using SharedSorter = StableKeySorter<LocalRec, KeyOf<LocalRec>>;
using EdgeSorter = StableKeySorter<EdgeRec, KeyOf<EdgeRec>>;
using EntrySorter = StableKeySorter<EntryRec, KeyOf<EntryRec>>;

// stages can be compared on a busy machine, where wall time says little (bench/ingest.sh); with
// the resident set at the end of the stage, to see where the cap goes.
class StageClock {
 public:
  explicit StageClock(bool enabled) : enabled_(enabled) { reset(); }
  void mark(const char* stage) {
    checkInterrupt(std::string("ingest: after the ") + stage + " stage");  // the end of every stage is a safe point
    if (!enabled_) return;
    double wall = now(), cpu = cpuSeconds();
    std::fprintf(stderr, "ingest: stage %s: %.2f s wall, %.2f s cpu, rss %.0f MiB (peak %.0f)\n", stage, wall - wall_,
                 cpu - cpu_, double(currentRssBytes()) / double(1 << 20), double(peakRssBytes()) / double(1 << 20));
    wall_ = wall;
    cpu_ = cpu;
  }

 private:
  void reset() {
    wall_ = now();
    cpu_ = cpuSeconds();
  }
  static double now() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }
  static double cpuSeconds() {
    rusage u{};
    getrusage(RUSAGE_SELF, &u);
    return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
  }
  bool enabled_;
  double wall_ = 0, cpu_ = 0;
};

// The vertex records of vert.bin, in RAM (a view: build() owns the bytes).
struct ResidentVertices {
  const char* data = nullptr;
  VertexRecordLayout layout{};
  size_t size = 0;  // record bytes
  const char* record(uint32_t v) const { return data + size_t(v) * size; }
  // The float position every centroid is computed from (as in the chunked path's chunks).
  void position(uint32_t v, float out[3]) const {
    const char* r = record(v);
    if (!layout.doublePrecision) {
      std::memcpy(out, r, 12);
    } else {
      double d[3];
      std::memcpy(d, r, 24);
      for (int a = 0; a < 3; ++a) out[a] = float(d[a]);
    }
  }
  void prefetch(uint32_t v) const { __builtin_prefetch(record(v)); }
  Centroid centroid(const uint32_t v[3]) const {
    float p[9];
    for (int k = 0; k < 3; ++k) position(v[k], p + 3 * k);
    const float* c[3] = {p, p + 3, p + 6};
    return centroidOf(v, c);
  }
  void centroidPoint(const uint32_t v[3], float out[3]) const {
    float p[9];
    for (int k = 0; k < 3; ++k) position(v[k], p + 3 * k);
    const float* c[3] = {p, p + 3, p + 6};
    ingest::centroidPoint(v, c, out);
  }
};

// Where the resident passes read the faces from: face.bin (3 x u32 a face), or, for a binary

// three 32-bit indices), which spares the parse a 12-bytes-a-face copy into fresh page cache (on
// this VM the most expensive part of writing a scratch file). The reader has checked every index
// during the parse; the records are checked again for their count byte.
struct FaceFile {
  std::string path;
  uint64_t offset = 0, count = 0;
  bool ply = false;
  uint64_t vertices = UINT64_MAX;  // in place: indices are checked again against it (the input
                                   // could have changed since the parse)
};

// The face records of a PLY whose layout allows reading them in place: binary little endian,


// Sequential batches of faces (3 indices each) from a FaceFile.
class FaceReader {
 public:
  explicit FaceReader(const FaceFile& file)
      : file_(file), reader_(file.path, 4 << 20, file.offset, file.ply ? file.count * 13 : UINT64_MAX) {}
  bool getBatch(std::vector<uint32_t>& out, size_t maxFaces) {
    if (!file_.ply) return reader_.getBatch(out, 3 * maxFaces);
    raw_.resize(maxFaces * 13);
    const size_t bytes = reader_.read(raw_.data(), raw_.size());
    if (bytes % 13 != 0)
      fail(file_.path, "input ends inside a face record at byte offset " + std::to_string(file_.offset + (done_ + bytes / 13) * 13));
    const size_t n = bytes / 13;
    out.resize(3 * n);
    for (size_t i = 0; i < n; ++i) {
      const char* r = raw_.data() + 13 * i;
      std::memcpy(&out[3 * i], r + 1, 12);
      if (uint8_t(r[0]) != 3 || out[3 * i] >= file_.vertices || out[3 * i + 1] >= file_.vertices || out[3 * i + 2] >= file_.vertices)
        fail(file_.path, "face " + std::to_string(done_ + i) + " at byte offset " + std::to_string(file_.offset + (done_ + i) * 13) +
                             " differs from the parse (the file changed during the ingest?)");
    }
    done_ += n;
    return n > 0;
  }

 private:
  FaceFile file_;
  TempReader reader_;
  std::vector<char> raw_;
  uint64_t done_ = 0;
};


// (Morton code, face): the resident path's Morton sort record. Added in face order to a stable
// sort by code, so ties come out by face: (code, face) order, as the chunked path's MortonFace sort.
struct MortonKey {
  uint32_t lo, hi, face;
  uint64_t code() const { return uint64_t(hi) << 32 | lo; }
};
struct MortonKeyOf {
  uint64_t operator()(const MortonKey& k) const { return k.code(); }
};

constexpr size_t kFaceBatch = 65536;

// The Morton sort of the resident path: (code, face) of every face, added in face order.
class MortonSort {
 public:
  MortonSort(std::string prefix, uint64_t budget) : prefix_(std::move(prefix)), budget_(budget) { reset(); }
  void reset() {
    sorter_ = std::make_unique<StableKeySorter<MortonKey, MortonKeyOf>>(prefix_, budget_, MortonKeyOf{}, 63, true);
    added_ = jumps_ = 0;
    lastTop_ = ~uint64_t(0);
  }
  // Codes of faces [first, first + n) (3 indices each, already computed by the caller or not).
  void add(const MortonKey* keys, size_t n, uint64_t first) {
    if (first != added_) fail(prefix_, "internal: Morton codes out of face order");
    // How often consecutive faces change octree cell 8 levels down: rarely in a scan's face
    // order, almost always in a shuffled one (see coherent()).
    for (size_t i = 0; i < n; ++i) {
      const uint64_t top = keys[i].code() >> 39;
      jumps_ += top != lastTop_;
      lastTop_ = top;
    }
    sorter_->addBatch(keys, n);
    added_ += n;
  }
  static MortonKey codeOf(const ResidentVertices& rv, const MortonBox& box, const uint32_t* v, uint64_t face, const uint32_t* later) {
    // Shuffled vertices read the positions at random: ask for a later face's corners now so
    // that several cache misses are in flight at once.
    if (later)
      for (int k = 0; k < 3; ++k) rv.prefetch(later[k]);
    float c[3];
    rv.centroidPoint(v, c);
    uint64_t code = box.code(c);
    return {uint32_t(code), uint32_t(code >> 32), uint32_t(face)};
  }
  uint64_t added() const { return added_; }
  // Whether the faces come in spatially coherent order (a jump on fewer than a quarter of them).
  bool coherent() const { return jumps_ * 4 <= added_; }
  StableKeySorter<MortonKey, MortonKeyOf>& sorter() { return *sorter_; }

 private:
  std::string prefix_;
  uint64_t budget_;
  std::unique_ptr<StableKeySorter<MortonKey, MortonKeyOf>> sorter_;
  uint64_t added_ = 0, jumps_ = 0, lastTop_ = ~uint64_t(0);
  std::vector<MortonKey> keys_;
};


// ---- what the stages hand to each other ----------------------------------------------------------

// What every stage reads: the scratch folder, the memory plan (every buffer's share of the cap),
// the assigner, and what it fills (the report and the new store's state).
struct IngestContext {
  const std::string& scratch;
  const IngestOptions& options;
  const MemoryPlan& plan;
  bool progress;         // progress lines on stderr
  CellAssigner& assigner;
  IngestReport& report;
  PatchStore::Impl& impl;
  StageClock& clock;
};

// What the parse leaves for the path that follows it.
struct ParsedInput {
  VertexRecordLayout layout{};
  Box3 bounds;
  uint64_t vertices = 0, faces = 0;
  FaceFile faceFile;           // where the passes after the parse read the faces
  VertexFile vertexFile;       // chunked: where the vertex records are
  bool resident = false;       // the vertex records are in `records` (else in scratch/vert.bin)
  std::vector<char> records;   // resident: every vertex record, in vertex order
  std::unique_ptr<MortonSort> morton;  // resident: the Morton sort, filled if the parse could
  std::vector<InputMaterial> materials;  // textured inputs: the materials, images to tile
};

// What the patch stages of both paths hand to the boundary stage.
struct PatchStageOutput {
  std::vector<uint64_t> patchKey;      // patch id -> cell key, ascending
  uint64_t distinctReferenced = 0;     // vertices some face uses
  std::unique_ptr<SharedSorter> shared;  // (vertex, patch) -> local, of vertices held twice or more
  std::unique_ptr<EdgeSorter> edges;     // uses of edges between two shared vertices
};

// After the assign stage of either path (every face has its cell): the assigner's lookups are
// released (CellAssigner::releaseLookups; unless IngestOptions::keepAssignerLookups) and the heap
// trimmed, so the later stages' sorters have that memory. Returns the resident bytes it freed.
uint64_t releaseAssignerLookups(IngestContext& ctx);
// Stage 1 (ingest_parse.cpp): reads the input into scratch (and RAM, when resident).
ParsedInput parseInput(const std::string& input, IngestContext& ctx);
// Stages 2-5 of the resident path (ingest_resident.cpp). Frees the parse's records.
void residentStages(IngestContext& ctx, ParsedInput& in, PatchStageOutput& out);
// Stages 2-6 of the chunked path (ingest_chunked.cpp); Full: the records carry more than float
// positions (double precision, normals or colours).
template <bool Full>
void chunkedStages(IngestContext& ctx, const ParsedInput& in, PatchStageOutput& out);

}  // namespace ingest
}  // namespace mt
