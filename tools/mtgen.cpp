// mtgen: streams a procedurally generated, scan-like mesh of any size to a mesh file, with memory
// O(rows) in the output size. The surface itself is defined in testing/scan_generator.h; this file is
// the command line, the output formats and the parallel streaming pipeline.
//
// Streaming: vertices are produced in chunks of grid rows and faces in chunks of rows (grid order)
// or of permutation indices (--shuffle). Chunks are computed in parallel by a TBB pipeline and
// written strictly in order, and every value is a pure function of its grid position, so the
// bytes do not depend on the thread count.
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <tbb/global_control.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

#include <atomic>
#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <sstream>
#include <cstdarg>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "base/error.h"
#include "base/exit_code.h"
#include "base/output_path.h"
#include "patchstore/io/mesh_reader.h"
#include "patchstore/io/ply_writer.h"
#include "base/cli_checks.h"
#include "testing/box_texture.h"
#include "testing/color_field.h"
#include "testing/scan_generator.h"
#include "testing/texture_atlas.h"
#include "texture/image_codec.h"

namespace {

// Hole placement is quadratic in the number of holes (10000 take ~7 s on 1M triangles, 100000
// on 10M over a minute): more is refused as a typo.
constexpr uint32_t kMaxHoles = 20'000;

using mtgen::Component;
using mtgen::ScanGenerator;

enum class Format { PlyBinary, PlyAscii, Obj, Off, Stl };

struct OutputSettings {
  std::string path;
  std::string tmpPath;  // uniqueTempName(path): written there, renamed over path when complete
  Format format = Format::PlyBinary;
  bool normals = false;
  bool colors = false;
  bool doublePrecision = false;
  // --offset: added (in double) to every position, e.g. UTM-like metres for a georeferenced scan.
  double offset[3] = {0, 0, 0};
  // --colors: the sharp procedural field over the surface's box (testing/color_field.h).
  std::shared_ptr<const mt::testing::ColorField> colorField;
};

// The temporary file of the current run, removed if the process is interrupted.
char gTemporaryPath[4096] = {0};

extern "C" void removeTemporaryAndExit(int signal) {
  if (gTemporaryPath[0]) unlink(gTemporaryPath);
  _exit(128 + signal);
}

// Gives `settings` its temporary name beside the output and arms its removal on interruption.
void armTemporary(OutputSettings& settings) {
  settings.tmpPath = mt::uniqueTempName(settings.path);
  if (settings.tmpPath.size() < sizeof gTemporaryPath)
    std::memcpy(gTemporaryPath, settings.tmpPath.c_str(), settings.tmpPath.size() + 1);
  for (int sig : {SIGINT, SIGTERM, SIGHUP}) signal(sig, removeTemporaryAndExit);
}

// ---------------------------------------------------------------------------------------------
// Output formats.

class MeshOutput {
 public:
  virtual ~MeshOutput() = default;
  virtual bool wantsVertices() const { return true; }
  // Triangle soups (STL) need the corner positions with each triangle instead of vertices.
  virtual bool wantsCorners() const { return false; }
  virtual void vertex(const double p[3], const float* normal, const uint8_t* color) = 0;
  virtual void triangle(const uint32_t t[3], const float* corners) = 0;
  // --texture: a triangle's corner texture coordinates and its texture page.
  virtual void triangleUV(const uint32_t t[3], const float uv[6], uint32_t page) { (void)t, (void)uv, (void)page; }
  virtual void finish() = 0;
};

// --texture: a binary PLY with per-face texture coordinates (MeshLab's layout: "texcoord" lists
// and "texnumber", the pages named by "comment TextureFile"), float x, y, z.
class TexturedPlyOutput final : public MeshOutput {
 public:
  TexturedPlyOutput(const OutputSettings& s, uint64_t vertices, uint64_t triangles, const std::vector<std::string>& pages)
      : settings_(s) {
    file_ = std::fopen(s.tmpPath.c_str(), "wb");
    if (!file_) mt::fail(s.path, std::string("cannot create output: ") + std::strerror(errno));
    std::setvbuf(file_, nullptr, _IOFBF, 1 << 20);
    std::string h = "ply\nformat binary_little_endian 1.0\ncomment written by mtgen --texture\n";
    for (const std::string& p : pages) h += "comment TextureFile " + p + "\n";
    h += "element vertex " + std::to_string(vertices) + "\nproperty float x\nproperty float y\nproperty float z\n";
    h += "element face " + std::to_string(triangles) +
         "\nproperty list uchar int vertex_indices\nproperty list uchar float texcoord\nproperty int texnumber\nend_header\n";
    put(h.data(), h.size());
  }
  ~TexturedPlyOutput() override {
    if (file_) std::fclose(file_);
    if (!finished_) std::remove(settings_.tmpPath.c_str());
  }
  void vertex(const double p[3], const float*, const uint8_t*) override {
    const float f[3] = {float(p[0]), float(p[1]), float(p[2])};
    put(f, sizeof f);
  }
  void triangle(const uint32_t*, const float*) override { mt::fail(settings_.path, "internal: a textured face without coordinates"); }
  void triangleUV(const uint32_t t[3], const float uv[6], uint32_t page) override {
    char r[42];
    r[0] = 3;
    std::memcpy(r + 1, t, 12);
    r[13] = 6;
    std::memcpy(r + 14, uv, 24);
    std::memcpy(r + 38, &page, 4);
    put(r, sizeof r);
  }
  void finish() override {
    if (std::fflush(file_) != 0 || fsync(fileno(file_)) != 0)
      mt::fail(settings_.path, std::string("write failed: ") + std::strerror(errno));
    std::fclose(file_);
    file_ = nullptr;
    if (std::rename(settings_.tmpPath.c_str(), settings_.path.c_str()) != 0)
      mt::fail(settings_.path, std::string("cannot rename temporary output: ") + std::strerror(errno));
    finished_ = true;
  }

 private:
  void put(const void* data, size_t n) {
    if (std::fwrite(data, 1, n, file_) != n) mt::fail(settings_.path, std::string("write failed: ") + std::strerror(errno));
  }
  OutputSettings settings_;
  FILE* file_ = nullptr;
  bool finished_ = false;
};

class BinaryPlyOutput final : public MeshOutput {
 public:
  BinaryPlyOutput(const OutputSettings& s)
      : writer_(s.path, mt::PlyWriteOptions{s.doublePrecision, s.normals, s.colors}, s.tmpPath) {
    for (int a = 0; a < 3; ++a) offset_[a] = s.offset[a];
  }
  void vertex(const double p[3], const float* normal, const uint8_t* color) override {
    const double q[3] = {p[0] + offset_[0], p[1] + offset_[1], p[2] + offset_[2]};
    writer_.addVertex(q, normal, color);
  }
  void triangle(const uint32_t t[3], const float*) override { writer_.addTriangle(t[0], t[1], t[2]); }
  void finish() override { writer_.finish(); }  // renames the temporary file over the output

 private:
  mt::PlyWriter writer_;
  double offset_[3] = {0, 0, 0};
};

// Text formats for small meshes. Coordinates are printed with %.9g of their float32 value, which a
// float32 parser recovers exactly. Written under a temporary name, renamed by finish().
class TextOutput final : public MeshOutput {
 public:
  TextOutput(const OutputSettings& s, uint64_t vertices, uint64_t triangles)
      : settings_(s), tmpPath_(s.tmpPath) {
    file_ = std::fopen(tmpPath_.c_str(), "wb");
    if (!file_) mt::fail(s.path, std::string("cannot create output: ") + std::strerror(errno));
    std::setvbuf(file_, nullptr, _IOFBF, 1 << 20);
    switch (s.format) {
      case Format::PlyAscii:
        print("ply\nformat ascii 1.0\ncomment written by mtgen\nelement vertex %llu\n",
              (unsigned long long)vertices);
        print("property float x\nproperty float y\nproperty float z\n");
        if (s.normals) print("property float nx\nproperty float ny\nproperty float nz\n");
        if (s.colors) print("property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n");
        print("element face %llu\nproperty list uchar int vertex_indices\nend_header\n",
              (unsigned long long)triangles);
        break;
      case Format::Obj:
        print("# written by mtgen: %llu vertices, %llu triangles\n", (unsigned long long)vertices,
              (unsigned long long)triangles);
        break;
      case Format::Off:
        print("OFF\n%llu %llu 0\n", (unsigned long long)vertices, (unsigned long long)triangles);
        break;
      case Format::Stl:
        print("solid mtgen\n");
        break;
      case Format::PlyBinary:
        break;
    }
  }
  ~TextOutput() override {
    if (file_) std::fclose(file_);
    if (!finished_) std::remove(tmpPath_.c_str());
  }

  bool wantsVertices() const override { return settings_.format != Format::Stl; }
  bool wantsCorners() const override { return settings_.format == Format::Stl; }

  void vertex(const double p[3], const float* n, const uint8_t* c) override {
    float x = float(p[0]), y = float(p[1]), z = float(p[2]);
    switch (settings_.format) {
      case Format::PlyAscii:
        print("%.9g %.9g %.9g", double(x), double(y), double(z));
        if (settings_.normals) print(" %.9g %.9g %.9g", double(n[0]), double(n[1]), double(n[2]));
        if (settings_.colors) print(" %u %u %u %u", c[0], c[1], c[2], c[3]);
        print("\n");
        break;
      case Format::Obj:
        print("v %.9g %.9g %.9g\n", double(x), double(y), double(z));
        if (settings_.normals) print("vn %.9g %.9g %.9g\n", double(n[0]), double(n[1]), double(n[2]));
        break;
      case Format::Off:
        print("%.9g %.9g %.9g\n", double(x), double(y), double(z));
        break;
      default:
        break;
    }
  }

  void triangle(const uint32_t t[3], const float* corners) override {
    switch (settings_.format) {
      case Format::PlyAscii:
      case Format::Off:
        print("3 %u %u %u\n", t[0], t[1], t[2]);
        break;
      case Format::Obj:
        if (settings_.normals)
          print("f %u//%u %u//%u %u//%u\n", t[0] + 1, t[0] + 1, t[1] + 1, t[1] + 1, t[2] + 1, t[2] + 1);
        else
          print("f %u %u %u\n", t[0] + 1, t[1] + 1, t[2] + 1);
        break;
      case Format::Stl: {
        const float* a = corners;
        const float* b = corners + 3;
        const float* c = corners + 6;
        double e1[3] = {double(b[0]) - a[0], double(b[1]) - a[1], double(b[2]) - a[2]};
        double e2[3] = {double(c[0]) - a[0], double(c[1]) - a[1], double(c[2]) - a[2]};
        double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
        double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        if (len > 0) n[0] /= len, n[1] /= len, n[2] /= len;
        print("facet normal %.9g %.9g %.9g\n outer loop\n", double(float(n[0])), double(float(n[1])),
              double(float(n[2])));
        for (int k = 0; k < 3; ++k)
          print("  vertex %.9g %.9g %.9g\n", double(corners[3 * k]), double(corners[3 * k + 1]),
                double(corners[3 * k + 2]));
        print(" endloop\nendfacet\n");
        break;
      }
      case Format::PlyBinary:
        break;
    }
  }

  void finish() override {
    if (settings_.format == Format::Stl) print("endsolid mtgen\n");
    if (std::fflush(file_) != 0 || fsync(fileno(file_)) != 0)
      mt::fail(settings_.path, std::string("write failed: ") + std::strerror(errno));
    std::fclose(file_);
    file_ = nullptr;
    if (std::rename(tmpPath_.c_str(), settings_.path.c_str()) != 0)
      mt::fail(settings_.path, std::string("cannot rename temporary output: ") + std::strerror(errno));
    finished_ = true;
  }

 private:
  __attribute__((format(printf, 2, 3))) void print(const char* format, ...) {
    va_list args;
    va_start(args, format);
    int n = std::vfprintf(file_, format, args);
    va_end(args);
    if (n < 0) mt::fail(settings_.path, std::string("write failed: ") + std::strerror(errno));
  }

  OutputSettings settings_;
  std::string tmpPath_;
  FILE* file_ = nullptr;
  bool finished_ = false;
};

// ---------------------------------------------------------------------------------------------
// Progress on stderr: every ~5% for outputs of more than kProgressTriangles, unless -q.
constexpr uint64_t kProgressTriangles = 5'000'000;

class Progress {
 public:
  Progress(uint64_t totalWork, uint64_t triangles, bool enabled)
      : total_(std::max<uint64_t>(1, totalWork)), triangles_(triangles), enabled_(enabled),
        start_(std::chrono::steady_clock::now()) {}
  void advance(uint64_t work) {
    done_ += work;
    if (!enabled_) return;
    int percent = int(100.0 * double(done_) / double(total_));
    if (percent < nextPercent_ || percent >= 100) return;
    double seconds = elapsed();
    double rate = double(triangles_) * double(done_) / double(total_) / std::max(seconds, 1e-9);
    std::fprintf(stderr, "mtgen: %3d%%  %.1f s  %.1f M triangles/s\n", percent, seconds, rate / 1e6);
    nextPercent_ = (percent / 5 + 1) * 5;
  }
  double elapsed() const {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }

 private:
  uint64_t total_, triangles_, done_ = 0;
  bool enabled_;
  int nextPercent_ = 5;
  std::chrono::steady_clock::time_point start_;
};

// ---------------------------------------------------------------------------------------------
// Streaming.

constexpr size_t kChunkVertices = 1 << 15;  // work unit of the pipeline; bounds its memory
constexpr size_t kChunkFaces = 1 << 16;

// The colour of a vertex at p (before --offset): the sharp procedural field (checker, stripes,
// spots: testing/color_field.h), shaded like stone by the displacement (hollows darker), so a
// simplifier that smears colour edges or drops spots shows it.
void colorFor(const mt::testing::ColorField& field, const double p[3], double displacement, double amplitudeSum,
              uint8_t out[4]) {
  double t = 0.5 + displacement / (1.2 * std::max(amplitudeSum, 1e-12));
  t = std::clamp(t, 0.0, 1.0);
  field.colorAt(p, out, t * t * (3 - 2 * t));
}

// The box the colour field is laid out in: every component's centre +- its scaled outer radius.
std::shared_ptr<const mt::testing::ColorField> colorFieldOf(const ScanGenerator& generator) {
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  for (const Component& c : generator.components()) {
    const double r = c.scale * (c.major + c.minor + c.amplitudeSum);
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], c.center[a] - r), hi[a] = std::max(hi[a], c.center[a] + r);
  }
  return std::make_shared<mt::testing::ColorField>(lo, hi);
}

struct VertexChunk {
  uint32_t component = 0, rowBegin = 0, rowEnd = 0;
  std::vector<double> xyz;
  std::vector<float> normals;
  std::vector<uint8_t> colors;
  size_t count = 0;
};

void computeVertexChunk(const ScanGenerator& gen, const std::vector<mtgen::ColParams>& cols,
                        const OutputSettings& out, VertexChunk& chunk) {
  const Component& c = gen.components()[chunk.component];
  const uint32_t V = c.cols, U = c.rows;
  // Normals are central differences of the grid neighbours, and close/slivers move a vertex
  // towards its neighbours, so compute one halo row each side. Rows past the end of an open sheet
  // are clamped (one-sided differences at its border), rows of a torus wrap around; vertex row U
  // (the unwelded seam copy of row 0) wraps to row 0 like any other.
  const uint32_t halo = out.normals || c.moves() ? 1 : 0;
  const uint32_t gridRows = chunk.rowEnd - chunk.rowBegin + 2 * halo;
  std::vector<double> grid(size_t(gridRows) * V * 3);
  std::vector<double> disp(out.colors ? size_t(gridRows) * V : 0);
  ScanGenerator::RowLattice lattice;
  for (uint32_t k = 0; k < gridRows; ++k) {
    uint32_t row = c.sheet ? uint32_t(std::clamp<int64_t>(int64_t(chunk.rowBegin) - halo + k, 0, U - 1))
                           : uint32_t((uint64_t(chunk.rowBegin) + U - halo + k) % U);
    mtgen::RowParams rp = ScanGenerator::rowParams(c, row);
    lattice.fill(c, rp);
    double* p = &grid[size_t(k) * V * 3];
    for (uint32_t j = 0; j < V; ++j)
      ScanGenerator::position(c, rp, lattice, cols[j], p + 3 * j, out.colors ? &disp[size_t(k) * V + j] : nullptr);
  }
  // Final positions of a row: the grid with close/slivers moves applied (from unmoved neighbours,
  // the same operations as ScanGenerator::finalPosition, so every path gives the same bits).
  std::vector<double> moved(c.moves() ? size_t(V) * 3 : 0);
  const uint32_t W = c.vertexCols();
  size_t capacity = size_t(chunk.rowEnd - chunk.rowBegin) * W;
  chunk.xyz.reserve(capacity * 3);
  if (out.normals) chunk.normals.reserve(capacity * 3);
  if (out.colors) chunk.colors.reserve(capacity * 4);
  for (uint32_t row = chunk.rowBegin; row < chunk.rowEnd; ++row) {
    uint32_t k = row - chunk.rowBegin + halo;
    const double* final = &grid[size_t(k) * V * 3];
    if (c.moves()) {
      std::copy(final, final + size_t(V) * 3, moved.begin());
      const uint32_t gridRow = row >= U ? row - U : row;
      for (uint32_t j = 0; j < V; ++j) {
        mtgen::Move m = ScanGenerator::moveOf(c, gridRow, j);
        if (m.kind == 0) continue;
        const double* n[2];
        for (int e = 0; e < 2; ++e) {
          const int* d = mtgen::kNeighbour[(m.dir + e) % 6];
          n[e] = &grid[(size_t(k + d[0]) * V + ScanGenerator::wrap(int64_t(j) + d[1], V)) * 3];
        }
        ScanGenerator::applyMove(m, n[0], n[1], &moved[size_t(j) * 3]);
      }
      final = moved.data();
    }
    const size_t rowStart = chunk.count;
    const mtgen::Interval* drop = ScanGenerator::droppedBegin(c, row);
    const mtgen::Interval* dropEnd = ScanGenerator::droppedEnd(c, row);
    for (uint32_t j = 0; j < W; ++j) {
      if (drop != dropEnd && j >= drop->lo) {  // skip the vertices strictly inside a hole
        j = drop->hi;
        ++drop;
        continue;
      }
      const uint32_t g = j >= V ? j - V : j;  // column V is the seam copy of column 0
      const double* p = final + size_t(g) * 3;
      chunk.xyz.insert(chunk.xyz.end(), p, p + 3);
      if (out.normals) {
        uint32_t jn = g + 1 == V ? (c.sheet ? g : 0) : g + 1, jp = g == 0 ? (c.sheet ? 0 : V - 1) : g - 1;
        const double* up = &grid[(size_t(k + 1) * V + g) * 3];
        const double* down = &grid[(size_t(k - 1) * V + g) * 3];
        const double* right = &grid[(size_t(k) * V + jn) * 3];
        const double* left = &grid[(size_t(k) * V + jp) * 3];
        double du[3] = {up[0] - down[0], up[1] - down[1], up[2] - down[2]};
        double dv[3] = {right[0] - left[0], right[1] - left[1], right[2] - left[2]};
        double n[3] = {du[1] * dv[2] - du[2] * dv[1], du[2] * dv[0] - du[0] * dv[2], du[0] * dv[1] - du[1] * dv[0]};
        double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        for (int a = 0; a < 3; ++a) chunk.normals.push_back(float(len > 0 ? n[a] / len : (a == 2 ? 1.0 : 0.0)));
      }
      if (out.colors) {
        uint8_t rgba[4];
        colorFor(*out.colorField, p, disp[size_t(k) * V + g], c.amplitudeSum, rgba);
        chunk.colors.insert(chunk.colors.end(), rgba, rgba + 4);
      }
      ++chunk.count;
    }
    if (c.isLine(row)) {  // the T-junction vertices of this row, after its grid vertices
      for (uint32_t j = 0; j < V; ++j) {
        const double* a = final + size_t(j) * 3;
        const double* b = final + size_t(j + 1 == V ? 0 : j + 1) * 3;
        const double p[3] = {0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]), 0.5 * (a[2] + b[2])};
        chunk.xyz.insert(chunk.xyz.end(), p, p + 3);
        // Normal and colour: the mean of the two ends' (a line row loses no vertex to a hole, so
        // grid vertex j of this row is record rowStart + j).
        const size_t ea = rowStart + j, eb = rowStart + (j + 1 == V ? 0 : j + 1);
        if (out.normals) {
          double n[3], len = 0;
          for (int e = 0; e < 3; ++e) n[e] = double(chunk.normals[3 * ea + e]) + chunk.normals[3 * eb + e], len += n[e] * n[e];
          len = std::sqrt(len);
          for (int e = 0; e < 3; ++e) chunk.normals.push_back(float(len > 0 ? n[e] / len : (e == 2 ? 1.0 : 0.0)));
        }
        if (out.colors)
          for (int e = 0; e < 4; ++e)
            chunk.colors.push_back(uint8_t((unsigned(chunk.colors[4 * ea + e]) + chunk.colors[4 * eb + e] + 1) / 2));
        ++chunk.count;
      }
    }
  }
}

struct FaceChunk {
  // Grid order: cell rows [rowBegin, rowEnd) of one component. Otherwise (shuffle or triangle
  // soup): sequence positions [begin, end) of the global grid-face range.
  bool byRows = true;
  uint32_t component = 0, rowBegin = 0, rowEnd = 0;
  uint64_t begin = 0, end = 0;
  std::vector<uint32_t> triangles;
  std::vector<float> corners;  // 9 floats per triangle, triangle soups only
  std::vector<float> uv;       // --texture: 6 floats per triangle
  std::vector<uint32_t> page;  // --texture: 1 per triangle
};

// --texture: the corner coordinates of cell row `row`'s triangles, in cellRowTriangles' order
// (cells left to right, holes skipped; (v00, v10, v11), (v00, v11, v01), and on a T-junction line
// (v00, v11, m), (m, v11, v01)).
void cellRowTexcoords(const mtgen::TextureAtlas& atlas, uint32_t component, const Component& c, uint32_t row, FaceChunk& chunk) {
  static const double kPlain[2][3][2] = {{{0, 0}, {1, 0}, {1, 1}}, {{0, 0}, {1, 1}, {0, 1}}};
  static const double kSplit[3][3][2] = {{{0, 0}, {1, 0}, {1, 1}}, {{0, 0}, {1, 1}, {0, 0.5}}, {{0, 0.5}, {1, 1}, {0, 1}}};
  const bool line = c.isLine(row);
  for (uint32_t col = 0; col < c.cols; ++col) {
    if (ScanGenerator::cellRemoved(c, row, col)) continue;
    const int n = line ? 3 : 2;
    for (int t = 0; t < n; ++t) {
      uint32_t page = 0;
      for (int k = 0; k < 3; ++k) {
        const double* o = line ? kSplit[t][k] : kPlain[t][k];
        float uv[2];
        atlas.cornerUV(component, row, col, o[0], o[1], uv, page);
        chunk.uv.insert(chunk.uv.end(), uv, uv + 2);
      }
      chunk.page.push_back(page);
    }
  }
}

void computeFaceChunk(const ScanGenerator& gen, const mtgen::FeistelPermutation* shuffle, bool corners,
                      FaceChunk& chunk, const mtgen::TextureAtlas* atlas = nullptr) {
  if (chunk.byRows) {
    const Component& c = gen.components()[chunk.component];
    chunk.triangles.reserve(size_t(chunk.rowEnd - chunk.rowBegin) * c.cols * 6);
    for (uint32_t row = chunk.rowBegin; row < chunk.rowEnd; ++row) {
      ScanGenerator::cellRowTriangles(c, row, chunk.triangles);
      if (atlas) cellRowTexcoords(*atlas, chunk.component, c, row, chunk);
    }
    return;
  }
  chunk.triangles.reserve(size_t(chunk.end - chunk.begin) * 3);
  for (uint64_t k = chunk.begin; k < chunk.end; ++k) {
    uint64_t f = shuffle ? (*shuffle)(k) : k;
    uint32_t tri[3];
    mtgen::VertexRef refs[3];
    if (!gen.gridTriangle(f, tri, corners ? refs : static_cast<mtgen::VertexRef*>(nullptr))) continue;
    chunk.triangles.insert(chunk.triangles.end(), tri, tri + 3);
    if (corners)
      for (const auto& g : refs) {
        double p[3];
        gen.position(g, p);
        chunk.corners.insert(chunk.corners.end(), {float(p[0]), float(p[1]), float(p[2])});
      }
  }
}

size_t pipelineTokens() { return 2 * std::max<size_t>(1, tbb::this_task_arena::max_concurrency()) + 2; }

void streamVertices(const ScanGenerator& gen, const OutputSettings& settings, MeshOutput& out, Progress& progress) {
  for (uint32_t ci = 0; ci < gen.components().size(); ++ci) {
    const Component& c = gen.components()[ci];
    std::vector<mtgen::ColParams> cols(c.cols);  // O(columns): shared by every row
    for (uint32_t j = 0; j < c.cols; ++j) cols[j] = ScanGenerator::colParams(c, j);
    const uint32_t rowsPerChunk = uint32_t(std::max<size_t>(1, kChunkVertices / c.cols));
    uint32_t nextRow = 0;
    tbb::parallel_pipeline(
        pipelineTokens(),
        tbb::make_filter<void, std::shared_ptr<VertexChunk>>(
            tbb::filter_mode::serial_in_order,
            [&](tbb::flow_control& fc) -> std::shared_ptr<VertexChunk> {
              if (nextRow >= c.vertexRows()) {
                fc.stop();
                return nullptr;
              }
              auto chunk = std::make_shared<VertexChunk>();
              chunk->component = ci;
              chunk->rowBegin = nextRow;
              chunk->rowEnd = nextRow = std::min(c.vertexRows(), nextRow + rowsPerChunk);
              return chunk;
            }) &
            tbb::make_filter<std::shared_ptr<VertexChunk>, std::shared_ptr<VertexChunk>>(
                tbb::filter_mode::parallel,
                [&](std::shared_ptr<VertexChunk> chunk) {
                  computeVertexChunk(gen, cols, settings, *chunk);
                  return chunk;
                }) &
            tbb::make_filter<std::shared_ptr<VertexChunk>, void>(
                tbb::filter_mode::serial_in_order, [&](std::shared_ptr<VertexChunk> chunk) {
                  for (size_t v = 0; v < chunk->count; ++v)
                    out.vertex(&chunk->xyz[3 * v], settings.normals ? &chunk->normals[3 * v] : nullptr,
                               settings.colors ? &chunk->colors[4 * v] : nullptr);
                  progress.advance(chunk->count);
                }));
  }
}

void streamFaces(const ScanGenerator& gen, bool shuffle, MeshOutput& out, Progress& progress,
                 const mtgen::TextureAtlas* atlas = nullptr) {
  const bool corners = out.wantsCorners();
  std::unique_ptr<mtgen::FeistelPermutation> permutation;
  if (shuffle)
    permutation = std::make_unique<mtgen::FeistelPermutation>(gen.gridFaceCount(),
                                                              mtgen::hashKey(gen.options().seed, 0x5EF1E));
  const bool byRows = !shuffle && !corners;
  uint32_t component = 0, nextRow = 0;
  uint64_t next = 0;
  tbb::parallel_pipeline(
      pipelineTokens(),
      tbb::make_filter<void, std::shared_ptr<FaceChunk>>(
          tbb::filter_mode::serial_in_order,
          [&](tbb::flow_control& fc) -> std::shared_ptr<FaceChunk> {
            auto chunk = std::make_shared<FaceChunk>();
            chunk->byRows = byRows;
            if (byRows) {
              while (component < gen.components().size() && nextRow >= gen.components()[component].rows)
                ++component, nextRow = 0;
              if (component >= gen.components().size()) {
                fc.stop();
                return nullptr;
              }
              const Component& c = gen.components()[component];
              uint32_t rowsPerChunk = uint32_t(std::max<size_t>(1, kChunkFaces / (2 * size_t(c.cols))));
              chunk->component = component;
              chunk->rowBegin = nextRow;
              chunk->rowEnd = nextRow = std::min(c.rows, nextRow + rowsPerChunk);
            } else {
              if (next >= gen.gridFaceCount()) {
                fc.stop();
                return nullptr;
              }
              chunk->begin = next;
              chunk->end = next = std::min(gen.gridFaceCount(), next + kChunkFaces);
            }
            return chunk;
          }) &
          tbb::make_filter<std::shared_ptr<FaceChunk>, std::shared_ptr<FaceChunk>>(
              tbb::filter_mode::parallel,
              [&](std::shared_ptr<FaceChunk> chunk) {
                computeFaceChunk(gen, permutation.get(), corners, *chunk, atlas);
                return chunk;
              }) &
          tbb::make_filter<std::shared_ptr<FaceChunk>, void>(
              tbb::filter_mode::serial_in_order, [&](std::shared_ptr<FaceChunk> chunk) {
                size_t n = chunk->triangles.size() / 3;
                if (atlas) {
                  if (chunk->page.size() != n) mt::fail("mtgen", "internal: texture coordinates out of step with the faces");
                  for (size_t t = 0; t < n; ++t) out.triangleUV(&chunk->triangles[3 * t], &chunk->uv[6 * t], chunk->page[t]);
                } else {
                  for (size_t t = 0; t < n; ++t)
                    out.triangle(&chunk->triangles[3 * t], corners ? &chunk->corners[9 * t] : nullptr);
                }
                progress.advance(n);
              }));
}

// "1M", "53M", "2.5k", "1e6", "1000000" -> count; 0 on anything else.
uint64_t parseCount(const std::string& text) {
  if (text.empty()) return 0;
  char* end = nullptr;
  errno = 0;
  double value = std::strtod(text.c_str(), &end);
  if (errno != 0 || end == text.c_str()) return 0;
  std::string suffix(end);
  double multiplier = 1;
  if (suffix == "k" || suffix == "K") multiplier = 1e3;
  else if (suffix == "m" || suffix == "M") multiplier = 1e6;
  else if (suffix == "g" || suffix == "G") multiplier = 1e9;
  else if (!suffix.empty()) return 0;
  double count = std::round(value * multiplier);
  if (!(count >= 1) || count > 1e18) return 0;
  return uint64_t(count);
}

// The command line, as parsed.
struct Cli {
  OutputSettings settings;
  std::string trianglesText = "1M", formatText = "ply", densityText = "uniform", pathologyText, offsetText;
  mtgen::GeneratorOptions gen;
  bool shuffle = false;
  unsigned threads = 0;
  std::string textureText;           // --texture: "", charts or fragmented
  mtgen::TextureOptions texture;
  std::string paintInput;  // --paint IN
  bool quiet = false;      // -q: no progress lines
  CLI::Option* formatOption = nullptr;
};

// The surface's options: size, seed, holes, components, density, pathologies, face order.
void addSurfaceOptions(CLI::App& app, Cli& c) {
  app.add_option("-t,--triangles", c.trianglesText,
                 "Number of triangles, with optional suffix k (1e3), M (1e6), G (1e9): 2.5k, 1M, 53M. "
                 "The output has this count within 1% (exactly, in most cases); from 18 per component to 4G")
      ->default_str("1M");
  app.add_option("-s,--seed", c.gen.seed, "Seed of every random choice (shape, holes, layout, shuffle)")
      ->check(mt::cli::countIn(0, UINT64_MAX))
      ->default_str("1");
  app.add_option("--holes", c.gen.holes,
                 "Number of holes (open boundaries like scanner occlusions): roughly round, sizes from a few "
                 "edges around to about half the tube radius, never touching each other, so the mesh has "
                 "exactly this many boundary loops; fails if they cannot fit. At most one per 100 triangles "
                 "(placing them takes time quadratic in their number)")
      ->check(mt::cli::countIn(0, kMaxHoles))
      ->default_str("0");
  app.add_option("--components", c.gen.components,
                 "Number of separate closed components of different sizes, placed apart on a lattice; the "
                 "triangle budget is split by surface area")
      ->default_str("1")
      ->check(mt::cli::countIn(1, 1000000));
  app.add_option("--density", c.densityText,
                 "uniform: near-uniform triangle size; varying: the parameterization is warped so the edge "
                 "length varies smoothly by 10x around the major circle (3x around the minor one)")
      ->check(CLI::IsMember({"uniform", "varying"}))
      ->default_str("uniform");
  std::string pathologyHelp =
      "Scan pathologies to add, comma-separated, or all (none by default; each is a pure function of the grid "
      "position, so the bytes still do not depend on the thread count):";
  for (const mtgen::PathologyInfo& p : mtgen::kPathologies) pathologyHelp += std::string("\n  ") + p.name + ": " + p.help;
  app.add_option("--pathology", c.pathologyText, pathologyHelp)->default_str("none");
  app.add_flag("--shuffle", c.shuffle,
               "Emit faces in a pseudo-random order (a keyed bijection of the face indices, O(1) memory); "
               "vertices stay in grid order and the set of triangles is unchanged");
}

// The output's options: name, format, vertex attributes; and the thread count.
void addOutputOptions(CLI::App& app, Cli& c) {
  app.add_flag("--normals", c.settings.normals,
               "Write unit per-vertex normals (central differences of the grid) [ply, ply-ascii, obj]");
  app.add_flag("--colors", c.settings.colors,
               "Write per-vertex RGBA colours with sharp features: a coarse checker of four hues, dark stripes and\n"
               "small vivid spots (testing/color_field.h), shaded by the displacement [ply, ply-ascii]");
  c.formatOption =
      app.add_option("--format", c.formatText,
                     "ply (binary little-endian), ply-ascii, obj, off, stl (ASCII triangle soup); it must agree with "
                     "the output's extension (.ply for both PLY forms). Text formats are meant for small meshes; "
                     "their coordinates are the float32 values printed with %.9g")
          ->check(CLI::IsMember({"ply", "ply-ascii", "obj", "off", "stl"}))
          ->default_str("from the extension");
  app.add_option("--offset", c.offsetText,
                 "X,Y,Z added to every position in double, each within +-1e9 (e.g. 500000,4000000,100: UTM-like metres\n"
                 "for a georeferenced scan); implies --double [ply only]");
  app.add_flag("--double", c.settings.doublePrecision,
               "Binary PLY with double x,y,z (the full-precision generated values) [ply only]");
  app.add_option("--texture", c.textureText,
                 "A textured scan [ply only]: per-face texture coordinates (PLY texcoord lists, texnumber) and texture pages\n"
                 "OUT_tex<k>.jpg beside the output (named by 'comment TextureFile'). charts: charts of 48 x 48 cells, each\n"
                 "its own slot, so chart borders are seams; fragmented: charts of 1 x 2 cells (four triangles each): thousands\n"
                 "of tiny charts. The texels show sharp checks and lines in the torus angles (testing/texture_atlas.h).\n"
                 "box (with --paint IN only): IN with box-mapped charts (testing/box_texture.h) and one PNG page of the\n"
                 "--colors field")
      ->check(CLI::IsMember({"charts", "fragmented", "box"}));
  app.add_option("--texels-per-cell", c.texture.texelsPerCell, "--texture: texels per grid cell side")
      ->check(mt::cli::countIn(1, 64))
      ->default_str("2");
  app.add_option("--texture-page", c.texture.pageSide, "--texture: the largest texture page side, in texels (more pages when needed)")
      ->check(mt::cli::countIn(64, 16384))
      ->default_str("4096");
  app.add_option("--texture-quality", c.texture.quality, "--texture: JPEG quality of the pages")
      ->check(mt::cli::countIn(1, 100))
      ->default_str("90");
  app.add_option("--threads", c.threads, "Worker threads (0 = all cores); the output does not depend on it")
      ->check(mt::cli::countIn(0, 4096))
      ->default_str("0");
}

// Prints "mtgen: error: ..." and returns false.
bool refuse(const char* format, ...) __attribute__((format(printf, 1, 2)));
bool refuse(const char* format, ...) {
  std::fprintf(stderr, "mtgen: error: ");
  va_list args;
  va_start(args, format);
  std::vfprintf(stderr, format, args);
  va_end(args);
  std::fprintf(stderr, "\n");
  return false;
}

// The triangle count, the pathologies and the hole count; false (with the message) when refused.
bool checkSurface(Cli& c) {
  c.gen.triangles = parseCount(c.trianglesText);
  if (c.gen.triangles == 0)
    return refuse("--triangles must be a positive count like 1000, 2.5k, 1M, at most 4G (got '%s')", c.trianglesText.c_str());
  std::string badPathology;
  if (!mtgen::parsePathologies(c.pathologyText, c.gen.pathologies, badPathology)) {
    std::string names;
    for (const mtgen::PathologyInfo& p : mtgen::kPathologies) names += std::string(names.empty() ? "" : ", ") + p.name;
    return refuse("--pathology: unknown '%s' (a comma-separated list of %s, or all)", badPathology.c_str(), names.c_str());
  }
  if (c.gen.holes > c.gen.triangles / 100)
    return refuse("--holes %u: at most one hole per 100 triangles (%llu for --triangles %s)", c.gen.holes,
                  (unsigned long long)(c.gen.triangles / 100), c.trianglesText.c_str());
  c.gen.varyingDensity = c.densityText == "varying";
  return true;
}

// The format: from the extension, and --format (if given) must agree with it, so that no file
// gets bytes its name does not announce; then the attributes the format can hold.
bool chooseFormat(Cli& c) {
  OutputSettings& settings = c.settings;
  std::string ext = std::filesystem::path(settings.path).extension().string();
  for (auto& ch : ext) ch = char(std::tolower(static_cast<unsigned char>(ch)));
  const char* byExtension = ext == ".ply" ? "ply" : ext == ".obj" ? "obj" : ext == ".off" ? "off" : ext == ".stl" ? "stl" : nullptr;
  if (!byExtension)
    return refuse("%s: %s (supported: .ply, .obj, .off, .stl)", settings.path.c_str(),
                  ext.empty() ? "the output name has no extension: cannot choose its format" : ("cannot write the format " + ext).c_str());
  if (c.formatOption->count() == 0) c.formatText = byExtension;
  else if (c.formatText.rfind(byExtension, 0) != 0)
    return refuse("--format %s does not match the output's extension %s", c.formatText.c_str(), ext.c_str());
  const std::string& f = c.formatText;
  settings.format = f == "ply" ? Format::PlyBinary : f == "ply-ascii" ? Format::PlyAscii : f == "obj" ? Format::Obj
                  : f == "off" ? Format::Off : Format::Stl;
  bool anyPly = settings.format == Format::PlyBinary || settings.format == Format::PlyAscii;
  if (settings.doublePrecision && settings.format != Format::PlyBinary) return refuse("--double needs --format ply");
  if (!c.offsetText.empty()) {
    // X,Y,Z, three finite numbers; the coordinates then need doubles (binary PLY only).
    std::stringstream in(c.offsetText);
    std::string part;
    int n = 0;
    while (std::getline(in, part, ',')) {
      size_t used = 0;
      double v = 0;
      try {
        v = std::stod(part, &used);
      } catch (const std::exception&) {
        used = 0;
      }
      if (n == 3 || used == 0 || used != part.size() || !std::isfinite(v) || std::abs(v) > 1e9)
        return refuse("--offset wants X,Y,Z, three numbers within +-1e9 (got '%s')", c.offsetText.c_str());
      settings.offset[n++] = v;
    }
    if (n != 3) return refuse("--offset wants X,Y,Z, three numbers within +-1e9 (got '%s')", c.offsetText.c_str());
    if (settings.format != Format::PlyBinary) return refuse("--offset needs --format ply (binary, double coordinates)");
    settings.doublePrecision = true;
  }
  if (settings.colors && !anyPly) return refuse("--colors needs --format ply or ply-ascii");
  if (!c.textureText.empty()) {
    if (settings.format != Format::PlyBinary) return refuse("--texture needs --format ply");
    if (c.textureText == "box" && c.paintInput.empty()) return refuse("--texture box textures a mesh given by --paint IN");
    if (c.shuffle) return refuse("--texture writes faces in grid order: it cannot be combined with --shuffle");
    if (settings.normals || settings.colors || settings.doublePrecision)
      return refuse("--texture writes float x, y, z only: it cannot be combined with --normals, --colors, --double or --offset");
    c.texture.fragmented = c.textureText == "fragmented";
  }
  if (settings.normals && !anyPly && settings.format != Format::Obj)
    return refuse("--normals needs --format ply, ply-ascii or obj");
  return true;
}

// Streams the mesh to the temporary name, renames it over the output and prints the summary line.
// --texture: the pages are written first (each renamed when complete), then the mesh naming them.
void writeMesh(const OutputSettings& settings, const ScanGenerator& generator, bool shuffle, bool quiet,
               const mtgen::TextureOptions* texture = nullptr) {
  std::unique_ptr<MeshOutput> out;
  std::unique_ptr<mtgen::TextureAtlas> atlas;
  if (texture) {
    atlas = std::make_unique<mtgen::TextureAtlas>(generator, *texture);
    const std::filesystem::path p(settings.path);
    std::vector<std::string> names;
    for (int k = 0; k < atlas->pages(); ++k) {
      names.push_back(p.stem().string() + "_tex" + std::to_string(k) + ".jpg");
      atlas->writePage(k, (p.parent_path() / names.back()).string());
    }
    std::fprintf(stderr, "mtgen: %d texture pages of %d x up to %d texels, %llu charts\n", atlas->pages(), atlas->pageWidth(),
                 atlas->pageHeight(0), (unsigned long long)atlas->charts());
    out = std::make_unique<TexturedPlyOutput>(settings, generator.vertexCount(), generator.triangleCount(), names);
  } else if (settings.format == Format::PlyBinary)
    out = std::make_unique<BinaryPlyOutput>(settings);
  else
    out = std::make_unique<TextOutput>(settings, generator.vertexCount(), generator.triangleCount());
  const uint64_t triangles = generator.triangleCount();
  const uint64_t vertices = out->wantsVertices() ? generator.vertexCount() : 0;
  Progress progress(vertices + triangles, triangles, !quiet && triangles > kProgressTriangles);
  if (out->wantsVertices()) streamVertices(generator, settings, *out, progress);
  streamFaces(generator, shuffle, *out, progress, atlas.get());
  out->finish();
  gTemporaryPath[0] = 0;

  struct stat st {};
  stat(settings.path.c_str(), &st);
  double seconds = progress.elapsed();
  std::fprintf(stderr, "mtgen: wrote %s: %llu triangles, %llu vertices, %lld bytes, %.2f s (%.1f M triangles/s)\n",
               settings.path.c_str(), (unsigned long long)triangles, (unsigned long long)generator.vertexCount(),
               (long long)st.st_size, seconds, double(triangles) / std::max(seconds, 1e-9) / 1e6);
}

// --paint: IN with the colour field on its vertices, as binary PLY (two reads of IN: its box,
// then the copy; triangles are held until the vertices are written, since OBJ interleaves them).
int paintMesh(const std::string& input, const std::string& output) {
  struct Box : mt::MeshSink {
    double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
    mt::MeshHeader header;
    void begin(const mt::MeshHeader& h) override { header = h; }
    void vertices(const mt::InputVertex* v, size_t n, uint64_t) override {
      for (size_t i = 0; i < n; ++i)
        for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], v[i].p[a]), hi[a] = std::max(hi[a], v[i].p[a]);
    }
    void triangles(const uint32_t*, size_t) override {}
  } box;
  mt::openMesh(input)->read(box);
  mt::checkOutputPath(output, {input});
  const mt::testing::ColorField field(box.lo, box.hi);
  struct Copy : mt::MeshSink {
    mt::PlyWriter writer;
    const mt::testing::ColorField& field;
    std::vector<uint32_t> tris;
    Copy(const std::string& out, bool dbl, const mt::testing::ColorField& f)
        : writer(out, mt::PlyWriteOptions{dbl, false, true}), field(f) {}
    void vertices(const mt::InputVertex* v, size_t n, uint64_t) override {
      for (size_t i = 0; i < n; ++i) {
        uint8_t rgba[4];
        field.colorAt(v[i].p, rgba);
        writer.addVertex(v[i].p, nullptr, rgba);
      }
    }
    void triangles(const uint32_t* t, size_t n) override { tris.insert(tris.end(), t, t + 3 * n); }
  } copy(output, box.header.doublePrecision, field);
  mt::openMesh(input)->read(copy);
  for (size_t t = 0; t < copy.tris.size(); t += 3) copy.writer.addTriangle(copy.tris[t], copy.tris[t + 1], copy.tris[t + 2]);
  copy.writer.finish();
  std::fprintf(stderr, "mtgen: painted %s -> %s: %llu vertices, %llu triangles\n", input.c_str(), output.c_str(),
               (unsigned long long)copy.writer.vertexCount(), (unsigned long long)copy.writer.triangleCount());
  return 0;
}

// --paint IN --texture box: IN with box-mapped charts and the colour field baked into one PNG page
// (testing/box_texture.h), as a PLY with per-face texcoord lists naming OUT_tex0.png. Holds IN in
// RAM (24 bytes a vertex, 36 a triangle) and the page.
int textureMesh(const std::string& input, const std::string& output, int pageSide) {
  struct Load : mt::MeshSink {
    std::vector<double> positions;
    std::vector<uint32_t> tris;
    void vertices(const mt::InputVertex* v, size_t n, uint64_t) override {
      for (size_t i = 0; i < n; ++i) positions.insert(positions.end(), v[i].p, v[i].p + 3);
    }
    void triangles(const uint32_t* t, size_t n) override { tris.insert(tris.end(), t, t + 3 * n); }
  } in;
  mt::openMesh(input)->read(in);
  mt::checkOutputPath(output, {input});
  const size_t nv = in.positions.size() / 3, nt = in.tris.size() / 3;
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  for (size_t v = 0; v < nv; ++v)
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], in.positions[3 * v + size_t(a)]), hi[a] = std::max(hi[a], in.positions[3 * v + size_t(a)]);
  const mt::testing::ColorField field(lo, hi);
  mt::testing::BoxTextureOptions options;
  options.pageSide = pageSide;
  const mt::testing::BoxTexture box = mt::testing::boxTexture(in.positions.data(), nv, in.tris.data(), nt, field, options);
  const std::filesystem::path p(output);
  const std::string page = p.stem().string() + "_tex0.png";
  mt::tex::writeFileAtomically((p.parent_path() / page).string(), mt::tex::encodePng(box.page));
  OutputSettings settings;
  settings.path = output;
  armTemporary(settings);
  TexturedPlyOutput out(settings, nv, nt, {page});
  for (size_t v = 0; v < nv; ++v) out.vertex(&in.positions[3 * v], nullptr, nullptr);
  for (size_t t = 0; t < nt; ++t) out.triangleUV(&in.tris[3 * t], &box.cornerUV[6 * t], 0);
  out.finish();
  gTemporaryPath[0] = 0;
  std::fprintf(stderr, "mtgen: textured %s -> %s: %zu vertices, %zu triangles, %u charts, page %s %d x %d\n", input.c_str(),
               output.c_str(), nv, nt, box.charts, page.c_str(), box.page.width, box.page.height);
  return 0;
}

int run(int argc, char** argv) {
  CLI::App app{
      "mtgen: streams a procedurally generated, scan-like closed mesh of any size to a mesh file.\n"
      "Each component is a torus displaced by multi-octave noise (detail down to ~2 edges, like a dense\n"
      "scan), sampled on a grid: vertices in grid order, faces in grid order unless --shuffle.\n"
      "Memory is O(grid rows), never O(triangles). Same options -> identical bytes (any thread count).",
      "mtgen"};
  Cli c;
  app.add_option("-o,--output", c.settings.path,
                 "Output file; its extension gives the format unless --format does (.ply, .obj, .off, .stl). "
                 "Written as OUT.tmp.PID.RANDOM, renamed when complete")
      ->required();
  addSurfaceOptions(app, c);
  addOutputOptions(app, c);
  app.add_option("--paint", c.paintInput,
                 "Instead of generating: copy the mesh IN (PLY, OBJ, OFF, STL, glTF) to the output (binary PLY) with\n"
                 "the --colors field painted on its vertices (over IN's bounding box), e.g. to colour a scangen scan.\n"
                 "Holds IN's triangles in RAM (12 bytes each); IN's own colours are replaced. Not with --texture");
  app.add_flag("-q,--quiet", c.quiet,
               "No progress lines on stderr (printed for outputs of more than " + std::to_string(kProgressTriangles / 1000000) +
                   "M triangles); the summary line stays");
  if (int code = mt::cli::parse(app, argc, argv, "mtgen: error"); code >= 0) return code;
  if (!checkSurface(c) || !chooseFormat(c)) return 1;
  // --paint copies IN with the colour field: it writes no texture coordinates nor pages, so a
  // --texture there would be silently dropped.
  if (!c.paintInput.empty() && !c.textureText.empty() && c.textureText != "box")
    return refuse("--texture cannot be combined with --paint, except as --texture box (--texture %s makes the torus's "
                  "charts; --paint copies IN)", c.textureText.c_str()), 1;
  if (!c.paintInput.empty() && c.settings.format != Format::PlyBinary)
    return refuse("--paint writes binary PLY: the output name must end in .ply (got %s)", c.settings.path.c_str()), 1;

  std::unique_ptr<tbb::global_control> threadLimit;
  if (c.threads > 0)
    threadLimit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, c.threads);
  try {
    if (!c.paintInput.empty() && c.textureText == "box") return textureMesh(c.paintInput, c.settings.path, c.texture.pageSide);
    if (!c.paintInput.empty()) return paintMesh(c.paintInput, c.settings.path);
    const ScanGenerator generator(c.gen);
    if (c.settings.colors) c.settings.colorField = colorFieldOf(generator);
    mt::checkOutputPath(c.settings.path, {});  // not a directory, and its folder exists
    armTemporary(c.settings);
    writeMesh(c.settings, generator, c.shuffle, c.quiet, c.textureText.empty() ? nullptr : &c.texture);
  } catch (const std::exception& e) {
    return mt::reportError("mtgen", e);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) { return run(argc, argv); }
