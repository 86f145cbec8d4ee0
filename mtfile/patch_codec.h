// Patch codec: one patch <-> one payload of the MT file (mt_format.h has the byte layouts).
//
// BMT section 6 stores rendering patches "as optimized triangle strips, with precomputed normals
// and then individually compressed using a quick decompression algorithm". Here, per patch:
//   1. positions are quantized on ONE global grid (QuantizationGrid): q = round((p - origin)/step).
//      A vertex shared by two patches has the same double position in both (the patch store keeps
//      it bit-identical), hence the same q, hence the same decoded float: no crack can appear;
//   2. triangles keep their order when it is coherent, else are put in fan order (fan_order.h),
//      and vertices in first-use (fetch) order;
//   3. normals (given, or computed from the quantized geometry) are stored octahedral 2x8 bit,
//      colours RGBA8;
//   4. Codec::Meshopt: the triangles by the range-coded connectivity code
//      (patch_codec_connectivity.cpp) or, when zstd makes it smaller (regular grids),
//      meshopt_encodeIndexBuffer in the zstd frame (as an option, a strip with
//      meshopt_encodeIndexSequence); positions by parallelogram prediction, range-coded;
//      normals/colours by meshopt_encodeVertexBuffer in the zstd frame;
//      Codec::Draco: edgebreaker with the grid coordinates as a lossless INT32 attribute.
// Decoding returns the exact grid coordinates, so a decode is bit-exact on positions.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "mtfile/mt_format.h"

namespace mt {

// The global quantization grid (stated in the FileHeader). The builder picks the step; quantizing
// moves a point by at most maxError() = step*sqrt(3)/2, which the builder adds to node errors.
struct QuantizationGrid {
  double origin[3] = {0, 0, 0};
  double step = 1;
  uint32_t bits = 31;  // q components are < 2^bits

  // A grid covering [minCorner, maxCorner] with the given step (origin = minCorner). Throws
  // mt::Error when the box needs more than 31 bits per axis at that step.
  static QuantizationGrid fromBounds(const double minCorner[3], const double maxCorner[3], double step);

  // Throws mt::Error when p falls outside the grid.
  void quantize(const double p[3], uint32_t q[3]) const;
  double dequantize(int axis, uint32_t q) const { return origin[axis] + step * double(q); }
  double maxError() const;
};

struct PatchCodecOptions {
  format::Codec codec = format::Codec::Meshopt;
  // Store normals: the given ones, or, when PatchInput::normals is null, area-weighted normals of
  // the quantized patch. (Normals computed per patch differ across patch borders; the builder
  // passes normals computed on the whole region to avoid shading seams.)
  // Off by default: stored normals cost ~0.6 B/triangle (meshopt) / ~0.55 (Draco), 40-120% of
  // the position+index bytes; the renderer computes them from the decoded patch instead.
  bool normals = false;
  bool colors = true;        // store colours when PatchInput::colors is given
  int zstdLevel = 3;         // Codec::Meshopt: zstd level over the streams (9: -3% bytes, 1.6x slower encode)
  int dracoSpeed = 1;        // Codec::Draco: encoder speed 0 (smallest) .. 10 (fastest)
  // Codec::Meshopt: code every patch's triangles as one tri-strip with restarts (BMT section 6;
  // mtbuild --index-order strip) instead of the triangle list (the default). The decoder gives the
  // same triangles either way; docs/mt-format.md has the measured size and decode speed.
  bool strips = false;
  // The triangles come out of simplification (the survivors keep their input order, which is not
  // coherent any more: measured 1.91 B/tri of raw index code on a 2M scan's simplified patches):
  // put them in fan order without first trying their own order (saves one index encode).
  bool simplified = false;
};

// One patch to encode: plain arrays (pointer + count), like meshoptimizer.
struct PatchInput {
  const double* positions = nullptr;  // 3 per vertex
  size_t vertexCount = 0;
  const uint32_t* triangles = nullptr;  // 3 per triangle, indices < vertexCount
  size_t triangleCount = 0;
  const float* normals = nullptr;     // optional, 3 per vertex
  const uint8_t* colors = nullptr;    // optional, 4 per vertex (RGBA)
};

// Vertices that no triangle uses are dropped. Throws mt::Error on bad input (index out of range,
// position outside the grid).
std::vector<uint8_t> encodePatch(const PatchInput& patch, const QuantizationGrid& grid,
                                 const PatchCodecOptions& options);

struct DecodedPatch {
  std::vector<uint32_t> q;          // 3 per vertex: global grid coordinates (exact)
  std::vector<float> positions;     // 3 per vertex: float(origin + step * q)
  std::vector<uint32_t> triangles;  // 3 per triangle
  std::vector<float> normals;       // 3 per vertex (unit), empty when not stored
  std::vector<uint8_t> colors;      // 4 per vertex, empty when not stored
  uint32_t vertexCount() const { return uint32_t(q.size() / 3); }
  uint32_t triangleCount() const { return uint32_t(triangles.size() / 3); }
};

// Throws mt::Error("...") describing what is wrong with the payload; callers prefix the file and
// patch (MtFileReader::readPatch does). The header's counts bound every allocation (mt_format.h:
// at most kMaxPayloadTriangles triangles, 3 vertices per triangle).
DecodedPatch decodePatch(const uint8_t* data, size_t size, format::Codec codec,
                         const QuantizationGrid& grid);
// The same for a payload of an MT file, whose index states its triangle count
// (PatchRecord::triangles): a header that says otherwise is refused before anything is decoded.
DecodedPatch decodePatch(const uint8_t* data, size_t size, format::Codec codec,
                         const QuantizationGrid& grid, uint32_t indexTriangles);

// Where a payload's bytes go (bench_mt_payload): the payload and frame headers, the index code
// (the zstd frame when it holds the index code; with kPayloadRangeIndices the range-coded index
// bytes, found by decoding them), the attributes' frame (kPayloadRangeIndices only), the positions,
// and whatever could not be split. Meshopt payloads only; other codecs give header + other.
struct PayloadBytes {
  size_t header = 0, index = 0, attributes = 0, positions = 0, other = 0;
};
PayloadBytes payloadBytes(const uint8_t* data, size_t size, format::Codec codec);

// Octahedral 2x8-bit normal coding (mt_format.h describes it).
void encodeOctahedral8(const float n[3], uint8_t out[2]);
void decodeOctahedral8(const uint8_t in[2], float n[3]);

}  // namespace mt
