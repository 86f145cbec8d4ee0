// mtbuild end to end on small generated scans: determinism (threads, memory cap), the DAG's
// invariants (monotone errors, nested spheres, every patch on one arc), holes still simplify.
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <filesystem>
#include <random>

#include <nlohmann/json.hpp>

#include "mtbuild/build.h"
#include "mtfile/mt_file.h"
#include "mtbuild/region_window.h"
#include "tests/test_support.h"

namespace mt::test {
namespace {

namespace fs = std::filesystem;

std::string makeScan(const TempDir& tmp, const std::string& name, const std::string& options) {
  std::string path = tmp.file(name);
  CommandResult r = runTool("mtgen", "-o " + path + " " + options);
  EXPECT_EQ(r.exitCode, 0) << r.output;
  return path;
}

void build(const std::string& in, const std::string& out, const std::string& options) {
  CommandResult r = runTool("mtbuild", in + " -o " + out + " -q " + options);
  ASSERT_EQ(r.exitCode, 0) << r.output;
}

TEST(Mtbuild, SameBytesWhateverTheThreadsAndTheMemoryCap) {
  TempDir tmp;
  std::string in = makeScan(tmp, "scan.ply", "--triangles 60k --holes 12 --shuffle --seed 5");
  build(in, tmp.file("t1.mt"), "--threads 1 --memory 1G");
  build(in, tmp.file("t2.mt"), "--threads 2 --memory 1G");
  build(in, tmp.file("m.mt"), "--threads 0 --memory 24M");  // 0: all cores
  std::string a = readFile(tmp.file("t1.mt"));
  EXPECT_GT(a.size(), 10000u);
  EXPECT_TRUE(a == readFile(tmp.file("t2.mt"))) << "--threads 1 and 2 differ";
  EXPECT_TRUE(a == readFile(tmp.file("m.mt"))) << "--memory 1G and 24M (and --threads 0) differ";
  for (auto& e : fs::directory_iterator(tmp.path()))
    EXPECT_EQ(e.path().string().find(".work"), std::string::npos) << "work directory left behind: " << e.path();
}

// The level loop's window, driven through random schedules as the threads drive it (start in
// order, process out of order, commit in order): the bytes in flight stay within
// max(budget, the largest region), the count bound holds, and every level empties.
TEST(MtbuildWindow, BytesInFlightStayWithinTheBudgetOrOneRegion) {
  std::mt19937 rng(7);
  for (int round = 0; round < 200; ++round) {
    const size_t regions = 1 + rng() % 40, maxRegions = 1 + rng() % 6;
    std::vector<RegionBytes> bytes(regions);
    uint64_t largest = 0;
    for (RegionBytes& b : bytes) {
      b = estimateRegionBytes(1 + rng() % 200000, rng() % 120000);
      largest = std::max(largest, b.working);
    }
    const uint64_t budget = round % 4 == 0 ? 0 : round % 4 == 1 ? 1 : largest / 2 + rng() % (3 * largest);
    RegionWindow w(budget, maxRegions);
    size_t started = 0, committed = 0;
    std::vector<bool> processed(regions, false);
    for (int steps = 0; committed < regions; ++steps) {
      ASSERT_LT(steps, 100000) << "the window does not empty";
      const int move = int(rng() % 3);
      if (move == 0 && started < regions && w.admits(bytes[started].working)) {
        w.start(bytes[started++]);
      } else if (move == 1 && committed < started) {
        size_t i = committed + rng() % (started - committed);
        if (!processed[i]) w.processed(bytes[i]), processed[i] = true;
      } else if (move == 2 && committed < started && processed[committed]) {
        w.committed(bytes[committed++]);
      } else if (started == committed) {
        ASSERT_TRUE(w.admits(bytes[started].working)) << "an empty window must admit the next region";
      }
      ASSERT_LE(w.bytes(), std::max(budget == 0 ? UINT64_MAX : budget, largest));
      ASSERT_LE(w.regions(), maxRegions);
    }
    EXPECT_EQ(w.bytes(), 0u);
    EXPECT_EQ(w.regions(), 0u);
    if (budget == 1) {
      EXPECT_EQ(w.peakRegions(), 1u) << "a budget below every region runs them one at a time";
    }
  }
}

// The byte bound in the real level loop: the same bytes whatever the budget and the threads; at a
// budget below every region one region is in flight, at a large one the count bound rules, in
// between the bytes in flight stay within it.
TEST(MtbuildWindow, TheLevelLoopHonoursItsByteBudgetAndKeepsTheBytes) {
  TempDir tmp;
  std::string in = makeScan(tmp, "scan.ply", "--triangles 60k --holes 6 --seed 21");
  auto buildWith = [&](const std::string& name, uint32_t threads, uint64_t budget) {
    BuildOptions o;
    o.threads = threads;
    o.progress = false;
    o.patchTriangles = 400;
    o.levelLoopBytes = budget;
    return buildMt(in, tmp.file(name), o);
  };
  BuildReport tiny1 = buildWith("tiny1.mt", 1, 1), tiny2 = buildWith("tiny2.mt", 2, 1);
  BuildReport large1 = buildWith("large1.mt", 1, 1ull << 40), large2 = buildWith("large2.mt", 2, 1ull << 40);
  const uint64_t largest = tiny2.levelLoopLargestRegionBytes;
  ASSERT_GT(largest, 0u);
  BuildReport mid = buildWith("mid.mt", 2, 2 * largest + largest / 2);
  const std::string bytes = readFile(tmp.file("tiny1.mt"));
  ASSERT_GT(bytes.size(), 10000u);
  for (const char* name : {"tiny2.mt", "large1.mt", "large2.mt", "mid.mt"})
    EXPECT_TRUE(readFile(tmp.file(name)) == bytes) << name << " differs from tiny1.mt";
  for (const BuildReport* r : {&tiny1, &tiny2}) {
    EXPECT_EQ(r->levelLoopPeakRegions, 1u);
    EXPECT_EQ(r->levelLoopPeakBytes, r->levelLoopLargestRegionBytes);
  }
  EXPECT_LE(mid.levelLoopPeakBytes, mid.levelLoopBytes);
  EXPECT_EQ(mid.levelLoopLargestRegionBytes, largest);
  EXPECT_LE(large1.levelLoopPeakRegions, 2u) << "one thread: one region processed, one waiting at most";
  EXPECT_GE(large2.levelLoopPeakRegions, 2u) << "two threads and no byte bound keep two regions in flight";
  EXPECT_LE(large2.levelLoopPeakRegions, 4u) << "the count bound: 2 x threads";
}

TEST(Mtbuild, DagInvariantsHold) {
  TempDir tmp;
  std::string in = makeScan(tmp, "scan.ply", "--triangles 40k --holes 8 --components 2 --seed 9");
  build(in, tmp.file("a.mt"), "--patch-triangles 300");
  auto mt = MtFileReader::open(tmp.file("a.mt"));
  const auto& nodes = mt->nodes();
  const auto& arcs = mt->arcs();
  ASSERT_GT(nodes.size(), 10u);
  EXPECT_TRUE(std::isinf(nodes.back().error));
  std::vector<int> onArc(mt->patches().size(), 0);
  for (const auto& arc : arcs) {
    const auto& from = nodes[arc.from];
    const auto& to = nodes[arc.to];
    EXPECT_GE(to.error, from.error) << "error must not shrink towards the sink";
    EXPECT_LT(from.level, to.level);
    if (arc.from != 0) {
      double d = std::sqrt(std::pow(to.center[0] - from.center[0], 2) + std::pow(to.center[1] - from.center[1], 2) +
                           std::pow(to.center[2] - from.center[2], 2));
      EXPECT_LE(d + from.radius, to.radius * (1 + 1e-6)) << "sphere of node " << arc.to << " must contain node " << arc.from;
    }
    for (uint32_t i = 0; i < arc.patchCount; ++i) ++onArc[mt->patchRefs()[arc.firstPatchRef + i]];
  }
  for (size_t p = 0; p < onArc.size(); ++p) EXPECT_EQ(onArc[p], 1) << "patch " << p;
  // Every patch decodes and lies within its producing node's sphere.
  for (uint32_t p = 0; p < mt->patches().size(); ++p) {
    DecodedPatch d = mt->readPatch(p);
    const auto& node = nodes[arcs[mt->patches()[p].arc].from];
    if (mt->patches()[p].arc == 0 || arcs[mt->patches()[p].arc].from == 0) continue;
    for (size_t v = 0; v < d.positions.size(); v += 3) {
      double d2 = 0;
      for (int a = 0; a < 3; ++a) d2 += std::pow(d.positions[v + a] - node.center[a], 2);
      EXPECT_LE(std::sqrt(d2), node.radius + 2 * mt->header().quantizationError);
    }
  }
}

TEST(Mtbuild, AScanWithManyHolesReachesASmallCoarsestLevel) {
  TempDir tmp;
  std::string in = makeScan(tmp, "holes.ply", "--triangles 80k --holes 60 --seed 2");
  build(in, tmp.file("h.mt"), "--patch-triangles 200");
  auto mt = MtFileReader::open(tmp.file("h.mt"));
  const uint32_t sink = uint32_t(mt->nodes().size() - 1);
  uint64_t top = 0;
  for (const auto& arc : mt->arcs())
    if (arc.to == sink)
      for (uint32_t i = 0; i < arc.patchCount; ++i) top += mt->patches()[mt->patchRefs()[arc.firstPatchRef + i]].triangles;
  EXPECT_LE(top, mt->header().inputTriangles / 100) << "coarsest level has " << top << " triangles";
}

// --stats-json says where the CPU went: the ingest's and every level's user and kernel seconds,
// and the whole run's. The kernel's count of the child's CPU (RUSAGE_CHILDREN: the shell and
// mtbuild, reaped) bounds the run's total from above, which bounds the ingest's and the levels'
// sum: a level reporting the CPU since the start, or since the ingest, would exceed it.
double childCpuSeconds() {
  rusage u{};
  getrusage(RUSAGE_CHILDREN, &u);
  return double(u.ru_utime.tv_sec) + double(u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

TEST(MtbuildStats, EveryLevelReportsWhereItsCpuWent) {
  TempDir tmp;
  std::string in = makeScan(tmp, "scan.ply", "--triangles 60k --holes 6 --seed 3");
  const double before = childCpuSeconds();
  build(in, tmp.file("s.mt"), "--patch-triangles 300 --threads 2 --stats-json " + tmp.file("s.json"));
  const double outside = childCpuSeconds() - before;
  const nlohmann::json d = nlohmann::json::parse(readFile(tmp.file("s.json")));
  ASSERT_GE(d["levels"].size(), 3u) << d.dump(1);
  const double total = d["cpu_user_seconds"].get<double>() + d["cpu_sys_seconds"].get<double>();
  const double ingest = d["ingest_user_seconds"].get<double>() + d["ingest_sys_seconds"].get<double>();
  EXPECT_GT(d["ingest_user_seconds"].get<double>() + d["ingest_sys_seconds"].get<double>(), 0) << "the ingest reads and sorts";
  EXPECT_GE(d["ingest_sys_seconds"].get<double>(), 0);
  double levels = 0;
  for (const nlohmann::json& l : d["levels"]) {
    ASSERT_TRUE(l.contains("user_seconds") && l.contains("sys_seconds")) << l.dump();
    const double user = l["user_seconds"].get<double>(), sys = l["sys_seconds"].get<double>();
    EXPECT_GE(user, 0) << l.dump();
    EXPECT_GE(sys, 0) << l.dump();
    EXPECT_GT(user + sys, 0) << "level " << l["level"] << " simplified " << l["triangles_in"] << " triangles without CPU";
    // Two workers (TBB limited to two as well) over the level's wall time, and a little for the
    // clock reads' order.
    EXPECT_LE(user + sys, 2 * l["seconds"].get<double>() + 0.05) << l.dump();
    levels += user + sys;
    // Every region runs the simplifier at least once, and at most 17 times (simplifyWithRules)
    // per simplifyRegion call, of which the root's settleRoot makes up to three.
    ASSERT_TRUE(l.contains("simplifier_runs")) << l.dump();
    const uint64_t runs = l["simplifier_runs"].get<uint64_t>(), regions = l["regions"].get<uint64_t>();
    EXPECT_GE(runs, regions) << l.dump();
    EXPECT_LE(runs, 3 * 17 * regions) << l.dump();
  }
  EXPECT_LE(ingest + levels, total + 1e-3) << "the parts exceed the whole: " << d.dump(1);
  EXPECT_LE(total, outside + 1e-3) << "the build reports more CPU than the kernel counted for it";
  // The run's CPU is mostly the ingest's and the levels': what lies between (the grid weld, the
  // sink, the file's index) is smaller than the two.
  EXPECT_GT(ingest + levels, 0.5 * total) << d.dump(1);
}

// mtverify: checksums, monotone errors, nested spheres, and random cuts welded by exact position
// with no boundary or non-manifold edge the finest level does not have.
struct VerifyCase {
  const char* name;
  const char* mtgen;  // empty: the non-manifold mesh written by the test
  const char* build;
};

TEST(Mtbuild, CutsAreCrackFreeOnClosedHoledMultiComponentAndNonManifoldMeshes) {
  std::vector<VerifyCase> cases = {
      {"closed", "--triangles 50k --seed 11", "--patch-triangles 400"},
      {"holes", "--triangles 50k --holes 25 --shuffle --seed 12", "--patch-triangles 400"},
      {"components", "--triangles 50k --components 4 --density varying --seed 13", "--patch-triangles 400"},
      {"non-manifold", "", "--patch-triangles 300"},
      {"draco, regular partition", "--triangles 30k --holes 5 --seed 14", "--codec draco --partition regular --patch-triangles 400"},
  };
  for (const VerifyCase& c : cases) {
    TempDir tmp;
    std::string in = *c.mtgen ? makeScan(tmp, "in.ply", c.mtgen) : writeNonManifoldPly(tmp);
    build(in, tmp.file("c.mt"), c.build);
    CommandResult v = runTool("mtverify", tmp.file("c.mt") + " --cuts 12");
    EXPECT_EQ(v.exitCode, 0) << c.name << "\n" << v.output;
  }
}

// A store healed out of core (holes filled across patch borders, smoothed) is a valid build input.
TEST(Mtbuild, AHealedStoreBuildsAndVerifies) {
  TempDir tmp;
  std::string in = makeScan(tmp, "h.ply", "--triangles 40k --holes 15 --seed 4");
  ASSERT_EQ(runTool("mtstore", "ingest " + in + " -o " + tmp.file("s") + " -q --patch-triangles 300").exitCode, 0);
  CommandResult heal = runTool("mtstore", "heal " + tmp.file("s") + " --fill-holes 100 --smooth 2");
  ASSERT_EQ(heal.exitCode, 0) << heal.output;
  EXPECT_NE(heal.output.find("filled 15"), std::string::npos) << heal.output;
  build(tmp.file("s"), tmp.file("h.mt"), "--patch-triangles 300");
  CommandResult v = runTool("mtverify", tmp.file("h.mt") + " --cuts 8");
  EXPECT_EQ(v.exitCode, 0) << v.output;
  EXPECT_NE(v.output.find("input has 0 boundary"), std::string::npos) << v.output;
}

// The root levels follow one another while each gains; a level that would gain nothing is not
// added. Here the model ends as a soup of isolated triangles no simplifier can collapse (a
// triangle's collapse would leave its apex with none) beside a grid that simplifies away: the
// level loop reaches a root of about the soup's size (levels 20,202 -> 10,094 -> 5,043, then root
// levels 2,521 -> 1,260 -> 629 triangles) that the next root level can only copy. Before the rule
// that copy was added as a level of its own, all of its input kept (with the one-step root of
// before: 5,042 -> 601, then 601 of 601; the 53 M armadillo scan's levels 12 and 13 were the same
// 12,936 triangles).
TEST(Mtbuild, ARootLevelThatGainsNothingIsNotAdded) {
  TempDir tmp;
  TestMesh mesh;
  const uint32_t n = 100;  // a wavy n x n grid: 2 (n - 1)^2 triangles
  for (uint32_t j = 0; j < n; ++j)
    for (uint32_t i = 0; i < n; ++i)
      mesh.positions.insert(mesh.positions.end(), {double(i), double(j), 0.3 * std::sin(0.4 * i) * std::cos(0.3 * j)});
  for (uint32_t j = 0; j + 1 < n; ++j)
    for (uint32_t i = 0; i + 1 < n; ++i) {
      const uint32_t a = j * n + i, b = a + 1, c = a + n, d = c + 1;
      mesh.triangles.insert(mesh.triangles.end(), {a, b, d, a, d, c});
    }
  for (uint32_t k = 0; k < 600; ++k) {  // isolated triangles 2 apart on a plane above the grid
    const double x = 2.0 * (k % 24), y = 2.0 * (k / 24), z = 5;
    const uint32_t v = mesh.vertexCount();
    mesh.positions.insert(mesh.positions.end(), {x, y, z, x + 0.8, y, z, x, y + 0.8, z + 0.2});
    mesh.triangles.insert(mesh.triangles.end(), {v, v + 1, v + 2});
  }
  const std::string in = tmp.file("soup.ply"), out = tmp.file("soup.mt");
  writePly(in, mesh);
  BuildOptions o;
  o.threads = 1;
  o.progress = false;
  o.patchTriangles = 300;
  o.rootTriangles = 200;
  o.simplifier = RegionSimplifier::Quadric;  // meshopt drops an isolated triangle whole
  o.progress = true;  // the progress lines name the levels past the partition's as root levels
  testing::internal::CaptureStderr();
  BuildReport r = buildMt(in, out, o);
  const std::string progress = testing::internal::GetCapturedStderr();
  ASSERT_GE(r.levels.size(), 2u);
  EXPECT_EQ(r.levels.back().regions, 1u) << "the last level is a root level";
  // "level N/M" counts the partition's M levels; a further root level is not "level 7/6".
  size_t counted = 0, furtherRoot = 0;
  for (size_t at = progress.find("level "); at != std::string::npos; at = progress.find("level ", at + 1)) {
    unsigned level = 0, of = 0;
    char after = 0;
    if (std::sscanf(progress.c_str() + at, "level %u/%u", &level, &of) == 2) {
      ++counted;
      EXPECT_LE(level, of) << progress;
    } else if (std::sscanf(progress.c_str() + at, "level %u (a further root level%c", &level, &after) == 2 && after == ')') {
      ++furtherRoot;
    }
  }
  EXPECT_GE(counted, 1u) << progress;
  EXPECT_GE(furtherRoot, 1u) << "this build tries a root level past the partition's (and drops it)\n" << progress;
  for (size_t i = 1; i < r.levels.size(); ++i)
    EXPECT_LE(r.levels[i].trianglesOut * 10, r.levels[i].trianglesIn * 9)
        << "level " << r.levels[i].level << " keeps " << r.levels[i].trianglesOut << " of " << r.levels[i].trianglesIn
        << " triangles";
  auto mt = MtFileReader::open(out);
  EXPECT_EQ(mt->header().levelCount, r.levels.size() + 1) << "the file's levels are the report's and the sink";
  CommandResult v = runTool("mtverify", out + " --cuts 8");
  EXPECT_EQ(v.exitCode, 0) << v.output;
}

// The coarse end of the DAG: past the partition's last level the whole model is one region, and
// the root levels keep 1/k of it each while that stays over rootTriangles, then go to
// rootTriangles / 2. So no level is more than 2k times smaller than the one below, and a budget
// between the partition's last level and the root gets a cut of about its size (before, the root
// went there in one step: on arm3.3M 51,820 triangles, then 1,998, and every budget from 2 k to
// 51 k drew the 1,998).
TEST(Mtbuild, TheRootIsReachedInStepsOfTheLevelRatio) {
  TempDir tmp;
  const std::string in = makeScan(tmp, "r.ply", "--triangles 120k --holes 6 --seed 23");
  for (uint32_t k : {2u, 4u}) {
    BuildOptions o;
    o.threads = 2;
    o.progress = false;
    o.patchTriangles = 300;  // rootTriangles: 600
    o.levelRatio = k;
    const std::string out = tmp.file("r" + std::to_string(k) + ".mt");
    const BuildReport r = buildMt(in, out, o);
    ASSERT_GE(r.levels.size(), 3u);
    EXPECT_LE(r.levels.back().trianglesOut, 600u) << "k " << k;
    size_t roots = 0;
    for (const LevelReport& l : r.levels) {
      // At most 2k: the last root step goes from at most k x rootTriangles to rootTriangles / 2
      // (10% for a simplifier that stops a little under its target).
      EXPECT_GE(l.trianglesOut * 2 * k * 11 / 10, l.trianglesIn)
          << "k " << k << ": level " << l.level << " keeps " << l.trianglesOut << " of " << l.trianglesIn << " triangles";
      roots += l.regions == 1;
    }
    EXPECT_GE(roots, 2u) << "k " << k << ": the partition's last level reaches the root in more than one step";
    // A budget of each whole-model level's size draws that level, not the root below it.
    for (const LevelReport& l : r.levels) {
      if (l.regions != 1 || l.trianglesOut <= 600) continue;
      CommandResult e = runTool("mtextract", out + " --triangles " + std::to_string(l.trianglesOut) + " -o " + tmp.file("c.ply"));
      ASSERT_EQ(e.exitCode, 0) << e.output;
      const size_t at = e.output.find(" triangles,");
      ASSERT_NE(at, std::string::npos) << e.output;
      const uint64_t drawn = std::stoull(e.output.substr(e.output.rfind(' ', at - 1) + 1));
      EXPECT_EQ(drawn, l.trianglesOut) << "k " << k << ": a budget of " << l.trianglesOut << "\n" << e.output;
    }
    // Each whole-model node is stored in patches by the coarsest partition cells (2 to 8 here),
    // not as one patch that a renderer must draw whole whatever its budget.
    CommandResult info = runTool("mtinfo", out);
    ASSERT_EQ(info.exitCode, 0) << info.output;
    for (size_t i = 0; i < r.levels.size(); ++i) {
      if (r.levels[i].regions != 1) continue;
      const std::string row = "\n" + std::string(i + 1 < 10 ? "    " : "   ") + std::to_string(i + 1) + " ";
      const size_t at = info.output.find(row);
      ASSERT_NE(at, std::string::npos) << "k " << k << ": no row for level " << i + 1 << "\n" << info.output;
      unsigned level = 0, nodes = 0, patches = 0;
      ASSERT_EQ(std::sscanf(info.output.c_str() + at, "%u %u %u", &level, &nodes, &patches), 3) << info.output;
      EXPECT_EQ(nodes, 1u) << "k " << k << ": level " << level;
      EXPECT_GE(patches, 2u) << "k " << k << ": level " << level << "\n" << info.output;
      EXPECT_LE(patches, 8u) << "k " << k << ": level " << level << "\n" << info.output;
    }
    CommandResult v = runTool("mtverify", out + " --cuts 8");
    EXPECT_EQ(v.exitCode, 0) << v.output;
  }
}

TEST(Mtbuild, TinyInputsBuildFilesThatVerify) {
  // One triangle, three collinear vertices, two triangles, a tetrahedron, an open pyramid: each
  // region must keep a triangle, or its node has no arc to the sink and mtverify rejects the file.
  TempDir tmp;
  const std::vector<std::pair<std::string, std::string>> meshes = {
      {"one", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"},
      {"collinear", "OFF\n3 1 0\n0 0 0\n1 0 0\n2 0 0\n3 0 1 2\n"},
      {"two", "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 1 3 2\n"},
      // Closed (a tetrahedron) and open (a square pyramid without its base): the simplifier
      // collapses each to nothing; the region must be kept instead.
      {"tetrahedron", "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 1 2 3\n3 2 0 3\n"},
      {"pyramid", "OFF\n5 4 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n0.5 0.5 1\n3 0 1 4\n3 1 2 4\n3 2 3 4\n3 3 0 4\n"}};
  for (const auto& [name, text] : meshes) {
    writeFile(tmp.file(name + ".off"), text);
    auto b = runTool("mtbuild", tmp.file(name + ".off") + " -o " + tmp.file(name + ".mt") + " -q");
    ASSERT_EQ(b.exitCode, 0) << name << ": " << b.output;
    auto v = runTool("mtverify", tmp.file(name + ".mt"));
    EXPECT_EQ(v.exitCode, 0) << name << ": " << v.output;
    auto x = runTool("mtextract", tmp.file(name + ".mt") + " --error 0 -o " + tmp.file(name + ".ply"));
    EXPECT_EQ(x.exitCode, 0) << name << ": " << x.output;
  }
}

TEST(Mtbuild, BadInputIsAClearErrorAndLeavesNoFile) {
  TempDir tmp;
  writeFile(tmp.file("bad.ply"), "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                                 "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                                 "0 0 0\n1 0 0\n0 1 0\n3 0 1 9\n");
  CommandResult r = runTool("mtbuild", tmp.file("bad.ply") + " -o " + tmp.file("bad.mt") + " -q");
  EXPECT_EQ(r.exitCode, 1);
  EXPECT_NE(r.output.find(tmp.file("bad.ply")), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(tmp.file("bad.mt")));
  for (auto& e : fs::directory_iterator(tmp.path()))
    EXPECT_EQ(e.path().filename().string().find("bad.mt."), std::string::npos) << "left behind: " << e.path();
  EXPECT_NE(runTool("mtbuild", "x.ply -o y.mt --codec zip").exitCode, 0);
}


// --resume: a build killed with SIGKILL after a level's checkpoint, or in the
// middle of a level, continues from its last finished level and writes the same bytes as a build
// that was never interrupted. The kill points are test hooks in LevelBuilder (env variables).
int levelRegions(const std::string& statsJson, int level) {
  // The "regions" member of level `level` (1-based) in --stats-json output.
  size_t at = statsJson.find("{\"level\": " + std::to_string(level) + ",");
  if (at == std::string::npos) return -1;
  at = statsJson.find("\"regions\": ", at);
  return std::atoi(statsJson.c_str() + at + 11);
}

// runTool goes through `sh -c`, which reports a child killed by SIGKILL as exit status 137.
bool killed(const CommandResult& r) { return r.exitCode == -1 || r.exitCode == 128 + 9; }

CommandResult buildKilled(const std::string& in, const std::string& out, const std::string& options, const char* hook,
                          int value) {
  setenv(hook, std::to_string(value).c_str(), 1);
  CommandResult r = runTool("mtbuild", in + " -o " + out + " -q " + options);
  unsetenv(hook);
  return r;
}

TEST(MtbuildResume, KilledBuildsResumeToTheSameBytes) {
  TempDir tmp;
  std::string in = makeScan(tmp, "scan.ply", "--triangles 40k --holes 10 --seed 21");
  const std::string opts = "--patch-triangles 300 --threads 2";
  build(in, tmp.file("clean.mt"), opts + " --stats-json " + tmp.file("clean.json"));
  const std::string clean = readFile(tmp.file("clean.mt"));
  const std::string stats = readFile(tmp.file("clean.json"));
  const int level1 = levelRegions(stats, 1), level2 = levelRegions(stats, 2);
  ASSERT_GT(level1, 4) << stats;
  ASSERT_GT(level2, 2) << stats;

  struct Kill {
    const char* hook;
    int value;
    const char* what;
  } kills[] = {
      {"MT_TEST_KILL_AFTER_LEVEL", 2, "after level 2's checkpoint"},
      {"MT_TEST_KILL_AFTER_REGIONS", level1 + level2 / 2, "in the middle of level 2"},
      {"MT_TEST_KILL_AFTER_REGIONS", 3, "in the middle of level 1"},
  };
  for (const Kill& k : kills) {
    std::string out = tmp.file("k.mt");
    CommandResult stopped = buildKilled(in, out, opts, k.hook, k.value);
    ASSERT_TRUE(killed(stopped)) << k.what << ": the hook did not kill the build\n" << stopped.output;
    ASSERT_FALSE(fs::exists(out)) << k.what;
    ASSERT_TRUE(fs::exists(out + ".work")) << k.what;
    // --threads differs on purpose: it does not change the bytes, so a resume may change it.
    CommandResult resumed = runTool("mtbuild", in + " -o " + out + " --resume --patch-triangles 300 --threads 1");
    ASSERT_EQ(resumed.exitCode, 0) << k.what << "\n" << resumed.output;
    EXPECT_NE(resumed.output.find("continuing after level"), std::string::npos) << resumed.output;
    EXPECT_TRUE(readFile(out) == clean) << k.what << ": resumed build differs from the uninterrupted one";
    EXPECT_FALSE(fs::exists(out + ".work"));
    EXPECT_FALSE(fs::exists(out + ".lock"));
    for (auto& e : fs::directory_iterator(tmp.path()))
      EXPECT_EQ(e.path().filename().string().find("k.mt.tmp"), std::string::npos) << "temporary file left: " << e.path();
    fs::remove(out);
  }
}

TEST(MtbuildResume, ResumingWithOtherOptionsOrInputIsRefusedClearly) {
  TempDir tmp;
  std::string in = makeScan(tmp, "scan.ply", "--triangles 20k --seed 22");
  build(in, tmp.file("clean.mt"), "--patch-triangles 300");
  std::string out = tmp.file("k.mt");
  ASSERT_TRUE(killed(buildKilled(in, out, "--patch-triangles 300", "MT_TEST_KILL_AFTER_LEVEL", 1)));
  CommandResult r = runTool("mtbuild", in + " -o " + out + " -q --resume --patch-triangles 300 --codec draco");
  EXPECT_EQ(r.exitCode, 1) << r.output;
  EXPECT_NE(r.output.find("cannot --resume"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("codec was meshopt"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(out));
  // The refused resume kept the checkpoint: the right options still finish it.
  r = runTool("mtbuild", in + " -o " + out + " -q --resume --patch-triangles 300");
  ASSERT_EQ(r.exitCode, 0) << r.output;
  EXPECT_TRUE(readFile(out) == readFile(tmp.file("clean.mt")));
  // Another input under the same name is refused too.
  fs::remove(out);
  ASSERT_TRUE(killed(buildKilled(in, out, "--patch-triangles 300", "MT_TEST_KILL_AFTER_LEVEL", 1)));
  makeScan(tmp, "scan.ply", "--triangles 20k --seed 23");
  r = runTool("mtbuild", in + " -o " + out + " -q --resume --patch-triangles 300");
  EXPECT_EQ(r.exitCode, 1) << r.output;
  EXPECT_NE(r.output.find("input_"), std::string::npos) << r.output;
}

TEST(MtbuildResume, AKilledIngestStartsOverAndAPlainRunDiscardsOldWork) {
  TempDir tmp;
  std::string in = makeScan(tmp, "scan.ply", "--triangles 20k --holes 4 --seed 24");
  build(in, tmp.file("clean.mt"), "--patch-triangles 300");
  std::string out = tmp.file("k.mt");
  // What a kill during ingest leaves: a work directory (marked as a build's) without a finished store.
  fs::create_directories(out + ".work/store.tmp-ingest");
  writeFile(out + ".work/.mtbuild-work", "");
  writeFile(out + ".work/store.tmp-ingest/garbage", "half an ingest");
  CommandResult r = runTool("mtbuild", in + " -o " + out + " --resume --patch-triangles 300");
  ASSERT_EQ(r.exitCode, 0) << r.output;
  EXPECT_NE(r.output.find("starting from the input"), std::string::npos) << r.output;
  EXPECT_TRUE(readFile(out) == readFile(tmp.file("clean.mt")));
  // Without --resume, a killed build's work is thrown away (and the run says so).
  fs::remove(out);
  ASSERT_TRUE(killed(buildKilled(in, out, "--patch-triangles 300", "MT_TEST_KILL_AFTER_LEVEL", 1)));
  r = runTool("mtbuild", in + " -o " + out + " --patch-triangles 300");
  ASSERT_EQ(r.exitCode, 0) << r.output;
  EXPECT_NE(r.output.find("starting over"), std::string::npos) << r.output;
  EXPECT_TRUE(readFile(out) == readFile(tmp.file("clean.mt")));
}

// --level-ratio 4: each level keeps about a quarter of the one below (the partition's levels aim
// at a quarter of the cells, each region is simplified to a quarter), so the file stores ~4/3 of
// the input's triangles instead of ~2x; the cuts stay crack-free, the errors monotone, the bytes
// the same whatever the threads and the cap, a killed build resumes to them, and a resume or a
// store input with another ratio is refused.
double jsonLevelShare(const nlohmann::json& level) {
  return double(level["triangles_out"].get<uint64_t>()) / double(level["triangles_in"].get<uint64_t>());
}

TEST(MtbuildLevelRatio, EachLevelKeepsAQuarterAndCutsStayCrackFree) {
  TempDir tmp;
  std::string in = makeScan(tmp, "scan.ply", "--triangles 80k --holes 12 --components 2 --seed 31");
  build(in, tmp.file("two.mt"), "--patch-triangles 300 --stats-json " + tmp.file("two.json"));
  build(in, tmp.file("four.mt"), "--patch-triangles 300 --level-ratio 4 --threads 1 --stats-json " + tmp.file("four.json"));
  auto two = nlohmann::json::parse(readFile(tmp.file("two.json")));
  auto four = nlohmann::json::parse(readFile(tmp.file("four.json")));
  EXPECT_EQ(two["level_ratio"], 2);
  EXPECT_EQ(four["level_ratio"], 4);
  const auto& levels = four["levels"];
  ASSERT_GE(levels.size(), 3u) << four.dump();
  EXPECT_LT(levels.size(), two["levels"].size());
  // Every level but the root's keeps about a quarter (the default: about half).
  for (size_t l = 0; l + 1 < levels.size(); ++l) {
    EXPECT_NEAR(jsonLevelShare(levels[l]), 0.25, 0.06) << "level " << l + 1;
    EXPECT_NEAR(jsonLevelShare(two["levels"][l]), 0.5, 0.06) << "level " << l + 1 << " at ratio 2";
  }
  const double input = four["input_triangles"].get<double>();
  EXPECT_LT(four["stored_triangles"].get<double>(), 1.45 * input);
  EXPECT_GT(two["stored_triangles"].get<double>(), 1.8 * input);
  EXPECT_LT(four["file_bytes"].get<double>(), 0.8 * two["file_bytes"].get<double>());

  auto mt = MtFileReader::open(tmp.file("four.mt"));
  std::vector<int> onArc(mt->patches().size(), 0);
  for (const auto& arc : mt->arcs()) {
    EXPECT_GE(mt->nodes()[arc.to].error, mt->nodes()[arc.from].error) << "error must not shrink towards the sink";
    for (uint32_t i = 0; i < arc.patchCount; ++i) ++onArc[mt->patchRefs()[arc.firstPatchRef + i]];
  }
  for (size_t p = 0; p < onArc.size(); ++p) EXPECT_EQ(onArc[p], 1) << "patch " << p;
  CommandResult v = runTool("mtverify", tmp.file("four.mt") + " --cuts 12");
  EXPECT_EQ(v.exitCode, 0) << v.output;

  // The same bytes at 2 threads and a small cap; ratio 3 builds and verifies too.
  build(in, tmp.file("four2.mt"), "--patch-triangles 300 --level-ratio 4 --threads 2 --memory 24M");
  EXPECT_TRUE(readFile(tmp.file("four.mt")) == readFile(tmp.file("four2.mt"))) << "--threads 1 and 2 (24M) differ";
  build(in, tmp.file("three.mt"), "--patch-triangles 300 --level-ratio 3");
  v = runTool("mtverify", tmp.file("three.mt") + " --cuts 6");
  EXPECT_EQ(v.exitCode, 0) << v.output;
  // --level-ratio 2 is the default, byte for byte.
  build(in, tmp.file("two2.mt"), "--patch-triangles 300 --level-ratio 2");
  EXPECT_TRUE(readFile(tmp.file("two.mt")) == readFile(tmp.file("two2.mt")));
}

TEST(MtbuildLevelRatio, ResumesAndStoresKeepTheirRatioAndBadValuesAreRefused) {
  TempDir tmp;
  std::string in = makeScan(tmp, "scan.ply", "--triangles 40k --holes 6 --seed 32");
  const std::string opts = "--patch-triangles 200 --level-ratio 4";
  build(in, tmp.file("clean.mt"), opts);
  std::string out = tmp.file("k.mt");
  ASSERT_TRUE(killed(buildKilled(in, out, opts, "MT_TEST_KILL_AFTER_LEVEL", 1)));
  // Another ratio: refused, naming it; the checkpoint stays, and the same ratio finishes it.
  CommandResult r = runTool("mtbuild", in + " -o " + out + " -q --resume --patch-triangles 200");
  EXPECT_EQ(r.exitCode, 1) << r.output;
  EXPECT_NE(r.output.find("level_ratio was 4 for the killed build, is 2 now"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(out));
  r = runTool("mtbuild", in + " -o " + out + " -q --resume " + opts);
  ASSERT_EQ(r.exitCode, 0) << r.output;
  EXPECT_TRUE(readFile(out) == readFile(tmp.file("clean.mt"))) << "resumed build differs from the uninterrupted one";

  // A store made with a ratio keeps it: built as such, and another ratio is refused by name.
  ASSERT_EQ(runTool("mtstore", "ingest " + in + " -o " + tmp.file("s") + " -q " + opts).exitCode, 0);
  build(tmp.file("s"), tmp.file("store.mt"), "--stats-json " + tmp.file("store.json"));
  EXPECT_EQ(nlohmann::json::parse(readFile(tmp.file("store.json")))["level_ratio"], 4);
  EXPECT_EQ(runTool("mtverify", tmp.file("store.mt") + " --cuts 4").exitCode, 0);
  r = runTool("mtbuild", tmp.file("s") + " -o " + tmp.file("other.mt") + " -q --level-ratio 2");
  EXPECT_EQ(r.exitCode, 1) << r.output;
  EXPECT_NE(r.output.find("V-partition has level ratio 4; omit --level-ratio"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(tmp.file("other.mt")));
  EXPECT_FALSE(fs::exists(tmp.file("other.mt.work"))) << "refused before the store was copied";
  // A default store, asked for another ratio: refused the same way.
  ASSERT_EQ(runTool("mtstore", "ingest " + in + " -o " + tmp.file("s2") + " -q --patch-triangles 200").exitCode, 0);
  r = runTool("mtbuild", tmp.file("s2") + " -o " + tmp.file("other.mt") + " -q --level-ratio 4");
  EXPECT_EQ(r.exitCode, 1) << r.output;
  EXPECT_NE(r.output.find("V-partition has level ratio 2"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(tmp.file("other.mt.work")));
  // The library checks what the tools check.
  BuildOptions o;
  o.levelRatio = 9;
  EXPECT_THROW(buildMt(in, tmp.file("lib.mt"), o), Error);
  o.levelRatio = 4;
  o.partition = PartitionKind::Regular;
  EXPECT_THROW(buildMt(in, tmp.file("lib.mt"), o), Error);
  EXPECT_FALSE(fs::exists(tmp.file("lib.mt.work")));

  // Out of range, not a number, or with a partition that has its own ratios: refused before
  // anything is written.
  for (const char* bad : {"--level-ratio 1", "--level-ratio 9", "--level-ratio 0", "--level-ratio x",
                          "--level-ratio 4 --partition regular"}) {
    r = runTool("mtbuild", in + " -o " + tmp.file("bad.mt") + " -q " + bad);
    EXPECT_NE(r.exitCode, 0) << bad << "\n" << r.output;  // 1, or CLI11's own code for "x"
    EXPECT_NE(r.output.find("level-ratio"), std::string::npos) << bad << "\n" << r.output;
    EXPECT_FALSE(fs::exists(tmp.file("bad.mt"))) << bad;
    EXPECT_FALSE(fs::exists(tmp.file("bad.mt.work"))) << bad;
  }
  for (const char* bad : {"--level-ratio 9", "--level-ratio 4 --partition grid", "--level-ratio 4 --partition regular2d"}) {
    r = runTool("mtstore", "ingest " + in + " -o " + tmp.file("bad") + " -q " + std::string(bad));
    EXPECT_NE(r.exitCode, 0) << bad << "\n" << r.output;
    EXPECT_NE(r.output.find("level-ratio"), std::string::npos) << bad << "\n" << r.output;
    EXPECT_FALSE(fs::exists(tmp.file("bad"))) << bad;
  }
}

}  // namespace
}  // namespace mt::test
