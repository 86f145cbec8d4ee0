// The patch store never loses a user's data: one writer at a time (STORE/LOCK), readers see the
// last committed version while a heal runs, heal compacts and refuses nonsense, a killed or
// interrupted ingest leaves nothing behind, and mtstore's inputs and outputs are checked.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <functional>
#include <map>
#include <thread>

#include "patchstore/heal/heal.h"
#include "patchstore/patch_store.h"
#include "test_support.h"

namespace fs = std::filesystem;
using namespace mt;
using test::CommandResult;
using test::runShell;
using test::runTool;
using test::TempDir;

namespace {

// A tool started in the background (its output into a file), to be signalled or raced.
struct Background {
  pid_t pid = -1;
  std::string log;
  Background(const std::string& tool, const std::string& args, const std::string& logPath) : log(logPath) {
    std::string cmd = "exec " + test::binDir() + "/" + tool + " " + args + " >" + logPath + " 2>&1";
    pid = fork();
    if (pid == 0) {
      execl("/bin/sh", "sh", "-c", cmd.c_str(), static_cast<char*>(nullptr));
      _exit(127);
    }
  }
  ~Background() {
    if (pid > 0) {  // a test that failed before waiting: do not leave the tool running
      kill(pid, SIGKILL);
      waitpid(pid, nullptr, 0);
    }
  }
  Background(const Background&) = delete;
  Background& operator=(const Background&) = delete;
  // Exit code, or 1000 + signal when killed by one.
  int wait() {
    int status = 0;
    waitpid(pid, &status, 0);
    pid = -pid;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 1000 + WTERMSIG(status);
  }
  std::string output() const { return test::readFile(log); }
};

bool waitFor(const std::function<bool()>& cond, double seconds) {
  auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
  while (std::chrono::steady_clock::now() < end) {
    if (cond()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return cond();
}

// name -> bytes of every file in a store (LOCK aside).
std::map<std::string, std::string> storeFiles(const std::string& dir) {
  std::map<std::string, std::string> files;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().filename() != "LOCK" && e.is_regular_file()) files[e.path().filename().string()] = test::readFile(e.path().string());
  return files;
}

uint64_t storeBytes(const std::string& dir) {
  uint64_t n = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) n += e.file_size();
  return n;
}

std::string makeStore(const TempDir& tmp, const std::string& triangles, const std::string& name = "s") {
  CommandResult gen = runTool("mtgen", "-o " + tmp.file(name + ".ply") + " --triangles " + triangles + " --seed 5");
  EXPECT_EQ(gen.exitCode, 0) << gen.output;
  CommandResult in = runTool("mtstore", "ingest " + tmp.file(name + ".ply") + " -o " + tmp.file(name) + " -q");
  EXPECT_EQ(in.exitCode, 0) << in.output;
  return tmp.file(name);
}

}  // namespace

TEST(StoreSafety, TwoHealsAtOnceGiveOneGoodResultAndOneRefusal) {
  TempDir tmp;
  std::string store = makeStore(tmp, "200k");
  Background first("mtstore", "heal " + store + " --smooth 40 -q", tmp.file("first.log"));
  ASSERT_TRUE(waitFor([&] { return test::fileExists(store + "/LOCK"); }, 30)) << "the first heal never took the lock";
  auto before = storeFiles(store);
  CommandResult second = runTool("mtstore", "heal " + store + " --weld 0");
  EXPECT_EQ(second.exitCode, 1) << second.output;
  EXPECT_NE(second.output.find("in use by process " + std::to_string(first.pid)), std::string::npos) << second.output;
  EXPECT_EQ(storeFiles(store).size() >= 1, true);
  // While the first heal writes, a reader sees a whole committed version.
  CommandResult check = runTool("mtstore", "check " + store);
  EXPECT_EQ(check.exitCode, 0) << check.output;
  EXPECT_EQ(first.wait(), 0) << first.output();
  CommandResult after = runTool("mtstore", "check " + store);
  EXPECT_EQ(after.exitCode, 0) << after.output;
  EXPECT_NE(after.output.find(": OK"), std::string::npos) << after.output;
  EXPECT_FALSE(test::fileExists(store + "/LOCK"));
  (void)before;
}

TEST(StoreSafety, SecondWriterThroughTheApiIsRefusedAndAReaderKeepsItsVersion) {
  TempDir tmp;
  std::string store = makeStore(tmp, "20k");
  auto reader = PatchStore::open(store);  // opened before the writer: keeps this version
  CheckReport clean = reader->check();
  ASSERT_TRUE(clean.ok);
  auto original = reader->patch(reader->patchIds()[0]);
  {
    auto writer = PatchStore::open(store);
    writer->lockForWriting();
    CommandResult other = runTool("mtstore", "heal " + store + " --smooth 1");
    EXPECT_EQ(other.exitCode, 1) << other.output;
    EXPECT_NE(other.output.find("in use by process " + std::to_string(getpid())), std::string::npos) << other.output;
    // Many commits: compaction deletes the segments the reader's version lives in.
    heal::HealOptions o;
    heal::smooth(*writer, 12, o);
  }
  CheckReport still = reader->check();
  EXPECT_TRUE(still.ok) << (still.problems.empty() ? "" : still.problems[0]);
  Patch again = reader->patch(original.id);
  EXPECT_EQ(again.positions, original.positions);  // the old version, not the smoothed one
  // A store opened before another writer committed may not write on top of it.
  EXPECT_THROW(reader->lockForWriting(), Error);
  EXPECT_TRUE(PatchStore::open(store)->check().ok);
}

TEST(StoreSafety, SmoothReclaimsOldBlocksAndPrintsOneLinePerIteration) {
  TempDir tmp;
  std::string store = makeStore(tmp, "200k");
  const uint64_t start = storeBytes(store);
  CommandResult r = runTool("mtstore", "heal " + store + " --smooth 10");
  ASSERT_EQ(r.exitCode, 0) << r.output;
  const uint64_t end = storeBytes(store);
  EXPECT_LT(end, 3 * start) << "store grew from " << start << " to " << end << " bytes";
  for (int i = 1; i <= 10; ++i)
    EXPECT_NE(r.output.find("heal: smooth " + std::to_string(i) + "/10:"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("M vertices/s"), std::string::npos) << r.output;
  EXPECT_EQ(runTool("mtstore", "check " + store).exitCode, 0);
}

TEST(StoreSafety, HealRefusesNonsenseAndLeavesTheStoreUntouched) {
  TempDir tmp;
  std::string store = makeStore(tmp, "20k");
  auto before = storeFiles(store);
  struct Case {
    std::string args, expect;
  };
  std::vector<Case> cases = {
      {"--weld 1", "above 1% of the bounding-box diagonal"},
      {"--remove-small-components 10000000", "would remove every component (1 components, 20002 triangles"},
      {"--remove-small-components 0", "N must be at least 1"},
      {"--smooth 0", "from 1 to 1000000"},
      {"--fill-holes 2", "from 3 to 1000000"},
      {"--weld -1", "finite number >= 0"},
      {"--weld nan", "finite number >= 0"},
  };
  for (const Case& c : cases) {
    CommandResult r = runTool("mtstore", "heal " + store + " " + c.args);
    EXPECT_EQ(r.exitCode, 1) << c.args << ": " << r.output;
    EXPECT_NE(r.output.find(c.expect), std::string::npos) << c.args << ": " << r.output;
    EXPECT_EQ(storeFiles(store), before) << c.args << " changed the store";
    EXPECT_FALSE(test::fileExists(store + "/tmp")) << c.args << " left scratch";
  }
  // Forced, they run.
  CommandResult forced = runTool("mtstore", "heal " + store + " --remove-small-components 10000000 --force -q");
  EXPECT_EQ(forced.exitCode, 0) << forced.output;
  EXPECT_NE(forced.output.find("20002"), std::string::npos) << forced.output;
}

TEST(StoreSafety, IngestRemovesTheLeftoversOfAKilledIngest) {
  TempDir tmp;
  test::writeFile(tmp.file("a.off"), "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
  // A PID that names no process: a child that has exited and been reaped.
  pid_t dead = fork();
  if (dead == 0) _exit(0);
  waitpid(dead, nullptr, 0);
  std::string leftover = tmp.file("s.ingest-" + std::to_string(dead));
  fs::create_directories(leftover + "/tmp");
  test::writeFile(leftover + "/INGEST-LOCK", std::to_string(dead) + "\n");
  test::writeFile(leftover + "/SEG-000001.dat", std::string(1000, 'x'));
  // Not ours (no lock file): never touched.
  std::string foreign = tmp.file("s.ingest-" + std::to_string(dead + 1000000));
  fs::create_directories(foreign);
  CommandResult r = runTool("mtstore", "ingest " + tmp.file("a.off") + " -o " + tmp.file("s") + " -q");
  ASSERT_EQ(r.exitCode, 0) << r.output;
  EXPECT_FALSE(fs::exists(leftover));
  EXPECT_NE(r.output.find("removed " + leftover), std::string::npos) << r.output;
  EXPECT_TRUE(fs::exists(foreign));
  EXPECT_FALSE(fs::exists(tmp.file("s") + "/INGEST-LOCK"));
}

TEST(StoreSafety, InterruptedIngestRemovesEverythingAndSaysSo) {
  TempDir tmp;
  ASSERT_EQ(runTool("mtgen", "-o " + tmp.file("big.ply") + " --triangles 2M").exitCode, 0);
  Background ingest("mtstore", "ingest " + tmp.file("big.ply") + " -o " + tmp.file("s") + " --memory 32M", tmp.file("log"));
  ASSERT_TRUE(waitFor([&] { return fs::exists(tmp.file("s.ingest-" + std::to_string(ingest.pid))); }, 30));
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  kill(ingest.pid, SIGINT);
  int code = ingest.wait();
  if (code == 0) GTEST_SKIP() << "the ingest finished before the signal";
  EXPECT_EQ(code, 130) << ingest.output();
  EXPECT_NE(ingest.output().find("nothing was written"), std::string::npos) << ingest.output();
  for (const auto& e : fs::directory_iterator(tmp.path()))
    EXPECT_EQ(e.path().filename().string().rfind("s", 0) == 0 && e.path().extension() != ".ply", false) << e.path();
}

TEST(StoreSafety, InterruptedHealKeepsWholeIterationsAndSaysWhichPassesWereKept) {
  TempDir tmp;
  std::string store = makeStore(tmp, "200k");
  Background heal("mtstore", "heal " + store + " --weld 0 --smooth 100000 --remove-degenerate", tmp.file("log"));
  ASSERT_TRUE(waitFor([&] { return heal.output().find("heal: smooth 1/100000:") != std::string::npos; }, 120)) << heal.output();
  kill(heal.pid, SIGTERM);
  EXPECT_EQ(heal.wait(), 143) << heal.output();
  std::string out = heal.output();
  EXPECT_NE(out.find("iterations done and kept in the store"), std::string::npos) << out;
  EXPECT_NE(out.find("passes finished: --weld"), std::string::npos) << out;
  EXPECT_NE(out.find("not run: --remove-degenerate"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(store + "/tmp"));
  EXPECT_FALSE(fs::exists(store + "/LOCK"));
  CommandResult check = runTool("mtstore", "check " + store);
  EXPECT_EQ(check.exitCode, 0) << check.output;
}

TEST(StoreSafety, IngestRefusesNonRegularInputsAndExistingFolders) {
  TempDir tmp;
  ASSERT_EQ(runTool("mtgen", "-o " + tmp.file("m.ply") + " --triangles 2k").exitCode, 0);
  ASSERT_EQ(mkfifo(tmp.file("fifo").c_str(), 0644), 0);
  fs::create_directories(tmp.file("dir"));
  struct Case {
    std::string input, expect;
  };
  for (const Case& c : std::vector<Case>{{tmp.file("fifo"), "is a FIFO, not a mesh file"},
                                         {"/dev/null", "is a character device, not a mesh file"},
                                         {tmp.file("dir"), "is a directory, not a mesh file"},
                                         {tmp.file("missing.ply"), "no such file"}}) {
    // timeout: the old binary blocked forever on a FIFO.
    CommandResult r = runShell("timeout 20 " + test::binDir() + "/mtstore ingest " + c.input + " -o " + tmp.file("out") + " -q");
    EXPECT_EQ(r.exitCode, 1) << c.input << ": " << r.output;
    EXPECT_NE(r.output.find(c.expect), std::string::npos) << c.input << ": " << r.output;
    EXPECT_FALSE(fs::exists(tmp.file("out")));
  }
  for (const auto& e : fs::directory_iterator(tmp.path()))
    EXPECT_EQ(e.path().string().find(".ingest-"), std::string::npos) << "leftover " << e.path();
  // An existing folder, even empty, is the user's: refused and left as it was.
  fs::create_directories(tmp.file("empty"));
  fs::create_directories(tmp.file("full"));
  test::writeFile(tmp.file("full/keep.txt"), "keep");
  for (const std::string& out : {tmp.file("empty"), tmp.file("full"), std::string(".")}) {
    CommandResult r = runTool("mtstore", "ingest " + tmp.file("m.ply") + " -o " + out + " -q");
    EXPECT_EQ(r.exitCode, 1) << out << ": " << r.output;
    EXPECT_NE(r.output.find("is an existing folder"), std::string::npos) << out << ": " << r.output;
  }
  EXPECT_TRUE(fs::is_directory(tmp.file("empty")));
  EXPECT_TRUE(fs::is_empty(tmp.file("empty")));
  EXPECT_EQ(test::readFile(tmp.file("full/keep.txt")), "keep");
}

TEST(StoreSafety, ExportChecksItsOutputAndNeverTruncatesAnExistingFile) {
  TempDir tmp;
  std::string store = makeStore(tmp, "20k");
  fs::create_directories(tmp.file("d"));
  CommandResult dir = runTool("mtstore", "export " + store + " -o " + tmp.file("d") + " -q");
  EXPECT_EQ(dir.exitCode, 1) << dir.output;
  EXPECT_NE(dir.output.find("is a directory"), std::string::npos) << dir.output;
  auto before = storeFiles(store);
  CommandResult self = runTool("mtstore", "export " + store + " -o " + store + "/CURRENT -q");
  EXPECT_EQ(self.exitCode, 1) << self.output;
  EXPECT_NE(self.output.find("is the input"), std::string::npos) << self.output;
  EXPECT_EQ(storeFiles(store), before);
  CommandResult ok = runTool("mtstore", "export " + store + " -o " + tmp.file("out.ply") + " -q");
  ASSERT_EQ(ok.exitCode, 0) << ok.output;
  for (const auto& e : fs::directory_iterator(tmp.path()))
    EXPECT_EQ(e.path().string().find(".tmp."), std::string::npos) << "leftover " << e.path();
  // A failing export (a corrupted block) leaves the existing file as it was.
  test::writeFile(tmp.file("keep.ply"), "precious");
  for (const auto& e : fs::directory_iterator(store))
    if (e.path().filename().string().rfind("SEG-", 0) == 0) {
      std::string bytes = test::readFile(e.path().string());
      bytes[bytes.size() / 2] ^= 0x5a;
      test::writeFile(e.path().string(), bytes);
    }
  CommandResult bad = runTool("mtstore", "export " + store + " -o " + tmp.file("keep.ply") + " -q");
  EXPECT_EQ(bad.exitCode, 3) << bad.output;
  EXPECT_EQ(test::readFile(tmp.file("keep.ply")), "precious");
}
