// Codec::Meshopt (patch_codec.h; byte layouts in mt_format.h).
//
// Triangles: the connectivity code (patch_codec_connectivity.cpp), or meshopt_encodeIndexBuffer
// (list) or meshopt_encodeIndexSequence (strip) in the zstd frame. Positions:
// parallelogram prediction (Touma-Gotsman) along the decoded triangle order, residuals range-coded
// by prediction kind; normals/colours: meshopt vertex codec. The sizes and the attributes (and the
// index code when zstd finds its repeats) go into one zstd frame. Measured on scan-like patches the
// parallelogram residuals take ~40% fewer bytes than meshopt_encodeVertexBuffer on the raw grid
// coordinates (docs/mt-format.md).
#include <meshoptimizer.h>
#include <zstd.h>

#include <algorithm>
#include <cassert>
#include <cstring>
#include <memory>
#include <mutex>
#include <string>

#include "base/error.h"
#include "mtfile/patch_codec_detail.h"
#include "mtfile/patch_codec_positions.h"
#include "mtfile/range_coder.h"

namespace mt::codec_detail {

using format::Codec;
using format::PayloadHeader;

void setMeshoptVersions() {
  static std::once_flag once;
  // Index codec v1 (0.14+) codes triangle lists ~10% smaller than v0; vertex codec v0 is the
  // only one 0.18 has. Set once: these are process-wide settings in meshoptimizer.
  std::call_once(once, [] {
    meshopt_encodeIndexVersion(1);
    meshopt_encodeVertexVersion(0);
  });
}

namespace {

// The residual model (mt_format.h, kPayloadRangePositions): per axis, the bit length k (0..32)
// of zigzag(r) as a 6-bit binary tree, then the k-1 bits below its leading one, most significant
// first, each with its own probability per (axis, k, bit).
struct ResidualModel {
  uint16_t length[3][64];
  uint16_t mantissa[3][33][32];
  ResidualModel() {
    std::fill(&length[0][0], &length[0][0] + sizeof length / 2, uint16_t(1024));
    std::fill(&mantissa[0][0][0], &mantissa[0][0][0] + sizeof mantissa / 2, uint16_t(1024));
  }
  void encode(RangeEncoder& rc, int axis, uint32_t z) {
    uint32_t k = z ? 32 - uint32_t(__builtin_clz(z)) : 0;
    for (uint32_t i = 6, m = 1; i-- > 0;) {
      uint32_t b = (k >> i) & 1;
      rc.bit(length[axis][m], b);
      m = (m << 1) | b;
    }
    for (uint32_t i = k >= 2 ? k - 1 : 0; i-- > 0;) rc.bit(mantissa[axis][k][i], (z >> i) & 1);
  }
  // False when the stream names a length above 32 (damaged payload).
  bool decode(RangeDecoder& rc, int axis, uint32_t& z) {
    uint32_t m = 1;
    for (int i = 0; i < 6; ++i) m = (m << 1) | rc.bit(length[axis][m]);
    uint32_t k = m - 64;
    if (k > 32) return false;
    if (k == 0) return z = 0, true;
    z = 1;
    for (uint32_t i = k - 1; i-- > 0;) z = (z << 1) | rc.bit(mantissa[axis][k][i]);
    return true;
  }
};

// meshopt_encodeIndexBuffer, version 1, lays out a header byte (0xe1), one code byte per triangle,
// the data bytes (varint vertex deltas of the codes that need them), then its 16-byte auxiliary
// code table, which version 1 always writes as these bytes (meshoptimizer 0.18 indexcodec.cpp,
// kCodeAuxEncodingTable).
constexpr uint8_t kIndexHeaderV1 = 0xe1;
constexpr uint8_t kCodeAuxTableV1[16] = {0x00, 0x76, 0x87, 0x56, 0x67, 0x78, 0xa9, 0x86,
                                         0x65, 0x89, 0x68, 0x98, 0x01, 0x69, 0x00, 0x00};

// The index code's bytes, range-coded. A code byte's high nibble is the edge-FIFO slot the
// triangle reuses (15: none), its low nibble how the third vertex comes (0: the next new one);
// both depend on the triangle before (in fan order a fan's triangles repeat one code, a new fan
// starts with another). Measured on the patches of a 0.8M scan-derived build, bytes per input
// triangle for the index code: zstd 1.101, this model 0.924 (a static order-1 table 0.90).
struct IndexModel {
  CountedBit standard;
  CountedBit hi[32][16], lo[32][16];  // [previous high nibble, previous low nibble == 0][tree node]
  CountedBit data[2][256];            // [previous data byte continues a varint][tree node]
};

// The version-3 index code (meshopt_encodeIndexBuffer bytes, `bytes` of them, for `triangles`
// triangles; bytes >= 1 + triangles + 16 as version 1 always writes). Version-4 writers code the
// triangles with the connectivity code instead (patch_codec_connectivity.cpp).
void decodeIndexCode(RangeDecoder& rc, uint8_t* code, size_t bytes, uint32_t triangles) {
  IndexModel m;
  uint8_t* tail = code + bytes - 16;
  if (rc.bit(m.standard) == 0) {
    code[0] = kIndexHeaderV1;
    std::memcpy(tail, kCodeAuxTableV1, 16);
  } else {
    code[0] = uint8_t(rc.tree(m.data[0], 8));
    for (int i = 0; i < 16; ++i) tail[i] = uint8_t(rc.tree(m.data[0], 8));
  }
  // A valid stream is never read past its end: stop at once rather than decode the rest of a
  // damaged count from zeros (a 105-byte payload claiming 3.7M triangles took 1.4 s to refuse).
  // The message names the triangle (or code byte) being decoded when the stream ran out.
  uint32_t ctx = 0;
  for (uint32_t t = 0; t < triangles; ++t) {
    uint32_t h = rc.tree(m.hi[ctx], 4);
    uint32_t l = rc.tree(m.lo[(h << 1) | (ctx & 1)], 4);
    code[1 + t] = uint8_t((h << 4) | l);
    ctx = (h << 1) | (l == 0);
    if (rc.overrun() > 0)
      bad("index stream truncated at triangle " + std::to_string(t) + " of " + std::to_string(triangles));
  }
  uint32_t cont = 0;
  for (size_t i = 1 + triangles; i < bytes - 16; ++i) {
    code[i] = uint8_t(rc.tree(m.data[cont], 8));
    cont = code[i] >> 7;
    if (rc.overrun() > 0)
      bad("index stream truncated at code byte " + std::to_string(i) + " of " + std::to_string(bytes));
  }
}

// zstd over `raw` with one compression context per thread, reused: ZSTD_compress would allocate
// and clear a new one for every ~1 KB patch (its table set-up cost more than the compression
// itself). Same bytes.
std::vector<uint8_t> zstdFrame(const std::vector<uint8_t>& raw, int level) {
  std::vector<uint8_t> z(ZSTD_compressBound(raw.size()));
  thread_local std::unique_ptr<ZSTD_CCtx, size_t (*)(ZSTD_CCtx*)> cctx(ZSTD_createCCtx(), ZSTD_freeCCtx);
  if (!cctx) throw Error("encodePatch: zstd: cannot create a compression context");
  size_t zs = ZSTD_compressCCtx(cctx.get(), z.data(), z.size(), raw.data(), raw.size(), level);
  if (ZSTD_isError(zs)) throw Error(std::string("encodePatch: zstd: ") + ZSTD_getErrorName(zs));
  z.resize(zs);
  return z;
}

// The payload of the patch with the given triangle list (already in final order), in the smaller
// of two codings of the triangles:
//   A (version 2): the meshopt index code in the zstd frame, with the sizes and the attributes
//     (zstd finds the repeats of a regular grid's codes: 0.15 B/triangle on mtgen's level-0 patches);
//   C (version 4, kPayloadConnectivity; never for strips): sizes and attributes in the frame
//     (stored as they are when zstd does not make them smaller: zSize 0), the triangles by the
//     connectivity code ahead of the positions in the range-coded stream. Measured on the patches
//     of a 0.8M scan-derived build, index bytes per input triangle: zstd 1.10, the range-coded
//     meshopt code of version 3 (kPayloadRangeIndices) 0.92, the connectivity code 0.64.
// Version 3's coding (B) is never smaller than C, so the encoder no longer writes it.
std::vector<uint8_t> encodeMeshoptWith(const Prepared& p, const std::vector<uint32_t>& tri,
                                       const std::vector<uint8_t>& ibuf, uint32_t indexCount, bool strip,
                                       const PatchCodecOptions& options) {
  const PayloadHeader& h = p.header;
  size_t n = h.vertexCount;
  const int64_t range[3] = {kMaxQ, kMaxQ, kMaxQ};
  std::vector<int64_t> q(n * 3);
  for (size_t i = 0; i < n * 3; ++i) q[i] = p.q[i];
  std::vector<uint32_t> res(n * 3, 0);
  std::vector<uint8_t> kind(n, 0);
  // res in first-use order (the decoder's order): vertices are numbered by first use already, so
  // the walk meets them as 0, 1, 2, ... and the residuals are written in vertex order. The same
  // for both codings: C gives back the same triangles in the same order, each only rotated, and
  // a triangle whose corners are rotated has at most one new vertex.
  [[maybe_unused]] uint32_t visited = 0;
  parallelogramWalk(tri.data(), tri.size(), n, q.data(), range, [&](uint32_t v, const int64_t pred[3], const Prediction& how) {
    assert(v == visited++);
    for (int x = 0; x < 3; ++x) res[v * 3 + x] = zigzag(q[v * 3 + x] - pred[x]);
    kind[v] = uint8_t(how.kind);
  });
  uint8_t flags = uint8_t((h.flags & (format::kPayloadNormals | format::kPayloadColors)) |
                          format::kPayloadRangePositions | format::kPayloadPositionContexts |
                          (strip ? format::kPayloadStrip : 0));
  uint32_t attrStride = format::attributeStride(flags);
  std::vector<uint8_t> abuf;
  if (attrStride > 0) {
    std::vector<uint8_t> attrs(n * attrStride, 0);
    for (size_t v = 0; v < n; ++v) {
      uint8_t* d = &attrs[v * attrStride];
      if (!p.oct.empty()) std::memcpy(d, &p.oct[v * 2], 2), d += 2;
      if (!p.colors.empty()) std::memcpy(d, &p.colors[v * 4], 4);
    }
    abuf.resize(meshopt_encodeVertexBufferBound(n, attrStride));
    abuf.resize(meshopt_encodeVertexBuffer(abuf.data(), abuf.size(), attrs.data(), n, attrStride));
  }

  // A: sizes, index code and attributes in the frame; coded only where it can be the smaller: a
  // strip always (it has no C), a list when prepare() made its index code (Prepared::codingA).
  const bool tryA = strip || p.codingA;
  std::vector<uint8_t> raw, frame;
  if (tryA) {
    uint32_t sizes[3] = {uint32_t(ibuf.size()), indexCount, uint32_t(abuf.size())};
    appendBytes(raw, sizes, sizeof sizes);
    appendBytes(raw, ibuf.data(), ibuf.size());
    appendBytes(raw, abuf.data(), abuf.size());
    frame = zstdFrame(raw, options.zstdLevel);
  }
  // The range-coded stream: when C is chosen its encoder has coded the connectivity already and
  // goes on with the positions (one connectivity pass, not one to compare and one to write).
  std::vector<uint8_t> stream;
  std::unique_ptr<RangeEncoder> connEncoder;
  // C: the frame without the index code, and the connectivity code's bytes (coded alone here to
  // compare; the positions cost the same in both).
  if (!strip) {
    std::vector<uint8_t> rawC;
    uint32_t sizesC[3] = {0, indexCount, uint32_t(abuf.size())};
    appendBytes(rawC, sizesC, sizeof sizesC);
    appendBytes(rawC, abuf.data(), abuf.size());
    std::vector<uint8_t> frameC = abuf.empty() ? std::vector<uint8_t>() : zstdFrame(rawC, options.zstdLevel);
    bool stored = frameC.empty() || frameC.size() >= rawC.size();
    std::vector<uint32_t> coded;
    connEncoder = std::make_unique<RangeEncoder>(stream);
    encodeConnectivity(*connEncoder, tri.data(), tri.size(), n, coded);
    if (!tryA || (stored ? rawC.size() : frameC.size()) + connEncoder->finishedSize() <= frame.size()) {
      flags |= format::kPayloadConnectivity;
      raw.swap(rawC);
      if (stored) frame.clear();
      else frame.swap(frameC);
    } else {
      connEncoder.reset();
      stream.clear();
    }
  }

  PayloadHeader hh = h;
  hh.flags = flags;
  std::vector<uint8_t> out;
  appendBytes(out, &hh, sizeof hh);
  uint32_t rawSize = uint32_t(raw.size()), zSize = uint32_t(frame.size());
  appendBytes(out, &rawSize, 4);
  appendBytes(out, &zSize, 4);
  if (zSize) appendBytes(out, frame.data(), frame.size());
  else appendBytes(out, raw.data(), raw.size());
  // After the frame one range-coded stream: the connectivity code (kPayloadConnectivity), then
  // the position residuals in vertex order, x y z per vertex.
  RangeEncoder positionsOnly(stream);
  RangeEncoder& rc = connEncoder ? *connEncoder : positionsOnly;
  auto model = std::make_unique<ContextModel>();
  for (size_t v = 0; v < n; ++v)
    for (uint32_t x = 0; x < 3; ++x) encodeResidual(rc, *model, kind[v], x, res[v * 3 + x]);
  rc.finish();
  appendBytes(out, stream.data(), stream.size());
  return out;
}

// The patch as one tri-strip (BMT section 6 stores "optimized triangle strips"): meshopt_stripify
// of the coded list with restarts (~0u), coded by meshopt_encodeIndexSequence inside the zstd
// frame. The vertices are renumbered by first use in the strip, the order in which the decoder's
// walk meets them (and that keeps the sequence's deltas small). Empty when the strip does not give
// back every triangle (stripify drops degenerate ones): the caller then codes the list.
std::vector<uint8_t> encodeMeshoptStrip(const Prepared& p, const PatchCodecOptions& options) {
  size_t n = p.header.vertexCount;
  std::vector<uint32_t> s(meshopt_stripifyBound(p.indices.size()));
  s.resize(meshopt_stripify(s.data(), p.indices.data(), p.indices.size(), n, ~0u));
  std::vector<uint32_t> tri(meshopt_unstripifyBound(s.size()));
  tri.resize(meshopt_unstripify(tri.data(), s.data(), s.size(), ~0u));
  if (tri.size() != p.indices.size()) return {};
  std::vector<uint32_t> remap(n);
  size_t used = meshopt_optimizeVertexFetchRemap(remap.data(), tri.data(), tri.size(), n);
  if (used != n) return {};
  Prepared r;
  r.header = p.header;
  r.q.resize(n * 3);
  r.oct.resize(p.oct.size());
  r.colors.resize(p.colors.size());
  for (size_t v = 0; v < n; ++v) {
    std::memcpy(&r.q[remap[v] * 3], &p.q[v * 3], 12);
    if (!p.oct.empty()) std::memcpy(&r.oct[remap[v] * 2], &p.oct[v * 2], 2);
    if (!p.colors.empty()) std::memcpy(&r.colors[remap[v] * 4], &p.colors[v * 4], 4);
  }
  for (uint32_t& i : s)
    if (i != ~0u) i = remap[i];
  for (uint32_t& i : tri) i = remap[i];
  std::vector<uint8_t> sbuf(meshopt_encodeIndexSequenceBound(s.size(), n));
  sbuf.resize(meshopt_encodeIndexSequence(sbuf.data(), sbuf.size(), s.data(), s.size()));
  return encodeMeshoptWith(r, tri, sbuf, uint32_t(s.size()), true, options);
}

// The zstd frame (or stored bytes) after the payload header, decompressed: the three sizes and the
// streams the frame holds. rangeBegin is where the range-coded stream starts.
struct MeshoptFrame {
  std::vector<uint8_t> raw;
  uint32_t sizes[3];  // indexBytes, indexCount, attributeBytes
  const uint8_t* rangeBegin;
};

MeshoptFrame readMeshoptFrame(const uint8_t* data, size_t size, const PayloadHeader& h) {
  size_t pos = sizeof(PayloadHeader);
  uint32_t rawSize, zSize;
  if (size < pos + 8) bad("truncated before the zstd frame");
  std::memcpy(&rawSize, data + pos, 4);
  std::memcpy(&zSize, data + pos + 4, 4);
  pos += 8;
  const bool ranged = h.flags & format::kPayloadRangePositions;
  const bool rangeIndices = h.flags & format::kPayloadRangeIndices;
  const bool contextual = h.flags & format::kPayloadPositionContexts;
  const bool connectivity = h.flags & format::kPayloadConnectivity;
  if ((rangeIndices || contextual) && !ranged) bad("version-3 flags without range-coded positions");
  if (rangeIndices && (h.flags & format::kPayloadStrip)) bad("range-coded indices cannot be a strip");
  if (connectivity && (!contextual || rangeIndices || (h.flags & format::kPayloadStrip)))
    bad("connectivity code with flags " + std::to_string(h.flags));
  // Version 3 with range-coded indices, and version 4 with the connectivity code, may store the
  // raw bytes as they are (zSize 0).
  const bool stored = (rangeIndices || connectivity) && zSize == 0;
  const size_t frameBytes = stored ? rawSize : zSize;
  // Version 1 payloads end with the zstd frame; range-coded streams follow it.
  if (ranged ? frameBytes > size - pos : size - pos != zSize)
    bad("zstd frame size " + std::to_string(zSize) + " does not match payload");
  // rawSize is bounded by what the counts allow, so a damaged header cannot make us allocate GBs
  size_t n = h.vertexCount;
  uint64_t tri3 = uint64_t(h.triangleCount) * 3;
  uint64_t maxRaw = 12 + meshopt_encodeIndexSequenceBound(tri3 + h.triangleCount, n) +
                    meshopt_encodeIndexBufferBound(tri3, n) + meshopt_encodeVertexBufferBound(n, 8) + n * 12;
  if (rawSize > maxRaw) bad("raw size " + std::to_string(rawSize) + " too large for its counts");
  // Checked before decompressing: an empty stream would reach memcpy with a null destination.
  if (rawSize < 12) bad("raw stream too short");
  MeshoptFrame f;
  f.raw.resize(rawSize);
  if (stored) {
    std::memcpy(f.raw.data(), data + pos, rawSize);
  } else {
    thread_local std::unique_ptr<ZSTD_DCtx, size_t (*)(ZSTD_DCtx*)> dctx(ZSTD_createDCtx(), ZSTD_freeDCtx);
    if (!dctx) bad("cannot create a zstd decompression context");
    size_t got = ZSTD_decompressDCtx(dctx.get(), f.raw.data(), f.raw.size(), data + pos, zSize);
    if (ZSTD_isError(got) || got != rawSize) bad("zstd frame does not decompress");
  }
  std::memcpy(f.sizes, f.raw.data(), 12);
  f.rangeBegin = data + pos + frameBytes;
  return f;
}

// The triangle list from the index code `ib` (a list, or a strip with kPayloadStrip).
void decodeMeshoptTriangles(const PayloadHeader& h, const uint8_t* ib, const uint32_t sizes[3], DecodedPatch& out) {
  size_t n = h.vertexCount;
  uint64_t tri3 = uint64_t(h.triangleCount) * 3;
  uint32_t indexCount = sizes[1];
  if (h.flags & format::kPayloadStrip) {
    if (indexCount > tri3 + h.triangleCount + 3) bad("strip too long");
    std::vector<uint32_t> s(indexCount);
    if (indexCount && meshopt_decodeIndexSequence(s.data(), indexCount, 4, ib, sizes[0]) != 0)
      bad("index sequence does not decode");
    for (uint32_t i : s)
      if (i != ~0u && i >= n) bad("strip index out of range");
    out.triangles.resize(meshopt_unstripifyBound(indexCount));
    out.triangles.resize(meshopt_unstripify(out.triangles.data(), s.data(), indexCount, ~0u));
  } else {
    if (indexCount != tri3) bad("index count does not match triangle count");
    out.triangles.resize(indexCount);
    if (indexCount && meshopt_decodeIndexBuffer(out.triangles.data(), indexCount, 4, ib, sizes[0]) != 0)
      bad("index stream does not decode");
  }
  if (out.triangles.size() != tri3) bad("triangle count mismatch");
  for (uint32_t i : out.triangles)
    if (i >= n) bad("triangle index " + std::to_string(i) + " out of range");
}

// Normals and colours from the meshopt vertex code `ab` of `bytes` bytes.
void decodeMeshoptAttributes(const PayloadHeader& h, const uint8_t* ab, uint32_t bytes, DecodedPatch& out) {
  size_t n = h.vertexCount;
  uint32_t attrStride = format::attributeStride(h.flags);
  if (attrStride == 0) {
    if (bytes != 0) bad("attribute stream present without attributes");
    return;
  }
  std::vector<uint8_t> attrs(n * attrStride);
  if (n && meshopt_decodeVertexBuffer(attrs.data(), n, attrStride, ab, bytes) != 0)
    bad("attribute stream does not decode");
  if (h.flags & format::kPayloadNormals) out.normals.resize(n * 3);
  if (h.flags & format::kPayloadColors) out.colors.resize(n * 4);
  for (size_t v = 0; v < n; ++v) {
    const uint8_t* d = &attrs[v * attrStride];
    if (h.flags & format::kPayloadNormals) decodeOctahedral8(d, &out.normals[v * 3]), d += 2;
    if (h.flags & format::kPayloadColors) std::memcpy(&out.colors[v * 4], d, 4);
  }
}

// Positions of version 1 (byte planes `pb` in the frame) and version 2 (range-coded, one context
// per axis): all residuals first, then the walk.
void decodeLegacyPositions(RangeDecoder& rc, bool ranged, size_t planes, const uint8_t* pb,
                           const std::vector<uint32_t>& triangles, size_t n, std::vector<uint32_t>& qRel) {
  std::vector<uint32_t> res;
  if (ranged) {
    res.resize(n * 3);
    ResidualModel model;
    for (size_t i = 0; i < n * 3; ++i) {
      if (!model.decode(rc, int(i % 3), res[i])) bad("position stream names a residual wider than 32 bits");
      if (rc.overrun() > 0) bad("position stream truncated");
    }
  }
  std::vector<int64_t> q(n * 3, 0);
  const int64_t range[3] = {kMaxQ, kMaxQ, kMaxQ};
  size_t seenCount = 0;
  parallelogramWalk(triangles.data(), triangles.size(), n, q.data(), range,
                    [&](uint32_t v, const int64_t pred[3], const Prediction&) {
                      for (int x = 0; x < 3; ++x) {
                        uint32_t z = 0;
                        if (ranged) z = res[v * 3 + x];
                        else
                          for (size_t b = 0; b < planes; ++b) z |= uint32_t(pb[(x * planes + b) * n + v]) << (8 * b);
                        q[v * 3 + x] = pred[x] + unzigzag(z);
                      }
                      ++seenCount;
                    });
  storeDecodedPositions(q, seenCount, n, qRel);
}

}  // namespace

std::vector<uint8_t> encodeMeshopt(const Prepared& p, const PatchCodecOptions& options) {
  setMeshoptVersions();
  if (options.strips && !p.indices.empty()) {
    std::vector<uint8_t> strip = encodeMeshoptStrip(p, options);
    if (!strip.empty()) return strip;
  }
  return encodeMeshoptWith(p, p.indices, p.indexCode, uint32_t(p.indices.size()), false, options);
}

void decodeMeshopt(const uint8_t* data, size_t size, const PayloadHeader& h, DecodedPatch& out,
                   std::vector<uint32_t>& qRel) {
  MeshoptFrame f = readMeshoptFrame(data, size, h);
  const bool ranged = h.flags & format::kPayloadRangePositions;
  const bool rangeIndices = h.flags & format::kPayloadRangeIndices;
  size_t n = h.vertexCount;
  size_t planes = ranged ? 0 : (h.flags & format::kPayloadWide) ? 4 : 2;
  const uint32_t* sizes = f.sizes;
  // The range-coded stream (positions, and first the index code with kPayloadRangeIndices).
  RangeDecoder rc(f.rangeBegin, data + size);
  std::vector<uint8_t> rangedIndex;
  const uint8_t* ib = f.raw.data() + 12;
  const uint8_t* ab = ib + sizes[0];
  if (h.flags & format::kPayloadConnectivity) {
    if (uint64_t(sizes[2]) + 12 != f.raw.size() || sizes[0] != 0 || sizes[1] != uint64_t(h.triangleCount) * 3)
      bad("stream sizes do not add up");
    decodeConnectivity(rc, h.triangleCount, uint32_t(n), out.triangles);
    decodeMeshoptAttributes(h, f.raw.data() + 12, sizes[2], out);
    decodeContextPositions(rc, out.triangles, n, qRel);
    return;
  }
  if (rangeIndices) {
    if (uint64_t(sizes[2]) + 12 != f.raw.size()) bad("stream sizes do not add up");
    if (sizes[0] < 1 + uint64_t(h.triangleCount) + 16 ||
        sizes[0] > meshopt_encodeIndexBufferBound(uint64_t(h.triangleCount) * 3, n))
      bad("index code size " + std::to_string(sizes[0]) + " does not fit the triangle count");
    rangedIndex.resize(sizes[0]);
    decodeIndexCode(rc, rangedIndex.data(), rangedIndex.size(), h.triangleCount);
    if (rc.overrun() > 0) bad("index stream truncated");
    ib = rangedIndex.data();
    ab = f.raw.data() + 12;
  } else if (uint64_t(sizes[0]) + sizes[2] + 12 + n * 3 * planes != f.raw.size()) {
    bad("stream sizes do not add up");
  }
  decodeMeshoptTriangles(h, ib, sizes, out);
  decodeMeshoptAttributes(h, ab, sizes[2], out);
  if (h.flags & format::kPayloadPositionContexts) decodeContextPositions(rc, out.triangles, n, qRel);
  else decodeLegacyPositions(rc, ranged, planes, ab + sizes[2], out.triangles, n, qRel);
}

PayloadBytes meshoptPayloadBytes(const uint8_t* data, size_t size) {
  PayloadBytes b;
  b.header = sizeof(PayloadHeader);
  PayloadHeader h;
  if (size < sizeof h + 8) return b.other = size - b.header, b;
  std::memcpy(&h, data, sizeof h);
  uint32_t rawSize, zSize;
  std::memcpy(&rawSize, data + sizeof h, 4);
  std::memcpy(&zSize, data + sizeof h + 4, 4);
  b.header += 8;
  const bool rangeIndices = h.flags & format::kPayloadRangeIndices;
  const bool connectivity = h.flags & format::kPayloadConnectivity;
  size_t frame = (rangeIndices || connectivity) && zSize == 0 ? rawSize : zSize;
  if (frame > size - b.header) return b.other = size - b.header, b;
  if (!(h.flags & format::kPayloadRangePositions)) return b.index = size - b.header, b;
  const uint8_t* rs = data + b.header + frame;
  size_t rest = size - b.header - frame;
  if (!rangeIndices && !connectivity) {
    // The frame holds the index code (and the attributes, if any).
    b.index = frame, b.positions = rest;
    return b;
  }
  b.attributes = frame;
  if (connectivity) {
    if (h.triangleCount > format::kMaxPayloadTriangles || uint64_t(h.vertexCount) > uint64_t(h.triangleCount) * 3)
      return b.other = rest, b;
    RangeDecoder rc(rs, rs + rest);
    std::vector<uint32_t> triangles;
    try {
      decodeConnectivity(rc, h.triangleCount, h.vertexCount, triangles);
    } catch (const Error&) {
      return b.other = rest, b;
    }
    b.index = std::min(rest, rc.consumed(rs) > 4 ? rc.consumed(rs) - 4 : size_t(0));
    b.positions = rest - b.index;
    return b;
  }
  std::vector<uint8_t> raw(std::max<uint32_t>(rawSize, 12));
  if (zSize == 0) std::memcpy(raw.data(), data + b.header, rawSize);
  else if (ZSTD_isError(ZSTD_decompress(raw.data(), raw.size(), data + b.header, zSize))) return b.other = rest, b;
  uint32_t indexBytes;
  std::memcpy(&indexBytes, raw.data(), 4);
  if (indexBytes < 1 + uint64_t(h.triangleCount) + 16 || indexBytes > (uint64_t(h.triangleCount) + 1) * 64)
    return b.other = rest, b;
  std::vector<uint8_t> code(indexBytes);
  RangeDecoder rc(rs, rs + rest);
  try {
    decodeIndexCode(rc, code.data(), code.size(), h.triangleCount);
  } catch (const Error&) {
    return b.other = rest, b;
  }
  // The decoder has read up to 4 bytes ahead of what the index code needed.
  b.index = std::min(rest, rc.consumed(rs) > 4 ? rc.consumed(rs) - 4 : size_t(0));
  b.positions = rest - b.index;
  return b;
}

}  // namespace mt::codec_detail
