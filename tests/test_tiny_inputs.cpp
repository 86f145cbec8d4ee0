// Tiny and degenerate inputs: each builds an MT file that mtverify accepts and mtextract cuts, or
// is refused with one line naming the input and exit code 1 and no output. Never a crash, never
// a file mtverify rejects.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <filesystem>
#include <sstream>

#include "base/exit_code.h"
#include "test_support.h"

namespace fs = std::filesystem;
using mt::test::CommandResult;
using mt::test::TempDir;
using mt::test::runTool;
using mt::test::writeFile;

namespace {

struct Case {
  std::string name, off;
};

std::string off(const std::vector<std::array<double, 3>>& v, const std::vector<std::array<int, 3>>& f) {
  std::ostringstream s;
  s.precision(17);
  s << "OFF\n" << v.size() << " " << f.size() << " 0\n";
  for (const auto& p : v) s << p[0] << " " << p[1] << " " << p[2] << "\n";
  for (const auto& t : f) s << "3 " << t[0] << " " << t[1] << " " << t[2] << "\n";
  return s.str();
}

// n separate triangles (one component each), spread along x.
std::string separateTriangles(int n, bool flat) {
  std::vector<std::array<double, 3>> v;
  std::vector<std::array<int, 3>> f;
  for (int i = 0; i < n; ++i) {
    const double x = 3.0 * i, z = flat ? 0.0 : 0.1 * (i % 7);
    v.push_back({x, 0, z});
    v.push_back({x + 1, 0, z});
    v.push_back({x, 1, z + (flat ? 0.0 : 0.5)});
    f.push_back({3 * i, 3 * i + 1, 3 * i + 2});
  }
  return off(v, f);
}

std::vector<Case> cases() {
  std::vector<Case> c;
  c.push_back({"one", off({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 1, 2}})});
  c.push_back({"two", off({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}}, {{0, 1, 2}, {1, 3, 2}})});
  c.push_back({"three", off({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 1}, {2, 0, 0}}, {{0, 1, 2}, {1, 3, 2}, {1, 4, 3}})});
  c.push_back({"collinear", off({{0, 0, 0}, {1, 0, 0}, {2, 0, 0}}, {{0, 1, 2}})});
  // Every triangle degenerate: repeated indices, and a point repeated three times.
  c.push_back({"all_degenerate", off({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, {{0, 0, 1}, {1, 2, 2}, {0, 1, 1}})});
  c.push_back({"one_point", off({{1, 1, 1}, {1, 1, 1}, {1, 1, 1}}, {{0, 1, 2}})});
  // A single line: every vertex on the x axis (a bounding box with two zero extents).
  c.push_back({"line", off({{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {3, 0, 0}}, {{0, 1, 2}, {1, 2, 3}, {0, 2, 3}})});
  c.push_back({"components_300", separateTriangles(300, false)});
  c.push_back({"flat_components_500", separateTriangles(500, true)});
  return c;
}

}  // namespace

TEST(TinyInputs, BuildAValidFileOrAreRefusedClearly) {
  TempDir tmp;
  int built = 0, refused = 0;
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.name);
    const std::string in = tmp.file(c.name + ".off"), out = tmp.file(c.name + ".mt");
    writeFile(in, c.off);
    CommandResult b = runTool("mtbuild", in + " -o " + out + " -q --threads 1");
    if (b.exitCode == 0) {
      ++built;
      CommandResult v = runTool("mtverify", out);
      EXPECT_EQ(v.exitCode, 0) << v.output;
      CommandResult x = runTool("mtextract", out + " --error 0 -o " + tmp.file(c.name + ".ply"));
      EXPECT_EQ(x.exitCode, 0) << x.output;
      EXPECT_EQ(runTool("mtinfo", "--check " + out).exitCode, 0);
    } else {
      ++refused;
      EXPECT_EQ(b.exitCode, mt::kExitInvalidInput) << b.output;
      EXPECT_NE(b.output.find(in), std::string::npos) << "names the input: " << b.output;
      EXPECT_EQ(std::count(b.output.begin(), b.output.end(), '\n'), 1) << "one line: " << b.output;
      EXPECT_FALSE(fs::exists(out));
    }
    std::printf("[ tiny ] %-20s %s\n", c.name.c_str(), b.exitCode == 0 ? "built, verified" : b.output.c_str());
  }
  EXPECT_GE(built, 5) << "the non-degenerate ones build";
  (void)refused;
}
