// A textured mesh derived from a real scan: the scangen dragon (../shared/tools/scangen.cpp on
// Debian's libcgal-demo ChineseDragon-10kv, with holes) given box-mapped charts and a texture of
// the colour field by `mtgen --paint IN --texture box` (testing/box_texture.h), so the textured
// pipeline is tested on a shape mtgen did not make: seams along the block planes and wherever
// the normal's dominant axis changes (scattered on a noisy scan), holes, a real scan's triangle
// sizes. It builds, every cut mtverify draws is crack-free, and the 1 px cut drawn with its
// node textures is within 30 dB of the full resolution.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <regex>
#include <string>

#include "mtrender/image.h"
#include "test_support.h"
#include "test_support_render.h"

using mt::test::coveredPsnr;
using mt::test::fileExists;
using mt::test::runShell;
using mt::test::runTool;
using mt::test::TempDir;
using ::testing::HasSubstr;

namespace {

const std::string kSourceDir = MT_SOURCE_DIR;
const std::string kBuildDir = MT_BUILD_DIR;

// The fixed view at 1280 x 960, box-filtered to 320 x 240 (the reference's texels and triangles
// are far below a pixel: point-sampled, its aliasing would be most of any difference).
mt::render::Image render(const std::string& mt, const std::string& dir, const std::string& extra, uint64_t* triangles) {
  std::filesystem::remove_all(dir);
  const int frames = 60;
  auto r = runTool("mtrender", mt + " --headless --width 1280 --height 960 --camera-path fixed --frames " + std::to_string(frames) +
                                   " --screenshots " + dir + " --screenshot-every 1000 --fixed-triangles 2000000 --cache 256M " +
                                   "--color texture --stats " + dir + ".csv " + extra);
  EXPECT_EQ(r.exitCode, 0) << r.output;
  EXPECT_THAT(r.output, ::testing::Not(HasSubstr("no texture")));
  // The last frame's drawn triangles: the CSV's fourth column.
  const std::string csv = mt::test::readFile(dir + ".csv");
  const size_t last = csv.find_last_of('\n', csv.size() - 2);
  size_t at = last + 1;
  for (int comma = 0; comma < 3; ++comma) at = csv.find(',', at) + 1;
  *triangles = std::stoull(csv.substr(at));
  char name[64];
  std::snprintf(name, sizeof name, "/frame_%05d.png", frames - 1);
  return mt::test::boxDownsample(mt::render::readPng(dir + name), 4);
}

}  // namespace

TEST(TexturedScan, DragonBuildsCrackFreeAndDrawsItsTextureAtOnePixel) {
  const std::string scangenSource = kSourceDir + "/../shared/tools/scangen.cpp";
  ASSERT_TRUE(fileExists(scangenSource)) << scangenSource << " is missing: the scan-derived meshes are made by "
                                         << "../shared/tools/scangen.cpp, so shared/ must be beside the repository";
  ASSERT_TRUE(fileExists(mt::test::binDir() + "/scangen")) << "build/bin/scangen is missing: re-run cmake and build it";
  const std::string bases = kBuildDir + "/scan-bases";
  auto fetched = runShell(kSourceDir + "/scripts/scan_bases.sh " + bases);  // does nothing when complete
  ASSERT_EQ(fetched.exitCode, 0) << "scripts/scan_bases.sh could not fetch the base models:\n" << fetched.output;
  TempDir dir;
  auto made = runTool("scangen", bases + "/ChineseDragon-10kv.off 2 " + dir.file("dragon.ply") + " --holes 0.3");
  ASSERT_EQ(made.exitCode, 0) << made.output;

  // The texture: one PNG page, charts of 2 x 2 x 2 blocks times 6 directions.
  auto painted = runTool("mtgen", "-o " + dir.file("dt.ply") + " --paint " + dir.file("dragon.ply") + " --texture box");
  ASSERT_EQ(painted.exitCode, 0) << painted.output;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(painted.output, m, std::regex("([0-9]+) triangles, ([0-9]+) charts"))) << painted.output;
  EXPECT_GT(std::stoull(m[1]), 200'000u) << "the dragon at scangen level 2";
  EXPECT_GE(std::stoul(m[2]), 24u) << "charts in most of the 48 (block, direction) pairs: seams";
  EXPECT_TRUE(fileExists(dir.file("dt_tex0.png")));

  auto built = runTool("mtbuild", dir.file("dt.ply") + " -o " + dir.file("dt.mt") + " --threads 2 -q");
  ASSERT_EQ(built.exitCode, 0) << built.output;
  auto info = runTool("mtinfo", dir.file("dt.mt"));
  EXPECT_THAT(info.output, HasSubstr("textures")) << info.output;
  auto verified = runTool("mtverify", dir.file("dt.mt") + " --cuts 32");
  EXPECT_EQ(verified.exitCode, 0) << verified.output;
  EXPECT_THAT(verified.output, HasSubstr("34 of 34 conforming")) << verified.output;

  // The 1 px cut (tolerance 4 at 4x the size) against the full resolution (every patch of the
  // input, without culling). A node's texels are no wider than its error (the texel size enters
  // the error when the floor's texels are wider: mtbuild/region_texture.h), so the cut shows no
  // texel wider than a pixel: 31.5 dB measured, 27.6 dB when the texel size followed the level.
  uint64_t fullTriangles = 0, cutTriangles = 0, coarseTriangles = 0;
  const auto full = render(dir.file("dt.mt"), dir.file("full"), "--tolerance 0.01 --no-cull", &fullTriangles);
  const auto cut = render(dir.file("dt.mt"), dir.file("cut"), "--tolerance 4", &cutTriangles);
  const auto coarse = render(dir.file("dt.mt"), dir.file("coarse"), "--tolerance 32", &coarseTriangles);
  EXPECT_LT(cutTriangles, fullTriangles) << "the 1 px cut is coarser than the full resolution";
  const double psnr = coveredPsnr(cut, full), psnrCoarse = coveredPsnr(coarse, full);
  EXPECT_GE(psnr, 30.0) << "1 px cut against the full resolution";
  EXPECT_LT(psnrCoarse, psnr) << "an 8 px cut is farther from it (the comparison can fail)";
  std::printf("textured dragon: full %llu triangles; 1 px cut %llu triangles, %.1f dB; 8 px cut %llu triangles, %.1f dB\n",
              (unsigned long long)fullTriangles, (unsigned long long)cutTriangles, psnr, (unsigned long long)coarseTriangles,
              psnrCoarse);
}
