// Ingest, the chunked path (stages 2-6, see ingest.cpp): bounded by the cap whatever the input
// size. The vertex positions do not fit in RAM at once, so every face is joined with its
// corners' positions by FaceJoin (ingest_join.h: a sweep in face order with two windows of
// positions, then buckets of vertex chunks for the faces the windows missed). Twice: once for
// the centroids and Morton codes the V-partition samples, once, with the V-partition built, for
// the cell keys. The vertex records and the faces are read in place from a binary PLY.
#include <malloc.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>

#include <array>
#include <functional>

#include "base/progress.h"
#include "patchstore/ingest_internal.h"
#include "patchstore/ingest_join.h"

namespace mt {
namespace ingest {
namespace {

constexpr size_t kBatch = FaceJoin::kBatch;

// Stage 2's sort: (Morton code, face), 12 bytes a face, as the resident path's (MortonKey), by a
// stable radix sort on the code. Faces arrive in join order (which depends on the cap), so a run
// of equal codes is put back in face order as it is read (InMortonOrder): (code, face) order.
using MortonKeySorter = StableKeySorter<MortonKey, MortonKeyOf>;
// The same with the centroid and area, for an assigner that streams every centroid.
struct MortonCentroid {
  MortonKey key;
  Centroid c;
};
struct MortonCentroidOf {
  uint64_t operator()(const MortonCentroid& m) const { return m.key.code(); }
};
using MortonCentroidSorter = StableKeySorter<MortonCentroid, MortonCentroidOf>;

inline const MortonKey& keyOf(const MortonKey& k) { return k; }
inline const MortonKey& keyOf(const MortonCentroid& m) { return m.key; }

// The records of a code-sorted stream `source` (bool(Record&)) in (code, face) order.
template <class Record, class Source>
class InMortonOrder {
 public:
  explicit InMortonOrder(Source source) : source_(std::move(source)) { have_ = source_(head_); }
  bool next(Record& out) {
    if (at_ == ties_.size()) {
      if (!have_) return false;
      ties_.clear();
      at_ = 0;
      const uint64_t code = keyOf(head_).code();
      do {
        ties_.push_back(head_);
        have_ = source_(head_);
      } while (have_ && keyOf(head_).code() == code);
      if (ties_.size() > 1)
        std::sort(ties_.begin(), ties_.end(), [](const Record& a, const Record& b) { return keyOf(a).face < keyOf(b).face; });
    }
    out = ties_[at_++];
    return true;
  }

 private:
  Source source_;
  Record head_{};
  bool have_ = false;
  std::vector<Record> ties_;
  size_t at_ = 0;
};
template <class Record, class Source>
InMortonOrder<Record, Source> inMortonOrder(Source source) {
  return InMortonOrder<Record, Source>(std::move(source));
}

// The join's share of the cap for positions (tests set a smaller one: IngestOptions::positionBytes).
uint64_t positionBytes(const IngestContext& ctx) {
  return ctx.options.positionBytes ? ctx.options.positionBytes : ctx.plan.chunkedPositions;
}

void endOfPass(IngestContext& ctx, const char* stage) {
  malloc_trim(0);
  ctx.clock.mark(stage);
}

void reportJoin(IngestContext& ctx, const FaceJoin& join, const char* what) {
  ctx.report.sweptFaces += join.swept();
  ctx.report.bucketedFaces += join.bucketed();
  if (ctx.progress)
    std::fprintf(stderr, "ingest: %s: %llu faces joined in the sweep's windows, %llu through the buckets of %llu vertex chunks\n", what,
                 (unsigned long long)join.swept(), (unsigned long long)join.bucketed(), (unsigned long long)join.chunks());
}

// besideBytes: what the caller keeps resident through the join (the positions' share gives it up).
FaceJoin makeJoin(IngestContext& ctx, const ParsedInput& in, const char* name, uint64_t besideBytes = 0) {
  const uint64_t positions = positionBytes(ctx), floor = std::min<uint64_t>(positions, 4 << 20);
  const uint64_t share = positions > besideBytes + floor ? positions - besideBytes : floor;
  return FaceJoin(in.faceFile, in.vertexFile, in.layout, in.faces, share, ctx.plan.chunkedBuckets, ctx.scratch + "/" + name);
}

// Stage 2: every face joined with its corners; its Morton code goes to the sort. Returns whether
// the input's face order is spatially coherent (MortonSort::coherent's measure, over the faces
// the sweep joined, which come in face order; an input the sweep mostly missed is not).
bool chunkedMorton(IngestContext& ctx, const ParsedInput& in, MortonKeySorter& sorter) {
  FaceJoin join = makeJoin(ctx, in, "j1");
  const MortonBox box(in.bounds);
  std::vector<MortonKey> keys(kBatch), packed;
  uint64_t jumps = 0, swept = 0, lastTop = ~uint64_t(0);
  Progress progress(ctx.progress, "ingest: morton", in.faces);
  join.run(
      [&](size_t slot, uint32_t face, const uint32_t* v, const float* const* p) {
        float c[3];
        centroidPoint(v, p, c);
        const uint64_t code = box.code(c);
        keys[slot] = {uint32_t(code), uint32_t(code >> 32), face};
      },
      [&](const uint8_t* valid, size_t n, bool sweep) {
        packed.clear();
        for (size_t i = 0; i < n; ++i) {
          if (!valid[i]) continue;
          packed.push_back(keys[i]);
          if (sweep) {
            const uint64_t top = keys[i].code() >> 39;
            jumps += top != lastTop;
            lastTop = top;
            ++swept;
          }
        }
        sorter.addBatch(packed.data(), packed.size());
      },
      progress);
  progress.finish(in.faces);
  reportJoin(ctx, join, "morton");
  if (sorter.count() != in.faces) fail(ctx.scratch, "internal: the Morton sort holds " + std::to_string(sorter.count()) + " faces");
  return swept * 2 >= in.faces && jumps * 4 <= swept;
}

// The Morton-ordered centroids for the assigner. sample() merges the sort (in key ranges, on
// parallel threads), picks every stride-th face, and joins the picked faces alone with their
// corners for their centroids and areas (carrying them through the sort instead, 28 bytes a face,
// cost more than this extra read of the faces). forEach() (the grid and regular assigners stream
// every centroid) materializes the stream once as morton.bin, from a join and sort of its own.
class ChunkedCentroids : public CentroidSource {
 public:
  ChunkedCentroids(IngestContext& ctx, const ParsedInput& in, MortonKeySorter& sorter)
      : ctx_(ctx), in_(in), sorter_(sorter) {}
  uint64_t count() const override { return in_.faces; }
  Box3 bounds() const override { return in_.bounds; }

  std::vector<float> sample(uint64_t stride) const override {
    if (consumed_) return CentroidSource::sample(stride);
    stride = std::max<uint64_t>(1, stride);
    checkInterrupt("ingest: sort");
    sorter_.finish();
    ctx_.clock.mark("morton merge");
    const size_t parts = size_t(std::max(1, tbb::this_task_arena::max_concurrency()));
    std::vector<std::vector<uint64_t>> partPicks(parts);  // face << 32 | rank / stride
    std::vector<uint64_t> partCount(parts, 0);
    sorter_.mergeInParts(parts, [&](size_t part, uint64_t rank, const auto& next) {
      auto ordered = inMortonOrder<MortonKey>([&](MortonKey& k) { return next(k); });
      MortonKey k;
      uint64_t n = 0;
      for (; ordered.next(k); ++rank, ++n)
        if (rank % stride == 0) partPicks[part].push_back(uint64_t(k.face) << 32 | uint32_t(rank / stride));
      partCount[part] = n;
    });
    consumed_ = true;
    uint64_t total = 0;
    std::vector<uint64_t> picks;
    for (size_t p = 0; p < parts; ++p) {
      total += partCount[p];
      picks.insert(picks.end(), partPicks[p].begin(), partPicks[p].end());
      std::vector<uint64_t>().swap(partPicks[p]);
    }
    if (total != in_.faces) fail(ctx_.scratch, "internal: Morton sort holds " + std::to_string(total) + " faces");
    if (picks.size() >= (uint64_t(1) << 32)) fail(ctx_.scratch, "internal: too many sampled faces");
    {
      std::vector<uint64_t> tmp(picks.size());
      const uint64_t* sorted = radixSort(picks.data(), tmp.data(), picks.size(), [](uint64_t x) { return x; }, 64);
      if (sorted != picks.data()) picks.swap(tmp);
    }
    std::vector<uint32_t> faces(picks.size()), slotOf(picks.size());
    for (size_t i = 0; i < picks.size(); ++i) {
      faces[i] = uint32_t(picks[i] >> 32);
      slotOf[i] = uint32_t(picks[i]);
    }
    std::vector<uint64_t>().swap(picks);
    // The picked faces' centroids and areas. perFace gets a batch slot; the batch's filled slots
    // are mapped back to their rank through the face index.
    std::vector<float> out(4 * faces.size());
    std::vector<Centroid> cents(kBatch);
    std::vector<uint32_t> faceAt(kBatch);
    // The picks' faces, ranks and centroids (24 bytes a pick: 4 Mi picks at a billion triangles,
    // 2 M at 100 M) stay beside the join's windows: they come out of the positions' share (at 100 M
    // and --memory 96M they took the sample stage to 103 MiB).
    FaceJoin join = makeJoin(ctx_, in_, "j0", uint64_t(faces.size()) * (4 + 4 + 16));
    Progress progress(ctx_.progress, "ingest: sample", faces.size());
    join.run(
        [&](size_t slot, uint32_t face, const uint32_t* v, const float* const* p) {
          cents[slot] = centroidOf(v, p);
          faceAt[slot] = face;
        },
        [&](const uint8_t* valid, size_t n, bool) {
          for (size_t i = 0; i < n; ++i) {
            if (!valid[i]) continue;
            const size_t at = size_t(std::lower_bound(faces.begin(), faces.end(), faceAt[i]) - faces.begin());
            assert(at < faces.size() && faces[at] == faceAt[i]);
            std::memcpy(&out[4 * size_t(slotOf[at])], &cents[i], 16);
          }
        },
        progress, &faces);
    progress.finish(faces.size());
    reportJoin(ctx_, join, "sample");
    ctx_.clock.mark("sample");
    return out;
  }

  void forEach(const std::function<void(const float*, size_t)>& fn) const override {
    if (!materialized_) materialize();
    TempReader r(ctx_.scratch + "/morton.bin", 4 << 20);
    std::vector<Centroid> batch;
    while (r.getBatch(batch, kBatch)) fn(&batch[0].x, batch.size());
  }

 private:
  void materialize() const {
    consumed_ = true;
    MortonCentroidSorter sorter(ctx_.scratch + "/s1", ctx_.plan.chunkedSorter, MortonCentroidOf{}, 63, true);
    {
      FaceJoin join = makeJoin(ctx_, in_, "j3");
      const MortonBox box(in_.bounds);
      std::vector<MortonCentroid> recs(kBatch), packed;
      Progress progress(ctx_.progress, "ingest: centroids", in_.faces);
      join.run(
          [&](size_t slot, uint32_t face, const uint32_t* v, const float* const* p) {
            const Centroid c = centroidOf(v, p);
            const uint64_t code = box.code(&c.x);
            recs[slot] = {{uint32_t(code), uint32_t(code >> 32), face}, c};
          },
          [&](const uint8_t* valid, size_t n, bool) {
            packed.clear();
            for (size_t i = 0; i < n; ++i)
              if (valid[i]) packed.push_back(recs[i]);
            sorter.addBatch(packed.data(), packed.size());
          },
          progress);
      progress.finish(in_.faces);
    }
    checkInterrupt("ingest: sort");
    sorter.finish();
    TempWriter out(ctx_.scratch + "/morton.bin", 4 << 20);
    auto ordered = inMortonOrder<MortonCentroid>([&](MortonCentroid& m) { return sorter.next(m); });
    MortonCentroid m;
    uint64_t n = 0;
    for (; ordered.next(m); ++n) out.put(m.c);
    out.close();
    if (n != in_.faces) fail(ctx_.scratch, "internal: Morton sort holds " + std::to_string(n) + " faces");
    materialized_ = true;
  }

  IngestContext& ctx_;
  const ParsedInput& in_;
  MortonKeySorter& sorter_;
  mutable bool materialized_ = false, consumed_ = false;
};

// Stages 2 and 3: the Morton codes, then the assigner prepared from the Morton-ordered centroids
// (the irregular V-partition samples them; its time is reported apart from the sort's). Returns
// whether the face order is coherent.
bool chunkedPartition(IngestContext& ctx, const ParsedInput& in) {
  auto sorter = std::make_unique<MortonKeySorter>(ctx.scratch + "/s0", ctx.plan.chunkedSorter, MortonKeyOf{}, 63, true);
  const bool coherent = chunkedMorton(ctx, in, *sorter);
  endOfPass(ctx, "morton");
  {
    ChunkedCentroids centroids(ctx, in, *sorter);
    Progress progress(ctx.progress, "ingest: partition", in.faces);
    ctx.assigner.prepare(centroids, ctx.plan.assigner);
    progress.finish(in.faces);
  }
  sorter.reset();
  std::remove((ctx.scratch + "/morton.bin").c_str());
  ctx.report.assigner = ctx.assigner.describe();
  endOfPass(ctx, "partition");
  return coherent;
}

// What the group sort keeps of a face: its index (faces arrive in join order; a group is put
// back in face order) and its corners.
struct FaceRec {
  uint32_t face, v[3];
};
struct ByFace {
  bool operator()(const FaceRec& a, const FaceRec& b) const { return a.face < b.face; }
};
using FaceGroups = KeyGroupSorter<FaceRec, ByFace>;

// Stage 4: every face joined again, keyed by its cell, grouped by key. A coherent face order looks
// the keys up as the faces come (consecutive faces hit the same seeds); otherwise a batch's
// lookups go in Morton order (as the resident path's shuffled inputs), in parallel pieces.
std::unique_ptr<FaceGroups> chunkedAssign(IngestContext& ctx, const ParsedInput& in, bool coherent) {
  auto groups = std::make_unique<FaceGroups>(ctx.scratch + "/g", ctx.plan.chunkedSorter, ByFace{}, true);
  FaceJoin join = makeJoin(ctx, in, "j2");
  const MortonBox box(in.bounds);
  const CellAssigner& assigner = ctx.assigner;
  std::vector<uint64_t> keys(kBatch), packedKeys, order, tmp;
  std::vector<FaceRec> recs(kBatch), packed;
  std::vector<float> cents(coherent ? 0 : 3 * kBatch);
  Progress progress(ctx.progress, "ingest: assign", in.faces);
  join.run(
      [&](size_t slot, uint32_t face, const uint32_t* v, const float* const* p) {
        float c[3];
        centroidPoint(v, p, c);
        recs[slot] = {face, {v[0], v[1], v[2]}};
        if (coherent)
          keys[slot] = assigner.cellKey(c);
        else
          std::memcpy(&cents[3 * slot], c, 12);
      },
      [&](const uint8_t* valid, size_t n, bool) {
        if (!coherent) {
          order.clear();
          for (size_t i = 0; i < n; ++i)
            if (valid[i]) order.push_back((box.code(&cents[3 * i]) >> 20) << 20 | i);  // batch index below bit 20
          tmp.resize(order.size());
          const uint64_t* sorted = radixSort(order.data(), tmp.data(), order.size(), [](uint64_t x) { return x; }, 63);
          tbb::parallel_for(tbb::blocked_range<size_t>(0, order.size(), 4096), [&](const tbb::blocked_range<size_t>& r) {
            for (size_t j = r.begin(); j < r.end(); ++j) {
              const size_t i = size_t(sorted[j] & ((1u << 20) - 1));
              keys[i] = assigner.cellKey(&cents[3 * i]);
            }
          });
        }
        packedKeys.clear();
        packed.clear();
        for (size_t i = 0; i < n; ++i)
          if (valid[i]) {
            packedKeys.push_back(keys[i]);
            packed.push_back(recs[i]);
          }
        groups->addBatch(packedKeys.data(), packed.data(), packed.size());
      },
      progress);
  progress.finish(in.faces);
  reportJoin(ctx, join, "assign");
  if (groups->count() != in.faces) fail(ctx.scratch, "internal: the groups hold " + std::to_string(groups->count()) + " faces");
  checkInterrupt("ingest: sort");
  groups->finish();
  endOfPass(ctx, "assign");
  return groups;
}

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
// sort of the three corners per triangle; a wide range (a subdivided mesh's coarse vertices, a
// shuffled input) is radix sorted on the range's bits (std::sort was 8% of the chunked path on
// arm3.3M).
void distinctSorted(const std::vector<uint32_t>& values, std::vector<uint32_t>& out) {
  out.clear();
  if (values.empty()) return;
  auto [lo, hi] = std::minmax_element(values.begin(), values.end());
  const uint32_t base = *lo;
  const uint64_t range = uint64_t(*hi) - base + 1;
  if (range > 16 * uint64_t(values.size())) {
    thread_local std::vector<uint32_t> a, b;
    a.resize(values.size());
    b.resize(values.size());
    for (size_t i = 0; i < values.size(); ++i) a[i] = values[i] - base;
    const uint32_t* sorted = lsdRadixSort(a.data(), b.data(), a.size(), [](uint32_t x) { return x; }, bitWidth(range - 1));
    for (size_t i = 0; i < a.size(); ++i)
      if (i == 0 || sorted[i] != sorted[i - 1]) out.push_back(sorted[i] + base);
    return;
  }
  std::vector<uint64_t>& bits = chunkedScratch().keys;
  bits.assign(size_t((range + 63) / 64), 0);
  for (uint32_t v : values) bits[(v - base) >> 6] |= uint64_t(1) << ((v - base) & 63);
  for (size_t w = 0; w < bits.size(); ++w)
    for (uint64_t x = bits[w]; x; x &= x - 1) out.push_back(base + uint32_t(w * 64 + unsigned(__builtin_ctzll(x))));
}

// (patch << 32 | vertex): unique keys, radix sorted.
template <bool Full>
using PatchSorter = StableKeySorter<VertexData<Full>, KeyOf<VertexData<Full>>>;

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

// (vertex << 32 | patch): unique keys, radix sorted.
struct Identity {
  uint64_t operator()(uint64_t x) const { return x; }
};
using PairSorter = StableKeySorter<uint64_t, Identity>;

// Stage 5, first pass over the groups: consecutive keys become patches 0..P-1 (out.patchKey);
// each patch's distinct vertices give (vertex, patch) pairs, externally sorted by vertex. Patches
// are gathered in batches; their distinct vertices are found in parallel and added in patch order
// (the result does not depend on the thread count).
std::unique_ptr<PairSorter> chunkedGroup(IngestContext& ctx, FaceGroups& groups, PatchStageOutput& out) {
  std::vector<uint64_t>& patchKey = out.patchKey;
  auto pairs = std::make_unique<PairSorter>(ctx.scratch + "/s2", ctx.plan.chunkedSorter, Identity{}, 64, true);
  constexpr size_t kPatches = 64;
  std::vector<std::vector<uint32_t>> tris(kPatches), verts(kPatches);
  std::vector<FaceRec> faces;
  size_t filled = 0;
  auto flush = [&]() {
    tbb::parallel_for(size_t(0), filled, [&](size_t i) { distinctSorted(tris[i], verts[i]); });
    for (size_t i = 0; i < filled; ++i) {
      const uint32_t k = uint32_t(patchKey.size() - filled + i);
      for (uint32_t v : verts[i]) pairs->add(uint64_t(v) << 32 | k);
    }
    filled = 0;
  };
  uint64_t key;
  while (groups.nextGroup(key, faces)) {
    assert(patchKey.empty() || patchKey.back() < key);  // groups come in ascending key order
    if (filled == kPatches) flush();
    patchKey.push_back(key);
    std::vector<uint32_t>& t = tris[filled++];
    t.resize(3 * faces.size());
    for (size_t i = 0; i < faces.size(); ++i) std::memcpy(&t[3 * i], faces[i].v, 12);
  }
  flush();
  if (patchKey.size() >= (uint64_t(1) << 32)) fail(ctx.scratch, "more than 2^32 patches");
  ctx.clock.mark("group");
  return pairs;
}

// Stage 5: the (vertex, patch) pairs merge-joined with the vertex records -> (patch, vertex, data)
// sorted by patch. Counts the vertices some face uses.
template <bool Full>
std::unique_ptr<PatchSorter<Full>> chunkedJoin(IngestContext& ctx, const ParsedInput& in, PairSorter& pairs,
                                               PatchStageOutput& out) {
  checkInterrupt("ingest: sort");
  pairs.finish();
  auto byPatch = std::make_unique<PatchSorter<Full>>(ctx.scratch + "/s3", ctx.plan.chunkedSorter, KeyOf<VertexData<Full>>{}, 64, true);
  Progress progress(ctx.progress, "ingest: vertices", in.vertices, "vert");
  const size_t size = in.layout.size();
  TempReader vr(in.vertexFile.path, 4 << 20, in.vertexFile.offset, in.vertices * size);
  std::vector<char> rec(size);
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
      if (vr.read(rec.data(), size) != size) fail(in.vertexFile.path, "the vertex records end early (the file changed during the ingest?)");
    VertexData<Full> d = vertexData<Full>(in.layout, rec.data(), uint32_t(holders.size()));
    for (uint32_t k : holders) {
      d.key = uint64_t(k) << 32 | v;
      byPatch->add(d);
    }
    progress.update(nextVertex);
  }
  progress.finish(in.vertices);
  if (!in.vertexFile.ply) std::remove(in.vertexFile.path.c_str());
  endOfPass(ctx, "vertices");
  return byPatch;
}

// Stage 6, gathering: patch k's vertices (from the patch-sorted stream, read on from d/have) and
// its faces (the second pass over the groups).
template <bool Full>
void gatherPatch(PatchWork& w, uint32_t k, const ParsedInput& in, PatchSorter<Full>& byPatch, VertexData<Full>& d, bool& have,
                 FaceGroups& groups, std::vector<FaceRec>& faces, const std::string& scratch) {
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
  uint64_t key;
  if (!groups.nextGroup(key, faces) || key != w.p.cell) fail(scratch, "internal: patch groups changed between passes");
  w.p.triangles.resize(3 * faces.size());
  for (size_t i = 0; i < faces.size(); ++i) std::memcpy(&w.p.triangles[3 * i], faces[i].v, 12);
}

// Stage 6: one geometry block per patch; shared vertices -> (vertex, patch, local) and cross
// edges to the boundary stage's sorters. A pipeline, as the resident path's (pipelineGroups):
// batches of patches gathered from the sorted streams in patch order (one thread), built in
// parallel, and written in patch order (one thread), the three at once. Gathering and writing are
// mostly the sorters' merge and the store's appends; done in turn with the building (gather 64,
// build 64, write 64) they left a core idle most of the stage. The store does not depend on the
// thread count. At most `tokens` batches are in flight (the threads and two more, of 64 / tokens
// patches each: the 64 patches the stage held before; 4 of 16 on two cores), in a ring of `tokens`
// slots: batch i takes slot i % tokens, which batch i - tokens has left (writes are serial and in
// order, and batch i cannot start before a finished write gives a token back). The ring owns the
// batches, so a failure anywhere in the pipeline leaves nothing behind.
template <bool Full>
void chunkedPatches(IngestContext& ctx, const ParsedInput& in, FaceGroups& groups, PatchSorter<Full>& byPatch,
                    PatchStageOutput& out) {
  checkInterrupt("ingest: sort");
  byPatch.finish();
  groups.rewind(true);
  out.shared = std::make_unique<SharedSorter>(ctx.scratch + "/s4", ctx.plan.chunkedSharedSorter);
  out.edges = std::make_unique<EdgeSorter>(ctx.scratch + "/s5", ctx.plan.chunkedEdgeSorter);
  const uint32_t P = uint32_t(out.patchKey.size());
  Progress progress(ctx.progress, "ingest: patches", in.faces);
  VertexData<Full> d;
  bool have = byPatch.next(d);
  uint64_t facesDone = 0;
  const size_t tokens = size_t(std::max(2, tbb::this_task_arena::max_concurrency())) + 2;
  const uint32_t perBatch = uint32_t(std::max<size_t>(1, 64 / tokens));
  std::vector<FaceRec> faces;
  uint32_t next = 0;
  uint64_t batches = 0;
  std::vector<std::vector<PatchWork>> ring(tokens);
  auto gather = [&](tbb::flow_control& fc) -> std::vector<PatchWork>* {
    if (next == P) {
      fc.stop();
      return nullptr;
    }
    std::vector<PatchWork>* work = &ring[batches++ % tokens];
    assert(work->empty());
    work->resize(std::min(P - next, perBatch));
    for (PatchWork& w : *work) {
      const uint32_t k = next++;
      w.p.id = k;
      w.p.cell = out.patchKey[k];
      gatherPatch<Full>(w, k, in, byPatch, d, have, groups, faces, ctx.scratch);
    }
    return work;
  };
  auto build = [&](std::vector<PatchWork>* work) {
    for (PatchWork& w : *work) buildPatch(w, ctx.impl.layout, ctx.scratch);
    return work;
  };
  auto write = [&](std::vector<PatchWork>* batch) {
    for (PatchWork& w : *batch) {
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
    batch->clear();
    progress.update(facesDone);
  };
  using Batch = std::vector<PatchWork>*;
  tbb::parallel_pipeline(tokens, tbb::make_filter<void, Batch>(tbb::filter_mode::serial_in_order, gather) &
                                      tbb::make_filter<Batch, Batch>(tbb::filter_mode::parallel, build) &
                                      tbb::make_filter<Batch, void>(tbb::filter_mode::serial_in_order, write));
  uint64_t key;
  if (have || groups.nextGroup(key, faces) || facesDone != in.faces)
    fail(ctx.scratch, "internal: a vertex or a face of the sorted streams is in no patch");
  progress.finish(facesDone);
  endOfPass(ctx, "patches");
}

}  // namespace

// A store's patch record as ingest keeps it: a node of Impl::patches (the pair, the tree's
// three links and colour) and malloc's header; base/memory_plan.h plans with kPatchRecordBytes.
static_assert(sizeof(std::pair<const PatchId, PatchRecord>) + 32 + 16 <= kPatchRecordBytes,
              "kPatchRecordBytes no longer covers a patch record");

template <bool Full>
void chunkedStages(IngestContext& ctx, const ParsedInput& in, PatchStageOutput& out) {
  assert(!in.resident);
  const bool coherent = chunkedPartition(ctx, in);
  // From here to the end of the ingest the V-partition stays resident beside every stage's
  // buffers (its seeds, candidate tables and key table: tens of MiB at 100 M triangles, ~200 MiB
  // at a billion), with the process itself: measured once the partition stage has trimmed the
  // heap, and left out of what the later stages plan with (MemoryPlan::besides).
  const uint64_t resident = currentRssBytes();
  const MemoryPlan assignPlan = ctx.plan.besides(resident);
  IngestContext assignCtx{ctx.scratch, ctx.options, assignPlan, ctx.progress, ctx.assigner, ctx.report, ctx.impl, ctx.clock};
  std::unique_ptr<FaceGroups> groups = chunkedAssign(assignCtx, in, coherent);
  if (!in.faceFile.ply) std::remove(in.faceFile.path.c_str());
  // Every face has its cell: the assigner keeps only what the store saves of it (the sequence's
  // bytes), and what that frees (the seed grids, candidate tables and key maps: most of the
  // partition's resident set) goes to the later stages' sorters.
  const uint64_t freed = releaseAssignerLookups(ctx);
  const uint64_t partition = resident - std::min(resident, freed);
  std::unique_ptr<PairSorter> pairs = chunkedGroup(assignCtx, *groups, out);
  // The join and the patch stage also run beside the store's patch records, which the patch stage
  // adds one per patch (and the patch keys).
  const MemoryPlan patchPlan = ctx.plan.besides(partition + uint64_t(out.patchKey.size()) * (kPatchRecordBytes + 8));
  IngestContext patchCtx{ctx.scratch, ctx.options, patchPlan, ctx.progress, ctx.assigner, ctx.report, ctx.impl, ctx.clock};
  if (ctx.progress)
    std::fprintf(stderr, "ingest: beside the stages: %.0f MiB resident after the partition (%.0f MiB once the assignment is done), %.0f MiB of %zu patch records; sorters %.0f then %.0f MiB\n",
                 double(resident) / double(1 << 20), double(partition) / double(1 << 20),
                 double(out.patchKey.size() * (kPatchRecordBytes + 8)) / double(1 << 20),
                 out.patchKey.size(), double(assignPlan.chunkedSorter) / double(1 << 20), double(patchPlan.chunkedSorter) / double(1 << 20));
  std::unique_ptr<PatchSorter<Full>> byPatch = chunkedJoin<Full>(patchCtx, in, *pairs, out);
  pairs.reset();
  chunkedPatches<Full>(patchCtx, in, *groups, *byPatch, out);
  groups.reset();
}

template void chunkedStages<false>(IngestContext&, const ParsedInput&, PatchStageOutput&);
template void chunkedStages<true>(IngestContext&, const ParsedInput&, PatchStageOutput&);

}  // namespace ingest
}  // namespace mt
