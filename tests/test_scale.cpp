// Scale paths that must give what the in-RAM paths give: a cut welded in bounded memory
// (mtfile/mt_cut_writer.h) against assembleCut, vertex for vertex and triangle for triangle, with
// budgets small enough that every sort spills; and mtextract's streamed PLY against its in-RAM one,
// byte for byte, with the streamed run's peak RSS bounded by the budget plus the file's tables.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include "mtbuild/build.h"
#include "mtfile/mt_cut.h"
#include "mtfile/mt_cut_writer.h"
#include "mtfile/mt_file.h"
#include "tests/test_support.h"

namespace mt::test {
namespace {

// A wavy height field of n x n quads as an ASCII PLY with per-vertex normals and colours, so the
// weld's normal sums and first colours are exercised too.
std::string writeAttributedPly(const TempDir& dir, int n) {
  std::string s = "ply\nformat ascii 1.0\nelement vertex " + std::to_string((n + 1) * (n + 1)) +
                  "\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\n"
                  "property float nz\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n"
                  "element face " + std::to_string(2 * n * n) + "\nproperty list uchar int vertex_indices\nend_header\n";
  char line[256];
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const double x = double(i) / n, y = double(j) / n, z = 0.05 * std::sin(9 * x) * std::cos(7 * y);
      const double nx = -0.45 * std::cos(9 * x) * std::cos(7 * y), ny = 0.35 * std::sin(9 * x) * std::sin(7 * y);
      const double len = std::sqrt(nx * nx + ny * ny + 1);
      std::snprintf(line, sizeof line, "%.7f %.7f %.7f %.6f %.6f %.6f %d %d %d 255\n", x, y, z, nx / len, ny / len, 1 / len,
                    i % 256, j % 256, (i * j) % 256);
      s += line;
    }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      s += "3 " + std::to_string(a) + " " + std::to_string(b) + " " + std::to_string(d) + "\n";
      s += "3 " + std::to_string(a) + " " + std::to_string(d) + " " + std::to_string(c) + "\n";
    }
  const std::string path = dir.file("attr.ply");
  writeFile(path, s);
  return path;
}

std::string buildMt(const TempDir& tmp, const std::string& in, const std::string& name) {
  const std::string out = tmp.file(name);
  CommandResult b = runTool("mtbuild", in + " -o " + out + " -q --patch-triangles 300");
  EXPECT_EQ(b.exitCode, 0) << b.output;
  return out;
}

// What the streamed weld hands its sink.
struct RecordingSink : WeldedCutSink {
  WeldedCutInfo info;
  std::vector<double> positions;
  std::vector<float> normals;
  std::vector<uint8_t> colors;
  std::vector<uint32_t> triangles;
  int begun = 0;
  std::function<void()> onFirstVertex;  // called once, before the first vertex is recorded
  void begin(const WeldedCutInfo& i) override {
    info = i;
    ++begun;
  }
  void vertex(const double p[3], const float* n, const uint8_t* c) override {
    EXPECT_EQ(begun, 1);
    EXPECT_TRUE(triangles.empty()) << "all vertices before the first triangle";
    if (positions.empty() && onFirstVertex) onFirstVertex();
    positions.insert(positions.end(), p, p + 3);
    if (n) normals.insert(normals.end(), n, n + 3);
    if (c) colors.insert(colors.end(), c, c + 4);
  }
  void triangle(uint32_t a, uint32_t b, uint32_t c) override { triangles.insert(triangles.end(), {a, b, c}); }
};

void expectSameAsAssembled(const MtFileReader& r, const std::vector<uint32_t>& arcs, uint64_t memory, const std::string& what) {
  SCOPED_TRACE(what + ", memory " + std::to_string(memory));
  const WeldedMesh m = assembleCut(r, arcs);
  TempDir scratch;
  WeldedCutOptions options;
  options.memoryBytes = memory;
  options.scratchDir = scratch.path();
  int polls = 0;
  options.poll = [&] { ++polls; };
  RecordingSink sink;
  // When the first vertex comes, the uses are read and their runs gone; the welded vertices are all
  // in runs (every sort spills at 64 KiB), 40 bytes each with normals or colours, 24 without.
  uint64_t vertexRunBytes = 0;
  bool usesLeft = false;
  sink.onFirstVertex = [&] {
    for (const auto& e : std::filesystem::directory_iterator(scratch.path())) {
      const std::string name = e.path().filename().string();
      if (name.find(".vertices") != std::string::npos) vertexRunBytes += e.file_size();
      if (name.find(".uses") != std::string::npos) usesLeft = true;
    }
  };
  const WeldedCutInfo info = writeWeldedCut(r, arcs, options, sink);
  EXPECT_FALSE(usesLeft);
  if (memory < (1 << 20) && info.vertices > 4096) {
    const bool attributes = r.header().vertexFlags & (format::kHasNormals | format::kHasColors);
    EXPECT_EQ(vertexRunBytes, info.vertices * (attributes ? 40 : 24));
  }
  EXPECT_GT(polls, 0);
  EXPECT_EQ(info.vertices, m.vertexCount());
  EXPECT_EQ(info.triangles, m.triangleCount());
  EXPECT_EQ(info.degenerateTriangles, m.degenerateTriangles);
  EXPECT_EQ(info.patches, m.patches);
  EXPECT_EQ(info.normals, !m.normals.empty());
  EXPECT_EQ(info.colors, !m.colors.empty());
  double maxAbs = 0;
  for (double p : m.positions) maxAbs = std::max(maxAbs, std::abs(p));
  EXPECT_EQ(info.maxAbsCoordinate, maxAbs);
  // Exact equality: the same order, the same doubles, the same float sums.
  EXPECT_TRUE(sink.positions == m.positions);
  EXPECT_TRUE(sink.normals == m.normals);
  EXPECT_TRUE(sink.colors == m.colors);
  EXPECT_TRUE(sink.triangles == m.triangles);
  // The run files are gone once read.
  CommandResult ls = runShell("ls -A " + scratch.path() + " | wc -l");
  EXPECT_EQ(std::stoi(ls.output), 0) << ls.output;
}

TEST(StreamedWeld, SameMeshAsAssembleCutWhateverTheBudget) {
  struct Case {
    const char* name;
    const char* mtgen;  // empty: the attributed height field
  };
  const Case cases[] = {{"holes, shuffled", "--triangles 24k --holes 16 --shuffle --seed 12"},
                        {"components", "--triangles 20k --components 4 --density varying --seed 13"},
                        {"normals and colours", ""}};
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    TempDir tmp;
    std::string in;
    if (*c.mtgen) {
      in = tmp.file("in.ply");
      CommandResult g = runTool("mtgen", "-o " + in + " " + c.mtgen);
      ASSERT_EQ(g.exitCode, 0) << g.output;
    } else {
      in = writeAttributedPly(tmp, 100);
    }
    std::string mt;
    if (*c.mtgen) {
      mt = buildMt(tmp, in, "c.mt");
    } else {  // normals are stored only on request (no mtbuild option)
      mt = tmp.file("c.mt");
      BuildOptions o;
      o.normals = true;
      o.patchTriangles = 300;
      o.progress = false;
      o.memoryBytes = 64 << 20;
      buildMt(in, mt, o);
    }
    auto r = MtFileReader::open(mt);
    if (!*c.mtgen) {
      ASSERT_TRUE(r->header().vertexFlags & format::kHasNormals);
      ASSERT_TRUE(r->header().vertexFlags & format::kHasColors);
    }
    std::vector<std::pair<std::string, std::vector<uint32_t>>> cuts = {
        {"finest", cutArcs(*r, finestCut(*r).inSet)}, {"coarsest", cutArcs(*r, coarsestCut(*r).inSet)}};
    std::mt19937_64 rng(5);
    for (int k = 0; k < 2; ++k) cuts.push_back({"random " + std::to_string(k), cutArcs(*r, randomCut(*r, rng).inSet)});
    for (const auto& [name, arcs] : cuts) {
      // 64 KiB: runs of a few hundred records, every sort spills; 1 GiB: nothing touches the disk.
      expectSameAsAssembled(*r, arcs, 64 << 10, name);
      expectSameAsAssembled(*r, arcs, uint64_t(1) << 30, name);
    }
  }
}

// Peak RSS of a tool run, from GNU time's %M (KiB).
uint64_t peakKib(const std::string& output) {
  const size_t at = output.rfind("PEAK ");
  return at == std::string::npos ? 0 : std::stoull(output.substr(at + 5));
}

TEST(StreamedWeld, MtextractWritesTheSameBytesWithinASmallMemory) {
  TempDir tmp;
  const std::string in = tmp.file("in.ply");
  ASSERT_EQ(runTool("mtgen", "-o " + in + " --triangles 400k --holes 20 --seed 3").exitCode, 0);
  const std::string mt = buildMt(tmp, in, "c.mt");
  const std::string ram = tmp.file("ram.ply"), streamed = tmp.file("streamed.ply");
  CommandResult a = runTool("mtextract", mt + " --error 0 -o " + ram);
  ASSERT_EQ(a.exitCode, 0) << a.output;
  EXPECT_EQ(a.output.find("bounded memory"), std::string::npos) << a.output;
  // The finest cut's welded mesh takes ~25 MB in RAM; at --memory 2M it is streamed.
  const bool haveTime = runShell("test -x /usr/bin/time").exitCode == 0;
  const std::string tool = binDir() + "/mtextract " + mt + " --error 0 --memory 2M -o " + streamed;
  CommandResult b = runShell(haveTime ? "/usr/bin/time -f 'PEAK %M' " + tool + " 2>&1" : tool + " 2>&1");
  ASSERT_EQ(b.exitCode, 0) << b.output;
  EXPECT_NE(b.output.find("bounded memory"), std::string::npos) << b.output;
  EXPECT_EQ(readFile(ram), readFile(streamed));
  if (haveTime) {
    CommandResult c = runShell("/usr/bin/time -f 'PEAK %M' " + binDir() + "/mtextract " + mt + " --error 0 -o " + ram + " 2>&1");
    ASSERT_EQ(c.exitCode, 0) << c.output;
    // The streamed run holds the budget, the file's tables and the binary; the in-RAM one the mesh.
    EXPECT_LT(peakKib(b.output), peakKib(c.output)) << b.output << c.output;
  }
  // No scratch left beside the output.
  CommandResult ls = runShell("ls -A " + tmp.path() + " | grep -c sort");
  EXPECT_EQ(std::stoi(ls.output), 0) << ls.output;
}

}  // namespace
}  // namespace mt::test
