// mtcluster under mpirun on this machine (oversubscribed ranks): the same bytes as
// mtbuild, the work spread over the ranks, and a rank killed mid-build stops the job with an
// error naming the rank and the level, after which --resume finishes with the same bytes.
#include <gtest/gtest.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <regex>

#include "base/error.h"
#include "cluster/region_messages.h"
#include "mtbuild/build.h"
#include "tests/test_support.h"

namespace mt::test {
namespace {

namespace fs = std::filesystem;

bool haveMpirun() { return std::system("command -v mpirun > /dev/null 2>&1") == 0; }

// mpirun as CI runs it: as root, more ranks than cores. `env`: a variable to pass to the ranks.
// Each mpirun has a session directory of its own (TMPDIR): ctest runs these tests in parallel, and
// Open MPI's shared one (/tmp/ompi.HOST.UID) was removed by an mpirun ending while another created
// its own in it ("orte_session_dir failed", seen once in CI).
CommandResult mpirun(int ranks, const std::string& args, const std::string& env = "") {
  const TempDir session;
  return mt::test::runShell("TMPDIR=" + session.path() + " mpirun --allow-run-as-root --oversubscribe -np " +
                            std::to_string(ranks) + (env.empty() ? "" : " -x " + env) + " " + binDir() +
                            "/mtcluster " + args);
}

std::string scanAndReference(const TempDir& tmp, const std::string& mtgen, const std::string& build) {
  std::string in = tmp.file("scan.ply");
  CommandResult g = runTool("mtgen", "-o " + in + " " + mtgen);
  EXPECT_EQ(g.exitCode, 0) << g.output;
  CommandResult b = runTool("mtbuild", in + " -o " + tmp.file("ref.mt") + " -q " + build + " --stats-json " + tmp.file("ref.json"));
  EXPECT_EQ(b.exitCode, 0) << b.output;
  return in;
}

uint64_t sumOf(const std::string& json, const std::string& member) {
  uint64_t sum = 0;
  std::regex re("\"" + member + "\": ([0-9]+)");
  for (auto it = std::sregex_iterator(json.begin(), json.end(), re); it != std::sregex_iterator(); ++it)
    sum += std::stoull((*it)[1]);
  return sum;
}

TEST(Mtcluster, ThreeRanksWriteTheSameBytesAsMtbuild) {
  if (!haveMpirun()) GTEST_SKIP() << "mpirun not installed";
  TempDir tmp;
  const std::string opts = "--patch-triangles 300";
  std::string in = scanAndReference(tmp, "--triangles 30k --holes 6 --seed 31", opts);
  CommandResult r = mpirun(3, in + " -o " + tmp.file("c.mt") + " -q " + opts + " --stats-json " + tmp.file("c.json"));
  ASSERT_EQ(r.exitCode, 0) << r.output;
  std::string ref = readFile(tmp.file("ref.mt"));
  ASSERT_GT(ref.size(), 1000u);
  EXPECT_TRUE(readFile(tmp.file("c.mt")) == ref) << "mtcluster -np 3 and mtbuild differ";
  // Every region was processed exactly once, by some rank, and the ranks say what they did.
  std::string json = readFile(tmp.file("c.json"));
  EXPECT_NE(json.find("\"ranks\": 3"), std::string::npos) << json;
  EXPECT_NE(json.find("\"parallel_efficiency\""), std::string::npos) << json;
  EXPECT_EQ(sumOf(json, "tasks"), sumOf(readFile(tmp.file("ref.json")), "regions")) << json;
  EXPECT_GT(sumOf(json, "bytes_sent"), 0u);
  EXPECT_FALSE(fs::exists(tmp.file("c.mt.work")));
  // Another level ratio travels with the partition to the ranks (each region kept at a quarter).
  CommandResult b = runTool("mtbuild", in + " -o " + tmp.file("ref4.mt") + " -q " + opts + " --level-ratio 4");
  ASSERT_EQ(b.exitCode, 0) << b.output;
  r = mpirun(3, in + " -o " + tmp.file("c4.mt") + " -q " + opts + " --level-ratio 4");
  ASSERT_EQ(r.exitCode, 0) << r.output;
  EXPECT_TRUE(readFile(tmp.file("c4.mt")) == readFile(tmp.file("ref4.mt"))) << "--level-ratio 4: mtcluster -np 3 and mtbuild differ";
  EXPECT_FALSE(readFile(tmp.file("c4.mt")) == ref);
}

TEST(Mtcluster, ADeadRankStopsTheJobNamingRankAndLevelAndResumeFinishes) {
  if (!haveMpirun()) GTEST_SKIP() << "mpirun not installed";
  TempDir tmp;
  const std::string opts = "--patch-triangles 300";
  std::string in = scanAndReference(tmp, "--triangles 40k --holes 4 --seed 32", opts);
  // Rank 2 SIGKILLs itself when its first region of level 2 arrives (levels 1-4 have 21, 11, 5 and
  // 1 regions; every idle worker is handed one as a level starts, so this is level 2 whatever the
  // ranks' speeds).
  setenv("MT_TEST_KILL_RANK", "2:2", 1);
  CommandResult r = mpirun(3, in + " -o " + tmp.file("c.mt") + " -q " + opts, "MT_TEST_KILL_RANK");
  unsetenv("MT_TEST_KILL_RANK");
  EXPECT_NE(r.exitCode, 0) << r.output;
  EXPECT_TRUE(std::regex_search(r.output, std::regex("rank 2[^0-9]"))) << r.output;
  EXPECT_NE(r.output.find("during level 2 "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("--resume"), std::string::npos) << r.output;
  EXPECT_FALSE(fs::exists(tmp.file("c.mt")));
  // Resume with another number of ranks: same checkpoint format, same bytes.
  r = mpirun(2, in + " -o " + tmp.file("c.mt") + " --resume " + opts);
  ASSERT_EQ(r.exitCode, 0) << r.output;
  EXPECT_NE(r.output.find("continuing after level 1 "), std::string::npos) << r.output;
  EXPECT_TRUE(readFile(tmp.file("c.mt")) == readFile(tmp.file("ref.mt"))) << "resumed mtcluster differs from mtbuild";
}

TEST(Mtcluster, BadInputIsAOneLineErrorWithoutAbortingTheRanks) {
  if (!haveMpirun()) GTEST_SKIP() << "mpirun not installed";
  TempDir tmp;
  writeFile(tmp.file("bad.ply"), "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                                 "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                                 "0 0 0\n1 0 0\n0 1 0\n3 0 1 9\n");
  CommandResult r = mpirun(3, tmp.file("bad.ply") + " -o " + tmp.file("bad.mt") + " -q");
  EXPECT_NE(r.exitCode, 0) << r.output;
  EXPECT_NE(r.output.find("mtcluster: " + tmp.file("bad.ply")), std::string::npos) << r.output;
  EXPECT_EQ(r.output.find("MPI_ABORT"), std::string::npos) << "workers should be stopped, not aborted\n" << r.output;
  EXPECT_FALSE(fs::exists(tmp.file("bad.mt")));
  EXPECT_FALSE(fs::exists(tmp.file("bad.mt.work")));
}

// The messages themselves (no MPI): a real region's task and result survive encode/decode bit for
// bit, a worker with a decoded context computes the same result, and damaged bytes are an error.
TEST(ClusterMessages, RoundTripExactlyAndRejectDamage) {
  TempDir tmp;
  std::string in = tmp.file("scan.ply");
  ASSERT_EQ(runTool("mtgen", "-o " + in + " --triangles 20k --holes 3 --seed 33").exitCode, 0);
  BuildOptions o;
  o.progress = false;
  o.patchTriangles = 300;
  LevelBuilder builder(in, tmp.file("m.mt"), o);
  ASSERT_TRUE(builder.beginLevel());
  ASSERT_GT(builder.regionCount(), 2u);
  RegionTask task = builder.loadRegion(1);
  ASSERT_GT(task.mesh.triangleCount(), 0u);

  std::string taskBytes = cluster::encodeTask(7, task);
  uint64_t index = 0;
  RegionTask copy = cluster::decodeTask(taskBytes, index);
  EXPECT_EQ(index, 7u);
  EXPECT_EQ(copy.level, task.level);
  EXPECT_EQ(copy.region, task.region);
  EXPECT_TRUE(copy.mesh.positions == task.mesh.positions);
  EXPECT_TRUE(copy.mesh.triangles == task.mesh.triangles);
  EXPECT_TRUE(copy.mesh.locked == task.mesh.locked);
  EXPECT_TRUE(copy.mesh.unifiedOf == task.mesh.unifiedOf);

  cluster::WorkerContext worker;
  cluster::decodeContext(cluster::encodeContext(builder.context(), builder.sequenceBytes()), worker);
  RegionResult here = processRegion(task, builder.context());
  RegionResult there = processRegion(copy, worker.context);
  here.seconds = there.seconds = 0;  // the only field allowed to differ
  std::string a = cluster::encodeResult(3, here), b = cluster::encodeResult(3, there);
  EXPECT_TRUE(a == b) << "a worker's result differs from the local one";
  ASSERT_EQ(here.encoded.size(), task.mesh.patches.size());
  RegionResult back = cluster::decodeResult(a, index);
  EXPECT_EQ(index, 3u);
  EXPECT_TRUE(cluster::encodeResult(3, back) == a);

  std::string damaged = taskBytes;
  damaged[damaged.size() / 2] ^= 0x40;
  EXPECT_THROW(cluster::decodeTask(damaged, index), mt::Error);
  EXPECT_THROW(cluster::decodeTask(taskBytes.substr(0, taskBytes.size() - 9), index), mt::Error);
  EXPECT_THROW(cluster::decodeResult(taskBytes, index), mt::Error);  // a task is not a result
}

}  // namespace
}  // namespace mt::test
