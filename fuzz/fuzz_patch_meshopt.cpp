// libFuzzer target: the Meshopt patch decoder (mtfile/patch_codec_meshopt.cpp) on arbitrary payload
// bytes; fuzz_patch_decoder.h says what is checked.
#include "fuzz/fuzz_patch_decoder.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  mt::fuzz::decodeAndCheckPatch(data, size, mt::format::Codec::Meshopt);
  return 0;
}
