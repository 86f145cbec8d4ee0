// Ingest, the resident path (stages 2-5, see ingest.cpp): the vertex records stay in RAM, so every
// pass that needs a position reads it directly instead of joining through an external sort.
#include <malloc.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

#include <array>
#include <atomic>
#include <functional>
#include <mutex>
#include <optional>

#include "base/progress.h"
#include "patchstore/ingest_internal.h"

namespace mt {
namespace ingest {
namespace {

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


// A centroid keyed by Morton code, for an assigner that streams every centroid.
struct MortonCentroid {
  uint32_t lo, hi;
  Centroid c;
};
struct MortonCentroidOf {
  uint64_t operator()(const MortonCentroid& k) const { return uint64_t(k.hi) << 32 | k.lo; }
};

constexpr size_t kFaceBatch = 65536;

// demand: sample() sorts 12-byte (code, face) records only and computes the few centroids it
// returns; forEach() (grid and regular assigners) materializes the whole stream once.
class ResidentCentroids : public CentroidSource {
 public:
  ResidentCentroids(IngestContext& ctx, ParsedInput& in, const ResidentVertices& vertices, uint64_t budget)
      : scratch_(ctx.scratch), faceFile_(in.faceFile), vertices_(vertices), faces_(in.faces), bounds_(in.bounds),
        morton_(*in.morton), budget_(budget), clock_(ctx.clock), progress_(ctx.progress) {}
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
  std::vector<char> positions;  // the patch's position records, before packing
};

// buildResidentPatch, step 1. Corners sorted by vertex (radix, on the patch's index range): the
// distinct vertices in ascending order are the local order (s.globals), and every corner gets its
// local index (s.local). Returns the sorted (vertex - vmin, corner) pairs, which step 4 reads.
const uint64_t* localOrder(const ResidentPatch& w, PatchScratch& s) {
  const size_t nt = w.faces.size(), nc = 3 * nt;
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
  s.firstCorner.push_back(uint32_t(nc));
  assert(std::is_sorted(s.globals.begin(), s.globals.end()));  // local order = ascending input index
  return sorted;
}

// buildResidentPatch, step 2. The payload: header, positions, normals, colours, triangles; and the
// patch's bounds and which of its vertices are shared (s.shared).
void writePayload(ResidentPatch& w, const ResidentVertices& rv, const uint8_t* state, PatchScratch& s) {
  const uint32_t nv = uint32_t(s.globals.size());
  const size_t nt = w.faces.size(), nc = 3 * nt;
  const VertexRecordLayout& L = rv.layout;
  const size_t posBytes = L.doublePrecision ? 24 : 12;
  const size_t attributeBytes = nv * ((L.normals ? 12 : 0) + (L.colors ? 4 : 0) + (L.texcoords ? 12 : 0));
  store_format::GeometryHeader h{nv, uint32_t(nt), (L.doublePrecision ? store_format::kGeomDouble : 0u) |
                                                       (L.normals ? store_format::kGeomNormals : 0u) |
                                                       (L.colors ? store_format::kGeomColors : 0u) |
                                                       (L.texcoords ? store_format::kGeomTexcoords | store_format::kGeomVertexUV : 0u) |
                                                       (nt ? store_format::kGeomPackedTriangles : 0u) |
                                                       (nv ? store_format::kGeomPackedPositions : 0u),
                                 0};
  w.payload.assign(reinterpret_cast<const char*>(&h), sizeof h);
  s.positions.resize(nv * posBytes);
  char* out = s.positions.data();
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
  if (nv) appendPackedPositions(w.payload, s.positions.data(), nv, posBytes);
  const size_t at = w.payload.size();
  w.payload.resize(at + attributeBytes);
  out = w.payload.data() + at;
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
  if (L.texcoords)  // the per-vertex form of store_format.h
    for (uint32_t l = 0; l < nv; ++l) {
      std::memcpy(out, rv.record(s.globals[l]) + L.texcoordOffset(), 12);
      out += 12;
    }
  assert(size_t(out - w.payload.data()) == at + attributeBytes);  // every byte of the attributes written once
  if (nt) appendPackedTriangles(w.payload, s.local.data(), nc, nv);
}

// buildResidentPatch, step 3. Duplicate faces (same vertex set): sorted local triples packed into
// one integer, counted through an open-addressing set (each repeat of a triple counts once).
uint64_t countDuplicates(const uint32_t* tri, size_t nt, uint32_t nv, PatchScratch& s) {
  const uint32_t lb = bitsFor(std::max<uint32_t>(1, nv - 1));
  uint64_t duplicates = 0;
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
        ++duplicates;
      else
        s.set[h] = key;
    }
    return duplicates;
  }
  std::vector<std::array<uint32_t, 3>> sortedTris(nt);
  for (size_t t = 0; t < nt; ++t) {
    sortedTris[t] = {tri[3 * t], tri[3 * t + 1], tri[3 * t + 2]};
    std::sort(sortedTris[t].begin(), sortedTris[t].end());
  }
  std::sort(sortedTris.begin(), sortedTris.end());
  for (size_t t = 1; t < nt; ++t) duplicates += sortedTris[t] == sortedTris[t - 1];
  return duplicates;
}

// buildResidentPatch, step 4. Edge use counts, from the corners of each vertex a (sorted by step
// 1): a proper triangle at a holds each of its two other corners once, so the uses of edge (a, b),
// b > a, are how often b shows up among them. Degenerate triangles have no proper edges. Edges
// between two shared vertices may continue in another patch: they go to w.crossEdges, to be
// summed over patches; the others are counted here.
void countEdges(ResidentPatch& w, const uint64_t* sorted, PatchScratch& s) {
  const uint32_t nv = uint32_t(s.globals.size());
  const uint32_t* tri = s.local.data();
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
}

// The geometry block of one patch (store_format.h), byte for byte what encodeGeometry writes for
// the chunked path's Patch: local vertex order is ascending input index; triangles keep their
// face order and corner order. Also the per-patch defect counts and the boundary inputs.
void buildResidentPatch(ResidentPatch& w, const ResidentVertices& rv, const uint8_t* state, PatchScratch& s) {
  const uint64_t* sorted = localOrder(w, s);
  const uint32_t nv = uint32_t(s.globals.size());
  w.vertices = nv;
  w.triangles = uint32_t(w.faces.size());
  writePayload(w, rv, state, s);
  w.duplicates = countDuplicates(s.local.data(), w.faces.size(), nv, s);
  w.nonManifold = 0;
  w.crossEdges.clear();
  countEdges(w, sorted, s);
  w.shared.clear();
  for (uint32_t l = 0; l < nv; ++l)
    if (s.shared[l]) w.shared.push_back({s.globals[l], l});
}

// Stage 2: the assigner prepared from the Morton-ordered centroids (the irregular V-partition
// samples them). Returns whether the input's face order is spatially coherent.
bool residentPartition(IngestContext& ctx, ParsedInput& in, const ResidentVertices& rv) {
  bool coherent = true;
  {
    // The sorters' shares are what the resident set (records, code, the assigner later) leaves,
    // with a margin for what the pass allocates besides them (MemoryPlan::residentSorter).
    ResidentCentroids centroids(ctx, in, rv, ctx.plan.residentSorter(currentRssBytes(), 32 << 20));
    Progress progress(ctx.progress, "ingest: partition", in.faces);
    ctx.assigner.prepare(centroids, ctx.plan.assigner);
    progress.finish(in.faces);
    coherent = centroids.coherent();
    std::remove((ctx.scratch + "/morton.bin").c_str());
  }
  ctx.report.assigner = ctx.assigner.describe();
  malloc_trim(0);
  ctx.clock.mark("partition");
  return coherent;
}

using FaceGroups = KeyGroupSorter<FaceCorners, AdditionOrder>;

// Stage 3: every face keyed in face order, grouped by key. Lookups are cheap in a coherent order
// (consecutive faces hit the same seeds, BMT's scans list faces so); a shuffled input's batches
// are looked up in Morton order instead, in bigger batches (which makes runs of the same query
// cells), and the keys put back in face order.
std::unique_ptr<FaceGroups> residentAssign(IngestContext& ctx, const ParsedInput& in, const ResidentVertices& rv, bool coherent) {
  const size_t batchFaces = coherent ? kFaceBatch : 4 * kFaceBatch;
  const uint64_t batchBytes = coherent ? 0 : (size_t(std::max(2, tbb::this_task_arena::max_concurrency())) + 2) * batchFaces * 56;
  auto groups = std::make_unique<FaceGroups>(ctx.scratch + "/g", ctx.plan.residentSorter(currentRssBytes(), (48 << 20) + batchBytes),
                                             AdditionOrder{}, true);
  Progress progress(ctx.progress, "ingest: assign", in.faces);
  struct Keyed {
    std::vector<uint64_t> keys;
    std::vector<FaceCorners> recs;
    std::vector<float> centroids;
    std::vector<uint64_t> order, tmp;
  };
  const MortonBox box(in.bounds);
  CellAssigner& assigner = ctx.assigner;
  auto keyCoherent = [&](FaceBatch<Keyed>& b) {
    for (size_t i = 0, n = b.count(); i < n; ++i) {
      if (i + 16 < n)
        for (int k = 0; k < 3; ++k) rv.prefetch(b.idx[3 * (i + 16) + k]);
      const uint32_t* v = &b.idx[3 * i];
      float c[3];
      rv.centroidPoint(v, c);
      b.out.keys[i] = assigner.cellKey(c);
      b.out.recs[i] = {{v[0], v[1], v[2]}};
    }
  };
  auto keyShuffled = [&](FaceBatch<Keyed>& b) {
    const size_t n = b.count();
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
  };
  pipelineFaces<Keyed>(
      in.faceFile, batchFaces,
      [&](FaceBatch<Keyed>& b) {
        b.out.keys.resize(b.count());
        b.out.recs.resize(b.count());
        if (coherent)
          keyCoherent(b);
        else
          keyShuffled(b);
      },
      [&](FaceBatch<Keyed>& b) {
        groups->addBatch(b.out.keys.data(), b.out.recs.data(), b.count());
        progress.update(b.first + b.count());
      });
  if (groups->count() != in.faces) fail(ctx.scratch, "internal: face file holds " + std::to_string(groups->count()) + " faces");
  checkInterrupt("ingest: sort");
  groups->finish();
  progress.finish(in.faces);
  std::remove((ctx.scratch + "/face.bin").c_str());
  malloc_trim(0);
  ctx.clock.mark("assign");
  return groups;
}

// A pipeline over the groups (patches in key order): gather a batch on one thread, work(patch) on
// the patches of the batch on any thread, finish(patch) the batches in order.
template <class Work, class Finish>
void pipelineGroups(FaceGroups& groups, const Work& work, const Finish& finish) {
  struct Batch {
    uint32_t first = 0;
    std::vector<ResidentPatch> patches;
  };
  constexpr size_t kPatches = 32;
  const size_t tokens = size_t(std::max(2, tbb::this_task_arena::max_concurrency())) + 2;
  uint32_t nextId = 0;
  bool more = true;
  auto gather = [&](tbb::flow_control& fc) -> Batch* {
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
  };
  auto process = [&](Batch* b) {
    for (ResidentPatch& p : b->patches) work(p);
    return b;
  };
  auto commit = [&](Batch* b) {
    std::unique_ptr<Batch> owned(b);
    for (ResidentPatch& p : b->patches) finish(p);
  };
  tbb::parallel_pipeline(tokens, tbb::make_filter<void, Batch*>(tbb::filter_mode::serial_in_order, gather) &
                                     tbb::make_filter<Batch*, Batch*>(tbb::filter_mode::parallel, process) &
                                     tbb::make_filter<Batch*, void>(tbb::filter_mode::serial_in_order, commit));
}

// Stage 4: one pass over the patches marks every vertex held (bit 0) and held by a second patch
// (bit 1). A patch's distinct vertices come from a per-thread bit set of the vertices it touched,
// cleared again through the list of them. Fills out.patchKey and out.distinctReferenced.
std::vector<uint8_t> residentShared(IngestContext& ctx, const ParsedInput& in, FaceGroups& groups, PatchStageOutput& out) {
  const uint64_t nv = in.vertices;
  std::vector<uint8_t> state(nv, 0);
  Progress progress(ctx.progress, "ingest: shared", in.faces);
  tbb::enumerable_thread_specific<std::pair<std::vector<uint64_t>, std::vector<uint32_t>>> marks;
  std::atomic<uint64_t> held{0};
  uint64_t facesDone = 0;
  auto mark = [&](ResidentPatch& p) {
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
  };
  pipelineGroups(groups, mark, [&](ResidentPatch& p) {
    assert(out.patchKey.empty() || out.patchKey.back() < p.key);  // groups come in ascending key order
    out.patchKey.push_back(p.key);
    facesDone += p.triangles;
    progress.update(facesDone);
  });
  assert(facesDone == in.faces);  // every face is in one group
  out.distinctReferenced = held.load();
  progress.finish(in.faces);
  malloc_trim(0);
  ctx.clock.mark("shared");
  return state;
}

// Stage 5: the patches built in parallel, appended in patch order. The boundary stage's sorters
// fill while the records are resident: their share is what is left now (they spill early, which
// costs little: a few million records; in the background, off the ordered stage).
void residentPatches(IngestContext& ctx, const ParsedInput& in, const ResidentVertices& rv, FaceGroups& groups,
                     const std::vector<uint8_t>& state, PatchStageOutput& out) {
  {
    const uint64_t inUse = currentRssBytes();
    out.shared = std::make_unique<SharedSorter>(ctx.scratch + "/s4", ctx.plan.residentSharedSorter(inUse), KeyOf<LocalRec>{}, 64, true);
    out.edges = std::make_unique<EdgeSorter>(ctx.scratch + "/s5", ctx.plan.residentEdgeSorter(inUse), KeyOf<EdgeRec>{}, 64, true);
  }
  SharedSorter& shared = *out.shared;
  EdgeSorter& edges = *out.edges;
  Progress progress(ctx.progress, "ingest: patches", in.faces);
  groups.rewind(true);
  tbb::enumerable_thread_specific<PatchScratch> scratchSpace;
  uint64_t facesDone = 0;
  IngestReport& report = ctx.report;
  auto append = [&](ResidentPatch& p) {
    if (p.id >= out.patchKey.size() || out.patchKey[p.id] != p.key) fail(ctx.scratch, "internal: patch order changed between passes");
    report.duplicateTriangles += p.duplicates;
    report.nonManifoldEdges += p.nonManifold;
    for (auto& [key, uses] : p.crossEdges) edges.add({key, uses, 0});
    for (auto& [v, l] : p.shared) shared.add({uint64_t(v) << 32 | p.id, l, 0});
    PatchRecord rec;
    rec.meta = {p.id, p.key, 0, p.vertices, p.triangles, 0, p.bounds};
    rec.geometry = ctx.impl.appendBlock(p.payload);
    ctx.impl.patches[p.id] = rec;
    facesDone += p.triangles;
    progress.update(facesDone);
  };
  pipelineGroups(groups, [&](ResidentPatch& p) { buildResidentPatch(p, rv, state.data(), scratchSpace.local()); }, append);
  if (facesDone != in.faces) fail(ctx.scratch, "internal: patches hold " + std::to_string(facesDone) + " faces");
  progress.finish(in.faces);
}

}  // namespace

void residentStages(IngestContext& ctx, ParsedInput& in, PatchStageOutput& out) {
  assert(in.resident && in.records.size() == in.vertices * in.layout.size());
  std::remove((ctx.scratch + "/vert.bin").c_str());
  const ResidentVertices rv{in.records.data(), in.layout, in.layout.size()};
  const bool coherent = residentPartition(ctx, in, rv);
  std::unique_ptr<FaceGroups> groups = residentAssign(ctx, in, rv, coherent);
  // Every face has its cell: the later passes, which plan with the resident set they measure,
  // have what the assigner's lookups held for their sorters.
  releaseAssignerLookups(ctx);
  std::vector<uint8_t> state = residentShared(ctx, in, *groups, out);
  residentPatches(ctx, in, rv, *groups, state, out);
  groups->release();
  groups.reset();
  std::vector<uint8_t>().swap(state);
  std::vector<char>().swap(in.records);
  malloc_trim(0);
  ctx.clock.mark("patches");
}

}  // namespace ingest
}  // namespace mt
