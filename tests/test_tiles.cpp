// 3D Tiles export (interop/tiles_export.h): the tree's rules on a real build (REPLACE, geometric
// errors never above the parent's, spheres inside the parent's, every content present, the root
// transform carrying the grid's origin exactly), the full resolution present exactly once in the
// leaves, and nothing left behind when the directory exists.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <set>

#include "mtfile/mt_cut.h"
#include "mtfile/mt_file.h"
#include "patchstore/io/mesh_reader.h"
#include "tests/test_support.h"

namespace mt {
namespace {

using nlohmann::json;
using test::runTool;
using test::TempDir;

struct Count : MeshSink {
  uint64_t t = 0;
  void vertices(const InputVertex*, size_t, uint64_t) override {}
  void triangles(const uint32_t*, size_t n) override { t += n; }
};

TEST(Tiles, ExportOfAGeoreferencedBuildFollowsTheTreeRules) {
  TempDir dir;
  ASSERT_EQ(runTool("mtgen", "-o " + dir.file("scan.ply") + " --triangles 30k --offset 500000,4000000,100").exitCode, 0);
  auto built = runTool("mtbuild", dir.file("scan.ply") + " -o " + dir.file("scan.mt") + " --crs EPSG:32633 -q --patch-triangles 500");
  ASSERT_EQ(built.exitCode, 0) << built.output;
  auto ex = runTool("mtexport", "tiles " + dir.file("scan.mt") + " " + dir.file("tiles"));
  ASSERT_EQ(ex.exitCode, 0) << ex.output;
  auto reader = MtFileReader::open(dir.file("scan.mt"));
  const auto& h = reader->header();

  json ts = json::parse(test::readFile(dir.file("tiles/tileset.json")));
  EXPECT_EQ(ts["asset"]["version"], "1.1");
  EXPECT_EQ(ts["asset"]["extras"]["crs"], "EPSG:32633");
  const json& root = ts["root"];
  EXPECT_EQ(root["refine"], "REPLACE");
  // The root transform is the grid's origin, bit for bit (JSON numbers round-trip doubles).
  for (int a = 0; a < 3; ++a) EXPECT_EQ(root["transform"][12 + a].get<double>(), h.gridOrigin[a]);
  EXPECT_GT(h.gridOrigin[0], 499000.0);

  std::set<std::string> contents;
  uint64_t leafTriangles = 0;
  int depth = 0;
  std::function<void(const json&, const json*, int)> walk = [&](const json& t, const json* parent, int d) {
    depth = std::max(depth, d);
    const double e = t["geometricError"];
    EXPECT_GE(e, 0);
    const auto& s = t["boundingVolume"]["sphere"];
    if (parent) {
      EXPECT_LE(e, (*parent)["geometricError"].get<double>());
      const auto& ps = (*parent)["boundingVolume"]["sphere"];
      const double dist = std::hypot(s[0].get<double>() - ps[0].get<double>(), s[1].get<double>() - ps[1].get<double>(),
                                     s[2].get<double>() - ps[2].get<double>());
      EXPECT_LE(dist + s[3].get<double>(), ps[3].get<double>() * (1 + 1e-12));
    }
    if (t.contains("content")) {
      const std::string uri = t["content"]["uri"];
      ASSERT_TRUE(test::fileExists(dir.file("tiles/" + uri))) << uri;
      // The source's pieces (geometricError 0) hold the full resolution, each once.
      if (e == 0 && uri.find("tiles/s") == 0 && contents.insert(uri).second) {
        Count c;
        openMesh(dir.file("tiles/" + uri))->read(c);
        leafTriangles += c.t;
      }
    }
    if (t.contains("children"))
      for (const json& c : t["children"]) walk(c, &t, d + 1);
  };
  walk(root, nullptr, 0);
  EXPECT_GE(depth, 2);
  // The finest cut, welded, against the leaves (degenerate triangles are dropped in both).
  WeldedMesh finest = assembleCut(*reader, cutArcs(*reader, finestCut(*reader).inSet));
  EXPECT_EQ(leafTriangles, finest.triangleCount());
  EXPECT_NE(ex.output.find("tiles"), std::string::npos);

  // An existing directory is refused, and nothing is written or left beside it.
  auto again = runTool("mtexport", "tiles " + dir.file("scan.mt") + " " + dir.file("tiles"));
  EXPECT_EQ(again.exitCode, 1);
  EXPECT_NE(again.output.find("exists"), std::string::npos) << again.output;
  size_t entries = 0;
  for (auto& e : std::filesystem::directory_iterator(dir.path())) entries += e.path().filename().string().find("tmp") != std::string::npos;
  EXPECT_EQ(entries, 0u);
  EXPECT_NE(runTool("mtexport", "--help").output.find("tiles"), std::string::npos);
}

}  // namespace
}  // namespace mt
