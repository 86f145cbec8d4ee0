// mtrender's interactive viewer under a virtual X server (xvfb-run): it opens the GLFW window,
// renders a few frames of a replayed camera path with the HUD, takes a screenshot and exits.
#include <gtest/gtest.h>

#include <sys/wait.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "mtrender/image.h"
#include "tests/test_support.h"

using mt::test::runTool;
using mt::test::TempDir;

namespace {

int shell(const std::string& cmd, std::string& output) {
  FILE* pipe = popen((cmd + " 2>&1").c_str(), "r");
  if (!pipe) return -1;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, pipe)) > 0) output.append(buf, n);
  int status = pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST(MtRenderViewer, OpensRendersAndTakesAScreenshot) {
  std::string out;
  if (shell("command -v xvfb-run", out) != 0) GTEST_SKIP() << "xvfb-run is not installed";
  TempDir dir;
  ASSERT_EQ(runTool("mtgen", "-o " + dir.file("s.ply") + " --triangles 10k --seed 3").exitCode, 0);
  auto b = runTool("mtbuild", dir.file("s.ply") + " -o " + dir.file("s.mt") + " --patch-triangles 300 --threads 2 -q");
  ASSERT_EQ(b.exitCode, 0) << b.output;
  const std::string shot = dir.file("viewer.png"), stats = dir.file("viewer.csv");
  out.clear();
  int rc = shell("xvfb-run -a -s '-screen 0 640x480x24' " + mt::test::binDir() + "/mtrender " + dir.file("s.mt") +
                     " --width 256 --height 256 --camera-path orbit --max-frames 8 --screenshot " + shot +
                     " --stats " + stats,
                 out);
  ASSERT_EQ(rc, 0) << out;
  EXPECT_NE(out.find("frames 8"), std::string::npos) << out;
  mt::render::Image img = mt::render::readPng(shot);
  ASSERT_GT(img.width, 0);
  // The model is on screen: some pixels differ from the background colour (20, 23, 28).
  size_t covered = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const uint8_t* p = img.pixel(x, y);
      covered += p[0] != 20 || p[1] != 23 || p[2] != 28;
    }
  EXPECT_GT(covered, size_t(img.width) * img.height / 50);
  const std::string csv = mt::test::readFile(stats);
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 9);  // header + 8 frames
}

}  // namespace
