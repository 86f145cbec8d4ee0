// The doors between the rooms, checked on the binaries: the readers of MT files (mtinfo,
// mtverify, mtextract, mtrender) carry nothing of the patch store or the V-partitions, so the
// file format stays readable without the build side (and the coming web and export code can
// rely on the same). A symbol of either in their binaries means a link the design does not allow.
#include <gtest/gtest.h>

#include <string>

#include "tests/test_support.h"

namespace mt::test {
namespace {

TEST(Doors, MtFileReadersLinkNeitherThePatchStoreNorThePartitions) {
  ASSERT_EQ(runShell("command -v nm").exitCode, 0) << "nm (binutils) is needed for this check";
  for (const std::string tool : {"mtinfo", "mtverify", "mtextract", "mtexport", "mtrender"}) {
    const std::string bin = binDir() + "/" + tool;
    CommandResult all = runShell("nm -C " + bin + " | wc -l");
    ASSERT_EQ(all.exitCode, 0) << all.output;
    ASSERT_GT(std::stoul(all.output), 100u) << tool << ": no symbols to check";
    CommandResult r = runShell("nm -C " + bin + " | grep -E ' mt::(PatchStore|vp::|heal::|VPartition|PartitionSequence)' | head -5");
    EXPECT_EQ(r.output, "") << tool << " links the patch store or the partitions:\n" << r.output;
  }
  // The check can fail: the builder does carry the store.
  CommandResult b = runShell("nm -C " + binDir() + "/mtbuild | grep -c ' mt::PatchStore'");
  EXPECT_NE(b.output, "0\n") << b.output;
}

// testing/ (generators and test surfaces) is linked by mtgen, the tests and the benchmarks only:
// no production binary carries a symbol of it.
TEST(Doors, ProductionBinariesCarryNothingOfTesting) {
  ASSERT_EQ(runShell("command -v nm").exitCode, 0) << "nm (binutils) is needed for this check";
  const std::string pattern = "' (mtgen::ScanGenerator|mt::makeScanGrid|mt::test::)'";
  for (const std::string tool : {"mtinfo", "mtverify", "mtextract", "mtexport", "mtrender", "mtbuild", "mtstore"}) {
    CommandResult r = runShell("nm -C " + binDir() + "/" + tool + " | grep -E " + pattern + " | head -5");
    EXPECT_EQ(r.exitCode, 0) << r.output;
    EXPECT_EQ(r.output, "") << tool << " links testing/:\n" << r.output;
  }
  // The check can fail: mtgen does carry the generator.
  CommandResult g = runShell("nm -C " + binDir() + "/mtgen | grep -cE " + pattern);
  EXPECT_NE(g.output, "0\n") << g.output;
}

}  // namespace
}  // namespace mt::test
