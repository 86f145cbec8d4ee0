// glTF in and out: the streaming reader (patchstore/io/gltf_reader.cpp) on hand-made files (several
// meshes and node transforms at UTM-like coordinates, indexed and not, .gltf with an external
// buffer, meshopt- and Draco-compressed), its errors on damaged files, and the round trip
// glTF -> mtbuild -> mtextract --error 0 -> glTF, whose triangles must equal the input's as a
// multiset of grid points (bit-exact on the MT grid), in every output variant. Also the MT file's
// metadata block (the CRS).
#include <draco/compression/encode.h>
#include <draco/mesh/triangle_soup_mesh_builder.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "interop/gltf_writer.h"
#include "mtfile/mt_file.h"
#include "patchstore/io/mesh_reader.h"
#include "texture/image_codec.h"
#include "tests/test_support.h"

namespace mt {
namespace {

using nlohmann::json;
using test::runTool;
using test::TempDir;

// Everything a reader delivered.
struct Soup : MeshSink {
  MeshHeader header;
  std::vector<InputVertex> v;
  std::vector<uint32_t> t;
  void begin(const MeshHeader& h) override { header = h; }
  void vertices(const InputVertex* p, size_t n, uint64_t first) override {
    EXPECT_EQ(first, v.size());
    v.insert(v.end(), p, p + n);
  }
  void triangles(const uint32_t* idx, size_t n) override {
    for (size_t i = 0; i < 3 * n; ++i) EXPECT_LT(idx[i], v.size());
    t.insert(t.end(), idx, idx + 3 * n);
  }
};

Soup readMesh(const std::string& path) {
  Soup s;
  openMesh(path)->read(s);
  return s;
}

// The JSON of a GLB or a .gltf.
json gltfJson(const std::string& path) {
  const std::string bytes = test::readFile(path);
  if (bytes.compare(0, 4, "glTF") != 0) return json::parse(bytes);
  uint32_t length = 0;
  std::memcpy(&length, bytes.data() + 12, 4);
  return json::parse(bytes.substr(20, length));
}

// Triangles as grid points, each rotated to start at its smallest corner (orientation kept), sorted.
using GridTri = std::array<int64_t, 9>;
std::vector<GridTri> onGrid(const Soup& s, const double origin[3], double step) {
  std::vector<GridTri> out;
  for (size_t i = 0; i < s.t.size(); i += 3) {
    std::array<std::array<int64_t, 3>, 3> c;
    for (int k = 0; k < 3; ++k)
      for (int a = 0; a < 3; ++a) c[k][a] = int64_t(std::floor((s.v[s.t[i + k]].p[a] - origin[a]) / step + 0.5));
    int m = 0;
    for (int k = 1; k < 3; ++k)
      if (c[k] < c[m]) m = k;
    GridTri g;
    for (int k = 0; k < 3; ++k)
      for (int a = 0; a < 3; ++a) g[3 * k + a] = c[(m + k) % 3][a];
    out.push_back(g);
  }
  std::sort(out.begin(), out.end());
  return out;
}

// A wavy n x n grid at spacing 0.25, positions relative to its mesh node.
struct Grid {
  int n;
  std::vector<float> p;
  std::vector<uint32_t> t;
  explicit Grid(int n_, float phase = 0) : n(n_) {
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i)
        p.insert(p.end(), {0.25f * float(i), 0.25f * float(j), 0.125f * float(std::round(4 * std::sin(0.4 * i + phase) * std::cos(0.3 * j)))});
    for (int j = 0; j + 1 < n; ++j)
      for (int i = 0; i + 1 < n; ++i) {
        uint32_t a = uint32_t(j * n + i), b = a + 1, c = a + uint32_t(n), d = c + 1;
        t.insert(t.end(), {a, b, d, a, d, c});
      }
  }
};

// Builds a glTF document and its binary buffer by hand.
struct Doc {
  json j;
  std::vector<uint8_t> bin;
  Doc() {
    j["asset"] = {{"version", "2.0"}};
    j["buffers"] = json::array();
    j["bufferViews"] = json::array();
    j["accessors"] = json::array();
    j["meshes"] = json::array();
    j["nodes"] = json::array();
  }
  int view(const void* data, size_t size) {
    while (bin.size() % 4) bin.push_back(0);
    j["bufferViews"].push_back({{"buffer", 0}, {"byteOffset", bin.size()}, {"byteLength", size}});
    bin.insert(bin.end(), static_cast<const uint8_t*>(data), static_cast<const uint8_t*>(data) + size);
    return int(j["bufferViews"].size() - 1);
  }
  int accessor(int view, int componentType, size_t count, const char* type) {
    j["accessors"].push_back({{"bufferView", view}, {"componentType", componentType}, {"count", count}, {"type", type}});
    return int(j["accessors"].size() - 1);
  }
  int positions(const std::vector<float>& p) {
    int a = accessor(view(p.data(), p.size() * 4), 5126, p.size() / 3, "VEC3");
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t i = 0; i < p.size(); ++i) lo[i % 3] = std::min(lo[i % 3], p[i]), hi[i % 3] = std::max(hi[i % 3], p[i]);
    j["accessors"][a]["min"] = {lo[0], lo[1], lo[2]};
    j["accessors"][a]["max"] = {hi[0], hi[1], hi[2]};
    return a;
  }
  int mesh(json primitive) {
    j["meshes"].push_back({{"primitives", json::array({primitive})}});
    return int(j["meshes"].size() - 1);
  }
  void node(json n) { j["nodes"].push_back(n); }
  void scene() {
    json roots = json::array();
    for (size_t i = 0; i < j["nodes"].size(); ++i) roots.push_back(i);
    j["scenes"] = json::array({{{"nodes", roots}}});
    j["scene"] = 0;
  }
  std::string glb() {
    while (bin.size() % 4) bin.push_back(0);
    j["buffers"] = json::array({{{"byteLength", bin.size()}}});
    std::string text = j.dump();
    while (text.size() % 4) text += ' ';
    std::string out;
    auto u32 = [&](uint32_t v) { out.append(reinterpret_cast<const char*>(&v), 4); };
    u32(0x46546C67), u32(2), u32(uint32_t(12 + 8 + text.size() + 8 + bin.size()));
    u32(uint32_t(text.size())), u32(0x4E4F534A);
    out += text;
    u32(uint32_t(bin.size())), u32(0x004E4942);
    out.append(reinterpret_cast<const char*>(bin.data()), bin.size());
    return out;
  }
  // .gltf + external .bin named `binName` beside it.
  void writeGltf(const TempDir& dir, const std::string& name, const std::string& binName) {
    j["buffers"] = json::array({{{"byteLength", bin.size()}, {"uri", binName}}});
    test::writeFile(dir.file(name), j.dump(2));
    test::writeFile(dir.file(binName), std::string(bin.begin(), bin.end()));
  }
};

// The test scene: two meshes at UTM-like coordinates (one indexed with uint16, one with uint32
// indices under a rotated and scaled child node), and a non-indexed third one.
Doc sceneDoc() {
  Doc d;
  Grid a(40), b(30, 1.0f), c(12, 2.0f);
  std::vector<uint16_t> ai(a.t.begin(), a.t.end());
  int ma = d.mesh({{"attributes", {{"POSITION", d.positions(a.p)}}},
                   {"indices", d.accessor(d.view(ai.data(), ai.size() * 2), 5123, ai.size(), "SCALAR")}});
  int mb = d.mesh({{"attributes", {{"POSITION", d.positions(b.p)}}},
                   {"indices", d.accessor(d.view(b.t.data(), b.t.size() * 4), 5125, b.t.size(), "SCALAR")}});
  std::vector<float> soup;
  for (uint32_t i : c.t) soup.insert(soup.end(), &c.p[3 * i], &c.p[3 * i] + 3);
  int mc = d.mesh({{"attributes", {{"POSITION", d.positions(soup)}}}});
  d.node({{"mesh", ma}, {"translation", {500000.0, 4000000.0, 100.0}}, {"children", json::array({1})}});
  d.node({{"mesh", mb}, {"translation", {12.0, 0.0, 0.0}}, {"rotation", {0.0, 0.0, 0.38268343236508978, 0.92387953251128674}},
          {"scale", {1.5, 1.5, 1.5}}});
  d.node({{"mesh", mc}, {"translation", {500000.0, 4000020.0, 100.0}}});
  d.j["scenes"] = json::array({{{"nodes", {0, 2}}}});
  d.j["scene"] = 0;
  return d;
}

TEST(GltfReader, ReadsMeshesPrimitivesAndNodeTransformsInDouble) {
  TempDir dir;
  Doc d = sceneDoc();
  test::writeFile(dir.file("scene.glb"), d.glb());
  Soup s = readMesh(dir.file("scene.glb"));
  EXPECT_EQ(s.header.format, MeshFormat::Glb);
  EXPECT_TRUE(s.header.doublePrecision);
  EXPECT_EQ(s.t.size() / 3, size_t(2 * 39 * 39 + 2 * 29 * 29 + 2 * 11 * 11));
  EXPECT_EQ(s.v.size(), size_t(40 * 40 + 30 * 30 + 2 * 11 * 11 * 3));
  // Mesh A's corner (1,1) at exactly 500000.25, 4000000.25: the node translation in double.
  EXPECT_EQ(s.v[41].p[0], 500000.25);
  EXPECT_EQ(s.v[41].p[1], 4000000.25);
  // Mesh B under A: rotated 45 degrees about z, scaled 1.5, moved by 12 in A's frame.
  const double r = 0.25 * 1.5 * std::sqrt(0.5);
  EXPECT_NEAR(s.v[1600 + 1].p[0], 500012.0 + r, 1e-9);
  EXPECT_NEAR(s.v[1600 + 1].p[1], 4000000.0 + r, 1e-9);

  // The same document as .gltf with an external buffer reads the same.
  d.writeGltf(dir, "scene.gltf", "scene-data.bin");
  Soup g = readMesh(dir.file("scene.gltf"));
  EXPECT_EQ(g.header.format, MeshFormat::Gltf);
  ASSERT_EQ(g.v.size(), s.v.size());
  for (size_t i = 0; i < s.v.size(); ++i)
    for (int a = 0; a < 3; ++a) ASSERT_EQ(g.v[i].p[a], s.v[i].p[a]);
  EXPECT_EQ(g.t, s.t);
}

TEST(GltfReader, ReadsDracoAndMeshoptCompressedPrimitives) {
  TempDir dir;
  Grid a(25);
  // Draco, lossless (no position quantization), in a GLB with KHR_draco_mesh_compression.
  draco::TriangleSoupMeshBuilder builder;
  builder.Start(int(a.t.size() / 3));
  const int pos = builder.AddAttribute(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32);
  for (size_t f = 0; f < a.t.size() / 3; ++f)
    builder.SetAttributeValuesForFace(pos, draco::FaceIndex(uint32_t(f)), &a.p[3 * a.t[3 * f]], &a.p[3 * a.t[3 * f + 1]],
                                      &a.p[3 * a.t[3 * f + 2]]);
  std::unique_ptr<draco::Mesh> mesh = builder.Finalize();
  ASSERT_TRUE(mesh);
  draco::Encoder encoder;
  encoder.SetSpeedOptions(5, 5);
  draco::EncoderBuffer buffer;
  ASSERT_TRUE(encoder.EncodeMeshToBuffer(*mesh, &buffer).ok());
  const uint32_t uid = mesh->attribute(pos)->unique_id();
  Doc d;
  int bv = d.view(buffer.data(), buffer.size());
  d.j["accessors"].push_back({{"componentType", 5126}, {"count", mesh->num_points()}, {"type", "VEC3"},
                              {"min", {0, 0, -0.5}}, {"max", {6, 6, 0.5}}});
  d.j["accessors"].push_back({{"componentType", 5125}, {"count", a.t.size()}, {"type", "SCALAR"}});
  d.mesh({{"attributes", {{"POSITION", 0}}}, {"indices", 1},
          {"extensions", {{"KHR_draco_mesh_compression", {{"bufferView", bv}, {"attributes", {{"POSITION", uid}}}}}}}});
  d.node({{"mesh", 0}, {"translation", {500000.0, 4000000.0, 0.0}}});
  d.scene();
  d.j["extensionsUsed"] = json::array({"KHR_draco_mesh_compression"});
  d.j["extensionsRequired"] = json::array({"KHR_draco_mesh_compression"});
  test::writeFile(dir.file("draco.glb"), d.glb());
  Soup draco = readMesh(dir.file("draco.glb"));

  // The plain reference.
  Doc plain;
  plain.mesh({{"attributes", {{"POSITION", plain.positions(a.p)}}},
              {"indices", plain.accessor(plain.view(a.t.data(), a.t.size() * 4), 5125, a.t.size(), "SCALAR")}});
  plain.node({{"mesh", 0}, {"translation", {500000.0, 4000000.0, 0.0}}});
  plain.scene();
  test::writeFile(dir.file("plain.glb"), plain.glb());
  Soup ref = readMesh(dir.file("plain.glb"));
  const double origin[3] = {499990, 3999990, -10};
  EXPECT_EQ(onGrid(draco, origin, 1.0 / 1024), onGrid(ref, origin, 1.0 / 1024));

  // Meshopt: our writer's EXT_meshopt_compression output, with and without quantization.
  std::vector<double> p(ref.v.size() * 3);
  for (size_t i = 0; i < ref.v.size(); ++i)
    for (int k = 0; k < 3; ++k) p[3 * i + k] = ref.v[i].p[k];
  interop::GltfMeshView view;
  view.vertexCount = ref.v.size();
  view.triangleCount = ref.t.size() / 3;
  view.positions = p.data();
  view.triangles = ref.t.data();
  interop::GltfOptions o;
  o.meshopt = true;
  interop::writeGltfFile(dir.file("meshopt.glb"), view, o);
  EXPECT_EQ(onGrid(readMesh(dir.file("meshopt.glb")), origin, 1.0 / 1024), onGrid(ref, origin, 1.0 / 1024));
  interop::writeGltfFile(dir.file("meshopt.gltf"), view, o);
  EXPECT_EQ(onGrid(readMesh(dir.file("meshopt.gltf")), origin, 1.0 / 1024), onGrid(ref, origin, 1.0 / 1024));
}

// glTF in -> MT -> glTF cut at full resolution: the input's triangles, as a multiset, bit-exact on
// the MT grid, for every output variant; the CRS given to mtbuild is in the file, in mtinfo and in
// the glTF's asset.extras.
TEST(GltfRoundTrip, FullResolutionCutEqualsTheInputOnTheGrid) {
  TempDir dir;
  test::writeFile(dir.file("scene.glb"), sceneDoc().glb());
  auto built = runTool("mtbuild", dir.file("scene.glb") + " -o " + dir.file("scene.mt") + " --crs EPSG:32633 -q");
  ASSERT_EQ(built.exitCode, 0) << built.output;
  auto reader = MtFileReader::open(dir.file("scene.mt"));
  EXPECT_EQ(reader->crs(), "EPSG:32633");
  EXPECT_GT(reader->header().metadataSize, 0u);
  const double* origin = reader->header().gridOrigin;
  const double step = reader->header().gridStep;
  EXPECT_EQ(reader->header().weldedTriangles, 0u);
  const auto input = onGrid(readMesh(dir.file("scene.glb")), origin, step);
  auto info = runTool("mtinfo", dir.file("scene.mt"));
  EXPECT_NE(info.output.find("EPSG:32633"), std::string::npos) << info.output;

  for (const std::string variant : {"cut.glb", "cut.gltf", "cut-meshopt.glb --meshopt", "cut-q.glb --quantize",
                                    "cut-qm.gltf --quantize --meshopt"}) {
    SCOPED_TRACE(variant);
    auto ex = runTool("mtextract", dir.file("scene.mt") + " --error 0 -o " + dir.path() + "/" + variant);
    ASSERT_EQ(ex.exitCode, 0) << ex.output;
    EXPECT_EQ(ex.output.find("warning"), std::string::npos) << ex.output;
    const std::string out = dir.file(variant.substr(0, variant.find(' ')));
    EXPECT_EQ(onGrid(readMesh(out), origin, step), input);
    // The CRS travels with the cut, and so does the offset: as the mesh node's translation (a
    // JSON double at UTM coordinates), the stored positions being small differences from it.
    const json doc = gltfJson(out);
    EXPECT_EQ(doc["asset"]["extras"]["crs"], "EPSG:32633");
    const json& node = doc["nodes"][0];
    ASSERT_TRUE(node.contains("translation")) << node.dump();
    EXPECT_NEAR(node["translation"][0].get<double>(), 500000, 100);
    EXPECT_NEAR(node["translation"][1].get<double>(), 4000000, 100);
    EXPECT_NEAR(node["translation"][2].get<double>(), 100, 100);
    const json& pos = doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"].get<int>()];
    const double scale = node.contains("scale") ? node["scale"][0].get<double>() : 1.0;
    for (int a = 0; a < 3; ++a) EXPECT_LT(std::max(std::abs(pos["min"][a].get<double>()), std::abs(pos["max"][a].get<double>())) * scale, 100.0);
  }
  // The glTF options are refused for PLY, and unknown extensions still are.
  auto ply = runTool("mtextract", dir.file("scene.mt") + " --error 0 --meshopt -o " + dir.file("cut.ply"));
  EXPECT_EQ(ply.exitCode, 1);
  EXPECT_NE(ply.output.find("--meshopt and --quantize are for glTF output"), std::string::npos) << ply.output;
  auto xyz = runTool("mtextract", dir.file("scene.mt") + " --error 0 -o " + dir.file("cut.xyz"));
  EXPECT_EQ(xyz.exitCode, 1);
  EXPECT_NE(xyz.output.find("supported: .ply, .glb, .gltf"), std::string::npos) << xyz.output;
  EXPECT_FALSE(test::fileExists(dir.file("cut.ply")));
  // A coarser cut is smaller and still reads.
  auto coarse = runTool("mtextract", dir.file("scene.mt") + " --triangles 2000 -o " + dir.file("coarse.glb"));
  ASSERT_EQ(coarse.exitCode, 0) << coarse.output;
  EXPECT_LT(readMesh(dir.file("coarse.glb")).t.size(), input.size() * 3);
}

// The colour of every vertex, keyed by its grid point.
std::map<std::array<int64_t, 3>, std::array<uint8_t, 4>> coloursOnGrid(const Soup& s, const double origin[3], double step) {
  std::map<std::array<int64_t, 3>, std::array<uint8_t, 4>> out;
  for (const InputVertex& v : s.v) {
    std::array<int64_t, 3> q;
    for (int a = 0; a < 3; ++a) q[a] = int64_t(std::floor((v.p[a] - origin[a]) / step + 0.5));
    out[q] = {v.c[0], v.c[1], v.c[2], v.c[3]};
  }
  return out;
}

TEST(GltfWriter, EveryGltfWeWriteCarriesTheMtsColours) {
  // A scan with per-vertex colours: every cut variant and every tile content has COLOR_0, and the
  // colours read back are the MT's (the PLY cut's) at the same grid points.
  TempDir dir;
  ASSERT_EQ(runTool("mtgen", "-o " + dir.file("scan.ply") + " --triangles 6k --colors").exitCode, 0);
  // meshopt's simplifier keeps every vertex's input colour, so a grid point has one colour at every
  // level (the colour-aware quadric, the default for coloured input, blends kept vertices' colours).
  auto built = runTool("mtbuild", dir.file("scan.ply") + " -o " + dir.file("scan.mt") + " -q --patch-triangles 500 --simplifier meshopt");
  ASSERT_EQ(built.exitCode, 0) << built.output;
  auto reader = MtFileReader::open(dir.file("scan.mt"));
  const double* origin = reader->header().gridOrigin;
  const double step = reader->header().gridStep;
  ASSERT_EQ(runTool("mtextract", dir.file("scan.mt") + " --error 0 -o " + dir.file("cut.ply")).exitCode, 0);
  const Soup ply = readMesh(dir.file("cut.ply"));
  ASSERT_TRUE(ply.header.hasColors);
  const auto reference = coloursOnGrid(ply, origin, step);
  size_t distinct = 0;
  for (const auto& [q, c] : reference) distinct += c != reference.begin()->second;
  ASSERT_GT(distinct, reference.size() / 4) << "the scan's colours are not varied enough to test";

  std::vector<std::string> files;
  for (const std::string variant : {"cut.glb", "cut.gltf", "cut-m.glb --meshopt", "cut-q.glb --quantize", "cut-qm.gltf --quantize --meshopt"}) {
    auto ex = runTool("mtextract", dir.file("scan.mt") + " --error 0 -o " + dir.path() + "/" + variant);
    ASSERT_EQ(ex.exitCode, 0) << ex.output;
    files.push_back(dir.file(variant.substr(0, variant.find(' '))));
  }
  for (const std::string variant : {"tiles", "tiles-m --codec meshopt", "tiles-n --codec none", "tiles-f --no-quantize"}) {
    auto ex = runTool("mtexport", "tiles " + dir.file("scan.mt") + " " + dir.path() + "/" + variant);
    ASSERT_EQ(ex.exitCode, 0) << ex.output;
    for (auto& e : std::filesystem::directory_iterator(dir.file(variant.substr(0, variant.find(' ')) + "/tiles")))
      files.push_back(e.path().string());
  }
  ASSERT_GT(files.size(), 10u);
  for (const std::string& f : files) {
    SCOPED_TRACE(f);
    const json doc = gltfJson(f);
    EXPECT_TRUE(doc["meshes"][0]["primitives"][0]["attributes"].contains("COLOR_0"));
    Soup s = readMesh(f);
    ASSERT_TRUE(s.header.hasColors);
    // A tile content is in the tileset's frame: relative to the grid origin, +Z up turned to glTF's +Y up.
    if (f.find("/tiles/") != std::string::npos)
      for (InputVertex& v : s.v) {
        const double r[3] = {v.p[0], v.p[1], v.p[2]};
        v.p[0] = origin[0] + r[0], v.p[1] = origin[1] - r[2], v.p[2] = origin[2] + r[1];
      }
    size_t wrong = 0;
    for (const auto& [q, c] : coloursOnGrid(s, origin, step)) {
      auto it = reference.find(q);
      wrong += it == reference.end() || it->second != c;
    }
    EXPECT_EQ(wrong, 0u);
  }
}

TEST(MtMetadata, NoCrsMeansNoBlockAndADamagedBlockIsRefused) {
  TempDir dir;
  test::writeFile(dir.file("scene.glb"), sceneDoc().glb());
  ASSERT_EQ(runTool("mtbuild", dir.file("scene.glb") + " -o " + dir.file("plain.mt") + " -q").exitCode, 0);
  ASSERT_EQ(runTool("mtbuild", dir.file("scene.glb") + " -o " + dir.file("crs.mt") + " --crs EPSG:32633 -q").exitCode, 0);
  auto plain = MtFileReader::open(dir.file("plain.mt"));
  EXPECT_EQ(plain->header().metadataSize, 0u);
  EXPECT_EQ(plain->header().metadataOffset, 0u);
  EXPECT_EQ(plain->crs(), "");
  EXPECT_TRUE(plain->metadata().empty());
  auto crs = MtFileReader::open(dir.file("crs.mt"));
  // The block sits between the patch index and the footer: the files differ by it (and the header).
  EXPECT_EQ(crs->fileSize(), plain->fileSize() + crs->header().metadataSize);
  EXPECT_EQ(crs->header().metadataOffset, crs->header().patchesOffset + crs->header().patchCount * sizeof(format::PatchRecord));
  // A flipped byte inside the block: the footer checksum covers it.
  std::string bytes = test::readFile(dir.file("crs.mt"));
  bytes[size_t(crs->header().metadataOffset) + 9] ^= 0x20;
  test::writeFile(dir.file("bad.mt"), bytes);
  try {
    MtFileReader::open(dir.file("bad.mt"));
    FAIL() << "a damaged metadata block was accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Corruption);
    EXPECT_NE(std::string(e.what()).find("checksum"), std::string::npos) << e.what();
  }
  auto help = runTool("mtbuild", "--help");
  EXPECT_NE(help.output.find("--crs"), std::string::npos);
  // mtgen --offset: positions moved in double; only binary PLY can hold them.
  ASSERT_EQ(runTool("mtgen", "-o " + dir.file("a.ply") + " --triangles 2k").exitCode, 0);
  ASSERT_EQ(runTool("mtgen", "-o " + dir.file("b.ply") + " --triangles 2k --offset 500000,4000000,100.5").exitCode, 0);
  Soup a = readMesh(dir.file("a.ply")), b = readMesh(dir.file("b.ply"));
  ASSERT_EQ(a.v.size(), b.v.size());
  EXPECT_TRUE(b.header.doublePrecision);
  for (size_t i = 0; i < a.v.size(); i += 97) {
    EXPECT_NEAR(b.v[i].p[0] - 500000.0, a.v[i].p[0], 1e-6);
    EXPECT_NEAR(b.v[i].p[1] - 4000000.0, a.v[i].p[1], 1e-6);
    EXPECT_NEAR(b.v[i].p[2] - 100.5, a.v[i].p[2], 1e-6);
  }
  auto obj = runTool("mtgen", "-o " + dir.file("c.obj") + " --triangles 2k --offset 1,2,3");
  EXPECT_EQ(obj.exitCode, 1);
  EXPECT_NE(obj.output.find("--offset needs --format ply"), std::string::npos) << obj.output;
  auto bad = runTool("mtgen", "-o " + dir.file("d.ply") + " --triangles 2k --offset 1,2");
  EXPECT_EQ(bad.exitCode, 1);
  EXPECT_NE(bad.output.find("--offset wants X,Y,Z"), std::string::npos) << bad.output;
}

// Damaged and wrong files: one clear error naming the file and where.
TEST(GltfReader, BadFilesGiveOneClearErrorNamingTheFileAndWhere) {
  TempDir dir;
  Grid a(5);
  auto good = [&] {
    Doc d;
    d.mesh({{"attributes", {{"POSITION", d.positions(a.p)}}},
            {"indices", d.accessor(d.view(a.t.data(), a.t.size() * 4), 5125, a.t.size(), "SCALAR")}});
    d.node({{"mesh", 0}});
    d.scene();
    return d;
  };
  struct Case {
    std::string name, bytes, expect;
  };
  std::vector<Case> cases;
  {
    std::string g = good().glb();
    cases.push_back({"truncated.glb", g.substr(0, g.size() - 10), "differs from the file's"});
    std::string v = g;
    v[4] = 3;
    cases.push_back({"version.glb", v, "GLB version 3 at byte offset 4"});
  }
  {
    Doc d = good();
    std::string g = d.glb();
    const size_t brace = g.find("{");
    g[brace + 1] = '!';  // JSON syntax error right after the opening brace
    cases.push_back({"json.glb", g, "bad JSON at byte offset 21"});
  }
  {
    Doc d = good();
    d.j["accessors"][1]["count"] = 1000;  // runs past its view
    cases.push_back({"range.glb", d.glb(), "accessor 1 (indices of mesh 0 primitive 0): 1000 elements"});
  }
  {
    Doc d = good();
    std::vector<uint32_t> t = a.t;
    t[7] = 99;
    d.bin.clear();
    d.j["bufferViews"] = json::array();
    d.view(a.p.data(), a.p.size() * 4);
    d.view(t.data(), t.size() * 4);
    cases.push_back({"index.glb", d.glb(), "element 7: index 99 >= the primitive's 25 vertices, at byte offset"});
  }
  {
    Doc d = good();
    std::vector<float> p = a.p;
    p[3 * 6 + 1] = NAN;
    d.bin.clear();
    d.j["bufferViews"] = json::array();
    d.view(p.data(), p.size() * 4);
    d.view(a.t.data(), a.t.size() * 4);
    cases.push_back({"nan.glb", d.glb(), "accessor 0 (POSITION of mesh 0 primitive 0) element 6: non-finite position at byte offset"});
  }
  {
    Doc d = good();
    d.j["accessors"][0]["sparse"] = {{"count", 1}};
    cases.push_back({"sparse.glb", d.glb(), "sparse accessors are not read"});
  }
  {
    Doc d = good();
    d.j["meshes"][0]["primitives"][0]["indices"] = 7;
    cases.push_back({"missing.glb", d.glb(), "refers to accessors 7, which does not exist"});
  }
  {
    Doc d = good();
    d.j["extensionsRequired"] = json::array({"KHR_gaussian_splatting"});
    cases.push_back({"ext.glb", d.glb(), "requires the extension KHR_gaussian_splatting"});
  }
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string path = dir.file(c.name);
    test::writeFile(path, c.bytes);
    try {
      Soup s;
      openMesh(path)->read(s);
      ADD_FAILURE() << "no error";
    } catch (const Error& e) {
      const std::string m = e.what();
      EXPECT_EQ(m.rfind(path + ": ", 0), 0u) << m;
      EXPECT_NE(m.find(c.expect), std::string::npos) << m;
      EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    }
  }
  // A .gltf whose buffer file is missing names that file.
  good().writeGltf(dir, "nobin.gltf", "nobin.bin");
  std::remove(dir.file("nobin.bin").c_str());
  try {
    readMesh(dir.file("nobin.gltf"));
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("nobin.bin"), std::string::npos) << e.what();
  }
  // mtbuild says the same and leaves nothing.
  auto r = runTool("mtbuild", dir.file("index.glb") + " -o " + dir.file("x.mt") + " -q");
  EXPECT_EQ(r.exitCode, 1);
  EXPECT_NE(r.output.find("index 99"), std::string::npos) << r.output;
  EXPECT_FALSE(test::fileExists(dir.file("x.mt")));
}

// ---- Textures ---------------------------------------------------------------------------------

// A smooth test picture (JPEG keeps it within a few levels): each texel's colour from its position.
tex::RgbImage testPicture(int w, int h, int seed) {
  tex::RgbImage im(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      uint8_t* p = im.pixel(x, y);
      p[0] = uint8_t(128 + 100 * std::sin(0.21 * x + seed));
      p[1] = uint8_t(128 + 100 * std::cos(0.17 * y + 2 * seed));
      p[2] = uint8_t(128 + 90 * std::sin(0.11 * (x + y)));
    }
  return im;
}

// Texture coordinates of a Grid in glTF's convention (v down), inside [0.05, 0.95].
std::vector<float> gridUV(const Grid& g) {
  std::vector<float> uv;
  for (int j = 0; j < g.n; ++j)
    for (int i = 0; i < g.n; ++i) uv.insert(uv.end(), {0.05f + 0.9f * float(i) / float(g.n - 1), 0.05f + 0.9f * float(j) / float(g.n - 1)});
  return uv;
}

// Two textured meshes (a PNG in a buffer view; a JPEG beside the file, its uri %-escaped) and an
// untextured one, at UTM-like coordinates under node transforms.
Doc texturedDoc(const TempDir& dir) {
  Doc d;
  Grid a(30), b(20, 1.0f), c(10, 2.0f);
  const std::vector<uint8_t> png = tex::encodePng(testPicture(64, 48, 1));
  const std::vector<uint8_t> jpeg = tex::encodeJpeg(testPicture(40, 40, 2), 95);
  test::writeFile(dir.file("tex b.jpg"), std::string(jpeg.begin(), jpeg.end()));
  const int pngView = d.view(png.data(), png.size());
  d.j["images"] = json::array({{{"bufferView", pngView}, {"mimeType", "image/png"}}, {{"uri", "tex%20b.jpg"}}});
  d.j["textures"] = json::array({{{"source", 0}}, {{"source", 1}}});
  d.j["materials"] = json::array({{{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}}},
                                  {{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 1}, {"texCoord", 1}}}}}},
                                  {{"pbrMetallicRoughness", {{"baseColorFactor", {0.5, 0.5, 0.5, 1.0}}}}}});
  auto uvAccessor = [&](const Grid& g) {
    const std::vector<float> uv = gridUV(g);
    return d.accessor(d.view(uv.data(), uv.size() * 4), 5126, uv.size() / 2, "VEC2");
  };
  const int ua = uvAccessor(a), ub = uvAccessor(b);
  int ma = d.mesh({{"attributes", {{"POSITION", d.positions(a.p)}, {"TEXCOORD_0", ua}}},
                   {"indices", d.accessor(d.view(a.t.data(), a.t.size() * 4), 5125, a.t.size(), "SCALAR")},
                   {"material", 0}});
  // Material 1 reads TEXCOORD_1 (TEXCOORD_0 is there too, and is not its coordinates).
  int mb = d.mesh({{"attributes", {{"POSITION", d.positions(b.p)}, {"TEXCOORD_0", ua}, {"TEXCOORD_1", ub}}},
                   {"indices", d.accessor(d.view(b.t.data(), b.t.size() * 4), 5125, b.t.size(), "SCALAR")},
                   {"material", 1}});
  const std::vector<float> other(2 * size_t(b.n * b.n), 0.9f);
  d.j["meshes"][size_t(mb)]["primitives"][0]["attributes"]["TEXCOORD_0"] = d.accessor(d.view(other.data(), other.size() * 4), 5126, other.size() / 2, "VEC2");
  int mc = d.mesh({{"attributes", {{"POSITION", d.positions(c.p)}}},
                   {"indices", d.accessor(d.view(c.t.data(), c.t.size() * 4), 5125, c.t.size(), "SCALAR")},
                   {"material", 2}});
  d.node({{"mesh", ma}, {"translation", {500000.0, 4000000.0, 100.0}}, {"children", json::array({1})}});
  d.node({{"mesh", mb}, {"translation", {9.0, 0.0, 0.0}}, {"rotation", {0.0, 0.0, 0.38268343236508978, 0.92387953251128674}},
          {"scale", {1.5, 1.5, 1.5}}});
  d.node({{"mesh", mc}, {"translation", {500000.0, 4000020.0, 100.0}}});
  d.j["scenes"] = json::array({{{"nodes", {0, 2}}}});
  d.j["scene"] = 0;
  return d;
}

// Per triangle (as grid points, rotated to its smallest corner): its corners' texture coordinates
// in texels of its image (v up, as readers deliver), and the image. Reads with the reader alive,
// so embedded images are still where its materials say.
struct TexturedTri {
  double texel[6];
  const tex::RgbImage* image = nullptr;
};
struct TexturedSoup {
  std::vector<tex::RgbImage> images;
  std::map<GridTri, TexturedTri> tris;
  size_t untextured = 0, vertices = 0;
};
void readTextured(const std::string& path, const double origin[3], double step, TexturedSoup& out) {
  auto reader = openMesh(path);
  Soup s;
  reader->read(s);
  ASSERT_TRUE(s.header.hasTexcoords) << path;
  out.images.clear();
  for (const InputMaterial& m : s.header.materials)
    out.images.push_back(m.texture.empty() ? tex::RgbImage() : tex::readImageFile(m.texture));
  out.vertices = s.v.size();
  for (size_t i = 0; i < s.t.size(); i += 3) {
    std::array<std::array<int64_t, 3>, 3> c;
    for (int k = 0; k < 3; ++k)
      for (int a = 0; a < 3; ++a) c[k][a] = int64_t(std::floor((s.v[s.t[i + k]].p[a] - origin[a]) / step + 0.5));
    int m = 0;
    for (int k = 1; k < 3; ++k)
      if (c[k] < c[m]) m = k;
    GridTri g;
    TexturedTri t;
    const uint32_t material = s.v[s.t[i]].material;
    for (int k = 0; k < 3; ++k) EXPECT_EQ(s.v[s.t[i + k]].material, material);
    for (int k = 0; k < 3; ++k) {
      const InputVertex& v = s.v[s.t[i + (m + k) % 3]];
      for (int a = 0; a < 3; ++a) g[3 * k + a] = c[(m + k) % 3][a];
      if (material != kNoMaterial) {
        const tex::RgbImage& im = out.images.at(material);
        t.texel[2 * k] = double(v.uv[0]) * im.width;
        t.texel[2 * k + 1] = double(v.uv[1]) * im.height;
      }
    }
    if (material == kNoMaterial) {
      ++out.untextured;
      continue;
    }
    t.image = &out.images[material];
    EXPECT_TRUE(out.tris.emplace(g, t).second) << "a triangle twice";
  }
}

TEST(GltfReader, ReadsBaseColourTexturesFromBufferViewsAndFiles) {
  TempDir dir;
  test::writeFile(dir.file("tex.glb"), texturedDoc(dir).glb());
  auto reader = openMesh(dir.file("tex.glb"));
  Soup s;
  reader->read(s);
  ASSERT_TRUE(s.header.hasTexcoords);
  ASSERT_EQ(s.header.materials.size(), 2u);  // the untextured material plays no part
  EXPECT_EQ(tex::readImageFile(s.header.materials[0].texture).width, 64);
  EXPECT_EQ(s.header.materials[1].texture, dir.file("tex b.jpg"));
  // Mesh a's vertex (i, j) = (3, 2): u = 0.05 + 0.9 * 3 / 29, v flipped to up.
  const InputVertex& v = s.v[2 * 30 + 3];
  EXPECT_EQ(v.material, 0u);
  EXPECT_FLOAT_EQ(v.uv[0], 0.05f + 0.9f * 3.0f / 29.0f);
  EXPECT_NEAR(v.uv[1], 1.0 - (0.05 + 0.9 * 2.0 / 29.0), 1e-6);
  EXPECT_EQ(s.v[900].material, 1u);           // mesh b reads TEXCOORD_1
  EXPECT_NEAR(s.v[900 + 5].uv[0], 0.05 + 0.9 * 5 / 19.0, 1e-6);
  EXPECT_EQ(s.v.back().material, kNoMaterial);  // mesh c
  const std::string embedded = s.header.materials[0].texture;
  reader.reset();
  EXPECT_FALSE(test::fileExists(embedded)) << "the reader's copy of an embedded image outlives it";

  // The JPEG as a base64 data URI, in a .gltf with an external .bin: the same texels.
  Doc d = texturedDoc(dir);
  const std::string jpeg = test::readFile(dir.file("tex b.jpg"));
  static const char* k64 = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string b64;
  for (size_t i = 0; i < jpeg.size(); i += 3) {
    uint32_t n = uint32_t(uint8_t(jpeg[i])) << 16;
    if (i + 1 < jpeg.size()) n |= uint32_t(uint8_t(jpeg[i + 1])) << 8;
    if (i + 2 < jpeg.size()) n |= uint8_t(jpeg[i + 2]);
    b64 += k64[(n >> 18) & 63];
    b64 += k64[(n >> 12) & 63];
    b64 += i + 1 < jpeg.size() ? k64[(n >> 6) & 63] : '=';
    b64 += i + 2 < jpeg.size() ? k64[n & 63] : '=';
  }
  d.j["images"][1] = {{"uri", "data:image/jpeg;base64," + b64}};
  d.writeGltf(dir, "uri.gltf", "uri.bin");
  Soup u;
  openMesh(dir.file("uri.gltf"))->read(u);
  ASSERT_EQ(u.header.materials.size(), 2u);
  EXPECT_EQ(u.v.size(), s.v.size());
  EXPECT_EQ(u.v[900 + 5].material, 1u);
  EXPECT_EQ(u.v[900 + 5].uv[0], s.v[900 + 5].uv[0]);
  EXPECT_FALSE(test::fileExists(u.header.materials[1].texture));  // removed with its reader
  const tex::RgbImage fromUri = [&] {
    auto r = openMesh(dir.file("uri.gltf"));
    return tex::readImageFile(r->header().materials[1].texture);
  }();
  const tex::RgbImage fromFile = tex::readImageFile(dir.file("tex b.jpg"));
  EXPECT_EQ(fromUri.rgb, fromFile.rgb);
}

// A Draco primitive's TEXCOORD_0 (KHR_draco_mesh_compression names it among its attributes) is
// read like a plain one: every vertex gets its grid vertex's coordinates, v flipped up.
TEST(GltfReader, ReadsTextureCoordinatesOfDracoPrimitives) {
  TempDir dir;
  Grid a(12);
  const std::vector<float> uv = gridUV(a);
  draco::TriangleSoupMeshBuilder builder;
  builder.Start(int(a.t.size() / 3));
  const int pos = builder.AddAttribute(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32);
  const int tc = builder.AddAttribute(draco::GeometryAttribute::TEX_COORD, 2, draco::DT_FLOAT32);
  for (size_t f = 0; f < a.t.size() / 3; ++f) {
    const uint32_t* c = &a.t[3 * f];
    builder.SetAttributeValuesForFace(pos, draco::FaceIndex(uint32_t(f)), &a.p[3 * c[0]], &a.p[3 * c[1]], &a.p[3 * c[2]]);
    builder.SetAttributeValuesForFace(tc, draco::FaceIndex(uint32_t(f)), &uv[2 * c[0]], &uv[2 * c[1]], &uv[2 * c[2]]);
  }
  std::unique_ptr<draco::Mesh> mesh = builder.Finalize();
  ASSERT_TRUE(mesh);
  draco::Encoder encoder;
  encoder.SetSpeedOptions(5, 5);
  draco::EncoderBuffer buffer;
  ASSERT_TRUE(encoder.EncodeMeshToBuffer(*mesh, &buffer).ok());
  Doc d;
  const std::vector<uint8_t> png = tex::encodePng(testPicture(16, 16, 3));
  const int pngView = d.view(png.data(), png.size());
  d.j["images"] = json::array({{{"bufferView", pngView}, {"mimeType", "image/png"}}});
  d.j["textures"] = json::array({{{"source", 0}}});
  d.j["materials"] = json::array({{{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", 0}}}}}}});
  const int bv = d.view(buffer.data(), buffer.size());
  d.j["accessors"].push_back({{"componentType", 5126}, {"count", mesh->num_points()}, {"type", "VEC3"},
                              {"min", {0, 0, -0.5}}, {"max", {3, 3, 0.5}}});
  d.j["accessors"].push_back({{"componentType", 5126}, {"count", mesh->num_points()}, {"type", "VEC2"}});
  d.j["accessors"].push_back({{"componentType", 5125}, {"count", a.t.size()}, {"type", "SCALAR"}});
  d.mesh({{"attributes", {{"POSITION", 0}, {"TEXCOORD_0", 1}}}, {"indices", 2}, {"material", 0},
          {"extensions", {{"KHR_draco_mesh_compression", {{"bufferView", bv},
                                                         {"attributes", {{"POSITION", mesh->attribute(pos)->unique_id()},
                                                                         {"TEXCOORD_0", mesh->attribute(tc)->unique_id()}}}}}}}});
  d.node({{"mesh", 0}});
  d.scene();
  d.j["extensionsUsed"] = json::array({"KHR_draco_mesh_compression"});
  d.j["extensionsRequired"] = json::array({"KHR_draco_mesh_compression"});
  test::writeFile(dir.file("draco.glb"), d.glb());
  Soup s = readMesh(dir.file("draco.glb"));
  ASSERT_TRUE(s.header.hasTexcoords);
  ASSERT_EQ(s.t.size(), a.t.size());
  for (const InputVertex& v : s.v) {
    const int i = int(std::lround(v.p[0] / 0.25)), j = int(std::lround(v.p[1] / 0.25));
    ASSERT_TRUE(i >= 0 && i < a.n && j >= 0 && j < a.n);
    EXPECT_EQ(v.material, 0u);
    EXPECT_FLOAT_EQ(v.uv[0], uv[2 * size_t(j * a.n + i)]);
    EXPECT_NEAR(v.uv[1], 1.0 - double(uv[2 * size_t(j * a.n + i) + 1]), 1e-6);
  }
}

TEST(GltfTextures, TexturedGltfToMtToGltfKeepsTrianglesAndTexels) {
  TempDir dir;
  test::writeFile(dir.file("tex.glb"), texturedDoc(dir).glb());
  auto built = runTool("mtbuild", dir.file("tex.glb") + " -o " + dir.file("tex.mt") + " -q --patch-triangles 300");
  ASSERT_EQ(built.exitCode, 0) << built.output;
  auto reader = MtFileReader::open(dir.file("tex.mt"));
  ASSERT_TRUE(reader->hasTextures());
  const double* origin = reader->header().gridOrigin;
  const double step = reader->header().gridStep;
  const auto input = onGrid(readMesh(dir.file("tex.glb")), origin, step);
  TexturedSoup in;
  readTextured(dir.file("tex.glb"), origin, step, in);
  ASSERT_EQ(in.untextured, 2u * 9 * 9);
  for (const std::string variant : {"cut.glb", "cut.gltf", "cut-meshopt.glb --meshopt", "cut-q.glb --quantize"}) {
    SCOPED_TRACE(variant);
    auto ex = runTool("mtextract", dir.file("tex.mt") + " --error 0 -o " + dir.path() + "/" + variant);
    ASSERT_EQ(ex.exitCode, 0) << ex.output;
    EXPECT_EQ(ex.output.find("warning"), std::string::npos) << ex.output;
    const std::string out = dir.file(variant.substr(0, variant.find(' ')));
    // The triangles, bit-exact on the grid.
    EXPECT_EQ(onGrid(readMesh(out), origin, step), input);
    // A material and an embedded image per patch atlas.
    const json doc = gltfJson(out);
    ASSERT_TRUE(doc.contains("materials"));
    EXPECT_EQ(doc["materials"].size(), doc["images"].size());
    EXPECT_GT(doc["images"].size(), 2u);
    for (const json& im : doc["images"]) EXPECT_TRUE(im.contains("bufferView")) << im.dump();
    // The texels: the build cuts each patch's islands out of the input image and moves them by
    // whole texels, keeping coordinates to 1/16 texel. So every corner's texel position differs
    // from the input's by one whole-texel offset per triangle (within 1/32 texel), and the texels
    // there are the input's (through the MT's JPEG, quality 90).
    TexturedSoup cut;
    readTextured(out, origin, step, cut);
    EXPECT_EQ(cut.tris.size() + cut.untextured, input.size());
    double worst = 0, sumDiff = 0;
    int maxDiff = 0;
    size_t samples = 0;
    for (const auto& [g, ti] : in.tris) {
      auto it = cut.tris.find(g);
      ASSERT_TRUE(it != cut.tris.end());
      const TexturedTri& to = it->second;
      double shift[2];
      for (int a = 0; a < 2; ++a) shift[a] = std::round(to.texel[a] - ti.texel[a]);
      for (int k = 0; k < 3; ++k)
        for (int a = 0; a < 2; ++a) worst = std::max(worst, std::abs(to.texel[2 * k + a] - ti.texel[2 * k + a] - shift[a]));
      // The texel under the triangle's centroid, in both images (rows top first, v up).
      double cin[2] = {0, 0}, cout[2] = {0, 0};
      for (int k = 0; k < 3; ++k)
        for (int a = 0; a < 2; ++a) cin[a] += ti.texel[2 * k + a] / 3, cout[a] += to.texel[2 * k + a] / 3;
      auto texel = [](const tex::RgbImage& im, const double at[2]) {
        const int x = std::clamp(int(std::floor(at[0])), 0, im.width - 1);
        const int y = std::clamp(im.height - 1 - int(std::floor(at[1])), 0, im.height - 1);
        return im.pixel(x, y);
      };
      const uint8_t* a = texel(*ti.image, cin);
      const uint8_t* b = texel(*to.image, cout);
      for (int c = 0; c < 3; ++c) {
        const int d = std::abs(int(a[c]) - int(b[c]));
        maxDiff = std::max(maxDiff, d);
        sumDiff += d;
        ++samples;
      }
    }
    EXPECT_LE(worst, 1.0 / 32 + 1e-3) << "texture coordinates moved by more than the MT keeps";
    EXPECT_LT(sumDiff / double(samples), 4.0);
    EXPECT_LE(maxDiff, 40);
    std::printf("%s: %zu bytes, %zu vertices, %zu images; texel positions within %.4f texel of a whole-texel shift; "
                "texel colour difference mean %.2f max %d\n",
                variant.c_str(), size_t(test::readFile(out).size()), cut.vertices, size_t(doc["images"].size()), worst,
                sumDiff / double(samples), maxDiff);
  }
}

TEST(GltfReader, BadTexturesGiveOneClearErrorNamingTheFileAndWhere) {
  TempDir dir;
  struct Case {
    std::string name, expect;
    std::function<void(Doc&)> damage;
  };
  const std::vector<Case> cases = {
      {"missing.glb", "cannot open", [](Doc& d) { d.j["images"][1]["uri"] = "nothere.jpg"; }},
      {"corrupt.glb", "image 0 (buffer view 0, byte offset", [](Doc& d) { d.bin[1] = 'X'; }},
      {"texcoord.glb", "material 1 baseColorTexture uses texCoord 3, but mesh 1 primitive 0 has no TEXCOORD_3",
       [](Doc& d) { d.j["materials"][1]["pbrMetallicRoughness"]["baseColorTexture"]["texCoord"] = 3; }},
      {"texture.glb", "material 0 baseColorTexture refers to textures 7, which does not exist",
       [](Doc& d) { d.j["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["index"] = 7; }},
      {"image.glb", "texture 1 refers to images 9, which does not exist", [](Doc& d) { d.j["textures"][1]["source"] = 9; }},
      {"range.glb", "TEXCOORD_0 of mesh 0 primitive 0) element 0: texture coordinate (-0.500000",
       [](Doc& d) {
         const int a = d.j["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"];
         const size_t at = d.j["bufferViews"][d.j["accessors"][size_t(a)]["bufferView"].get<size_t>()]["byteOffset"];
         const float bad = -0.5f;
         std::memcpy(&d.bin[at], &bad, 4);
       }},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    Doc d = texturedDoc(dir);
    c.damage(d);
    const std::string path = dir.file(c.name);
    test::writeFile(path, d.glb());
    try {
      Soup s;
      openMesh(path)->read(s);
      ADD_FAILURE() << "no error";
    } catch (const Error& e) {
      const std::string m = e.what();
      EXPECT_NE(m.find(c.name), std::string::npos) << m;
      EXPECT_NE(m.find(c.expect), std::string::npos) << m;
      EXPECT_EQ(m.find('\n'), std::string::npos) << m;
      std::printf("%s\n", m.c_str());
    }
  }
  // mtbuild: the same message, exit 1, nothing left.
  Doc d = texturedDoc(dir);
  d.bin[1] = 'X';
  test::writeFile(dir.file("bad.glb"), d.glb());
  auto r = runTool("mtbuild", dir.file("bad.glb") + " -o " + dir.file("x.mt") + " -q");
  EXPECT_EQ(r.exitCode, 1) << r.output;
  EXPECT_NE(r.output.find("neither PNG nor JPEG"), std::string::npos) << r.output;
  EXPECT_FALSE(test::fileExists(dir.file("x.mt")));
}

// The copies a reader makes of embedded images (in $TMPDIR) go with it, and also when it is
// refused while it opens: a broken image after a good one leaves neither copy behind.
TEST(GltfReader, ABrokenImageLeavesNoCopyInTmpdir) {
  TempDir dir;
  const std::string tmpdir = dir.file("tmpdir");
  std::filesystem::create_directory(tmpdir);
  const char* was = std::getenv("TMPDIR");
  const std::string saved = was ? was : "";
  setenv("TMPDIR", tmpdir.c_str(), 1);
  auto entries = [&] {
    return size_t(std::distance(std::filesystem::directory_iterator(tmpdir), std::filesystem::directory_iterator()));
  };
  // Both images embedded: image 0 a PNG in a buffer view, image 1 a data URI.
  Doc good = texturedDoc(dir);
  good.j["images"][1] = {{"uri", "data:image/png;base64,iVBORw0KGgo="}};  // a PNG's 8 magic bytes
  test::writeFile(dir.file("good.glb"), good.glb());
  {
    auto reader = openMesh(dir.file("good.glb"));
    EXPECT_EQ(entries(), 2u) << "the reader copies both embedded images to $TMPDIR";
  }
  EXPECT_EQ(entries(), 0u);
  struct Case {
    const char* name;
    std::function<void(Doc&)> damage;
  } cases[] = {
      {"second.glb", [](Doc& d) { d.j["images"][1] = {{"uri", "data:image/png;base64,AAAAAAAAAAA="}}; }},
      {"first.glb", [](Doc& d) { d.bin[1] = 'X'; }},
  };
  for (const Case& c : cases) {
    Doc d = good;
    c.damage(d);
    test::writeFile(dir.file(c.name), d.glb());
    try {
      openMesh(dir.file(c.name));
      ADD_FAILURE() << c.name << ": opened";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("neither PNG nor JPEG"), std::string::npos) << e.what();
    }
    std::vector<std::string> left;
    for (const auto& e : std::filesystem::directory_iterator(tmpdir)) left.push_back(e.path().string());
    EXPECT_TRUE(left.empty()) << c.name << ": left " << ::testing::PrintToString(left);
  }
  if (was) setenv("TMPDIR", saved.c_str(), 1);
  else unsetenv("TMPDIR");
}

}  // namespace
}  // namespace mt
