// The reading tools (mtinfo, mtverify, mtextract, mtrender) and mtgen against a careless command
// line: every numeric option is refused outside its range with the option and the range in one
// line; sizes go through the one parseSize; inputs that are not regular files (a FIFO, a folder,
// /dev/null) are refused at once instead of blocking; no output may replace an input, and an
// output's format comes from its name or is refused. Each tool runs under `timeout`, so a tool
// that blocks or runs away fails the test (exit 124) instead of hanging it.
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "base/error.h"
#include "base/size.h"
#include "mtfile/mt_file.h"
#include "patchstore/patch_store.h"
#include "tests/test_support.h"

namespace mt::test {
namespace {

namespace fs = std::filesystem;

constexpr int kTimedOut = 124;  // timeout(1)'s exit code

// `tool args` from build/bin with stdin closed, killed after `seconds`.
CommandResult runLimited(const std::string& tool, const std::string& args, int seconds = 20) {
  return mt::test::runShell("timeout " + std::to_string(seconds) + " " + binDir() + "/" + tool + " " + args + " </dev/null");
}

size_t lines(const std::string& s) { return size_t(std::count(s.begin(), s.end(), '\n')); }

std::vector<std::string> entries(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(dir)) names.push_back(e.path().filename().string());
  std::sort(names.begin(), names.end());
  return names;
}

// Expects a one-line refusal (exit 1) holding every needle.
void expectRefused(const std::string& tool, const std::string& args, const std::vector<std::string>& needles) {
  auto r = runLimited(tool, args);
  EXPECT_NE(r.exitCode, kTimedOut) << tool << " " << args << ": blocked or ran away";
  EXPECT_EQ(r.exitCode, 1) << tool << " " << args << "\n" << r.output;
  EXPECT_EQ(lines(r.output), 1u) << tool << " " << args << "\n" << r.output;
  for (const std::string& n : needles) EXPECT_NE(r.output.find(n), std::string::npos) << tool << " " << args << "\n" << r.output;
}

// One small MT for the suite: mtgen, then mtbuild.
class ToolOptions : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    auto g = runLimited("mtgen", "-o " + dir_->file("m.ply") + " --triangles 20k --seed 5", 60);
    ASSERT_EQ(g.exitCode, 0) << g.output;
    auto b = runLimited("mtbuild", dir_->file("m.ply") + " -o " + mt() + " --patch-triangles 500 --threads 2 -q", 120);
    ASSERT_EQ(b.exitCode, 0) << b.output;
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  static std::string mt() { return dir_->file("a.mt"); }
  static TempDir* dir_;
};
TempDir* ToolOptions::dir_ = nullptr;

// ---- parseSize --------------------------------------------------------------------------------

TEST(ParseSize, UnitsAndRange) {
  EXPECT_EQ(parseSize("1"), 1u);
  EXPECT_EQ(parseSize("64K"), 64ull << 10);
  EXPECT_EQ(parseSize("64k"), 64ull << 10);
  EXPECT_EQ(parseSize("1.5K"), 1536u);
  EXPECT_EQ(parseSize("256MB"), 256ull << 20);
  EXPECT_EQ(parseSize("4GiB"), 4ull << 30);
  EXPECT_EQ(parseSize("2T"), 2ull << 40);
  EXPECT_EQ(parseSize("1024T"), 1ull << 50);
  for (const char* bad : {"", "nan", "NaN", "inf", "-inf", "infinity", "-1", "-1M", "+1M", "0", "0K", "0.5", "1e-4K",
                          "1025T", "99999T", "1e30", " 1M", "1 M", "0x10", "5X", "lots", "1MM"}) {
    try {
      parseSize(bad);
      ADD_FAILURE() << "'" << bad << "' accepted";
    } catch (const Error& e) {
      // The refusal gives the accepted form and range.
      EXPECT_NE(std::string(e.what()).find("1024T = 1 PiB"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("'" + std::string(bad) + "'"), std::string::npos) << e.what();
    }
  }
  try {
    parseSize("12Q", "--memory");
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()).rfind("--memory: invalid size unit in '12Q'", 0), 0u) << e.what();
  }
}

// ---- inputs that are not regular files ----------------------------------------------------------

TEST_F(ToolOptions, NonRegularInputsAreRefusedAtOnce) {
  TempDir dir;
  const std::string fifo = dir.file("fifo.mt"), folder = dir.file("folder.mt");
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  fs::create_directory(folder);
  struct Input {
    std::string path, kind;
  } inputs[] = {{fifo, "is a FIFO, not an MT file"},
                {folder, "is a directory, not an MT file"},
                {"/dev/null", "is a character device, not an MT file"},
                {dir.file("missing.mt"), "no such file"}};
  for (const Input& in : inputs) {
    expectRefused("mtinfo", in.path, {"mtinfo: " + in.path + ": " + in.kind});
    expectRefused("mtinfo", in.path + " --check", {in.kind});
    expectRefused("mtverify", in.path, {"mtverify: " + in.path + ": " + in.kind});
    expectRefused("mtextract", in.path + " --error 0 -o " + dir.file("cut.ply"), {"mtextract: " + in.path + ": " + in.kind});
    expectRefused("mtrender", in.path + " --headless --quiet --frames 2",
                  {"mtrender: " + in.path + ": " + in.kind});
    // Each input of several.
    expectRefused("mtrender", mt() + " " + in.path + " --headless --quiet --frames 2", {in.path + ": " + in.kind});
  }
  // The camera path is an input too.
  expectRefused("mtrender", mt() + " --headless --quiet --frames 2 --camera-path " + fifo,
                {fifo + ": is a FIFO, not a camera path file"});
  EXPECT_EQ(entries(dir.path()), (std::vector<std::string>{"fifo.mt", "folder.mt"}));
}

// ---- mtextract -------------------------------------------------------------------------------

TEST_F(ToolOptions, MtextractNeverOverwritesItsInput) {
  TempDir dir;
  const std::string copy = dir.file("model.ply");  // an MT file under a PLY name
  fs::copy_file(mt(), copy);
  const std::string bytes = readFile(copy);
  fs::create_symlink(copy, dir.file("link.ply"));
  fs::create_hard_link(copy, dir.file("hard.ply"));
  for (const std::string& out : {copy, dir.path() + "/./model.ply", dir.file("link.ply"), dir.file("hard.ply")})
    expectRefused("mtextract", copy + " --error 0 -o " + out, {"is the input", "choose another output name"});
  expectRefused("mtextract", mt() + " --error 0 -o " + mt(), {"is the input"});
  EXPECT_EQ(readFile(copy), bytes);
  EXPECT_EQ(readFile(mt()), readFile(copy));
  expectRefused("mtextract", copy + " --error 0 -o " + dir.path(), {"is a directory"});
  expectRefused("mtextract", copy + " --error 0 -o " + dir.file("no/such/cut.ply"), {"does not exist"});
}

TEST_F(ToolOptions, MtextractNumericOptionsHaveRanges) {
  TempDir dir;
  const std::string out = " -o " + dir.file("cut.ply");
  const std::string view = " --eye 1,2,3 --target 0,0,0";
  struct Case {
    std::string args;
    std::vector<std::string> needles;
  } cases[] = {
      {"--triangles -1", {"--triangles: must be an integer in [1, 1000000000000]", "'-1'"}},
      {"--triangles 0", {"--triangles: must be an integer in [1, 1000000000000]", "'0'"}},
      {"--triangles 1.5", {"--triangles: must be an integer"}},
      {"--triangles 1e3", {"--triangles: must be an integer"}},
      {"--error -1", {"--error: must be a finite number >= 0"}},
      {"--error nan", {"--error: must be a finite number >= 0", "'nan'"}},
      {"--error inf", {"--error: must be a finite number >= 0", "'inf'"}},
      {view + " --fov 0", {"--fov: must be a number in (0, 180) degrees"}},
      {view + " --fov 180", {"--fov: must be a number in (0, 180) degrees"}},
      {view + " --fov nan", {"--fov: must be a number in (0, 180) degrees"}},
      {view + " --width 0", {"--width: must be a number in [1, 1000000] pixels"}},
      {view + " --width -1920", {"--width: must be a number in [1, 1000000] pixels"}},
      {view + " --pixels 0", {"--pixels: must be a number in (0, 1000000] pixels"}},
      {view + " --pixels inf", {"--pixels: must be a number in (0, 1000000] pixels"}},
      {view + " --triangles -1", {"--triangles: must be an integer in [1, 1000000000000]"}},
  };
  for (const Case& c : cases) expectRefused("mtextract", mt() + " " + c.args + out, c.needles);
  EXPECT_TRUE(entries(dir.path()).empty());
  // The bounds themselves are accepted.
  auto r = runLimited("mtextract", mt() + " --triangles 1" + out);
  EXPECT_EQ(r.exitCode, 0) << r.output;
  r = runLimited("mtextract", mt() + view + " --fov 179 --width 1 --pixels 1000000" + out);
  EXPECT_EQ(r.exitCode, 0) << r.output;
}

TEST_F(ToolOptions, MtextractWritesItsFormatsOnlyAndOnlyWhenComplete) {
  TempDir dir;
  for (const std::string name : {"cut.xyz", "cut.stl", "cut", "cut.ply.tmp", ".ply"}) {
    expectRefused("mtextract", mt() + " --error 0 -o " + dir.file(name), {"supported: .ply, .glb, .gltf, .obj"});
    EXPECT_FALSE(fileExists(dir.file(name))) << name;
  }
  EXPECT_TRUE(entries(dir.path()).empty());
  auto r = runLimited("mtextract", mt() + " --error 0 -o " + dir.file("cut.ply"));
  ASSERT_EQ(r.exitCode, 0) << r.output;
  auto upper = runLimited("mtextract", mt() + " --error 0 -o " + dir.file("CUT.PLY"));
  ASSERT_EQ(upper.exitCode, 0) << upper.output;
  // Only the outputs: the temporary names are gone, and the bytes are a PLY.
  EXPECT_EQ(entries(dir.path()), (std::vector<std::string>{"CUT.PLY", "cut.ply"}));
  EXPECT_EQ(readFile(dir.file("cut.ply")).rfind("ply\nformat binary_little_endian 1.0\n", 0), 0u);
  EXPECT_EQ(readFile(dir.file("cut.ply")), readFile(dir.file("CUT.PLY")));
  // A failure during the extraction (a damaged payload of the finest cut) leaves the old output
  // as it was and no temporary beside it.
  const std::string old = readFile(dir.file("cut.ply"));
  const std::string broken = dir.file("broken.mt");
  std::string bytes = readFile(mt());
  {
    auto reader = MtFileReader::open(mt());
    const auto& patch = reader->patches()[0];  // on an arc out of the source: in the finest cut
    bytes[patch.offset + patch.size / 2] ^= 0x5a;
  }
  writeFile(broken, bytes);
  r = runLimited("mtextract", broken + " --error 0 -o " + dir.file("cut.ply"));
  EXPECT_EQ(r.exitCode, 3) << r.output;
  EXPECT_NE(r.output.find("patch 0 is damaged"), std::string::npos) << r.output;
  EXPECT_EQ(readFile(dir.file("cut.ply")), old);
  EXPECT_EQ(entries(dir.path()), (std::vector<std::string>{"CUT.PLY", "broken.mt", "cut.ply"}));
  // The same for glTF output (.glb, and .gltf with its .bin): nothing under either name.
  for (const std::string name : {"cut.glb", "cut.gltf"}) {
    r = runLimited("mtextract", broken + " --error 0 -o " + dir.file(name));
    EXPECT_EQ(r.exitCode, 3) << r.output;  // a damaged file: corruption
  }
  EXPECT_EQ(entries(dir.path()), (std::vector<std::string>{"CUT.PLY", "broken.mt", "cut.ply"}));
}

// ---- mtinfo / mtverify ------------------------------------------------------------------------

TEST_F(ToolOptions, MtverifyCountsAndMemoryHaveRanges) {
  expectRefused("mtverify", mt() + " --cuts -1", {"--cuts: must be an integer in [0, 1000000]", "'-1'"});
  expectRefused("mtverify", mt() + " --cuts 4294967295", {"--cuts: must be an integer in [0, 1000000]"});
  expectRefused("mtverify", mt() + " --seed -1", {"--seed: must be an integer in [0, 18446744073709551615]"});
  for (const char* m : {"0", "1", "-1M", "nan", "inf", "1K", "2048T", "99999T", "12Q"})
    expectRefused("mtverify", mt() + " --memory " + std::string(m),
                  {"--memory: ", std::string("'") + m + "'", "from 64K to 1024T"});
  auto r = runLimited("mtverify", mt() + " --cuts 0 --memory 64K");
  EXPECT_EQ(r.exitCode, 0) << r.output;
  r = runLimited("mtverify", mt() + " --cuts 1 --memory 1024T");
  EXPECT_EQ(r.exitCode, 0) << r.output;
  expectRefused("mtinfo", mt() + " --no-such-option", {"mtinfo: ", "--no-such-option"});
}

TEST(ToolHelp, EveryOptionStatesItsRange) {
  struct Help {
    const char* tool;
    std::vector<std::string> needles;
  } helps[] = {
      {"mtextract",
       {"a finite number >= 0", "an integer in [1, 1000000000000]", "(0, 180) degrees", "[1, 1000000] pixels",
        "(0, 1000000] pixels", ".ply (binary little-endian, welded), .glb or .gltf"}},
      {"mtverify", {"an integer in [0, 1000000]", "from 64K to 1024T", "=8", "=1G"}},
      {"mtrender",
       {"(0, 60000] ms", "an integer in [1, 10000000]", "an integer in [16, 16384]", "(0, 10000] pixels",
        "from 1M to 1024T", "an integer in [0, 255]", "an integer in [1, 64]", "{auto,shaded,vertex,texture,patch,lod}"}},
      {"mtgen", {"an integer in [0, 20000]", "an integer in [1, 1000000]", "to 4G", ".ply, .obj, .off, .stl"}},
  };
  for (const Help& h : helps) {
    auto r = runLimited(h.tool, "--help");
    EXPECT_EQ(r.exitCode, 0) << h.tool;
    for (const std::string& n : h.needles) EXPECT_NE(r.output.find(n), std::string::npos) << h.tool << ": " << n << "\n" << r.output;
  }
}

// The tools that print progress lines all take -q, --quiet (mtserve's logs requests instead).
TEST(ToolHelp, EveryToolThatPrintsProgressTakesDashQ) {
  for (const char* tool : {"mtbuild", "mtgen", "mtverify", "mtrender", "mtexport tiles", "mtstore ingest", "mtstore export",
                           "mtstore heal", "mtserve"}) {
    auto r = runLimited(tool, "--help");
    EXPECT_EQ(r.exitCode, 0) << tool << "\n" << r.output;
    EXPECT_NE(r.output.find("-q,--quiet"), std::string::npos) << tool << "\n" << r.output;
  }
}

// mtgen -q: the progress lines of a large output go, its summary line stays.
TEST(MtgenOptions, QuietDropsTheProgressLines) {
  TempDir dir;
  auto loud = runLimited("mtgen", "-o " + dir.file("a.ply") + " --triangles 5.2M --threads 2", 600);
  ASSERT_EQ(loud.exitCode, 0) << loud.output;
  EXPECT_NE(loud.output.find("%  "), std::string::npos) << "no progress line above 5M triangles:\n" << loud.output;
  auto quiet = runLimited("mtgen", "-o " + dir.file("b.ply") + " --triangles 5.2M --threads 2 -q", 600);
  ASSERT_EQ(quiet.exitCode, 0) << quiet.output;
  EXPECT_EQ(quiet.output.find("%  "), std::string::npos) << quiet.output;
  EXPECT_NE(quiet.output.find("mtgen: wrote " + dir.file("b.ply")), std::string::npos) << quiet.output;
  EXPECT_EQ(mt::test::runShell("cmp -s " + dir.file("a.ply") + " " + dir.file("b.ply")).exitCode, 0) << "-q changed the bytes";
}

// ---- mtrender -----------------------------------------------------------------------------------

TEST_F(ToolOptions, MtrenderRefusesNonsenseOptions) {
  TempDir dir;
  const std::string run = mt() + " --headless --quiet --width 64 --height 64 ";
  struct Case {
    std::string args;
    std::vector<std::string> needles;
  } cases[] = {
      {"--budget-ms 0", {"--budget-ms: must be a number in (0, 60000] ms", "'0'"}},
      {"--budget-ms -1", {"--budget-ms: must be a number in (0, 60000] ms"}},
      {"--budget-ms nan", {"--budget-ms: must be a number in (0, 60000] ms", "'nan'"}},
      {"--frames 0", {"--frames: must be an integer in [1, 10000000]", "'0'"}},
      {"--frames -1", {"--frames: must be an integer in [1, 10000000]", "'-1'"}},
      {"--tolerance 0", {"--tolerance: must be a number in (0, 10000] pixels"}},
      {"--tolerance -1", {"--tolerance: must be a number in (0, 10000] pixels"}},
      {"--background 999 -5 0", {"--background: must be an integer in [0, 255]"}},
      {"--background 0 -5 0", {"--background: must be an integer in [0, 255]", "'-5'"}},
      {"--screenshot-every 0", {"--screenshot-every: must be an integer in [1, 10000000]"}},
      {"--width 0", {"--width: must be an integer in [16, 16384]", "'0'"}},
      {"--height 100000", {"--height: must be an integer in [16, 16384]"}},
      {"--still-frames 0", {"--still-frames: must be an integer in [1, 64]"}},
      {"--fixed-triangles -1", {"--fixed-triangles: must be an integer"}},
      {"--extract-ms 0", {"--extract-ms: must be a number in (0, 60000] ms"}},
      {"--load-budget 0", {"--load-budget: must be an integer in [1, 1000000]"}},
      {"--frame-interval-ms -1", {"--frame-interval-ms: must be a number in [0, 60000] ms"}},
      {"--test-read-delay-ms inf", {"--test-read-delay-ms: must be a number in [0, 60000] ms"}},
      {"--color red", {"--color: red not in {auto,shaded,vertex,texture,patch,lod}"}},
      {"--cache 0", {"--cache: ", "'0'", "from 1M to 1024T"}},
      {"--cache 1K", {"--cache: size '1K' out of range (from 1M to 1024T"}},
      {"--cache 99999T", {"--cache: size '99999T' out of range (from 1M to 1024T"}},
      {"--cache nan", {"--cache: invalid size 'nan'", "from 1M to 1024T"}},
      {"--gpu-cache -1M", {"--gpu-cache: invalid size '-1M'", "from 1M to 1024T"}},
  };
  for (const Case& c : cases) expectRefused("mtrender", run + c.args, c.needles);
  expectRefused("mtrender", mt() + " --max-frames 0", {"--max-frames: must be an integer in [1, 1000000000]"});
  EXPECT_TRUE(entries(dir.path()).empty());
}

TEST_F(ToolOptions, MtrenderOutputsNeverReplaceAnInput) {
  TempDir dir;
  const std::string model = dir.file("model.mt"), shot = dir.file("shot.png");
  fs::copy_file(mt(), model);
  fs::copy_file(mt(), shot);  // an MT file under a PNG name
  const std::string bytes = readFile(model);
  const std::string run = " --headless --quiet --width 64 --height 64 --frames 2 ";
  expectRefused("mtrender", model + run + "--stats " + model, {model + ": is the input"});
  expectRefused("mtrender", model + " " + shot + run + "--stats " + shot, {"is the input"});
  expectRefused("mtrender", shot + " --max-frames 1 --screenshot " + shot, {"is the input"});
  expectRefused("mtrender", model + " --max-frames 1 --screenshot " + dir.file("shot.jpg"), {"must end in .png"});
  expectRefused("mtrender", model + " --max-frames 1 --record " + model, {"is the input"});
  expectRefused("mtrender", model + run + "--plot " + model, {"is not a directory"});
  expectRefused("mtrender", model + run + "--screenshots " + model, {"is not a directory"});
  fs::create_directory(dir.file("plots"));
  fs::copy_file(mt(), dir.file("plots/frames.csv"));
  expectRefused("mtrender", dir.file("plots/frames.csv") + run + "--plot " + dir.file("plots"), {"is the input"});
  fs::copy_file(mt(), dir.file("frame_00000.png"));
  expectRefused("mtrender", dir.file("frame_00000.png") + run + "--screenshots " + dir.path(),
                {"would be overwritten by a screenshot"});
  EXPECT_EQ(readFile(model), bytes);
  EXPECT_EQ(readFile(shot), bytes);
  EXPECT_EQ(readFile(dir.file("plots/frames.csv")), bytes);
  EXPECT_EQ(readFile(dir.file("frame_00000.png")), bytes);
}

// ---- mtgen ------------------------------------------------------------------------------------

TEST(MtgenOptions, CountsHaveRanges) {
  TempDir dir;
  const std::string out = "-o " + dir.file("g.ply") + " ";
  struct Case {
    std::string args;
    std::vector<std::string> needles;
  } cases[] = {
      {"--triangles 0", {"--triangles must be a positive count", "'0'"}},
      {"--triangles -5", {"--triangles must be a positive count"}},
      {"--triangles nan", {"--triangles must be a positive count"}},
      {"--triangles 99999G", {"--triangles must be at most 4G"}},
      {"--holes 4294967295", {"--holes: must be an integer in [0, 20000]"}},
      {"--holes -1", {"--holes: must be an integer in [0, 20000]", "'-1'"}},
      {"--triangles 1k --holes 11", {"--holes 11: at most one hole per 100 triangles (10 for --triangles 1k)"}},
      {"--components 0", {"--components: must be an integer in [1, 1000000]"}},
      {"--components -1", {"--components: must be an integer in [1, 1000000]"}},
      {"--threads 99999", {"--threads: must be an integer in [0, 4096]"}},
      {"--threads -1", {"--threads: must be an integer in [0, 4096]"}},
      {"--seed -1", {"--seed: must be an integer in [0, 18446744073709551615]"}},
  };
  for (const Case& c : cases) expectRefused("mtgen", out + c.args, c.needles);
  EXPECT_TRUE(entries(dir.path()).empty());
}

TEST(MtgenOptions, FormatComesFromTheExtension) {
  TempDir dir;
  for (const std::string name : {"g.xyz", "g.glb", "g", "g.mt"})
    expectRefused("mtgen", "-o " + dir.file(name) + " --triangles 1k", {"supported: .ply, .obj, .off, .stl"});
  expectRefused("mtgen", "-o " + dir.file("g.obj") + " --triangles 1k --format ply",
                {"--format ply does not match the output's extension .obj"});
  expectRefused("mtgen", "-o " + dir.file("g.ply") + " --triangles 1k --format stl", {"does not match"});
  expectRefused("mtgen", "-o " + dir.path() + " --triangles 1k", {"supported"});
  fs::create_directory(dir.file("sub.ply"));
  expectRefused("mtgen", "-o " + dir.file("sub.ply") + " --triangles 1k", {"is a directory"});
  fs::remove(dir.file("sub.ply"));
  EXPECT_TRUE(entries(dir.path()).empty());

  // Without --format the extension decides; with it, both agree. Nothing else is left behind.
  for (const std::string& args : {"-o " + dir.file("a.obj"), "-o " + dir.file("b.OFF"), "-o " + dir.file("c.stl"),
                                 "-o " + dir.file("d.ply"), "-o " + dir.file("e.ply") + " --format ply-ascii",
                                 "-o " + dir.file("f.obj") + " --format obj"}) {
    auto r = runLimited("mtgen", args + " --triangles 1k");
    EXPECT_EQ(r.exitCode, 0) << args << "\n" << r.output;
  }
  EXPECT_EQ(entries(dir.path()), (std::vector<std::string>{"a.obj", "b.OFF", "c.stl", "d.ply", "e.ply", "f.obj"}));
  EXPECT_EQ(readFile(dir.file("a.obj")).rfind("# written by mtgen", 0), 0u);
  EXPECT_EQ(readFile(dir.file("b.OFF")).rfind("OFF\n", 0), 0u);
  EXPECT_EQ(readFile(dir.file("c.stl")).rfind("solid mtgen\n", 0), 0u);
  EXPECT_EQ(readFile(dir.file("d.ply")).rfind("ply\nformat binary_little_endian", 0), 0u);
  EXPECT_EQ(readFile(dir.file("e.ply")).rfind("ply\nformat ascii", 0), 0u);
  EXPECT_EQ(readFile(dir.file("a.obj")), readFile(dir.file("f.obj")));
}

// An interrupted run removes its temporary files (both the run's unique name and the PLY writer's
// own) and leaves nothing under the output name.
TEST(MtgenOptions, InterruptedRunLeavesNothing) {
  TempDir dir;
  for (const char* name : {"big.ply", "big.obj"}) {
    const std::string cmd = "timeout -s INT 0.5 " + binDir() + "/mtgen -o " + dir.file(name) +
                            " --triangles 1G --threads 1 >/dev/null 2>&1";
    const int status = std::system(cmd.c_str());
    ASSERT_TRUE(WIFEXITED(status));
    EXPECT_EQ(WEXITSTATUS(status), 124) << name << ": finished within a second?";
    EXPECT_TRUE(entries(dir.path()).empty()) << name << ": " << (entries(dir.path()).empty() ? "" : entries(dir.path())[0]);
  }
}

}  // namespace
}  // namespace mt::test
