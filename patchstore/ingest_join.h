// Ingest, the chunked path: every face joined with the float positions of its three corners, when
// the vertex records do not fit the cap (ingest_chunked.cpp joins twice: for the Morton codes,
// then, once the V-partition exists, for the cell keys). Internal to patchstore/ingest*.cpp.
//
// Phase 1, the sweep. Faces are read in face order, in batches, and two windows of vertex
// positions are kept in RAM, each a ring over a range of vertex indices that only moves forward
// (so each reads the vertex records once, in order). Window A ends at (a little past) the highest
// corners of the batch: the front where a scan's faces bring in new vertices. Window B ends at the
// highest corners below A: the older vertices the front still refers to (the previous rows of a
// grid, an earlier strip of a scan, the coarser levels of a subdivided mesh). Both follow the 99th
// percentile, not the maximum, so that a few far corners do not drag them away from the rest. A
// face whose three corners lie in the windows is joined there and then. Measured with windows of 0.4-2 M vertices: 97.5% of
// the faces of arm3.3M and arm13M (scangen's armadillo), 100% of dragon5M and of mtgen's scans;
// with window A alone, 66-88% of the armadillo's.
//
// Phase 2, the buckets. Every other face goes to the bucket of the chunk of its lowest corner
// (chunks: consecutive vertex ranges the size of both windows together, so phase 2 uses the same
// RAM). The buckets are taken in chunk order, each with its chunk's positions loaded: a face whose
// corners are all found is joined; one that needs a later chunk moves on to that chunk's bucket,
// carrying the positions found so far (at most two: every corner in an earlier chunk has been
// found, since a face always moves to the chunk of its lowest corner not found yet). A shuffled
// input goes through phase 2 almost whole. Bucket files are written in large appends and given
// back to the file system as they are read (TempReader::consumeAsRead).
//
// What the caller computes from a joined face (a centroid, a code, a key) must not depend on the
// order faces are joined in, which depends on the cap: the callers sort what they emit.
#pragma once

#include <fcntl.h>
#include <tbb/parallel_for.h>
#include <tbb/task_group.h>
#include <unistd.h>

#include "base/progress.h"
#include "base/temp_file.h"
#include "patchstore/ingest_internal.h"

namespace mt {
namespace ingest {

// Reads vertex records [first, first + n) of a VertexFile as float positions (3 per vertex), in
// aligned blocks past the page cache (base/temp_file.h says why).
class VertexLoader {
 public:
  VertexLoader(const VertexFile& file, const VertexRecordLayout& layout) : file_(file), layout_(layout), staging_(kStaging) {
    fd_ = openScratch(file.path, O_RDONLY, direct_);
    if (fd_ < 0) fail(file.path, std::string("cannot open the vertex records: ") + std::strerror(errno));
  }
  ~VertexLoader() {
    if (fd_ >= 0) ::close(fd_);
  }
  VertexLoader(const VertexLoader&) = delete;
  VertexLoader& operator=(const VertexLoader&) = delete;

  void load(uint64_t first, uint64_t n, float* out) {
    assert(first + n <= file_.count);
    const size_t size = layout_.size();
    const bool plain = !layout_.doublePrecision && size == 12;  // the records are the positions
    uint64_t at = file_.offset + first * size;                   // next byte wanted
    const uint64_t end = at + n * size;
    char* dst = reinterpret_cast<char*>(out);
    std::vector<char> partial;  // a record split between two blocks
    while (at < end) {
      const uint64_t block = at / kDirectAlign * kDirectAlign;
      const size_t want = size_t(std::min<uint64_t>(staging_.capacity(), (end - block + kDirectAlign - 1) / kDirectAlign * kDirectAlign));
      const size_t got = readAt(block, want);
      const size_t skip = size_t(at - block);
      if (got <= skip) fail(file_.path, "the vertex records end at byte offset " + std::to_string(at) + " (the file changed during the ingest?)");
      const size_t bytes = size_t(std::min<uint64_t>(got - skip, end - at));
      const char* src = staging_.data() + skip;
      if (plain) {
        std::memcpy(dst, src, bytes);
        dst += bytes;
      } else {
        // Whole records are converted; a record cut by the block end waits in `partial`.
        size_t used = 0;
        if (!partial.empty()) {
          const size_t take = std::min(bytes, size - partial.size());
          partial.insert(partial.end(), src, src + take);
          used = take;
          if (partial.size() == size) {
            convert(partial.data(), 1, reinterpret_cast<float*>(dst));
            dst += 12;
            partial.clear();
          }
        }
        const size_t whole = (bytes - used) / size;
        convert(src + used, whole, reinterpret_cast<float*>(dst));
        dst += 12 * whole;
        used += whole * size;
        partial.insert(partial.end(), src + used, src + bytes);
      }
      at += bytes;
    }
    assert(partial.empty());
  }

 private:
  static constexpr size_t kStaging = 1 << 20;
  void convert(const char* rec, size_t count, float* out) const {
    for (size_t i = 0; i < count; ++i) {
      double p[3];
      layout_.position(rec + i * layout_.size(), p);
      for (int a = 0; a < 3; ++a) out[3 * i + a] = float(p[a]);
    }
  }
  // Up to `want` bytes at the aligned offset `at` into the staging buffer; the count read.
  size_t readAt(uint64_t at, size_t want) {
    size_t done = 0;
    while (done < want) {
      const ssize_t got = ::pread(fd_, staging_.data() + done, want - done, off_t(at + done));
      if (got < 0 && errno == EINTR) continue;
      if (got < 0) fail(file_.path, "cannot read the vertex records at byte offset " + std::to_string(at + done) + ": " + std::strerror(errno));
      if (got == 0) break;
      done += size_t(got);
      if (direct_ && done % kDirectAlign != 0) break;  // a short direct read: the end of the file
    }
    return done;
  }
  VertexFile file_;
  VertexRecordLayout layout_;
  int fd_ = -1;
  bool direct_ = false;
  AlignedBuffer staging_;
};

class FaceJoin {
 public:
  static constexpr size_t kBatch = 65536;
  // A face waiting in the bucket of its lowest corner's chunk.
  struct BucketFace {
    uint32_t face, v[3];
  };
  // A face moving on to a later chunk with the positions found so far, in corner order (the
  // corners in earlier chunks).
  struct CarriedFace {
    uint32_t face, v[3];
    float p[6];
  };

  // positionBytes: both windows (phase 1), one chunk (phase 2); bucketBytes: the bucket files'
  // write buffers, all together; prefix: scratch path prefix of the bucket files.
  FaceJoin(const FaceFile& faces, const VertexFile& vertices, const VertexRecordLayout& layout, uint64_t faceCount,
           uint64_t positionBytes, uint64_t bucketBytes, std::string prefix)
      : faces_(faces), vertices_(vertices), layout_(layout), faceCount_(faceCount), prefix_(std::move(prefix)) {
    uint64_t cap = 4096;
    while (cap * 2 * 2 * 12 <= positionBytes && cap * 2 < (uint64_t(1) << 31)) cap *= 2;
    window_ = cap;
    chunk_ = 2 * cap;
    chunks_ = std::max<uint64_t>(1, (vertices.count + chunk_ - 1) / chunk_);
    bufferBytes_ = std::clamp<uint64_t>(bucketBytes / (2 * chunks_), 64 << 10, 1 << 20);
  }

  uint64_t swept() const { return swept_; }
  uint64_t bucketed() const { return bucketed_; }
  uint64_t chunks() const { return chunks_; }

  // perFace(slot, face, v, p) for every face exactly once, on any thread (v: the 3 corners, p: their
  // 3 float positions); after each batch, perBatch(valid, n, sweep) on the calling thread:
  // valid[slot] for slot < n says which slots perFace filled; sweep: the batch is phase 1's, its
  // filled slots in face order. `only` (ascending face indices), if given: those faces alone.
  template <class PerFace, class PerBatch>
  void run(const PerFace& perFace, const PerBatch& perBatch, Progress& progress, const std::vector<uint32_t>* only = nullptr) {
    only_ = only;
    expected_ = only ? only->size() : faceCount_;
    pos_.assign(size_t(6 * window_), 0.0f);
    buckets_.clear();
    buckets_.resize(size_t(2 * chunks_));
    for (uint64_t k = 0; k < chunks_; ++k) {
      buckets_[2 * k].path = prefix_ + ".b" + std::to_string(k);
      buckets_[2 * k + 1].path = prefix_ + ".c" + std::to_string(k);
    }
    try {
      sweep(perFace, perBatch, progress);
      for (uint64_t k = 0; k < chunks_; ++k) drain(k, perFace, perBatch, progress);
    } catch (...) {
      for (Bucket& b : buckets_) std::remove(b.path.c_str());
      throw;
    }
    if (swept_ + bucketed_ != expected_) fail(prefix_, "internal: the join gave " + std::to_string(swept_ + bucketed_) + " faces");
    std::vector<float>().swap(pos_);
    buckets_.clear();
  }

 private:
  // A ring over vertices [lo, hi), hi - lo <= cap: the position of v is at v & (cap - 1).
  struct Window {
    float* pos = nullptr;
    uint64_t cap = 0, lo = 0, hi = 0;
    bool has(uint32_t v) const { return v >= lo && v < hi; }
    const float* at(uint32_t v) const { return pos + 3 * (v & (cap - 1)); }
    void moveTo(uint64_t newHi, VertexLoader& loader) {
      if (newHi <= hi) return;
      const uint64_t from = std::max(hi, newHi > cap ? newHi - cap : 0);
      for (uint64_t v = from; v < newHi;) {
        const uint64_t slot = v & (cap - 1), n = std::min(newHi - v, cap - slot);
        loader.load(v, n, pos + 3 * slot);
        v += n;
      }
      hi = newHi;
      lo = std::max(lo, newHi > cap ? newHi - cap : 0);
    }
  };
  struct Bucket {
    std::string path;
    std::unique_ptr<AlignedBuffer> buffer;  // allocated on first use
    size_t used = 0;
    uint64_t bytes = 0;  // in the file so far
  };

  void put(uint64_t bucket, const void* rec, size_t size) {
    Bucket& b = buckets_[bucket];
    if (!b.buffer) b.buffer = std::make_unique<AlignedBuffer>(bufferBytes_);
    if (b.used + size > b.buffer->capacity()) flush(b, false);
    std::memcpy(b.buffer->data() + b.used, rec, size);
    b.used += size;
  }
  // Appends the buffer's whole blocks to the bucket's file (all of it when `last`), the file
  // opened for the append only (hundreds of buckets hold no descriptor between appends) and
  // written past the page cache (base/temp_file.h).
  void flush(Bucket& b, bool last) {
    const size_t whole = last ? b.used : b.used / kDirectAlign * kDirectAlign;
    if (whole == 0) return;
    bool direct = false;
    const int fd = openScratch(b.path, O_WRONLY | O_CREAT, direct);
    if (fd < 0) fail(b.path, std::string("cannot create scratch file: ") + std::strerror(errno));
    if (direct && whole % kDirectAlign != 0) ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_DIRECT);
    try {
      writeAllAt(fd, b.buffer->data(), whole, b.bytes, b.path);
    } catch (...) {
      ::close(fd);
      throw;
    }
    if (::close(fd) != 0) fail(b.path, std::string("cannot write scratch file: ") + std::strerror(errno));
    b.bytes += whole;
    std::memmove(b.buffer->data(), b.buffer->data() + whole, b.used - whole);
    b.used -= whole;
    if (last) b.buffer.reset();
  }
  uint64_t chunkOf(uint32_t v) const { return v / chunk_; }

  template <class PerFace, class PerBatch>
  void sweep(const PerFace& perFace, const PerBatch& perBatch, Progress& progress) {
    VertexLoader loaderA(vertices_, layout_), loaderB(vertices_, layout_);
    Window a{pos_.data(), window_}, b{pos_.data() + 3 * window_, window_};
    FaceReader reader(faces_);
    std::vector<uint32_t> idx, next, sel;  // sel: the batch's faces to join (indices in the batch)
    std::vector<uint32_t> high, low;       // the windows' targets: highest corners, corners below A
    std::vector<uint8_t> valid;
    size_t onlyAt = 0;
    // A batch's corners span about half as many vertices as it has faces in scan order: at most
    // half a window's worth, so that a batch's span fits its windows.
    const size_t batch = size_t(std::min<uint64_t>(kBatch, window_ / 2));
    bool have = reader.getBatch(idx, batch), haveNext = false;
    uint64_t first = 0;
    tbb::task_group prefetch;
    // The next batch is read while this one is joined; an error waits for the read in flight.
    struct WaitOnUnwind {
      tbb::task_group& g;
      ~WaitOnUnwind() {
        try {
          g.wait();
        } catch (...) {
        }
      }
    } waitOnUnwind{prefetch};
    while (have) {
      prefetch.run([&] { haveNext = reader.getBatch(next, batch); });
      const size_t n = idx.size() / 3;
      const uint32_t* v = idx.data();
      sel.clear();
      if (only_) {
        for (; onlyAt < only_->size() && (*only_)[onlyAt] < first + n; ++onlyAt) sel.push_back(uint32_t((*only_)[onlyAt] - first));
      } else {
        sel.resize(n);
        for (size_t i = 0; i < n; ++i) sel[i] = uint32_t(i);
      }
      const size_t m = sel.size();
      // Window A ends a little past the 99th percentile of the faces' highest corners, window B
      // past the 99th percentile of the corners below A: a few corners far from the rest (a
      // vertex written out of order) move no window, their faces go to the buckets.
      // (Percentiles of every 4th face: a batch is thousands of faces.)
      const uint64_t slack = window_ / 16;
      auto quantileEnd = [&](std::vector<uint32_t>& x) -> uint64_t {
        if (x.empty()) return 0;
        auto at = x.begin() + ptrdiff_t(x.size() * 99 / 100);
        std::nth_element(x.begin(), at, x.end());
        return uint64_t(*at) + 1 + slack;
      };
      high.clear();
      for (size_t j = 0; j < m; j += 4) {
        const uint32_t* f = v + 3 * size_t(sel[j]);
        high.push_back(std::max({f[0], f[1], f[2]}));
      }
      a.moveTo(std::min(vertices_.count, quantileEnd(high)), loaderA);
      low.clear();
      for (size_t j = 0; j < m; j += 4)
        for (int k = 0; k < 3; ++k)
          if (v[3 * size_t(sel[j]) + k] < a.lo) low.push_back(v[3 * size_t(sel[j]) + k]);
      b.moveTo(std::min(a.lo, quantileEnd(low)), loaderB);
      valid.assign(n, 0);
      tbb::parallel_for(tbb::blocked_range<size_t>(0, m, 4096), [&](const tbb::blocked_range<size_t>& r) {
        for (size_t j = r.begin(); j < r.end(); ++j) {
          if (j + 16 < r.end())
            for (int k = 0; k < 3; ++k) {
              const uint32_t u = v[3 * size_t(sel[j + 16]) + k];
              __builtin_prefetch(a.has(u) ? a.at(u) : b.at(u));
            }
          const size_t i = sel[j];
          const float* p[3];
          bool ok = true;
          for (int k = 0; k < 3 && ok; ++k) {
            const uint32_t u = v[3 * i + k];
            p[k] = a.has(u) ? a.at(u) : b.has(u) ? b.at(u) : nullptr;
            ok = p[k] != nullptr;
          }
          if (!ok) continue;
          perFace(i, uint32_t(first + i), v + 3 * i, p);
          valid[i] = 1;
        }
      });
      perBatch(valid.data(), n, true);
      for (const uint32_t i : sel) {
        if (valid[i]) {
          ++swept_;
          continue;
        }
        const uint32_t* f = v + 3 * i;
        BucketFace rec{uint32_t(first + i), {f[0], f[1], f[2]}};
        put(2 * chunkOf(std::min({f[0], f[1], f[2]})), &rec, sizeof rec);
      }
      first += n;
      progress.update(swept_);
      prefetch.wait();
      std::swap(idx, next);
      have = haveNext;
    }
    if (first != faceCount_) fail(faces_.path, "internal: the sweep read " + std::to_string(first) + " faces");
    for (uint64_t k = 0; k < chunks_; ++k) flush(buckets_[2 * k], true);
  }

  // Phase 2, chunk k: its bucket (faces whose lowest corner is in it), then the faces carried to it.
  template <class PerFace, class PerBatch>
  void drain(uint64_t k, const PerFace& perFace, const PerBatch& perBatch, Progress& progress) {
    Bucket& own = buckets_[2 * k];
    Bucket& carried = buckets_[2 * k + 1];
    flush(carried, true);
    if (own.bytes == 0 && carried.bytes == 0) return;
    const uint64_t lo = k * chunk_, hi = std::min(vertices_.count, lo + chunk_);
    {
      VertexLoader loader(vertices_, layout_);
      loader.load(lo, hi - lo, pos_.data());
    }
    // Resolves the corners of chunk k; the rest of p[] already points at positions found earlier.
    // Returns whether the face is complete; else fills `out` with the positions found so far and
    // `next` with the chunk to carry it to.
    auto resolve = [&](const uint32_t* v, const float** p, CarriedFace& out, uint64_t& next) {
      next = UINT64_MAX;
      for (int c = 0; c < 3; ++c) {
        if (v[c] >= lo && v[c] < hi) {
          p[c] = &pos_[3 * (v[c] - lo)];
        } else if (v[c] >= hi) {
          p[c] = nullptr;
          next = std::min(next, chunkOf(v[c]));
        }
      }
      if (next == UINT64_MAX) return true;
      int slot = 0;
      for (int c = 0; c < 3; ++c)
        if (p[c]) std::memcpy(&out.p[3 * slot++], p[c], 12);
      assert(slot <= 2);  // a face with three corners found is complete
      return false;
    };
    std::vector<uint8_t> valid;
    std::vector<CarriedFace> out;
    std::vector<uint64_t> target;
    auto forward = [&](size_t n) {
      for (size_t i = 0; i < n; ++i) {
        if (valid[i]) {
          ++bucketed_;
          continue;
        }
        put(2 * target[i] + 1, &out[i], sizeof(CarriedFace));
      }
      progress.update(swept_ + bucketed_);
    };
    if (own.bytes > 0) {
      TempReader r(own.path, 4 << 20);
      r.consumeAsRead();
      std::vector<BucketFace> batch;
      while (r.getBatch(batch, kBatch)) {
        const size_t n = batch.size();
        valid.assign(n, 0);
        out.resize(n);
        target.resize(n);
        tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 4096), [&](const tbb::blocked_range<size_t>& range) {
          for (size_t i = range.begin(); i < range.end(); ++i) {
            const BucketFace& f = batch[i];
            const float* p[3] = {nullptr, nullptr, nullptr};
            if (!resolve(f.v, p, out[i], target[i])) {
              out[i].face = f.face;
              std::memcpy(out[i].v, f.v, 12);
              continue;
            }
            perFace(i, f.face, f.v, p);
            valid[i] = 1;
          }
        });
        perBatch(valid.data(), n, false);
        forward(n);
      }
    }
    if (carried.bytes > 0) {
      TempReader r(carried.path, 4 << 20);
      r.consumeAsRead();
      std::vector<CarriedFace> batch;
      while (r.getBatch(batch, kBatch)) {
        const size_t n = batch.size();
        valid.assign(n, 0);
        out.resize(n);
        target.resize(n);
        tbb::parallel_for(tbb::blocked_range<size_t>(0, n, 4096), [&](const tbb::blocked_range<size_t>& range) {
          for (size_t i = range.begin(); i < range.end(); ++i) {
            const CarriedFace& f = batch[i];
            // Corners in earlier chunks were found, in corner order, into f.p.
            const float* p[3] = {nullptr, nullptr, nullptr};
            int slot = 0;
            for (int c = 0; c < 3; ++c)
              if (f.v[c] < lo) p[c] = &f.p[3 * slot++];
            if (!resolve(f.v, p, out[i], target[i])) {
              out[i].face = f.face;
              std::memcpy(out[i].v, f.v, 12);
              continue;
            }
            perFace(i, f.face, f.v, p);
            valid[i] = 1;
          }
        });
        perBatch(valid.data(), n, false);
        forward(n);
      }
    }
    std::remove(own.path.c_str());
    std::remove(carried.path.c_str());
  }

  FaceFile faces_;
  VertexFile vertices_;
  VertexRecordLayout layout_;
  uint64_t faceCount_;
  std::string prefix_;
  uint64_t window_ = 0, chunk_ = 0, chunks_ = 0, bufferBytes_ = 0;
  std::vector<float> pos_;
  std::vector<Bucket> buckets_;  // 2k: faces whose lowest corner is in chunk k; 2k + 1: carried to it
  uint64_t swept_ = 0, bucketed_ = 0;
  const std::vector<uint32_t>* only_ = nullptr;
  uint64_t expected_ = 0;
};

}  // namespace ingest
}  // namespace mt
