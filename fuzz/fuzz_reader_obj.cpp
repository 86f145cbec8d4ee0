// libFuzzer target: the OBJ reader (patchstore/io/obj_reader.cpp) on arbitrary bytes, checking
// the guarantees of mesh_reader.h on everything it delivers.
#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  mt::fuzz::readMesh("input.obj", data, size);
  return 0;
}
