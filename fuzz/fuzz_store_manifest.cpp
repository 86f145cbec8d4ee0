// libFuzzer target: the patch store's manifest reader (patchstore/store_manifest.cpp):
// the input replaces the manifest of a small store, which is opened and read.
#include "fuzz/fuzz_store.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const std::string file = mt::fuzz::storeFile("MANIFEST");
  mt::fuzz::openAndReadStore(file, data, size);
  return 0;
}
