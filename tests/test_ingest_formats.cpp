// Ingest -> export round trip for every input format the readers accept: the exported triangles
// are the input's, with bit-exact coordinates (and normals/colours where the input has them).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <fstream>

#include "patchstore/patch_store.h"
#include "tests/test_support.h"

namespace mt {
namespace {

using test::TempDir;

struct Mesh {
  std::vector<double> p;
  std::vector<float> n;
  std::vector<uint8_t> c;
  std::vector<uint32_t> t;
};

// A wavy sphere-like grid with a hole, values chosen so text formats carry them exactly.
Mesh makeMesh(bool precise) {
  Mesh m;
  const int R = 40, S = 30;
  for (int i = 0; i <= R; ++i)
    for (int j = 0; j < S; ++j) {
      double th = M_PI * (0.05 + 0.9 * i / R), ph = 2 * M_PI * j / S;
      double r = 1 + 0.05 * std::sin(5 * ph) * std::sin(3 * th);
      double q[3] = {r * std::sin(th) * std::cos(ph), r * std::sin(th) * std::sin(ph), r * std::cos(th)};
      for (double v : q) m.p.push_back(precise ? v + 1e-12 : double(float(v)));
      for (double v : q) m.n.push_back(float(v / r));
      m.c.insert(m.c.end(), {uint8_t(i * 6), uint8_t(j * 8), 128, 255});
    }
  for (int i = 0; i < R; ++i)
    for (int j = 0; j < S; ++j) {
      if (i > 10 && i < 14 && j > 4 && j < 9) continue;  // a hole
      uint32_t a = i * S + j, b = (i + 1) * S + j, c = (i + 1) * S + (j + 1) % S, d = i * S + (j + 1) % S;
      m.t.insert(m.t.end(), {a, b, c, a, c, d});
    }
  return m;
}

std::string g9(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

void writeFormat(const Mesh& m, const std::string& format, const std::string& path) {
  std::ofstream f(path, std::ios::binary);
  size_t nv = m.p.size() / 3, nt = m.t.size() / 3;
  auto be = [&](auto v) {
    char b[sizeof v];
    std::memcpy(b, &v, sizeof v);
    std::reverse(b, b + sizeof v);
    f.write(b, sizeof v);
  };
  if (format == "ply-ascii") {
    f << "ply\nformat ascii 1.0\nelement vertex " << nv
      << "\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\n"
         "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\nelement face "
      << nt << "\nproperty list uchar int vertex_indices\nend_header\n";
    for (size_t v = 0; v < nv; ++v)
      f << g9(m.p[3 * v]) << " " << g9(m.p[3 * v + 1]) << " " << g9(m.p[3 * v + 2]) << " " << g9(m.n[3 * v]) << " "
        << g9(m.n[3 * v + 1]) << " " << g9(m.n[3 * v + 2]) << " " << int(m.c[4 * v]) << " " << int(m.c[4 * v + 1]) << " "
        << int(m.c[4 * v + 2]) << " " << int(m.c[4 * v + 3]) << "\n";
    for (size_t t = 0; t < nt; ++t) f << "3 " << m.t[3 * t] << " " << m.t[3 * t + 1] << " " << m.t[3 * t + 2] << "\n";
  } else if (format == "ply-be-double") {
    f << "ply\nformat binary_big_endian 1.0\nelement vertex " << nv
      << "\nproperty double x\nproperty double y\nproperty double z\nelement face " << nt
      << "\nproperty list uchar uint vertex_indices\nend_header\n";
    for (double v : m.p) be(v);
    for (size_t t = 0; t < nt; ++t) {
      f.put(3);
      for (int k = 0; k < 3; ++k) be(m.t[3 * t + k]);
    }
  } else if (format == "obj") {
    for (size_t v = 0; v < nv; ++v) f << "v " << g9(m.p[3 * v]) << " " << g9(m.p[3 * v + 1]) << " " << g9(m.p[3 * v + 2]) << "\n";
    for (size_t t = 0; t < nt; ++t) f << "f " << m.t[3 * t] + 1 << " " << m.t[3 * t + 1] + 1 << " " << m.t[3 * t + 2] + 1 << "\n";
  } else if (format == "off") {
    f << "OFF\n" << nv << " " << nt << " 0\n";
    for (size_t v = 0; v < nv; ++v) f << g9(m.p[3 * v]) << " " << g9(m.p[3 * v + 1]) << " " << g9(m.p[3 * v + 2]) << "\n";
    for (size_t t = 0; t < nt; ++t) f << "3 " << m.t[3 * t] << " " << m.t[3 * t + 1] << " " << m.t[3 * t + 2] << "\n";
  } else if (format == "stl-ascii") {
    f << "solid test\n";
    for (size_t t = 0; t < nt; ++t) {
      f << "facet normal 0 0 0\nouter loop\n";
      for (int k = 0; k < 3; ++k) {
        uint32_t v = m.t[3 * t + k];
        f << "vertex " << g9(m.p[3 * v]) << " " << g9(m.p[3 * v + 1]) << " " << g9(m.p[3 * v + 2]) << "\n";
      }
      f << "endloop\nendfacet\n";
    }
    f << "endsolid test\n";
  } else if (format == "stl-binary") {
    char header[80] = "solid but binary";
    f.write(header, 80);
    uint32_t count = uint32_t(nt);
    f.write(reinterpret_cast<char*>(&count), 4);
    for (size_t t = 0; t < nt; ++t) {
      float rec[12] = {0, 0, 0};
      for (int k = 0; k < 3; ++k)
        for (int a = 0; a < 3; ++a) rec[3 + 3 * k + a] = float(m.p[3 * m.t[3 * t + k] + a]);
      f.write(reinterpret_cast<char*>(rec), 48);
      f.write("\0\0", 2);
    }
  }
}

struct Corner {
  std::array<double, 3> p;
  std::array<float, 3> n;
  std::array<uint8_t, 4> c;
  bool operator<(const Corner& o) const { return std::tie(p, n, c) < std::tie(o.p, o.n, o.c); }
  bool operator==(const Corner& o) const { return p == o.p && n == o.n && c == o.c; }
};
using Triangle = std::array<Corner, 3>;

struct Collect : MeshSink {
  std::vector<InputVertex> v;
  std::vector<uint32_t> t;
  void vertices(const InputVertex* in, size_t n, uint64_t) override { v.insert(v.end(), in, in + n); }
  void triangles(const uint32_t* idx, size_t n) override { t.insert(t.end(), idx, idx + 3 * n); }
};

std::vector<Triangle> read(const std::string& path, uint64_t* vertices = nullptr) {
  Collect c;
  openMesh(path)->read(c);
  std::vector<Triangle> out;
  for (size_t i = 0; i < c.t.size(); i += 3) {
    Triangle tri;
    for (int k = 0; k < 3; ++k) {
      const InputVertex& v = c.v[c.t[i + k]];
      tri[k] = {{v.p[0], v.p[1], v.p[2]}, {v.n[0], v.n[1], v.n[2]}, {v.c[0], v.c[1], v.c[2], v.c[3]}};
    }
    std::rotate(tri.begin(), std::min_element(tri.begin(), tri.end()), tri.end());  // keep orientation
    out.push_back(tri);
  }
  std::sort(out.begin(), out.end());
  if (vertices) *vertices = c.v.size();
  return out;
}

class FormatRoundTrip : public ::testing::TestWithParam<std::string> {};

TEST_P(FormatRoundTrip, ExportEqualsInput) {
  TempDir tmp;
  const std::string format = GetParam();
  Mesh m = makeMesh(format == "ply-be-double");
  std::string in = tmp.file("in." + format.substr(0, 3));
  writeFormat(m, format, in);
  auto assigner = makeGridAssigner(300);
  IngestOptions o;
  o.progress = false;
  IngestReport r = PatchStore::ingest(in, tmp.file("store"), *assigner, o);
  EXPECT_EQ(r.inputTriangles, m.t.size() / 3);
  auto store = PatchStore::open(tmp.file("store"));
  EXPECT_TRUE(store->check().ok);
  EXPECT_GT(store->patchIds().size(), 3u);
  store->exportPly(tmp.file("out.ply"));
  uint64_t exportedVertices = 0;
  std::vector<Triangle> expected = read(in), actual = read(tmp.file("out.ply"), &exportedVertices);
  EXPECT_TRUE(expected == actual) << format << ": " << expected.size() << " vs " << actual.size() << " triangles";
  // Soups are welded: the store has the indexed mesh's vertex count, not three per triangle.
  // The 6 vertices inside the hole are referenced by no triangle and dropped.
  std::vector<uint32_t> used = m.t;
  std::sort(used.begin(), used.end());
  used.erase(std::unique(used.begin(), used.end()), used.end());
  EXPECT_EQ(exportedVertices, used.size()) << format;
  if (format.rfind("stl", 0) == 0) {
    EXPECT_EQ(r.weldedVertices, m.t.size() - used.size());
    EXPECT_EQ(r.unreferencedVertices, 0u);
  } else {
    EXPECT_EQ(r.unreferencedVertices, m.p.size() / 3 - used.size());
  }
  // Decimal text is kept as double (it may carry more than float32); binary float stays float.
  EXPECT_EQ(store->layout().doublePrecision, format != "stl-binary") << format;
  EXPECT_EQ(store->layout().normals, format == "ply-ascii");
  EXPECT_EQ(store->layout().colors, format == "ply-ascii");
}

INSTANTIATE_TEST_SUITE_P(AllFormats, FormatRoundTrip,
                         ::testing::Values("ply-ascii", "ply-be-double", "obj", "off", "stl-ascii", "stl-binary"),
                         [](const auto& info) {
                           std::string n = info.param;
                           std::replace(n.begin(), n.end(), '-', '_');
                           return n;
                         });

}  // namespace
}  // namespace mt
