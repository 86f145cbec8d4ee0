// Internals of the patch codec, shared by its files (not a public API; patch_codec.h is):
//   patch_codec.cpp          the grid, octahedral normals, the preparation every codec starts
//                            from (compact, quantize, order) and the dispatch by codec;
//   patch_codec_meshopt.cpp  Codec::Meshopt: meshopt index code, predicted positions, range coder;
//   patch_codec_draco.cpp    Codec::Draco: edgebreaker with the grid coordinates as an attribute;
//   range_coder.h            the adaptive binary range coder of the meshopt payloads.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "mtfile/mt_format.h"
#include "mtfile/patch_codec.h"

namespace mt::codec_detail {

// A patch ready for a codec: vertices compacted and renumbered in fetch order, quantized.
struct Prepared {
  format::PayloadHeader header{};
  std::vector<uint32_t> q;        // relative to header.qMin, 3 per vertex, fetch order
  std::vector<uint8_t> oct;       // 2 per vertex or empty
  std::vector<uint8_t> colors;    // 4 per vertex or empty
  std::vector<uint32_t> indices;  // coded order (see prepare in patch_codec.cpp)
  // Payload coding A (the index code in the zstd frame, patch_codec_meshopt.cpp) is compared
  // with the connectivity code only for an unsimplified patch: A won on none of the simplified
  // patches of six scan-derived builds and 143 small real meshes (it wins on grid-regular level-0
  // patches, where zstd finds the codes' repeats), and coding it cost ~4% of the level loop from
  // level 2 on. indexCode is computed only then (a strip has its own code).
  bool codingA = false;
  std::vector<uint8_t> indexCode; // meshopt_encodeIndexBuffer(indices) when codingA (Codec::Meshopt)
};

inline void appendBytes(std::vector<uint8_t>& out, const void* data, size_t size) {
  const uint8_t* p = static_cast<const uint8_t*>(data);
  out.insert(out.end(), p, p + size);
}

// Throws mt::Error("bad patch payload: " + what).
[[noreturn]] void bad(const std::string& what);

// The meshopt index and vertex codec versions are process-wide state: set once, before any encode.
void setMeshoptVersions();

// Each decoder fills out.triangles (and normals, colours) and qRel (3 per vertex, q - qMin).
std::vector<uint8_t> encodeMeshopt(const Prepared& p, const PatchCodecOptions& options);
void decodeMeshopt(const uint8_t* data, size_t size, const format::PayloadHeader& h, DecodedPatch& out,
                   std::vector<uint32_t>& qRel);
// payloadBytes for a meshopt payload of at least sizeof(PayloadHeader) bytes.
PayloadBytes meshoptPayloadBytes(const uint8_t* data, size_t size);

// The connectivity code (kPayloadConnectivity, patch_codec_connectivity.cpp) of a triangle list
// whose vertices are numbered by first use; `coded` receives the triangles as the decoder gives
// them back (each rotated to start at the edge it is attached to). The decoder throws on a code
// that names no valid vertex or leaves vertices unreferenced.
class RangeEncoder;
class RangeDecoder;
void encodeConnectivity(RangeEncoder& rc, const uint32_t* indices, size_t indexCount, size_t vertexCount,
                        std::vector<uint32_t>& coded);
void decodeConnectivity(RangeDecoder& rc, uint32_t triangleCount, uint32_t vertexCount,
                        std::vector<uint32_t>& triangles);

std::vector<uint8_t> encodeDraco(const Prepared& p, const PatchCodecOptions& options);
void decodeDraco(const uint8_t* data, size_t size, const format::PayloadHeader& h, DecodedPatch& out,
                 std::vector<uint32_t>& qRel);

}  // namespace mt::codec_detail
