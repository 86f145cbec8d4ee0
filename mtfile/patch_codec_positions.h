// The position code of the meshopt payloads (mt_format.h, kPayloadRangePositions,
// kPayloadPositionContexts): the parallelogram walk that predicts each vertex from those decoded
// before it (Touma-Gotsman), and the context model of version 3 that range-codes the residuals by
// prediction kind. Shared by the encoder and the decoders of patch_codec_meshopt.cpp, and by the
// browser's wasm decoder (web/wasm/), so it needs the C++ standard library only.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "mtfile/range_coder.h"

namespace mt::codec_detail {

// Directed edge -> opposite vertex, for the parallelogram rule. Open addressing, no deletes.
class EdgeMap {
 public:
  explicit EdgeMap(size_t edges) {
    size_t n = 16;
    while (n < edges * 2) n *= 2;
    keys_.assign(n, ~0ull);
    vals_.resize(n);
    mask_ = n - 1;
  }
  void put(uint32_t a, uint32_t b, uint32_t c) {
    uint64_t k = (uint64_t(a) << 32) | b;
    for (uint64_t i = hash(k);; i = (i + 1) & mask_)
      if (keys_[i] == ~0ull || keys_[i] == k) {
        keys_[i] = k, vals_[i] = c;
        return;
      }
  }
  bool get(uint32_t a, uint32_t b, uint32_t* c) const {
    uint64_t k = (uint64_t(a) << 32) | b;
    for (uint64_t i = hash(k);; i = (i + 1) & mask_) {
      if (keys_[i] == ~0ull) return false;
      if (keys_[i] == k) return *c = vals_[i], true;
    }
  }

 private:
  uint64_t hash(uint64_t k) const { return ((k * 0x9E3779B97F4A7C15ull) >> 20) & mask_; }
  std::vector<uint64_t> keys_;
  std::vector<uint32_t> vals_;
  uint64_t mask_;
};

// How a vertex was predicted (the parallelogramWalk cases, mt_format.h), and from which corners:
// the context of its residual in the version-3 position model.
enum PredictionKind : uint32_t { kParallelogram = 0, kMidpoint = 1, kOneKnown = 2, kNoneKnown = 3 };
struct Prediction {
  uint32_t kind;
  uint32_t a, b, c;  // kParallelogram: a + b - c; kMidpoint: a, b; kOneKnown: a; kNoneKnown: a = last or ~0u
};

// Visits the vertices in first-use order of `indices` and calls f(v, pred, how) with the prediction
// of v from already visited vertices; f must make q[v] known before returning (the encoder already
// has it, the decoder computes it from the residual). Predictions are clamped to [0, range].
template <typename F>
void parallelogramWalk(const uint32_t* indices, size_t indexCount, size_t vertexCount, const int64_t* q,
                       const int64_t range[3], F&& f) {
  std::vector<uint8_t> known(vertexCount, 0);
  EdgeMap edges(indexCount);
  uint32_t last = ~0u;
  for (size_t t = 0; t < indexCount; t += 3) {
    for (int k = 0; k < 3; ++k) {
      uint32_t v = indices[t + k];
      if (known[v]) continue;
      uint32_t a = indices[t + (k + 1) % 3], b = indices[t + (k + 2) % 3], c;
      int64_t pred[3] = {0, 0, 0};
      Prediction how{kNoneKnown, last, ~0u, ~0u};
      if (known[a] && known[b]) {
        if (edges.get(b, a, &c) || edges.get(a, b, &c)) {
          for (int x = 0; x < 3; ++x) pred[x] = q[a * 3 + x] + q[b * 3 + x] - q[c * 3 + x];
          how = {kParallelogram, a, b, c};
        } else {
          for (int x = 0; x < 3; ++x) pred[x] = (q[a * 3 + x] + q[b * 3 + x]) >> 1;
          how = {kMidpoint, a, b, ~0u};
        }
      } else if (known[a] || known[b]) {
        uint32_t s = known[a] ? a : b;
        for (int x = 0; x < 3; ++x) pred[x] = q[s * 3 + x];
        how = {kOneKnown, s, ~0u, ~0u};
      } else if (last != ~0u) {
        for (int x = 0; x < 3; ++x) pred[x] = q[last * 3 + x];
      }
      for (int x = 0; x < 3; ++x) pred[x] = std::clamp<int64_t>(pred[x], 0, range[x]);
      f(v, pred, how);
      known[v] = 1;
      last = v;
    }
    uint32_t a = indices[t], b = indices[t + 1], c = indices[t + 2];
    edges.put(a, b, c), edges.put(b, c, a), edges.put(c, a, b);
  }
}

// Predictions are clamped to [0, kMaxQ] (the same on both sides), so |residual| < 2^31 and its
// zigzag code fits 32 bits.
constexpr int64_t kMaxQ = 0x7FFFFFFF;

inline uint32_t zigzag(int64_t r) { return uint32_t((uint64_t(r) << 1) ^ uint64_t(r >> 63)); }
inline int64_t unzigzag(uint32_t z) { return int64_t(z >> 1) ^ -int64_t(z & 1); }

// The position residual model: zigzag(r)'s bit length k (0..32) as a 6-bit tree, then the k-1
// bits below its leading one, with probabilities per (prediction kind, axis): parallelogram
// residuals are several times smaller than midpoint, one-known and first-vertex ones (mean k 2.2
// against 3.2, 3.4 and 7.6 per axis on a 0.8M scan-derived build), and mixing them in one context
// cost bits. Measured, position bytes per input triangle (0.8M scan-derived / 1M mtgen builds):
// version 2 (axis contexts, LZMA rate) 1.566 / 1.363; counted probabilities 1.530 / 1.316; and
// kind contexts 1.533 / 1.264. Also tried, all larger because a patch is too short to learn
// more contexts: the predicting edge's length in grid steps (bit length; as context 1.571 /
// 1.290, as the offset of k 1.636 / 1.352), the axis' share of the predicting triangle's normal
// (1.550 / 1.272), the mantissa by that share (1.558 / 1.272).
struct ContextModel {
  CountedBit length[4][3][64];     // [kind][axis][tree node]
  CountedBit mantissa[3][33][32];  // [axis][k][bit]
};

inline void encodeResidual(RangeEncoder& rc, ContextModel& m, uint32_t kind, uint32_t axis, uint32_t z) {
  uint32_t k = z ? 32 - uint32_t(__builtin_clz(z)) : 0;
  rc.tree(m.length[kind][axis], k, 6);
  CountedBit* man = m.mantissa[axis][k];
  for (uint32_t i = k >= 2 ? k - 1 : 0; i-- > 0;) rc.bit(man[i], (z >> i) & 1);
}

// False when the stream names a length above 32 (damaged payload).
inline bool decodeResidual(RangeDecoder& rc, ContextModel& m, uint32_t kind, uint32_t axis, uint32_t& z) {
  uint32_t k = rc.tree(m.length[kind][axis], 6);
  if (k > 32) return false;
  if (k <= 1) return z = k, true;
  CountedBit* man = m.mantissa[axis][k];
  z = 1;
  for (uint32_t i = k - 1; i-- > 0;) z = (z << 1) | rc.bit(man[i]);
  return true;
}
// Checks the decoded grid coordinates (each within [0, kMaxQ], every vertex seen) and stores them
// as qRel.
void storeDecodedPositions(const std::vector<int64_t>& q, size_t seenCount, size_t n, std::vector<uint32_t>& qRel);

// Positions with kPayloadPositionContexts: the encoder's walk replayed, each residual decoded with
// the context of its prediction kind, plus its prediction, gives q. Throws (bad) on a damaged
// stream.
void decodeContextPositions(RangeDecoder& rc, const std::vector<uint32_t>& triangles, size_t n,
                            std::vector<uint32_t>& qRel);

}  // namespace mt::codec_detail
