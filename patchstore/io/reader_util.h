// Internals shared by the streaming mesh readers (not part of the contract in mesh_reader.h):
// chunked file input, line and token splitting, strict number parsing, and the batcher that turns
// vertices and polygons into bounded batches for a MeshSink.
#pragma once

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "patchstore/io/mesh_reader.h"

namespace mt::io {

// Big reads keep syscalls rare; 1 MiB still fits in L2 next to a batch, so the bytes the kernel
// copied in are parsed before they are evicted (4 MiB measured ~5% slower on binary PLY). The
// buffer only grows past this for a single huge text line.
constexpr size_t kReadChunk = size_t(1) << 20;
// Vertices or triangles per sink call: large enough to amortize the call, small enough that a
// batch (16K vertices * 40 bytes = 640 KiB) stays in L2 while the sink reads it; 64K batches
// measured ~20% slower on binary PLY because every vertex store missed the cache.
constexpr size_t kBatch = size_t(1) << 14;
// A text line longer than this is treated as a broken file rather than grown into without limit.
constexpr size_t kMaxLine = size_t(64) << 20;

// A file read front to back through one reusable buffer. offset() is the absolute position of the
// next unconsumed byte, which is what error messages and ReadStats.bytes report.
class InputFile {
 public:
  explicit InputFile(const std::string& path) : path_(path) {
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) fail(path_, std::string("cannot open: ") + std::strerror(errno));
    struct stat st;
    if (::fstat(fd_, &st) != 0) fail(path_, std::string("cannot open: ") + std::strerror(errno));
    if (S_ISDIR(st.st_mode)) fail(path_, std::string("cannot open: ") + std::strerror(EISDIR));
    size_ = uint64_t(st.st_size);
    ::posix_fadvise(fd_, 0, 0, POSIX_FADV_SEQUENTIAL);
    buffer_.resize(kReadChunk);
  }
  ~InputFile() { ::close(fd_); }
  InputFile(const InputFile&) = delete;
  InputFile& operator=(const InputFile&) = delete;

  const std::string& path() const { return path_; }
  uint64_t size() const { return size_; }
  uint64_t offset() const { return base_ + begin_; }
  uint64_t line() const { return line_; }

  const char* data() const { return buffer_.data() + begin_; }
  size_t available() const { return end_ - begin_; }
  void consume(size_t n) { begin_ += n; }

  // Makes at least n bytes available contiguously unless the file ends first.
  bool ensure(size_t n) { return available() >= n || refill(n); }
  bool atEnd() { return !ensure(1); }

  // Skips n bytes; false when the file ends first (everything up to the end is then consumed).
  bool skip(uint64_t n) {
    while (n > 0) {
      if (!ensure(1)) return false;
      size_t step = size_t(std::min<uint64_t>(n, available()));
      consume(step);
      n -= step;
    }
    return true;
  }

  // Next line without its "\n" or "\r\n"; false at end of file. A last line without a newline
  // still counts as a line.
  bool nextLine(std::string_view& line) {
    size_t scanned = 0;
    for (;;) {
      const char* s = data();
      size_t n = available();
      if (const void* nl = std::memchr(s + scanned, '\n', n - scanned)) {
        size_t len = size_t(static_cast<const char*>(nl) - s);
        consume(len + 1);
        line = trimCr(std::string_view(s, len));
        ++line_;
        return true;
      }
      if (eof_) {
        if (n == 0) return false;
        consume(n);
        line = trimCr(std::string_view(s, n));
        ++line_;
        return true;
      }
      if (n >= kMaxLine) fail(path_, "line longer than 64 MiB (line " + std::to_string(line_ + 1) + ")");
      scanned = n;
      refill(n + 1);
    }
  }

 private:
  static std::string_view trimCr(std::string_view s) {
    return !s.empty() && s.back() == '\r' ? s.substr(0, s.size() - 1) : s;
  }

  // Moves the unconsumed tail to the front, grows the buffer if n does not fit, then reads until
  // n bytes are available or the file ends.
  bool refill(size_t n) {
    if (begin_ > 0) {
      std::memmove(buffer_.data(), buffer_.data() + begin_, end_ - begin_);
      base_ += begin_;
      end_ -= begin_;
      begin_ = 0;
    }
    if (n > buffer_.size()) buffer_.resize(std::max(n, buffer_.size() * 2));
    while (end_ < n && !eof_) {
      ssize_t r = ::read(fd_, buffer_.data() + end_, buffer_.size() - end_);
      if (r < 0) {
        if (errno == EINTR) continue;
        fail(path_, std::string("read error: ") + std::strerror(errno));
      }
      if (r == 0) eof_ = true;
      end_ += size_t(r);
    }
    return end_ >= n;
  }

  std::string path_;
  int fd_ = -1;
  uint64_t size_ = 0;
  std::vector<char> buffer_;
  size_t begin_ = 0, end_ = 0;  // unconsumed bytes are buffer_[begin_, end_)
  uint64_t base_ = 0;           // file offset of buffer_[0]
  uint64_t line_ = 0;           // lines returned by nextLine so far
  bool eof_ = false;
};

inline bool isSpace(char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f'; }

// Whitespace-separated tokens of one line.
struct Tokens {
  std::string_view rest;
  bool next(std::string_view& token) {
    size_t i = 0;
    while (i < rest.size() && isSpace(rest[i])) ++i;
    if (i == rest.size()) {
      rest = {};
      return false;
    }
    size_t j = i;
    while (j < rest.size() && !isSpace(rest[j])) ++j;
    token = rest.substr(i, j - i);
    rest = rest.substr(j);
    return true;
  }
  bool empty() const {
    for (char c : rest)
      if (!isSpace(c)) return false;
    return true;
  }
};

// Strict number parsing: the whole token must be the number (std::from_chars, which is exact and
// locale independent). A leading '+' is accepted because some writers emit it.
template <class T>
bool parseNumber(std::string_view token, T& out) {
  const char* b = token.data();
  const char* e = b + token.size();
  if (b != e && *b == '+') ++b;
  if (b == e) return false;
  auto [ptr, ec] = std::from_chars(b, e, out);
  if constexpr (std::is_floating_point_v<T>) {
    if (ec == std::errc::result_out_of_range && ptr == e) {
      // from_chars leaves `out` untouched on overflow/underflow; strtod gives what IEEE rounding
      // would (0 for tiny numbers, inf for huge ones, which the finiteness checks then reject).
      // This path is rare, so the copy for the terminating NUL does not matter.
      std::string copy(b, e);
      out = T(std::strtod(copy.c_str(), nullptr));
      return true;
    }
  }
  return ec == std::errc() && ptr == e;
}

inline std::string quoted(std::string_view s) {
  constexpr size_t kMax = 40;  // a garbage token can be a whole binary blob; keep messages short
  std::string q(s.substr(0, kMax));
  for (char& c : q)
    if (static_cast<unsigned char>(c) < 32 || static_cast<unsigned char>(c) > 126) c = '?';
  return "'" + q + (s.size() > kMax ? "...'" : "'");
}

inline std::string atLine(uint64_t line) { return " (line " + std::to_string(line) + ")"; }
inline std::string atByte(uint64_t offset) { return " (byte offset " + std::to_string(offset) + ")"; }

inline InputVertex blankVertex() {
  InputVertex v;
  v.p[0] = v.p[1] = v.p[2] = 0;
  v.n[0] = v.n[1] = v.n[2] = 0;
  v.c[0] = v.c[1] = v.c[2] = v.c[3] = 255;
  v.uv[0] = v.uv[1] = 0;
  v.material = kNoMaterial;
  return v;
}

// Texture coordinates must lie in [0, 1] (per-patch atlases cut the texels they cover out of the
// image; a repeating texture is not supported): values within kTexcoordSlack outside (rounding
// of writers) are clamped, others are refused. True when (u, v) is acceptable; clamps in place.
constexpr double kTexcoordSlack = 1e-3;
inline bool acceptTexcoord(double& u, double& v) {
  if (!(u >= -kTexcoordSlack && u <= 1 + kTexcoordSlack && v >= -kTexcoordSlack && v <= 1 + kTexcoordSlack)) return false;
  u = std::clamp(u, 0.0, 1.0);
  v = std::clamp(v, 0.0, 1.0);
  return true;
}

// A path named inside FILE, resolved against FILE's folder (absolute paths kept; Windows
// separators turned into '/').
inline std::string resolveBeside(const std::string& file, std::string name) {
  for (char& c : name)
    if (c == '\\') c = '/';
  if (!name.empty() && name[0] == '/') return name;
  const size_t slash = file.rfind('/');
  return slash == std::string::npos ? name : file.substr(0, slash + 1) + name;
}

// A material's texture image must exist and be a regular file; the message names the file and
// line that named it.
inline void checkTextureFile(const InputMaterial& m) {
  if (m.texture.empty()) return;
  struct stat st;
  if (::stat(m.texture.c_str(), &st) != 0)
    fail(m.texture, std::string("texture image of material '") + m.name + "' (named in " + m.source +
                        "): cannot open: " + std::strerror(errno));
  if (!S_ISREG(st.st_mode))
    fail(m.texture, std::string("texture image of material '") + m.name + "' (named in " + m.source + ") is not a regular file");
}

inline bool isFinite(const InputVertex& v) {
  return std::isfinite(v.p[0]) && std::isfinite(v.p[1]) && std::isfinite(v.p[2]);
}

// A 0..1 colour channel to 0..255, rounded and clamped.
inline uint8_t unitToByte(double x) {
  if (!(x > 0)) return 0;  // also NaN
  return x >= 1 ? 255 : uint8_t(x * 255.0 + 0.5);
}

// Colour channels as the readers check them: a float channel must lie in 0..1 and an integer one
// in 0..`max` (255 for 8-bit, 65535 for 16-bit channels). A float slightly outside 0..1 (by less
// than half an 8-bit level, as writers' rounding leaves it) is clamped; anything farther, or NaN,
// is refused: a float channel written as 0..255, or a negative integer, is a wrong file, and
// clamping it would silently paint the model white or black.
inline bool unitColorByte(double x, uint8_t& out) {
  constexpr double kSlack = 0.5 / 255.0;
  if (!(x >= -kSlack && x <= 1 + kSlack)) return false;  // also NaN
  out = unitToByte(x);
  return true;
}
inline bool integerColorByte(double x, double max, uint8_t& out) {
  if (!(x >= 0 && x <= max) || x != std::floor(x)) return false;
  out = uint8_t(max > 255 ? std::lround(x * 255.0 / max) : long(x));
  return true;
}
// The message for a refused channel value: "colour value 300 out of range (8-bit channels are 0..255)".
inline std::string badColorMessage(double x, bool unit, double max) {
  char value[40];
  std::snprintf(value, sizeof value, "%.9g", x);
  return std::string("colour value ") + value + " out of range (" +
         (unit ? std::string("float channels are 0..1") : max > 255 ? "16-bit channels are 0..65535" : "8-bit channels are 0..255") + ")";
}

// Collects vertices and triangles into fixed-size batches and hands them to the sink, keeping
// ReadStats up to date. Vertices are always flushed before triangles, so every index in a
// triangle batch refers to a vertex the sink has already received.
class Batcher {
 public:
  Batcher(MeshSink& sink, ReadStats& stats) : sink_(sink), stats_(stats) {
    vertices_.resize(kBatch);
    indices_.resize(kBatch * 3);
  }
  // Every triangle then carries corner texture coordinates and a material, handed to the sink's
  // cornerTexcoords() after each triangle batch (addCorner with texture coordinates, addTriangle
  // fills none: 0,0 and kNoMaterial).
  void enableCorners() {
    cornerUV_.assign(kBatch * 6, 0.0f);
    cornerMaterial_.assign(kBatch, kNoMaterial);
  }
  Batcher(const Batcher&) = delete;
  Batcher& operator=(const Batcher&) = delete;

  // Room for up to `room` vertices at the returned pointer; commitVertices(n) publishes n of them.
  InputVertex* vertexSlots(size_t& room) {
    if (vertexCount_ == kBatch) flushVertices();
    room = kBatch - vertexCount_;
    return vertices_.data() + vertexCount_;
  }
  void commitVertices(size_t n) {
    vertexCount_ += n;
    stats_.vertices += n;
  }
  InputVertex& addVertex() {
    size_t room;
    InputVertex* v = vertexSlots(room);
    commitVertices(1);
    return *v;
  }

  uint32_t* triangleSlots(size_t& room) {
    if (triangleCount_ == kBatch) flushTriangles();
    room = kBatch - triangleCount_;
    return indices_.data() + triangleCount_ * 3;
  }
  void commitTriangles(size_t n, size_t degenerate) {
    triangleCount_ += n;
    stats_.triangles += n;
    stats_.degenerateTriangles += degenerate;
  }
  void addTriangle(uint32_t a, uint32_t b, uint32_t c) {
    size_t room;
    uint32_t* t = triangleSlots(room);
    t[0] = a;
    t[1] = b;
    t[2] = c;
    if (!cornerUV_.empty()) {
      std::fill_n(&cornerUV_[triangleCount_ * 6], 6, 0.0f);
      cornerMaterial_[triangleCount_] = kNoMaterial;
    }
    commitTriangles(1, (a == b) | (b == c) | (a == c));
  }
  void addTriangle(const uint32_t v[3], const float uv[6], uint32_t material) {
    size_t room;
    uint32_t* t = triangleSlots(room);
    std::copy_n(v, 3, t);
    std::copy_n(uv, 6, &cornerUV_[triangleCount_ * 6]);
    cornerMaterial_[triangleCount_] = material;
    commitTriangles(1, (v[0] == v[1]) | (v[1] == v[2]) | (v[0] == v[2]));
  }
  // A polygon corner with texture coordinates (enableCorners() first); the face's material is
  // given at beginFace.
  void addCorner(uint32_t index, float u, float v) {
    if (corners_ == 0) first_ = index, firstUV_[0] = u, firstUV_[1] = v;
    else if (corners_ >= 2) {
      const uint32_t tri[3] = {first_, previous_, index};
      const float uv[6] = {firstUV_[0], firstUV_[1], previousUV_[0], previousUV_[1], u, v};
      addTriangle(tri, uv, faceMaterial_);
    }
    previous_ = index;
    previousUV_[0] = u, previousUV_[1] = v;
    ++corners_;
  }
  void beginFace(uint32_t material) {
    corners_ = 0;
    faceMaterial_ = material;
  }

  // Polygon corners, fan-triangulated (c0, ci, ci+1) as they arrive so no polygon is buffered.
  void beginFace() { corners_ = 0; }
  void addCorner(uint32_t index) {
    if (corners_ == 0) first_ = index;
    else if (corners_ >= 2) addTriangle(first_, previous_, index);
    previous_ = index;
    ++corners_;
  }
  // Returns the number of corners; the caller rejects faces with fewer than 3.
  uint64_t endFace() {
    if (corners_ > 3) ++stats_.polygons;
    return corners_;
  }

  void flush() { flushTriangles(); }

 private:
  void flushVertices() {
    if (vertexCount_ == 0) return;
    sink_.vertices(vertices_.data(), vertexCount_, stats_.vertices - vertexCount_);
    vertexCount_ = 0;
  }
  void flushTriangles() {
    flushVertices();
    if (triangleCount_ == 0) return;
    sink_.triangles(indices_.data(), triangleCount_);
    if (!cornerUV_.empty()) sink_.cornerTexcoords(cornerUV_.data(), cornerMaterial_.data(), triangleCount_);
    triangleCount_ = 0;
  }

  MeshSink& sink_;
  ReadStats& stats_;
  std::vector<InputVertex> vertices_;
  std::vector<uint32_t> indices_;
  size_t vertexCount_ = 0, triangleCount_ = 0;
  uint64_t corners_ = 0;
  uint32_t first_ = 0, previous_ = 0;
  std::vector<float> cornerUV_;           // 6 per triangle of the batch (enableCorners)
  std::vector<uint32_t> cornerMaterial_;  // 1 per triangle of the batch
  float firstUV_[2] = {0, 0}, previousUV_[2] = {0, 0};
  uint32_t faceMaterial_ = kNoMaterial;
};

// Per-format openers, called by openMesh once the format is known. The header is parsed here.
std::unique_ptr<MeshReader> openPly(std::unique_ptr<InputFile> in, const MeshOpenOptions& options);
std::unique_ptr<MeshReader> openObj(std::unique_ptr<InputFile> in, const MeshOpenOptions& options);
// The wedge split (wedge_split.cpp): a reader with per-corner texture coordinates turned into
// one with per-vertex ones.
std::unique_ptr<MeshReader> splitWedges(std::unique_ptr<MeshReader> source, const std::string& path,
                                        const MeshOpenOptions& options);
std::unique_ptr<MeshReader> openOff(std::unique_ptr<InputFile> in);
std::unique_ptr<MeshReader> openStl(std::unique_ptr<InputFile> in, bool binary);
// glTF reads its buffers with positional reads (base/env.h), not through InputFile.
std::unique_ptr<MeshReader> openGltf(const std::string& path, bool glb, const MeshOpenOptions& options);

}  // namespace mt::io
