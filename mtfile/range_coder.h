// The adaptive binary range coder of the meshopt payloads (mt_format.h, kPayloadRangePositions,
// kPayloadRangeIndices, kPayloadPositionContexts): LZMA's coder with its 11-bit probabilities
// (version 2) and the counted probabilities of version 3.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace mt::codec_detail {

// A patch codes ~1000 vertices and ~2000 triangles: with LZMA's fixed adaptation rate (1/32 from
// an even start) most of the cost of a context is learning it, so every added context measured
// worse. Version-3 probabilities count their updates and move by 1/(n+2) for the n-th one (the
// frequency estimate, as in Krichevsky-Trofimov), by 1/32 from the 30th on (the LZMA rate): the
// first samples of a context teach it as much as a static table would.
struct CountedBit {
  uint16_t p = 2048;  // P(bit = 0) in 1/4096
  uint16_t n = 0;     // updates so far, saturating at kCountedBitLimit
};
constexpr uint16_t kCountedBitLimit = 30;
// kRate[n] = 65536 / (n + 2): integer, the same everywhere.
constexpr auto kRate = [] {
  std::array<uint32_t, kCountedBitLimit + 1> r{};
  for (uint32_t n = 0; n <= kCountedBitLimit; ++n) r[n] = 65536 / (n + 2);
  return r;
}();
inline void adapt(CountedBit& c, uint32_t b) {
  uint32_t rate = kRate[c.n];
  int32_t p = c.p;
  if (!b) p += int32_t((uint32_t(4096 - p) * rate) >> 16);
  else p -= int32_t((uint32_t(p) * rate) >> 16);
  c.p = uint16_t(std::clamp(p, 31, 4065));
  if (c.n < kCountedBitLimit) ++c.n;
}

// Adaptive binary range coder (the LZMA one: 32-bit range, 11-bit probabilities adapted by 1/32,
// carries propagated through a cached byte) for the position residuals. Measured on level-1
// regions of a 1M scan: the order-0 entropy of the zigzag residuals is 0.29 bytes per triangle,
// zstd over byte planes reached 0.51 (a Huffman table per ~500-vertex patch, LZ matches that do
// not exist in noise); this coder needs no table and adapts within the patch.
class RangeEncoder {
 public:
  explicit RangeEncoder(std::vector<uint8_t>& out) : out_(out), start_(out.size()) {}
  void bit(uint16_t& p, uint32_t b) {
    uint32_t bound = (range_ >> 11) * p;
    if (!b) {
      range_ = bound;
      p = uint16_t(p + ((2048 - p) >> 5));
    } else {
      low_ += bound;
      range_ -= bound;
      p = uint16_t(p - (p >> 5));
    }
    while (range_ < (1u << 24)) range_ <<= 8, shiftLow();
  }
  void bit(CountedBit& c, uint32_t b) {
    uint32_t bound = (range_ >> 12) * c.p;
    if (!b) {
      range_ = bound;
    } else {
      low_ += bound;
      range_ -= bound;
    }
    adapt(c, b);
    while (range_ < (1u << 24)) range_ <<= 8, shiftLow();
  }
  // nbits of sym, most significant first, through the binary tree probs[1 .. 2^nbits - 1].
  void tree(CountedBit* probs, uint32_t sym, int nbits) {
    for (uint32_t i = uint32_t(nbits), m = 1; i-- > 0;) {
      uint32_t b = (sym >> i) & 1;
      bit(probs[m], b);
      m = (m << 1) | b;
    }
  }
  // How many bytes finish() would leave in the output now, without changing the coder: the bytes
  // already out (less the unstored first one) and what its five flushing shifts would add.
  size_t finishedSize() const {
    uint64_t low = low_, pending = cacheSize_;
    size_t written = out_.size() - start_;
    for (int i = 0; i < 5; ++i) {
      if (uint32_t(low) < 0xFF000000u || (low >> 32) != 0) written += pending, pending = 0;
      ++pending;
      low = (low & 0x00FFFFFFu) << 8;
    }
    return written - 1;
  }
  void finish() {
    for (int i = 0; i < 5; ++i) shiftLow();
    out_.erase(out_.begin() + std::ptrdiff_t(start_));  // LZMA's first byte is always 0: not stored
  }

 private:
  void shiftLow() {
    if (uint32_t(low_) < 0xFF000000u || (low_ >> 32) != 0) {
      uint8_t carry = uint8_t(low_ >> 32), temp = cache_;
      do {
        out_.push_back(uint8_t(temp + carry));
        temp = 0xFF;
      } while (--cacheSize_ != 0);
      cache_ = uint8_t(low_ >> 24);
    }
    ++cacheSize_;
    low_ = (low_ & 0x00FFFFFFu) << 8;
  }
  std::vector<uint8_t>& out_;
  size_t start_;
  uint64_t low_ = 0, cacheSize_ = 1;
  uint32_t range_ = 0xFFFFFFFFu;
  uint8_t cache_ = 0;
};

class RangeDecoder {
 public:
  RangeDecoder(const uint8_t* p, const uint8_t* end) : p_(p), end_(end) {
    for (int i = 0; i < 4; ++i) code_ = (code_ << 8) | next();
  }
  uint32_t bit(uint16_t& p) {
    uint32_t bound = (range_ >> 11) * p, b;
    if (code_ < bound) {
      range_ = bound;
      p = uint16_t(p + ((2048 - p) >> 5));
      b = 0;
    } else {
      code_ -= bound;
      range_ -= bound;
      p = uint16_t(p - (p >> 5));
      b = 1;
    }
    while (range_ < (1u << 24)) range_ <<= 8, code_ = (code_ << 8) | next();
    return b;
  }
  uint32_t bit(CountedBit& c) {
    uint32_t bound = (range_ >> 12) * c.p, b;
    if (code_ < bound) {
      range_ = bound;
      b = 0;
    } else {
      code_ -= bound;
      range_ -= bound;
      b = 1;
    }
    adapt(c, b);
    while (range_ < (1u << 24)) range_ <<= 8, code_ = (code_ << 8) | next();
    return b;
  }
  uint32_t tree(CountedBit* probs, int nbits) {
    uint32_t m = 1;
    for (int i = 0; i < nbits; ++i) m = (m << 1) | bit(probs[m]);
    return m - (1u << nbits);
  }
  // Stream bytes read so far (the first 4 are read at construction).
  size_t consumed(const uint8_t* begin) const { return size_t(p_ - begin) + overrun_; }
  // Bytes asked for beyond the stream (a valid stream needs none).
  size_t overrun() const { return overrun_; }

 private:
  uint8_t next() {
    if (p_ < end_) return *p_++;
    ++overrun_;
    return 0;
  }
  const uint8_t* p_;
  const uint8_t* end_;
  uint32_t code_ = 0, range_ = 0xFFFFFFFFu;
  size_t overrun_ = 0;
};

}  // namespace mt::codec_detail
