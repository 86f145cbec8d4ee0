// mtstore end to end: bad input gives one clear line naming the file and the element/offset, exit
// code 1, and nothing under the output name; defects that are legal are accepted and counted.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "patchstore/io/mesh_reader.h"
#include "tests/test_support.h"

namespace mt::test {
namespace {

namespace fs = std::filesystem;

std::string plyHeader(const char* format, int nv, int nf, const char* coord = "float") {
  return std::string("ply\nformat ") + format + " 1.0\nelement vertex " + std::to_string(nv) + "\nproperty " + coord +
         " x\nproperty " + coord + " y\nproperty " + coord + " z\nelement face " + std::to_string(nf) +
         "\nproperty list uchar int vertex_indices\nend_header\n";
}

std::string lastLine(const std::string& s) {
  std::string t = s;
  while (!t.empty() && t.back() == '\n') t.pop_back();
  size_t nl = t.rfind('\n');
  return nl == std::string::npos ? t : t.substr(nl + 1);
}

struct BadCase {
  const char* name;
  const char* file;        // file name (extension matters)
  std::string bytes;
  const char* mustContain; // in the error line, besides the path
};

std::string binaryTriangles(int nv, const std::vector<int>& faces, float bad = 0, int badIndex = -1) {
  std::string b;
  for (int v = 0; v < nv; ++v)
    for (int a = 0; a < 3; ++a) {
      float f = (v == badIndex && a == 1) ? bad : float(v + a);
      b.append(reinterpret_cast<char*>(&f), 4);
    }
  for (size_t i = 0; i < faces.size(); i += 3) {
    b.push_back(3);
    for (int k = 0; k < 3; ++k) b.append(reinterpret_cast<const char*>(&faces[i + k]), 4);
  }
  return b;
}

TEST(MtstoreCli, BadInputGivesOneClearLineAndLeavesNothing) {
  TempDir tmp;
  std::vector<int> faces = {0, 1, 2, 1, 3, 2, 2, 3, 4};
  std::string good = plyHeader("binary_little_endian", 5, 3) + binaryTriangles(5, faces);
  std::vector<BadCase> cases = {
      {"truncated binary", "trunc.ply", good.substr(0, good.size() - 7), "byte offset"},
      {"counts that lie", "lie.ply", plyHeader("binary_little_endian", 9, 3) + binaryTriangles(5, faces), "byte offset"},
      {"index out of range", "range.ply", plyHeader("binary_little_endian", 5, 3) + binaryTriangles(5, {0, 1, 2, 1, 3, 2, 2, 3, 7}), "face 2"},
      {"negative index", "neg.ply", plyHeader("ascii", 3, 1) + "0 0 0\n1 0 0\n0 1 0\n3 0 1 -1\n", "line 13"},
      {"NaN coordinate", "nan.ply", plyHeader("ascii", 3, 1) + "0 0 0\n1 nan 0\n0 1 0\n3 0 1 2\n", "line 11"},
      {"Inf coordinate", "inf.ply", plyHeader("binary_little_endian", 5, 3) + binaryTriangles(5, faces, INFINITY, 3), "vertex 3"},
      {"garbage number", "garbage.obj", "v 0 0 0\nv 1 0 0\nv 0 1x 0\nf 1 2 3\n", "line 3"},
      {"unknown format", "scan.xyz", "this is not a mesh\n1 2 3\n", "unknown"},
      {"unknown format, known extension", "fake.stl", std::string("\x01\x02\x03", 3), ""},
      {"empty mesh", "empty.off", "OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n", "no triangles"},
      {"zero-byte file", "zero.ply", "", "empty"},
      {"missing file", "missing.ply", "", "no such file"},
  };
  for (const BadCase& c : cases) {
    std::string in = tmp.file(c.file);
    if (std::string(c.name) != "missing file") writeFile(in, c.bytes);
    std::string store = tmp.file(std::string("store-") + c.file);
    CommandResult r = runTool("mtstore", "ingest " + in + " -o " + store);
    EXPECT_EQ(r.exitCode, 1) << c.name << "\n" << r.output;
    std::string line = lastLine(r.output);
    EXPECT_EQ(line.rfind("mtstore: ", 0), 0u) << c.name << ": " << line;
    EXPECT_NE(line.find(in), std::string::npos) << c.name << ": the error must name the file: " << line;
    EXPECT_NE(line.find(c.mustContain), std::string::npos) << c.name << ": expected '" << c.mustContain << "' in: " << line;
    EXPECT_FALSE(fs::exists(store)) << c.name;
    for (auto& e : fs::directory_iterator(tmp.path()))
      EXPECT_EQ(e.path().string().find(".ingest-"), std::string::npos) << c.name << ": leftover " << e.path();
  }
}

TEST(MtstoreCli, LegalDefectsAreAcceptedAndCounted) {
  TempDir tmp;
  // A strip of 4 triangles plus: a degenerate face, a duplicate face (reversed), two unreferenced
  // vertices, and a non-manifold edge (1,2) used by three faces.
  std::string ply = plyHeader("ascii", 8, 7) +
                    "0 0 0\n1 0 0\n0 1 0\n1 1 0\n2 0 0\n5 5 5\n6 6 6\n0 0 1\n"
                    "3 0 1 2\n3 1 3 2\n3 1 4 3\n3 0 0 1\n3 2 1 0\n3 1 2 7\n3 3 4 4\n";
  writeFile(tmp.file("dirty.ply"), ply);
  CommandResult r = runTool("mtstore", "ingest " + tmp.file("dirty.ply") + " -o " + tmp.file("s") + " -q");
  ASSERT_EQ(r.exitCode, 0) << r.output;
  CommandResult info = runTool("mtstore", "info " + tmp.file("s") + " --json");
  ASSERT_EQ(info.exitCode, 0) << info.output;
  EXPECT_NE(info.output.find("\"degenerateTriangles\": 2"), std::string::npos) << info.output;
  EXPECT_NE(info.output.find("\"duplicateTriangles\": 1"), std::string::npos) << info.output;
  EXPECT_NE(info.output.find("\"unreferencedVertices\": 2"), std::string::npos) << info.output;
  EXPECT_NE(info.output.find("\"nonManifoldEdges\": 1"), std::string::npos) << info.output;
  EXPECT_NE(info.output.find("\"triangles\": 7"), std::string::npos) << info.output;
  EXPECT_EQ(runTool("mtstore", "check " + tmp.file("s")).exitCode, 0);
}

TEST(MtstoreCli, CheckFindsACorruptedStoreAndExportLeavesNoPartialFile) {
  TempDir tmp;
  std::string ply = plyHeader("ascii", 4, 2) + "0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 1 3 2\n";
  writeFile(tmp.file("a.ply"), ply);
  ASSERT_EQ(runTool("mtstore", "ingest " + tmp.file("a.ply") + " -o " + tmp.file("s") + " -q").exitCode, 0);
  for (auto& e : fs::directory_iterator(tmp.file("s")))
    if (e.path().filename().string().rfind("SEG-", 0) == 0) {
      std::string b = readFile(e.path());
      b[b.size() - 3] ^= 1;
      writeFile(e.path(), b);
    }
  CommandResult check = runTool("mtstore", "check " + tmp.file("s"));
  EXPECT_EQ(check.exitCode, 3) << check.output;
  EXPECT_NE(check.output.find("checksum mismatch"), std::string::npos) << check.output;
  CommandResult exp = runTool("mtstore", "export " + tmp.file("s") + " -o " + tmp.file("out.ply"));
  EXPECT_EQ(exp.exitCode, 3) << exp.output;
  EXPECT_FALSE(fs::exists(tmp.file("out.ply")));
  for (auto& e : fs::directory_iterator(tmp.path())) EXPECT_EQ(e.path().filename().string().find(".tmp"), std::string::npos) << e.path();
}

// The round trip at scale: a 1M-triangle scan with holes and shuffled faces, ingested
// under a small cap (so the sorts spill), exported, and compared triangle by triangle with
// bit-exact coordinates.
struct Soup : MeshSink {
  std::vector<float> p;
  std::vector<std::array<float, 9>> tris;
  void vertices(const InputVertex* v, size_t n, uint64_t) override {
    for (size_t i = 0; i < n; ++i)
      for (int a = 0; a < 3; ++a) p.push_back(float(v[i].p[a]));
  }
  void triangles(const uint32_t* idx, size_t n) override {
    for (size_t t = 0; t < n; ++t) {
      std::array<std::array<float, 3>, 3> c;
      for (int k = 0; k < 3; ++k) c[k] = {p[3 * idx[3 * t + k]], p[3 * idx[3 * t + k] + 1], p[3 * idx[3 * t + k] + 2]};
      std::rotate(c.begin(), std::min_element(c.begin(), c.end()), c.end());  // keeps orientation
      std::array<float, 9> flat;
      for (int k = 0; k < 9; ++k) flat[k] = c[k / 3][k % 3];
      tris.push_back(flat);
    }
  }
};

TEST(MtstoreCli, MillionTriangleScanRoundTripsExactly) {
  TempDir tmp;
  CommandResult gen = runTool("mtgen", "-o " + tmp.file("scan.ply") + " --triangles 1M --holes 30 --shuffle --seed 21");
  ASSERT_EQ(gen.exitCode, 0) << gen.output;
  CommandResult in = runTool("mtstore", "ingest " + tmp.file("scan.ply") + " -o " + tmp.file("s") + " -q --memory 24M");
  ASSERT_EQ(in.exitCode, 0) << in.output;
  ASSERT_EQ(runTool("mtstore", "check " + tmp.file("s")).exitCode, 0);
  ASSERT_EQ(runTool("mtstore", "export " + tmp.file("s") + " -o " + tmp.file("out.ply") + " -q").exitCode, 0);
  Soup a, b;
  openMesh(tmp.file("scan.ply"))->read(a);
  openMesh(tmp.file("out.ply"))->read(b);
  ASSERT_GE(a.tris.size(), 990000u);
  std::sort(a.tris.begin(), a.tris.end());
  std::sort(b.tris.begin(), b.tris.end());
  EXPECT_TRUE(a.tris == b.tris) << a.tris.size() << " vs " << b.tris.size() << " triangles";
  EXPECT_EQ(a.p.size(), b.p.size()) << "vertex count (mtgen writes no unreferenced vertices)";
}

TEST(MtstoreCli, HelpExplainsEverySubcommand) {
  CommandResult r = runTool("mtstore", "--help-all");
  EXPECT_EQ(r.exitCode, 0);
  for (const char* s : {"ingest", "info", "export", "check", "--memory", "--patch-triangles", "--json"})
    EXPECT_NE(r.output.find(s), std::string::npos) << s;
  EXPECT_NE(runTool("mtstore", "frobnicate x").exitCode, 0);
}

}  // namespace
}  // namespace mt::test
