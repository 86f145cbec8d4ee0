// Georeferenced scans: coordinates far from the origin (UTM-like metres) with centimetre detail.
// Whatever the input format, the finest cut of the build must hold every input triangle, each
// vertex within the grid step of its input position: no precision is lost on the way (text is
// parsed and stored as double; the MT grid is relative to the model's box).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "mtfile/mt_file.h"
#include "patchstore/io/ply_writer.h"
#include "patchstore/io/mesh_reader.h"
#include "tests/test_support.h"

namespace mt {
namespace {

using test::runTool;
using test::TempDir;

// An n x n grid at `spacing`, its corner at (x0, y0, z0), with a small height pattern.
struct Grid {
  int n;
  double x0, y0, z0, spacing;
  double x(int i) const { return x0 + spacing * i; }
  double y(int j) const { return y0 + spacing * j; }
  double z(int i, int j) const { return z0 + spacing * 0.1 * ((i * 7 + j * 3) % 5); }
  size_t triangles() const { return size_t(2) * (n - 1) * (n - 1); }
  template <class Fn>
  void faces(Fn fn) const {
    for (int j = 0; j + 1 < n; ++j)
      for (int i = 0; i + 1 < n; ++i) {
        int a = j * n + i, b = a + 1, c = a + n, d = c + 1;
        fn(a, b, d);
        fn(a, d, c);
      }
  }
};

void writeText(const Grid& g, const std::string& path, const std::string& format) {
  std::ostringstream o;
  o.precision(17);
  const size_t nv = size_t(g.n) * g.n;
  if (format == "off") o << "OFF\n" << nv << ' ' << g.triangles() << " 0\n";
  if (format == "ply")
    o << "ply\nformat ascii 1.0\nelement vertex " << nv << "\nproperty float x\nproperty float y\nproperty float z\n"
      << "element face " << g.triangles() << "\nproperty list uchar int vertex_indices\nend_header\n";
  for (int j = 0; j < g.n; ++j)
    for (int i = 0; i < g.n; ++i) o << (format == "obj" ? "v " : "") << g.x(i) << ' ' << g.y(j) << ' ' << g.z(i, j) << '\n';
  g.faces([&](int a, int b, int c) {
    if (format == "obj") o << "f " << a + 1 << ' ' << b + 1 << ' ' << c + 1 << '\n';
    else o << "3 " << a << ' ' << b << ' ' << c << '\n';
  });
  test::writeFile(path, o.str());
}

void writeBinary(const Grid& g, const std::string& path, bool doublePrecision) {
  PlyWriteOptions options;
  options.doublePrecision = doublePrecision;
  PlyWriter w(path, options);
  for (int j = 0; j < g.n; ++j)
    for (int i = 0; i < g.n; ++i) {
      double p[3] = {g.x(i), g.y(j), g.z(i, j)};
      if (!doublePrecision)
        for (double& c : p) c = double(float(c));
      w.addVertex(p);
    }
  g.faces([&](int a, int b, int c) { w.addTriangle(uint32_t(a), uint32_t(b), uint32_t(c)); });
  w.finish();
}

struct Collect : MeshSink {
  std::vector<double> positions;
  std::vector<uint32_t> tris;
  void vertices(const InputVertex* v, size_t n, uint64_t) override {
    for (size_t i = 0; i < n; ++i) positions.insert(positions.end(), v[i].p, v[i].p + 3);
  }
  void triangles(const uint32_t* idx, size_t n) override { tris.insert(tris.end(), idx, idx + 3 * n); }
};

// Builds, verifies and extracts the finest cut; every triangle must be there and every vertex
// within the grid step of the grid point it stands for.
void expectFinestCutKeepsEverything(const Grid& g, const std::string& input, bool floatInput) {
  const std::string mt = input + ".mt", cut = input + ".cut.ply";
  auto b = runTool("mtbuild", input + " -o " + mt + " -q");
  ASSERT_EQ(b.exitCode, 0) << b.output;
  auto v = runTool("mtverify", mt);
  EXPECT_EQ(v.exitCode, 0) << v.output;
  auto x = runTool("mtextract", mt + " --error 0 -o " + cut);
  ASSERT_EQ(x.exitCode, 0) << x.output;
  EXPECT_EQ(x.output.find("degenerate"), std::string::npos) << x.output;
  auto reader = MtFileReader::open(mt);
  const double step = reader->header().gridStep;
  EXPECT_LT(step, g.spacing / 2) << input;
  Collect c;
  openMesh(cut)->read(c);
  EXPECT_EQ(c.tris.size() / 3, g.triangles()) << input;
  EXPECT_EQ(c.positions.size() / 3, size_t(g.n) * g.n) << input;
  double worst = 0;
  for (size_t k = 0; k < c.positions.size(); k += 3) {
    const int i = int(std::lround((c.positions[k] - g.x0) / g.spacing));
    const int j = int(std::lround((c.positions[k + 1] - g.y0) / g.spacing));
    double p[3] = {g.x(i), g.y(j), g.z(i, j)};
    if (floatInput)
      for (double& q : p) q = double(float(q));
    for (int a = 0; a < 3; ++a) worst = std::max(worst, std::abs(c.positions[k + a] - p[a]));
  }
  EXPECT_LE(worst, step) << input << ": a vertex moved by " << worst << ", the grid step is " << step;
}

TEST(Georeferenced, CentimetreGridAtUtmCoordinatesKeepsEveryTriangleInEveryFormat) {
  TempDir tmp;
  // 1 cm at (6 000 000, 4 000 000): float32 resolution there is 0.5 m.
  const Grid g{200, 6000000.0, 4000000.0, 123.25, 0.01};
  for (const std::string format : {"off", "obj", "ply"}) {
    const std::string in = tmp.file("utm." + format);
    writeText(g, in, format);
    expectFinestCutKeepsEverything(g, in, false);
  }
  writeBinary(g, tmp.file("utm-double.ply"), true);
  expectFinestCutKeepsEverything(g, tmp.file("utm-double.ply"), false);
}

TEST(Georeferenced, FloatPlyAtUtmCoordinatesKeepsWhatFloatCanHold) {
  // A float32 binary PLY cannot hold centimetres at 4e6 m, but a 0.5 m grid is exact there: all of
  // its triangles must come through.
  TempDir tmp;
  const Grid g{150, 500000.0, 4000000.0, 80.0, 0.5};
  writeBinary(g, tmp.file("utm-float.ply"), false);
  expectFinestCutKeepsEverything(g, tmp.file("utm-float.ply"), true);
}

}  // namespace
}  // namespace mt
