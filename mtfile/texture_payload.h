// A patch's texture payload (mt_format.h "Textures"): its atlas image (bytes as they are: JPEG or
// PNG, decoded by the reader with texture/) and the texture coordinates of every corner, in the
// order the patch's geometry payload decodes its triangles.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "mtfile/patch_codec.h"

namespace mt {

struct TexturePayload {
  uint16_t width = 0, height = 0;
  uint8_t imageFormat = 0;         // format::kImageJpeg / kImagePng
  std::vector<uint8_t> image;      // the encoded image
  std::vector<float> cornerUV;     // 6 per triangle: (u, v) of corners a, b, c; v = 0 at the bottom row
};

// `triangles` are the decoded patch's (3 per triangle, indices < vertexCount): the order and
// corner order the coordinates are given in. Coordinates are clamped to [0, 1] and kept to
// 1/65535. Throws mt::Error when a vertex has more than 254 distinct coordinates.
std::vector<uint8_t> encodeTexturePayload(const uint32_t* triangles, size_t triangleCount, size_t vertexCount,
                                          const float* cornerUV, const uint8_t* image, size_t imageBytes, uint16_t width,
                                          uint16_t height, uint8_t imageFormat);
// Throws mt::Error("...") on a damaged payload (callers prefix the file and patch).
TexturePayload decodeTexturePayload(const uint8_t* data, size_t size, const uint32_t* triangles, size_t triangleCount,
                                    size_t vertexCount);

// For each triangle of `decoded` (a payload of `input`, decodePatch'ed), which input triangle it
// is and how its corners turned: 3 * inputTriangle + r, with decoded corner c = input corner
// (c + r) % 3. Triangles are matched by their corners' grid coordinates (the grid weld makes
// those unique per vertex); throws mt::Error when one has no match.
std::vector<uint32_t> matchDecodedTriangles(const DecodedPatch& decoded, const PatchInput& input, const QuantizationGrid& grid);

}  // namespace mt
