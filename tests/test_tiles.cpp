// 3D Tiles export (interop/tiles_export.h): the tree's rules on a real build (REPLACE, geometric
// errors never above the parent's, spheres inside the parent's, every content present, the root
// transform carrying the grid's origin exactly), the full resolution present exactly once in the
// leaves, and nothing left behind when the directory exists.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <cstring>
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

// A tile content's triangles as MT grid points (each rotated to start at its smallest corner, so
// orientation counts): the content's frame is the grid origin's, +Z up turned to glTF's +Y up.
using GridTri = std::array<int64_t, 9>;
struct OnGrid : MeshSink {
  const double* origin;
  double step;
  std::vector<std::array<int64_t, 3>> v;
  std::vector<GridTri>* out;
  OnGrid(const double* o, double s, std::vector<GridTri>* t) : origin(o), step(s), out(t) {}
  void vertices(const InputVertex* p, size_t n, uint64_t) override {
    for (size_t i = 0; i < n; ++i) {
      const double model[3] = {p[i].p[0], -p[i].p[2], p[i].p[1]};  // glTF y-up -> the tiles' z-up
      v.push_back({std::llround(model[0] / step), std::llround(model[1] / step), std::llround(model[2] / step)});
    }
  }
  void triangles(const uint32_t* idx, size_t n) override {
    for (size_t t = 0; t < n; ++t) out->push_back(rotated({v[idx[3 * t]], v[idx[3 * t + 1]], v[idx[3 * t + 2]]}));
  }
  static GridTri rotated(std::array<std::array<int64_t, 3>, 3> c) {
    int m = 0;
    for (int k = 1; k < 3; ++k)
      if (c[k] < c[m]) m = k;
    GridTri g;
    for (int k = 0; k < 3; ++k)
      for (int a = 0; a < 3; ++a) g[3 * k + a] = c[(m + k) % 3][a];
    return g;
  }
};

TEST(Tiles, ExportOfAGeoreferencedBuildFollowsTheTreeRules) {
  TempDir dir;
  ASSERT_EQ(runTool("mtgen", "-o " + dir.file("scan.ply") + " --triangles 30k --offset 500000,4000000,100").exitCode, 0);
  auto built = runTool("mtbuild", dir.file("scan.ply") + " -o " + dir.file("scan.mt") + " --crs EPSG:32633 -q --patch-triangles 500");
  ASSERT_EQ(built.exitCode, 0) << built.output;
  // The model frame (the CRS ignored): the root transform is the grid's origin.
  auto ex = runTool("mtexport", "tiles " + dir.file("scan.mt") + " " + dir.file("tiles") + " --model-frame");
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
  for (int k = 0; k < 12; ++k) EXPECT_EQ(root["transform"][k].get<double>(), k % 5 == 0 ? 1.0 : 0.0) << k;
  EXPECT_GT(h.gridOrigin[0], 499000.0);

  std::set<std::string> contents;
  std::vector<GridTri> leaves;
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
        OnGrid c(h.gridOrigin, h.gridStep, &leaves);
        openMesh(dir.file("tiles/" + uri))->read(c);
      }
    }
    if (t.contains("children"))
      for (const json& c : t["children"]) walk(c, &t, d + 1);
  };
  walk(root, nullptr, 0);
  EXPECT_GE(depth, 2);
  // The finest cut, welded, against the leaves (degenerate triangles are dropped in both).
  WeldedMesh finest = assembleCut(*reader, cutArcs(*reader, finestCut(*reader).inSet));
  // Exactly, on the grid (the default contents are Draco-coded grid coordinates: lossless).
  std::vector<GridTri> cut;
  for (uint32_t t = 0; t < finest.triangleCount(); ++t) {
    std::array<std::array<int64_t, 3>, 3> c;
    for (int k = 0; k < 3; ++k)
      for (int a = 0; a < 3; ++a) c[k][a] = finest.q[3 * finest.triangles[3 * t + k] + a];
    cut.push_back(OnGrid::rotated(c));
  }
  std::sort(cut.begin(), cut.end());
  std::sort(leaves.begin(), leaves.end());
  EXPECT_EQ(leaves.size(), cut.size());
  EXPECT_TRUE(leaves == cut) << "the full-resolution leaves are not the finest cut's triangles";
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

// The tileset's frame -> ECEF: the root transform (column-major).
void rootToEcef(const json& root, const double x[3], double out[3]) {
  const json& m = root["transform"];
  for (int r = 0; r < 3; ++r)
    out[r] = m[12 + r].get<double>() + m[r].get<double>() * x[0] + m[4 + r].get<double>() * x[1] + m[8 + r].get<double>() * x[2];
}

TEST(Tiles, WithACrsTheRootTransformPutsTheModelOnTheGlobe) {
  TempDir dir;
  ASSERT_EQ(runTool("mtgen", "-o " + dir.file("scan.ply") + " --triangles 5k --offset 500000,4000000,100").exitCode, 0);
  ASSERT_EQ(runTool("mtbuild", dir.file("scan.ply") + " -o " + dir.file("scan.mt") + " --crs EPSG:32633 -q").exitCode, 0);
  auto ex = runTool("mtexport", "tiles " + dir.file("scan.mt") + " " + dir.file("tiles"));
  ASSERT_EQ(ex.exitCode, 0) << ex.output;
  EXPECT_NE(ex.output.find("placed on the globe (WGS 84 / UTM zone 33N)"), std::string::npos) << ex.output;
  auto reader = MtFileReader::open(dir.file("scan.mt"));
  const auto& h = reader->header();
  const json ts = json::parse(test::readFile(dir.file("tiles/tileset.json")));
  const json& root = ts["root"];
  EXPECT_EQ(ts["asset"]["extras"]["crs"], "EPSG:32633");
  // The model's box centre (in the tiles' frame, relative to the grid origin) lands where PROJ
  // puts it: easting 500000 northing 4000000 is longitude 15 (zone 33's central meridian), latitude
  // 36.1447180988 (cs2cs EPSG:32633 EPSG:4979); the centre is a few mm off that point (a metre of
  // easting is 1/(0.9996 * 89.9 km) degrees there, of northing 1/(0.9996 * 110.95 km)); height
  // above the WGS84 ellipsoid = z. Where the closed form puts that, within 1 mm.
  double x[3], ecef[3], c[3];
  for (int k = 0; k < 3; ++k) c[k] = 0.5 * (h.boundsMin[k] + h.boundsMax[k]), x[k] = c[k] - h.gridOrigin[k];
  ASSERT_LT(std::abs(c[0] - 500000) + std::abs(c[1] - 4000000), 1.0);
  rootToEcef(root, x, ecef);
  const double lonDeg = 15.0 + (c[0] - 500000) / (0.9996 * 89.9e3), latDeg = 36.1447180988 + (c[1] - 4000000) / (0.9996 * 110.95e3);
  const double lon = lonDeg * M_PI / 180, lat = latDeg * M_PI / 180;
  const double a = 6378137.0, f = 1 / 298.257223563, e2 = f * (2 - f), n = a / std::sqrt(1 - e2 * std::sin(lat) * std::sin(lat));
  const double expected[3] = {(n + c[2]) * std::cos(lat) * std::cos(lon), (n + c[2]) * std::cos(lat) * std::sin(lon),
                              (n * (1 - e2) + c[2]) * std::sin(lat)};
  EXPECT_LT(std::hypot(ecef[0] - expected[0], ecef[1] - expected[1], ecef[2] - expected[2]), 1e-3);
  EXPECT_NEAR(ts["asset"]["extras"]["placement"]["latitude"].get<double>(), latDeg, 1e-8);
  // The model's +z is the local up and its +y north (on the central meridian): the root's columns
  // are unit vectors (x 1/0.9996 for the grid's scale factor) along up and north.
  const json& m = root["transform"];
  const double up[3] = {std::cos(lat) * std::cos(lon), std::cos(lat) * std::sin(lon), std::sin(lat)};
  EXPECT_GT(m[8].get<double>() * up[0] + m[9].get<double>() * up[1] + m[10].get<double>() * up[2], 1 - 1e-9);
  EXPECT_NEAR(m[6].get<double>(), std::cos(lat) / 0.9996, 1e-4);  // north's z component
  // The CLI's --crs overrides (an MT file without one), --model-frame and --crs exclude each
  // other, and a CRS PROJ does not know fails with one line, exit 1, nothing left.
  ASSERT_EQ(runTool("mtbuild", dir.file("scan.ply") + " -o " + dir.file("plain.mt") + " -q").exitCode, 0);
  auto over = runTool("mtexport", "tiles " + dir.file("plain.mt") + " " + dir.file("over") + " --crs EPSG:32633");
  ASSERT_EQ(over.exitCode, 0) << over.output;
  const json ts2 = json::parse(test::readFile(dir.file("over/tileset.json")));
  double ecef2[3];
  auto plain = MtFileReader::open(dir.file("plain.mt"));
  for (int k = 0; k < 3; ++k) x[k] = 0.5 * (plain->header().boundsMin[k] + plain->header().boundsMax[k]) - plain->header().gridOrigin[k];
  rootToEcef(ts2["root"], x, ecef2);
  EXPECT_LT(std::hypot(ecef2[0] - ecef[0], ecef2[1] - ecef[1], ecef2[2] - ecef[2]), 1e-3);
  EXPECT_NE(runTool("mtexport", "tiles " + dir.file("scan.mt") + " " + dir.file("x") + " --crs EPSG:32633 --model-frame").exitCode, 0);
  auto bad = runTool("mtexport", "tiles " + dir.file("scan.mt") + " " + dir.file("bad") + " --crs EPSG:999999");
  EXPECT_EQ(bad.exitCode, 1) << bad.output;
  EXPECT_NE(bad.output.find("EPSG:999999"), std::string::npos) << bad.output;
  EXPECT_EQ(std::count(bad.output.begin(), bad.output.end(), '\n'), 1) << bad.output;
  EXPECT_FALSE(std::filesystem::exists(dir.file("bad")));
}

// A textured file's export: every content carries texture coordinates and its patches' atlases,
// one material and one embedded image each; every stored patch is in one content, so the images
// over all contents are the MT's textured patches, each once; the glTF reader takes them back.
TEST(Tiles, ATexturedBuildsContentsCarryTheirPatchesAtlases) {
  TempDir dir;
  ASSERT_EQ(runTool("mtgen", "-o " + dir.file("tex.ply") + " --triangles 20k --texture charts").exitCode, 0);
  auto built = runTool("mtbuild", dir.file("tex.ply") + " -o " + dir.file("tex.mt") + " -q --patch-triangles 500");
  ASSERT_EQ(built.exitCode, 0) << built.output;
  auto reader = MtFileReader::open(dir.file("tex.mt"));
  ASSERT_TRUE(reader->hasTextures());
  size_t texturedPatches = 0;
  for (const auto& t : reader->textures()) texturedPatches += t.width > 0;
  ASSERT_GT(texturedPatches, 10u);
  for (const std::string codec : {"draco", "none"}) {
    SCOPED_TRACE(codec);
    const std::string out = dir.file("tiles-" + codec);
    auto ex = runTool("mtexport", "tiles " + dir.file("tex.mt") + " " + out + " --codec " + codec);
    ASSERT_EQ(ex.exitCode, 0) << ex.output;
    size_t images = 0, contents = 0;
    for (const auto& e : std::filesystem::directory_iterator(out + "/tiles")) {
      ++contents;
      const std::string bytes = test::readFile(e.path().string());
      uint32_t length = 0;
      std::memcpy(&length, bytes.data() + 12, 4);
      const json doc = json::parse(bytes.substr(20, length));
      ASSERT_TRUE(doc.contains("images")) << e.path();
      EXPECT_EQ(doc["images"].size(), doc["materials"].size());
      images += doc["images"].size();
      // Draco does not code texture coordinates here: meshopt stands in.
      const bool meshopt = doc.contains("extensionsUsed") &&
                           std::find(doc["extensionsUsed"].begin(), doc["extensionsUsed"].end(), "EXT_meshopt_compression") !=
                               doc["extensionsUsed"].end();
      EXPECT_EQ(meshopt, codec == "draco") << e.path();
      struct Check : MeshSink {
        size_t untextured = 0, count = 0;
        void vertices(const InputVertex* p, size_t n, uint64_t) override {
          for (size_t i = 0; i < n; ++i) untextured += p[i].material == kNoMaterial;
          count += n;
        }
        void triangles(const uint32_t*, size_t) override {}
      } check;
      auto mesh = openMesh(e.path().string());
      ASSERT_TRUE(mesh->header().hasTexcoords) << e.path();
      EXPECT_EQ(mesh->header().materials.size(), doc["images"].size());
      mesh->read(check);
      EXPECT_EQ(check.untextured, 0u) << e.path();
      EXPECT_GT(check.count, 0u);
    }
    EXPECT_GT(contents, 3u);
    EXPECT_EQ(images, texturedPatches);
  }
}

}  // namespace
}  // namespace mt
