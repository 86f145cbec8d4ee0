#include "patchstore/io/ply_writer.h"

#include <cstring>

#include "base/output_path.h"

namespace mt {

namespace {
// Room for the header; the final header is padded with a comment to exactly this size so that
// it can be rewritten in place once the counts are known.
constexpr long kHeaderBytes = 512;
constexpr size_t kBufferBytes = 1 << 20;

std::string headerText(const PlyWriteOptions& o, uint64_t vertices, uint64_t triangles) {
  std::string h = "ply\nformat binary_little_endian 1.0\ncomment written by batched-mt\n";
  h += "element vertex " + std::to_string(vertices) + "\n";
  const char* t = o.doublePrecision ? "double" : "float";
  for (const char* axis : {"x", "y", "z"}) h += std::string("property ") + t + " " + axis + "\n";
  if (o.normals) h += "property float nx\nproperty float ny\nproperty float nz\n";
  if (o.colors)
    h += "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n";
  h += "element face " + std::to_string(triangles) + "\n";
  h += vertices < (1ull << 31) ? "property list uchar int vertex_indices\n"
                               : "property list uchar uint vertex_indices\n";
  return h;
}
}  // namespace

PlyWriter::PlyWriter(const std::string& path, const PlyWriteOptions& options, const std::string& temporaryPath)
    : path_(path), tmpPath_(temporaryPath.empty() ? uniqueTempName(path) : temporaryPath), options_(options) {
  file_ = Env::Default()->newWritableFile(tmpPath_);  // throws naming the file (Io)
  buffer_.reserve(kBufferBytes);
  try {
    writeHeader();
  } catch (...) {
    // The destructor does not run for a constructor that throws: remove the temporary here.
    file_.reset();
    std::remove(tmpPath_.c_str());
    throw;
  }
}

PlyWriter::~PlyWriter() {
  file_.reset();
  if (!finished_) std::remove(tmpPath_.c_str());
}

void PlyWriter::writeHeader() {
  std::string h = headerText(options_, vertices_, triangles_);
  const std::string end = "end_header\n";
  long pad = kHeaderBytes - long(h.size() + end.size());
  if (pad < 10) fail(path_, "PLY header does not fit its reserved space");
  h += "comment " + std::string(size_t(pad - 9), ' ') + "\n" + end;
  if (file_->size() == 0) file_->append(h.data(), h.size());
  else file_->writeAt(0, h.data(), h.size());
  headerBytes_ = long(h.size());
}

void PlyWriter::flush() {
  if (buffer_.empty()) return;
  file_->append(buffer_.data(), buffer_.size());  // throws naming the file and offset (Io)
  buffer_.clear();
}

void PlyWriter::addVertex(const double p[3], const float* normal, const uint8_t* color) {
  if (triangles_ != 0) fail(path_, "PlyWriter: vertex added after the first triangle");
  char record[3 * 8 + 12 + 4];
  size_t n = 0;
  if (options_.doublePrecision) {
    std::memcpy(record, p, 24);
    n = 24;
  } else {
    float f[3] = {float(p[0]), float(p[1]), float(p[2])};
    std::memcpy(record, f, 12);
    n = 12;
  }
  if (options_.normals) {
    static const float zero[3] = {0, 0, 0};
    std::memcpy(record + n, normal ? normal : zero, 12);
    n += 12;
  }
  if (options_.colors) {
    static const uint8_t white[4] = {255, 255, 255, 255};
    std::memcpy(record + n, color ? color : white, 4);
    n += 4;
  }
  buffer_.insert(buffer_.end(), record, record + n);
  if (buffer_.size() >= kBufferBytes) flush();
  ++vertices_;
}

void PlyWriter::addTriangle(uint32_t a, uint32_t b, uint32_t c) {
  char record[13];
  record[0] = 3;
  uint32_t idx[3] = {a, b, c};
  std::memcpy(record + 1, idx, 12);
  buffer_.insert(buffer_.end(), record, record + 13);
  if (buffer_.size() >= kBufferBytes) flush();
  ++triangles_;
}

void PlyWriter::finish() {
  flush();
  writeHeader();
  file_->sync();
  file_->close();
  file_.reset();
  Env::Default()->renameFile(tmpPath_, path_);
  finished_ = true;
}

}  // namespace mt
