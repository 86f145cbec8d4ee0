// What the two patch decoders' targets share (fuzz_patch_meshopt, fuzz_patch_draco): a payload of
// arbitrary bytes is decoded with one codec (no checksum in the way: the MT reader checks one before
// decoding, this does not), and a decoded patch must be consistent: every index below the vertex
// count, arrays of matching sizes. mt::Error is the expected answer to bad bytes.
#pragma once

#include <cstdint>
#include <cstdlib>

#include "base/error.h"
#include "mtfile/patch_codec.h"

namespace mt::fuzz {

inline void decodeAndCheckPatch(const uint8_t* data, size_t size, mt::format::Codec codec) {
  mt::QuantizationGrid grid;  // origin 0, step 1, 31 bits
  try {
    mt::DecodedPatch d = mt::decodePatch(data, size, codec, grid);
    if (d.q.size() % 3 || d.triangles.size() % 3 || d.positions.size() != d.q.size()) std::abort();
    if (!d.normals.empty() && d.normals.size() != d.q.size()) std::abort();
    if (!d.colors.empty() && d.colors.size() != d.q.size() / 3 * 4) std::abort();
    for (uint32_t i : d.triangles)
      if (i >= d.vertexCount()) std::abort();
  } catch (const mt::Error&) {
  }
}

}  // namespace mt::fuzz
