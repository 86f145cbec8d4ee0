// A cut welded by grid position, streamed in bounded memory (mt_cut_writer.h). assembleCut gives
// welded vertex w to the w-th distinct grid point in order of first use (a use is one vertex of
// one decoded patch, numbered by `seq` in arc order then patchRefs order, then vertex order); a
// shared vertex's normal is the float sum of its uses' normals in use order, normalized, and its
// colour is its first use's. Here the same comes out of four external sorts, each pass reading
// what the previous one wrote in order:
//   1 uses        decode the patches in order: (q, seq, normal, colour) of every use -> sorted
//                 by (q, seq); degenerate triangles counted (two corners with one q are welded
//                 into one vertex whatever the rest of the cut is); max |coordinate|
//   2 groups      each q's uses in seq order: its first use `first`, its normal summed in seq
//                 order -> the vertex (first, q, normal, colour) sorted by first; every use
//                 (first, seq) sorted by first
//   3 vertices    vertices in first-use order are ids 0, 1, ... (assembleCut's): written to the
//                 sink; the uses, in the same order, get their id -> (seq, id) sorted by seq
//   4 triangles   decode the patches again in order: a patch's uses are consecutive seqs, so
//                 their ids are the next records of the last sort; triangles remapped, degenerate
//                 ones dropped, written to the sink
// Every sort key is total (seq is unique), so the result depends on nothing but the file and the
// arcs: the same bytes as assembleCut + a writer, whatever the budget.
#include "mtfile/mt_cut_writer.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstring>

#include "base/error.h"
#include "base/external_sort.h"
#include "mtfile/mt_cut_internal.h"
#include "mtfile/mt_format.h"

namespace mt {

using cut_internal::cutPatchIds;

namespace {

// One use of a grid point (pass 1), with its normal and colour when the file has either; without
// them a use is 24 bytes instead of 40, and so is a welded vertex: the finest cut of a
// billion-triangle file peaked at 19,895 MiB of scratch and output instead of 27,530.
template <bool kAttributes>
struct Use {
  uint32_t q[3];
  uint32_t hasNormal;
  uint64_t seq;
  float n[3];
  uint8_t c[4];
};
template <>
struct Use<false> {
  uint32_t q[3];
  uint32_t unused;
  uint64_t seq;
};
static_assert(sizeof(Use<true>) == 40 && sizeof(Use<false>) == 24, "Use layout");
template <bool kAttributes>
struct UseLess {
  bool operator()(const Use<kAttributes>& a, const Use<kAttributes>& b) const {
    if (a.q[0] != b.q[0]) return a.q[0] < b.q[0];
    if (a.q[1] != b.q[1]) return a.q[1] < b.q[1];
    if (a.q[2] != b.q[2]) return a.q[2] < b.q[2];
    return a.seq < b.seq;
  }
};
// A welded vertex (pass 2), keyed by its first use.
template <bool kAttributes>
struct Vertex {
  uint64_t first;
  uint32_t q[3];
  float n[3];
  uint8_t c[4];
};
template <>
struct Vertex<false> {
  uint64_t first;
  uint32_t q[3];
  uint32_t unused;
};
static_assert(sizeof(Vertex<true>) == 40 && sizeof(Vertex<false>) == 24, "Vertex layout");
// A use and its vertex's first use (pass 2); then a use and its vertex id (pass 3).
struct UseRef {
  uint64_t key;
  uint64_t value;
};
struct FirstOf {
  template <class V>
  uint64_t operator()(const V& v) const { return v.first; }
};
struct KeyOf {
  uint64_t operator()(const UseRef& r) const { return r.key; }
};

// Patches decoded in parallel, in batches bounded by their triangles (and at most 1024, as
// assembleCut), handed over in order.
template <class Fn>
void forEachDecoded(const MtFileReader& r, const std::vector<uint32_t>& ids, uint64_t batchTriangles,
                    const std::function<void()>& poll, const Fn& fn) {
  std::vector<DecodedPatch> decoded;
  for (size_t first = 0; first < ids.size();) {
    if (poll) poll();
    size_t count = 0;
    uint64_t tris = 0;
    while (first + count < ids.size() && count < 1024 && (count == 0 || tris < batchTriangles))
      tris += r.patches().at(ids[first + count++]).triangles;
    decoded.assign(count, DecodedPatch{});
    tbb::parallel_for(size_t(0), count, [&](size_t i) { decoded[i] = r.readPatch(ids[first + i]); });
    for (size_t i = 0; i < count; ++i) {
      fn(first + i, decoded[i]);
      decoded[i] = DecodedPatch{};
    }
    first += count;
  }
}

}  // namespace

uint64_t assembledCutBytes(const MtFileReader& r, const std::vector<uint32_t>& arcs) {
  uint64_t vertices = 0, triangles = 0, batch = 0, largest = 0;
  const std::vector<uint32_t> ids = cutPatchIds(r, arcs);
  for (uint32_t id : ids) {
    const format::PatchRecord& p = r.patches().at(id);
    vertices += p.vertices, triangles += p.triangles;
    largest = std::max<uint64_t>(largest, p.vertices * 40ull + p.triangles * 12ull);
  }
  batch = 1024 * largest;
  const bool normals = r.header().vertexFlags & format::kHasNormals;
  const bool colors = r.header().vertexFlags & format::kHasColors;
  // Per vertex: q, positions, normals and their use counts, colours, and weld-index slots
  // (16 bytes, between 1.5 and 3 per vertex); per triangle: corners and patch.
  const uint64_t perVertex = 12 + 24 + (normals ? 16 : 0) + (colors ? 4 : 0) + 48;
  return vertices * perVertex + triangles * 16 + std::min<uint64_t>(batch, triangles * 60 + (1 << 20));
}

namespace {

template <bool kAttributes>
WeldedCutInfo weldCut(const MtFileReader& r, const std::vector<uint32_t>& arcs, const WeldedCutOptions& options,
                      WeldedCutSink& sink) {
  using UseRecord = Use<kAttributes>;
  using VertexRecord = Vertex<kAttributes>;
  const std::vector<uint32_t> ids = cutPatchIds(r, arcs);
  const QuantizationGrid grid = r.grid();
  const bool normals = r.header().vertexFlags & format::kHasNormals;
  const bool colors = r.header().vertexFlags & format::kHasColors;
  const std::string prefix = options.scratchDir + "/weld";
  // The budget: half for the sorts filling at any one time, an eighth for a batch of decoded
  // patches (~60 bytes a triangle), the rest for what the sorts' merges and the sink hold.
  const uint64_t budget = std::max<uint64_t>(options.memoryBytes, 64 << 10);
  const uint64_t sorts = budget / 2;
  const uint64_t batchTriangles = std::max<uint64_t>(1, budget / 8 / 60);
  WeldedCutInfo info;
  info.patches = ids.size();

  // Pass 1: every use, sorted by (q, seq).
  ExternalSorter<UseRecord, UseLess<kAttributes>> uses(prefix + ".uses", sorts / 2, UseLess<kAttributes>{});
  uint64_t seq = 0, patchTriangles = 0;
  forEachDecoded(r, ids, batchTriangles, options.poll, [&](size_t, const DecodedPatch& d) {
    const bool hasN = normals && d.normals.size() == d.q.size();
    const bool hasC = colors && d.colors.size() == size_t(d.vertexCount()) * 4;
    for (uint32_t v = 0; v < d.vertexCount(); ++v) {
      UseRecord u{};
      for (int a = 0; a < 3; ++a) {
        u.q[a] = d.q[3 * v + a];
        info.maxAbsCoordinate = std::max(info.maxAbsCoordinate, std::abs(grid.dequantize(a, u.q[a])));
      }
      u.seq = seq + v;
      if constexpr (kAttributes) {
        u.hasNormal = hasN;
        if (hasN) std::memcpy(u.n, &d.normals[3 * v], 12);
        for (int c = 0; c < 4; ++c) u.c[c] = hasC ? d.colors[4 * v + c] : 255;
      }
      uses.add(u);
    }
    auto same = [&](uint32_t a, uint32_t b) { return std::memcmp(&d.q[3 * a], &d.q[3 * b], 12) == 0; };
    for (uint32_t t = 0; t < d.triangleCount(); ++t) {
      const uint32_t* f = &d.triangles[3 * t];
      if (same(f[0], f[1]) || same(f[1], f[2]) || same(f[0], f[2])) ++info.degenerateTriangles;
    }
    patchTriangles += d.triangleCount();
    seq += d.vertexCount();
  });
  info.triangles = patchTriangles - info.degenerateTriangles;
  if (options.poll) options.poll();

  // Pass 2: grouped by q.
  uses.finish();
  StableKeySorter<VertexRecord, FirstOf> vertices(prefix + ".vertices", sorts / 4, FirstOf{});
  StableKeySorter<UseRef, KeyOf> byFirst(prefix + ".byfirst", sorts / 4, KeyOf{});
  {
    UseRecord u;
    bool have = uses.next(u);
    uint64_t groups = 0;
    while (have) {
      VertexRecord w{};
      w.first = u.seq;
      std::memcpy(w.q, u.q, 12);
      [[maybe_unused]] float n[3] = {0, 0, 0};
      if constexpr (kAttributes) std::memcpy(w.c, u.c, 4);
      do {
        if constexpr (kAttributes)
          if (u.hasNormal)
            for (int a = 0; a < 3; ++a) n[a] += u.n[a];
        byFirst.add({w.first, u.seq});
        have = uses.next(u);
      } while (have && std::memcmp(u.q, w.q, 12) == 0);
      if constexpr (kAttributes) {
        const float len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        if (len > 0)
          for (int a = 0; a < 3; ++a) n[a] /= len;
        std::memcpy(w.n, n, 12);
      }
      vertices.add(w);
      if ((++groups & 0xfffff) == 0 && options.poll) options.poll();
    }
    info.vertices = groups;
  }
  if (info.vertices >= (uint64_t(1) << 32)) fail(r.path(), "the cut has more than 2^32 vertices: cannot be indexed by 32 bits");
  info.normals = normals && info.vertices > 0;
  info.colors = colors && info.vertices > 0;
  sink.begin(info);

  // Pass 3: vertices in first-use order; every use gets its vertex's id.
  vertices.finish();
  byFirst.finish();
  StableKeySorter<UseRef, KeyOf> bySeq(prefix + ".byseq", sorts, KeyOf{});
  {
    VertexRecord w;
    UseRef ref;
    bool haveRef = byFirst.next(ref);
    for (uint64_t id = 0; vertices.next(w); ++id) {
      double p[3];
      for (int a = 0; a < 3; ++a) p[a] = grid.dequantize(a, w.q[a]);
      if constexpr (kAttributes) sink.vertex(p, info.normals ? w.n : nullptr, info.colors ? w.c : nullptr);
      else sink.vertex(p, nullptr, nullptr);
      while (haveRef && ref.key == w.first) {
        bySeq.add({ref.value, id});
        haveRef = byFirst.next(ref);
      }
      if ((id & 0xfffff) == 0 && options.poll) options.poll();
    }
    if (haveRef) fail(r.path(), "internal: a use without its vertex in the weld");
  }

  // Pass 4: triangles, patch by patch.
  bySeq.finish();
  std::vector<uint32_t> local;
  uint64_t expectSeq = 0, written = 0;
  forEachDecoded(r, ids, batchTriangles, options.poll, [&](size_t, const DecodedPatch& d) {
    local.resize(d.vertexCount());
    for (uint32_t v = 0; v < d.vertexCount(); ++v) {
      UseRef ref;
      if (!bySeq.next(ref) || ref.key != expectSeq++)
        fail(r.path(), "internal: the weld's uses and the second decode of the patches disagree");
      local[v] = uint32_t(ref.value);
    }
    for (uint32_t t = 0; t < d.triangleCount(); ++t) {
      const uint32_t a = local[d.triangles[3 * t]], b = local[d.triangles[3 * t + 1]], c = local[d.triangles[3 * t + 2]];
      if (a == b || b == c || a == c) continue;
      sink.triangle(a, b, c);
      ++written;
    }
  });
  UseRef rest;
  if (bySeq.next(rest) || expectSeq != seq || written != info.triangles)
    fail(r.path(), "internal: the second decode of the cut's patches gave other counts");
  return info;
}

}  // namespace

WeldedCutInfo writeWeldedCut(const MtFileReader& r, const std::vector<uint32_t>& arcs, const WeldedCutOptions& options,
                             WeldedCutSink& sink) {
  if (r.header().vertexFlags & (format::kHasNormals | format::kHasColors)) return weldCut<true>(r, arcs, options, sink);
  return weldCut<false>(r, arcs, options, sink);
}

}  // namespace mt
