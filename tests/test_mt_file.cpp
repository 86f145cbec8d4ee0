// MT file writer/reader (mtfile/mt_file.h): round trip, temporary name until complete, and clear
// one-line errors naming the file (and the patch or byte offset) for every kind of damage.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <set>
#include <string>

#include "base/env.h"
#include "base/error.h"
#include "base/process.h"
#include "mtfile/mt_file.h"
#include "testing/scan_grid.h"
#include "tests/test_support.h"

using namespace mt;
using namespace mt::format;

namespace {

struct Built {
  std::string path;
  std::vector<std::vector<uint8_t>> payloads;
  uint32_t triangles[4];
};

// A tiny DAG: source -> {A, B} -> sink, four patches (source has 2, A and B one each).
Built writeSmall(const std::string& path, Codec codec, Env* env = Env::Default()) {
  Built b;
  b.path = path;
  FileHeader h{};
  h.codec = uint32_t(codec);
  h.levelCount = 2;
  h.inputTriangles = 1234;
  double lo[3] = {-1, -1, -10}, hi[3] = {100, 100, 10};
  QuantizationGrid grid = QuantizationGrid::fromBounds(lo, hi, 1.0 / 64);
  for (int a = 0; a < 3; ++a) h.gridOrigin[a] = grid.origin[a], h.boundsMin[a] = lo[a], h.boundsMax[a] = hi[a];
  h.gridStep = grid.step;
  h.gridBits = grid.bits;
  h.quantizationError = grid.maxError();
  MtFileWriter w(path, h, {}, env);
  EXPECT_FALSE(test::fileExists(path)) << "nothing under the final name before finish()";
  for (int i = 0; i < 4; ++i) {
    ScanGridOptions o;
    o.nx = 10 + i * 3, o.ny = 12;
    o.seed = uint64_t(i + 1);
    ScanGrid g = makeScanGrid(o);
    PatchCodecOptions opt;
    opt.codec = codec;
    b.payloads.push_back(encodePatch({g.positions.data(), g.vertexCount(), g.triangles.data(), g.triangleCount(), nullptr, nullptr},
                                     grid, opt));
    b.triangles[i] = g.triangleCount();
    EXPECT_EQ(w.appendPatch(b.payloads.back().data(), b.payloads.back().size(), g.triangleCount(), g.vertexCount()),
              uint32_t(i));
  }
  std::vector<NodeRecord> nodes(4);
  for (uint32_t i = 0; i < 4; ++i) {
    nodes[i] = NodeRecord{};
    nodes[i].level = i == 0 ? 0 : i == 3 ? 2 : 1;
    nodes[i].error = i == 3 ? INFINITY : float(i) * 0.5f;
    nodes[i].radius = 10.f + float(i);
    nodes[i].coneCutoff = -1;
  }
  std::vector<DagArc> arcs = {{2, 3, {3}}, {0, 1, {0}}, {0, 2, {1}}, {1, 3, {2}}};  // any order
  w.finish(nodes, arcs);
  return b;
}

TEST(MtFile, RoundTrip) {
  test::TempDir dir;
  for (Codec codec : {Codec::Meshopt, Codec::Draco}) {
    Built b = writeSmall(dir.file(codec == Codec::Draco ? "draco.mt" : "meshopt.mt"), codec);
    EXPECT_TRUE(test::fileExists(b.path));
    EXPECT_FALSE(test::fileExists(b.path + ".tmp"));
    auto r = MtFileReader::open(b.path);
    EXPECT_EQ(r->codec(), codec);
    EXPECT_EQ(r->header().levelCount, 2u);
    EXPECT_EQ(r->header().inputTriangles, 1234u);
    ASSERT_EQ(r->nodes().size(), 4u);
    ASSERT_EQ(r->arcs().size(), 4u);
    ASSERT_EQ(r->patches().size(), 4u);
    // forward stars sorted by (from, to), backward stars consistent
    EXPECT_EQ(r->nodes()[0].arcCount, 2u);
    EXPECT_EQ(r->arcs()[r->nodes()[0].firstArc].to, 1u);
    EXPECT_EQ(r->nodes()[3].backArcCount, 2u);
    EXPECT_EQ(r->nodes()[0].backArcCount, 0u);
    EXPECT_EQ(r->nodes()[0].triangles, b.triangles[0] + b.triangles[1]);
    EXPECT_TRUE(std::isinf(r->nodes()[3].error));
    uint64_t stored = 0;
    for (uint32_t p = 0; p < 4; ++p) {
      EXPECT_EQ(r->patches()[p].offset % r->header().payloadAlignment, 0u);
      EXPECT_EQ(r->readPayload(p), b.payloads[p]);
      DecodedPatch d = r->readPatch(p);
      EXPECT_EQ(d.triangleCount(), b.triangles[p]);
      stored += d.triangleCount();
      const ArcRecord& a = r->arcs()[r->patches()[p].arc];
      bool listed = false;
      for (uint32_t k = 0; k < a.patchCount; ++k) listed |= r->patchRefs()[a.firstPatchRef + k] == p;
      EXPECT_TRUE(listed);
    }
    EXPECT_EQ(r->header().storedTriangles, stored);
  }
}

void expectOpenError(const std::string& path, const std::string& needle,
                     ErrorKind kind = ErrorKind::Corruption) {
  try {
    MtFileReader::open(path);
    FAIL() << "opened a damaged file; expected: " << needle;
  } catch (const Error& e) {
    std::string m = e.what();
    EXPECT_EQ(e.kind(), kind) << errorKindName(e.kind()) << ": " << m;
    EXPECT_EQ(m.rfind(path + ": ", 0), 0u) << m;
    EXPECT_NE(m.find(needle), std::string::npos) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << "one line: " << m;
  }
}

TEST(MtFile, CorruptedPayloadNamesThePatch) {
  test::TempDir dir;
  Built b = writeSmall(dir.file("c.mt"), Codec::Meshopt);
  std::string bytes = test::readFile(b.path);
  uint64_t off;
  {
    auto r = MtFileReader::open(b.path);
    off = r->patches()[2].offset + r->patches()[2].size / 2;
  }
  bytes[off] ^= 0x01;
  test::writeFile(b.path, bytes);
  auto r = MtFileReader::open(b.path);  // the index is intact: open succeeds
  EXPECT_NO_THROW(r->readPatch(1));
  try {
    r->readPatch(2);
    FAIL();
  } catch (const Error& e) {
    std::string m = e.what();
    EXPECT_EQ(e.kind(), ErrorKind::Corruption) << m;
    EXPECT_NE(m.find(b.path + ": patch 2 is damaged"), std::string::npos) << m;
    EXPECT_NE(m.find("byte offset"), std::string::npos) << m;
  }
}

TEST(MtFile, TruncatedBadMagicBadFooterBadIndex) {
  test::TempDir dir;
  Built b = writeSmall(dir.file("d.mt"), Codec::Draco);
  const std::string good = test::readFile(b.path);

  test::writeFile(b.path, good.substr(0, good.size() - 5));
  expectOpenError(b.path, "footer");
  test::writeFile(b.path, good.substr(0, 100));
  expectOpenError(b.path, "shorter than header", ErrorKind::InvalidInput);
  test::writeFile(b.path, "");
  expectOpenError(b.path, "shorter than header", ErrorKind::InvalidInput);

  std::string bad = good;
  bad[0] = 'X';
  test::writeFile(b.path, bad);
  expectOpenError(b.path, "bad magic", ErrorKind::InvalidInput);  // not one of our files

  bad = good;
  bad[bad.size() - 3] ^= 0x20;
  test::writeFile(b.path, bad);
  expectOpenError(b.path, "footer magic");

  bad = good;  // a bit flip in the DAG
  bad[good.size() - kFooterSize - 40] ^= 0x10;
  test::writeFile(b.path, bad);
  expectOpenError(b.path, "checksum mismatch");

  bad = good;  // a bit flip in the header (grid step)
  bad[offsetof(FileHeader, gridStep)] ^= 0x10;
  test::writeFile(b.path, bad);
  expectOpenError(b.path, "checksum mismatch");

  bad = good;  // version
  bad[8] = 99;
  test::writeFile(b.path, bad);
  expectOpenError(b.path, "unsupported MT version", ErrorKind::InvalidInput);

  expectOpenError(dir.file("missing.mt"), "cannot open", ErrorKind::Io);

  // Truncating in the middle of the payloads shifts the footer: detected, never a crash.
  for (size_t cut = kHeaderSize; cut < good.size(); cut += 97) {
    test::writeFile(b.path, good.substr(0, cut));
    EXPECT_THROW(MtFileReader::open(b.path), Error) << "cut " << cut;
  }
}

TEST(MtFile, AbandonedWriterLeavesNothing) {
  test::TempDir dir;
  std::string path = dir.file("x.mt");
  {
    FileHeader h{};
    h.codec = uint32_t(Codec::Meshopt);
    MtFileWriter w(path, h);
    uint8_t junk[100] = {};
    w.appendPatch(junk, sizeof junk, 0, 0);
    EXPECT_TRUE(test::fileExists(path + ".tmp"));
  }  // destroyed without finish(): a crash or an error in the builder
  EXPECT_FALSE(test::fileExists(path));
  EXPECT_FALSE(test::fileExists(path + ".tmp"));

  FileHeader h{};
  MtFileWriter w(path, h);
  uint8_t junk[10] = {};
  w.appendPatch(junk, sizeof junk, 1, 3);
  EXPECT_THROW(w.finish(std::vector<NodeRecord>(2), {}), Error) << "patch on no arc";
  EXPECT_FALSE(test::fileExists(path));
}

// Every write, fsync and rename of a build, failed in turn: each failure is an Io error naming
// the file, and leaves no file under the final name and no temporary file beside it.
TEST(MtFile, FailingWriteSyncOrRenameLeavesNothing) {
  test::TempDir dir;
  const std::string path = dir.file("x.mt");
  FaultInjectionEnv counting(Env::Default());
  writeSmall(path, Codec::Meshopt, &counting);
  const std::string good = test::readFile(path);
  ASSERT_GE(counting.writes, 2);  // payloads are buffered: the payload block, then the header
  ASSERT_EQ(counting.syncs, 1);
  ASSERT_EQ(counting.renames, 1);
  const std::pair<FaultInjectionEnv::Op, int64_t> ops[] = {{FaultInjectionEnv::Op::Write, counting.writes},
                                                           {FaultInjectionEnv::Op::Sync, counting.syncs},
                                                           {FaultInjectionEnv::Op::Rename, counting.renames}};
  for (auto [op, count] : ops)
    for (int64_t n = 1; n <= count; ++n) {
      std::remove(path.c_str());
      FaultInjectionEnv env(Env::Default());
      env.failAfter(op, n);
      try {
        writeSmall(path, Codec::Meshopt, &env);
        ADD_FAILURE() << "no error at op " << int(op) << " call " << n;
      } catch (const Error& e) {
        EXPECT_EQ(e.kind(), ErrorKind::Io) << e.what();
        EXPECT_EQ(std::string(e.what()).rfind(path, 0), 0u) << "names the file: " << e.what();
        EXPECT_NE(std::string(e.what()).find("injected"), std::string::npos) << e.what();
      }
      EXPECT_TRUE(env.fired());
      EXPECT_FALSE(test::fileExists(path)) << "op " << int(op) << " call " << n;
      EXPECT_TRUE(Env::Default()->listDir(dir.path()).empty()) << "a temporary file is left, op " << int(op) << " call " << n;
    }
  // Unarmed, the Env changes nothing: the same bytes as the default Env.
  writeSmall(dir.file("plain.mt"), Codec::Meshopt);
  EXPECT_EQ(test::readFile(dir.file("plain.mt")), good);
}

// A failing read is an Io error naming the file and the byte offset, in open() and in readPayload().
TEST(MtFile, FailingReadNamesTheOffset) {
  test::TempDir dir;
  Built b = writeSmall(dir.file("x.mt"), Codec::Meshopt);
  FaultInjectionEnv counting(Env::Default());
  auto r = MtFileReader::open(b.path, &counting);
  const int64_t openReads = counting.reads;
  // The header, the footer, then each section of the index straight into its array.
  const FileHeader& h = r->header();
  std::vector<std::string> offsets = {"at byte offset 0", "at byte offset " + std::to_string(r->fileSize() - kFooterSize)};
  for (uint64_t at : {h.nodesOffset, h.arcsOffset, h.backArcsOffset, h.patchRefsOffset, h.patchesOffset})
    offsets.push_back("at byte offset " + std::to_string(at));
  ASSERT_EQ(openReads, int64_t(offsets.size())) << "header, footer, nodes, arcs, backward stars, patch references, patch index";
  EXPECT_EQ(offsets[2], "at byte offset " + std::to_string(h.metaOffset)) << "the index starts with the nodes";
  for (int64_t n = 1; n <= openReads; ++n) {
    FaultInjectionEnv env(Env::Default());
    env.failAfter(FaultInjectionEnv::Op::Read, n);
    try {
      MtFileReader::open(b.path, &env);
      ADD_FAILURE() << "read " << n << " did not fail";
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::Io) << e.what();
      EXPECT_EQ(std::string(e.what()), b.path + ": injected read failure " + offsets[n - 1]);
    }
  }
  counting.failAfter(FaultInjectionEnv::Op::Read, 1);
  try {
    r->readPayload(2);
    ADD_FAILURE() << "readPayload did not fail";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Io) << e.what();
    EXPECT_EQ(std::string(e.what()), b.path + ": injected read failure at byte offset " + std::to_string(r->patches()[2].offset));
  }
  EXPECT_EQ(r->readPayload(2), b.payloads[2]) << "the next read succeeds";
}

// The VmFlags of the mapping of this process that holds address `a` (/proc/self/smaps), or "".
std::string vmFlagsAt(uintptr_t a) {
  std::ifstream smaps("/proc/self/smaps");
  std::string line;
  bool inside = false;
  while (std::getline(smaps, line)) {
    unsigned long lo = 0, hi = 0;
    if (std::sscanf(line.c_str(), "%lx-%lx ", &lo, &hi) == 2 && line.find(':') > line.find(' ')) {
      inside = a >= lo && a < hi;
    } else if (inside && line.rfind("VmFlags:", 0) == 0) {
      return line + " ";
    }
  }
  return "";
}

// adviseHugePages: the 2 MiB-aligned interior of a large array is marked for huge pages (the
// "hg" flag of its mapping) unless the kernel has none or MT_NO_HUGEPAGES=1 says no; nothing
// below 4 MiB; and it is advice only: whatever the buffer holds before and whatever is written
// after stays, for any start (aligned or not) and size.
TEST(MtFile, HugePageAdviceMarksLargeArraysAndKeepsEveryByte) {
  std::ifstream thp("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string modes;
  const char* no = std::getenv("MT_NO_HUGEPAGES");
  const bool expectAdvice = std::getline(thp, modes) && modes.find("[never]") == std::string::npos &&
                            !(no && std::string(no) == "1");
  std::vector<uint64_t> big(3 * 1024 * 1024 + 7);  // ~24 MiB: several 2 MiB pages inside
  for (size_t i = 0; i < big.size(); ++i) big[i] = i * 0x9E3779B97F4A7C15ull;
  const std::vector<uint64_t> copy = big;
  adviseHugePages(reinterpret_cast<char*>(big.data()) + 3, big.size() * 8 - 3);  // unaligned
  adviseHugePages(big.data(), 4096);                                              // below the floor
  adviseHugePages(nullptr, uint64_t(1) << 30);
  EXPECT_TRUE(big == copy) << "the advice changed the array's bytes";
  std::vector<uint32_t> small(512 * 1024), fresh;  // 2 MiB: below the floor
  adviseHugePages(small.data(), small.size() * 4);
  fresh.reserve(5 * 1024 * 1024);
  adviseHugePages(fresh.data(), fresh.capacity() * 4);  // the reader's use: before the first touch
  const uintptr_t huge = uintptr_t(2) << 20;
  const uintptr_t inside = (reinterpret_cast<uintptr_t>(fresh.data()) + huge - 1) & ~(huge - 1);
  const uintptr_t bigInside = (reinterpret_cast<uintptr_t>(big.data()) + huge - 1) & ~(huge - 1);
  if (expectAdvice) {
    EXPECT_NE(vmFlagsAt(inside).find(" hg "), std::string::npos) << vmFlagsAt(inside);
    EXPECT_NE(vmFlagsAt(bigInside).find(" hg "), std::string::npos) << vmFlagsAt(bigInside);
  }
  // A 2 MiB array is left alone: the mapping that holds it is not advised by this call (glibc's
  // own hugetlb tunable, when set, may have advised it already; nothing to check then).
  const char* tunables = std::getenv("GLIBC_TUNABLES");
  if (!(tunables && std::strstr(tunables, "hugetlb"))) {
    EXPECT_EQ(vmFlagsAt(reinterpret_cast<uintptr_t>(small.data())).find(" hg "), std::string::npos);
  }
  fresh.resize(fresh.capacity());
  EXPECT_TRUE(std::all_of(fresh.begin(), fresh.end(), [](uint32_t v) { return v == 0; }));
  for (size_t i = 0; i < fresh.size(); ++i) fresh[i] = uint32_t(i ^ 0x5a5a5a5au);
  size_t wrong = 0;
  for (size_t i = 0; i < fresh.size(); ++i) wrong += fresh[i] != uint32_t(i ^ 0x5a5a5a5au);
  EXPECT_EQ(wrong, 0u);
}

// readRanges (the reader's index read): a large read in 1 MiB chunks by several threads gives
// the bytes one read per range gives, and a failing chunk's error is thrown, naming its offset.
TEST(MtFile, RangesReadInParallelChunksGiveTheSameBytes) {
  test::TempDir dir;
  const std::string path = dir.file("r.bin");
  std::string bytes(5 * 1024 * 1024 + 12345, '\0');
  uint64_t x = 88172645463325252ull;
  for (char& c : bytes) x ^= x << 13, x ^= x >> 7, x ^= x << 17, c = char(x);
  test::writeFile(path, bytes);
  // Three ranges out of file order, none a whole number of chunks, one empty.
  const std::vector<std::pair<uint64_t, size_t>> spans = {{2900000, 2345678}, {17, 2999983}, {5000, 0}};
  for (uint64_t parallelFrom : {uint64_t(0), uint64_t(1) << 40}) {
    std::vector<std::string> out;
    std::vector<FileRange> ranges;
    for (const auto& [offset, size] : spans) out.emplace_back(size, '\0');
    for (size_t i = 0; i < spans.size(); ++i) ranges.push_back({spans[i].first, spans[i].second, out[i].data()});
    FaultInjectionEnv counting(Env::Default());
    auto counted = counting.newRandomAccessFile(path);
    readRanges(*counted, ranges, parallelFrom);
    for (size_t i = 0; i < spans.size(); ++i)
      EXPECT_EQ(out[i], bytes.substr(size_t(spans[i].first), spans[i].second)) << "range " << i << " parallelFrom " << parallelFrom;
    EXPECT_EQ(counting.reads, parallelFrom ? 2 : 6) << "one read per non-empty range, or one per MiB chunk";
  }
  // Each read in turn (the 1st to the 6th) fails: an Io error naming a chunk's start.
  for (int64_t n = 1; n <= 6; ++n) {
    FaultInjectionEnv env(Env::Default());
    env.failAfter(FaultInjectionEnv::Op::Read, n);
    auto f = env.newRandomAccessFile(path);
    std::string a(2345678, '\0'), b(2999983, '\0');
    std::vector<FileRange> ranges = {{2900000, a.size(), a.data()}, {17, b.size(), b.data()}};
    try {
      readRanges(*f, ranges, 0);
      ADD_FAILURE() << "read " << n << " did not fail";
    } catch (const Error& e) {
      EXPECT_EQ(e.kind(), ErrorKind::Io) << e.what();
      const std::string what = e.what();
      const std::string prefix = path + ": injected read failure at byte offset ";
      ASSERT_EQ(what.compare(0, prefix.size(), prefix), 0) << what;
      const std::set<std::string> chunkStarts = {"17", "1048593", "2097169", "2900000", "3948576", "4997152"};
      EXPECT_EQ(chunkStarts.count(what.substr(prefix.size())), 1u) << what;
    }
  }
  // Two chunks fail: the one first in the file is named, whatever the threads' timing, on both paths.
  struct FailsAt : RandomAccessFile {
    const RandomAccessFile& base;
    std::set<uint64_t> bad;
    FailsAt(const RandomAccessFile& b, std::set<uint64_t> at) : base(b), bad(std::move(at)) {}
    void read(uint64_t offset, size_t size, void* out) const override {
      if (bad.count(offset)) throw Error("failed at byte offset " + std::to_string(offset), ErrorKind::Io);
      base.read(offset, size, out);
    }
    uint64_t size() const override { return base.size(); }
  };
  auto plain = Env::Default()->newRandomAccessFile(path);
  for (uint64_t parallelFrom : {uint64_t(0), uint64_t(1) << 40})
    for (int round = 0; round < 20; ++round) {
      std::string a(2345678, '\0'), b(2999983, '\0');
      std::vector<FileRange> ranges = {{2900000, a.size(), a.data()}, {17, b.size(), b.data()}};
      const FailsAt file(*plain, parallelFrom ? std::set<uint64_t>{2900000, 17} : std::set<uint64_t>{1048593, 3948576});
      try {
        readRanges(file, ranges, parallelFrom);
        ADD_FAILURE() << "no failure";
      } catch (const Error& e) {
        EXPECT_EQ(std::string(e.what()), parallelFrom ? "failed at byte offset 17" : "failed at byte offset 1048593") << "round " << round;
      }
    }
}

// The resume constructor continues the temporary file at the checkpoint's length: bytes written
// after it are cut off, and a file missing or shorter than the checkpoint is refused and kept.
TEST(MtFile, ResumedWriterContinuesAtTheCheckpoint) {
  test::TempDir dir;
  const std::string path = dir.file("r.mt"), tmp = dir.file("r.mt.partial");
  Built whole = writeSmall(dir.file("whole.mt"), Codec::Meshopt);
  auto ref = MtFileReader::open(whole.path);
  FileHeader h = ref->header();
  uint64_t length = 0;
  std::vector<PatchRecord> records;
  {
    MtFileWriter w(path, h, tmp);
    for (int i = 0; i < 2; ++i) w.appendPatch(whole.payloads[i].data(), whole.payloads[i].size(), whole.triangles[i], 0);
    w.syncPayloads();
    length = w.bytesWritten();
    records = w.patchRecords();
    w.appendPatch(whole.payloads[3].data(), whole.payloads[3].size(), whole.triangles[3], 0);  // not checkpointed
    w.detach();
  }
  ASSERT_TRUE(test::fileExists(tmp)) << "detach keeps the file";
  ASSERT_GT(Env::Default()->fileSize(tmp), length);
  EXPECT_THROW(MtFileWriter(path, h, length + 1 + Env::Default()->fileSize(tmp), records, tmp), Error);
  EXPECT_TRUE(test::fileExists(tmp)) << "a refused resume keeps the killed build's file";
  try {
    MtFileWriter(path, h, 0, {}, dir.file("missing.partial"));
    ADD_FAILURE() << "resumed a missing file";
  } catch (const Error& e) {
    EXPECT_EQ(e.kind(), ErrorKind::Io) << e.what();
  }
  MtFileWriter w(path, h, length, records, tmp);
  EXPECT_EQ(w.bytesWritten(), length);
  EXPECT_EQ(Env::Default()->fileSize(tmp), length) << "cut back to the checkpoint";
  for (int i = 2; i < 4; ++i) w.appendPatch(whole.payloads[i].data(), whole.payloads[i].size(), whole.triangles[i], 0);
  std::vector<NodeRecord> nodes(ref->nodes());
  std::vector<DagArc> arcs = {{2, 3, {3}}, {0, 1, {0}}, {0, 2, {1}}, {1, 3, {2}}};
  w.finish(nodes, arcs);
  EXPECT_FALSE(test::fileExists(tmp));
  auto r = MtFileReader::open(path);
  ASSERT_EQ(r->patches().size(), 4u);
  for (uint32_t i = 0; i < 4; ++i) EXPECT_EQ(r->readPayload(i), whole.payloads[i]) << "patch " << i;
}

}  // namespace
