// The texture room (texture/): images decoded row by row and scaled, encoded; bad images refused
// with the file and byte offset.
#include <gtest/gtest.h>

#include <gmock/gmock.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#include "base/error.h"
#include "base/exit_code.h"
#include <filesystem>
#include <map>

#include "mtbuild/build.h"
#include "mtfile/mt_file.h"
#include "mtfile/texture_payload.h"
#include "patchstore/heal/heal.h"
#include "patchstore/io/mesh_reader.h"
#include "patchstore/patch_store.h"
#include "patchstore/store_textures.h"
#include "test_support.h"
#include "testing/textured_grid.h"
#include "texture/atlas_crop.h"
#include "texture/bake.h"
#include "texture/block_fill.h"
#include "texture/chart_rotate.h"
#include "texture/image_codec.h"
#include "texture/obj_writer.h"
#include "texture/tiled_image.h"

namespace mt {
namespace {

using tex::RgbImage;

// A picture with sharp features: a checkerboard of 8-px cells with a colour ramp.
RgbImage testPicture(int w, int h) {
  RgbImage img(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      uint8_t* p = img.pixel(x, y);
      const bool on = ((x / 8) + (y / 8)) % 2 == 0;
      p[0] = uint8_t(on ? 230 : 20);
      p[1] = uint8_t((x * 255) / std::max(1, w - 1));
      p[2] = uint8_t((y * 255) / std::max(1, h - 1));
    }
  return img;
}

double psnr(const RgbImage& a, const RgbImage& b) {
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.height, b.height);
  double se = 0;
  for (size_t i = 0; i < a.rgb.size(); ++i) se += double(a.rgb[i] - b.rgb[i]) * double(a.rgb[i] - b.rgb[i]);
  const double mse = se / double(a.rgb.size());
  return mse == 0 ? 99 : 10 * std::log10(255.0 * 255.0 / mse);
}

TEST(TextureImage, PngRoundTripIsExact) {
  RgbImage img = testPicture(37, 21);
  std::vector<uint8_t> png = tex::encodePng(img);
  EXPECT_EQ(tex::sniffImage(png.data(), png.size()), tex::ImageFormat::Png);
  RgbImage back = tex::decodeImage(png.data(), png.size(), "mem.png");
  EXPECT_EQ(back.width, 37);
  EXPECT_EQ(back.height, 21);
  EXPECT_EQ(back.rgb, img.rgb);
}

TEST(TextureImage, JpegRoundTripIsClose) {
  RgbImage img = testPicture(64, 48);
  std::vector<uint8_t> jpg = tex::encodeJpeg(img, 95);
  EXPECT_EQ(tex::sniffImage(jpg.data(), jpg.size()), tex::ImageFormat::Jpeg);
  RgbImage back = tex::decodeImage(jpg.data(), jpg.size(), "mem.jpg");
  EXPECT_GT(psnr(img, back), 30.0);
  // Deterministic bytes.
  EXPECT_EQ(jpg, tex::encodeJpeg(img, 95));
  // Lower quality: smaller and further.
  std::vector<uint8_t> low = tex::encodeJpeg(img, 30);
  EXPECT_LT(low.size(), jpg.size());
  EXPECT_LT(psnr(img, tex::decodeImage(low.data(), low.size(), "x")), psnr(img, back));
}

TEST(TextureImage, ScaledDecodeIsTheBoxMean) {
  RgbImage img = testPicture(33, 17);
  std::vector<uint8_t> png = tex::encodePng(img);
  auto d = tex::ImageDecoder::openMemory(png.data(), png.size(), "mem.png", 1);
  EXPECT_EQ(d->width(), 17);
  EXPECT_EQ(d->height(), 9);
  EXPECT_EQ(d->fullWidth(), 33);
  std::vector<uint8_t> row(size_t(d->width()) * 3);
  d->readRow(row.data());
  // Pixel (0,0) of the half-size image: the mean of the 2x2 block.
  for (int c = 0; c < 3; ++c) {
    int sum = img.pixel(0, 0)[c] + img.pixel(1, 0)[c] + img.pixel(0, 1)[c] + img.pixel(1, 1)[c];
    EXPECT_EQ(row[size_t(c)], uint8_t((sum + 2) / 4));
  }
  // JPEG scaled by libjpeg: the sizes round up the same way.
  std::vector<uint8_t> jpg = tex::encodeJpeg(img, 90);
  auto j = tex::ImageDecoder::openMemory(jpg.data(), jpg.size(), "mem.jpg", 2);
  EXPECT_EQ(j->width(), 9);
  EXPECT_EQ(j->height(), 5);
}

TEST(TextureImage, FilesThroughEnvAndBadImages) {
  test::TempDir dir;
  RgbImage img = testPicture(40, 30);
  tex::writeFileAtomically(dir.file("a.png"), tex::encodePng(img));
  tex::writeFileAtomically(dir.file("a.jpg"), tex::encodeJpeg(img, 90));
  EXPECT_EQ(tex::readImageFile(dir.file("a.png")).rgb, img.rgb);
  tex::ImageInfo info = tex::readImageInfo(dir.file("a.jpg"));
  EXPECT_EQ(info.format, tex::ImageFormat::Jpeg);
  EXPECT_EQ(info.width, 40);
  EXPECT_EQ(info.height, 30);

  auto expectError = [](const std::string& path, const std::string& part) {
    try {
      tex::RgbImage r = tex::readImageFile(path);
      ADD_FAILURE() << path << " was read (" << r.width << " x " << r.height << ")";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
    }
  };
  // Truncated: the message says where the data ended.
  for (const char* name : {"a.png", "a.jpg"}) {
    std::string bytes = test::readFile(dir.file(name));
    test::writeFile(dir.file(std::string("cut-") + name), bytes.substr(0, bytes.size() / 2));
    expectError(dir.file(std::string("cut-") + name), "byte offset");
  }
  test::writeFile(dir.file("junk.png"), "this is not an image at all");
  expectError(dir.file("junk.png"), "not a JPEG or PNG image");
  test::writeFile(dir.file("empty.jpg"), "");
  expectError(dir.file("empty.jpg"), "empty");
  expectError(dir.file("missing.png"), "missing.png");
  // Damaged PNG data (a flipped byte inside the compressed stream): the CRC catches it.
  std::string png = test::readFile(dir.file("a.png"));
  png[png.size() / 2] ^= 0x5a;
  test::writeFile(dir.file("flip.png"), png);
  expectError(dir.file("flip.png"), "damaged PNG image");
}

// ---- Readers: texture coordinates, materials, images -------------------------------------------

struct Collect : MeshSink {
  MeshHeader header;
  std::vector<InputVertex> v;
  std::vector<uint32_t> t;
  void begin(const MeshHeader& h) override { header = h; }
  void vertices(const InputVertex* p, size_t n, uint64_t first) override {
    EXPECT_EQ(first, v.size());
    v.insert(v.end(), p, p + n);
  }
  void triangles(const uint32_t* p, size_t n) override {
    for (size_t i = 0; i < 3 * n; ++i) EXPECT_LT(p[i], v.size());
    t.insert(t.end(), p, p + 3 * n);
  }
  // The (u, v, material) of corner k of triangle i, through its vertex.
  std::array<double, 3> corner(size_t i, int k) const {
    const InputVertex& x = v[t[3 * i + size_t(k)]];
    return {x.uv[0], x.uv[1], double(x.material)};
  }
  std::array<double, 3> pos(size_t i, int k) const {
    const InputVertex& x = v[t[3 * i + size_t(k)]];
    return {x.p[0], x.p[1], x.p[2]};
  }
};

Collect readAll(const std::string& path) {
  Collect c;
  auto r = openMesh(path);
  r->read(c);
  return c;
}

std::string errorOf(const std::string& path) {
  try {
    Collect c;
    openMesh(path)->read(c);
  } catch (const Error& e) {
    std::string m = e.what();
    EXPECT_EQ(m.find('\n'), std::string::npos) << m;
    return m;
  }
  ADD_FAILURE() << path << " did not fail";
  return "";
}

// A unit square of two triangles with a seam down its diagonal's vertices: 4 positions, the
// corners of the two triangles naming different texture coordinates for vertices 0 and 2.
void writeSquareObj(const test::TempDir& dir, const std::string& extraFace = "") {
  tex::writeFileAtomically(dir.file("tex a.png"), tex::encodePng(testPicture(16, 16)));
  tex::writeFileAtomically(dir.file("b.jpg"), tex::encodeJpeg(testPicture(8, 8), 90));
  test::writeFile(dir.file("m.mtl"),
                  "newmtl A\nKd 1 0 0\nmap_Kd -s 1 1 1 -clamp on tex a.png\n\nnewmtl B\nKd 0 1 0\nmap_Kd b.jpg\n"
                  "newmtl Plain\nKd 0 0 1\n");
  test::writeFile(dir.file("sq.obj"),
                  "mtllib m.mtl\n"
                  "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                  "vt 0 0\nvt 0.5 0\nvt 0.5 0.5\nvt 0.6 0.6\nvt 1 1\nvt 0.6 1\n"
                  "usemtl A\nf 1/1 2/2 3/3\n"
                  "usemtl B\nf 1/4/1 3/5/1 4/6/1\n" + extraFace);
}

// writeTexturedObj writes each file under a temporary name: when a rename fails (the final name
// is an existing directory) or any later step does, nothing is left under a temporary name, and
// the files written before it are removed too.
TEST(TextureObj, AFailedRenameLeavesNoTemporaryFile) {
  const double positions[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  const uint32_t triangles[3] = {0, 1, 2}, texture[1] = {0};
  const float uv[6] = {0, 0, 1, 0, 0, 1};
  const std::vector<RgbImage> textures = {testPicture(16, 16)};
  tex::TexturedMeshView m;
  m.positions = positions;
  m.vertexCount = 3;
  m.triangles = triangles;
  m.triangleCount = 1;
  m.cornerUV = uv;
  m.triangleTexture = texture;
  m.textures = &textures;
  for (const char* blocked : {"cut.obj", "cut.mtl", "cut_0.png"}) {
    test::TempDir dir;
    std::filesystem::create_directory(dir.file(blocked));
    EXPECT_THROW(tex::writeTexturedObj(dir.file("cut.obj"), m), Error) << blocked;
    std::vector<std::string> left;
    for (const auto& e : std::filesystem::directory_iterator(dir.path()))
      if (e.path().filename() != blocked) left.push_back(e.path().filename().string());
    EXPECT_TRUE(left.empty()) << blocked << " a directory: left " << ::testing::PrintToString(left);
  }
  test::TempDir dir;  // and the same mesh, unblocked, is written
  tex::ObjWriteInfo info = tex::writeTexturedObj(dir.file("cut.obj"), m);
  EXPECT_EQ(info.files.size(), 3u);
  EXPECT_EQ(size_t(std::distance(std::filesystem::directory_iterator(dir.path()), std::filesystem::directory_iterator())), 3u);
}

TEST(TextureReaders, ObjCornersBecomeWedges) {
  test::TempDir dir;
  writeSquareObj(dir, "usemtl Plain\nf 2 3 4\n");
  Collect c = readAll(dir.file("sq.obj"));
  EXPECT_TRUE(c.header.hasTexcoords);
  EXPECT_FALSE(c.header.cornerTexcoords);
  ASSERT_EQ(c.header.materials.size(), 3u);
  EXPECT_EQ(c.header.materials[0].name, "A");
  EXPECT_EQ(c.header.materials[0].texture, dir.file("tex a.png"));
  EXPECT_EQ(c.header.materials[0].diffuse[0], 255);
  EXPECT_EQ(c.header.materials[1].texture, dir.file("b.jpg"));
  EXPECT_EQ(c.header.materials[2].texture, "");
  ASSERT_EQ(c.t.size(), 9u);
  // Corners keep their own coordinates and positions (the untextured face's corners have no
  // material, so they get wedges of their own).
  EXPECT_EQ(c.corner(0, 0), (std::array<double, 3>{0, 0, 0}));
  EXPECT_EQ(c.corner(0, 2), (std::array<double, 3>{0.5, 0.5, 0}));
  EXPECT_EQ(c.corner(1, 0), (std::array<double, 3>{0.6f, 0.6f, 1}));
  EXPECT_EQ(c.corner(1, 1), (std::array<double, 3>{1, 1, 1}));
  EXPECT_EQ(c.corner(2, 0)[2], double(kNoMaterial));
  EXPECT_EQ(c.pos(0, 0), c.pos(1, 0));
  EXPECT_EQ(c.pos(0, 2), c.pos(1, 1));
  EXPECT_NE(c.t[0], c.t[3]);  // the seam: two vertices, one position
  EXPECT_EQ(c.pos(1, 2), (std::array<double, 3>{0, 1, 0}));
  // 4 positions: 0 (2 wedges), 1 (2: A and none), 2 (3), 3 (2) = 9 vertices, in position order.
  ASSERT_EQ(c.v.size(), 9u);
  const int order[9] = {0, 0, 1, 1, 2, 2, 2, 3, 3};
  const double xy[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  for (size_t i = 0; i < 9; ++i) EXPECT_EQ(c.v[i].p[0], xy[order[i]][0]) << i;
  for (size_t i = 0; i < 9; ++i) EXPECT_EQ(c.v[i].p[1], xy[order[i]][1]) << i;
}

TEST(TextureReaders, PlyPerVertexPerCornerAndTexnumber) {
  test::TempDir dir;
  tex::writeFileAtomically(dir.file("t0.png"), tex::encodePng(testPicture(4, 4)));
  tex::writeFileAtomically(dir.file("t1.png"), tex::encodePng(testPicture(4, 4)));
  // Per vertex: passed through with material 0.
  test::writeFile(dir.file("pv.ply"),
                  "ply\nformat ascii 1.0\ncomment TextureFile t0.png\nelement vertex 3\nproperty float x\nproperty float y\n"
                  "property float z\nproperty float texture_u\nproperty float texture_v\nelement face 1\n"
                  "property list uchar int vertex_indices\nend_header\n0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 1\n3 0 1 2\n");
  Collect a = readAll(dir.file("pv.ply"));
  EXPECT_TRUE(a.header.hasTexcoords);
  ASSERT_EQ(a.v.size(), 3u);
  EXPECT_EQ(a.v[1].uv[0], 1.0f);
  EXPECT_EQ(a.v[2].uv[1], 1.0f);
  EXPECT_EQ(a.v[2].material, 0u);
  // Per corner with texnumber (MeshLab's layout), binary.
  std::string body =
      "ply\nformat binary_little_endian 1.0\ncomment TextureFile t0.png\ncomment TextureFile t1.png\nelement vertex 4\n"
      "property float x\nproperty float y\nproperty float z\nelement face 2\nproperty list uchar int vertex_indices\n"
      "property list uchar float texcoord\nproperty int texnumber\nend_header\n";
  auto put = [&](auto x) { body.append(reinterpret_cast<const char*>(&x), sizeof x); };
  const float p[4][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  for (auto& q : p) put(q[0]), put(q[1]), put(q[2]);
  put(uint8_t(3)), put(int32_t(0)), put(int32_t(1)), put(int32_t(2));
  put(uint8_t(6)), put(0.f), put(0.f), put(1.f), put(0.f), put(1.f), put(1.f), put(int32_t(0));
  put(uint8_t(3)), put(int32_t(0)), put(int32_t(2)), put(int32_t(3));
  put(uint8_t(6)), put(0.f), put(0.f), put(.5f), put(.5f), put(0.f), put(.5f), put(int32_t(1));
  test::writeFile(dir.file("pc.ply"), body);
  Collect b = readAll(dir.file("pc.ply"));
  ASSERT_EQ(b.t.size(), 6u);
  EXPECT_EQ(b.corner(0, 1), (std::array<double, 3>{1, 0, 0}));
  EXPECT_EQ(b.corner(1, 1), (std::array<double, 3>{.5, .5, 1}));
  EXPECT_NE(b.t[0], b.t[3]);  // vertex 0: (0, 0) in both faces, but two images
  EXPECT_EQ(b.v.size(), 6u);
  // Triangle strips beside faces with texnumber: a strip's triangles take image 0 and their
  // vertices' coordinates; the face keeps its image.
  test::writeFile(dir.file("st.ply"),
                  "ply\nformat ascii 1.0\ncomment TextureFile t0.png\ncomment TextureFile t1.png\nelement vertex 4\n"
                  "property float x\nproperty float y\nproperty float z\nproperty float s\nproperty float t\nelement face 1\n"
                  "property list uchar int vertex_indices\nproperty int texnumber\nelement tristrips 1\n"
                  "property list int int vertex_indices\nend_header\n0 0 0 0 0\n1 0 0 1 0\n1 1 0 1 1\n0 1 0 0 1\n"
                  "3 0 1 2 1\n3 0 2 3\n");
  Collect st = readAll(dir.file("st.ply"));
  ASSERT_EQ(st.t.size(), 6u);
  EXPECT_EQ(st.corner(0, 1), (std::array<double, 3>{1, 0, 1}));
  EXPECT_EQ(st.corner(1, 1), (std::array<double, 3>{1, 1, 0}));
  EXPECT_EQ(st.corner(1, 2), (std::array<double, 3>{0, 1, 0}));
  EXPECT_EQ(st.pos(1, 2), (std::array<double, 3>{0, 1, 0}));
}

TEST(TextureReaders, BadReferencesAreClearErrors) {
  using ::testing::HasSubstr;
  test::TempDir dir;
  writeSquareObj(dir);
  auto variant = [&](const std::string& name, const std::string& from, const std::string& to) {
    std::string s = test::readFile(dir.file("sq.obj"));
    size_t at = s.find(from);
    EXPECT_NE(at, std::string::npos) << from;
    s.replace(at, from.size(), to);
    test::writeFile(dir.file(name), s);
    return dir.file(name);
  };
  EXPECT_THAT(errorOf(variant("vt.obj", "f 1/1 2/2 3/3", "f 1/1 2/2 3/7")),
              AllOf(HasSubstr("texture coordinate index 7 out of range (6 vt so far) at face 0"), HasSubstr("(line 13)")));
  EXPECT_THAT(errorOf(variant("uv.obj", "vt 1 1", "vt 1 1.5")), AllOf(HasSubstr("outside [0, 1]"), HasSubstr("line 10")));
  EXPECT_THAT(errorOf(variant("mtl.obj", "usemtl B", "usemtl Nope")), HasSubstr("usemtl 'Nope' names no material"));
  // A missing library: read untextured, as before textures were read.
  EXPECT_FALSE(readAll(variant("lib.obj", "mtllib m.mtl", "mtllib gone.mtl")).header.hasTexcoords);
  EXPECT_THAT(errorOf(variant("novt.obj", "f 1/1 2/2 3/3", "f 1 2/2 3/3")), HasSubstr("corner without a texture coordinate"));
  std::remove(dir.file("b.jpg").c_str());
  EXPECT_THAT(errorOf(dir.file("sq.obj")), AllOf(HasSubstr("b.jpg"), HasSubstr("texture image of material 'B'"),
                                                 HasSubstr("m.mtl (line 7)"), HasSubstr("No such file")));
  // PLY: texnumber out of range, texcoord count, a coordinate out of range.
  tex::writeFileAtomically(dir.file("t0.png"), tex::encodePng(testPicture(4, 4)));
  const std::string head =
      "ply\nformat ascii 1.0\ncomment TextureFile t0.png\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list uchar int vertex_indices\nproperty list uchar float texcoord\n"
      "property int texnumber\nend_header\n0 0 0\n1 0 0\n0 1 0\n";
  test::writeFile(dir.file("n.ply"), head + "3 0 1 2 6 0 0 1 0 0 1 1\n");
  EXPECT_THAT(errorOf(dir.file("n.ply")), AllOf(HasSubstr("texnumber 1 of face 0 out of range (1 TextureFile"), HasSubstr("line 16")));
  test::writeFile(dir.file("c.ply"), head + "3 0 1 2 4 0 0 1 0 0\n");
  EXPECT_THAT(errorOf(dir.file("c.ply")), HasSubstr("4 texcoord values for 3 corners"));
  test::writeFile(dir.file("r.ply"), head + "3 0 1 2 6 0 0 1 0 0 -1 0\n");
  EXPECT_THAT(errorOf(dir.file("r.ply")), AllOf(HasSubstr("face 0 corner 2 is outside [0, 1]"), HasSubstr("line 16")));
  test::writeFile(dir.file("f.ply"), "ply\nformat ascii 1.0\ncomment TextureFile nothere.png\n" + head.substr(head.find("element")) +
                                         "3 0 1 2 6 0 0 1 0 0 1 0\n");
  EXPECT_THAT(errorOf(dir.file("f.ply")), AllOf(HasSubstr("nothere.png"), HasSubstr("line 3")));
  // Through mtbuild: the same one-line message, exit 1 (invalid input), nothing under the output's
  // name; a corrupt image the same.
  test::writeFile(dir.file("junk.png"), "this is not an image at all");
  test::writeFile(dir.file("j.ply"), "ply\nformat ascii 1.0\ncomment TextureFile junk.png\n" + head.substr(head.find("element")) +
                                         "3 0 1 2 6 0 0 1 0 0 1 0\n");
  for (const char* name : {"f", "j", "n", "r"}) {
    test::CommandResult b = test::runTool("mtbuild", dir.file(std::string(name) + ".ply") + " -o " + dir.file(std::string(name) + ".mt") + " -q");
    EXPECT_EQ(b.exitCode, kExitInvalidInput) << name << ": " << b.output;
    EXPECT_THAT(b.output, HasSubstr(std::string(name) + ".ply")) << name;
    EXPECT_FALSE(test::fileExists(dir.file(std::string(name) + ".mt"))) << name;
  }
  EXPECT_THAT(test::runTool("mtbuild", dir.file("j.ply") + " -o " + dir.file("j.mt")).output, HasSubstr("not a JPEG or PNG image"));
}

// ---- Baked atlases: the uncovered texels, the charts' frames --------------------------------------

TEST(TextureAtlas, EmptyBlocksAreFilledFlatAndCoveredTexelsKept) {
  // Two "charts" (a disc and a thin diagonal band) of a detailed picture over a 100 x 60 atlas
  // (sides not multiples of 8: partial blocks at the right and bottom).
  const int w = 100, h = 60;
  RgbImage img = testPicture(w, h);
  std::vector<uint8_t> filled(size_t(w) * h, 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const bool disc = (x - 25) * (x - 25) + (y - 30) * (y - 30) < 15 * 15, band = std::abs((x - 50) - y) < 2 && x >= 50;
      filled[size_t(y) * w + x] = disc || band;
      if (!(disc || band)) std::fill_n(img.pixel(x, y), 3, uint8_t(0));
    }
  const RgbImage before = img;
  const std::vector<uint8_t> covered = filled;
  tex::fillEmptyBlocks(img, filled);
  size_t flatBlocks = 0;
  for (size_t i = 0; i < filled.size(); ++i) {
    EXPECT_EQ(filled[i], 1) << "texel " << i;
    if (covered[i]) {
      EXPECT_EQ(std::memcmp(&img.rgb[3 * i], &before.rgb[3 * i], 3), 0) << "covered texel " << i;
    }
  }
  for (int by = 0; by < (h + 7) / 8; ++by)
    for (int bx = 0; bx < (w + 7) / 8; ++bx) {
      bool empty = true;
      for (int y = 8 * by; y < std::min(h, 8 * by + 8); ++y)
        for (int x = 8 * bx; x < std::min(w, 8 * bx + 8); ++x) empty = empty && !covered[size_t(y) * w + x];
      // A block without covered texels is one colour, a picture's colour (none is black: red >= 20).
      const uint8_t* first = img.pixel(8 * bx, 8 * by);
      if (!empty) {
        // The uncovered texels of a mixed block take one colour too: the block's covered mean.
        const uint8_t* u = nullptr;
        for (int y = 8 * by; y < std::min(h, 8 * by + 8); ++y)
          for (int x = 8 * bx; x < std::min(w, 8 * bx + 8); ++x)
            if (!covered[size_t(y) * w + x]) {
              if (!u) u = img.pixel(x, y);
              EXPECT_EQ(std::memcmp(u, img.pixel(x, y), 3), 0) << x << "," << y;
            }
        continue;
      }
      ++flatBlocks;
      EXPECT_GE(first[0], 20) << "block " << bx << "," << by;
      for (int y = 8 * by; y < std::min(h, 8 * by + 8); ++y)
        for (int x = 8 * bx; x < std::min(w, 8 * bx + 8); ++x) EXPECT_EQ(std::memcmp(first, img.pixel(x, y), 3), 0) << x << "," << y;
    }
  EXPECT_GT(flatBlocks, 40u);
  // So the JPEG is smaller than with the uncovered texels black (the steps at the charts' edges
  // and the picture's colour inside mixed blocks cost bits).
  EXPECT_LT(tex::encodeJpeg(img, 90).size(), tex::encodeJpeg(before, 90).size());
  // An atlas without any covered texel is left as it is.
  RgbImage blank(16, 16);
  std::vector<uint8_t> none(256, 0);
  tex::fillEmptyBlocks(blank, none);
  EXPECT_EQ(none, std::vector<uint8_t>(256, 0));
}

TEST(TextureAtlas, CropAtlasKeepsTheInputTexelsAndFillsBetweenTheCutOuts) {
  // Three triangles of different sizes over one picture (red is 20 or 230 everywhere): their
  // cut-outs are packed with room between them, which is filled (no red 0 left), and each cut-out
  // keeps the picture's texels exactly.
  struct Source : tex::TexelSource {
    const RgbImage* img;
    int width(uint32_t) const override { return img->width; }
    int height(uint32_t) const override { return img->height; }
    void flatColor(uint32_t, uint8_t rgb[3]) const override { rgb[0] = rgb[1] = rgb[2] = 7; }
    void copyRect(uint32_t, int x0, int y0, int w, int h, uint8_t* out) const override {
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          std::copy_n(img->pixel(std::clamp(x0 + x, 0, img->width - 1), std::clamp(y0 + y, 0, img->height - 1)), 3, &out[3 * (size_t(y) * w + x)]);
    }
  };
  const RgbImage picture = testPicture(256, 256);
  Source src;
  src.img = &picture;
  // Corners in texels (x right, y down), as (u, v) with v = 0 at the bottom.
  const double tris[3][6] = {{10, 10, 40, 10, 10, 40}, {100, 120, 200, 120, 100, 130}, {30, 200, 37, 200, 30, 250}};
  std::vector<float> uv;
  for (const auto& t : tris)
    for (int k = 0; k < 3; ++k) uv.push_back(float((t[2 * k] + 0.3) / 256)), uv.push_back(float(1 - (t[2 * k + 1] + 0.3) / 256));
  const uint32_t idx[9] = {0, 1, 2, 3, 4, 5, 6, 7, 8}, mat[3] = {0, 0, 0};
  const tex::CropResult r = tex::cropAtlas(idx, 3, 9, uv.data(), mat, src);
  ASSERT_EQ(r.scale, 1);
  size_t zero = 0;
  for (int y = 0; y < r.image.height; ++y)
    for (int x = 0; x < r.image.width; ++x) zero += r.image.pixel(x, y)[0] == 0;
  EXPECT_EQ(zero, 0u) << r.image.width << " x " << r.image.height;
  for (int t = 0; t < 3; ++t) {
    // The texel at each corner's and at the centroid's atlas position is the picture's there.
    double cu = 0, cv = 0, px = 0, py = 0;
    for (int k = 0; k < 3; ++k) {
      cu += r.cornerUV[6 * t + 2 * k] / 3.0, cv += r.cornerUV[6 * t + 2 * k + 1] / 3.0;
      px += (tris[t][2 * k] + 0.3) / 3, py += (tris[t][2 * k + 1] + 0.3) / 3;  // (off the texels' borders)
    }
    const uint8_t* got = r.image.pixel(int(cu * r.image.width), int((1 - cv) * r.image.height));
    EXPECT_EQ(std::memcmp(got, picture.pixel(int(px), int(py)), 3), 0) << "triangle " << t;
  }
}

TEST(TextureAtlas, ChartsTurnToTheirMinimumAreaBox) {
  // A 10 x 2 rectangle's corners and inner points turned by 30 degrees: the box found is 10 x 2.
  std::vector<double> xy;
  const double a = M_PI / 6;
  for (double x : {0.0, 3.0, 10.0})
    for (double y : {0.0, 1.0, 2.0}) xy.push_back(x * std::cos(a) - y * std::sin(a)), xy.push_back(x * std::sin(a) + y * std::cos(a));
  const tex::BoxFrame f = tex::minAreaBox(xy.data(), xy.size() / 2);
  EXPECT_NEAR(f.area, 20.0, 1e-9);
  EXPECT_NEAR(std::fabs(f.c * std::cos(a) + f.s * std::sin(a)) + std::fabs(-f.c * std::sin(a) + f.s * std::cos(a)), 1.0, 1e-9)
      << "an axis along the rectangle's sides";
  // Pseudo-random clouds: never larger than the unrotated box, every point inside the rectangle.
  uint32_t seed = 12345;
  auto rnd = [&] { return (seed = seed * 1664525u + 1013904223u) / 4294967296.0; };
  for (int trial = 0; trial < 200; ++trial) {
    std::vector<double> p(2 * (3 + trial % 17));
    const double stretch = 1 + 9 * rnd(), turn = M_PI * rnd();
    for (size_t i = 0; i < p.size(); i += 2) {
      const double x = stretch * rnd(), y = rnd();
      p[i] = x * std::cos(turn) - y * std::sin(turn), p[i + 1] = x * std::sin(turn) + y * std::cos(turn);
    }
    double lo[2] = {INFINITY, INFINITY}, hi[2] = {-INFINITY, -INFINITY};
    for (size_t i = 0; i < p.size(); ++i) lo[i % 2] = std::min(lo[i % 2], p[i]), hi[i % 2] = std::max(hi[i % 2], p[i]);
    const tex::BoxFrame b = tex::minAreaBox(p.data(), p.size() / 2);
    EXPECT_LE(b.area, (hi[0] - lo[0]) * (hi[1] - lo[1]) * (1 + 1e-12)) << trial;
    EXPECT_NEAR(b.c * b.c + b.s * b.s, 1.0, 1e-12);
  }
  // Axis-aligned points keep the identity frame.
  const double square[8] = {0, 0, 1, 0, 1, 1, 0, 1};
  const tex::BoxFrame id = tex::minAreaBox(square, 4);
  EXPECT_EQ(id.c, 1.0);
  EXPECT_EQ(id.s, 0.0);
}

TEST(TextureBake, DiagonalStripPacksTightAndEveryTexelIsFilled) {
  // The finer surface: a 10 x 10 square in z = 0 over a smooth picture (u = x / 10, v = y / 10).
  RgbImage picture(256, 256);
  for (int y = 0; y < 256; ++y)
    for (int x = 0; x < 256; ++x) {
      uint8_t* p = picture.pixel(x, y);
      p[0] = uint8_t(x), p[1] = uint8_t(255 - y), p[2] = 128;
    }
  const double fineP[12] = {0, 0, 0, 10, 0, 0, 10, 10, 0, 0, 10, 0};
  const uint32_t fineT[6] = {0, 1, 2, 0, 2, 3};
  const float fineUV[12] = {0, 0, 1, 0, 1, 1, 0, 0, 1, 1, 0, 1};
  const uint32_t fineImage[2] = {0, 0};
  tex::TexturedSurface fine;
  fine.positions = fineP, fine.vertexCount = 4, fine.triangles = fineT, fine.triangleCount = 2;
  fine.cornerUV = fineUV, fine.image = fineImage, fine.images = {&picture};
  const tex::SurfaceIndex index(fine);
  // The coarse patch: a strip 0.5 wide along the diagonal from (1, 1) to (9, 9), 16 quads.
  std::vector<double> pos;
  std::vector<uint32_t> tri;
  const double n = 0.5 * std::sqrt(0.5);  // 0.5 along the strip's across direction (-1, 1) / sqrt 2
  for (int i = 0; i <= 16; ++i) {
    const double t = 1 + 8.0 * i / 16;
    pos.insert(pos.end(), {t, t, 0.0, t - n, t + n, 0.0});
    if (i < 16) tri.insert(tri.end(), {uint32_t(2 * i), uint32_t(2 * i + 2), uint32_t(2 * i + 3), uint32_t(2 * i), uint32_t(2 * i + 3), uint32_t(2 * i + 1)});
  }
  const double texel = 0.05;
  const tex::BakeResult b = tex::bakeAtlas(pos.data(), pos.size() / 3, tri.data(), tri.size() / 3, index, texel, 0.0, 2048, 2, 10.0 / 256);
  EXPECT_EQ(b.charts, 1u);
  EXPECT_EQ(b.texelSize, texel);
  // Its axis-aligned box is 8.35 x 8.35 units (167^2 texels); turned, 11.3 x 0.5 (about 226 x 10).
  EXPECT_LT(double(b.image.width) * b.image.height, 0.2 * (8.35 / texel) * (8.35 / texel)) << b.image.width << " x " << b.image.height;
  // The baked colours are the picture's at the same points; no texel is left black (the picture
  // has blue 128 everywhere, so a black texel is one nothing filled).
  for (size_t t = 0; t < tri.size() / 3; ++t) {
    double u = 0, v = 0, x = 0, y = 0;
    for (int k = 0; k < 3; ++k) {
      u += b.cornerUV[6 * t + 2 * size_t(k)] / 3, v += b.cornerUV[6 * t + 2 * size_t(k) + 1] / 3;
      x += pos[3 * tri[3 * t + size_t(k)]] / 3, y += pos[3 * tri[3 * t + size_t(k)] + 1] / 3;
    }
    uint8_t got[3], want[3];
    tex::sampleBilinear(b.image, u, v, got);
    tex::sampleBilinear(picture, x / 10, y / 10, want);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(got[c], want[c], 3) << "triangle " << t << " channel " << c;
  }
  size_t black = 0;
  for (int y = 0; y < b.image.height; ++y)
    for (int x = 0; x < b.image.width; ++x) black += b.image.pixel(x, y)[2] == 0;
  EXPECT_EQ(black, 0u);
}

// ---- Tiled images --------------------------------------------------------------------------------

TEST(TextureTiles, TiledFileRoundTripsAndScalesToFitMemory) {
  test::TempDir dir;
  RgbImage img = testPicture(300, 200);
  tex::writeFileAtomically(dir.file("big.png"), tex::encodePng(img));
  tex::TiledInfo full = tex::writeTiledImage(dir.file("big.png"), dir.file("full.tiles"), 64 << 20, Env::Default(), 64);
  EXPECT_EQ(full.shift, 0);
  auto t = tex::TiledImage::open(dir.file("full.tiles"));
  EXPECT_EQ(t->width(), 300);
  EXPECT_EQ(t->header().tilesX, 5u);
  t->verify();
  tex::TileCache cache({std::shared_ptr<const tex::TiledImage>(std::move(t))}, 3 * 64 * 64 * 3);
  std::vector<uint8_t> rect(50 * 70 * 3);
  cache.copyRect(0, 40, 100, 50, 70, rect.data());  // crosses tile borders
  for (int y = 0; y < 70; ++y)
    for (int x = 0; x < 50; ++x)
      for (int c = 0; c < 3; ++c) ASSERT_EQ(rect[(size_t(y) * 50 + size_t(x)) * 3 + size_t(c)], img.pixel(40 + x, 100 + y)[c]);
  EXPECT_LE(cache.peakBytes(), 4u * 64 * 64 * 3);  // the cap (one tile over while it is read)
  // A band of 64 rows x 300 x 3 bytes is 57600, twice that must fit: with 60000 bytes the image
  // is halved.
  tex::TiledInfo half = tex::writeTiledImage(dir.file("big.png"), dir.file("half.tiles"), 60000, Env::Default(), 64);
  EXPECT_EQ(half.shift, 1);
  EXPECT_EQ(half.width, 150);
  EXPECT_EQ(half.sourceWidth, 300);
  // Damage: a flipped byte in a tile is found and named.
  std::string bytes = test::readFile(dir.file("full.tiles"));
  bytes[100] ^= 0x40;
  test::writeFile(dir.file("bad.tiles"), bytes);
  try {
    tex::TiledImage::open(dir.file("bad.tiles"))->verify();
    ADD_FAILURE() << "damage not found";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Corruption);
    EXPECT_THAT(e.what(), ::testing::HasSubstr("tile (0, 0) at byte offset 64 is damaged"));
  }
}

// ---- The store -----------------------------------------------------------------------------------

std::unique_ptr<PatchStore> ingestTextured(const std::string& input, const std::string& dir, uint64_t memory = 1ull << 30) {
  auto assigner = makeGridAssigner(500);
  IngestOptions o;
  o.memoryBytes = memory;
  o.progress = false;
  PatchStore::ingest(input, dir, *assigner, o);
  return PatchStore::open(dir);
}

std::string segments(const std::string& dir) {
  std::vector<std::string> names;
  for (auto& e : std::filesystem::directory_iterator(dir))
    if (e.path().filename().string().rfind("SEG-", 0) == 0) names.push_back(e.path().string());
  std::sort(names.begin(), names.end());
  std::string all;
  for (auto& n : names) all += test::readFile(n);
  return all;
}

// The texture coordinates textured_grid gives the corner at (x, y) of a triangle with centroid
// (cx, cy) (the chart is the centroid's): recomputed here from the positions alone.
std::array<double, 2> expectedUV(double x, double y, double cx, double cy, int C, int T) {
  const int ci = std::min(C - 1, int(cx * C)), cj = std::min(C - 1, int(cy * C));
  std::vector<int> perm(size_t(C * C));
  for (int c = 0; c < C * C; ++c) perm[size_t(c)] = (c * 7 + 3) % (C * C);
  for (int c = 0; c < C * C; ++c)
    for (int d = 0; d < c; ++d)
      if (perm[size_t(d)] == perm[size_t(c)]) perm[size_t(c)] = (perm[size_t(c)] + 1) % (C * C), d = -1;
  const int p = perm[size_t(cj * C + ci)];
  const double cell = 1.0 / C, margin = 2.0 / T;
  const double fx = (x - ci * cell) / cell, fy = (y - cj * cell) / cell;
  return {(p % C) * cell + margin + fx * (cell - 2 * margin), (p / C) * cell + margin + fy * (cell - 2 * margin)};
}

// Every corner of every patch has the texture coordinates of the input; returns the triangles.
size_t checkCornerUVs(const PatchStore& store, int C, int T) {
  size_t triangles = 0;
  for (PatchId id : store.patchIds()) {
    Patch p = store.patch(id);
    EXPECT_EQ(p.cornerUV.size(), 6 * size_t(p.triangleCount()));
    for (uint32_t t = 0; t < p.triangleCount(); ++t) {
      EXPECT_EQ(p.triangleMaterial[t], 0u);
      double cx = 0, cy = 0;
      for (int k = 0; k < 3; ++k) cx += p.positions[3 * p.triangles[3 * t + k]] / 3, cy += p.positions[3 * p.triangles[3 * t + k] + 1] / 3;
      for (int k = 0; k < 3; ++k) {
        const double* q = &p.positions[3 * p.triangles[3 * t + k]];
        std::array<double, 2> uv = expectedUV(q[0], q[1], cx, cy, C, T);
        EXPECT_NEAR(p.cornerUV[6 * t + 2 * k], uv[0], 1e-5) << "patch " << id << " triangle " << t;
        EXPECT_NEAR(p.cornerUV[6 * t + 2 * k + 1], uv[1], 1e-5);
      }
      ++triangles;
    }
  }
  return triangles;
}

TEST(TextureStore, IngestKeepsCornersAndTilesTheImage) {
  test::TempDir dir;
  testing::TexturedGridOptions go;
  go.n = 40;
  go.charts = 2;
  const std::string obj = testing::writeTexturedGrid(dir.path(), "g", go);
  auto store = ingestTextured(obj, dir.file("s"));
  EXPECT_TRUE(store->layout().texcoords);
  std::vector<StoreMaterial> mats = storeMaterials(*store);
  ASSERT_EQ(mats.size(), 1u);
  EXPECT_EQ(mats[0].name, "skin");
  EXPECT_EQ(mats[0].width, 64);
  EXPECT_TRUE(std::filesystem::exists(dir.file("s/") + mats[0].file));
  EXPECT_EQ(checkCornerUVs(*store, 2, 64), 3200u);
  EXPECT_TRUE(store->check().ok);
  // The chunked path writes the same bytes as the resident one.
  auto chunked = ingestTextured(obj, dir.file("c"), 24ull << 20);
  EXPECT_TRUE(segments(dir.file("s")) == segments(dir.file("c")));
  // The PLY form (per-face texcoord lists) gives the same texture coordinates.
  go.ply = true;
  auto plyStore = ingestTextured(testing::writeTexturedGrid(dir.path(), "p", go), dir.file("p"));
  EXPECT_EQ(checkCornerUVs(*plyStore, 2, 64), 3200u);
}

TEST(TextureStore, GridWeldClosesSeamsAndKeepsCorners) {
  test::TempDir dir;
  testing::TexturedGridOptions go;
  go.n = 40;
  go.charts = 4;
  auto store = ingestTextured(testing::writeTexturedGrid(dir.path(), "g", go), dir.file("s"));
  uint64_t verticesBefore = 0;
  std::map<std::array<double, 3>, int> distinct;
  for (PatchId id : store->patchIds()) {
    Patch p = store->patch(id);
    for (uint32_t v = 0; v < p.vertexCount(); ++v) distinct[{p.positions[3 * v], p.positions[3 * v + 1], p.positions[3 * v + 2]}]++;
  }
  const auto unique = [&] {
    // Distinct store vertices: an exported PLY has each once.
    struct Count : MeshSink {
      uint64_t n = 0;
      void vertices(const InputVertex*, size_t k, uint64_t) override { n += k; }
      void triangles(const uint32_t*, size_t) override {}
    } c;
    store->exportPly(dir.file("x.ply"));
    openMesh(dir.file("x.ply"))->read(c);
    return c.n;
  };
  verticesBefore = unique();
  EXPECT_EQ(distinct.size(), 41u * 41u);
  EXPECT_GT(verticesBefore, 41u * 41u);  // the seams' twins
  heal::GridCells cells;
  cells.step = 1e-4;
  heal::HealOptions ho;
  ho.progress = false;
  heal::PassReport r = heal::weldToGrid(*store, cells, ho);
  EXPECT_EQ(r.get("merged"), verticesBefore - 41 * 41);
  EXPECT_EQ(r.get("degenerate"), 0u);
  EXPECT_EQ(unique(), 41u * 41u);
  EXPECT_EQ(checkCornerUVs(*store, 4, 64), 3200u);  // seams kept per corner
  EXPECT_TRUE(store->check().ok);
}

TEST(TextureStore, CheckFindsDamagedTiles) {
  test::TempDir dir;
  auto store = ingestTextured(testing::writeTexturedGrid(dir.path(), "g", {}), dir.file("s"));
  const std::string tiles = dir.file("s/") + storeMaterials(*store)[0].file;
  std::string bytes = test::readFile(tiles);
  bytes[80] ^= 1;
  test::writeFile(tiles, bytes);
  CheckReport r = PatchStore::open(dir.file("s"))->check();
  EXPECT_FALSE(r.ok);
  ASSERT_FALSE(r.problems.empty());
  EXPECT_THAT(r.problems[0], ::testing::HasSubstr("is damaged"));
}

// ---- The MT file ---------------------------------------------------------------------------------

struct LevelFidelity {
  uint64_t triangles = 0, off = 0;  // triangles whose centroid's colour is off by more than 48
  double meanError = 0;             // mean over triangles of the largest channel difference
};

// Every patch's texture checked against the colour function the textured grid shows: the atlas
// colour at each triangle's centroid (through the decoded corner coordinates) against
// texturedColor at its position. Per level.
std::map<uint32_t, LevelFidelity> textureFidelity(const std::string& path) {
  auto r = MtFileReader::open(path);
  EXPECT_TRUE(r->hasTextures());
  std::map<uint32_t, LevelFidelity> out;
  for (uint32_t a = 0; a < r->arcs().size(); ++a) {
    const uint32_t level = r->nodes()[r->arcs()[a].from].level;
    for (uint32_t k = 0; k < r->arcs()[a].patchCount; ++k) {
      const uint32_t p = r->patchRefs()[r->arcs()[a].firstPatchRef + k];
      DecodedPatch d = r->readPatch(p);
      std::vector<uint8_t> bytes = r->readTexturePayload(p);
      EXPECT_FALSE(bytes.empty()) << "patch " << p;
      if (bytes.empty()) continue;
      TexturePayload tp = decodeTexturePayload(bytes.data(), bytes.size(), d.triangles.data(), d.triangleCount(), d.vertexCount());
      EXPECT_EQ(tp.width, r->textures()[p].width);
      tex::RgbImage img = tex::decodeImage(tp.image.data(), tp.image.size(), "atlas");
      LevelFidelity& f = out[level];
      for (uint32_t t = 0; t < d.triangleCount(); ++t) {
        double x = 0, y = 0, u = 0, v = 0;
        for (int c = 0; c < 3; ++c) {
          x += d.positions[3 * d.triangles[3 * t + c]] / 3, y += d.positions[3 * d.triangles[3 * t + c] + 1] / 3;
          u += tp.cornerUV[6 * t + 2 * c] / 3, v += tp.cornerUV[6 * t + 2 * c + 1] / 3;
        }
        uint8_t got[3], want[3];
        tex::sampleBilinear(img, u, v, got);
        testing::texturedColor(x, y, want);
        double e = 0;
        for (int c = 0; c < 3; ++c) e = std::max(e, std::fabs(double(got[c]) - want[c]));
        f.meanError += e;
        f.off += e > 48;
        ++f.triangles;
      }
    }
  }
  for (auto& [level, f] : out) f.meanError /= double(std::max<uint64_t>(1, f.triangles));
  return out;
}

TEST(TextureBuild, EveryLevelShowsTheInputsColours) {
  test::TempDir dir;
  testing::TexturedGridOptions go;
  go.n = 120;
  go.charts = 4;
  go.textureSize = 512;
  const std::string obj = testing::writeTexturedGrid(dir.path(), "g", go);
  BuildOptions o;
  o.progress = false;
  o.patchTriangles = 600;
  o.threads = 2;
  BuildReport rep = buildMt(obj, dir.file("g.mt"), o);
  EXPECT_GT(rep.textureBytes, 0u);
  std::map<uint32_t, LevelFidelity> f = textureFidelity(dir.file("g.mt"));
  ASSERT_GE(f.size(), 3u) << "levels";
  for (auto& [level, lf] : f) {
    // The finest level keeps the input's texels (JPEG 90 aside); coarser ones are re-baked, each
    // from the one below, so they blur a little more per level.
    EXPECT_LT(lf.meanError, level == 0 ? 8.0 : 8.0 + 4.0 * level) << "level " << level;
    // Triangles whose centroid lies within a texel or two of a sharp edge of the pattern may be off:
    // a band that widens with the texels (they grow with the node error, up to 2x per level).
    EXPECT_LT(double(lf.off), 0.04 * (1 + level) * double(lf.triangles)) << "level " << level;
    std::printf("level %u: %llu triangles, mean error %.2f, off %llu\n", level, (unsigned long long)lf.triangles, lf.meanError, (unsigned long long)lf.off);
  }
  // The same bytes on one thread; mtverify's checks hold (checksums, crack-free random cuts).
  o.threads = 1;
  buildMt(obj, dir.file("g1.mt"), o);
  EXPECT_TRUE(test::readFile(dir.file("g.mt")) == test::readFile(dir.file("g1.mt")));
  test::CommandResult v = test::runTool("mtverify", dir.file("g.mt") + " --cuts 8");
  EXPECT_EQ(v.exitCode, 0) << v.output;

  // mtextract: the finest and a coarse cut as OBJ + MTL + PNG, read back by our own reader, show
  // the same colours.
  for (const char* cut : {"--error 0", "--triangles 2000"}) {
    test::CommandResult x = test::runTool("mtextract", dir.file("g.mt") + " " + cut + " -o " + dir.file("cut.obj"));
    ASSERT_EQ(x.exitCode, 0) << x.output;
    Collect c = readAll(dir.file("cut.obj"));
    ASSERT_TRUE(c.header.hasTexcoords);
    std::vector<tex::RgbImage> pages;
    for (const InputMaterial& m : c.header.materials)
      pages.push_back(m.texture.empty() ? tex::RgbImage() : tex::readImageFile(m.texture));
    double err = 0;
    for (size_t t = 0; t < c.t.size() / 3; ++t) {
      double x0 = 0, y0 = 0, u = 0, w = 0;
      for (int k = 0; k < 3; ++k) {
        const InputVertex& q = c.v[c.t[3 * t + size_t(k)]];
        x0 += q.p[0] / 3, y0 += q.p[1] / 3, u += q.uv[0] / 3, w += q.uv[1] / 3;
      }
      ASSERT_LT(c.v[c.t[3 * t]].material, pages.size());
      uint8_t got[3], want[3];
      tex::sampleBilinear(pages[c.v[c.t[3 * t]].material], u, w, got);
      testing::texturedColor(x0, y0, want);
      double e = 0;
      for (int k = 0; k < 3; ++k) e = std::max(e, std::fabs(double(got[k]) - want[k]));
      err += e;
    }
    EXPECT_LT(err / double(c.t.size() / 3), 14.0) << cut;
  }
  // A .obj of a cut too large for --memory is refused (exit 5), and nothing is left.
  test::CommandResult big = test::runTool("mtextract", dir.file("g.mt") + " --error 0 --memory 1M -o " + dir.file("big.obj"));
  EXPECT_EQ(big.exitCode, 5) << big.output;
  EXPECT_FALSE(test::fileExists(dir.file("big.obj")));
  EXPECT_FALSE(test::fileExists(dir.file("big.mtl")));
}

}  // namespace
}  // namespace mt
