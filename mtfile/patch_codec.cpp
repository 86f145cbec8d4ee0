// Patch codec (see patch_codec.h; byte layouts in mt_format.h): the grid, octahedral normals, the
// preparation shared by both codecs, and the dispatch. The codecs are patch_codec_meshopt.cpp and
// patch_codec_draco.cpp (patch_codec_detail.h lists the files).
#include "mtfile/patch_codec.h"

#include <meshoptimizer.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <string>

#include "base/error.h"
#include "mtfile/fan_order.h"
#include "mtfile/patch_codec_detail.h"

namespace mt {

using format::Codec;
using format::PayloadHeader;
using codec_detail::bad;
using codec_detail::Prepared;

// ---------------------------------------------------------------------------------------------
// Grid

QuantizationGrid QuantizationGrid::fromBounds(const double minCorner[3], const double maxCorner[3],
                                              double step) {
  if (!(step > 0) || !std::isfinite(step)) throw Error("quantization grid: step must be > 0");
  QuantizationGrid g;
  g.step = step;
  uint32_t bits = 1;
  for (int a = 0; a < 3; ++a) {
    g.origin[a] = minCorner[a];
    double cells = std::floor((maxCorner[a] - minCorner[a]) / step + 0.5) + 1;
    if (!(cells < double(1u << 31)))
      throw Error("quantization grid: box needs more than 31 bits per axis at step " + std::to_string(step),
                  ErrorKind::Resource);
    while (double(1ull << bits) < cells) ++bits;
  }
  g.bits = bits;
  return g;
}

void QuantizationGrid::quantize(const double p[3], uint32_t q[3]) const {
  for (int a = 0; a < 3; ++a) {
    // round half up, the same on every machine: shared vertices must get the same q everywhere
    double v = std::floor((p[a] - origin[a]) / step + 0.5);
    if (!(v >= 0 && v < double(1ull << bits)))
      throw Error("quantization grid: position " + std::to_string(p[a]) + " outside the grid on axis " +
                  std::to_string(a));
    q[a] = uint32_t(v);
  }
}

double QuantizationGrid::maxError() const { return step * std::sqrt(3.0) * 0.5; }

// ---------------------------------------------------------------------------------------------
// Octahedral normals (Meyer et al. 2010, "On floating-point normal vectors"), 8 bits per component.

static float signNotZero(float v) { return v >= 0 ? 1.f : -1.f; }

void encodeOctahedral8(const float n[3], uint8_t out[2]) {
  float l1 = std::fabs(n[0]) + std::fabs(n[1]) + std::fabs(n[2]);
  float x = 0, y = 0;
  if (l1 > 0) {
    x = n[0] / l1;
    y = n[1] / l1;
    if (n[2] < 0) {
      float fx = (1 - std::fabs(y)) * signNotZero(x);
      float fy = (1 - std::fabs(x)) * signNotZero(y);
      x = fx;
      y = fy;
    }
  } else {
    x = 0, y = 0;  // degenerate normal: +z
  }
  out[0] = uint8_t(std::lround(std::clamp(x * 0.5f + 0.5f, 0.f, 1.f) * 255.f));
  out[1] = uint8_t(std::lround(std::clamp(y * 0.5f + 0.5f, 0.f, 1.f) * 255.f));
}

void decodeOctahedral8(const uint8_t in[2], float n[3]) {
  float x = in[0] / 255.f * 2 - 1, y = in[1] / 255.f * 2 - 1;
  float z = 1 - std::fabs(x) - std::fabs(y);
  if (z < 0) {
    float fx = (1 - std::fabs(y)) * signNotZero(x);
    float fy = (1 - std::fabs(x)) * signNotZero(y);
    x = fx;
    y = fy;
  }
  float len = std::sqrt(x * x + y * y + z * z);
  n[0] = x / len, n[1] = y / len, n[2] = z / len;
}

// ---------------------------------------------------------------------------------------------
// Shared preparation: compact, quantize, order.

[[noreturn]] void codec_detail::bad(const std::string& what) { throw Error("bad patch payload: " + what); }

namespace {

Prepared prepare(const PatchInput& in, const QuantizationGrid& grid, const PatchCodecOptions& options) {
  if (in.triangleCount > 0 && (!in.triangles || !in.positions))
    throw Error("encodePatch: null positions or triangles");
  for (size_t i = 0; i < in.triangleCount * 3; ++i)
    if (in.triangles[i] >= in.vertexCount)
      throw Error("encodePatch: triangle " + std::to_string(i / 3) + " uses vertex " +
                  std::to_string(in.triangles[i]) + " of " + std::to_string(in.vertexCount));

  Prepared out;
  size_t indexCount = in.triangleCount * 3;
  // Triangle order, then vertices renumbered by first use: both make the index and vertex deltas
  // small, which is what the codecs exploit. meshopt_encodeIndexBuffer codes a triangle cheaply
  // when it shares an edge with a recent one and brings its new vertex in fetch order. Patches
  // often arrive in an order that is already good: a scan's faces come in scan order (level 0),
  // and that order is kept when its index code is strip-like already (<= kCoherentIndexBytes per
  // triangle before zstd; measured on the 10M mtgen scan's patches: 1.04-1.52, a shuffled scan's
  // 5.3-6.4). Simplification keeps the survivors' order, which is not coherent any more (1.91 on
  // the simplified patches of a 2M scan): those are put in fan order (fan_order.h: 1.20;
  // meshopt_optimizeVertexCacheStrip gets 1.16 but costs 3.4x as much, ~8% of the level loop's
  // instructions, ~15% of its time before the input order was kept). Whole files on the m10 scan,
  // bytes per input triangle: cache-strip order for the incoherent patches 2.40, fan order 2.33
  // (the parallelogram-predicted positions and zstd gain more than the index code loses), and
  // 2.31 with the threshold at 1.3 instead of 1.6 (flat from 1.15 to 1.4); fan order for every
  // patch 2.44. Level-loop CPU 18.9 -> 16.6 s. Deterministic either way.
  constexpr double kCoherentIndexBytes = 1.3;
  std::vector<uint32_t> remap(in.vertexCount);
  codec_detail::setMeshoptVersions();  // the index codec version is process-wide state: set before the first encode
  // The index code is what the coherence test below and payload coding A (Prepared::codingA)
  // read; a simplified patch uses neither.
  out.codingA = !options.simplified;
  const bool indexCode = out.codingA;
  auto orderBy = [&](const uint32_t* tri) {
    size_t used = meshopt_optimizeVertexFetchRemap(remap.data(), tri, indexCount, in.vertexCount);
    out.indices.resize(indexCount);
    meshopt_remapIndexBuffer(out.indices.data(), tri, indexCount, remap.data());
    if (indexCode) {
      out.indexCode.resize(meshopt_encodeIndexBufferBound(indexCount, used));
      out.indexCode.resize(meshopt_encodeIndexBuffer(out.indexCode.data(), out.indexCode.size(), out.indices.data(), indexCount));
    }
    return used;
  };
  size_t used = 0;
  if (options.codec == Codec::Draco) {
    // Edgebreaker chooses its own traversal; only the fetch order matters here.
    used = meshopt_optimizeVertexFetchRemap(remap.data(), in.triangles, indexCount, in.vertexCount);
    out.indices.resize(indexCount);
    meshopt_remapIndexBuffer(out.indices.data(), in.triangles, indexCount, remap.data());
  } else {
    if (!options.simplified) used = orderBy(in.triangles);
    if (options.simplified || double(out.indexCode.size()) > kCoherentIndexBytes * double(in.triangleCount)) {
      std::vector<uint32_t> ordered(indexCount);
      fanOrderTriangles(ordered.data(), in.triangles, indexCount, in.vertexCount);
      used = orderBy(ordered.data());
    }
  }

  std::vector<uint32_t> qAbs(used * 3);
  uint32_t qMin[3] = {~0u, ~0u, ~0u};
  for (size_t v = 0; v < in.vertexCount; ++v) {
    if (remap[v] == ~0u) continue;
    uint32_t* q = &qAbs[remap[v] * 3];
    grid.quantize(in.positions + v * 3, q);
    for (int a = 0; a < 3; ++a) qMin[a] = std::min(qMin[a], q[a]);
  }
  if (used == 0) qMin[0] = qMin[1] = qMin[2] = 0;

  PayloadHeader& h = out.header;
  h.vertexCount = uint32_t(used);
  h.triangleCount = uint32_t(in.triangleCount);
  for (int a = 0; a < 3; ++a) h.qMin[a] = qMin[a];
  h.flags = 0;
  out.q.resize(used * 3);
  for (size_t i = 0; i < used * 3; ++i) out.q[i] = qAbs[i] - qMin[i % 3];

  if (options.normals) {
    h.flags |= format::kPayloadNormals;
    std::vector<float> n(used * 3, 0.f);
    if (in.normals) {
      for (size_t v = 0; v < in.vertexCount; ++v)
        if (remap[v] != ~0u) std::memcpy(&n[remap[v] * 3], in.normals + v * 3, 12);
    } else {
      // Area-weighted face normals of the QUANTIZED geometry (what the renderer will draw).
      for (size_t t = 0; t < indexCount; t += 3) {
        const uint32_t* a = &out.q[out.indices[t] * 3];
        const uint32_t* b = &out.q[out.indices[t + 1] * 3];
        const uint32_t* c = &out.q[out.indices[t + 2] * 3];
        double e1[3], e2[3];
        for (int k = 0; k < 3; ++k) e1[k] = double(b[k]) - a[k], e2[k] = double(c[k]) - a[k];
        double fn[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                        e1[0] * e2[1] - e1[1] * e2[0]};
        for (int j = 0; j < 3; ++j)
          for (int k = 0; k < 3; ++k) n[out.indices[t + j] * 3 + k] += float(fn[k]);
      }
    }
    out.oct.resize(used * 2);
    for (size_t v = 0; v < used; ++v) encodeOctahedral8(&n[v * 3], &out.oct[v * 2]);
  }
  if (in.colors && options.colors) {
    h.flags |= format::kPayloadColors;
    out.colors.resize(used * 4);
    for (size_t v = 0; v < in.vertexCount; ++v)
      if (remap[v] != ~0u) std::memcpy(&out.colors[remap[v] * 4], in.colors + v * 4, 4);
  }
  return out;
}

}  // namespace

// ---------------------------------------------------------------------------------------------

PayloadBytes payloadBytes(const uint8_t* data, size_t size, Codec codec) {
  if (codec == Codec::Meshopt && size >= sizeof(PayloadHeader)) return codec_detail::meshoptPayloadBytes(data, size);
  PayloadBytes b;
  b.header = std::min(size, sizeof(PayloadHeader));
  b.other = size - b.header;
  return b;
}

std::vector<uint8_t> encodePatch(const PatchInput& patch, const QuantizationGrid& grid,
                                 const PatchCodecOptions& options) {
  Prepared p = prepare(patch, grid, options);
  switch (options.codec) {
    case Codec::Meshopt: return codec_detail::encodeMeshopt(p, options);
    case Codec::Draco: return codec_detail::encodeDraco(p, options);
  }
  throw Error("encodePatch: unknown codec " + std::to_string(uint32_t(options.codec)));
}

namespace {

DecodedPatch decodeWithHeader(const uint8_t* data, size_t size, Codec codec, const QuantizationGrid& grid,
                              const PayloadHeader& h) {
  // Every bit of h.flags is defined (mt_format.h); the codec checks the combinations.
  // The counts bound every allocation below (mt_format.h): not the payload's size, which a flat,
  // regular patch makes tiny (hundreds of triangles per byte).
  if (h.triangleCount > format::kMaxPayloadTriangles)
    bad(std::to_string(h.triangleCount) + " triangles, more than a payload may hold (" +
        std::to_string(format::kMaxPayloadTriangles) + ")");
  if (uint64_t(h.vertexCount) > uint64_t(h.triangleCount) * 3)
    bad(std::to_string(h.vertexCount) + " vertices for " + std::to_string(h.triangleCount) +
        " triangles (every vertex belongs to a triangle)");
  DecodedPatch out;
  std::vector<uint32_t> qRel;
  switch (codec) {
    case Codec::Meshopt: codec_detail::decodeMeshopt(data, size, h, out, qRel); break;
    case Codec::Draco: codec_detail::decodeDraco(data, size, h, out, qRel); break;
    default: bad("unknown codec " + std::to_string(uint32_t(codec)));
  }
  size_t n = qRel.size() / 3;
  for (uint32_t i : out.triangles)
    if (i >= n) bad("triangle index " + std::to_string(i) + " out of range");
  out.q.resize(n * 3);
  out.positions.resize(n * 3);
  for (size_t i = 0; i < n * 3; ++i) {
    uint64_t q = uint64_t(qRel[i]) + h.qMin[i % 3];
    if (q >= (1ull << grid.bits)) bad("grid coordinate outside the grid");
    out.q[i] = uint32_t(q);
    out.positions[i] = float(grid.dequantize(int(i % 3), uint32_t(q)));
  }
  return out;
}

PayloadHeader headerOf(const uint8_t* data, size_t size) {
  if (size < sizeof(PayloadHeader)) bad("shorter than its header (" + std::to_string(size) + " bytes)");
  PayloadHeader h;
  std::memcpy(&h, data, sizeof h);
  return h;
}

}  // namespace

DecodedPatch decodePatch(const uint8_t* data, size_t size, Codec codec, const QuantizationGrid& grid) {
  return decodeWithHeader(data, size, codec, grid, headerOf(data, size));
}

DecodedPatch decodePatch(const uint8_t* data, size_t size, Codec codec, const QuantizationGrid& grid,
                         uint32_t indexTriangles) {
  const PayloadHeader h = headerOf(data, size);
  if (h.triangleCount != indexTriangles)
    bad("its header says " + std::to_string(h.triangleCount) + " triangles, the index " + std::to_string(indexTriangles));
  return decodeWithHeader(data, size, codec, grid, h);
}

}  // namespace mt
