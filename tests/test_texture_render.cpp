// mtrender --color texture: a textured mtgen scan (`mtgen --texture charts`) built and drawn with
// its node textures. The RAM cache holds each textured patch's corner coordinates and texels in its
// place holder (counted in the cap), the GPU cache its split vertices and mipmapped atlas (counted
// in the GPU bytes), and the image shows the texture: the pattern's two check colours (orange and
// blue, testing/texture_atlas.h) where the untextured drawing has none, and a fine cut within 30 dB
// of the full resolution.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <limits>
#include <set>
#include <string>
#include <tuple>

#include "mtrender/color_mode.h"
#include "texture/image_codec.h"
#include "mtrender/gl_renderer.h"
#include "mtrender/image.h"
#include "mtrender/patch_server.h"
#include "test_support.h"
#include "test_support_render.h"

using mt::test::coveredPsnr;
using mt::test::runTool;
using mt::test::TempDir;
using ::testing::HasSubstr;
using ::testing::Not;
using namespace mt::render;

namespace {

class TexturedBuild : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    auto g = runTool("mtgen", "-o " + dir_->file("t.ply") + " --triangles 60k --holes 3 --seed 5 --texture charts");
    ASSERT_EQ(g.exitCode, 0) << g.output;
    auto b = runTool("mtbuild", dir_->file("t.ply") + " -o " + mt() + " --patch-triangles 500 --threads 2 -q");
    ASSERT_EQ(b.exitCode, 0) << b.output;
  }
  static void TearDownTestSuite() { delete dir_; }
  static std::string mt() { return dir_->file("t.mt"); }
  static TempDir* dir_;
};
TempDir* TexturedBuild::dir_ = nullptr;

Image render(const std::string& mt, const std::string& dir, const std::string& extra, std::string* log = nullptr) {
  std::filesystem::remove_all(dir);
  const int frames = 60;
  auto r = runTool("mtrender", mt + " --headless --width 320 --height 240 --camera-path fixed --frames " + std::to_string(frames) +
                                   " --screenshots " + dir + " --screenshot-every 1000 --fixed-triangles 400000 --cache 64M " + extra);
  EXPECT_EQ(r.exitCode, 0) << r.output;
  if (log) *log = r.output;
  char name[64];
  std::snprintf(name, sizeof name, "/frame_%05d.png", frames - 1);
  return readPng(dir + name);
}

// The pattern's checks: orange (225, 196, 90 tinted) and blue (60, 120, 190 tinted), each darkened
// by at most the ramp; the lines between them are a quarter as bright.
struct Census {
  size_t covered = 0, orange = 0, blue = 0;
};
Census census(const Image& img) {
  Census c;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const uint8_t* p = img.pixel(x, y);
      if (mt::test::isBackground(p)) continue;
      ++c.covered;
      c.orange += p[0] > 120 && p[0] > p[2] + 60;
      c.blue += p[2] > 100 && p[2] > p[0] + 60;
    }
  return c;
}

uint64_t statOf(const std::string& log, const std::string& key) {
  const size_t at = log.find("\n" + key + " ");
  if (at == std::string::npos) return 0;
  return std::stoull(log.substr(at + key.size() + 2));
}

}  // namespace

// The file says it has textures; auto and texture draw them.
TEST_F(TexturedBuild, AutoChoosesTextureForATexturedFile) {
  const ColorSupport s = colorSupportOf({mt()});
  EXPECT_TRUE(s.hasTextures);
  std::string note;
  EXPECT_EQ(resolveColorMode("auto", s, &note), ColorMode::Texture);
  EXPECT_EQ(resolveColorMode("texture", s, &note), ColorMode::Texture);
  EXPECT_EQ(note, "");
  EXPECT_EQ(nextColorMode(ColorMode::Vertex, s), ColorMode::Texture);
}

// The RAM cache: a textured patch's place holder holds its corner coordinates and its decoded atlas
// (the same texels the stored JPEG decodes to), counted in the patch's bytes and the cache's.
TEST_F(TexturedBuild, RamCacheHoldsAndCountsTheTexels) {
  mt::test::RenderRig rig({mt()}, 64ull << 20);
  const Scene& sc = rig.scene;
  const auto& reader = sc.reader(0);
  ASSERT_TRUE(reader.hasTextures());
  // Every textured patch's bound includes its texels; load a few of them.
  std::vector<LoadRequest> want;
  uint64_t textured = 0;
  for (uint32_t p = 0; p < sc.patchCount(); ++p) {
    const auto& rec = reader.textures()[sc.patch(p).local];
    if (rec.size == 0) continue;
    ++textured;
    EXPECT_GE(sc.decodedBytesBound(p), uint64_t(sc.patch(p).triangles) * 12 + uint64_t(rec.width) * rec.height * 3);
    if (want.size() < 8 && (p % 7) == 0) want.push_back({p, Urgency::UrgentDown});
  }
  ASSERT_GT(textured, sc.patchCount() / 2) << "most patches carry an atlas";
  ASSERT_FALSE(want.empty());
  rig.server->submit(want, 1);
  ASSERT_TRUE(rig.server->waitIdle(60000));
  EXPECT_EQ(rig.server->badPatches(), 0u);
  uint64_t viewBytes = 0;
  for (const LoadRequest& r : want) {
    ASSERT_EQ(rig.cache->state(r.id), PatchCache::State::Ready);
    const uint32_t id = r.id;
    ASSERT_TRUE(rig.cache->pinAll(&id, 1));
    const PatchView v = rig.cache->view(id);
    const auto& rec = reader.textures()[sc.patch(id).local];
    ASSERT_TRUE(v.textured());
    EXPECT_EQ(v.texWidth, rec.width);
    EXPECT_EQ(v.texHeight, rec.height);
    EXPECT_EQ(v.bytes(), renderPatchBytes(v.vertexCount, v.indexCount / 3) + uint64_t(v.indexCount) * 4 +
                             uint64_t(rec.width) * rec.height * 3);
    viewBytes += v.bytes();
    // The texels are the stored image's, bottom row first.
    const mt::DecodedPatch d = reader.readPatch(sc.patch(id).local);
    const mt::TexturePayload t = reader.readTexture(sc.patch(id).local, d);
    const mt::tex::RgbImage img = mt::tex::decodeAnyImage(t.image.data(), t.image.size(), "atlas");
    for (int y : {0, int(rec.height) / 2, int(rec.height) - 1})
      for (int x : {0, int(rec.width) / 3, int(rec.width) - 1})
        for (int k = 0; k < 3; ++k)
          ASSERT_EQ(v.texels[(size_t(rec.height - 1 - y) * rec.width + x) * 3 + k], img.pixel(x, y)[k]) << x << "," << y;
    // Corner coordinates as stored, to unorm16.
    for (uint32_t i = 0; i < v.indexCount; i += 97)
      EXPECT_NEAR(v.cornerUV[i * 2] / 65535.0, t.cornerUV[i * 2], 1.0 / 65535);
    rig.cache->unpinAll(&id, 1);
  }
  EXPECT_GE(rig.cache->stats().usedBytes, viewBytes) << "the cache's bytes count the texels";
}

// The split: one GPU vertex per distinct (vertex, coordinate) pair, each corner keeping its vertex
// and its coordinate; the GPU cache counts the atlas with its mips and keeps its cap.
TEST_F(TexturedBuild, GpuSplitsVerticesAndCountsTheAtlas) {
  mt::test::RenderRig rig({mt()}, 64ull << 20);
  const auto& reader = rig.scene.reader(0);
  uint32_t id = 0;
  while (reader.textures()[rig.scene.patch(id).local].size == 0) ++id;
  rig.server->submit({{id, Urgency::UrgentDown}}, 1);
  ASSERT_TRUE(rig.server->waitIdle(60000));
  ASSERT_TRUE(rig.cache->pinAll(&id, 1));
  const PatchView v = rig.cache->view(id);
  ASSERT_TRUE(v.textured());
  std::vector<TexturedVertex> split;
  std::vector<uint32_t> indices;
  splitTexturedVertices(v, split, indices);
  std::set<std::tuple<uint32_t, uint16_t, uint16_t>> pairs;
  for (uint32_t i = 0; i < v.indexCount; ++i) pairs.insert({v.indices[i], v.cornerUV[2 * i], v.cornerUV[2 * i + 1]});
  EXPECT_EQ(split.size(), pairs.size());
  EXPECT_GT(split.size(), v.vertexCount) << "a patch of a charted scan has seams";
  ASSERT_EQ(indices.size(), v.indexCount);
  for (uint32_t i = 0; i < v.indexCount; ++i) {
    const TexturedVertex& s = split[indices[i]];
    ASSERT_EQ(s.uv[0], v.cornerUV[2 * i]);
    ASSERT_EQ(s.uv[1], v.cornerUV[2 * i + 1]);
    ASSERT_EQ(std::memcmp(&s.vertex, &v.vertices[v.indices[i]], sizeof(RenderVertex)), 0);
  }
  EglContext egl;
  const uint64_t atlas = mippedTextureBytes(v.texWidth, v.texHeight);
  EXPECT_GT(atlas, uint64_t(v.texWidth) * v.texHeight * 4);
  const uint64_t total = split.size() * sizeof(TexturedVertex) + uint64_t(v.indexCount) * 4 + atlas;
  const double origin[3] = {0, 0, 0};
  View view;
  view.width = view.height = 64;
  DrawSettings tex;
  tex.mode = ColorMode::Texture;
  {
    GlRenderer gl(64ull << 20);
    gl.useOffscreen(64, 64);
    gl.beginFrame(view, tex);
    EXPECT_EQ(gl.drawPatch(id, 0, origin, [&] { return v; }), v.indexCount / 3);
    EXPECT_EQ(gl.gpuTextureBytes(), atlas);
    EXPECT_EQ(gl.gpuBytes(), total);
    EXPECT_EQ(gl.texturedDraws(), 1u);
    gl.endFrame();
  }
  {
    // Other modes upload the geometry only; texture mode then uploads it again with its atlas.
    GlRenderer gl(64ull << 20);
    gl.useOffscreen(64, 64);
    DrawSettings vertex;
    vertex.mode = ColorMode::Vertex;
    gl.beginFrame(view, vertex);
    gl.drawPatch(id, 0, origin, [&] { return v; });
    EXPECT_EQ(gl.gpuTextureBytes(), 0u);
    EXPECT_EQ(gl.gpuBytes(), renderPatchBytes(v.vertexCount, v.indexCount / 3));
    gl.endFrame();
    gl.beginFrame(view, tex);
    gl.drawPatch(id, 0, origin, [&] { return v; });
    EXPECT_EQ(gl.gpuBytes(), total);
    EXPECT_EQ(gl.uploads(), 2u);
    gl.endFrame();
  }
  {
    // A cap below the patch with its atlas: not drawn, never over the cap.
    GlRenderer gl(total - 1);
    gl.useOffscreen(64, 64);
    gl.beginFrame(view, tex);
    EXPECT_EQ(gl.drawPatch(id, 0, origin, [&] { return v; }), 0u);
    EXPECT_EQ(gl.gpuBytes(), 0u);
    gl.endFrame();
  }
  rig.cache->unpinAll(&id, 1);
}

// The image: the texture's check colours show (the untextured drawing of the same file is white),
// in about the checker's proportions; a 0.25 px cut is within 30 dB of the full resolution (1 px:
// 20, see below), and far from the untextured drawing; auto draws the same image as texture.
TEST_F(TexturedBuild, RendersTheTextureCloseToTheFullResolution) {
  std::string log;
  const Image full = render(mt(), dir_->file("full"), "--color texture --tolerance 0.01", &log);
  EXPECT_THAT(log, Not(HasSubstr("no texture")));
  EXPECT_GT(statOf(log, "gpu_texture_bytes"), 0u) << log;
  const Image cut = render(mt(), dir_->file("cut"), "--color texture --tolerance 1");
  const Image fine = render(mt(), dir_->file("quarter"), "--color texture --tolerance 0.25");
  const Image white = render(mt(), dir_->file("vertex"), "--color vertex --tolerance 0.01");
  const Image autoMode = render(mt(), dir_->file("auto"), "--tolerance 0.01");
  const size_t pixels = size_t(full.width) * full.height;
  const Census f = census(full), w = census(white);
  ASSERT_GT(f.covered, pixels / 10) << "the model is in view";
  EXPECT_GT(f.orange, f.covered / 8) << "orange checks";
  EXPECT_GT(f.blue, f.covered / 8) << "blue checks";
  EXPECT_LT(double(std::max(f.orange, f.blue)), 3.0 * double(std::min(f.orange, f.blue))) << "about as many of each";
  EXPECT_EQ(w.orange + w.blue, 0u) << "the untextured drawing has no texture colours";
  // A node's texels are no wider than its error (mtbuild/region_texture.h), so the 1 px cut shows
  // texels of at most a pixel: 27.9 dB here (22.2 when the texel size followed the level, not the
  // error: texels of ~2 px at the 1 px cut), point-sampled at 320 x 240 against a reference whose
  // texels are far below a pixel (docs/appearance.md "Figures" measures it box-filtered: 30.8 dB).
  const double psnr = coveredPsnr(fine, full), psnr1 = coveredPsnr(cut, full);
  EXPECT_GE(psnr, 30.0) << "0.25 px cut against the full resolution";
  EXPECT_GE(psnr1, 25.0) << "1 px cut against the full resolution";
  EXPECT_LT(coveredPsnr(white, full), 15.0) << "the texture differs from the untextured drawing";
  EXPECT_EQ(autoMode.rgba, full.rgba) << "auto draws a textured file's textures";
  // The baseline (patches and atlases decoded inside the frame, no cache) draws the same image.
  const Image baseline = render(mt(), dir_->file("baseline"), "--color texture --tolerance 0.01 --baseline-mmap");
  EXPECT_GE(coveredPsnr(baseline, full), 45.0) << "the baseline's texture path against the cache's";
  std::printf("texture: covered %zu orange %zu blue %zu; 0.25 px cut %.1f dB, 1 px cut %.1f dB\n", f.covered, f.orange, f.blue,
              psnr, psnr1);
}

// Drawn other than textured (headless), a textured file's atlases are neither read nor counted:
// the place holders are sized without texels, and the caches hold none.
TEST_F(TexturedBuild, ShadedDrawingLoadsNoTexels) {
  Scene withTexels({mt()}), without({mt()});
  without.setLoadTextures(false);
  // The engine sizes its cache with the bounds of every patch at once: the same as one by one.
  const std::vector<uint64_t> allWith = withTexels.decodedBytesBounds(), allWithout = without.decodedBytesBounds();
  ASSERT_EQ(allWith.size(), withTexels.patchCount());
  ASSERT_EQ(allWithout.size(), without.patchCount());
  uint64_t texelBytes = 0;
  for (uint32_t p = 0; p < withTexels.patchCount(); ++p) {
    const auto& rec = withTexels.reader(0).textures()[withTexels.patch(p).local];
    const uint64_t expected = rec.size ? renderTextureBytes(withTexels.patch(p).triangles, rec.width, rec.height) : 0;
    EXPECT_EQ(withTexels.decodedBytesBound(p), without.decodedBytesBound(p) + expected) << "patch " << p;
    EXPECT_EQ(allWith[p], withTexels.decodedBytesBound(p)) << "patch " << p;
    EXPECT_EQ(allWithout[p], without.decodedBytesBound(p)) << "patch " << p;
    texelBytes += expected;
  }
  EXPECT_GT(texelBytes, 0u);
  std::string textured, shaded;
  render(mt(), dir_->file("tex"), "--color texture --tolerance 0.01", &textured);
  render(mt(), dir_->file("shaded"), "--color shaded --tolerance 0.01", &shaded);
  EXPECT_GT(statOf(textured, "gpu_texture_bytes"), 0u) << textured;
  EXPECT_EQ(statOf(shaded, "gpu_texture_bytes"), 0u) << shaded;
  EXPECT_LT(statOf(shaded, "cache_max_bytes"), statOf(textured, "cache_max_bytes"));
}

// A file without textures still falls back, saying so.
TEST(TextureRender, FileWithoutTexturesFallsBack) {
  TempDir dir;
  const std::string mt = mt::test::buildScanMt(dir, "u", "20k");
  std::string note;
  const ColorMode m = resolveColorMode("texture", colorSupportOf({mt}), &note);
  EXPECT_EQ(m, ColorMode::Shaded);
  EXPECT_THAT(note, HasSubstr("no texture in " + mt));
}

// mtgen refuses --texture charts|fragmented with --paint (it would drop the texture silently), and
// --texture box without it.
TEST(TextureRender, MtgenRefusesTextureWithPaint) {
  TempDir dir;
  auto g = runTool("mtgen", "-o " + dir.file("g.ply") + " --triangles 5k --seed 3");
  ASSERT_EQ(g.exitCode, 0) << g.output;
  auto bad = runTool("mtgen", "-o " + dir.file("p.ply") + " --paint " + dir.file("g.ply") + " --texture charts");
  EXPECT_NE(bad.exitCode, 0);
  EXPECT_THAT(bad.output, HasSubstr("--texture cannot be combined with --paint, except as --texture box"));
  EXPECT_FALSE(std::filesystem::exists(dir.file("p.ply")));
  auto box = runTool("mtgen", "-o " + dir.file("b.ply") + " --triangles 5k --texture box");
  EXPECT_NE(box.exitCode, 0);
  EXPECT_THAT(box.output, HasSubstr("--texture box textures a mesh given by --paint IN"));
  EXPECT_FALSE(std::filesystem::exists(dir.file("b.ply")));
}
