// Streaming binary little-endian PLY writer: vertices first, then triangles, counts known only at
// the end. The header is written with room for the final counts and rewritten on finish(); the
// file is written under PATH.tmp.PID.RANDOM (uniqueTempName) and renamed to PATH by finish(), so a
// failed or interrupted write never leaves a partial file under the final name. Every write, fsync
// and rename goes through Env::Default() (base/env.h), so tests can fail each in turn.
#pragma once

#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "base/env.h"
#include "patchstore/io/mesh_reader.h"

namespace mt {

struct PlyWriteOptions {
  bool doublePrecision = false;  // x,y,z as double instead of float
  bool normals = false;          // nx,ny,nz float
  bool colors = false;           // red,green,blue,alpha uchar
};

class PlyWriter {
 public:
  // Writes under `temporaryPath` (default: uniqueTempName(path)) and renames it over `path` in
  // finish(): nothing is ever left under `path` half written.
  PlyWriter(const std::string& path, const PlyWriteOptions& options, const std::string& temporaryPath = "");
  ~PlyWriter();  // removes the temporary file if finish() was not reached
  PlyWriter(const PlyWriter&) = delete;
  PlyWriter& operator=(const PlyWriter&) = delete;

  // All vertices must be added before the first triangle.
  void addVertex(const double p[3], const float* normal = nullptr, const uint8_t* color = nullptr);
  void addTriangle(uint32_t a, uint32_t b, uint32_t c);
  void finish();

  uint64_t vertexCount() const { return vertices_; }
  uint64_t triangleCount() const { return triangles_; }

 private:
  void writeHeader();
  void flush();
  std::string path_, tmpPath_;
  PlyWriteOptions options_;
  std::unique_ptr<WritableFile> file_;
  std::vector<char> buffer_;
  uint64_t vertices_ = 0, triangles_ = 0;
  long headerBytes_ = 0;
  bool finished_ = false;
};

}  // namespace mt
