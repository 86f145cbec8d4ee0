// The memory plan (base/memory_plan.h): the shares of every stage fit in the cap, grow with it,
// keep their floors; ingest stays within it on both paths and gives the same store either way;
// mtbuild's stats JSON prints the plan it ran with.
#include <gtest/gtest.h>

#include <fstream>
#include <string>

#include "base/memory_plan.h"
#include "tests/test_support.h"

namespace mt::test {
namespace {

constexpr uint64_t kMiB = 1ull << 20;

// The fixed shares, by name, so that every test checks all of them.
std::vector<std::pair<const char*, uint64_t>> shares(const MemoryPlan& p) {
  return {{"levelLoop", p.levelLoop},
          {"healSorter", p.healSorter},
          {"gridWeld", p.gridWeld},
          {"assigner", p.assigner},
          {"soupWeldSorter", p.soupWeldSorter},
          {"boundarySorter", p.boundarySorter},
          {"chunkedPositions", p.chunkedPositions},
          {"chunkedSorter", p.chunkedSorter},
          {"chunkedBuckets", p.chunkedBuckets},
          {"chunkedSharedSorter", p.chunkedSharedSorter},
          {"chunkedEdgeSorter", p.chunkedEdgeSorter},
          {"residentReserve", p.residentReserve},
          {"residentSorter", p.residentSorter(0, 48 * kMiB)},
          {"residentSharedSorter", p.residentSharedSorter(0)},
          {"residentEdgeSorter", p.residentEdgeSorter(0)}};
}

const uint64_t kTotals[] = {kMinPlanBytes, 24 * kMiB, 64 * kMiB, 200 * kMiB, 256 * kMiB, 512 * kMiB, 1ull << 30,
                            3ull << 30,    16ull << 30, 1ull << 40};

TEST(MemoryPlan, SharesAliveTogetherFitInTheCap) {
  for (uint64_t total : kTotals)
    for (unsigned threads : {1u, 2u, 8u, 64u}) {
      const MemoryPlan p = planMemory(total, threads);
      EXPECT_EQ(p.total, total);
      const auto phases = p.phases();
      EXPECT_GE(phases.size(), 8u);
      for (const auto& [name, bytes] : phases) {
        EXPECT_GT(bytes, 0u) << name << " at " << total;
        EXPECT_LE(bytes, total) << name << " at " << total << " bytes, " << threads << " threads";
      }
    }
}

TEST(MemoryPlan, EverySharePositiveAndMonotoneInTheCap) {
  for (unsigned threads : {1u, 2u, 16u}) {
    MemoryPlan last = planMemory(1 * kMiB, threads);
    for (uint64_t total = 1 * kMiB; total <= (64ull << 30); total = total * 5 / 4 + 12345) {
      const MemoryPlan p = planMemory(total, threads);
      const auto now = shares(p), before = shares(last);
      for (size_t i = 0; i < now.size(); ++i) {
        EXPECT_GT(now[i].second, 0u) << now[i].first << " at " << total;
        EXPECT_GE(now[i].second, before[i].second) << now[i].first << " shrank at " << total;
      }
      EXPECT_GE(p.residentRecordLimit(12), last.residentRecordLimit(12)) << total;
      EXPECT_GE(p.levelLoop, p.total / 4) << "the level loop is the build's largest stage";
      last = p;
    }
  }
}

TEST(MemoryPlan, FloorsAndTheResidentRule) {
  const MemoryPlan tiny = planMemory(1 * kMiB, 2);
  EXPECT_GE(tiny.chunkedEdgeSorter, 1 * kMiB) << "a sorter never gets less than 1 MiB";
  EXPECT_GE(tiny.levelLoop, 8 * kMiB);
  EXPECT_EQ(tiny.residentRecordLimit(12), 0u) << "below the reserve: the chunked path";
  // The grid weld's sorter keeps its 16 MiB floor (a heal pass sorts with half its heal cap).
  EXPECT_EQ(planMemory(planMemory(16 * kMiB, 2).gridWeld, 1).healSorter, 16 * kMiB);
  EXPECT_EQ(planMemory(4ull << 30, 2).healSorter, 2ull << 30);
  // Resident: the records, a state byte and the thread bits fit under the cap less the reserve.
  for (uint64_t total : kTotals)
    for (unsigned threads : {2u, 8u}) {
      const MemoryPlan p = planMemory(total, threads);
      for (uint64_t record : {12u, 24u, 40u}) {
        const double vertices = double(p.residentRecordLimit(record)) / double(record);
        EXPECT_LE(vertices * (double(record) + 1 + threads / 8.0), double(total - std::min(total, p.residentReserve)) + 1)
            << total << " " << record;
      }
      // More resident means less for the passes' sorters, never less than the floor.
      EXPECT_GE(p.residentSorter(0, 0), p.residentSorter(total / 2, 0));
      EXPECT_GE(p.residentSorter(total, total), 8 * kMiB * 4 / 5);
    }
  // More threads: more bits a vertex, so fewer records.
  EXPECT_GT(planMemory(1ull << 30, 2).residentRecordLimit(12), planMemory(1ull << 30, 64).residentRecordLimit(12));
}

// Stages that run beside data resident from stage to stage (the V-partition, the store's patch
// records) plan with what the cap leaves: their phases fit in total - resident, shrink as the
// resident part grows, and keep their floors when it reaches the cap.
TEST(MemoryPlan, StagesBesideResidentDataPlanWithWhatTheCapLeaves) {
  for (uint64_t total : kTotals)
    for (unsigned threads : {1u, 2u, 8u}) {
      const MemoryPlan p = planMemory(total, threads);
      uint64_t lastSorter = UINT64_MAX, lastBoundary = UINT64_MAX;
      for (uint64_t resident : {uint64_t(0), total / 8, total / 4, total / 2, total - total / 8, total, 2 * total}) {
        const MemoryPlan b = p.besides(resident);
        EXPECT_EQ(b.threads, p.threads);
        const uint64_t left = std::max(total > resident ? total - resident : 0, kMinPlanBytes / 2);
        EXPECT_EQ(b.total, left) << total << " " << resident;
        for (const auto& [name, bytes] : b.phases())
          if (std::string(name).rfind("ingest_chunked", 0) == 0 || name == "ingest_boundary") {
            EXPECT_LE(bytes, std::max(left, kMinPlanBytes)) << name << " at " << total << " beside " << resident;
          }
        EXPECT_LE(b.chunkedSorter, lastSorter) << "more resident, less for the sorters";
        EXPECT_LE(b.chunkedSorter, p.chunkedSorter);
        lastSorter = b.chunkedSorter;
        const uint64_t entries = p.boundarySorterBesides(resident);
        EXPECT_LE(entries, std::max<uint64_t>(p.boundarySorter, 1 * kMiB));
        EXPECT_GE(entries, 1 * kMiB) << "the sorter's floor";
        if (total > resident + 2 * kMiB) {
          EXPECT_LE(entries, (total - resident) / 2);
        }
        EXPECT_LE(entries, lastBoundary);
        lastBoundary = entries;
      }
      EXPECT_EQ(p.besides(0).chunkedSorter, p.chunkedSorter) << "nothing resident: the whole-cap rule";
    }
}

TEST(MemoryPlan, DescribeAndJsonNameEveryShare) {
  const MemoryPlan p = planMemory(512 * kMiB, 2);
  const std::string text = describe(p), json = toJson(p);
  EXPECT_NE(text.find("512.0 MiB"), std::string::npos) << text;
  EXPECT_NE(text.find("level loop"), std::string::npos) << text;
  EXPECT_NE(json.find("\"total\": " + std::to_string(512 * kMiB)), std::string::npos) << json;
  EXPECT_NE(json.find("\"level_loop\": " + std::to_string(p.levelLoop)), std::string::npos) << json;
  for (const auto& [name, bytes] : p.phases())
    EXPECT_NE(json.find("\"" + name + "\": " + std::to_string(bytes)), std::string::npos) << name << " " << json;
}

// The first number after `"key": ` in `json` ("" when absent).
std::string member(const std::string& json, const std::string& key) {
  const std::string tag = "\"" + key + "\": ";
  const size_t at = json.find(tag);
  if (at == std::string::npos) return "";
  const size_t from = at + tag.size();
  return json.substr(from, json.find_first_not_of("0123456789", from) - from);
}

TEST(MemoryPlan, StatsJsonCarriesThePlanTheBuildRanWith) {
  TempDir tmp;
  const std::string in = tmp.file("scan.ply");
  ASSERT_EQ(runTool("mtgen", "-o " + in + " --triangles 20k --seed 3").exitCode, 0);
  for (const char* cap : {"24M", "300M"}) {
    const std::string json = tmp.file(std::string("stats") + cap + ".json");
    CommandResult r = runTool("mtbuild", in + " -o " + tmp.file("out.mt") + " -q --threads 2 --memory " + cap + " --stats-json " + json);
    ASSERT_EQ(r.exitCode, 0) << r.output;
    const std::string stats = readFile(json);
    const MemoryPlan p = planMemory(std::string(cap) == "24M" ? 24 * kMiB : 300 * kMiB, 2);
    ASSERT_NE(stats.find("\"memory_plan\": {"), std::string::npos) << stats;
    EXPECT_EQ(member(stats, "total"), std::to_string(p.total)) << stats;
    EXPECT_EQ(member(stats, "threads"), "2") << stats;
    EXPECT_EQ(member(stats, "level_loop"), std::to_string(p.levelLoop)) << stats;
    EXPECT_EQ(member(stats, "grid_weld"), std::to_string(p.gridWeld)) << stats;
    EXPECT_EQ(member(stats, "chunked_sorter"), std::to_string(p.chunkedSorter)) << stats;
  }
}

// Both ingest paths (a cap below the resident reserve forces the chunked one) give the same
// segment bytes.
TEST(MemoryPlan, BothIngestPathsGiveTheSameStore) {
  TempDir tmp;
  const std::string in = tmp.file("scan.ply");
  ASSERT_EQ(runTool("mtgen", "-o " + in + " --triangles 60k --holes 5 --shuffle --seed 9").exitCode, 0);
  std::string segments[2];
  const char* caps[2] = {"32M", "512M"};
  for (int i = 0; i < 2; ++i) {
    const std::string store = tmp.file(std::string("s") + caps[i]);
    CommandResult r = runTool("mtstore", "ingest " + in + " -o " + store + " --quiet --memory " + caps[i]);
    ASSERT_EQ(r.exitCode, 0) << r.output;
    segments[i] = readFile(store + "/SEG-000001.dat");
  }
  EXPECT_GT(segments[0].size(), 100000u);
  EXPECT_TRUE(segments[0] == segments[1]) << "the chunked (32M) and resident (512M) paths differ";
}

// reexecWithMallocHugePages (mtbuild, mtverify, mtextract and mtrender call it first): the process
// it ends in has glibc.malloc.hugetlb=1 appended to the user's own tunables, the same arguments
// and MT_HUGEPAGES_REEXEC=1, or, when the user chose (MT_NO_HUGEPAGES=1, a hugetlb tunable of
// their own) or the kernel has no huge pages, is the process it started in, with the
// environment as it was.
TEST(MemoryPlan, HugePageReexecKeepsTheUsersChoiceAndTheArguments) {
  std::ifstream thp("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string modes;
  const bool kernelHasThem = std::getline(thp, modes) && modes.find("[never]") == std::string::npos;
  const std::string clean = "env -u GLIBC_TUNABLES -u MT_NO_HUGEPAGES -u MT_HUGEPAGES_REEXEC ";
  const std::string probe = binDir() + "/reexec_probe 'two words' --x 7";
  auto run = [&](const std::string& env) {
    CommandResult r = runShell(clean + env + " " + probe);
    EXPECT_EQ(r.exitCode, 0) << r.output;
    EXPECT_NE(r.output.find("\nargs=two words --x 7\n"), std::string::npos) << r.output;
    return r.output;
  };
  std::string out = run("");
  if (kernelHasThem) {
    EXPECT_NE(out.find("tunables=glibc.malloc.hugetlb=1\nreexec=1\n"), std::string::npos) << out;
  } else {
    EXPECT_NE(out.find("tunables=(unset)\nreexec=(unset)\n"), std::string::npos) << out;
  }
  out = run("GLIBC_TUNABLES=glibc.malloc.arena_max=2");
  if (kernelHasThem) {
    EXPECT_NE(out.find("tunables=glibc.malloc.arena_max=2:glibc.malloc.hugetlb=1\nreexec=1\n"), std::string::npos) << out;
  }
  out = run("GLIBC_TUNABLES=glibc.malloc.hugetlb=0");
  EXPECT_NE(out.find("tunables=glibc.malloc.hugetlb=0\nreexec=(unset)\n"), std::string::npos) << out;
  out = run("MT_NO_HUGEPAGES=1");
  EXPECT_NE(out.find("tunables=(unset)\nreexec=(unset)\n"), std::string::npos) << out;
}

}  // namespace
}  // namespace mt::test
