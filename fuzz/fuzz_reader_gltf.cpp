// libFuzzer target: the glTF reader (patchstore/io/gltf_reader.cpp), .glb and .gltf, on arbitrary
// bytes: the GLB container, the JSON, buffers (the BIN chunk, base64 data URIs), accessors of every
// component type, strides, sparse and quantized data, node transforms, strip and fan assembly, and
// the two compression extensions (Draco primitives, meshopt buffer views), checking the guarantees
// of mesh_reader.h on everything it delivers. An input that starts with the GLB magic is a .glb,
// any other a .gltf (the reader's own choice by content and extension).
#include <cstring>

#include "fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const bool glb = size >= 4 && std::memcmp(data, "glTF", 4) == 0;
  mt::fuzz::readMesh(glb ? "input.glb" : "input.gltf", data, size);
  return 0;
}
