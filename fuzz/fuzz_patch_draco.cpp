// libFuzzer target: the Draco patch decoder (mtfile/patch_codec_draco.cpp) on arbitrary payload
// bytes; fuzz_patch_decoder.h says what is checked.
#include "fuzz/fuzz_patch_decoder.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  mt::fuzz::decodeAndCheckPatch(data, size, mt::format::Codec::Draco);
  return 0;
}
