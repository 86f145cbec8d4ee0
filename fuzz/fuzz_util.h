// What the fuzz targets share: a scratch directory of this process (on /dev/shm when there is one,
// so the readers that take a path are fed from memory) and a checking mesh sink.
#pragma once

#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "patchstore/io/mesh_reader.h"

namespace mt::fuzz {

// A directory of this process, removed at exit.
inline const std::string& scratchDir() {
  static const std::string dir = [] {
    namespace fs = std::filesystem;
    const fs::path root = fs::exists("/dev/shm") ? fs::path("/dev/shm") : fs::temp_directory_path();
    fs::path d = root / ("mt-fuzz-" + std::to_string(::getpid()));
    fs::create_directories(d);
    static std::string keep = d.string();
    std::atexit([] { std::error_code ec; std::filesystem::remove_all(keep, ec); });
    return d.string();
  }();
  return dir;
}

inline void writeFile(const std::string& path, const uint8_t* data, size_t size) {
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) std::abort();
  if (size && std::fwrite(data, 1, size, f) != size) std::abort();
  std::fclose(f);
}

// Checks the guarantees of mesh_reader.h on whatever the reader delivers; a broken one aborts, which
// libFuzzer reports as a crash with the input that caused it.
class CheckingSink : public MeshSink {
 public:
  void begin(const MeshHeader& header) override { declared_ = header.declaredVertices; }
  void vertices(const InputVertex* v, size_t count, uint64_t first) override {
    if (first != delivered_) std::abort();
    for (size_t i = 0; i < count; ++i)
      for (double p : v[i].p)
        if (!std::isfinite(p)) std::abort();
    delivered_ += count;
  }
  void triangles(const uint32_t* indices, size_t count) override {
    const uint64_t limit = declared_ >= 0 ? uint64_t(declared_) : delivered_;
    for (size_t i = 0; i < 3 * count; ++i)
      if (indices[i] >= limit && indices[i] >= delivered_) std::abort();
    triangles_ += count;
  }
  uint64_t delivered_ = 0, triangles_ = 0;
  int64_t declared_ = -1;
};

// Feeds `data` to the mesh reader as the file `name` (its extension picks the format when the
// content does not) and reads it all; mt::Error is the expected answer to bad input.
inline void readMesh(const char* name, const uint8_t* data, size_t size) {
  const std::string path = scratchDir() + "/" + name;
  writeFile(path, data, size);
  try {
    auto reader = openMesh(path);
    CheckingSink sink;
    ReadStats stats = reader->read(sink);
    if (stats.vertices != sink.delivered_ || stats.triangles != sink.triangles_) std::abort();
  } catch (const mt::Error&) {
  }
}

}  // namespace mt::fuzz
