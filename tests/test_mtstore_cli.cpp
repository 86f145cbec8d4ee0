// mtstore end to end: bad input gives one clear line naming the file and the element/offset, exit
// code 1, and nothing under the output name; defects that are legal are accepted and counted.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

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
      {"missing file", "missing.ply", "", "cannot open"},
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
  EXPECT_EQ(check.exitCode, 1) << check.output;
  EXPECT_NE(check.output.find("checksum mismatch"), std::string::npos) << check.output;
  CommandResult exp = runTool("mtstore", "export " + tmp.file("s") + " -o " + tmp.file("out.ply"));
  EXPECT_EQ(exp.exitCode, 1) << exp.output;
  EXPECT_FALSE(fs::exists(tmp.file("out.ply")));
  for (auto& e : fs::directory_iterator(tmp.path())) EXPECT_EQ(e.path().string().find(".tmp-"), std::string::npos) << e.path();
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
