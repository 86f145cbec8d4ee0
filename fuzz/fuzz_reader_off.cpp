// libFuzzer target: the OFF reader (patchstore/io/off_reader.cpp) on arbitrary bytes, checking
// the guarantees of mesh_reader.h on everything it delivers.
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  mt::fuzz::readMesh("input.off", data, size);
  return 0;
}
