// Streaming mesh readers: exact data delivered for every format and variant, format detection,
// batching bounds, and the one-line error messages for broken input.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "patchstore/io/ply_writer.h"
#include "patchstore/io/mesh_reader.h"
#include "tests/test_support.h"

using ::testing::HasSubstr;
using mt::test::TempDir;
using mt::test::writeFile;

namespace {

// Collects everything and checks the sink-side guarantees of the contract as data arrives.
struct Collect : mt::MeshSink {
  mt::MeshHeader header;
  std::vector<mt::InputVertex> v;
  std::vector<uint32_t> t;
  mt::ReadStats stats;
  size_t maxVertexBatch = 0, maxTriangleBatch = 0, vertexCalls = 0, triangleCalls = 0;
  bool begun = false, ended = false;

  void begin(const mt::MeshHeader& h) override {
    header = h;
    begun = true;
  }
  void vertices(const mt::InputVertex* p, size_t n, uint64_t first) override {
    EXPECT_EQ(first, v.size());
    v.insert(v.end(), p, p + n);
    maxVertexBatch = std::max(maxVertexBatch, n);
    ++vertexCalls;
  }
  void triangles(const uint32_t* p, size_t n) override {
    for (size_t i = 0; i < n * 3; ++i) EXPECT_LT(p[i], v.size()) << "index before its vertex";
    t.insert(t.end(), p, p + n * 3);
    maxTriangleBatch = std::max(maxTriangleBatch, n);
    ++triangleCalls;
  }
  void end(const mt::ReadStats& s) override {
    stats = s;
    ended = true;
  }
  std::vector<uint32_t> tri(size_t i) const { return {t[i * 3], t[i * 3 + 1], t[i * 3 + 2]}; }
};

Collect readMesh(const std::string& path) {
  Collect c;
  auto reader = mt::openMesh(path);
  mt::ReadStats s = reader->read(c);
  EXPECT_TRUE(c.begun);
  EXPECT_TRUE(c.ended);
  EXPECT_EQ(s.vertices, c.v.size());
  EXPECT_EQ(s.triangles * 3, c.t.size());
  EXPECT_EQ(c.header.format, reader->header().format);
  return c;
}

// The message of the mt::Error that opening or reading `path` throws ("" if none).
std::string errorOf(const std::string& path) {
  try {
    Collect c;
    mt::openMesh(path)->read(c);
  } catch (const mt::Error& e) {
    std::string m = e.what();
    EXPECT_EQ(m.find('\n'), std::string::npos) << "multi-line message: " << m;
    EXPECT_EQ(m.rfind(path + ": ", 0), 0u) << "message does not start with the path: " << m;
    return m;
  }
  ADD_FAILURE() << path << " did not fail";
  return "";
}

void expectPos(const mt::InputVertex& v, double x, double y, double z) {
  EXPECT_EQ(v.p[0], x);
  EXPECT_EQ(v.p[1], y);
  EXPECT_EQ(v.p[2], z);
}

// Binary payload builder, in either byte order.
struct Bytes {
  std::string s;
  bool bigEndian = false;
  template <class T>
  Bytes& put(T value) {
    char b[sizeof(T)];
    std::memcpy(b, &value, sizeof value);
    if (bigEndian) std::reverse(b, b + sizeof value);
    s.append(b, sizeof value);
    return *this;
  }
  // A value stored as the named PLY type.
  Bytes& as(const std::string& type, double x) {
    if (type == "char" || type == "int8") return put(int8_t(x));
    if (type == "uchar" || type == "uint8") return put(uint8_t(x));
    if (type == "short" || type == "int16") return put(int16_t(x));
    if (type == "ushort" || type == "uint16") return put(uint16_t(x));
    if (type == "int" || type == "int32") return put(int32_t(x));
    if (type == "uint" || type == "uint32") return put(uint32_t(x));
    if (type == "float" || type == "float32") return put(float(x));
    if (type == "double" || type == "float64") return put(double(x));
    ADD_FAILURE() << "bad type " << type;
    return *this;
  }
};

std::string plyHeader(const std::string& format, const std::string& body) {
  return "ply\nformat " + format + " 1.0\ncomment test\n" + body + "end_header\n";
}

const double kTetra[4][3] = {{0, 0, 0}, {1, 0, 0}, {0, 2, 0}, {0, 0, 3}};
const uint32_t kTetraFaces[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};

void expectTetra(const Collect& c) {
  ASSERT_EQ(c.v.size(), 4u);
  ASSERT_EQ(c.t.size(), 12u);
  for (int i = 0; i < 4; ++i) expectPos(c.v[i], kTetra[i][0], kTetra[i][1], kTetra[i][2]);
  for (int i = 0; i < 4; ++i)
    EXPECT_EQ(c.tri(i), std::vector<uint32_t>(kTetraFaces[i], kTetraFaces[i] + 3));
}

// A binary tetrahedron with the given coordinate, list count and index types.
std::string binaryTetra(bool bigEndian, const std::string& coord, const std::string& count,
                        const std::string& index) {
  Bytes b;
  b.bigEndian = bigEndian;
  b.s = plyHeader(bigEndian ? "binary_big_endian" : "binary_little_endian",
                  "element vertex 4\nproperty " + coord + " x\nproperty " + coord + " y\nproperty " +
                      coord + " z\nelement face 4\nproperty list " + count + " " + index +
                      " vertex_indices\n");
  for (auto& p : kTetra) b.as(coord, p[0]).as(coord, p[1]).as(coord, p[2]);
  for (auto& f : kTetraFaces) b.as(count, 3).as(index, f[0]).as(index, f[1]).as(index, f[2]);
  return b.s;
}

// ---------------------------------------------------------------- PLY

TEST(PlyReader, EveryScalarTypeForCoordinates) {
  TempDir dir;
  const char* types[] = {"char",  "uchar",  "short",  "ushort",  "int",    "uint",
                         "float", "double", "int8",   "uint8",   "int16",  "uint16",
                         "int32", "uint32", "float32", "float64"};
  for (const char* type : types) {
    for (bool be : {false, true}) {
      SCOPED_TRACE(std::string(type) + (be ? " big endian" : " little endian"));
      std::string path = dir.file(std::string(type) + (be ? "_be" : "_le") + ".ply");
      writeFile(path, binaryTetra(be, type, "uchar", "int"));
      Collect c = readMesh(path);
      expectTetra(c);
      EXPECT_EQ(c.header.format, be ? mt::MeshFormat::PlyBinaryBE : mt::MeshFormat::PlyBinaryLE);
      std::string t = type;
      bool wide = t == "double" || t == "float64" || t == "int" || t == "int32" || t == "uint" || t == "uint32";
      EXPECT_EQ(c.header.doublePrecision, wide);
      EXPECT_EQ(c.header.declaredVertices, 4);
      EXPECT_EQ(c.header.declaredFaces, 4);
      EXPECT_FALSE(c.header.hasNormals);
      EXPECT_FALSE(c.header.hasColors);
      EXPECT_EQ(c.v[1].c[0], 255);
      EXPECT_EQ(c.stats.bytes, mt::test::readFile(path).size());
    }
  }
}

TEST(PlyReader, DoubleCoordinatesKeepFullPrecision) {
  TempDir dir;
  Bytes b;
  b.bigEndian = true;
  b.s = plyHeader("binary_big_endian",
                  "element vertex 3\nproperty double x\nproperty double y\nproperty double z\n"
                  "element face 1\nproperty list uchar int vertex_indices\n");
  b.put(0.1).put(1e-300).put(123456789.123456789).put(1.0).put(0.0).put(0.0).put(0.0).put(1.0).put(0.0);
  b.put(uint8_t(3)).put(int32_t(0)).put(int32_t(1)).put(int32_t(2));
  writeFile(dir.file("d.ply"), b.s);
  Collect c = readMesh(dir.file("d.ply"));
  EXPECT_TRUE(c.header.doublePrecision);
  expectPos(c.v[0], 0.1, 1e-300, 123456789.123456789);
}

TEST(PlyReader, EveryListCountAndIndexType) {
  TempDir dir;
  for (const char* count : {"uchar", "char", "ushort", "short", "int", "uint", "uint8", "int32"})
    for (const char* index : {"int", "uint", "short", "ushort", "uchar", "int32", "uint32"})
      for (bool be : {false, true}) {
        SCOPED_TRACE(std::string(count) + " " + index + (be ? " BE" : " LE"));
        std::string path = dir.file("l.ply");
        writeFile(path, binaryTetra(be, "float", count, index));
        expectTetra(readMesh(path));
      }
}

TEST(PlyReader, VertexIndexNameAndExtraPropertiesAndElementsSkipped) {
  TempDir dir;
  Bytes b;
  b.s = plyHeader("binary_little_endian",
                  "element material 2\nproperty uchar ambient\nproperty list uchar float coeffs\n"
                  "element vertex 4\nproperty uchar flags\nproperty float x\nproperty list uint short junk\n"
                  "property float y\nproperty double confidence\nproperty float z\n"
                  "element face 4\nproperty int tag\nproperty list uchar uint vertex_index\n"
                  "property list uchar float texcoord\nproperty uchar flags\n"
                  "element edge 1\nproperty int vertex1\nproperty int vertex2\n");
  b.put(uint8_t(7)).put(uint8_t(2)).put(1.5f).put(2.5f);
  b.put(uint8_t(8)).put(uint8_t(0));
  for (auto& p : kTetra) {
    b.put(uint8_t(1)).put(float(p[0])).put(uint32_t(2)).put(int16_t(5)).put(int16_t(6));
    b.put(float(p[1])).put(0.75).put(float(p[2]));
  }
  for (auto& f : kTetraFaces) {
    b.put(int32_t(-9)).put(uint8_t(3)).put(f[0]).put(f[1]).put(f[2]);
    b.put(uint8_t(2)).put(0.5f).put(0.25f).put(uint8_t(4));
  }
  b.put(int32_t(0)).put(int32_t(1));
  writeFile(dir.file("x.ply"), b.s);
  expectTetra(readMesh(dir.file("x.ply")));
}

TEST(PlyReader, NormalsAndColorsKept) {
  TempDir dir;
  Bytes b;
  b.s = plyHeader("binary_little_endian",
                  "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                  "property float nx\nproperty float ny\nproperty float nz\n"
                  "property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n"
                  "element face 1\nproperty list uchar int vertex_indices\n");
  for (int i = 0; i < 3; ++i)
    b.put(float(i)).put(0.f).put(0.f).put(0.f).put(0.f).put(1.f).put(uint8_t(10 * i)).put(uint8_t(20)).put(uint8_t(30)).put(uint8_t(40));
  b.put(uint8_t(3)).put(0).put(1).put(2);
  writeFile(dir.file("nc.ply"), b.s);
  Collect c = readMesh(dir.file("nc.ply"));
  EXPECT_TRUE(c.header.hasNormals);
  EXPECT_TRUE(c.header.hasColors);
  EXPECT_EQ(c.v[2].n[2], 1.f);
  EXPECT_EQ(c.v[2].c[0], 20);
  EXPECT_EQ(c.v[2].c[1], 20);
  EXPECT_EQ(c.v[2].c[2], 30);
  EXPECT_EQ(c.v[2].c[3], 40);
  expectPos(c.v[2], 2, 0, 0);
}

TEST(PlyReader, FloatColorsScaledAndAlphaOptional) {
  TempDir dir;
  std::string text = plyHeader("ascii",
                               "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                               "property float red\nproperty float green\nproperty float blue\n"
                               "element face 1\nproperty list uchar int vertex_indices\n") +
                     "0 0 0 1 0.5 0\n1 0 0 0 0 0\n0 1 0 1.001 -0.001 0.2\n3 0 1 2\n";
  writeFile(dir.file("fc.ply"), text);
  Collect c = readMesh(dir.file("fc.ply"));
  EXPECT_TRUE(c.header.hasColors);
  EXPECT_FALSE(c.header.hasNormals);
  EXPECT_EQ(c.v[0].c[0], 255);
  EXPECT_EQ(c.v[0].c[1], 128);
  EXPECT_EQ(c.v[0].c[2], 0);
  EXPECT_EQ(c.v[0].c[3], 255);
  EXPECT_EQ(c.v[2].c[0], 255);  // within half a level of 0..1: writers' rounding, clamped
  EXPECT_EQ(c.v[2].c[1], 0);
  EXPECT_EQ(c.v[2].c[2], 51);
}

// Every colour syntax of PLY: uchar and float channels, with and without alpha, in both binary
// byte orders (the fixed-record and the fast float-xyz paths) and ascii; 16-bit channels scaled.
TEST(PlyReader, ColourSyntaxes) {
  TempDir dir;
  const std::string faces = "element face 1\nproperty list uchar int vertex_indices\n";
  for (const char* type : {"uchar", "float", "double", "ushort"})
    for (bool alpha : {false, true})
      for (const char* format : {"binary_little_endian", "binary_big_endian", "ascii"}) {
        SCOPED_TRACE(std::string(type) + (alpha ? " rgba " : " rgb ") + format);
        std::string props = "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n";
        for (const char* ch : {"red", "green", "blue", "alpha"})
          if (alpha || std::string(ch) != "alpha") props += std::string("property ") + type + " " + ch + "\n";
        const double scale = std::string(type) == "uchar" ? 255 : std::string(type) == "ushort" ? 65535 : 1;
        // channel values in 8-bit levels: vertex v, channel k
        auto level = [](int v, int k) { return (v * 97 + k * 61 + 13) % 256; };
        const bool ascii = std::string(format) == "ascii";
        Bytes b;
        b.bigEndian = std::string(format) == "binary_big_endian";
        b.s = plyHeader(format, props + faces);
        std::string text = b.s;
        for (int v = 0; v < 3; ++v) {
          const float p[3] = {float(v == 1), float(v == 2), 0};
          for (float x : p) ascii ? void(text += std::to_string(x) + " ") : void(b.put(x));
          for (int k = 0; k < (alpha ? 4 : 3); ++k) {
            const double x = scale == 1 ? level(v, k) / 255.0 : scale == 65535 ? level(v, k) * 257.0 : level(v, k);
            if (ascii) {
              char num[32];
              std::snprintf(num, sizeof num, "%.17g ", x);
              text += num;
            } else {
              b.as(type, x);
            }
          }
          if (ascii) text += "\n";
        }
        if (ascii) text += "3 0 1 2\n";
        else b.put(uint8_t(3)).put(int32_t(0)).put(int32_t(1)).put(int32_t(2));
        writeFile(dir.file("c.ply"), ascii ? text : b.s);
        Collect c = readMesh(dir.file("c.ply"));
        ASSERT_TRUE(c.header.hasColors);
        for (int v = 0; v < 3; ++v)
          for (int k = 0; k < 4; ++k) EXPECT_EQ(c.v[v].c[k], k < 3 || alpha ? level(v, k) : 255) << v << " " << k;
      }
}

// A colour value no channel type allows is refused, naming the vertex, the property and where.
TEST(PlyReader, BadColourValuesRefused) {
  TempDir dir;
  const std::string head = "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n";
  const std::string faces = "element face 1\nproperty list uchar int vertex_indices\n";
  // floats written as 0..255
  writeFile(dir.file("a.ply"), plyHeader("ascii", head + "property float red\nproperty float green\nproperty float blue\n" + faces) +
                                   "0 0 0 0 0 0\n1 0 0 0.5 0.5 0.5\n0 1 0 200 30 40\n3 0 1 2\n");
  std::string m = errorOf(dir.file("a.ply"));
  EXPECT_THAT(m, HasSubstr("vertex 2 property red: colour value 200 out of range (float channels are 0..1)"));
  EXPECT_THAT(m, HasSubstr("(line 16)"));
  // NaN in a binary float channel (the fast path): the byte offset of the record
  Bytes b;
  b.s = plyHeader("binary_little_endian", head + "property float red\nproperty float green\nproperty float blue\n" + faces);
  const size_t data = b.s.size();
  for (int v = 0; v < 3; ++v) b.put(float(v)).put(0.f).put(0.f).put(0.5f).put(v == 1 ? std::nanf("") : 0.5f).put(0.5f);
  b.put(uint8_t(3)).put(int32_t(0)).put(int32_t(1)).put(int32_t(2));
  writeFile(dir.file("n.ply"), b.s);
  m = errorOf(dir.file("n.ply"));
  EXPECT_THAT(m, HasSubstr("vertex 1 property green: colour value nan out of range"));
  EXPECT_THAT(m, HasSubstr("byte offset " + std::to_string(data + 24)));
  // a negative integer channel
  writeFile(dir.file("s.ply"), plyHeader("ascii", head + "property short red\nproperty short green\nproperty short blue\n" + faces) +
                                   "0 0 0 0 0 0\n1 0 0 5 -3 0\n0 1 0 0 0 0\n3 0 1 2\n");
  EXPECT_THAT(errorOf(dir.file("s.ply")), HasSubstr("vertex 1 property green: colour value -3 out of range (16-bit channels are 0..65535)"));
  // 8-bit values in an int channel above 255
  writeFile(dir.file("i.ply"), plyHeader("ascii", head + "property int red\nproperty int green\nproperty int blue\n" + faces) +
                                   "0 0 0 0 0 0\n1 0 0 5 3 0\n0 1 0 0 0 256\n3 0 1 2\n");
  EXPECT_THAT(errorOf(dir.file("i.ply")), HasSubstr("vertex 2 property blue: colour value 256 out of range (8-bit channels are 0..255)"));
}

TEST(PlyReader, PolygonsFanTriangulatedInBothPaths) {
  TempDir dir;
  // Triangle, quad, pentagon and a degenerate triangle, mixed, so the fast path hands polygons
  // to the generic path and picks up again.
  for (bool be : {false, true}) {
    Bytes b;
    b.bigEndian = be;
    b.s = plyHeader(be ? "binary_big_endian" : "binary_little_endian",
                    "element vertex 5\nproperty float x\nproperty float y\nproperty float z\n"
                    "element face 4\nproperty list uchar int vertex_indices\n");
    for (int i = 0; i < 5; ++i) b.put(float(i)).put(float(i * i)).put(0.f);
    b.put(uint8_t(3)).put(0).put(1).put(2);
    b.put(uint8_t(4)).put(0).put(1).put(2).put(3);
    b.put(uint8_t(5)).put(4).put(3).put(2).put(1).put(0);
    b.put(uint8_t(3)).put(1).put(1).put(2);
    writeFile(dir.file("poly.ply"), b.s);
    Collect c = readMesh(dir.file("poly.ply"));
    std::vector<uint32_t> expected = {0, 1, 2, 0, 1, 2, 0, 2, 3, 4, 3, 2, 4, 2, 1, 4, 1, 0, 1, 1, 2};
    EXPECT_EQ(c.t, expected);
    EXPECT_EQ(c.stats.triangles, 7u);
    EXPECT_EQ(c.stats.polygons, 2u);
    EXPECT_EQ(c.stats.degenerateTriangles, 1u);
  }
}

// A 3 x 2 grid of quads as triangle strips: two strips separated by the end marker, the second
// with a degenerate join (a repeated index) in the middle, then a strip of two indices (nothing).
// Triangle k of a strip is (v[k], v[k+1], v[k+2]), its first two corners swapped when k is odd.
TEST(PlyReader, TriangleStripsUnrolledKeepingTheirOrientation) {
  TempDir dir;
  const std::vector<int64_t> strips = {0, 4, 1, 5, 2, 6, 3, 7, -1, 4, 8, 5, 9, 9, 6, 6, 10, 7, 11, -1, 1, 2};
  // Strip one: (0,4,1) (1,4,5) (1,5,2) (2,5,6) (2,6,3) (3,6,7). Strip two: (4,8,5) (5,8,9), then
  // the joins (5,9,9) (9,9,6) (9,6,6) (6,6,10) dropped, (6,10,7) at k = 6 (even), (7,10,11) at k = 7.
  const std::vector<uint32_t> expected = {0, 4, 1, 1, 4, 5, 1, 5, 2, 2, 5, 6, 2, 6, 3, 3, 6, 7,
                                          4, 8, 5, 5, 8, 9, 6, 10, 7, 7, 10, 11};
  struct Variant {
    std::string format, count, index;
  };
  for (const Variant& v : {Variant{"binary_little_endian", "int", "int"}, Variant{"binary_big_endian", "int", "int"},
                           Variant{"binary_little_endian", "uchar", "uint"}, Variant{"binary_big_endian", "ushort", "ushort"},
                           Variant{"ascii", "int", "int"}}) {
    SCOPED_TRACE(v.format + " " + v.count + " " + v.index);
    const bool ascii = v.format == "ascii";
    Bytes b;
    b.bigEndian = v.format == "binary_big_endian";
    // An extra scalar before the list and an extra list after it, read and dropped.
    b.s = plyHeader(v.format, "element vertex 12\nproperty float x\nproperty float y\nproperty float z\n"
                              "element tristrips 1\nproperty uchar flags\nproperty list " + v.count + " " + v.index +
                                  " vertex_indices\nproperty list uchar float weights\n");
    std::string text;
    for (int i = 0; i < 12; ++i) {
      if (ascii) text += std::to_string(i % 4) + " " + std::to_string(i / 4) + " 0\n";
      else b.put(float(i % 4)).put(float(i / 4)).put(0.f);
    }
    // The end marker: -1, or the largest value of an unsigned index type.
    const double end = v.index == "uint" ? 4294967295.0 : v.index == "ushort" ? 65535.0 : -1.0;
    if (ascii) {
      text += "3 " + std::to_string(strips.size());
      for (int64_t x : strips) text += " " + std::to_string(x);
      text += " 1 0.5\n";
      b.s += text;
    } else {
      b.put(uint8_t(3)).as(v.count, double(strips.size()));
      for (int64_t x : strips) b.as(v.index, x < 0 ? end : double(x));
      b.put(uint8_t(1)).put(0.5f);
    }
    writeFile(dir.file("s.ply"), b.s);
    Collect c = readMesh(dir.file("s.ply"));
    EXPECT_EQ(c.t, expected);
    EXPECT_EQ(c.v.size(), 12u);
    EXPECT_EQ(c.stats.triangles, 10u);
    EXPECT_EQ(c.stats.degenerateTriangles, 0u);  // the joins are not delivered
    EXPECT_EQ(c.header.declaredFaces, -1);        // a strip's triangle count is not declared
  }
  // A join of three degenerate triangles after a strip of odd length: the parity is the position
  // in the strip, not the count of triangles delivered (which would swap (6,10,7)).
  {
    std::string text = plyHeader("ascii", "element vertex 12\nproperty float x\nproperty float y\nproperty float z\n"
                                          "element tristrips 1\nproperty list int uint vertex_indices\n");
    for (int i = 0; i < 12; ++i) text += std::to_string(i % 4) + " " + std::to_string(i / 4) + " 0\n";
    text += "13 0 4 1 5 2 2 2 6 6 10 7 11 -1\n";  // ascii -1 ends a strip of an unsigned type too
    writeFile(dir.file("odd.ply"), text);
    Collect c = readMesh(dir.file("odd.ply"));
    EXPECT_EQ(c.t, (std::vector<uint32_t>{0, 4, 1, 1, 4, 5, 1, 5, 2, 6, 10, 7, 7, 10, 11}));
  }
  // Faces and strips in one file: both are read, in the file's order.
  std::string body = "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                     "element face 1\nproperty list uchar int vertex_indices\n"
                     "element tristrips 1\nproperty list int int vertex_indices\n";
  writeFile(dir.file("fs.ply"), plyHeader("ascii", body) + "0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n4 1 3 2 0\n");
  Collect c = readMesh(dir.file("fs.ply"));
  EXPECT_EQ(c.t, (std::vector<uint32_t>{0, 1, 2, 1, 3, 2, 2, 3, 0}));
}

TEST(PlyReader, AsciiFloatAndDoubleAndRecordsAcrossLines) {
  TempDir dir;
  std::string body = "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
                     "property list uchar int extra\n"
                     "element face 2\nproperty list uchar int vertex_indices\nproperty uchar flag\n";
  std::string data = "0.1 0 0 0\n1 0 0 2 7 8\n0 1\n 0 0 \r\n1 1 1e0 1 5\n\n4 0 1 3 2 9 3 0 1 3 1\n";
  writeFile(dir.file("a.ply"), plyHeader("ascii", body) + data);
  Collect c = readMesh(dir.file("a.ply"));
  EXPECT_EQ(c.header.format, mt::MeshFormat::PlyAscii);
  // Decimal text is parsed to double whatever type it declares: "float" at survey coordinates
  // would lose the centimetres.
  EXPECT_TRUE(c.header.doublePrecision);
  EXPECT_EQ(c.v[0].p[0], 0.1);
  expectPos(c.v[3], 1, 1, 1);
  EXPECT_EQ(c.t, (std::vector<uint32_t>{0, 1, 3, 0, 3, 2, 0, 1, 3}));
  EXPECT_EQ(c.stats.polygons, 1u);

  std::string dbody = "element vertex 3\nproperty double x\nproperty double y\nproperty double z\n"
                      "element face 1\nproperty list uchar int vertex_indices\n";
  writeFile(dir.file("d.ply"), plyHeader("ascii", dbody) + "0.1 0.2 0.3\n1 0 0\n0 1 0\n3 0 1 2\n");
  Collect d = readMesh(dir.file("d.ply"));
  EXPECT_TRUE(d.header.doublePrecision);
  expectPos(d.v[0], 0.1, 0.2, 0.3);
}

TEST(PlyReader, CrlfHeader) {
  TempDir dir;
  std::string text =
      "ply\r\nformat ascii 1.0\r\nelement vertex 3\r\nproperty float x\r\nproperty float y\r\n"
      "property float z\r\nelement face 1\r\nproperty list uchar int vertex_indices\r\nend_header\r\n"
      "0 0 0\r\n1 0 0\r\n0 1 0\r\n3 0 1 2\r\n";
  writeFile(dir.file("crlf.ply"), text);
  Collect c = readMesh(dir.file("crlf.ply"));
  EXPECT_EQ(c.t, (std::vector<uint32_t>{0, 1, 2}));
}

TEST(PlyReader, LargeFileStreamsInBoundedBatches) {
  TempDir dir;
  const uint32_t side = 708;  // 708^2 vertices, 2*707^2 = 999,698 triangles
  std::string path = dir.file("big.ply");
  {
    mt::PlyWriter w(path, mt::PlyWriteOptions{});
    for (uint32_t y = 0; y < side; ++y)
      for (uint32_t x = 0; x < side; ++x) {
        double p[3] = {double(x), double(y), double((x * 7 + y * 3) % 11)};
        w.addVertex(p);
      }
    for (uint32_t y = 0; y + 1 < side; ++y)
      for (uint32_t x = 0; x + 1 < side; ++x) {
        uint32_t i = y * side + x;
        w.addTriangle(i, i + 1, i + side);
        w.addTriangle(i + 1, i + side + 1, i + side);
      }
    w.finish();
  }
  Collect c = readMesh(path);
  ASSERT_EQ(c.v.size(), size_t(side) * side);
  ASSERT_EQ(c.t.size(), size_t(2) * (side - 1) * (side - 1) * 3);
  EXPECT_EQ(c.stats.degenerateTriangles, 0u);
  EXPECT_EQ(c.stats.bytes, mt::test::readFile(path).size());
  expectPos(c.v[side * 5 + 9], 9, 5, double((9 * 7 + 5 * 3) % 11));
  size_t last = c.t.size() / 3 - 1;
  uint32_t i = (side - 2) * side + side - 2;
  EXPECT_EQ(c.tri(last), (std::vector<uint32_t>{i + 1, i + side + 1, i + side}));
  // Bounded batches: many calls, none bigger than the reader's 64K batch.
  EXPECT_LE(c.maxVertexBatch, size_t(1) << 16);
  EXPECT_LE(c.maxTriangleBatch, size_t(1) << 16);
  EXPECT_GE(c.triangleCalls, c.t.size() / 3 / (size_t(1) << 16));
  EXPECT_GT(c.vertexCalls, 1u);
}

// ---------------------------------------------------------------- OBJ

TEST(ObjReader, AllFaceFormsNegativeIndicesPolygonsCrlf) {
  TempDir dir;
  std::string text =
      "# comment\r\nmtllib a.mtl\r\no thing\r\nv 0 0 0\r\nv 1 0 0 1.0\r\nv 1 1 0\r\n\r\nv 0 1 0\r\n"
      "vt 0 0\r\nvn 0 0 1\r\ng group\r\ns 1\r\nusemtl m\r\n"
      "f 1 2 3\r\nf 1/1 3/1 4/1\r\nf 1//1 2//1 3//1\r\nf 1/1/1 2/1/1 4/1/1\r\n"
      "f -4 -3 -2 -1\r\n  f\t1 2 3 4 3\r\nl 1 2\r\np 1\r\nv 5 5 5\r\nf -1 1 2\r\n";
  writeFile(dir.file("m.obj"), text);
  Collect c = readMesh(dir.file("m.obj"));
  EXPECT_EQ(c.header.format, mt::MeshFormat::Obj);
  EXPECT_EQ(c.header.declaredVertices, -1);
  EXPECT_FALSE(c.header.hasNormals);
  EXPECT_FALSE(c.header.hasColors);
  ASSERT_EQ(c.v.size(), 5u);
  expectPos(c.v[1], 1, 0, 0);
  expectPos(c.v[4], 5, 5, 5);
  std::vector<uint32_t> expected = {0, 1, 2, 0, 2, 3, 0, 1, 2, 0, 1, 3, 0, 1, 2, 0, 2, 3,
                                    0, 1, 2, 0, 2, 3, 0, 3, 2, 4, 0, 1};
  EXPECT_EQ(c.t, expected);
  EXPECT_EQ(c.stats.polygons, 2u);
  EXPECT_EQ(c.stats.degenerateTriangles, 0u);
}

TEST(ObjReader, VertexColors) {
  TempDir dir;
  writeFile(dir.file("c.obj"), "v 0 0 0 1 0 0.5\nv 1 0 0 0 1 0\nv 0 1 0\nf 1 2 3\n");
  Collect c = readMesh(dir.file("c.obj"));
  EXPECT_TRUE(c.header.hasColors);
  EXPECT_EQ(c.v[0].c[0], 255);
  EXPECT_EQ(c.v[0].c[1], 0);
  EXPECT_EQ(c.v[0].c[2], 128);
  EXPECT_EQ(c.v[1].c[1], 255);
  EXPECT_EQ(c.v[2].c[0], 255);  // no colour given: white
  EXPECT_EQ(c.v[0].p[0], 0);
}

TEST(ObjReader, BadVertexColoursRefused) {
  TempDir dir;
  // 0..255 colours: OBJ's extension is 0..1
  writeFile(dir.file("b.obj"), "v 0 0 0 1 0 0.5\nv 1 0 0 0 255 0\nv 0 1 0 0 0 0\nf 1 2 3\n");
  EXPECT_THAT(errorOf(dir.file("b.obj")),
              HasSubstr("vertex 1 green: colour value 255 out of range (float channels are 0..1) (line 2)"));
  // a colour after a first vertex without one would be dropped silently
  writeFile(dir.file("l.obj"), "v 0 0 0\nv 1 0 0 0 1 0\nv 0 1 0\nf 1 2 3\n");
  EXPECT_THAT(errorOf(dir.file("l.obj")), HasSubstr("vertex 1 has a colour but the file's first vertex has none"));
  writeFile(dir.file("n.obj"), "v 0 0 0 0.5 nan 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  EXPECT_THAT(errorOf(dir.file("n.obj")), HasSubstr("vertex 0 green: colour value nan out of range"));
}

// ---------------------------------------------------------------- OFF

TEST(OffReader, PlainWithCommentsAndPolygons) {
  TempDir dir;
  writeFile(dir.file("m.off"),
            "OFF\n# a comment\n5 3 0\n\n0 0 0\n1 0 0 # trailing\n1 1 0\n0 1 0\n0.5 0.5 1\n"
            "3 0 1 4\n4 0 1 2 3 255 0 0\n3 2 2 4\n");
  Collect c = readMesh(dir.file("m.off"));
  EXPECT_EQ(c.header.format, mt::MeshFormat::Off);
  EXPECT_EQ(c.header.declaredVertices, 5);
  EXPECT_EQ(c.header.declaredFaces, 3);
  EXPECT_FALSE(c.header.hasColors);
  expectPos(c.v[4], 0.5, 0.5, 1);
  EXPECT_EQ(c.t, (std::vector<uint32_t>{0, 1, 4, 0, 1, 2, 0, 2, 3, 2, 2, 4}));
  EXPECT_EQ(c.stats.polygons, 1u);
  EXPECT_EQ(c.stats.degenerateTriangles, 1u);
}

TEST(OffReader, ColorAndNormalVariants) {
  TempDir dir;
  writeFile(dir.file("c.off"), "COFF 3 1 0\n0 0 0 255 0 0 255\n1 0 0 0 128 0 255\n0 1 0 0 0 255 10\n3 0 1 2\n");
  Collect c = readMesh(dir.file("c.off"));
  EXPECT_TRUE(c.header.hasColors);
  EXPECT_EQ(c.v[1].c[1], 128);
  EXPECT_EQ(c.v[2].c[3], 10);

  writeFile(dir.file("n.off"), "NOFF\n3 1\n0 0 0 0 0 1\n1 0 0 0 1 0\n0 1 0 1 0 0\n3 0 1 2\n");
  Collect n = readMesh(dir.file("n.off"));
  EXPECT_TRUE(n.header.hasNormals);
  EXPECT_EQ(n.v[0].n[2], 1.f);
  EXPECT_EQ(n.v[1].n[1], 1.f);

  writeFile(dir.file("cn.off"), "CNOFF\n3 1 0\n0 0 0 0 0 1 1.0 0.5 0\n1 0 0 0 1 0 0 0 1\n0 1 0 1 0 0 0 0 0\n3 0 1 2\n");
  Collect cn = readMesh(dir.file("cn.off"));
  EXPECT_TRUE(cn.header.hasNormals && cn.header.hasColors);
  EXPECT_EQ(cn.v[0].c[0], 255);
  EXPECT_EQ(cn.v[0].c[1], 128);
  EXPECT_EQ(cn.v[1].c[2], 1);  // integers are 0..255
  EXPECT_EQ(cn.v[0].n[2], 1.f);
}

TEST(OffReader, BadColoursRefused) {
  TempDir dir;
  writeFile(dir.file("i.off"), "COFF 3 1 0\n0 0 0 255 0 0\n1 0 0 0 300 0\n0 1 0 0 0 255\n3 0 1 2\n");
  EXPECT_THAT(errorOf(dir.file("i.off")),
              HasSubstr("vertex 1 colour channel 1: colour value 300 out of range (8-bit channels are 0..255) (line 3)"));
  writeFile(dir.file("f.off"), "COFF 3 1 0\n0 0 0 1.0 0 0\n1 0 0 0 0.5 0\n0 1 0 0 0 -2.5\n3 0 1 2\n");
  EXPECT_THAT(errorOf(dir.file("f.off")),
              HasSubstr("vertex 2 colour channel 2: colour value -2.5 out of range (float channels are 0..1) (line 4)"));
}

// ---------------------------------------------------------------- STL

std::string binaryStl(const std::string& header80, const std::vector<std::array<float, 9>>& tris) {
  Bytes b;
  b.s = header80;
  b.s.resize(80, ' ');
  b.put(uint32_t(tris.size()));
  for (const auto& t : tris) {
    b.put(0.f).put(0.f).put(1.f);
    for (float f : t) b.put(f);
    b.put(uint16_t(0));
  }
  return b.s;
}

TEST(StlReader, AsciiSoup) {
  TempDir dir;
  writeFile(dir.file("a.stl"),
            "solid thing\n  facet normal 0 0 1\n    outer loop\n      vertex 0 0 0\n      vertex 1 0 0\n"
            "      vertex 0 1 0\n    endloop\n  endfacet\n  facet normal 0 0 1\n  outer loop\n"
            "vertex 1 0 0\nvertex 1 1 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid thing\n");
  Collect c = readMesh(dir.file("a.stl"));
  EXPECT_EQ(c.header.format, mt::MeshFormat::StlAscii);
  ASSERT_EQ(c.v.size(), 6u);
  expectPos(c.v[3], 1, 0, 0);
  expectPos(c.v[4], 1, 1, 0);
  EXPECT_EQ(c.t, (std::vector<uint32_t>{0, 1, 2, 3, 4, 5}));
}

TEST(StlReader, BinaryEvenWhenHeaderSaysSolid) {
  TempDir dir;
  std::vector<std::array<float, 9>> tris = {{0, 0, 0, 1, 0, 0, 0, 1, 0}, {1, 0, 0, 1, 1, 0, 0, 1, 0.5f}};
  for (const char* head : {"binary exporter", "solid fooled you"}) {
    SCOPED_TRACE(head);
    writeFile(dir.file("b.stl"), binaryStl(head, tris));
    Collect c = readMesh(dir.file("b.stl"));
    EXPECT_EQ(c.header.format, mt::MeshFormat::StlBinary);
    EXPECT_EQ(c.header.declaredFaces, 2);
    ASSERT_EQ(c.v.size(), 6u);
    expectPos(c.v[5], 0, 1, 0.5);
    EXPECT_EQ(c.t, (std::vector<uint32_t>{0, 1, 2, 3, 4, 5}));
    EXPECT_EQ(c.stats.bytes, 84u + 100u);
  }
}

TEST(StlReader, BinaryAcrossBatches) {
  TempDir dir;
  std::vector<std::array<float, 9>> tris;
  for (int i = 0; i < 70000; ++i) tris.push_back({float(i), 0, 0, float(i), 1, 0, float(i), 0, 1});
  writeFile(dir.file("big.stl"), binaryStl("x", tris));
  Collect c = readMesh(dir.file("big.stl"));
  ASSERT_EQ(c.v.size(), 210000u);
  expectPos(c.v[3 * 69999 + 2], 69999, 0, 1);
  EXPECT_EQ(c.tri(69999), (std::vector<uint32_t>{209997, 209998, 209999}));
  EXPECT_LE(c.maxVertexBatch, size_t(1) << 16);
}

// ---------------------------------------------------------------- detection

TEST(Detection, ContentBeatsExtension) {
  TempDir dir;
  writeFile(dir.file("ply.obj"), binaryTetra(false, "float", "uchar", "int"));
  EXPECT_EQ(mt::openMesh(dir.file("ply.obj"))->header().format, mt::MeshFormat::PlyBinaryLE);
  writeFile(dir.file("off.stl"), "# c\nOFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  EXPECT_EQ(mt::openMesh(dir.file("off.stl"))->header().format, mt::MeshFormat::Off);
  writeFile(dir.file("obj.off"), "# c\n\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3");
  EXPECT_EQ(mt::openMesh(dir.file("obj.off"))->header().format, mt::MeshFormat::Obj);
  writeFile(dir.file("stl"), "solid x\nfacet normal 0 0 0\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
                             "vertex 0 1 0\nendloop\nendfacet\nendsolid x\n");
  EXPECT_EQ(mt::openMesh(dir.file("stl"))->header().format, mt::MeshFormat::StlAscii);
  writeFile(dir.file("stl.ply"), binaryStl("solid", {{0, 0, 0, 1, 0, 0, 0, 1, 0}}));
  EXPECT_EQ(mt::openMesh(dir.file("stl.ply"))->header().format, mt::MeshFormat::StlBinary);
  EXPECT_STREQ(mt::formatName(mt::MeshFormat::StlBinary), "STL (binary)");
}

TEST(Detection, ExtensionWhenContentIsInconclusive) {
  TempDir dir;
  // An OBJ whose first 4 KiB are comments cannot be told by content.
  std::string comments;
  while (comments.size() < 5000) comments += "# exported by something verbose\n";
  writeFile(dir.file("long.OBJ"), comments + "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  Collect c = readMesh(dir.file("long.OBJ"));
  EXPECT_EQ(c.header.format, mt::MeshFormat::Obj);
  EXPECT_EQ(c.t.size(), 3u);
  writeFile(dir.file("long.txt"), comments);
  EXPECT_THAT(errorOf(dir.file("long.txt")), HasSubstr("unknown mesh format (expected PLY, OBJ, OFF, STL or glTF)"));
}

// ---------------------------------------------------------------- errors

TEST(ReaderErrors, OpenFailures) {
  TempDir dir;
  EXPECT_THAT(errorOf(dir.file("missing.ply")), HasSubstr("missing.ply: cannot open: No such file"));
  writeFile(dir.file("empty.ply"), "");
  EXPECT_EQ(errorOf(dir.file("empty.ply")), dir.file("empty.ply") + ": empty file");
  writeFile(dir.file("what.bin"), "hello world\n");
  EXPECT_EQ(errorOf(dir.file("what.bin")),
            dir.file("what.bin") + ": unknown mesh format (expected PLY, OBJ, OFF, STL or glTF)");
}

TEST(ReaderErrors, PlyTruncatedAndLyingCounts) {
  TempDir dir;
  std::string full = binaryTetra(false, "float", "uchar", "int");
  size_t header = full.find("end_header\n") + 11;
  std::string p = dir.file("t.ply");
  writeFile(p, full.substr(0, full.size() - 5));  // last face cut short
  std::string m = errorOf(p);
  EXPECT_THAT(m, HasSubstr("unexpected end of file in face 3"));
  EXPECT_THAT(m, HasSubstr("(byte offset " + std::to_string(full.size() - 5) + ")"));
  writeFile(p, full.substr(0, header + 12 * 2 + 3));  // inside vertex 2
  EXPECT_THAT(errorOf(p), HasSubstr("unexpected end of file in vertex 2 (byte offset"));
  writeFile(p, full + "xx");
  EXPECT_THAT(errorOf(p), HasSubstr("unexpected data after the last element (byte offset " +
                                    std::to_string(full.size()) + ")"));

  std::string body = "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                     "element face 2\nproperty list uchar int vertex_indices\n";
  writeFile(p, plyHeader("ascii", body) + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  EXPECT_THAT(errorOf(p), HasSubstr("unexpected end of file in face 1 (line 14)"));
  writeFile(p, plyHeader("ascii", body) + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 2\n3 2 1 0\n");
  EXPECT_THAT(errorOf(p), HasSubstr("unexpected data after the last element (line 16)"));
}

TEST(ReaderErrors, PlyBadIndicesAndCorners) {
  TempDir dir;
  std::string p = dir.file("i.ply");
  std::string full = binaryTetra(false, "float", "uchar", "int");
  size_t faces = full.find("end_header\n") + 11 + 48;
  std::string bad = full;
  int32_t big = 4;
  std::memcpy(&bad[faces + 13 * 2 + 5], &big, 4);  // face 2, second corner (fast path)
  writeFile(p, bad);
  EXPECT_THAT(errorOf(p), HasSubstr("index 4 out of range (4 vertices) at face 2 (byte offset " +
                                    std::to_string(faces + 26) + ")"));
  int32_t negative = -1;
  std::memcpy(&bad[faces + 13 * 2 + 5], &negative, 4);
  writeFile(p, bad);
  EXPECT_THAT(errorOf(p), HasSubstr("index -1 out of range (4 vertices) at face 2"));

  std::string be = binaryTetra(true, "float", "ushort", "uint");  // generic path
  size_t beFaces = be.find("end_header\n") + 11 + 48;
  be[beFaces + 14 + 5] = 9;  // face 1, last byte of the second (big-endian) index
  writeFile(p, be);
  EXPECT_THAT(errorOf(p), HasSubstr("index 9 out of range (4 vertices) at face 1 (byte offset " +
                                    std::to_string(beFaces + 14) + ")"));

  std::string body = "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                     "element face 1\nproperty list uchar int vertex_indices\n";
  writeFile(p, plyHeader("ascii", body) + "0 0 0\n1 0 0\n0 1 0\n2 0 1\n");
  EXPECT_THAT(errorOf(p), HasSubstr("face 0 has 2 corners (at least 3 needed) (line 14)"));
  writeFile(p, plyHeader("ascii", body) + "0 0 0\n1 0 0\n0 1 0\n3 0 1 -2\n");
  EXPECT_THAT(errorOf(p), HasSubstr("index -2 out of range (3 vertices) at face 0 (line 14)"));
}

TEST(ReaderErrors, PlyNonFiniteAndGarbage) {
  TempDir dir;
  std::string p = dir.file("n.ply");
  std::string full = binaryTetra(false, "float", "uchar", "int");
  size_t vertices = full.find("end_header\n") + 11;
  float nan = std::nanf("");
  std::memcpy(&full[vertices + 12 * 3 + 4], &nan, 4);
  writeFile(p, full);
  EXPECT_THAT(errorOf(p), HasSubstr("vertex 3 has a non-finite coordinate (byte offset " +
                                    std::to_string(vertices + 36) + ")"));

  std::string body = "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
                     "element face 1\nproperty list uchar int vertex_indices\n";
  writeFile(p, plyHeader("ascii", body) + "0 0 0\n1 abc 0\n0 1 0\n3 0 1 2\n");
  EXPECT_THAT(errorOf(p), HasSubstr("invalid number 'abc' at vertex 1 (line 12)"));
  writeFile(p, plyHeader("ascii", body) + "0 0 0\n1 0 0\n0 inf 0\n3 0 1 2\n");
  EXPECT_THAT(errorOf(p), HasSubstr("vertex 2 has a non-finite coordinate (line 13)"));
  writeFile(p, plyHeader("ascii", body) + "0 0 0\n1 0 0\n0 1e309 0\n3 0 1 2\n");  // overflows double
  EXPECT_THAT(errorOf(p), HasSubstr("vertex 2 has a non-finite coordinate (line 13)"));
}

TEST(ReaderErrors, PlyHeaderProblems) {
  TempDir dir;
  std::string p = dir.file("h.ply");
  std::string v = "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n";
  std::string f = "element face 1\nproperty list uchar int vertex_indices\n";
  writeFile(p, plyHeader("ascii", f + v));
  EXPECT_THAT(errorOf(p), HasSubstr("face element comes before the vertex element"));
  writeFile(p, plyHeader("ascii", v + "element face 0\nproperty list uchar int vertex_indices\n"));
  EXPECT_EQ(errorOf(p), p + ": mesh has no triangles");
  writeFile(p, plyHeader("ascii", v));
  EXPECT_EQ(errorOf(p), p + ": mesh has no triangles: no face or tristrips element, a point cloud of 3 vertices; mtbuild needs a triangle mesh");
  // Stanford's raw range scans: vertices and a range_grid of per-pixel vertex lists.
  writeFile(p, plyHeader("ascii", "obj_info num_cols 2\nobj_info num_rows 1\n" + v + "element range_grid 2\nproperty list uchar int vertex_indices\n"));
  EXPECT_THAT(errorOf(p), HasSubstr("a range image (range_grid); triangulate it into a mesh first"));
  writeFile(p, plyHeader("binary_little_endian",
                         "element vertex 5000000000\nproperty float x\nproperty float y\nproperty float z\n" + f));
  EXPECT_THAT(errorOf(p), HasSubstr("5000000000 vertices is more than the supported"));
  writeFile(p, plyHeader("ascii", v + "property quad w\n" + f));
  EXPECT_THAT(errorOf(p), HasSubstr("unknown type 'quad' in PLY header (line 8)"));
  writeFile(p, "ply\nformat ascii 1.0\n" + v);
  EXPECT_THAT(errorOf(p), HasSubstr("no end_header"));
}

TEST(ReaderErrors, PlyStripProblems) {
  TempDir dir;
  std::string p = dir.file("s.ply");
  std::string v = "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n";
  std::string s = "element tristrips 1\nproperty list int int vertex_indices\n";
  Bytes b;
  b.s = plyHeader("binary_little_endian", v + s);
  for (int i = 0; i < 3; ++i) b.put(float(i)).put(float(i * i)).put(0.f);
  const size_t list = b.s.size();
  b.put(int32_t(5)).put(int32_t(0)).put(int32_t(1)).put(int32_t(2)).put(int32_t(-1)).put(int32_t(3));
  writeFile(p, b.s);
  EXPECT_THAT(errorOf(p), HasSubstr("index 3 out of range (3 vertices) at tristrips 0 entry 4 (byte offset " +
                                    std::to_string(list + 4 + 16) + ")"));
  writeFile(p, b.s.substr(0, list + 10));
  EXPECT_THAT(errorOf(p), HasSubstr("unexpected end of file in tristrips 0"));
  writeFile(p, plyHeader("ascii", v + s) + "0 0 0\n1 0 0\n0 1 0\n4 0 1 -2 2\n");
  EXPECT_THAT(errorOf(p), HasSubstr("index -2 out of range (3 vertices) at tristrips 0 entry 2 (line 14)"));
  // Nothing but joins and short strips: no triangle.
  writeFile(p, plyHeader("ascii", v + s) + "0 0 0\n1 0 0\n0 1 0\n7 0 1 1 -1 2 0 -1\n");
  EXPECT_EQ(errorOf(p), p + ": mesh has no triangles");
  writeFile(p, plyHeader("ascii", s + v));
  EXPECT_THAT(errorOf(p), HasSubstr("tristrips element comes before the vertex element"));
  writeFile(p, plyHeader("ascii", v + "element tristrips 1\nproperty list int float vertex_indices\n") + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  EXPECT_THAT(errorOf(p), HasSubstr("tristrips vertex_indices must have an integer index type"));
  writeFile(p, plyHeader("ascii", v + "element tristrips 1\nproperty int x\n") + "0 0 0\n1 0 0\n0 1 0\n3\n");
  EXPECT_THAT(errorOf(p), HasSubstr("tristrips element has no vertex_indices list"));
}

TEST(ReaderErrors, ObjProblems) {
  TempDir dir;
  std::string p = dir.file("e.obj");
  writeFile(p, "v 0 0 0\nv 1 0 0\nf 1 2 3\nv 0 1 0\n");
  EXPECT_THAT(errorOf(p), HasSubstr("index 3 out of range (2 vertices so far) at face 0 (line 3)"));
  writeFile(p, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 1 2\n");
  EXPECT_THAT(errorOf(p), HasSubstr("index -4 out of range (3 vertices so far) at face 0 (line 4)"));
  writeFile(p, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n");
  EXPECT_THAT(errorOf(p), HasSubstr("index 0 out of range"));
  writeFile(p, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n");
  EXPECT_THAT(errorOf(p), HasSubstr("face 0 has 2 corners (at least 3 needed) (line 4)"));
  writeFile(p, "v 0 0 0\nv 1 0 abc\nv 0 1 0\nf 1 2 3\n");
  EXPECT_THAT(errorOf(p), HasSubstr("invalid number 'abc' at vertex 1 (line 2)"));
  writeFile(p, "v 0 0 0\nv 1 0 0\nv nan 1 0\nf 1 2 3\n");
  EXPECT_THAT(errorOf(p), HasSubstr("vertex 2 has a non-finite coordinate (line 3)"));
  writeFile(p, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x/3\n");
  EXPECT_THAT(errorOf(p), HasSubstr("invalid face corner 'x/3' at face 0 (line 4)"));
  writeFile(p, "v 0 0 0\nv 1 0 0\nv 0 1 0\n");
  EXPECT_EQ(errorOf(p), p + ": mesh has no triangles");
}

TEST(ReaderErrors, OffProblems) {
  TempDir dir;
  std::string p = dir.file("e.off");
  writeFile(p, "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  EXPECT_THAT(errorOf(p), HasSubstr("unexpected end of file in face 1 (line 6)"));
  writeFile(p, "OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n");
  EXPECT_THAT(errorOf(p), HasSubstr("unexpected end of file in vertex 3 (line 5)"));
  writeFile(p, "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 0 1 2\n");
  EXPECT_THAT(errorOf(p), HasSubstr("unexpected data after the last face (line 7)"));
  writeFile(p, "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n");
  EXPECT_THAT(errorOf(p), HasSubstr("index 3 out of range (3 vertices) at face 0 (line 6)"));
  writeFile(p, "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n");
  EXPECT_THAT(errorOf(p), HasSubstr("index -1 out of range (3 vertices) at face 0 (line 6)"));
  writeFile(p, "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n");
  EXPECT_THAT(errorOf(p), HasSubstr("face 0 has 2 corners (at least 3 needed) (line 6)"));
  writeFile(p, "OFF\n3 1 0\n0 0 0\n1 z 0\n0 1 0\n3 0 1 2\n");
  EXPECT_THAT(errorOf(p), HasSubstr("invalid number 'z' at vertex 1 (line 4)"));
  writeFile(p, "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 -inf\n3 0 1 2\n");
  EXPECT_THAT(errorOf(p), HasSubstr("vertex 2 has a non-finite coordinate (line 5)"));
  writeFile(p, "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n");
  EXPECT_EQ(errorOf(p), p + ": mesh has no triangles");
  writeFile(p, "4OFF\n3 1 0\n");
  EXPECT_THAT(errorOf(p), HasSubstr("unsupported OFF variant '4OFF'"));
}

TEST(ReaderErrors, StlProblems) {
  TempDir dir;
  std::string p = dir.file("e.stl");
  std::string full = binaryStl("binary", {{0, 0, 0, 1, 0, 0, 0, 1, 0}, {0, 0, 0, 1, 0, 0, 0, 1, 0}});
  writeFile(p, full.substr(0, full.size() - 10));  // by extension: content is inconclusive
  EXPECT_EQ(errorOf(p), p + ": unexpected end of file in triangle 1 (byte offset " +
                            std::to_string(full.size() - 10) + ")");
  std::string nan = full;
  float inf = INFINITY;
  std::memcpy(&nan[84 + 50 + 12 + 4 * 4], &inf, 4);  // triangle 1, second vertex, y
  writeFile(p, nan);
  EXPECT_EQ(errorOf(p), p + ": vertex 4 has a non-finite coordinate (byte offset 134)");
  writeFile(p, binaryStl("binary", {}));
  EXPECT_EQ(errorOf(p), p + ": mesh has no triangles");

  writeFile(p, "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n");
  EXPECT_THAT(errorOf(p), HasSubstr("unexpected end of file in facet 0 (line 5)"));
  writeFile(p, "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nendloop\nendfacet\nendsolid\n");
  EXPECT_THAT(errorOf(p), HasSubstr("facet 0 has 2 vertices (3 needed) (line 7)"));
  writeFile(p, "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 q 0\n");
  EXPECT_THAT(errorOf(p), HasSubstr("invalid number 'q' at facet 0 (line 5)"));
  writeFile(p, "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\n"
               "endloop\nendfacet\n");
  EXPECT_THAT(errorOf(p), HasSubstr("no 'endsolid'"));
}

}  // namespace
