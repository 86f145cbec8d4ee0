// Exit codes by kind (base/exit_code.h, README "Exit codes"): invalid input 1, a corrupt file 3,
// an I/O failure 4 (a write the file-size limit refuses stands for a full disk), a resource limit
// 5, the same in every tool, with the kind in the message. And damage anywhere in an MT file: a
// flipped byte at random offsets is reported by `mtinfo --check` and `mtverify`, naming the patch
// or the section, with exit code 3 (or 1 for the magic and version bytes: not an MT file of this
// version).
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <random>

#include "base/exit_code.h"
#include "mtfile/mt_file.h"
#include "test_support.h"

namespace fs = std::filesystem;
using mt::test::CommandResult;
using mt::test::TempDir;
using mt::test::binDir;
using mt::test::readFile;
using mt::test::runShell;
using mt::test::runTool;
using mt::test::writeFile;

namespace {

bool has(const std::string& text, const std::string& needle) { return text.find(needle) != std::string::npos; }

// A small MT file built by the tools (mtgen, mtbuild): 3000 triangles, several levels.
class ExitCodes : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir;
    ASSERT_EQ(runTool("mtgen", "-o " + dir_->file("in.ply") + " -t 3k -s 7").exitCode, 0);
    CommandResult b = runTool("mtbuild", dir_->file("in.ply") + " -o " + dir_->file("small.mt") +
                                             " --patch-triangles 100 --threads 1 -q");
    ASSERT_EQ(b.exitCode, 0) << b.output;
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  static std::string mt() { return dir_->file("small.mt"); }
  static TempDir* dir_;
};
TempDir* ExitCodes::dir_ = nullptr;

void flipByte(const std::string& path, uint64_t offset, uint8_t mask) {
  std::fstream f(path, std::ios::in | std::ios::out | std::ios::binary);
  f.seekg(std::streamoff(offset));
  char c = 0;
  f.read(&c, 1);
  c = char(uint8_t(c) ^ mask);
  f.seekp(std::streamoff(offset));
  f.write(&c, 1);
}

}  // namespace

TEST_F(ExitCodes, InvalidInputIsOne) {
  TempDir tmp;
  writeFile(tmp.file("bad.ply"), "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                                 "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                                 "0 0 0\n1 0 0\n0 1 0\n3 0 1 9\n");
  CommandResult r = runTool("mtbuild", tmp.file("bad.ply") + " -o " + tmp.file("bad.mt") + " -q");
  EXPECT_EQ(r.exitCode, mt::kExitInvalidInput) << r.output;
  EXPECT_TRUE(has(r.output, tmp.file("bad.ply"))) << r.output;
  EXPECT_EQ(runTool("mtstore", "ingest " + tmp.file("bad.ply") + " -o " + tmp.file("s") + " -q").exitCode,
            mt::kExitInvalidInput);
  EXPECT_EQ(runTool("mtinfo", "--no-such-option " + mt()).exitCode, mt::kExitInvalidInput);
  EXPECT_EQ(runTool("mtextract", mt() + " --error -1 -o " + tmp.file("x.ply")).exitCode, mt::kExitInvalidInput);
  EXPECT_EQ(runTool("mtverify", tmp.file("missing.mt")).exitCode, mt::kExitInvalidInput);
}

TEST_F(ExitCodes, CorruptFileIsThreeInEveryReader) {
  TempDir tmp;
  auto reader = mt::MtFileReader::open(mt());
  const mt::format::PatchRecord p = reader->patches()[0];
  // A damaged payload: the readers that decode it say which patch.
  const std::string payload = tmp.file("payload.mt");
  fs::copy_file(mt(), payload);
  flipByte(payload, p.offset + p.size / 2, 0x40);
  CommandResult info = runTool("mtinfo", "--check " + payload);
  EXPECT_EQ(info.exitCode, mt::kExitCorruption) << info.output;
  EXPECT_TRUE(has(info.output, "patch 0")) << info.output;
  CommandResult verify = runTool("mtverify", payload);
  EXPECT_EQ(verify.exitCode, mt::kExitCorruption) << verify.output;
  EXPECT_TRUE(has(verify.output, "patch 0")) << verify.output;
  CommandResult extract = runTool("mtextract", payload + " --error 0 -o " + tmp.file("x.ply"));
  EXPECT_EQ(extract.exitCode, mt::kExitCorruption) << extract.output;
  EXPECT_TRUE(has(extract.output, "[corrupt file]")) << extract.output;
  EXPECT_FALSE(fs::exists(tmp.file("x.ply")));
  // A damaged index: every reader refuses the file at open.
  const std::string index = tmp.file("index.mt");
  fs::copy_file(mt(), index);
  flipByte(index, reader->header().metaOffset + 5, 0x01);
  for (const std::string tool : {"mtinfo", "mtverify"}) {
    CommandResult r = runTool(tool, index);
    EXPECT_EQ(r.exitCode, mt::kExitCorruption) << tool << ": " << r.output;
    EXPECT_TRUE(has(r.output, tool + ": " + index + ": ")) << r.output;
    EXPECT_TRUE(has(r.output, "[corrupt file]")) << r.output;
  }
  EXPECT_EQ(runTool("mtextract", index + " --error 0 -o " + tmp.file("x.ply")).exitCode, mt::kExitCorruption);
  CommandResult tiles = runTool("mtexport", "tiles " + index + " " + tmp.file("tiles"));
  EXPECT_EQ(tiles.exitCode, mt::kExitCorruption) << tiles.output;
  EXPECT_TRUE(has(tiles.output, "mtexport: " + index + ": ")) << tiles.output;
  EXPECT_FALSE(fs::exists(tmp.file("tiles")));
}

// mtrender opens its files while its GL context comes up, so it meets a damaged index with the
// context made: a test of its own, among those run without leak detection under the sanitizers
// (scripts/test.sh: Mesa's driver keeps allocations LeakSanitizer cannot name).
TEST_F(ExitCodes, CorruptIndexIsThreeInMtrender) {
  TempDir tmp;
  auto reader = mt::MtFileReader::open(mt());
  const std::string index = tmp.file("index.mt");
  fs::copy_file(mt(), index);
  flipByte(index, reader->header().metaOffset + 5, 0x01);
  CommandResult render = runTool("mtrender", index + " --headless --width 32 --height 32 --frames 1");
  EXPECT_EQ(render.exitCode, mt::kExitCorruption) << render.output;
  EXPECT_TRUE(has(render.output, "mtrender: " + index + ": ")) << render.output;
  EXPECT_TRUE(has(render.output, "[corrupt file]")) << render.output;
}

TEST_F(ExitCodes, IoFailureIsFour) {
  // A file-size limit makes every write past it fail (EFBIG) as a full disk would (ENOSPC): the
  // writer's error names the file, the exit code is 4, and nothing is left under the final name.
  // (test_faults injects ENOSPC itself at every point of a build.)
  TempDir tmp;
  const std::string limited = "ulimit -f 8; trap '' XFSZ; ";  // 8 KiB; SIGXFSZ ignored, so write() fails
  CommandResult x = runShell(limited + binDir() + "/mtextract " + mt() + " --error 0 -o " + tmp.file("cut.ply"));
  EXPECT_EQ(x.exitCode, mt::kExitIo) << x.output;
  EXPECT_TRUE(has(x.output, "mtextract: " + tmp.file("cut.ply"))) << x.output;
  EXPECT_TRUE(has(x.output, "[I/O error]")) << x.output;
  EXPECT_TRUE(has(x.output, "File too large")) << x.output;
  CommandResult b = runShell(limited + binDir() + "/mtbuild " + dir_->file("in.ply") + " -o " + tmp.file("big.mt") +
                             " --patch-triangles 100 --threads 1 -q");
  EXPECT_EQ(b.exitCode, mt::kExitIo) << b.output;
  EXPECT_TRUE(has(b.output, "[I/O error]")) << b.output;
  for (const auto& e : fs::directory_iterator(tmp.path())) {
    const std::string name = e.path().filename().string();
    EXPECT_TRUE(name != "cut.ply" && name != "big.mt") << "left under the final name: " << name;
  }
  // The build's report (--stats-json) is written as every output is: a place that cannot take it
  // is an I/O error naming it.
  const std::string stats = tmp.file("missing/stats.json");
  CommandResult s = runTool("mtbuild", dir_->file("in.ply") + " -o " + tmp.file("s.mt") +
                                           " --patch-triangles 100 --threads 1 -q --stats-json " + stats);
  EXPECT_EQ(s.exitCode, mt::kExitIo) << s.output;
  EXPECT_TRUE(has(s.output, "mtbuild: " + stats)) << s.output;
  EXPECT_TRUE(has(s.output, "[I/O error]")) << s.output;
}

TEST_F(ExitCodes, MtserveOnAPortInUseIsAnIoError) {
  // The system refuses the port (another process listens on it): exit 4 with the kind, as in the
  // other tools.
  TempDir tmp;
  const int busy = ::socket(AF_INET, SOCK_STREAM, 0);
  ASSERT_GE(busy, 0);
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(::bind(busy, reinterpret_cast<sockaddr*>(&addr), sizeof addr), 0);
  ASSERT_EQ(::listen(busy, 1), 0);
  socklen_t len = sizeof addr;
  ASSERT_EQ(::getsockname(busy, reinterpret_cast<sockaddr*>(&addr), &len), 0);
  CommandResult r = runTool("mtserve", tmp.path() + " --port " + std::to_string(ntohs(addr.sin_port)) + " -q");
  ::close(busy);
  EXPECT_EQ(r.exitCode, mt::kExitIo) << r.output;
  EXPECT_TRUE(has(r.output, "mtserve: cannot listen on 127.0.0.1:")) << r.output;
  EXPECT_TRUE(has(r.output, "[I/O error]")) << r.output;
}

TEST_F(ExitCodes, ResourceLimitIsFive) {
  TempDir tmp;
  // More vertices than 32-bit indices address: a limit of the tools, not a damaged input.
  writeFile(tmp.file("huge.ply"), "ply\nformat binary_little_endian 1.0\nelement vertex 5000000000\nproperty float x\n"
                                  "property float y\nproperty float z\nelement face 1\n"
                                  "property list uchar int vertex_indices\nend_header\n");
  CommandResult b = runTool("mtbuild", tmp.file("huge.ply") + " -o " + tmp.file("huge.mt") + " -q");
  EXPECT_EQ(b.exitCode, mt::kExitResource) << b.output;
  EXPECT_TRUE(has(b.output, "mtbuild: " + tmp.file("huge.ply"))) << b.output;
  EXPECT_TRUE(has(b.output, "[resource limit]")) << b.output;
  CommandResult s = runTool("mtstore", "ingest " + tmp.file("huge.ply") + " -o " + tmp.file("s") + " -q");
  EXPECT_EQ(s.exitCode, mt::kExitResource) << s.output;
  EXPECT_FALSE(fs::exists(tmp.file("huge.mt")));
}

TEST_F(ExitCodes, RandomByteFlipsAreReportedWithThePatchOrSection) {
  // Every flip, wherever it lands (header, payloads, padding, DAG, index, footer), makes
  // `mtinfo --check` and `mtverify` fail naming what is damaged.
  TempDir tmp;
  const std::string original = readFile(mt());
  std::mt19937_64 random(20);
  const int flips = 60;
  int inPayloads = 0;
  auto reader = mt::MtFileReader::open(mt());
  for (int i = 0; i < flips; ++i) {
    const uint64_t offset = random() % original.size();
    const uint8_t mask = uint8_t(1u << (random() % 8));
    SCOPED_TRACE("byte " + std::to_string(offset) + " ^ " + std::to_string(mask));
    std::string damaged = original;
    damaged[offset] = char(uint8_t(damaged[offset]) ^ mask);
    const std::string path = tmp.file("flip.mt");
    writeFile(path, damaged);
    bool payload = false;
    for (const auto& p : reader->patches()) payload |= offset >= p.offset && offset < p.offset + p.size;
    inPayloads += payload;
    for (const std::string& command : {std::string("mtinfo --check"), std::string("mtverify")}) {
      // stderr only (the reports), in a subshell so runShell's own 2>&1 does not undo it.
      CommandResult r = runShell("(" + binDir() + "/" + command + " " + path + " 2>&1 >/dev/null)");
      EXPECT_NE(r.exitCode, 0) << command << " missed it:\n" << r.output;
      if (offset >= 16) {
        EXPECT_EQ(r.exitCode, mt::kExitCorruption) << command << ":\n" << r.output;
      }
      const bool named = has(r.output, "patch ") || has(r.output, "header") || has(r.output, "footer") ||
                         has(r.output, "index") || has(r.output, "magic") || has(r.output, "version") ||
                         has(r.output, "padding");
      EXPECT_TRUE(named) << command << " names no patch or section:\n" << r.output;
      if (payload) {
        EXPECT_TRUE(has(r.output, "patch ")) << command << ":\n" << r.output;
      }
    }
  }
  EXPECT_GT(inPayloads, flips / 2) << "most of a file is payloads";
}
