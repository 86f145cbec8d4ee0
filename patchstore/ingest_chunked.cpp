// Ingest, the chunked path (stages 2-6, see ingest.cpp): bounded by the cap whatever the input
// size; every pass streams scratch files through external sorts.
#include <malloc.h>
#include <tbb/parallel_for.h>

#include <array>
#include <functional>

#include "base/progress.h"
#include "patchstore/ingest_internal.h"

namespace mt {
namespace ingest {
namespace {

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
class CentroidPass {
 public:
  struct Pending {
    uint32_t face;
    uint32_t v[3];
    float p[9];
    uint32_t resolved;  // bit mask of corners with positions
  };
  CentroidPass(const std::string& dir, const MortonBox& morton, MortonFaceSorter& sorter, uint64_t lo, uint64_t hi,
               const std::vector<float>& pos)
      : dir_(dir), morton_(morton), sorter_(sorter), lo_(lo), hi_(hi), pos_(pos) {}
  // Carried faces come from `in` (the previous pass's carry file, or none) and go to `out` (none
  // on the last pass, where every face must resolve).
  void carry(TempReader* in, TempWriter* out) {
    carryIn_ = in;
    carryOut_ = out;
  }
  // One scan of the faces, in face order: faces wholly in this chunk are computed in parallel
  // (centroid and Morton code); faces spanning chunks that touch this one are resolved as far as
  // this chunk allows (new ones start here, earlier ones come from the carry file, which is in
  // face order too). Returns the faces completed.
  uint64_t run(Progress& progress, uint64_t done) {
    TempReader fr(dir_ + "/face.bin", 4 << 20);
    std::vector<uint32_t> batch;
    uint32_t face = 0;
    while (fr.getBatch(batch, 3 * 65536)) {
      const size_t n = batch.size() / 3;
      computeWhole(batch, face);
      for (size_t i = 0; i < n; ++i, ++face) {
        if (kind_[i] == 1) {
          sorter_.add(recs_[i]);
          ++done;
        } else if (kind_[i] == 2) {
          Pending f;
          if (std::min({batch[3 * i], batch[3 * i + 1], batch[3 * i + 2]}) >= lo_) {
            f = Pending{face, {batch[3 * i], batch[3 * i + 1], batch[3 * i + 2]}, {}, 0};
          } else if (!carryIn_ || !carryIn_->get(f) || f.face != face) {
            fail(dir_, "internal: carried face " + std::to_string(face) + " out of order");
          }
          done += resolve(f);
        }
      }
      progress.update(done);
    }
    return done;
  }

 private:
  // kind_[i] for the batch: 0 not this pass, 1 wholly in this chunk (recs_[i] computed), 2 spanning.
  void computeWhole(const std::vector<uint32_t>& batch, uint32_t first) {
    const size_t n = batch.size() / 3;
    recs_.resize(n);
    kind_.resize(n);
    const uint64_t lo = lo_, hi = hi_;
    const std::vector<float>& pos = pos_;
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
          kind_[i] = 1;
          const float* p[3] = {&pos[size_t(v[0] - lo) * 3], &pos[size_t(v[1] - lo) * 3], &pos[size_t(v[2] - lo) * 3]};
          MortonFace& m = recs_[i];
          m.face = first + uint32_t(i);
          std::memcpy(m.v, v, 12);
          m.c = centroidOf(v, p);
          m.code = morton_.code(&m.c.x);
        } else {
          kind_[i] = (vmin < hi && vmax >= lo) ? 2 : 0;
        }
      }
    });
  }
  // A spanning face: its corners in this chunk filled in; complete, it goes to the sorter (1),
  // else to the carry file (0).
  uint64_t resolve(Pending& f) {
    for (int k = 0; k < 3; ++k)
      if (!(f.resolved & (1u << k)) && f.v[k] >= lo_ && f.v[k] < hi_) {
        std::memcpy(&f.p[3 * k], &pos_[(f.v[k] - lo_) * 3], 12);
        f.resolved |= 1u << k;
      }
    if (f.resolved != 7) {
      if (!carryOut_) fail(dir_, "internal: unresolved face corner");
      carryOut_->put(f);
      return 0;
    }
    const float* p[3] = {&f.p[0], &f.p[3], &f.p[6]};
    MortonFace m{0, f.face, {f.v[0], f.v[1], f.v[2]}, centroidOf(f.v, p)};
    m.code = morton_.code(&m.c.x);
    sorter_.add(m);
    return 1;
  }

  const std::string& dir_;
  const MortonBox& morton_;
  MortonFaceSorter& sorter_;
  uint64_t lo_, hi_;
  const std::vector<float>& pos_;
  TempReader* carryIn_ = nullptr;
  TempWriter* carryOut_ = nullptr;
  std::vector<MortonFace> recs_;
  std::vector<uint8_t> kind_;
};

// The float positions of vertices [lo, hi), read on from vr (chunks are read in order: one
// sequential pass over vert.bin).
void loadPositions(TempReader& vr, const std::string& dir, const VertexRecordLayout& layout, uint64_t lo, uint64_t hi,
                   std::vector<float>& pos) {
  pos.resize((hi - lo) * 3);
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

void computeCentroids(const std::string& dir, const ParsedInput& in, uint64_t budget, MortonFaceSorter& sorter, bool showProgress) {
  const MortonBox morton(in.bounds);
  const uint64_t chunk = std::max<uint64_t>(1 << 16, budget / 12);
  const uint64_t chunks = (in.vertices + chunk - 1) / chunk;
  Progress progress(showProgress, "ingest: centroids", in.faces);
  std::vector<float> pos;
  uint64_t done = 0;
  TempReader vr(dir + "/vert.bin", 4 << 20);
  for (uint64_t c = 0; c < chunks; ++c) {
    const uint64_t lo = c * chunk, hi = std::min(in.vertices, lo + chunk);
    loadPositions(vr, dir, in.layout, lo, hi, pos);
    std::unique_ptr<TempReader> carryIn;
    std::unique_ptr<TempWriter> carryOut;
    std::string carryInPath = dir + "/carry" + std::to_string(c - 1);
    if (c > 0) carryIn = std::make_unique<TempReader>(carryInPath, 1 << 20);
    if (c + 1 < chunks) carryOut = std::make_unique<TempWriter>(dir + "/carry" + std::to_string(c), 1 << 20);
    CentroidPass pass(dir, morton, sorter, lo, hi, pos);
    pass.carry(carryIn.get(), carryOut.get());
    done = pass.run(progress, done);
    if (carryOut) carryOut->close();
    carryIn.reset();
    if (c > 0) std::remove(carryInPath.c_str());
  }
  if (done != in.faces) fail(dir, "internal: " + std::to_string(in.faces - done) + " centroids missing");
  progress.finish(in.faces);
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
  uint32_t material;  // texture coordinates (textured inputs): the material, then u, v
  double p[3];
  float n[3];
  uint8_t c[4];
  float uv[2];
};
template <class T>
struct KeyLess {
  bool operator()(const T& a, const T& b) const { return a.key < b.key; }
};

void endOfPass(IngestContext& ctx, const char* stage) {
  malloc_trim(0);
  ctx.clock.mark(stage);
}

// Stage 2: centroids, straight into an external sort by Morton code, merged once into morton.bin.
// The assigner streams the centroids in Morton order rather than face order: its passes (the
// irregular seeding) rely on consecutive triangles being close, which a scan with shuffled faces
// does not give, and the assign stage then looks cells up in spatially coherent order (cache hits
// instead of random reads of the seed tables). Deterministic: ties by face.
void chunkedCentroids(IngestContext& ctx, const ParsedInput& in) {
  MortonFaceSorter byCode(ctx.scratch + "/s0", ctx.plan.chunkedSorter, MortonFaceCode{}, 63, true);
  computeCentroids(ctx.scratch, in, ctx.plan.chunkedPositions, byCode, ctx.progress);
  std::remove((ctx.scratch + "/face.bin").c_str());
  endOfPass(ctx, "centroids");
  checkInterrupt("ingest: sort");
  byCode.finish();
  TempWriter out(ctx.scratch + "/morton.bin", 4 << 20);
  uint64_t written = 0;
  forEachInMortonOrder(byCode, [&](const MortonFace& m) {
    out.put(FaceCentroid{m.face, {m.v[0], m.v[1], m.v[2]}, m.c});
    ++written;
  });
  out.close();
  assert(written == in.faces);  // the sort kept every face
}

using CellSorter = ExternalSorter<FaceRec, FaceLess>;

// Stage 3: the assigner prepared (the irregular V-partition reads the stream once, a sample:
// vpartition/irregular.cpp; its time is reported apart from the sorts'), then every face keyed in
// Morton order; faces externally sorted by (cell key, face).
std::unique_ptr<CellSorter> chunkedAssign(IngestContext& ctx, const ParsedInput& in) {
  const uint64_t nf = in.faces;
  CentroidFile centroids(ctx.scratch + "/morton.bin", nf, in.bounds);
  {
    Progress progress(ctx.progress, "ingest: partition", nf);
    ctx.assigner.prepare(centroids, ctx.plan.assigner);
    progress.finish(nf);
  }
  ctx.report.assigner = ctx.assigner.describe();
  endOfPass(ctx, "partition");
  auto byCell = std::make_unique<CellSorter>(ctx.scratch + "/s1", ctx.plan.chunkedSorter, FaceLess{}, true);
  Progress progress(ctx.progress, "ingest: assign", nf);
  TempReader cr(ctx.scratch + "/morton.bin", 4 << 20);
  std::vector<FaceCentroid> batch;
  std::vector<FaceRec> recs;
  uint64_t done = 0;
  while (cr.getBatch(batch, 65536)) {
    recs.resize(batch.size());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, batch.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t i = r.begin(); i < r.end(); ++i) {
        const FaceCentroid& f = batch[i];
        recs[i] = FaceRec{ctx.assigner.cellKey(&f.c.x), f.face, {f.v[0], f.v[1], f.v[2]}};
      }
    });
    for (const FaceRec& r : recs) byCell->add(r);
    done += batch.size();
    progress.update(done);
  }
  if (done != nf) fail(ctx.scratch, "internal: Morton file holds " + std::to_string(done) + " faces");
  progress.finish(done);
  std::remove((ctx.scratch + "/morton.bin").c_str());
  endOfPass(ctx, "assign");
  return byCell;
}

// Per-thread scratch of buildPatch and chunkedGroup (reused from patch to patch).
struct ChunkedScratch {
  std::vector<uint64_t> table, keys, tmp;
};
ChunkedScratch& chunkedScratch() {
  thread_local ChunkedScratch s;
  return s;
}
inline unsigned bitWidth(uint64_t x) { return x == 0 ? 1 : unsigned(64 - __builtin_clzll(x)); }

// The distinct values of `values`, ascending, into `out`. A patch's corners span a narrow range
// of input indices in a scan: a bit set over the range, marked and read back in order, costs no
// sort of the three corners per triangle; a wide range (a shuffled input) is sorted.
void distinctSorted(const std::vector<uint32_t>& values, std::vector<uint32_t>& out) {
  out.clear();
  if (values.empty()) return;
  auto [lo, hi] = std::minmax_element(values.begin(), values.end());
  const uint32_t base = *lo;
  const uint64_t range = uint64_t(*hi) - base + 1;
  if (range > 16 * uint64_t(values.size())) {
    out = values;
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
    return;
  }
  std::vector<uint64_t>& bits = chunkedScratch().keys;
  bits.assign(size_t((range + 63) / 64), 0);
  for (uint32_t v : values) bits[(v - base) >> 6] |= uint64_t(1) << ((v - base) & 63);
  for (size_t w = 0; w < bits.size(); ++w)
    for (uint64_t x = bits[w]; x; x &= x - 1) out.push_back(base + uint32_t(w * 64 + unsigned(__builtin_ctzll(x))));
}

using PairSorter = ExternalSorter<uint64_t, U64Less>;

// Stage 4: consecutive keys become patches 0..P-1 -> pface.bin (their corners), patchTris (their
// triangle counts); unique (vertex, patch) pairs externally sorted by vertex. Patches are gathered
// in batches; their distinct vertices are found in parallel and written in patch order (the
// result does not depend on the thread count).
std::unique_ptr<PairSorter> chunkedGroup(IngestContext& ctx, CellSorter& byCell, std::vector<uint32_t>& patchTris,
                                         PatchStageOutput& out) {
  checkInterrupt("ingest: sort");
  byCell.finish();
  std::vector<uint64_t>& patchKey = out.patchKey;
  auto pairs = std::make_unique<PairSorter>(ctx.scratch + "/s2", ctx.plan.chunkedSorter, U64Less{}, true);
  TempWriter pface(ctx.scratch + "/pface.bin", 4 << 20);
  constexpr size_t kBatch = 64;
  std::vector<std::vector<uint32_t>> tris(kBatch), verts(kBatch);
  size_t filled = 0;
  auto flush = [&]() {
    tbb::parallel_for(size_t(0), filled, [&](size_t i) { distinctSorted(tris[i], verts[i]); });
    for (size_t i = 0; i < filled; ++i) {
      const uint32_t k = uint32_t(patchKey.size() - filled + i);
      pface.write(tris[i].data(), tris[i].size() * 4);
      patchTris.push_back(uint32_t(tris[i].size() / 3));
      for (uint32_t v : verts[i]) pairs->add(uint64_t(v) << 32 | k);
      tris[i].clear();
    }
    filled = 0;
  };
  FaceRec f;
  while (byCell.next(f)) {
    if (patchKey.empty() || patchKey.back() != f.key) {
      assert(patchKey.empty() || patchKey.back() < f.key);  // the sort gives ascending keys
      if (filled == kBatch) flush();
      patchKey.push_back(f.key);
      ++filled;
    }
    tris[filled - 1].insert(tris[filled - 1].end(), f.v, f.v + 3);
  }
  flush();
  pface.close();
  assert(patchTris.size() == patchKey.size());
  ctx.clock.mark("group");
  return pairs;
}

template <bool Full>
using PatchSorter = ExternalSorter<VertexData<Full>, KeyLess<VertexData<Full>>>;

// The data of vertex record `rec` for every patch that holds it.
template <bool Full>
VertexData<Full> vertexData(const VertexRecordLayout& layout, const char* rec, uint32_t holders) {
  VertexData<Full> d{};
  d.holders = holders;
  if constexpr (Full) {
    layout.position(rec, d.p);
    rec += layout.doublePrecision ? 24 : 12;
    if (layout.normals) {
      std::memcpy(d.n, rec, 12);
      rec += 12;
    }
    if (layout.colors) std::memcpy(d.c, rec, 4);
    if (layout.texcoords) {
      std::memcpy(d.uv, rec + (layout.colors ? 4 : 0), 8);
      std::memcpy(&d.material, rec + (layout.colors ? 4 : 0) + 8, 4);
    }
  } else {
    std::memcpy(d.p, rec, 12);
  }
  return d;
}

// Stage 5: the (vertex, patch) pairs merge-joined with vert.bin -> (patch, vertex, data) sorted
// by patch. Counts the vertices some face uses.
template <bool Full>
std::unique_ptr<PatchSorter<Full>> chunkedJoin(IngestContext& ctx, const ParsedInput& in, PairSorter& pairs,
                                               PatchStageOutput& out) {
  checkInterrupt("ingest: sort");
  pairs.finish();
  auto byPatch = std::make_unique<PatchSorter<Full>>(ctx.scratch + "/s3", ctx.plan.chunkedSorter, KeyLess<VertexData<Full>>{}, true);
  Progress progress(ctx.progress, "ingest: vertices", in.vertices, "vert");
  TempReader vr(ctx.scratch + "/vert.bin", 4 << 20);
  std::vector<char> rec(in.layout.size());
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
    ++out.distinctReferenced;
    assert(v >= nextVertex || nextVertex == 0);  // pairs come by ascending vertex
    for (; nextVertex <= v; ++nextVertex)
      if (vr.read(rec.data(), rec.size()) != rec.size()) fail(ctx.scratch, "vertex scratch file is short");
    VertexData<Full> d = vertexData<Full>(in.layout, rec.data(), uint32_t(holders.size()));
    for (uint32_t k : holders) {
      d.key = uint64_t(k) << 32 | v;
      byPatch->add(d);
    }
    progress.update(nextVertex);
  }
  progress.finish(in.vertices);
  std::remove((ctx.scratch + "/vert.bin").c_str());
  endOfPass(ctx, "vertices");
  return byPatch;
}

// One patch of the chunked path, built on a worker thread; written in patch order.
struct PatchWork {
  Patch p;
  std::vector<uint32_t> globalIds, holders;
  std::string payload;
  uint64_t duplicates = 0, nonManifold = 0;
  std::vector<EdgeRec> crossEdges;  // edges between two shared vertices: may continue elsewhere
};

// The geometry block of one patch (local order = ascending input index), its duplicate faces and
// edge use counts; edges between two shared vertices go to w.crossEdges, to be summed over patches.
// Corners find their local index in a hash table of the patch's vertices (a binary search per
// corner was the largest part of the chunked path's patch stage); duplicate faces and edges are
// counted from keys packed in k bits per local index and radix sorted (the orders, and so the
// cross-edge order, are those of the comparison sorts they replace).
void buildPatch(PatchWork& w, const VertexLayout& layout, const std::string& scratch) {
  Patch& p = w.p;
  ChunkedScratch& s = chunkedScratch();
  const uint32_t nv = uint32_t(w.globalIds.size());
  size_t slots = 16;
  while (slots < 2 * size_t(nv)) slots *= 2;
  const unsigned shift = 64 - unsigned(__builtin_ctzll(slots));
  constexpr uint64_t kEmpty = ~uint64_t(0);
  s.table.assign(slots, kEmpty);
  auto home = [&](uint32_t v) { return size_t((uint64_t(v) * 0x9E3779B97F4A7C15ull) >> shift); };
  for (uint32_t l = 0; l < nv; ++l) {
    size_t i = home(w.globalIds[l]);
    while (s.table[i] != kEmpty) i = (i + 1) & (slots - 1);
    s.table[i] = uint64_t(w.globalIds[l]) << 32 | l;
  }
  for (uint32_t& v : p.triangles) {
    size_t i = home(v);
    for (;; i = (i + 1) & (slots - 1)) {
      if (s.table[i] == kEmpty) fail(scratch, "internal: patch vertex missing");
      if (uint32_t(s.table[i] >> 32) == v) break;
    }
    v = uint32_t(s.table[i]);
  }
  const size_t nt = p.triangles.size() / 3;
  const unsigned k = bitWidth(nv > 0 ? nv - 1 : 0);
  if (3 * k <= 64) {
    s.keys.resize(nt);
    s.tmp.resize(nt);
    for (size_t t = 0; t < nt; ++t) {
      std::array<uint32_t, 3> s3 = {p.triangles[3 * t], p.triangles[3 * t + 1], p.triangles[3 * t + 2]};
      if (s3[1] < s3[0]) std::swap(s3[0], s3[1]);
      if (s3[2] < s3[1]) std::swap(s3[1], s3[2]);
      if (s3[1] < s3[0]) std::swap(s3[0], s3[1]);
      s.keys[t] = uint64_t(s3[0]) << (2 * k) | uint64_t(s3[1]) << k | s3[2];
    }
    const uint64_t* sorted = lsdRadixSort(s.keys.data(), s.tmp.data(), nt, [](uint64_t x) { return x; }, 3 * k);
    for (size_t i = 1; i < nt; ++i) w.duplicates += sorted[i] == sorted[i - 1];
  } else {
    std::vector<std::array<uint32_t, 3>> sortedTris;
    for (size_t t = 0; t < nt; ++t) {
      std::array<uint32_t, 3> s3 = {p.triangles[3 * t], p.triangles[3 * t + 1], p.triangles[3 * t + 2]};
      std::sort(s3.begin(), s3.end());
      sortedTris.push_back(s3);
    }
    std::sort(sortedTris.begin(), sortedTris.end());
    for (size_t i = 1; i < sortedTris.size(); ++i) w.duplicates += sortedTris[i] == sortedTris[i - 1];
  }
  s.keys.clear();
  for (size_t t = 0; t < nt; ++t) {
    const uint32_t* f = &p.triangles[3 * t];
    if (f[0] == f[1] || f[1] == f[2] || f[0] == f[2]) continue;  // degenerate: no proper edges
    for (int e = 0; e < 3; ++e) {
      uint32_t a = f[e], b = f[(e + 1) % 3];
      s.keys.push_back(uint64_t(std::min(a, b)) << k | std::max(a, b));
    }
  }
  s.tmp.resize(s.keys.size());
  const uint64_t* edges = lsdRadixSort(s.keys.data(), s.tmp.data(), s.keys.size(), [](uint64_t x) { return x; }, 2 * k);
  const uint64_t lowMask = (uint64_t(1) << k) - 1;
  for (size_t i = 0, n = s.keys.size(); i < n;) {
    size_t j = i;
    while (j < n && edges[j] == edges[i]) ++j;
    uint32_t a = uint32_t(edges[i] >> k), b = uint32_t(edges[i] & lowMask);
    if (w.holders[a] > 1 && w.holders[b] > 1)
      w.crossEdges.push_back({uint64_t(w.globalIds[a]) << 32 | w.globalIds[b], uint32_t(j - i), 0});
    else if (j - i > 2)
      ++w.nonManifold;
    i = j;
  }
  w.payload = encodeGeometry(p, layout);
}

// Stage 6, gathering: patch k's vertices (from the patch-sorted stream, read on from d/have) and
// its corners (from pface.bin).
template <bool Full>
void gatherPatch(PatchWork& w, uint32_t k, const ParsedInput& in, PatchSorter<Full>& byPatch, VertexData<Full>& d, bool& have,
                 TempReader& pface, uint32_t triangles, const std::string& scratch) {
  while (have && uint32_t(d.key >> 32) == k) {
    assert(w.globalIds.empty() || w.globalIds.back() < uint32_t(d.key));  // ascending input index
    w.globalIds.push_back(uint32_t(d.key));
    w.holders.push_back(d.holders);
    for (int a = 0; a < 3; ++a) w.p.positions.push_back(d.p[a]);
    if constexpr (Full) {
      if (in.layout.normals) w.p.normals.insert(w.p.normals.end(), d.n, d.n + 3);
      if (in.layout.colors) w.p.colors.insert(w.p.colors.end(), d.c, d.c + 4);
      if (in.layout.texcoords) {  // the per-vertex form (store_format.h), as the resident path writes it
        w.p.texcoords.insert(w.p.texcoords.end(), d.uv, d.uv + 2);
        w.p.vertexMaterial.push_back(d.material);
      }
    }
    have = byPatch.next(d);
  }
  w.p.triangles.resize(size_t(triangles) * 3);
  if (pface.read(w.p.triangles.data(), w.p.triangles.size() * 4) != w.p.triangles.size() * 4)
    fail(scratch, "patch face scratch file is short");
}

// Stage 6: one geometry block per patch; shared vertices -> (vertex, patch, local) and cross
// edges to the boundary stage's sorters. Patches are gathered from the sorted streams in batches,
// built in parallel, and written in patch order, so the store does not depend on the thread count.
template <bool Full>
void chunkedPatches(IngestContext& ctx, const ParsedInput& in, PatchSorter<Full>& byPatch, const std::vector<uint32_t>& patchTris,
                    PatchStageOutput& out) {
  checkInterrupt("ingest: sort");
  byPatch.finish();
  out.shared = std::make_unique<SharedSorter>(ctx.scratch + "/s4", ctx.plan.chunkedSharedSorter);
  out.edges = std::make_unique<EdgeSorter>(ctx.scratch + "/s5", ctx.plan.chunkedEdgeSorter);
  const uint32_t P = uint32_t(out.patchKey.size());
  Progress progress(ctx.progress, "ingest: patches", in.faces);
  TempReader pface(ctx.scratch + "/pface.bin", 4 << 20);
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
      w.p.cell = out.patchKey[k];
      gatherPatch<Full>(w, k, in, byPatch, d, have, pface, patchTris[k], ctx.scratch);
    }
    tbb::parallel_for(size_t(0), work.size(), [&](size_t i) { buildPatch(work[i], ctx.impl.layout, ctx.scratch); });
    for (PatchWork& w : work) {
      const Patch& p = w.p;
      ctx.report.duplicateTriangles += w.duplicates;
      ctx.report.nonManifoldEdges += w.nonManifold;
      for (const EdgeRec& e : w.crossEdges) out.edges->add(e);
      for (uint32_t v = 0; v < w.globalIds.size(); ++v)
        if (w.holders[v] > 1) out.shared->add({uint64_t(w.globalIds[v]) << 32 | p.id, v, 0});
      PatchRecord rec;
      rec.meta = {p.id, p.cell, 0, p.vertexCount(), p.triangleCount(), 0, boundsOf(p.positions)};
      rec.geometry = ctx.impl.appendBlock(w.payload);
      ctx.impl.patches[p.id] = rec;
      facesDone += p.triangleCount();
    }
    progress.update(facesDone);
  }
  assert(!have && facesDone == in.faces);  // every vertex datum and every face went to a patch
  progress.finish(facesDone);
  std::remove((ctx.scratch + "/pface.bin").c_str());
  endOfPass(ctx, "patches");
}

}  // namespace

template <bool Full>
void chunkedStages(IngestContext& ctx, const ParsedInput& in, PatchStageOutput& out) {
  assert(!in.resident);
  chunkedCentroids(ctx, in);
  endOfPass(ctx, "morton merge");
  std::unique_ptr<CellSorter> byCell = chunkedAssign(ctx, in);
  std::vector<uint32_t> patchTris;
  std::unique_ptr<PairSorter> pairs = chunkedGroup(ctx, *byCell, patchTris, out);
  byCell.reset();
  std::unique_ptr<PatchSorter<Full>> byPatch = chunkedJoin<Full>(ctx, in, *pairs, out);
  pairs.reset();
  chunkedPatches<Full>(ctx, in, *byPatch, patchTris, out);
}

template void chunkedStages<false>(IngestContext&, const ParsedInput&, PatchStageOutput&);
template void chunkedStages<true>(IngestContext&, const ParsedInput&, PatchStageOutput&);

}  // namespace ingest
}  // namespace mt
