// Ingest: a mesh file of any size into a new patch store, within the --memory cap.
//
// Memory depends on the cap, not on the input (BMT section 6 needs the store to exist before
// anything fits in RAM). Two paths give the same store byte for byte:
//
// Resident path, when the vertex records (one state byte and a bit per thread per vertex, and a
// reserve of max(128 MiB, cap/4)) fit in the cap (a 53 M-triangle scan at 512M): the records stay
// in RAM, so every pass that needs a position reads it directly instead of joining through an
// external sort. Faces are read from face.bin, or in place from a binary PLY of triangles.
//   1 parse      the reader on its own thread: vertex records in RAM, faces to a chunk queue (and
//                face.bin unless read in place); the main thread's pipeline computes the
//                (Morton code, face) of every chunk in parallel into a stable radix sort (12 bytes
//                a face, runs spilled by a background task)
//   2 sample     the merge of the runs, in key ranges on parallel threads, picks every stride-th
//                face (the irregular V-partition's sample, CentroidSource::sample); one more read
//                of the faces gives their centroids. An assigner that wants the whole stream (grid,
//                regular) gets it materialized.
//   3 assign     faces in face order -> centroid -> cell key (a shuffled order: looked up in
//                batch-local Morton order); corners grouped by key (KeyGroupSorter: counting-sorted
//                runs, whole groups merged, faces staying in face order)
//   4 shared     one pass over the groups marks the vertices held by two or more patches
//   5 patches    a second pass builds every patch (local order = ascending input index) with
//                positions read from RAM, in parallel, appended in order; shared vertices ->
//                (vertex, patch, local); edge use counts
// Chunked path, otherwise (bounded by the cap whatever the input size):
//   1 parse      input -> vert.bin (fixed records) + face.bin (3 x u32); bounding box
//   2 centroids  face.bin + vert.bin -> centroid xyz + area per face, straight into an external
//                sort by Morton code (ties: face); vertex positions are loaded in chunks that fit
//                the cap, faces that need a later chunk are carried forward. The merged stream is
//                written once: morton.bin = (face, corners, centroid) in Morton order
//   3 assign     the CellAssigner streams morton.bin as often as it likes (the irregular
//                V-partition once: a sample), then every face is keyed in Morton order (coherent
//                lookups); faces are externally sorted by (cell key, face)
//   4 group      consecutive keys become patches 0..P-1 -> pface.bin; unique (vertex, patch)
//                pairs are externally sorted by vertex
//   5 join       pairs merge-joined with vert.bin -> (patch, vertex, data) sorted by patch
//   6 patches    one geometry block per patch (local order = ascending input index); shared
//                vertices -> (vertex, patch, local) sorted by vertex; edge use counts
// Both paths end with
//   7 boundary   grouped by vertex -> (p, vp, q, vq) sorted by p -> one boundary block per patch
// Determinism: every sort key is total (or the sort is stable over a fixed input order), so the
// store does not depend on the cap, the path or the thread count.
#include <malloc.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>
#include <signal.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cinttypes>
#include <cmath>
#include <condition_variable>
#include <cstring>
#include <deque>
#include <filesystem>
#include <functional>
#include <limits>
#include <mutex>
#include <optional>
#include <thread>
#include <sstream>

#include "base/byte_io.h"
#include "base/external_sort.h"
#include "base/file_lock.h"
#include "base/interrupt.h"
#include "base/output_path.h"
#include "base/process.h"
#include "base/progress.h"
#include "base/temp_file.h"
#include "patchstore/store_impl.h"

namespace mt {

namespace {

namespace fs = std::filesystem;

// The vertex record layout in vert.bin, fixed by the input's header.
struct VertexRecordLayout {
  bool doublePrecision, normals, colors;
  size_t size() const { return (doublePrecision ? 24 : 12) + (normals ? 12 : 0) + (colors ? 4 : 0); }
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
    if (colors) std::memcpy(out, v.c, 4);
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


// Face chunks from the reader thread to the Morton pipeline of the resident path: a fixed pool
// of buffers, handed over in face order. The reader blocks when every buffer is in use, the
// pipeline when none is ready; cancel() (the pipeline failed) makes the reader stop.
class ChunkQueue {
 public:
  explicit ChunkQueue(size_t depth) : pool_(depth) {
    for (auto& b : pool_) free_.push_back(&b);
  }
  // Producer side.
  std::vector<uint32_t>* acquire() {
    std::unique_lock<std::mutex> lock(mutex_);
    cv_.wait(lock, [&] { return cancelled_ || !free_.empty(); });
    if (cancelled_) return nullptr;
    std::vector<uint32_t>* b = free_.back();
    free_.pop_back();
    b->clear();
    return b;
  }
  void push(std::vector<uint32_t>* chunk, uint64_t first) {
    std::lock_guard<std::mutex> lock(mutex_);
    ready_.push_back({chunk, first});
    cv_.notify_all();
  }
  // No more chunks (idempotent). `records` and `bounds` are what the codes are computed from.
  void finish() {
    std::lock_guard<std::mutex> lock(mutex_);
    done_ = true;
    cv_.notify_all();
  }
  void start(const char* records, const Box3& bounds) {
    std::lock_guard<std::mutex> lock(mutex_);
    records_ = records;
    bounds_ = bounds;
  }
  // Consumer side: false once finished and drained.
  bool pop(std::vector<uint32_t>*& chunk, uint64_t& first) {
    std::unique_lock<std::mutex> lock(mutex_);
    cv_.wait(lock, [&] { return done_ || !ready_.empty(); });
    if (ready_.empty()) return false;
    chunk = ready_.front().first;
    first = ready_.front().second;
    ready_.pop_front();
    return true;
  }
  void release(std::vector<uint32_t>* chunk) {
    std::lock_guard<std::mutex> lock(mutex_);
    free_.push_back(chunk);
    cv_.notify_all();
  }
  void cancel() {
    std::lock_guard<std::mutex> lock(mutex_);
    cancelled_ = true;
    cv_.notify_all();
  }
  const char* records() const { return records_; }
  const Box3& bounds() const { return bounds_; }

 private:
  std::vector<std::vector<uint32_t>> pool_;
  std::vector<std::vector<uint32_t>*> free_;
  std::deque<std::pair<std::vector<uint32_t>*, uint64_t>> ready_;
  std::mutex mutex_;
  std::condition_variable cv_;
  bool done_ = false, cancelled_ = false;
  const char* records_ = nullptr;
  Box3 bounds_;
};

// Stage 1 sink: vertex records to vert.bin (or to RAM, for the resident path), faces to
// face.bin; tracks the bounding box.
class ScratchSink : public MeshSink {
 public:
  // Vertex records are kept in RAM when the header declares a count whose records fit in
  // residentLimit bytes (0: never).
  ScratchSink(const std::string& dir, Progress& progress, uint64_t residentLimit)
      : vert_(dir + "/vert.bin", 4 << 20), face_(dir + "/face.bin", 4 << 20), progress_(progress), residentLimit_(residentLimit) {}
  void begin(const MeshHeader& h) override {
    header = h;
    layout = {h.doublePrecision, h.hasNormals, h.hasColors};
    record_.resize(layout.size());
    for (int a = 0; a < 3; ++a) {
      bounds.lo[a] = std::numeric_limits<double>::infinity();
      bounds.hi[a] = -std::numeric_limits<double>::infinity();
    }
    // STL soups are welded through vert.bin first (weldSoup); they may be loaded afterwards.
    const bool soup = h.format == MeshFormat::StlAscii || h.format == MeshFormat::StlBinary;
    if (!soup && h.declaredVertices >= 0 && uint64_t(h.declaredVertices) * layout.size() <= residentLimit_) {
      ram_.reserve(size_t(h.declaredVertices) * layout.size());
      inRam_ = true;
    }
  }
  void vertices(const InputVertex* v, size_t count, uint64_t) override {
    checkInterrupt("ingest: parse");  // a safe point per batch (on the reader's thread, whose errors are rethrown)
    if (fused_) {
      // Vertices after faces: the codes computed so far used a bounding box that is not final.
      // Stop handing over chunks; the Morton sort, left incomplete, is redone after the parse.
      fused_ = false;
      queue_->release(chunk_);
      chunk_ = nullptr;
      queue_->finish();
    }
    if (inRam_ && ram_.size() + count * layout.size() > ram_.capacity()) {
      // More vertices than declared (the reader reports that as an error, but stay bounded).
      vert_.write(ram_.data(), ram_.size());
      std::vector<char>().swap(ram_);
      inRam_ = false;
    }
    // The reader thread is the parse's critical path: one resize a batch, not a record.
    char* out = nullptr;
    if (inRam_) {
      const size_t at = ram_.size();
      ram_.resize(at + count * layout.size());
      out = ram_.data() + at;
    }
    for (size_t i = 0; i < count; ++i) {
      if (out) {
        layout.encode(v[i], out);
        out += layout.size();
      } else {
        layout.encode(v[i], record_.data());
        vert_.write(record_.data(), record_.size());
      }
      for (int a = 0; a < 3; ++a) {
        bounds.lo[a] = std::min(bounds.lo[a], v[i].p[a]);
        bounds.hi[a] = std::max(bounds.hi[a], v[i].p[a]);
      }
    }
    vertexCount += count;
  }
  void triangles(const uint32_t* idx, size_t count) override {
    checkInterrupt("ingest: parse");
    if (writeFaces_) face_.write(idx, count * 12);
    // The first and last faces, to check a face block read in place against (FaceFile).
    for (size_t i = 0; i < count && firstFaces_.size() < 3 * kCheckedFaces; ++i)
      firstFaces_.insert(firstFaces_.end(), idx + 3 * i, idx + 3 * i + 3);
    for (size_t i = count > kCheckedFaces ? count - kCheckedFaces : 0; i < count; ++i) {
      std::memcpy(&lastFaces_[3 * (lastCount_ % kCheckedFaces)], idx + 3 * i, 12);
      ++lastCount_;
    }
    if (queue_ && !fuseDecided_) {
      // Fused only when every declared vertex came first: then the records and the bounding box
      // are final, and the faces' Morton codes can be computed while the parse goes on.
      fuseDecided_ = true;
      fused_ = inRam_ && header.declaredVertices >= 0 && vertexCount == uint64_t(header.declaredVertices);
      if (fused_) {
        queue_->start(ram_.data(), bounds);
        chunk_ = acquire();
      } else {
        queue_->finish();
      }
    }
    if (fused_) {
      for (size_t done = 0; done < count;) {
        size_t take = std::min(count - done, kChunkFaces - chunk_->size() / 3);
        chunk_->insert(chunk_->end(), idx + 3 * done, idx + 3 * (done + take));
        done += take;
        if (chunk_->size() == 3 * kChunkFaces) {
          queue_->push(chunk_, pushed_);
          pushed_ += kChunkFaces;
          chunk_ = acquire();
        }
      }
    }
    faceCount += count;
    progress_.update(faceCount);
  }
  void close() {
    if (fused_ && chunk_ && !chunk_->empty()) {
      queue_->push(chunk_, pushed_);
      pushed_ += chunk_->size() / 3;
      chunk_ = nullptr;
    }
    if (queue_) queue_->finish();
    vert_.close();
    face_.close();
  }
  // Resident inputs: consecutive chunks of faces go to `queue` while the parse goes on (the
  // reader runs on its own thread, the Morton codes are computed on the others).
  void fuse(ChunkQueue* queue) { queue_ = queue; }
  // No face.bin: the faces will be read from the input (FaceFile), if it checks out.
  void skipFaceFile() { writeFaces_ = false; }
  bool wroteFaceFile() const { return writeFaces_; }
  const std::vector<uint32_t>& firstFaces() const { return firstFaces_; }
  // The last faces delivered, oldest first.
  std::vector<uint32_t> lastFaces() const {
    std::vector<uint32_t> out;
    const uint64_t n = std::min<uint64_t>(lastCount_, kCheckedFaces);
    for (uint64_t i = lastCount_ - n; i < lastCount_; ++i)
      out.insert(out.end(), &lastFaces_[3 * (i % kCheckedFaces)], &lastFaces_[3 * (i % kCheckedFaces)] + 3);
    return out;
  }
  bool inRam() const { return inRam_; }
  // The vertex records, in RAM (moved out; inRam() must be true or loadVertices() called).
  std::vector<char> takeVertices() { return std::move(ram_); }
  // Reads vert.bin into RAM (formats that declare no count, welded soups).
  void loadVertices(const std::string& dir) {
    ram_.resize(size_t(vertexCount) * layout.size());
    TempReader r(dir + "/vert.bin", 4 << 20);
    if (r.read(ram_.data(), ram_.size()) != ram_.size()) fail(dir, "vertex scratch file is short");
    inRam_ = true;
  }
  MeshHeader header;
  VertexRecordLayout layout{};
  Box3 bounds;
  uint64_t vertexCount = 0, faceCount = 0;

 private:
  std::vector<uint32_t>* acquire() {
    std::vector<uint32_t>* b = queue_->acquire();
    if (!b) throw Error("ingest cancelled");  // the pipeline failed: its error is reported
    return b;
  }
  static constexpr size_t kChunkFaces = 1 << 17;
  static constexpr size_t kCheckedFaces = 64;
  bool writeFaces_ = true;
  std::vector<uint32_t> firstFaces_, lastFaces_ = std::vector<uint32_t>(3 * kCheckedFaces);
  uint64_t lastCount_ = 0;
  TempWriter vert_, face_;
  Progress& progress_;
  uint64_t residentLimit_;
  std::vector<char> record_, ram_;
  bool inRam_ = false;
  ChunkQueue* queue_ = nullptr;
  bool fuseDecided_ = false, fused_ = false;
  std::vector<uint32_t>* chunk_ = nullptr;
  uint64_t pushed_ = 0;
};

struct Centroid {
  float x, y, z, area;
};

// Centroid and area of a triangle, independent of corner order (corners summed in ascending
// index order), so that duplicate faces always land in the same cell.
Centroid centroidOf(const uint32_t v[3], const float* const p[3]) {
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
void centroidPoint(const uint32_t v[3], const float* const p[3], float out[3]) {
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

// A face with its centroid, keyed by Morton code (ties: face index, so the order is total).
struct MortonFace {
  uint64_t code;
  uint32_t face;
  uint32_t v[3];
  Centroid c;
};
// The chunked path sorts these by code with a stable radix sort (StableKeySorter: a comparison
// sort of the 40-byte records was ~1/4 of the centroid stage on a 200M-triangle scan); faces
// arrive pass by pass, so equal codes come out in pass order and are put back in face order
// as they are read (forEachInMortonOrder), which gives (code, face) order.
struct MortonFaceCode {
  uint64_t operator()(const MortonFace& m) const { return m.code; }
};
using MortonFaceSorter = StableKeySorter<MortonFace, MortonFaceCode>;
// Calls fn(face) for every face of a finished sorter in (code, face) order.
template <class Fn>
void forEachInMortonOrder(MortonFaceSorter& sorter, const Fn& fn) {
  std::vector<MortonFace> ties;  // a run of equal codes
  auto flush = [&] {
    if (ties.size() > 1)
      std::sort(ties.begin(), ties.end(), [](const MortonFace& a, const MortonFace& b) { return a.face < b.face; });
    for (const MortonFace& m : ties) fn(m);
    ties.clear();
  };
  MortonFace m;
  while (sorter.next(m)) {
    if (!ties.empty() && ties.back().code != m.code) flush();
    ties.push_back(m);
  }
  flush();
}
// The record of morton.bin: what the assign stage needs per face, in Morton order.
struct FaceCentroid {
  uint32_t face;
  uint32_t v[3];
  Centroid c;
};

// Stage 2. Chunk c holds the float positions of vertices [c*chunk, (c+1)*chunk). Pass c reads
// the faces again (12 bytes each) and computes every face whose corners all lie in chunk c; a face
// spanning chunks (rare: scans list vertices in scan order) is carried from pass to pass with the
// corners resolved so far, until its last chunk. Every completed face goes straight into the
// Morton sorter (its order is total, so the chunking does not show).
void computeCentroids(const std::string& dir, const VertexRecordLayout& layout, uint64_t vertexCount, uint64_t faceCount,
                      uint64_t budget, const Box3& box, MortonFaceSorter& sorter,
                      bool showProgress) {
  const MortonBox morton(box);
  const uint64_t chunk = std::max<uint64_t>(1 << 16, budget / 12);
  const uint64_t chunks = (vertexCount + chunk - 1) / chunk;
  Progress progress(showProgress, "ingest: centroids", faceCount);
  std::vector<float> pos;
  struct Pending {
    uint32_t face;
    uint32_t v[3];
    float p[9];
    uint32_t resolved;  // bit mask of corners with positions
  };
  uint64_t done = 0;
  TempReader vr(dir + "/vert.bin", 4 << 20);  // chunks are read in order: one sequential pass
  for (uint64_t c = 0; c < chunks; ++c) {
    const uint64_t lo = c * chunk, hi = std::min(vertexCount, lo + chunk);
    pos.resize((hi - lo) * 3);
    {
      std::vector<char> rec(layout.size() * 4096);
      for (uint64_t v = lo; v < hi;) {
        uint64_t n = std::min<uint64_t>(hi - v, 4096);
        if (vr.read(rec.data(), n * layout.size()) != n * layout.size()) fail(dir, "vertex scratch file is short");
        for (uint64_t i = 0; i < n; ++i) {
          double p[3];
          layout.position(rec.data() + i * layout.size(), p);
          for (int a = 0; a < 3; ++a) pos[(v + i - lo) * 3 + a] = float(p[a]);
        }
        v += n;
      }
    }
    std::unique_ptr<TempReader> carryIn;
    std::unique_ptr<TempWriter> carryOut;
    std::string carryInPath = dir + "/carry" + std::to_string(c - 1);
    if (c > 0) carryIn = std::make_unique<TempReader>(carryInPath, 1 << 20);
    if (c + 1 < chunks) carryOut = std::make_unique<TempWriter>(dir + "/carry" + std::to_string(c), 1 << 20);
    auto resolve = [&](Pending& f) {
      for (int k = 0; k < 3; ++k)
        if (!(f.resolved & (1u << k)) && f.v[k] >= lo && f.v[k] < hi) {
          std::memcpy(&f.p[3 * k], &pos[(f.v[k] - lo) * 3], 12);
          f.resolved |= 1u << k;
        }
      if (f.resolved != 7) {
        if (!carryOut) fail(dir, "internal: unresolved face corner");
        carryOut->put(f);
        return;
      }
      const float* p[3] = {&f.p[0], &f.p[3], &f.p[6]};
      MortonFace m{0, f.face, {f.v[0], f.v[1], f.v[2]}, centroidOf(f.v, p)};
      m.code = morton.code(&m.c.x);
      sorter.add(m);
      ++done;
    };
    // One scan of the faces, in face order: faces wholly in this chunk are computed in parallel
    // (centroid and Morton code); faces spanning chunks that touch this one are resolved as far
    // as this chunk allows (new ones start here, earlier ones come from the carry file, which is
    // in face order too).
    TempReader fr(dir + "/face.bin", 4 << 20);
    std::vector<uint32_t> batch;
    std::vector<MortonFace> recs;
    std::vector<uint8_t> kind;  // 0: not this pass, 1: wholly in this chunk, 2: spanning
    uint32_t face = 0;
    while (fr.getBatch(batch, 3 * 65536)) {
      const size_t n = batch.size() / 3;
      recs.resize(n);
      kind.resize(n);
      const uint32_t first = face;
      tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 4096), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t i = r.begin(); i < r.end(); ++i) {
          // Shuffled faces read the positions at random: ask for a later face's corners now so
          // that several cache misses are in flight at once.
          if (i + 16 < r.end())
            for (int k = 0; k < 3; ++k) {
              uint32_t u = batch[3 * (i + 16) + k];
              if (u >= lo && u < hi) __builtin_prefetch(&pos[size_t(u - lo) * 3]);
            }
          const uint32_t* v = &batch[3 * i];
          uint32_t vmin = std::min({v[0], v[1], v[2]}), vmax = std::max({v[0], v[1], v[2]});
          if (vmin >= lo && vmax < hi) {
            kind[i] = 1;
            const float* p[3] = {&pos[size_t(v[0] - lo) * 3], &pos[size_t(v[1] - lo) * 3], &pos[size_t(v[2] - lo) * 3]};
            MortonFace& m = recs[i];
            m.face = first + uint32_t(i);
            std::memcpy(m.v, v, 12);
            m.c = centroidOf(v, p);
            m.code = morton.code(&m.c.x);
          } else {
            kind[i] = (vmin < hi && vmax >= lo) ? 2 : 0;
          }
        }
      });
      for (size_t i = 0; i < n; ++i, ++face) {
        if (kind[i] == 1) {
          sorter.add(recs[i]);
          ++done;
        } else if (kind[i] == 2) {
          Pending f;
          if (std::min({batch[3 * i], batch[3 * i + 1], batch[3 * i + 2]}) >= lo) {
            f = Pending{face, {batch[3 * i], batch[3 * i + 1], batch[3 * i + 2]}, {}, 0};
          } else if (!carryIn || !carryIn->get(f) || f.face != face) {
            fail(dir, "internal: carried face " + std::to_string(face) + " out of order");
          }
          resolve(f);
        }
      }
      progress.update(done);
    }
    if (carryOut) carryOut->close();
    carryIn.reset();
    if (c > 0) std::remove(carryInPath.c_str());
  }
  if (done != faceCount) fail(dir, "internal: " + std::to_string(faceCount - done) + " centroids missing");
  progress.finish(faceCount);
}

// morton.bin as the assigner's centroid stream (Morton order: consecutive centroids are close).
class CentroidFile : public CentroidSource {
 public:
  CentroidFile(std::string path, uint64_t count, Box3 bounds) : path_(std::move(path)), count_(count), bounds_(bounds) {}
  uint64_t count() const override { return count_; }
  Box3 bounds() const override { return bounds_; }
  void forEach(const std::function<void(const float*, size_t)>& fn) const override {
    TempReader r(path_, 4 << 20);
    std::vector<FaceCentroid> batch;
    std::vector<Centroid> cents;
    while (r.getBatch(batch, 65536)) {
      cents.resize(batch.size());
      for (size_t i = 0; i < batch.size(); ++i) cents[i] = batch[i].c;
      fn(&cents[0].x, cents.size());
    }
  }

 private:
  std::string path_;
  uint64_t count_;
  Box3 bounds_;
};

struct FaceRec {
  uint64_t key;
  uint32_t face;
  uint32_t v[3];
};
struct FaceLess {
  bool operator()(const FaceRec& a, const FaceRec& b) const { return a.key != b.key ? a.key < b.key : a.face < b.face; }
};
struct U64Less {
  bool operator()(uint64_t a, uint64_t b) const { return a < b; }
};
// (patch << 32 | vertex) with the vertex's data.
template <bool Full>
struct VertexData;
template <>
struct VertexData<false> {
  uint64_t key;
  uint32_t holders;
  float p[3];
};
template <>
struct VertexData<true> {
  uint64_t key;
  uint32_t holders;
  uint32_t pad;
  double p[3];
  float n[3];
  uint8_t c[4];
};
template <class T>
struct KeyLess {
  bool operator()(const T& a, const T& b) const { return a.key < b.key; }
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

// STL is a triangle soup: three new vertices per triangle. Vertices with bit-identical positions
// are welded (out of core: sort by position, then rewrite the corners in vertex order), so the
// store holds a connected mesh; the duplicates stay in vert.bin, unreferenced. Returns the count
// of vertices merged into an earlier one.
uint64_t weldSoup(const std::string& scratch, const VertexRecordLayout& layout, uint64_t nv, uint64_t budget) {
  struct PosRec {
    double p[3];
    uint32_t vertex, pad;
  };
  struct PosLess {
    bool operator()(const PosRec& a, const PosRec& b) const {
      for (int k = 0; k < 3; ++k)
        if (a.p[k] != b.p[k]) return a.p[k] < b.p[k];
      return a.vertex < b.vertex;
    }
  };
  struct MapRec {
    uint32_t vertex, canonical;
  };
  struct MapLess {
    bool operator()(const MapRec& a, const MapRec& b) const { return a.vertex < b.vertex; }
  };
  ExternalSorter<PosRec, PosLess> byPosition(scratch + "/w1", budget / 2, {}, true);
  {
    TempReader vr(scratch + "/vert.bin", 4 << 20);
    std::vector<char> rec(layout.size());
    for (uint32_t v = 0; v < nv; ++v) {
      if (vr.read(rec.data(), rec.size()) != rec.size()) fail(scratch, "vertex scratch file is short");
      PosRec r{};
      layout.position(rec.data(), r.p);
      for (double& x : r.p) x += 0.0;  // -0.0 welds with +0.0
      r.vertex = v;
      byPosition.add(r);
    }
  }
  checkInterrupt("ingest: sort");
  byPosition.finish();
  ExternalSorter<MapRec, MapLess> byVertex(scratch + "/w2", budget / 2, {}, true);
  uint64_t welded = 0;
  {
    PosRec r, first{};
    bool have = byPosition.next(r);
    while (have) {
      first = r;
      byVertex.add({r.vertex, r.vertex});
      while ((have = byPosition.next(r)) && r.p[0] == first.p[0] && r.p[1] == first.p[1] && r.p[2] == first.p[2]) {
        byVertex.add({r.vertex, first.vertex});
        ++welded;
      }
    }
  }
  checkInterrupt("ingest: sort");
  byVertex.finish();
  TempReader fr(scratch + "/face.bin", 4 << 20);
  TempWriter fw(scratch + "/face.welded", 4 << 20);
  std::vector<uint32_t> batch;
  uint64_t corner = 0;
  MapRec m;
  while (fr.getBatch(batch, 3 * 65536)) {
    for (uint32_t& v : batch) {
      if (v != corner || !byVertex.next(m) || m.vertex != v) fail(scratch, "internal: STL corners are not in vertex order");
      v = m.canonical;
      ++corner;
    }
    fw.write(batch.data(), batch.size() * 4);
  }
  fw.close();
  std::rename((scratch + "/face.welded").c_str(), (scratch + "/face.bin").c_str());
  return welded;
}


// Resident set size now (VmRSS), to size the passes that follow the resident vertex records.
// Per-stage wall and CPU seconds (all threads) on stderr with the progress lines, so that the
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

std::string encodeReport(const IngestReport& r) {
  std::ostringstream s;
  s << "input=" << r.input << "\nformat=" << r.format << "\ninputVertices=" << r.inputVertices
    << "\ninputTriangles=" << r.inputTriangles << "\ninputBytes=" << r.inputBytes << "\npolygons=" << r.polygons
    << "\ndegenerateTriangles=" << r.degenerateTriangles << "\nduplicateTriangles=" << r.duplicateTriangles
    << "\nunreferencedVertices=" << r.unreferencedVertices << "\nnonManifoldEdges=" << r.nonManifoldEdges
    << "\nweldedVertices=" << r.weldedVertices << "\nassigner=" << r.assigner << "\nseconds=" << r.seconds
    << "\npeakBytes=" << r.peakBytes << "\n";
  return s.str();
}


// ---- the resident path -------------------------------------------------------------------------

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
    mt::centroidPoint(v, c, out);
  }
};

// Where the resident passes read the faces from: face.bin (3 x u32 a face), or, for a binary
// little-endian PLY of triangles, the input file itself (13-byte records: a count byte of 3 and
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
// fixed-size records in every element before the faces, and the face element's only property a
// list of uchar (or char) count and int (or uint) indices. {} otherwise.
std::optional<FaceFile> plyTriangleBlock(const std::string& path) {
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return std::nullopt;
  std::string head(1 << 16, '\0');
  head.resize(std::fread(head.data(), 1, head.size(), f));
  std::fclose(f);
  auto typeSize = [](const std::string& t) -> int {
    if (t == "char" || t == "int8" || t == "uchar" || t == "uint8") return 1;
    if (t == "short" || t == "int16" || t == "ushort" || t == "uint16") return 2;
    if (t == "int" || t == "int32" || t == "uint" || t == "uint32" || t == "float" || t == "float32") return 4;
    if (t == "double" || t == "float64") return 8;
    return -1;
  };
  struct Element {
    std::string name;
    uint64_t count = 0, size = 0;
    bool fixed = true, triangleList = false;
    int properties = 0;
  };
  std::vector<Element> elements;
  std::istringstream in(head);
  std::string line;
  size_t consumed = 0, lineNo = 0;
  bool binaryLE = false, ended = false;
  while (std::getline(in, line)) {
    consumed += line.size() + 1;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream words(line);
    std::string w;
    words >> w;
    if (lineNo++ == 0) {
      if (w != "ply") return std::nullopt;
    } else if (w == "format") {
      std::string kind, version;
      words >> kind >> version;
      binaryLE = kind == "binary_little_endian";
    } else if (w == "element") {
      Element e;
      if (!(words >> e.name >> e.count)) return std::nullopt;
      elements.push_back(e);
    } else if (w == "property") {
      if (elements.empty()) return std::nullopt;
      Element& e = elements.back();
      std::string type, countType, itemType, name;
      words >> type;
      ++e.properties;
      if (type == "list") {
        words >> countType >> itemType >> name;
        e.fixed = false;
        e.triangleList = typeSize(countType) == 1 &&
                         (itemType == "int" || itemType == "int32" || itemType == "uint" || itemType == "uint32") &&
                         (name == "vertex_indices" || name == "vertex_index");
      } else {
        int size = typeSize(type);
        if (size < 0) return std::nullopt;
        e.size += uint64_t(size);
      }
    } else if (w == "end_header") {
      ended = true;
      break;
    } else if (w != "comment" && w != "obj_info" && !w.empty()) {
      return std::nullopt;
    }
  }
  if (!binaryLE || !ended || consumed > head.size()) return std::nullopt;
  uint64_t offset = consumed;
  for (const Element& e : elements) {
    if (e.name == "face") {
      if (e.properties != 1 || !e.triangleList) return std::nullopt;
      return FaceFile{path, offset, e.count, true};
    }
    if (!e.fixed) return std::nullopt;
    offset += e.count * e.size;
  }
  return std::nullopt;
}

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

// Faces in batches, in face order, through a TBB pipeline: the batch is read on one thread,
// work(batch) runs on any thread (batches in parallel), consume(batch) runs in face order.
template <class Out>
struct FaceBatch {
  uint64_t first = 0;  // index of the batch's first face
  std::vector<uint32_t> idx;  // 3 per face
  Out out;
  size_t count() const { return idx.size() / 3; }
};
template <class Out, class Work, class Consume>
void pipelineFaces(const FaceFile& faces, size_t batchFaces, const Work& work, const Consume& consume) {
  FaceReader fr(faces);
  const size_t tokens = size_t(std::max(2, tbb::this_task_arena::max_concurrency())) + 2;
  std::vector<std::unique_ptr<FaceBatch<Out>>> pool;
  std::vector<FaceBatch<Out>*> idle;
  std::mutex idleMutex;
  for (size_t i = 0; i < tokens; ++i) {
    pool.push_back(std::make_unique<FaceBatch<Out>>());
    idle.push_back(pool.back().get());
  }
  uint64_t next = 0;
  tbb::parallel_pipeline(
      tokens,
      tbb::make_filter<void, FaceBatch<Out>*>(tbb::filter_mode::serial_in_order,
                                              [&](tbb::flow_control& fc) -> FaceBatch<Out>* {
                                                FaceBatch<Out>* b;
                                                {
                                                  std::lock_guard<std::mutex> lock(idleMutex);
                                                  b = idle.back();
                                                  idle.pop_back();
                                                }
                                                if (!fr.getBatch(b->idx, batchFaces)) {
                                                  std::lock_guard<std::mutex> lock(idleMutex);
                                                  idle.push_back(b);
                                                  fc.stop();
                                                  return nullptr;
                                                }
                                                b->first = next;
                                                next += b->count();
                                                return b;
                                              }) &
          tbb::make_filter<FaceBatch<Out>*, FaceBatch<Out>*>(tbb::filter_mode::parallel,
                                                             [&](FaceBatch<Out>* b) {
                                                               work(*b);
                                                               return b;
                                                             }) &
          tbb::make_filter<FaceBatch<Out>*, void>(tbb::filter_mode::serial_in_order, [&](FaceBatch<Out>* b) {
            consume(*b);
            std::lock_guard<std::mutex> lock(idleMutex);
            idle.push_back(b);
          }));
}

// (Morton code, face): the resident path's Morton sort record. Added in face order to a stable
// sort by code, so ties come out by face: (code, face) order, as the chunked path's MortonFace sort.
struct MortonKey {
  uint32_t lo, hi, face;
  uint64_t code() const { return uint64_t(hi) << 32 | lo; }
};
struct MortonKeyOf {
  uint64_t operator()(const MortonKey& k) const { return k.code(); }
};
// A centroid keyed by Morton code, for an assigner that streams every centroid.
struct MortonCentroid {
  uint32_t lo, hi;
  Centroid c;
};
struct MortonCentroidOf {
  uint64_t operator()(const MortonCentroid& k) const { return uint64_t(k.hi) << 32 | k.lo; }
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

// The resident path's centroid stream, in Morton order (ties: face) like morton.bin, produced on
// demand: sample() sorts 12-byte (code, face) records only and computes the few centroids it
// returns; forEach() (grid and regular assigners) materializes the whole stream once.
class ResidentCentroids : public CentroidSource {
 public:
  ResidentCentroids(const std::string& scratch, const FaceFile& faceFile, const ResidentVertices& vertices, uint64_t faces,
                    Box3 bounds, MortonSort& morton, uint64_t budget, StageClock& clock, bool progress)
      : scratch_(scratch), faceFile_(faceFile), vertices_(vertices), faces_(faces), bounds_(bounds), morton_(morton),
        budget_(budget), clock_(clock), progress_(progress) {}
  uint64_t count() const override { return faces_; }
  Box3 bounds() const override { return bounds_; }
  // Whether the input's face order is spatially coherent (MortonSort::coherent), as measured by
  // the Morton pass (assumed when no pass ran).
  bool coherent() const { return coherent_ ? *coherent_ : morton_.added() == faces_ ? morton_.coherent() : true; }

  std::vector<float> sample(uint64_t stride) const override {
    if (materialized_) return CentroidSource::sample(stride);
    stride = std::max<uint64_t>(1, stride);
    // Morton codes of all faces, in face order, into a stable radix sort (runs on disk); done
    // during the parse already when the input allowed it (ScratchSink).
    if (morton_.added() != faces_) {
      morton_.reset();
      const MortonBox box(bounds_);
      Progress progress(progress_, "ingest: morton", faces_);
      struct Codes {
        std::vector<MortonKey> keys;
      };
      pipelineFaces<Codes>(
          faceFile_, kFaceBatch,
          [&](FaceBatch<Codes>& b) {
            const size_t n = b.count();
            b.out.keys.resize(n);
            for (size_t i = 0; i < n; ++i)
              b.out.keys[i] = MortonSort::codeOf(vertices_, box, &b.idx[3 * i], b.first + i, i + 16 < n ? &b.idx[3 * (i + 16)] : nullptr);
          },
          [&](FaceBatch<Codes>& b) {
            morton_.add(b.out.keys.data(), b.out.keys.size(), b.first);
            progress.update(b.first + b.count());
          });
      progress.finish(faces_);
    }
    StableKeySorter<MortonKey, MortonKeyOf>& sorter = morton_.sorter();
    checkInterrupt("ingest: sort");
    sorter.finish();
    clock_.mark("morton");
    // Ranks 0, stride, 2 stride, ... of the merged order; then their centroids, in one more
    // sequential read of the faces.
    // The merge runs in key ranges on parallel threads, each knowing the rank it starts at.
    std::vector<std::pair<uint32_t, uint32_t>> picks;  // (face, rank / stride)
    {
      const size_t parts = size_t(std::max(1, tbb::this_task_arena::max_concurrency()));
      std::vector<std::vector<std::pair<uint32_t, uint32_t>>> partPicks(parts);
      std::vector<uint64_t> partCount(parts, 0);
      sorter.mergeInParts(parts, [&](size_t part, uint64_t rank, const auto& next) {
        MortonKey k;
        uint64_t n = 0;
        for (; next(k); ++rank, ++n)
          if (rank % stride == 0) partPicks[part].push_back({k.face, uint32_t(rank / stride)});
        partCount[part] = n;
      });
      uint64_t total = 0;
      for (size_t p = 0; p < parts; ++p) {
        total += partCount[p];
        picks.insert(picks.end(), partPicks[p].begin(), partPicks[p].end());
      }
      if (total != faces_) fail(scratch_, "internal: Morton sort holds " + std::to_string(total) + " faces");
      coherent_ = morton_.coherent();
      morton_.reset();  // consumed: another sample() would sort again
    }
    std::vector<float> out(4 * picks.size());
    std::sort(picks.begin(), picks.end());
    FaceReader fr(faceFile_);
    std::vector<uint32_t> batch;
    uint64_t first = 0;
    size_t p = 0;
    while (p < picks.size() && fr.getBatch(batch, kFaceBatch)) {
      const uint64_t end = first + batch.size() / 3;
      for (; p < picks.size() && picks[p].first < end; ++p) {
        Centroid c = vertices_.centroid(&batch[3 * (picks[p].first - first)]);
        std::memcpy(&out[4 * size_t(picks[p].second)], &c, 16);
      }
      first = end;
    }
    if (p != picks.size()) fail(scratch_, "internal: sampled face past the end of the face file");
    clock_.mark("sample");
    return out;
  }

  void forEach(const std::function<void(const float*, size_t)>& fn) const override {
    if (!materialized_) materialize();
    TempReader r(scratch_ + "/morton.bin", 4 << 20);
    std::vector<Centroid> batch;
    while (r.getBatch(batch, kFaceBatch)) fn(&batch[0].x, batch.size());
  }

 private:
  void materialize() const {
    const MortonBox box(bounds_);
    StableKeySorter<MortonCentroid, MortonCentroidOf> sorter(scratch_ + "/m1", budget_, MortonCentroidOf{}, 63);
    struct Cents {
      std::vector<MortonCentroid> recs;
    };
    pipelineFaces<Cents>(
        faceFile_, kFaceBatch,
        [&](FaceBatch<Cents>& b) {
          const size_t n = b.count();
          b.out.recs.resize(n);
          for (size_t i = 0; i < n; ++i) {
            Centroid c = vertices_.centroid(&b.idx[3 * i]);
            uint64_t code = box.code(&c.x);
            b.out.recs[i] = {uint32_t(code), uint32_t(code >> 32), c};
          }
        },
        [&](FaceBatch<Cents>& b) { sorter.addBatch(b.out.recs.data(), b.out.recs.size()); });
    checkInterrupt("ingest: sort");
    sorter.finish();
    TempWriter out(scratch_ + "/morton.bin", 4 << 20);
    MortonCentroid m;
    while (sorter.next(m)) out.put(m.c);
    out.close();
    materialized_ = true;
  }

  std::string scratch_;
  FaceFile faceFile_;
  const ResidentVertices& vertices_;
  uint64_t faces_;
  Box3 bounds_;
  MortonSort& morton_;
  uint64_t budget_;
  StageClock& clock_;
  bool progress_;
  mutable bool materialized_ = false;
  mutable std::optional<bool> coherent_;
};

// What the patch stage keeps of a face: its corners. Faces are added in face order, and the
// group sorter keeps the order of addition within a key (runs in order, stable counting sort,
// runs merged lowest first), so a patch's faces come out in face order with no index stored.
struct FaceCorners {
  uint32_t v[3];
};
struct AdditionOrder {
  bool operator()(const FaceCorners&, const FaceCorners&) const { return false; }
};

// Vertex state for the resident patch stage: bit 0 = held by a patch, bit 1 = by two or more.
constexpr uint8_t kHeld = 1, kShared = 2;

uint32_t bitsFor(uint64_t maxValue) {
  uint32_t b = 1;
  while (b < 64 && (maxValue >> b) != 0) ++b;
  return b;
}

// One patch of the resident path, built on a worker thread; the ordered stage appends it.
struct ResidentPatch {
  uint32_t id = 0;
  uint64_t key = 0;
  std::vector<FaceCorners> faces;
  std::string payload;
  Box3 bounds;
  uint32_t vertices = 0, triangles = 0;
  std::vector<std::pair<uint32_t, uint32_t>> shared;  // (global vertex, local)
  std::vector<std::pair<uint64_t, uint32_t>> crossEdges;  // (lower global << 32 | higher, uses)
  uint64_t duplicates = 0, nonManifold = 0;
};

// Per-thread scratch of buildResidentPatch, kept across patches.
struct PatchScratch {
  std::vector<uint64_t> a, b, set;
  std::vector<uint32_t> globals, local, firstCorner, nb;
  std::vector<uint8_t> shared;  // per local vertex: held by another patch too
};

// The geometry block of one patch (store_format.h), byte for byte what encodeGeometry writes for
// the chunked path's Patch: local vertex order is ascending input index; triangles keep their
// face order and corner order. Also the per-patch defect counts and the boundary inputs.
void buildResidentPatch(ResidentPatch& w, const ResidentVertices& rv, const uint8_t* state, PatchScratch& s) {
  const size_t nt = w.faces.size(), nc = 3 * nt;
  // 1. Corners sorted by vertex (radix, on the patch's index range): the distinct vertices in
  //    ascending order are the local order, and every corner gets its local index.
  uint32_t vmin = UINT32_MAX, vmax = 0;
  for (const FaceCorners& f : w.faces)
    for (uint32_t v : f.v) {
      vmin = std::min(vmin, v);
      vmax = std::max(vmax, v);
    }
  s.a.resize(nc);
  s.b.resize(nc);
  for (size_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) s.a[3 * t + k] = uint64_t(w.faces[t].v[k] - vmin) << 32 | (3 * t + k);
  const uint64_t* sorted = radixSort(s.a.data(), s.b.data(), nc, [](uint64_t x) { return x >> 32; }, bitsFor(vmax - vmin));
  s.globals.clear();
  s.firstCorner.clear();
  s.local.resize(nc);
  for (size_t i = 0; i < nc; ++i) {
    uint32_t v = uint32_t(sorted[i] >> 32) + vmin;
    if (s.globals.empty() || s.globals.back() != v) {
      s.globals.push_back(v);
      s.firstCorner.push_back(uint32_t(i));
    }
    s.local[uint32_t(sorted[i])] = uint32_t(s.globals.size() - 1);
  }
  const uint32_t nv = uint32_t(s.globals.size());
  s.firstCorner.push_back(uint32_t(nc));
  w.vertices = nv;
  w.triangles = uint32_t(nt);

  // 2. The payload: header, positions, normals, colours, triangles.
  const VertexRecordLayout& L = rv.layout;
  const size_t posBytes = L.doublePrecision ? 24 : 12;
  const size_t bytes = sizeof(store_format::GeometryHeader) + nv * (posBytes + (L.normals ? 12 : 0) + (L.colors ? 4 : 0)) + nc * 4;
  w.payload.resize(bytes);
  char* out = w.payload.data();
  store_format::GeometryHeader h{nv, uint32_t(nt), (L.doublePrecision ? store_format::kGeomDouble : 0u) |
                                                       (L.normals ? store_format::kGeomNormals : 0u) |
                                                       (L.colors ? store_format::kGeomColors : 0u),
                                 0};
  std::memcpy(out, &h, sizeof h);
  out += sizeof h;
  for (int a = 0; a < 3; ++a) {
    w.bounds.lo[a] = std::numeric_limits<double>::infinity();
    w.bounds.hi[a] = -std::numeric_limits<double>::infinity();
  }
  s.shared.resize(nv);
  for (uint32_t l = 0; l < nv; ++l) {
    // The records are scattered over RAM: ask for a later one now (several misses in flight).
    if (l + 8 < nv) {
      rv.prefetch(s.globals[l + 8]);
      __builtin_prefetch(state + s.globals[l + 8]);
    }
    s.shared[l] = state[s.globals[l]] & kShared;
    const char* r = rv.record(s.globals[l]);
    std::memcpy(out, r, posBytes);
    out += posBytes;
    double p[3];
    L.position(r, p);
    for (int a = 0; a < 3; ++a) {
      w.bounds.lo[a] = std::min(w.bounds.lo[a], p[a]);
      w.bounds.hi[a] = std::max(w.bounds.hi[a], p[a]);
    }
  }
  if (L.normals)
    for (uint32_t l = 0; l < nv; ++l) {
      std::memcpy(out, rv.record(s.globals[l]) + posBytes, 12);
      out += 12;
    }
  if (L.colors)
    for (uint32_t l = 0; l < nv; ++l) {
      std::memcpy(out, rv.record(s.globals[l]) + posBytes + (L.normals ? 12 : 0), 4);
      out += 4;
    }
  std::memcpy(out, s.local.data(), nc * 4);

  // 3. Duplicate faces (same vertex set): sorted local triples packed into one integer, counted
  //    through an open-addressing set (each repeat of a triple counts once).
  const uint32_t lb = bitsFor(std::max<uint32_t>(1, nv - 1));
  const uint32_t* tri = s.local.data();
  w.duplicates = 0;
  w.nonManifold = 0;
  w.crossEdges.clear();
  if (3 * lb <= 63) {
    size_t cap = 16;
    while (cap < 2 * nt) cap <<= 1;
    s.set.assign(cap, 0);
    for (size_t t = 0; t < nt; ++t) {
      uint32_t x = tri[3 * t], y = tri[3 * t + 1], z = tri[3 * t + 2];
      if (x > y) std::swap(x, y);
      if (y > z) std::swap(y, z);
      if (x > y) std::swap(x, y);
      const uint64_t key = (uint64_t(1) << 63) | (uint64_t(x) << (2 * lb)) | (uint64_t(y) << lb) | z;
      size_t h = size_t((key * 0x9E3779B97F4A7C15ull) >> 32) & (cap - 1);
      while (s.set[h] != 0 && s.set[h] != key) h = (h + 1) & (cap - 1);
      if (s.set[h] == key)
        ++w.duplicates;
      else
        s.set[h] = key;
    }
  } else {
    std::vector<std::array<uint32_t, 3>> sortedTris(nt);
    for (size_t t = 0; t < nt; ++t) {
      sortedTris[t] = {tri[3 * t], tri[3 * t + 1], tri[3 * t + 2]};
      std::sort(sortedTris[t].begin(), sortedTris[t].end());
    }
    std::sort(sortedTris.begin(), sortedTris.end());
    for (size_t t = 1; t < nt; ++t) w.duplicates += sortedTris[t] == sortedTris[t - 1];
  }
  // 4. Edge use counts, from the corners of each vertex a (sorted above): a proper triangle at a
  //    holds each of its two other corners once, so the uses of edge (a, b), b > a, are how often
  //    b shows up among them. Degenerate triangles have no proper edges.
  for (uint32_t a = 0; a < nv; ++a) {
    s.nb.clear();
    for (uint32_t i = s.firstCorner[a]; i < s.firstCorner[a + 1]; ++i) {
      const uint32_t c = uint32_t(sorted[i]), t = c / 3, k = c % 3;
      const uint32_t* f = tri + 3 * t;
      if (f[0] == f[1] || f[1] == f[2] || f[0] == f[2]) continue;
      const uint32_t b1 = f[(k + 1) % 3], b2 = f[(k + 2) % 3];
      if (b1 > a) s.nb.push_back(b1);
      if (b2 > a) s.nb.push_back(b2);
    }
    // Insertion sort: a vertex has a handful of neighbours (shift, not swap: a swap's two stores
    // stall the next step's wider load).
    uint32_t* nb = s.nb.data();
    for (size_t i = 1; i < s.nb.size(); ++i) {
      const uint32_t x = nb[i];
      size_t j = i;
      for (; j > 0 && nb[j - 1] > x; --j) nb[j] = nb[j - 1];
      nb[j] = x;
    }
    for (size_t i = 0, n = s.nb.size(); i < n;) {
      size_t j = i;
      while (j < n && s.nb[j] == s.nb[i]) ++j;
      const uint32_t b = s.nb[i];
      if (s.shared[a] && s.shared[b])
        w.crossEdges.push_back({uint64_t(s.globals[a]) << 32 | s.globals[b], uint32_t(j - i)});
      else if (j - i > 2)
        ++w.nonManifold;
      i = j;
    }
  }
  w.shared.clear();
  for (uint32_t l = 0; l < nv; ++l)
    if (s.shared[l]) w.shared.push_back({s.globals[l], l});
}

// What the patch stages of both paths hand to the boundary stage.
struct PatchStageOutput {
  std::vector<uint64_t> patchKey;
};

// Resident path, stages 2-5 (see the top of the file): the patch geometry blocks are appended to
// impl, shared vertices and cross-patch edges fed to the two sorters of the boundary stage.
void residentStages(const std::string& scratch, const FaceFile& faceFile, const ResidentVertices& rv,
                    std::vector<char>& records, MortonSort& morton, const Box3& bounds, uint64_t nv, uint64_t nf,
                    uint64_t B, CellAssigner& assigner, IngestReport& report, PatchStore::Impl& impl,
                    std::unique_ptr<SharedSorter>& sharedPtr, std::unique_ptr<EdgeSorter>& edgesPtr,
                    PatchStageOutput& out, uint64_t& distinctReferenced, StageClock& clock, bool showProgress) {
  // Room left for the passes: the cap minus what is resident now (records, code, the assigner
  // later), with a margin for what the passes allocate besides their sort buffers.
  auto room = [&](uint64_t margin) {
    uint64_t rss = currentRssBytes();
    uint64_t left = B > rss + margin ? B - rss - margin : 0;
    return std::max<uint64_t>(8 << 20, left);
  };
  bool coherent = true;
  {
    ResidentCentroids centroids(scratch, faceFile, rv, nf, bounds, morton, room(32 << 20) * 4 / 5, clock, showProgress);
    Progress progress(showProgress, "ingest: partition", nf);
    assigner.prepare(centroids, B / 2);
    progress.finish(nf);
    coherent = centroids.coherent();
    std::remove((scratch + "/morton.bin").c_str());
  }
  report.assigner = assigner.describe();
  malloc_trim(0);
  clock.mark("partition");

  // 3 assign: every face keyed in face order, grouped by key. Lookups are cheap in a coherent
  // order (consecutive faces hit the same seeds, BMT's scans list faces so); a shuffled input's
  // batches are looked up in Morton order instead, in bigger batches (which makes runs of the
  // same query cells), and the keys put back in face order.
  const size_t batchFaces = coherent ? kFaceBatch : 4 * kFaceBatch;
  const uint64_t batchBytes = coherent ? 0 : (size_t(std::max(2, tbb::this_task_arena::max_concurrency())) + 2) * batchFaces * 56;
  KeyGroupSorter<FaceCorners, AdditionOrder> groups(scratch + "/g", room((48 << 20) + batchBytes) * 4 / 5, AdditionOrder{}, true);
  {
    Progress progress(showProgress, "ingest: assign", nf);
    struct Keyed {
      std::vector<uint64_t> keys;
      std::vector<FaceCorners> recs;
      std::vector<float> centroids;
      std::vector<uint64_t> order, tmp;
    };
    const MortonBox box(bounds);
    pipelineFaces<Keyed>(
        faceFile, batchFaces,
        [&](FaceBatch<Keyed>& b) {
          const size_t n = b.count();
          b.out.keys.resize(n);
          b.out.recs.resize(n);
          if (coherent) {
            for (size_t i = 0; i < n; ++i) {
              if (i + 16 < n)
                for (int k = 0; k < 3; ++k) rv.prefetch(b.idx[3 * (i + 16) + k]);
              const uint32_t* v = &b.idx[3 * i];
              float c[3];
              rv.centroidPoint(v, c);
              b.out.keys[i] = assigner.cellKey(c);
              b.out.recs[i] = {{v[0], v[1], v[2]}};
            }
            return;
          }
          b.out.centroids.resize(3 * n);
          b.out.order.resize(n);
          b.out.tmp.resize(n);
          for (size_t i = 0; i < n; ++i) {
            if (i + 16 < n)
              for (int k = 0; k < 3; ++k) rv.prefetch(b.idx[3 * (i + 16) + k]);
            const uint32_t* v = &b.idx[3 * i];
            float* c = &b.out.centroids[3 * i];
            rv.centroidPoint(v, c);
            b.out.order[i] = (box.code(c) >> 20) << 20 | i;  // batch index below bit 20
            b.out.recs[i] = {{v[0], v[1], v[2]}};
          }
          const uint64_t* order = radixSort(b.out.order.data(), b.out.tmp.data(), n, [](uint64_t x) { return x; }, 63);
          for (size_t j = 0; j < n; ++j) {
            const size_t i = size_t(order[j] & ((1u << 20) - 1));
            b.out.keys[i] = assigner.cellKey(&b.out.centroids[3 * i]);
          }
        },
        [&](FaceBatch<Keyed>& b) {
          groups.addBatch(b.out.keys.data(), b.out.recs.data(), b.count());
          progress.update(b.first + b.count());
        });
    if (groups.count() != nf) fail(scratch, "internal: face file holds " + std::to_string(groups.count()) + " faces");
    checkInterrupt("ingest: sort");
    groups.finish();
    progress.finish(nf);
  }
  std::remove((scratch + "/face.bin").c_str());
  malloc_trim(0);
  clock.mark("assign");

  // A pipeline over the groups (patches in key order): gather a batch on one thread, work on
  // the patches of the batch on any thread, finish the batches in order.
  struct Batch {
    uint32_t first = 0;
    std::vector<ResidentPatch> patches;
  };
  auto pipelineGroups = [&](const auto& work, const auto& finish) {
    constexpr size_t kPatches = 32;
    const size_t tokens = size_t(std::max(2, tbb::this_task_arena::max_concurrency())) + 2;
    uint32_t nextId = 0;
    bool more = true;
    tbb::parallel_pipeline(
        tokens,
        tbb::make_filter<void, Batch*>(tbb::filter_mode::serial_in_order,
                                       [&](tbb::flow_control& fc) -> Batch* {
                                         auto b = std::make_unique<Batch>();
                                         b->first = nextId;
                                         b->patches.resize(kPatches);
                                         size_t n = 0;
                                         while (n < kPatches && more) {
                                           ResidentPatch& p = b->patches[n];
                                           more = groups.nextGroup(p.key, p.faces);
                                           if (more) p.id = nextId++, ++n;
                                         }
                                         b->patches.resize(n);
                                         if (n == 0) {
                                           fc.stop();
                                           return nullptr;
                                         }
                                         return b.release();
                                       }) &
            tbb::make_filter<Batch*, Batch*>(tbb::filter_mode::parallel,
                                             [&](Batch* b) {
                                               for (ResidentPatch& p : b->patches) work(p);
                                               return b;
                                             }) &
            tbb::make_filter<Batch*, void>(tbb::filter_mode::serial_in_order, [&](Batch* b) {
              std::unique_ptr<Batch> owned(b);
              for (ResidentPatch& p : b->patches) finish(p);
            }));
  };

  // 4 shared vertices: one pass over the patches marks every vertex held (bit 0) and held by a
  // second patch (bit 1). A patch's distinct vertices come from a per-thread bit set of the
  // vertices it touched, cleared again through the list of them.
  std::vector<uint8_t> state(nv, 0);
  {
    Progress progress(showProgress, "ingest: shared", nf);
    tbb::enumerable_thread_specific<std::pair<std::vector<uint64_t>, std::vector<uint32_t>>> marks;
    std::atomic<uint64_t> held{0};
    uint64_t facesDone = 0;
    pipelineGroups(
        [&](ResidentPatch& p) {
          auto& [bits, touched] = marks.local();
          if (bits.empty()) bits.assign((nv + 63) / 64, 0);
          touched.clear();
          for (const FaceCorners& f : p.faces)
            for (uint32_t v : f.v) {
              const uint64_t bit = uint64_t(1) << (v & 63);
              if (!(bits[v >> 6] & bit)) {
                bits[v >> 6] |= bit;
                touched.push_back(v);
              }
            }
          uint64_t first = 0;
          for (uint32_t v : touched) {
            bits[v >> 6] &= ~(uint64_t(1) << (v & 63));
            uint8_t old = __atomic_fetch_or(&state[v], kHeld, __ATOMIC_RELAXED);
            if (old & kHeld)
              __atomic_fetch_or(&state[v], kShared, __ATOMIC_RELAXED);
            else
              ++first;
          }
          held += first;
          p.triangles = uint32_t(p.faces.size());
          std::vector<FaceCorners>().swap(p.faces);
        },
        [&](ResidentPatch& p) {
          out.patchKey.push_back(p.key);
          facesDone += p.triangles;
          progress.update(facesDone);
        });
    distinctReferenced = held.load();
    progress.finish(nf);
  }
  malloc_trim(0);
  clock.mark("shared");

  // 5 patches: built in parallel, appended in patch order. The boundary stage's sorters fill
  // while the records are resident: their share is what is left now (they spill early, which
  // costs little: a few million records; in the background, off the ordered stage).
  {
    const uint64_t left = room(48 << 20);
    sharedPtr = std::make_unique<SharedSorter>(scratch + "/s4", left / 3, KeyOf<LocalRec>{}, 64, true);
    edgesPtr = std::make_unique<EdgeSorter>(scratch + "/s5", left / 6, KeyOf<EdgeRec>{}, 64, true);
  }
  SharedSorter& shared = *sharedPtr;
  EdgeSorter& edges = *edgesPtr;
  {
    Progress progress(showProgress, "ingest: patches", nf);
    groups.rewind();
    tbb::enumerable_thread_specific<PatchScratch> scratchSpace;
    uint64_t facesDone = 0;
    pipelineGroups([&](ResidentPatch& p) { buildResidentPatch(p, rv, state.data(), scratchSpace.local()); },
                   [&](ResidentPatch& p) {
                     if (p.id >= out.patchKey.size() || out.patchKey[p.id] != p.key) fail(scratch, "internal: patch order changed between passes");
                     report.duplicateTriangles += p.duplicates;
                     report.nonManifoldEdges += p.nonManifold;
                     for (auto& [key, uses] : p.crossEdges) edges.add({key, uses, 0});
                     for (auto& [v, l] : p.shared) shared.add({uint64_t(v) << 32 | p.id, l, 0});
                     PatchRecord rec;
                     rec.meta = {p.id, p.key, 0, p.vertices, p.triangles, 0, p.bounds};
                     rec.geometry = impl.appendBlock(p.payload);
                     impl.patches[p.id] = rec;
                     facesDone += p.triangles;
                     progress.update(facesDone);
                   });
    if (facesDone != nf) fail(scratch, "internal: patches hold " + std::to_string(facesDone) + " faces");
    progress.finish(nf);
  }
  groups.release();
  std::vector<uint8_t>().swap(state);
  std::vector<char>().swap(records);
  malloc_trim(0);
  clock.mark("patches");
}

// The main ingest body, building the store in `dir` (already created, empty).
template <bool Full>
IngestReport build(const std::string& input, const std::string& dir, const std::string& scratch, CellAssigner& assigner,
                   const IngestOptions& opt, Env* env) {
  using Clock = std::chrono::steady_clock;
  auto t0 = Clock::now();
  IngestReport report;
  report.input = input;
  const uint64_t B = opt.memoryBytes;
  // The cap is about RSS: multi-MiB buffers in their own mappings, small ones kept for reuse
  // (patch_store.h); malloc_trim at the end of each pass returns the rest.
  useStreamingAllocator();
  auto endOfPass = [] { malloc_trim(0); };
  StageClock clock(opt.progress);

  // 1 parse. The vertex records stay in RAM when they, a state byte per vertex and a bit per
  // vertex and thread fit in the cap with a reserve for the passes' buffers and the assigner.
  auto reader = openMesh(input);
  const VertexRecordLayout expected{reader->header().doublePrecision, reader->header().hasNormals, reader->header().hasColors};
  // The reserve covers what the resident passes hold besides the records at their peak (sort
  // buffers, which shrink to fit, the assigner's seeds and tables, the process itself; measured
  // at 53M/512M: ~165 MiB above the records, of which ~60 MiB can shrink).
  const uint64_t reserve = std::max<uint64_t>(128ull << 20, B / 4);
  const double perVertex = double(expected.size()) + 1 + std::max(2, tbb::this_task_arena::max_concurrency()) / 8.0;
  const uint64_t residentLimit = B > reserve ? uint64_t(double(B - reserve) * double(expected.size()) / perVertex) : 0;
  Progress parseProgress(opt.progress, "ingest: parse", uint64_t(std::max<int64_t>(0, reader->header().declaredFaces)));
  ScratchSink sink(scratch, parseProgress, residentLimit);
  // A resident binary PLY of triangles: its faces are read in place later, not copied.
  std::optional<FaceFile> inPlace;
  if (reader->header().format == MeshFormat::PlyBinaryLE && reader->header().declaredVertices >= 0 &&
      uint64_t(reader->header().declaredVertices) * expected.size() <= residentLimit) {
    inPlace = plyTriangleBlock(input);
    if (inPlace && int64_t(inPlace->count) != reader->header().declaredFaces) inPlace.reset();
    if (inPlace) sink.skipFaceFile();
  }
  // The Morton sort of the resident path, filled during the parse when the input allows it; its
  // budget is what the declared vertex records leave.
  const uint64_t declaredRecords = uint64_t(std::max<int64_t>(0, reader->header().declaredVertices)) * expected.size();
  MortonSort morton(scratch + "/m0", std::max<uint64_t>(8 << 20, B > declaredRecords + (64 << 20) ? (B - declaredRecords - (64 << 20)) * 4 / 5 : 0));
  ReadStats stats;
  if (residentLimit > 0) {
    // The reader on its own thread; this one runs the Morton pipeline over its chunks (codes in
    // parallel, added to the sort in face order) until the reader is done.
    ChunkQueue queue(8);
    sink.fuse(&queue);
    std::exception_ptr readError;
    std::thread readerThread([&] {
      try {
        stats = reader->read(sink);
        sink.close();
      } catch (...) {
        readError = std::current_exception();
      }
      queue.finish();
    });
    try {
      struct Token {
        std::vector<uint32_t>* chunk = nullptr;
        uint64_t first = 0;
        std::vector<MortonKey> keys;
      };
      const size_t tokens = size_t(std::max(2, tbb::this_task_arena::max_concurrency())) + 1;
      std::vector<Token> pool(tokens);
      size_t nextToken = 0;
      tbb::parallel_pipeline(
          tokens,
          tbb::make_filter<void, Token*>(tbb::filter_mode::serial_in_order,
                                         [&](tbb::flow_control& fc) -> Token* {
                                           Token* t = &pool[nextToken++ % tokens];
                                           if (!queue.pop(t->chunk, t->first)) {
                                             fc.stop();
                                             return nullptr;
                                           }
                                           return t;
                                         }) &
              tbb::make_filter<Token*, Token*>(tbb::filter_mode::parallel,
                                               [&](Token* t) {
                                                 const ResidentVertices rv{queue.records(), expected, expected.size()};
                                                 const MortonBox box(queue.bounds());
                                                 const uint32_t* idx = t->chunk->data();
                                                 const size_t n = t->chunk->size() / 3;
                                                 t->keys.resize(n);
                                                 for (size_t i = 0; i < n; ++i)
                                                   t->keys[i] = MortonSort::codeOf(rv, box, idx + 3 * i, t->first + i,
                                                                                   i + 16 < n ? idx + 3 * (i + 16) : nullptr);
                                                 return t;
                                               }) &
              tbb::make_filter<Token*, void>(tbb::filter_mode::serial_in_order, [&](Token* t) {
                morton.add(t->keys.data(), t->keys.size(), t->first);
                queue.release(t->chunk);
              }));
    } catch (...) {
      queue.cancel();
      readerThread.join();
      throw;
    }
    readerThread.join();
    if (readError) std::rethrow_exception(readError);
  } else {
    stats = reader->read(sink);
    sink.close();
  }
  parseProgress.finish(stats.triangles);
  report.format = formatName(reader->header().format);
  report.inputVertices = stats.vertices;
  report.inputTriangles = stats.triangles;
  report.inputBytes = stats.bytes;
  report.polygons = stats.polygons;
  report.degenerateTriangles = stats.degenerateTriangles;
  if (stats.triangles == 0) fail(input, "mesh has no triangles");
  if (stats.triangles > 0xFFFFFFF0ull) fail(input, "more than 4 billion triangles are not supported");
  const VertexRecordLayout vlayout = sink.layout;
  if (Full != (vlayout.doublePrecision || vlayout.normals || vlayout.colors)) fail(input, "internal: wrong record type");
  const uint64_t nv = sink.vertexCount, nf = sink.faceCount;
  const MeshFormat format = reader->header().format;
  if (format == MeshFormat::StlAscii || format == MeshFormat::StlBinary) {
    Progress progress(opt.progress, "ingest: weld", nv, "vert");
    report.weldedVertices = weldSoup(scratch, vlayout, nv, B * 6 / 10);
    progress.finish(nv);
  }
  if (!sink.inRam() && nv * vlayout.size() <= residentLimit) sink.loadVertices(scratch);
  const bool resident = sink.inRam();
  if (!sink.wroteFaceFile()) {
    // The face block read in place must be exactly the faces the reader delivered: triangles
    // only (no polygon was fanned), the declared count, the same first and last faces.
    bool same = stats.polygons == 0 && stats.triangles == inPlace->count && resident;
    auto facesAt = [&](uint64_t first, uint64_t n) {
      FaceFile part = *inPlace;
      part.offset += first * 13;
      part.count = n;
      FaceReader r(part);
      std::vector<uint32_t> out, batch;
      while (out.size() < 3 * n && r.getBatch(batch, size_t(n))) out.insert(out.end(), batch.begin(), batch.end());
      return out;
    };
    if (same) {
      const std::vector<uint32_t> last = sink.lastFaces();
      try {
        same = facesAt(0, sink.firstFaces().size() / 3) == sink.firstFaces() &&
               facesAt(inPlace->count - last.size() / 3, last.size() / 3) == last;
      } catch (const Error&) {  // not where the header said: copy them instead
        same = false;
      }
    }
    if (!same) {
      // Polygons (or anything unexpected): the faces as the reader gives them, in a second read.
      struct FacesOnly : MeshSink {
        TempWriter out;
        explicit FacesOnly(const std::string& path) : out(path, 4 << 20) {}
        void vertices(const InputVertex*, size_t, uint64_t) override {}
        void triangles(const uint32_t* idx, size_t count) override { out.write(idx, count * 12); }
      } facesOnly(scratch + "/face.bin");
      openMesh(input)->read(facesOnly);
      facesOnly.out.close();
      inPlace.reset();
    }
  }
  if (inPlace) inPlace->vertices = nv;
  const FaceFile faceFile = inPlace ? *inPlace : FaceFile{scratch + "/face.bin", 0, nf, false};
  clock.mark("parse");

  auto impl = std::make_unique<PatchStore::Impl>();
  impl->env = env;
  impl->dir = dir;
  impl->layout = {vlayout.doublePrecision, vlayout.normals, vlayout.colors};
  impl->bounds = sink.bounds;
  PatchStageOutput patchStage;
  uint64_t distinctReferenced = 0;
  std::unique_ptr<SharedSorter> sharedPtr;
  std::unique_ptr<EdgeSorter> edgesPtr;
  if (resident) {
    std::remove((scratch + "/vert.bin").c_str());
    std::vector<char> records = sink.takeVertices();
    ResidentVertices rv{records.data(), vlayout, vlayout.size()};
    residentStages(scratch, faceFile, rv, records, morton, sink.bounds, nv, nf, B, assigner, report, *impl, sharedPtr, edgesPtr,
                   patchStage, distinctReferenced, clock, opt.progress);
  } else {
    // 2 centroids, straight into an external sort by Morton code. The assigner streams the
    // centroids in Morton order rather than face order: its passes (the irregular seeding) rely on
    // consecutive triangles being close, which a scan with shuffled faces does not give, and the
    // assign stage then looks cells up in spatially coherent order (cache hits instead of random
    // reads of the seed tables). Deterministic: ties by face.
    {
      MortonFaceSorter byCode(scratch + "/s0", B / 4, MortonFaceCode{}, 63, true);
      computeCentroids(scratch, vlayout, nv, nf, B * 2 / 5, sink.bounds, byCode, opt.progress);
      std::remove((scratch + "/face.bin").c_str());
      endOfPass();
      clock.mark("centroids");
      checkInterrupt("ingest: sort");
      byCode.finish();
      TempWriter out(scratch + "/morton.bin", 4 << 20);
      forEachInMortonOrder(byCode, [&](const MortonFace& m) { out.put(FaceCentroid{m.face, {m.v[0], m.v[1], m.v[2]}, m.c}); });
      out.close();
    }
    endOfPass();
    clock.mark("morton merge");
    CentroidFile centroids(scratch + "/morton.bin", nf, sink.bounds);
    {
      // The irregular V-partition reads the stream once (a sample; vpartition/irregular.cpp);
      // report its time, since it is a separate cost from the sorts.
      Progress progress(opt.progress, "ingest: partition", nf);
      assigner.prepare(centroids, B / 2);
      progress.finish(nf);
    }
    report.assigner = assigner.describe();
    endOfPass();
    clock.mark("partition");
    // 3 assign, in Morton order; faces externally sorted by (cell key, face).
    ExternalSorter<FaceRec, FaceLess> byCell(scratch + "/s1", B / 4, {}, true);
    {
      Progress progress(opt.progress, "ingest: assign", nf);
      TempReader cr(scratch + "/morton.bin", 4 << 20);
      std::vector<FaceCentroid> batch;
      std::vector<FaceRec> recs;
      uint64_t done = 0;
      while (cr.getBatch(batch, 65536)) {
        recs.resize(batch.size());
        tbb::parallel_for(tbb::blocked_range<size_t>(0, batch.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
          for (size_t i = r.begin(); i < r.end(); ++i) {
            const FaceCentroid& f = batch[i];
            recs[i] = FaceRec{assigner.cellKey(&f.c.x), f.face, {f.v[0], f.v[1], f.v[2]}};
          }
        });
        for (const FaceRec& r : recs) byCell.add(r);
        done += batch.size();
        progress.update(done);
      }
      if (done != nf) fail(scratch, "internal: Morton file holds " + std::to_string(done) + " faces");
      progress.finish(done);
    }
    std::remove((scratch + "/morton.bin").c_str());
    endOfPass();

    clock.mark("assign");
    // 4 group into patches
    checkInterrupt("ingest: sort");
    byCell.finish();
    std::vector<uint64_t>& patchKey = patchStage.patchKey;
    std::vector<uint32_t> patchTris;
    ExternalSorter<uint64_t, U64Less> pairs(scratch + "/s2", B / 4, {}, true);
    {
      TempWriter pface(scratch + "/pface.bin", 4 << 20);
      FaceRec f;
      // Patches are gathered in batches; their distinct vertices are found in parallel and written
      // in patch order (the result does not depend on the thread count).
      constexpr size_t kBatch = 64;
      std::vector<std::vector<uint32_t>> tris(kBatch), verts(kBatch);
      size_t filled = 0;
      auto flush = [&]() {
        tbb::parallel_for(size_t(0), filled, [&](size_t i) {
          verts[i] = tris[i];
          std::sort(verts[i].begin(), verts[i].end());
          verts[i].erase(std::unique(verts[i].begin(), verts[i].end()), verts[i].end());
        });
        for (size_t i = 0; i < filled; ++i) {
          const uint32_t k = uint32_t(patchKey.size() - filled + i);
          pface.write(tris[i].data(), tris[i].size() * 4);
          patchTris.push_back(uint32_t(tris[i].size() / 3));
          for (uint32_t v : verts[i]) pairs.add(uint64_t(v) << 32 | k);
          tris[i].clear();
        }
        filled = 0;
      };
      while (byCell.next(f)) {
        if (patchKey.empty() || patchKey.back() != f.key) {
          if (filled == kBatch) flush();
          patchKey.push_back(f.key);
          ++filled;
        }
        tris[filled - 1].insert(tris[filled - 1].end(), f.v, f.v + 3);
      }
      flush();
      pface.close();
    }
    const uint32_t P = uint32_t(patchKey.size());

    clock.mark("group");
    // 5 join pairs with vertex data
    checkInterrupt("ingest: sort");
    pairs.finish();
    ExternalSorter<VertexData<Full>, KeyLess<VertexData<Full>>> byPatch(scratch + "/s3", B / 4, {}, true);
    {
      Progress progress(opt.progress, "ingest: vertices", nv, "vert");
      TempReader vr(scratch + "/vert.bin", 4 << 20);
      std::vector<char> rec(vlayout.size());
      uint64_t nextVertex = 0;
      uint64_t pair;
      bool have = pairs.next(pair);
      std::vector<uint32_t> holders;
      while (have) {
        uint32_t v = uint32_t(pair >> 32);
        holders.clear();
        while (have && uint32_t(pair >> 32) == v) {
          holders.push_back(uint32_t(pair));
          have = pairs.next(pair);
        }
        ++distinctReferenced;
        for (; nextVertex <= v; ++nextVertex)
          if (vr.read(rec.data(), rec.size()) != rec.size()) fail(scratch, "vertex scratch file is short");
        VertexData<Full> d{};
        d.holders = uint32_t(holders.size());
        if constexpr (Full) {
          const char* r = rec.data();
          vlayout.position(r, d.p);
          r += vlayout.doublePrecision ? 24 : 12;
          if (vlayout.normals) {
            std::memcpy(d.n, r, 12);
            r += 12;
          }
          if (vlayout.colors) std::memcpy(d.c, r, 4);
        } else {
          std::memcpy(d.p, rec.data(), 12);
        }
        for (uint32_t k : holders) {
          d.key = uint64_t(k) << 32 | v;
          byPatch.add(d);
        }
        progress.update(nextVertex);
      }
      progress.finish(nv);
    }
    std::remove((scratch + "/vert.bin").c_str());
    endOfPass();

    clock.mark("vertices");
    // 6 patches
    checkInterrupt("ingest: sort");
    byPatch.finish();
    sharedPtr = std::make_unique<SharedSorter>(scratch + "/s4", B / 8);
    edgesPtr = std::make_unique<EdgeSorter>(scratch + "/s5", B / 16);
    auto& shared = *sharedPtr;
    auto& edges = *edgesPtr;
    {
      // Patches are gathered from the sorted streams in batches, built in parallel, and written in
      // patch order, so the store does not depend on the thread count.
      struct PatchWork {
        Patch p;
        std::vector<uint32_t> globalIds, holders;
        std::string payload;
        uint64_t duplicates = 0, nonManifold = 0;
        std::vector<EdgeRec> crossEdges;  // edges between two shared vertices: may continue elsewhere
      };
      auto buildPatch = [&](PatchWork& w) {
        Patch& p = w.p;
        for (uint32_t& v : p.triangles) {
          auto it = std::lower_bound(w.globalIds.begin(), w.globalIds.end(), v);
          if (it == w.globalIds.end() || *it != v) fail(scratch, "internal: patch vertex missing");
          v = uint32_t(it - w.globalIds.begin());
        }
        std::vector<std::array<uint32_t, 3>> sortedTris;
        std::vector<uint64_t> edgeList;
        for (size_t t = 0; t < p.triangles.size(); t += 3) {
          std::array<uint32_t, 3> s3 = {p.triangles[t], p.triangles[t + 1], p.triangles[t + 2]};
          std::sort(s3.begin(), s3.end());
          sortedTris.push_back(s3);
          if (s3[0] == s3[1] || s3[1] == s3[2]) continue;  // degenerate: no proper edges
          for (int e = 0; e < 3; ++e) {
            uint32_t a = p.triangles[t + e], b = p.triangles[t + (e + 1) % 3];
            edgeList.push_back(uint64_t(std::min(a, b)) << 32 | std::max(a, b));
          }
        }
        std::sort(sortedTris.begin(), sortedTris.end());
        for (size_t i = 1; i < sortedTris.size(); ++i) w.duplicates += sortedTris[i] == sortedTris[i - 1];
        std::sort(edgeList.begin(), edgeList.end());
        for (size_t i = 0; i < edgeList.size();) {
          size_t j = i;
          while (j < edgeList.size() && edgeList[j] == edgeList[i]) ++j;
          uint32_t a = uint32_t(edgeList[i] >> 32), b = uint32_t(edgeList[i]);
          if (w.holders[a] > 1 && w.holders[b] > 1)
            w.crossEdges.push_back({uint64_t(w.globalIds[a]) << 32 | w.globalIds[b], uint32_t(j - i), 0});
          else if (j - i > 2)
            ++w.nonManifold;
          i = j;
        }
        w.payload = encodeGeometry(p, impl->layout);
      };
      Progress progress(opt.progress, "ingest: patches", nf);
      TempReader pface(scratch + "/pface.bin", 4 << 20);
      VertexData<Full> d;
      bool have = byPatch.next(d);
      uint64_t facesDone = 0;
      constexpr uint32_t kBatch = 64;
      std::vector<PatchWork> work;
      for (uint32_t k0 = 0; k0 < P; k0 += kBatch) {
        const uint32_t k1 = std::min(P, k0 + kBatch);
        work.assign(k1 - k0, PatchWork());
        for (uint32_t k = k0; k < k1; ++k) {
          PatchWork& w = work[k - k0];
          w.p.id = k;
          w.p.cell = patchKey[k];
          while (have && uint32_t(d.key >> 32) == k) {
            w.globalIds.push_back(uint32_t(d.key));
            w.holders.push_back(d.holders);
            for (int a = 0; a < 3; ++a) w.p.positions.push_back(d.p[a]);
            if constexpr (Full) {
              if (vlayout.normals) w.p.normals.insert(w.p.normals.end(), d.n, d.n + 3);
              if (vlayout.colors) w.p.colors.insert(w.p.colors.end(), d.c, d.c + 4);
            }
            have = byPatch.next(d);
          }
          w.p.triangles.resize(size_t(patchTris[k]) * 3);
          if (pface.read(w.p.triangles.data(), w.p.triangles.size() * 4) != w.p.triangles.size() * 4)
            fail(scratch, "patch face scratch file is short");
        }
        tbb::parallel_for(size_t(0), work.size(), [&](size_t i) { buildPatch(work[i]); });
        for (PatchWork& w : work) {
          const Patch& p = w.p;
          report.duplicateTriangles += w.duplicates;
          report.nonManifoldEdges += w.nonManifold;
          for (const EdgeRec& e : w.crossEdges) edges.add(e);
          for (uint32_t v = 0; v < w.globalIds.size(); ++v)
            if (w.holders[v] > 1) shared.add({uint64_t(w.globalIds[v]) << 32 | p.id, v, 0});
          PatchRecord rec;
          rec.meta = {p.id, p.cell, 0, p.vertexCount(), p.triangleCount(), 0, boundsOf(p.positions)};
          rec.geometry = impl->appendBlock(w.payload);
          impl->patches[p.id] = rec;
          facesDone += p.triangleCount();
        }
        progress.update(facesDone);
      }
      progress.finish(facesDone);
    }
    std::remove((scratch + "/pface.bin").c_str());

    endOfPass();
    clock.mark("patches");
  }
  report.unreferencedVertices = nv - distinctReferenced - report.weldedVertices;
  const uint32_t P = uint32_t(patchStage.patchKey.size());
  auto& shared = *sharedPtr;
  auto& edges = *edgesPtr;
  // Edges shared between patches: sum their uses.
  checkInterrupt("ingest: sort");
  edges.finish();
  {
    EdgeRec e;
    bool have = edges.next(e);
    while (have) {
      uint64_t key = e.key;
      uint32_t count = 0;
      while (have && e.key == key) {
        count += e.count;
        have = edges.next(e);
      }
      if (count > 2) ++report.nonManifoldEdges;
    }
  }

  clock.mark("edges");
  // 7 boundary lists
  checkInterrupt("ingest: sort");
  shared.finish();
  EntrySorter entries(scratch + "/s6", B / 8);
  {
    LocalRec r;
    bool have = shared.next(r);
    std::vector<std::pair<uint32_t, uint32_t>> group;  // (patch, local)
    while (have) {
      uint32_t v = uint32_t(r.key >> 32);
      group.clear();
      while (have && uint32_t(r.key >> 32) == v) {
        group.push_back({uint32_t(r.key), r.local});
        have = shared.next(r);
      }
      // The group is in ascending patch order (the key's low half), so each (patch, local)
      // key gets its entries here, consecutively, by ascending neighbour.
      for (auto& a : group)
        for (auto& b : group)
          if (a.first != b.first) entries.add({uint64_t(a.first) << 32 | a.second, b.first, b.second});
    }
  }
  checkInterrupt("ingest: sort");
  entries.finish();
  {
    EntryRec e;
    bool have = entries.next(e);
    std::vector<BoundaryEntry> list;
    for (uint32_t k = 0; k < P; ++k) {
      list.clear();
      while (have && uint32_t(e.key >> 32) == k) {
        list.push_back({uint32_t(e.key), e.neighbour, e.remote});
        have = entries.next(e);
      }
      PatchRecord& rec = impl->patches[k];
      rec.boundary = impl->appendBlock(encodeBoundary(list));
      rec.meta.boundaryEntries = uint32_t(list.size());
    }
  }

  clock.mark("boundary");
  // Commit: segment durable, then the first manifest and CURRENT.
  impl->nextPatchId = P;
  for (auto& [id, rec] : impl->patches) impl->addLive(rec, +1);
  report.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  report.peakBytes = peakRssBytes();
  impl->blobs["ingest"] = encodeReport(report);
  std::string assignerBytes = assigner.serialize();
  if (!assignerBytes.empty()) impl->blobs["assigner"] = assignerBytes;
  impl->activeWriter->sync();
  impl->activeWriter->close();
  impl->activeWriter.reset();
  impl->writeNewManifest();
  return report;
}

}  // namespace


namespace {

constexpr const char* kIngestLockName = "INGEST-LOCK";

// Folders `prefix`PID left in `folder` by an ingest that was killed: each holds the lock file
// kIngestLockName while its ingest runs, so one whose lock no process holds, and whose PID names
// no running process, is certainly dead (a folder without the lock file is never touched).
void removeDeadLeftovers(const std::string& folder, const std::string& prefix) {
  std::error_code ec;
  for (fs::directory_iterator it(folder.empty() ? "." : folder, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.size() <= prefix.size() || name.compare(0, prefix.size(), prefix) != 0) continue;
    const std::string digits = name.substr(prefix.size());
    if (digits.find_first_not_of("0123456789") != std::string::npos || digits.size() > 9) continue;
    const long pid = std::stol(digits);
    const std::string path = it->path().string(), lock = path + "/" + kIngestLockName;
    std::error_code e2;
    if (pid == long(getpid()) || !fs::is_directory(path, e2) || !fs::exists(lock, e2)) continue;
    if (FileLock::holder(lock) != 0 || ::kill(pid_t(pid), 0) == 0 || errno != ESRCH) continue;
    fs::remove_all(path, e2);
    if (!e2)
      std::fprintf(stderr, "ingest: removed %s, left by an ingest that was killed (process %ld is gone)\n", path.c_str(), pid);
  }
}

std::string parentOf(const std::string& path) {
  std::string parent = fs::path(path).parent_path().string();
  return parent.empty() ? "." : parent;
}

}  // namespace

IngestReport PatchStore::ingest(const std::string& input, const std::string& dirIn, CellAssigner& assigner,
                                const IngestOptions& options, Env* env) {
  std::string dir = dirIn;
  while (dir.size() > 1 && dir.back() == '/') dir.pop_back();
  // A directory, FIFO or device would block or be misread; say what it is.
  requireRegularFile(input, "a mesh file");
  // The store directory is made here and only here: an existing folder (even an empty one, which
  // may be a mount point or carry permissions) is the user's, never removed or replaced.
  if (fs::is_directory(dir))
    fail(dir, std::string(env->exists(dir + "/CURRENT") ? "is an existing patch store" : "is an existing folder") +
                  "; ingest creates the store directory itself: choose a name that does not exist (nothing was changed)");
  if (env->exists(dir)) fail(dir, "already exists (remove it or choose another store directory)");
  const std::string base = fs::path(dir).filename().string();
  removeDeadLeftovers(parentOf(dir), base + ".ingest-");
  if (!options.tempDir.empty()) removeDeadLeftovers(options.tempDir, "mt-ingest-");
  std::string building = dir + ".ingest-" + std::to_string(getpid());
  std::error_code ec;
  fs::remove_all(building, ec);  // our own PID: a leftover of a dead process that had it
  env->createDir(building);
  std::string scratch = options.tempDir.empty() ? building + "/tmp" : options.tempDir + "/mt-ingest-" + std::to_string(getpid());
  try {
    // Held while the folders are in use, so that another ingest knows they are not leftovers.
    auto buildingLock = std::make_unique<FileLock>(building + "/" + kIngestLockName, building);
    std::unique_ptr<FileLock> scratchLock;
    env->createDir(scratch);
    if (!options.tempDir.empty()) scratchLock = std::make_unique<FileLock>(scratch + "/" + kIngestLockName, scratch);
    // Peek at the header to pick the record type; the reader is reopened by build().
    const MeshHeader header = openMesh(input)->header();
    bool full = header.doublePrecision || header.hasNormals || header.hasColors;
    IngestReport report = full ? build<true>(input, building, scratch, assigner, options, env)
                               : build<false>(input, building, scratch, assigner, options, env);
    checkInterrupt("ingest");
    scratchLock.reset();
    fs::remove_all(scratch, ec);
    buildingLock.reset();  // removes the lock file: the store holds only its own files
    env->renameFile(building, dir);
    env->syncDir(parentOf(dir));
    return report;
  } catch (...) {
    fs::remove_all(scratch, ec);
    fs::remove_all(building, ec);
    throw;
  }
}

}  // namespace mt
