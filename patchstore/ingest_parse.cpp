// Ingest stage 1, the parse (see ingest.cpp): the input read once into the scratch files (or into
// RAM, on the resident path), the faces' Morton codes computed while it goes on when the input
// allows it, STL soups welded, and the faces of a resident binary PLY read in place afterwards.
#include <malloc.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

#include <condition_variable>
#include <deque>
#include <exception>
#include <mutex>
#include <optional>
#include <sstream>
#include <thread>

#include "base/byte_io.h"
#include "base/progress.h"
#include "patchstore/ingest_internal.h"

namespace mt {
namespace ingest {
namespace {

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
    layout = {h.doublePrecision, h.hasNormals, h.hasColors, h.hasTexcoords};
    record_.resize(layout.size());
    lastVertices_.resize(kCheckedFaces * layout.size());
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
        if (writeVertices_) vert_.write(record_.data(), record_.size());
        // The first and last records, to check the vertex block read in place against.
        if (firstVertices_.size() < kCheckedFaces * record_.size())
          firstVertices_.insert(firstVertices_.end(), record_.begin(), record_.end());
        std::memcpy(&lastVertices_[(vertexCount + i) % kCheckedFaces * record_.size()], record_.data(), record_.size());
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
  // No vert.bin: the chunked path will read the vertex records from the input (VertexFile), if
  // they check out; never for records kept in RAM.
  void skipVertexFile() { writeVertices_ = false; }
  bool wroteVertexFile() const { return writeVertices_; }
  // The first and last vertex records written (not kept in RAM), oldest first.
  const std::vector<char>& firstVertexRecords() const { return firstVertices_; }
  std::vector<char> lastVertexRecords() const {
    std::vector<char> out;
    const uint64_t n = std::min<uint64_t>(vertexCount, kCheckedFaces), size = record_.size();
    for (uint64_t i = vertexCount - n; i < vertexCount; ++i)
      out.insert(out.end(), &lastVertices_[i % kCheckedFaces * size], &lastVertices_[i % kCheckedFaces * size] + size);
    return out;
  }
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
  bool writeFaces_ = true, writeVertices_ = true;
  std::vector<char> firstVertices_, lastVertices_;
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

// The vertex and face records of a binary little-endian PLY that can be read in place: every
// element before them of fixed-size records; faces whose only property is a list of uchar (or
// char) count and int (or uint) indices; vertices whose properties are exactly what vert.bin's
// record holds for `layout` (x y z float, or double; then nx ny nz float; then red green blue
// alpha uchar), in that order.
struct PlyBlocks {
  std::optional<FaceFile> faces;
  std::optional<VertexFile> vertices;
};
PlyBlocks plyBlocks(const std::string& path, const VertexRecordLayout& layout) {
  PlyBlocks blocks;
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return blocks;
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
    std::vector<std::pair<std::string, std::string>> scalars;  // (name, type)
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
      if (w != "ply") return blocks;
    } else if (w == "format") {
      std::string kind, version;
      words >> kind >> version;
      binaryLE = kind == "binary_little_endian";
    } else if (w == "element") {
      Element e;
      if (!(words >> e.name >> e.count)) return blocks;
      elements.push_back(e);
    } else if (w == "property") {
      if (elements.empty()) return blocks;
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
        if (size < 0) return blocks;
        words >> name;
        e.size += uint64_t(size);
        e.scalars.push_back({name, type});
      }
    } else if (w == "end_header") {
      ended = true;
      break;
    } else if (w != "comment" && w != "obj_info" && !w.empty()) {
      return blocks;
    }
  }
  if (!binaryLE || !ended || consumed > head.size()) return blocks;
  // vert.bin's record for this layout, as (name, type) in order.
  std::vector<std::pair<std::string, std::string>> record;
  for (const char* a : {"x", "y", "z"}) record.push_back({a, layout.doublePrecision ? "double" : "float"});
  if (layout.normals)
    for (const char* a : {"nx", "ny", "nz"}) record.push_back({a, "float"});
  if (layout.colors)
    for (const char* a : {"red", "green", "blue", "alpha"}) record.push_back({a, "uchar"});
  auto sameType = [](const std::string& a, const std::string& b) {
    auto canon = [](const std::string& t) {
      return t == "float32" ? std::string("float") : t == "float64" ? std::string("double") : t == "uint8" ? std::string("uchar") : t;
    };
    return canon(a) == canon(b);
  };
  uint64_t offset = consumed;
  for (const Element& e : elements) {
    if (e.name == "vertex" && e.fixed && e.scalars.size() == record.size() && e.size == layout.size()) {
      bool same = true;
      for (size_t k = 0; k < record.size(); ++k)
        same = same && e.scalars[k].first == record[k].first && sameType(e.scalars[k].second, record[k].second);
      if (same) blocks.vertices = VertexFile{path, offset, e.count, true};
    }
    if (e.name == "face") {
      if (e.properties == 1 && e.triangleList) blocks.faces = FaceFile{path, offset, e.count, true};
      return blocks;
    }
    if (!e.fixed) return blocks;
    offset += e.count * e.size;
  }
  return blocks;
}

// STL is a triangle soup: three new vertices per triangle. Vertices with bit-identical positions
// are welded (out of core: sort by position, then rewrite the corners in vertex order), so the
// store holds a connected mesh; the duplicates stay in vert.bin, unreferenced. Returns the count
// of vertices merged into an earlier one. `budget`: each of its two sorters' (alive together).
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
  ExternalSorter<PosRec, PosLess> byPosition(scratch + "/w1", budget, {}, true);
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
  ExternalSorter<MapRec, MapLess> byVertex(scratch + "/w2", budget, {}, true);
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

// The reader on its own thread; this one runs the Morton pipeline over its chunks (codes in
// parallel, added to the sort in face order) until the reader is done.
ReadStats readFused(MeshReader& reader, ScratchSink& sink, MortonSort& morton, const VertexRecordLayout& layout) {
  ReadStats stats;
  ChunkQueue queue(8);
  sink.fuse(&queue);
  std::exception_ptr readError;
  std::thread readerThread([&] {
    try {
      stats = reader.read(sink);
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
    auto pop = [&](tbb::flow_control& fc) -> Token* {
      Token* t = &pool[nextToken++ % tokens];
      if (!queue.pop(t->chunk, t->first)) {
        fc.stop();
        return nullptr;
      }
      return t;
    };
    auto codes = [&](Token* t) {
      const ResidentVertices rv{queue.records(), layout, layout.size()};
      const MortonBox box(queue.bounds());
      const uint32_t* idx = t->chunk->data();
      const size_t n = t->chunk->size() / 3;
      t->keys.resize(n);
      for (size_t i = 0; i < n; ++i)
        t->keys[i] = MortonSort::codeOf(rv, box, idx + 3 * i, t->first + i, i + 16 < n ? idx + 3 * (i + 16) : nullptr);
      return t;
    };
    auto add = [&](Token* t) {
      morton.add(t->keys.data(), t->keys.size(), t->first);
      queue.release(t->chunk);
    };
    tbb::parallel_pipeline(tokens, tbb::make_filter<void, Token*>(tbb::filter_mode::serial_in_order, pop) &
                                       tbb::make_filter<Token*, Token*>(tbb::filter_mode::parallel, codes) &
                                       tbb::make_filter<Token*, void>(tbb::filter_mode::serial_in_order, add));
  } catch (...) {
    queue.cancel();
    readerThread.join();
    throw;
  }
  readerThread.join();
  if (readError) std::rethrow_exception(readError);
  return stats;
}

// Whether the face block read in place is exactly the faces the reader delivered: triangles only
// (no polygon was fanned), the declared count, the same first and last faces.
bool sameFacesInPlace(const FaceFile& inPlace, const ScratchSink& sink, const ReadStats& stats) {
  if (stats.polygons != 0 || stats.triangles != inPlace.count) return false;
  auto facesAt = [&](uint64_t first, uint64_t n) {
    FaceFile part = inPlace;
    part.offset += first * 13;
    part.count = n;
    FaceReader r(part);
    std::vector<uint32_t> out, batch;
    while (out.size() < 3 * n && r.getBatch(batch, size_t(n))) out.insert(out.end(), batch.begin(), batch.end());
    return out;
  };
  const std::vector<uint32_t> last = sink.lastFaces();
  try {
    return facesAt(0, sink.firstFaces().size() / 3) == sink.firstFaces() &&
           facesAt(inPlace.count - last.size() / 3, last.size() / 3) == last;
  } catch (const Error&) {  // not where the header said: copy them instead
    return false;
  }
}

// Whether the vertex block read in place holds the records the reader delivered: the count, the
// same first and last records.
bool sameVerticesInPlace(const VertexFile& inPlace, const ScratchSink& sink) {
  const size_t size = sink.layout.size();
  if (inPlace.count != sink.vertexCount || sink.firstVertexRecords().empty()) return false;
  auto recordsAt = [&](uint64_t first, size_t bytes) {
    std::vector<char> out(bytes);
    TempReader r(inPlace.path, 1 << 16, inPlace.offset + first * size, bytes);
    return r.read(out.data(), bytes) == bytes ? out : std::vector<char>();
  };
  const std::vector<char> last = sink.lastVertexRecords();
  try {
    return recordsAt(0, sink.firstVertexRecords().size()) == sink.firstVertexRecords() &&
           recordsAt(inPlace.count - last.size() / size, last.size()) == last;
  } catch (const Error&) {
    return false;
  }
}

// The vertex records as the reader gives them, in a second read, to scratch/vert.bin.
void copyVertices(const std::string& input, const std::string& scratch, const VertexRecordLayout& layout) {
  struct VerticesOnly : MeshSink {
    TempWriter out;
    VertexRecordLayout layout;
    std::vector<char> rec;
    VerticesOnly(const std::string& path, const VertexRecordLayout& l) : out(path, 4 << 20), layout(l), rec(l.size()) {}
    void vertices(const InputVertex* v, size_t count, uint64_t) override {
      for (size_t i = 0; i < count; ++i) {
        layout.encode(v[i], rec.data());
        out.write(rec.data(), rec.size());
      }
    }
    void triangles(const uint32_t*, size_t) override {}
  } verticesOnly(scratch + "/vert.bin", layout);
  openMesh(input)->read(verticesOnly);
  verticesOnly.out.close();
}

// Polygons (or anything unexpected in a face block read in place): the faces as the reader gives
// them, in a second read, to scratch/face.bin.
void copyFaces(const std::string& input, const std::string& scratch) {
  struct FacesOnly : MeshSink {
    TempWriter out;
    explicit FacesOnly(const std::string& path) : out(path, 4 << 20) {}
    void vertices(const InputVertex*, size_t, uint64_t) override {}
    void triangles(const uint32_t* idx, size_t count) override { out.write(idx, count * 12); }
  } facesOnly(scratch + "/face.bin");
  openMesh(input)->read(facesOnly);
  facesOnly.out.close();
}

void reportRead(const MeshHeader& header, const ReadStats& stats, IngestReport& report) {
  report.format = formatName(header.format);
  report.inputVertices = stats.vertices;
  report.inputTriangles = stats.triangles;
  report.inputBytes = stats.bytes;
  report.polygons = stats.polygons;
  report.degenerateTriangles = stats.degenerateTriangles;
}

}  // namespace

ParsedInput parseInput(const std::string& input, IngestContext& ctx) {
  // Per-corner texture coordinates are split into wedges with scratch files here (wedge_split.cpp).
  auto reader = openMesh(input, MeshOpenOptions{ctx.scratch, ctx.plan.soupWeldSorter});
  const MeshHeader& header = reader->header();
  const VertexRecordLayout expected{header.doublePrecision, header.hasNormals, header.hasColors, header.hasTexcoords};
  // The records stay in RAM when they fit the plan's limit (its reserve covers what the resident
  // passes hold besides the records at their peak: sort buffers, which shrink to fit, the
  // assigner's seeds and tables, the process itself).
  const uint64_t residentLimit = ctx.plan.residentRecordLimit(expected.size());
  Progress parseProgress(ctx.progress, "ingest: parse", uint64_t(std::max<int64_t>(0, header.declaredFaces)));
  ScratchSink sink(ctx.scratch, parseProgress, residentLimit);
  // A binary PLY of triangles: its faces are read in place later, not copied; and when its
  // vertices take the chunked path, so are they, if their records are vert.bin's.
  std::optional<FaceFile> inPlace;
  std::optional<VertexFile> verticesInPlace;
  // Texture seams split the file's vertices into wedges: its records and indices are not the store's.
  if (header.format == MeshFormat::PlyBinaryLE && header.declaredVertices >= 0 && !header.splitAtSeams) {
    PlyBlocks blocks = plyBlocks(input, expected);
    inPlace = blocks.faces;
    if (inPlace && int64_t(inPlace->count) != header.declaredFaces) inPlace.reset();
    if (inPlace) sink.skipFaceFile();
    if (uint64_t(header.declaredVertices) * expected.size() > residentLimit && blocks.vertices &&
        int64_t(blocks.vertices->count) == header.declaredVertices) {
      verticesInPlace = blocks.vertices;
      sink.skipVertexFile();
    }
  }
  // The Morton sort of the resident path, filled during the parse when the input allows it; its
  // budget is what the declared vertex records leave (with 64 MiB for the parse's buffers).
  const uint64_t declaredRecords = uint64_t(std::max<int64_t>(0, header.declaredVertices)) * expected.size();
  ParsedInput in;
  in.morton = std::make_unique<MortonSort>(ctx.scratch + "/m0", ctx.plan.residentSorter(declaredRecords, 64ull << 20));
  ReadStats stats;
  if (residentLimit > 0) {
    stats = readFused(*reader, sink, *in.morton, expected);
  } else {
    stats = reader->read(sink);
    sink.close();
  }
  parseProgress.finish(stats.triangles);
  reportRead(header, stats, ctx.report);
  if (stats.triangles == 0) fail(input, "mesh has no triangles");
  if (stats.triangles > 0xFFFFFFF0ull) fail(input, "more than 4 billion triangles are not supported");
  in.layout = sink.layout;
  in.materials = header.materials;
  in.bounds = sink.bounds;
  in.vertices = sink.vertexCount;
  in.faces = sink.faceCount;
  assert(stats.triangles == in.faces);  // the sink saw every triangle the reader counted
  if (header.format == MeshFormat::StlAscii || header.format == MeshFormat::StlBinary) {
    Progress progress(ctx.progress, "ingest: weld", in.vertices, "vert");
    ctx.report.weldedVertices = weldSoup(ctx.scratch, in.layout, in.vertices, ctx.plan.soupWeldSorter);
    progress.finish(in.vertices);
  }
  if (!sink.wroteVertexFile() && !sameVerticesInPlace(*verticesInPlace, sink)) {
    copyVertices(input, ctx.scratch, in.layout);
    verticesInPlace.reset();
  }
  if (!sink.inRam() && in.vertices * in.layout.size() <= residentLimit) {
    assert(!verticesInPlace);  // only records beyond the limit are left in place
    sink.loadVertices(ctx.scratch);
  }
  in.resident = sink.inRam();
  if (!sink.wroteFaceFile() && !sameFacesInPlace(*inPlace, sink, stats)) {
    copyFaces(input, ctx.scratch);
    inPlace.reset();
  }
  if (inPlace) inPlace->vertices = in.vertices;
  in.faceFile = inPlace ? *inPlace : FaceFile{ctx.scratch + "/face.bin", 0, in.faces, false};
  in.vertexFile = verticesInPlace ? *verticesInPlace : VertexFile{ctx.scratch + "/vert.bin", 0, in.vertices, false};
  if (!in.resident) {
    ctx.report.verticesInPlace = bool(verticesInPlace);
    ctx.report.facesInPlace = bool(inPlace);
  }
  if (in.resident) in.records = sink.takeVertices();
  ctx.clock.mark("parse");
  return in;
}

}  // namespace ingest
}  // namespace mt
