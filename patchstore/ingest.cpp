// Ingest: a mesh file of any size into a new patch store, within the --memory cap.
//
// Every pass is sequential over scratch files or an external sort, so memory depends on the cap,
// not on the input (BMT section 6 needs the store to exist before anything fits in RAM):
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
//   7 boundary   grouped by vertex -> (p, vp, q, vq) sorted by p -> one boundary block per patch
// Determinism: every sort key is total, so the store does not depend on the cap or thread count.
#include <malloc.h>
#include <tbb/parallel_for.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cinttypes>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <limits>
#include <sstream>

#include "patchstore/byte_io.h"
#include "patchstore/external_sort.h"
#include "patchstore/progress.h"
#include "patchstore/store_impl.h"
#include "patchstore/temp_file.h"

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

// Stage 1 sink: writes scratch files, tracks the bounding box.
class ScratchSink : public MeshSink {
 public:
  ScratchSink(const std::string& dir, Progress& progress) : vert_(dir + "/vert.bin", 4 << 20), face_(dir + "/face.bin", 4 << 20), progress_(progress) {}
  void begin(const MeshHeader& h) override {
    header = h;
    layout = {h.doublePrecision, h.hasNormals, h.hasColors};
    record_.resize(layout.size());
    for (int a = 0; a < 3; ++a) {
      bounds.lo[a] = std::numeric_limits<double>::infinity();
      bounds.hi[a] = -std::numeric_limits<double>::infinity();
    }
  }
  void vertices(const InputVertex* v, size_t count, uint64_t) override {
    for (size_t i = 0; i < count; ++i) {
      layout.encode(v[i], record_.data());
      vert_.write(record_.data(), record_.size());
      for (int a = 0; a < 3; ++a) {
        bounds.lo[a] = std::min(bounds.lo[a], v[i].p[a]);
        bounds.hi[a] = std::max(bounds.hi[a], v[i].p[a]);
      }
    }
    vertexCount += count;
  }
  void triangles(const uint32_t* idx, size_t count) override {
    face_.write(idx, count * 12);
    faceCount += count;
    progress_.update(faceCount);
  }
  void close() {
    vert_.close();
    face_.close();
  }
  MeshHeader header;
  VertexRecordLayout layout{};
  Box3 bounds;
  uint64_t vertexCount = 0, faceCount = 0;

 private:
  TempWriter vert_, face_;
  Progress& progress_;
  std::vector<char> record_;
};

struct Centroid {
  float x, y, z, area;
};

// Centroid and area of a triangle, independent of corner order (corners summed in ascending
// index order), so that duplicate faces always land in the same cell.
Centroid centroidOf(const uint32_t v[3], const float* const p[3]) {
  int order[3] = {0, 1, 2};
  std::sort(order, order + 3, [&](int a, int b) { return v[a] < v[b]; });
  double c[3], e1[3], e2[3];
  for (int a = 0; a < 3; ++a) {
    c[a] = (double(p[order[0]][a]) + double(p[order[1]][a]) + double(p[order[2]][a])) / 3.0;
    e1[a] = double(p[order[1]][a]) - double(p[order[0]][a]);
    e2[a] = double(p[order[2]][a]) - double(p[order[0]][a]);
  }
  double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
  return {float(c[0]), float(c[1]), float(c[2]), float(0.5 * std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]))};
}

// 21 bits per axis interleaved: the Morton (Z-order) code of a point in the box.
uint64_t mortonCode(const float c[3], const Box3& box) {
  uint64_t code = 0;
  uint32_t q[3];
  for (int a = 0; a < 3; ++a) {
    double extent = box.hi[a] - box.lo[a];
    double t = extent > 0 ? (double(c[a]) - box.lo[a]) / extent : 0;
    q[a] = uint32_t(std::clamp(t, 0.0, 1.0) * double((1u << 21) - 1));
  }
  // Bit b of axis a goes to bit 3b + 2 - a (axis 0 most significant of each triple), spread with
  // the usual magic masks instead of a 63-step loop.
  auto spread = [](uint64_t x) {
    x &= 0x1fffff;
    x = (x | x << 32) & 0x1f00000000ffffull;
    x = (x | x << 16) & 0x1f0000ff0000ffull;
    x = (x | x << 8) & 0x100f00f00f00f00full;
    x = (x | x << 4) & 0x10c30c30c30c30c3ull;
    x = (x | x << 2) & 0x1249249249249249ull;
    return x;
  };
  code = spread(q[0]) << 2 | spread(q[1]) << 1 | spread(q[2]);
  return code;
}

// A face with its centroid, keyed by Morton code (ties: face index, so the order is total).
struct MortonFace {
  uint64_t code;
  uint32_t face;
  uint32_t v[3];
  Centroid c;
};
struct MortonLess {
  bool operator()(const MortonFace& a, const MortonFace& b) const {
    return a.code != b.code ? a.code < b.code : a.face < b.face;
  }
};
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
                      uint64_t budget, const Box3& box, ExternalSorter<MortonFace, MortonLess>& sorter,
                      bool showProgress) {
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
      m.code = mortonCode(&m.c.x, box);
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
            m.code = mortonCode(&m.c.x, box);
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
struct EntryLess {
  bool operator()(const EntryRec& a, const EntryRec& b) const {
    return a.key != b.key ? a.key < b.key : a.neighbour != b.neighbour ? a.neighbour < b.neighbour : a.remote < b.remote;
  }
};
struct EdgeRec {
  uint64_t key;  // lower vertex << 32 | higher vertex
  uint32_t count, pad;
};
struct EdgeLess {
  bool operator()(const EdgeRec& a, const EdgeRec& b) const { return a.key != b.key ? a.key < b.key : a.count < b.count; }
};

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
  ExternalSorter<PosRec, PosLess> byPosition(scratch + "/w1", budget / 2);
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
  byPosition.finish();
  ExternalSorter<MapRec, MapLess> byVertex(scratch + "/w2", budget / 2);
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

// Per-stage wall and CPU seconds (all threads) on stderr with the progress lines, so that the
// stages can be compared on a busy machine, where wall time says little (bench/ingest.sh).
class StageClock {
 public:
  explicit StageClock(bool enabled) : enabled_(enabled) { reset(); }
  void mark(const char* stage) {
    if (!enabled_) return;
    double wall = now(), cpu = cpuSeconds();
    std::fprintf(stderr, "ingest: stage %s: %.2f s wall, %.2f s cpu\n", stage, wall - wall_, cpu - cpu_);
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

// The main ingest body, building the store in `dir` (already created, empty).
template <bool Full>
IngestReport build(const std::string& input, const std::string& dir, const std::string& scratch, CellAssigner& assigner,
                   const IngestOptions& opt, Env* env) {
  using Clock = std::chrono::steady_clock;
  auto t0 = Clock::now();
  IngestReport report;
  report.input = input;
  const uint64_t B = opt.memoryBytes;
  // The cap is about RSS, and glibc's dynamic mmap threshold would serve later multi-MiB buffers
  // from the heap, where freed memory stays resident behind live blocks: keep every buffer of a
  // MiB or more in its own mapping, so that what a pass frees leaves the process at once.
  mallopt(M_MMAP_THRESHOLD, 1 << 20);
  auto endOfPass = [] { malloc_trim(0); };
  StageClock clock(opt.progress);

  // 1 parse
  auto reader = openMesh(input);
  Progress parseProgress(opt.progress, "ingest: parse", uint64_t(std::max<int64_t>(0, reader->header().declaredFaces)));
  ScratchSink sink(scratch, parseProgress);
  ReadStats stats = reader->read(sink);
  sink.close();
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

  clock.mark("parse");
  // 2 centroids, straight into an external sort by Morton code. The assigner streams the
  // centroids in Morton order rather than face order: its passes (the irregular seeding) rely on
  // consecutive triangles being close, which a scan with shuffled faces does not give, and the
  // assign stage then looks cells up in spatially coherent order (cache hits instead of random
  // reads of the seed tables). Deterministic: ties by face.
  {
    ExternalSorter<MortonFace, MortonLess> byCode(scratch + "/s0", B / 4);
    computeCentroids(scratch, vlayout, nv, nf, B * 2 / 5, sink.bounds, byCode, opt.progress);
    std::remove((scratch + "/face.bin").c_str());
    endOfPass();
    clock.mark("centroids");
    byCode.finish();
    TempWriter out(scratch + "/morton.bin", 4 << 20);
    MortonFace m;
    while (byCode.next(m)) out.put(FaceCentroid{m.face, {m.v[0], m.v[1], m.v[2]}, m.c});
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
  ExternalSorter<FaceRec, FaceLess> byCell(scratch + "/s1", B / 4);
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
  byCell.finish();
  std::vector<uint64_t> patchKey;
  std::vector<uint32_t> patchTris;
  ExternalSorter<uint64_t, U64Less> pairs(scratch + "/s2", B / 4);
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
  pairs.finish();
  ExternalSorter<VertexData<Full>, KeyLess<VertexData<Full>>> byPatch(scratch + "/s3", B / 4);
  uint64_t distinctReferenced = 0;
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
  byPatch.finish();
  auto impl = std::make_unique<PatchStore::Impl>();
  impl->env = env;
  impl->dir = dir;
  impl->layout = {vlayout.doublePrecision, vlayout.normals, vlayout.colors};
  impl->bounds = sink.bounds;
  ExternalSorter<LocalRec, KeyLess<LocalRec>> shared(scratch + "/s4", B / 8);
  ExternalSorter<EdgeRec, EdgeLess> edges(scratch + "/s5", B / 16);
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
  report.unreferencedVertices = nv - distinctReferenced - report.weldedVertices;
  std::remove((scratch + "/pface.bin").c_str());

  endOfPass();
  clock.mark("patches");
  // Edges shared between patches: sum their uses.
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
  shared.finish();
  ExternalSorter<EntryRec, EntryLess> entries(scratch + "/s6", B / 8);
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
      for (auto& a : group)
        for (auto& b : group)
          if (a.first != b.first) entries.add({uint64_t(a.first) << 32 | a.second, b.first, b.second});
    }
  }
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

IngestReport PatchStore::ingest(const std::string& input, const std::string& dirIn, CellAssigner& assigner,
                                const IngestOptions& options, Env* env) {
  std::string dir = dirIn;
  while (dir.size() > 1 && dir.back() == '/') dir.pop_back();
  if (env->exists(dir) && !(fs::is_directory(dir) && fs::is_empty(dir)))
    fail(dir, "already exists (remove it or choose another store directory)");
  std::string building = dir + ".ingest-" + std::to_string(getpid());
  std::error_code ec;
  fs::remove_all(building, ec);
  env->createDir(building);
  std::string scratch = options.tempDir.empty() ? building + "/tmp" : options.tempDir + "/mt-ingest-" + std::to_string(getpid());
  try {
    env->createDir(scratch);
    // Peek at the header to pick the record type; the reader is reopened by build().
    const MeshHeader header = openMesh(input)->header();
    bool full = header.doublePrecision || header.hasNormals || header.hasColors;
    IngestReport report = full ? build<true>(input, building, scratch, assigner, options, env)
                               : build<false>(input, building, scratch, assigner, options, env);
    fs::remove_all(scratch, ec);
    if (env->exists(dir)) fs::remove(dir, ec);  // the empty directory the user pointed at
    env->renameFile(building, dir);
    env->syncDir(fs::path(dir).parent_path().empty() ? "." : fs::path(dir).parent_path().string());
    return report;
  } catch (...) {
    fs::remove_all(scratch, ec);
    fs::remove_all(building, ec);
    throw;
  }
}

}  // namespace mt
