// libFuzzer target: the Draco patch decoder (mtfile/patch_codec_draco.cpp) on arbitrary payload
// bytes (no checksum in the way: the MT reader checks one before decoding, this does not). A
// decoded patch must be consistent: every index below the vertex count, arrays of matching sizes.
#include <cstdlib>

#include "base/error.h"
#include "mtfile/patch_codec.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  mt::QuantizationGrid grid;  // origin 0, step 1, 31 bits
  try {
    mt::DecodedPatch d = mt::decodePatch(data, size, mt::format::Codec::Draco, grid);
    if (d.q.size() % 3 || d.triangles.size() % 3 || d.positions.size() != d.q.size()) std::abort();
    if (!d.normals.empty() && d.normals.size() != d.q.size()) std::abort();
    if (!d.colors.empty() && d.colors.size() / 4 != d.q.size() / 3) std::abort();
    for (uint32_t i : d.triangles)
      if (i >= d.vertexCount()) std::abort();
  } catch (const mt::Error&) {
  }
  return 0;
}
