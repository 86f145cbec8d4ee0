// Texture payloads: see texture_payload.h and mt_format.h "Textures".
#include "mtfile/texture_payload.h"

#include <zstd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <string>
#include <unordered_map>

#include "base/error.h"

namespace mt {

using namespace format;

namespace {

// Coordinates in 1/16 texel of the image (mt_format.h kUvCornerLists).
uint32_t quantizeUV(float x, uint32_t side) { return uint32_t(std::lround(std::clamp(double(x), 0.0, 1.0) * 16.0 * side)); }

void putVarint(std::vector<uint8_t>& out, uint32_t v) {
  while (v >= 0x80) out.push_back(uint8_t(v | 0x80)), v >>= 7;
  out.push_back(uint8_t(v));
}
uint32_t zigzag(int32_t v) { return (uint32_t(v) << 1) ^ uint32_t(v >> 31); }
int32_t unzigzag(uint32_t v) { return int32_t(v >> 1) ^ -int32_t(v & 1); }

}  // namespace

std::vector<uint8_t> encodeTexturePayload(const uint32_t* triangles, size_t triangleCount, size_t vertexCount,
                                          const float* cornerUV, const uint8_t* image, size_t imageBytes, uint16_t width,
                                          uint16_t height, uint8_t imageFormat) {
  // Kinds and values (mt_format.h kUvCornerLists): each vertex's distinct coordinates in order.
  std::vector<uint8_t> kinds(3 * triangleCount), values;
  std::vector<uint32_t> first(vertexCount, UINT32_MAX);  // per vertex: its list's start in `lists`
  struct Entry {
    uint32_t st;      // s << 16 | t
    uint32_t next;    // the vertex's next entry, UINT32_MAX: none
  };
  std::vector<Entry> lists;
  std::vector<uint32_t> last(vertexCount, UINT32_MAX);
  if (width == 0 || height == 0 || width > kMaxAtlasSide || height > kMaxAtlasSide) throw Error("texture payload: image size out of range");
  uint32_t prevS = 0, prevT = 0;
  for (size_t t = 0; t < triangleCount; ++t)
    for (int c = 0; c < 3; ++c) {
      const uint32_t v = triangles[3 * t + size_t(c)];
      if (v >= vertexCount) throw Error("texture payload: triangle " + std::to_string(t) + " names vertex " + std::to_string(v));
      const uint32_t s = quantizeUV(cornerUV[6 * t + 2 * size_t(c)], width), q = quantizeUV(cornerUV[6 * t + 2 * size_t(c) + 1], height);
      const uint32_t st = s << 16 | q;
      int k = 0;
      uint32_t e = first[v];
      for (; e != UINT32_MAX && lists[e].st != st; e = lists[e].next) ++k;
      if (e == UINT32_MAX) {
        if (k >= 255) throw Error("texture payload: vertex " + std::to_string(v) + " has more than 254 distinct texture coordinates");
        lists.push_back({st, UINT32_MAX});
        const uint32_t id = uint32_t(lists.size() - 1);
        if (first[v] == UINT32_MAX) first[v] = id;
        else lists[last[v]].next = id;
        last[v] = id;
        kinds[3 * t + size_t(c)] = 255;
        putVarint(values, zigzag(int32_t(s) - int32_t(prevS)));
        putVarint(values, zigzag(int32_t(q) - int32_t(prevT)));
        prevS = s, prevT = q;
      } else {
        kinds[3 * t + size_t(c)] = uint8_t(k);
      }
    }
  std::vector<uint8_t> raw = kinds;
  raw.insert(raw.end(), values.begin(), values.end());
  std::vector<uint8_t> frame(ZSTD_compressBound(raw.size()));
  const size_t z = ZSTD_compress(frame.data(), frame.size(), raw.data(), raw.size(), 9);
  if (ZSTD_isError(z)) throw Error(std::string("texture payload: ") + ZSTD_getErrorName(z));
  TexturePayloadHeader h{};
  h.triangleCount = uint32_t(triangleCount);
  h.width = width;
  h.height = height;
  h.imageFormat = imageFormat;
  h.uvCoding = kUvCornerLists;
  h.uvBytes = uint32_t(z);
  std::vector<uint8_t> out(sizeof h + z + imageBytes);
  std::memcpy(out.data(), &h, sizeof h);
  std::memcpy(out.data() + sizeof h, frame.data(), z);
  if (imageBytes) std::memcpy(out.data() + sizeof h + z, image, imageBytes);
  return out;
}

TexturePayload decodeTexturePayload(const uint8_t* data, size_t size, const uint32_t* triangles, size_t triangleCount,
                                    size_t vertexCount) {
  TexturePayloadHeader h;
  if (size < sizeof h) throw Error("texture payload shorter than its header");
  std::memcpy(&h, data, sizeof h);
  if (h.triangleCount != triangleCount)
    throw Error("texture payload has " + std::to_string(h.triangleCount) + " triangles, the patch " + std::to_string(triangleCount));
  if (h.uvCoding != kUvCornerLists || h.reserved != 0) throw Error("texture payload: unknown coordinate coding");
  if (h.imageFormat != kImageJpeg && h.imageFormat != kImagePng) throw Error("texture payload: unknown image format");
  if (h.width == 0 || h.height == 0 || h.width > kMaxAtlasSide || h.height > kMaxAtlasSide)
    throw Error("texture payload: image size out of range");
  if (h.uvBytes > size - sizeof h) throw Error("texture payload: coordinates run past its end");
  const uint8_t* frame = data + sizeof h;
  const unsigned long long rawSize = ZSTD_getFrameContentSize(frame, h.uvBytes);
  // Kinds (3 per triangle) and at most one value (two varints of up to 5 bytes) per corner.
  if (rawSize == ZSTD_CONTENTSIZE_ERROR || rawSize == ZSTD_CONTENTSIZE_UNKNOWN || rawSize < 3 * uint64_t(triangleCount) ||
      rawSize > 33 * uint64_t(triangleCount))
    throw Error("texture payload: bad coordinate frame");
  std::vector<uint8_t> raw(static_cast<size_t>(rawSize));
  const size_t n = ZSTD_decompress(raw.data(), raw.size(), frame, h.uvBytes);
  if (ZSTD_isError(n) || n != raw.size()) throw Error("texture payload: damaged coordinate frame");
  TexturePayload out;
  out.width = h.width;
  out.height = h.height;
  out.imageFormat = h.imageFormat;
  out.image.assign(data + sizeof h + h.uvBytes, data + size);
  out.cornerUV.resize(6 * triangleCount);
  std::vector<uint32_t> first(vertexCount, UINT32_MAX);
  struct Entry {
    uint32_t st, next;
  };
  std::vector<Entry> lists;
  std::vector<uint32_t> last(vertexCount, UINT32_MAX);
  size_t value = 3 * triangleCount;
  auto varint = [&]() {
    uint32_t v = 0;
    for (int shift = 0;; shift += 7) {
      if (value >= raw.size() || shift > 28) throw Error("texture payload: coordinate values end early or are damaged");
      const uint8_t b = raw[value++];
      v |= uint32_t(b & 0x7F) << shift;
      if (!(b & 0x80)) return v;
    }
  };
  int64_t prevS = 0, prevT = 0;
  const double su = 1.0 / (16.0 * h.width), sv = 1.0 / (16.0 * h.height);
  for (size_t t = 0; t < triangleCount; ++t)
    for (int c = 0; c < 3; ++c) {
      const uint32_t v = triangles[3 * t + size_t(c)];
      if (v >= vertexCount) throw Error("texture payload: triangle names a vertex out of range");
      const uint8_t kind = raw[3 * t + size_t(c)];
      uint32_t st;
      if (kind == 255) {
        prevS += unzigzag(varint());
        prevT += unzigzag(varint());
        if (prevS < 0 || prevT < 0 || prevS > 16 * int64_t(h.width) || prevT > 16 * int64_t(h.height))
          throw Error("texture payload: a coordinate lies outside the image");
        st = uint32_t(prevS) << 16 | uint32_t(prevT);
        lists.push_back({st, UINT32_MAX});
        const uint32_t id = uint32_t(lists.size() - 1);
        if (first[v] == UINT32_MAX) first[v] = id;
        else lists[last[v]].next = id;
        last[v] = id;
      } else {
        uint32_t e = first[v];
        for (int k = 0; k < kind && e != UINT32_MAX; ++k) e = lists[e].next;
        if (e == UINT32_MAX) throw Error("texture payload: a corner names a coordinate its vertex does not have");
        st = lists[e].st;
      }
      out.cornerUV[6 * t + 2 * size_t(c)] = float(double(st >> 16) * su);
      out.cornerUV[6 * t + 2 * size_t(c) + 1] = float(double(st & 0xFFFF) * sv);
    }
  if (value != raw.size()) throw Error("texture payload: trailing coordinate values");
  return out;
}

std::vector<uint32_t> matchDecodedTriangles(const DecodedPatch& decoded, const PatchInput& input, const QuantizationGrid& grid) {
  // Key: the three grid positions in ascending order (a hash over them), then candidates checked exactly.
  using Q = std::array<uint32_t, 3>;
  std::vector<Q> inputQ(input.vertexCount);
  for (size_t v = 0; v < input.vertexCount; ++v) grid.quantize(&input.positions[3 * v], inputQ[v].data());
  auto keyOf = [](Q a, Q b, Q c) {
    if (b < a) std::swap(a, b);
    if (c < b) std::swap(b, c);
    if (b < a) std::swap(a, b);
    uint64_t h = 1469598103934665603ull;
    for (const Q* q : {&a, &b, &c})
      for (uint32_t x : *q) h = (h ^ x) * 1099511628211ull;
    return h;
  };
  std::unordered_multimap<uint64_t, uint32_t> byKey;
  byKey.reserve(input.triangleCount * 2);
  for (uint32_t t = 0; t < input.triangleCount; ++t)
    byKey.emplace(keyOf(inputQ[input.triangles[3 * t]], inputQ[input.triangles[3 * t + 1]], inputQ[input.triangles[3 * t + 2]]), t);
  std::vector<uint8_t> used(input.triangleCount, 0);
  std::vector<uint32_t> out(decoded.triangleCount());
  auto qOf = [&](uint32_t v) { return Q{decoded.q[3 * v], decoded.q[3 * v + 1], decoded.q[3 * v + 2]}; };
  for (uint32_t t = 0; t < decoded.triangleCount(); ++t) {
    const Q d[3] = {qOf(decoded.triangles[3 * t]), qOf(decoded.triangles[3 * t + 1]), qOf(decoded.triangles[3 * t + 2])};
    auto range = byKey.equal_range(keyOf(d[0], d[1], d[2]));
    // The lowest unused input triangle with these corners in this cyclic order (duplicate faces
    // are taken in turn).
    uint32_t best = UINT32_MAX;
    for (auto it = range.first; it != range.second; ++it) {
      const uint32_t i = it->second;
      if (used[i] || 3 * i >= best) continue;
      for (uint32_t r = 0; r < 3; ++r)
        if (inputQ[input.triangles[3 * i + r]] == d[0] && inputQ[input.triangles[3 * i + (r + 1) % 3]] == d[1] &&
            inputQ[input.triangles[3 * i + (r + 2) % 3]] == d[2]) {
          best = 3 * i + r;
          break;
        }
    }
    if (best == UINT32_MAX) throw Error("texture: decoded triangle " + std::to_string(t) + " matches no triangle of the patch");
    used[best / 3] = 1;
    out[t] = best;
  }
  return out;
}

}  // namespace mt
