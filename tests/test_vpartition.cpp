// vpartition: regular and irregular V-partition sequences, assignment, crossing, serialization,
// determinism, shape metrics (BMT sections 3.2 and 4).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstring>
#include <map>
#include <set>
#include <thread>
#include <tuple>

#include <xxhash.h>

#include "base/error.h"
#include "base/memory_plan.h"
#include "patchstore/patch_store.h"
#include "tests/test_support.h"
#include "testing/memory_centroids.h"
#include "vpartition/level.h"
#include "vpartition/vpartition.h"

namespace mt {
namespace {

using test::MemoryCentroids;
using test::TestMesh;

struct NamedMesh {
  const char* name;
  TestMesh (*make)();
};

TestMesh meshClosed() { return test::closedBlob(110); }                  // 145k triangles
TestMesh meshHoles() { return test::holedTorus(480, 160); }              // ~140k triangles
TestMesh meshComponents() { return test::components(250); }             // ~150k triangles
TestMesh meshWarped() { return test::warpedDensity(400, 200); }           // 160k triangles

const NamedMesh kScanLike[] = {
    {"closed", meshClosed}, {"holes", meshHoles}, {"components", meshComponents},
    {"warped", meshWarped}};

uint32_t bruteNearest(const std::vector<float>& seeds, const float p[3]) {
  uint32_t best = 0;
  float bestD = INFINITY;
  for (uint32_t i = 0; i < seeds.size() / 3; ++i) {
    float dx = p[0] - seeds[3 * i], dy = p[1] - seeds[3 * i + 1], dz = p[2] - seeds[3 * i + 2];
    float d = dx * dx + dy * dy + dz * dz;
    if (d < bestD) { bestD = d; best = i; }
  }
  return best;
}

// ---- irregular: shape on scan-like meshes --------------------------------------------------

// The shape every level of a sequence keeps: each seed owns a non-empty cell, the counts are on
// target and the cells within 2x the mean where a level has cells to count, and a V(i+1) cell
// overlaps a bounded number of Vi cells (the backward star: what the DAG's fan-in follows).
void expectLevelShapes(const PartitionSequence& seq, const PartitionMetrics& m, double starMean, uint32_t starMax) {
  for (const LevelMetrics& l : m.levels) {
    SCOPED_TRACE("level " + std::to_string(l.level));
    EXPECT_EQ(l.cells, seq.cellCount(l.level));
    EXPECT_GE(l.minTriangles, 1u);
    if (l.target >= 16) {
      EXPECT_NEAR(double(l.cells) / l.target, 1.0, 0.15);
      EXPECT_LE(l.maxTriangles / l.meanTriangles, 2.0);
    }
    EXPECT_LE(l.backwardStarMean, starMean);
    EXPECT_LE(l.backwardStarMax, starMax);
  }
}

class IrregularShape : public ::testing::TestWithParam<NamedMesh> {};

TEST_P(IrregularShape, CellsUniformCountsOnTargetStarsBounded) {
  TestMesh mesh = GetParam().make();
  MemoryCentroids src(mesh);
  VPartitionOptions o;
  o.patchTriangles = 200;
  PartitionSequence seq = PartitionSequence::build(src, o);
  PartitionMetrics m = computeMetrics(seq, src);
  std::printf("[%s] %llu triangles\n%s", GetParam().name, (unsigned long long)src.count(),
              formatMetricsText(m).c_str());
  ASSERT_GE(seq.levels(), 3u);
  // Streaming: a handful of passes (area, seeding + calibration, Lloyd, recount).
  EXPECT_LE(m.build.passes, 6u);
  expectLevelShapes(seq, m, 8.0, 16);
  // Coarsest level is small; path length (levels) logarithmic in the finest cell count.
  EXPECT_LE(m.levels.back().cells, 12u);
  EXPECT_LE(double(seq.levels()), std::log2(double(m.levels[0].cells)) + 2);
  // V*0 (the patches): no empty ones by construction; their mean is near the requested size. A
  // V*0 cell is at most a whole V0 cell (when no V1 border crosses it), so its maximum is bounded
  // by the V0 maximum, i.e. by 2x the V0 mean.
  EXPECT_GE(m.levels[0].crossMin, 1u);
  EXPECT_NEAR(m.levels[0].crossMean / o.patchTriangles, 1.0, 0.25);
  EXPECT_LE(m.levels[0].crossMax, 2.0 * m.levels[0].meanTriangles);
  // The patches ingest makes (the balanced V*0 keys of the assigner): max/mean <= 2, no slivers.
  VPartitionAssigner assigner(o);
  assigner.prepare(src, 0);
  std::map<uint64_t, uint32_t> patches;
  for (size_t t = 0; t < src.count(); ++t) ++patches[assigner.cellKey(&src.data()[4 * t])];
  uint32_t maxPatch = 0, minPatch = UINT32_MAX;
  for (auto& [key, count] : patches) maxPatch = std::max(maxPatch, count), minPatch = std::min(minPatch, count);
  double mean = double(src.count()) / double(patches.size());
  std::printf("[%s] patches: %zu, triangles min %u mean %.1f max %u (max/mean %.2f)\n", GetParam().name, patches.size(),
              minPatch, mean, maxPatch, maxPatch / mean);
  EXPECT_LE(maxPatch / mean, 2.0);
  EXPECT_GE(minPatch, o.patchTriangles / 8);
}

INSTANTIATE_TEST_SUITE_P(ScanLike, IrregularShape, ::testing::ValuesIn(kScanLike),
                         [](const auto& info) { return std::string(info.param.name); });

// ---- irregular: determinism, streaming memory --------------------------------------------

TEST(Irregular, SameSeedsWhateverThreadsBatchesAndMemory) {
  TestMesh mesh = test::holedTorus(300, 100);
  MemoryCentroids a(mesh, 65536), b(mesh, 777);
  VPartitionOptions o;
  o.patchTriangles = 150;
  o.threads = 1;
  std::string one = PartitionSequence::build(a, o).serialize();
  o.threads = 3;
  std::string three = PartitionSequence::build(b, o).serialize();
  EXPECT_EQ(one, three);
  // Through the CellAssigner, with different memory shares.
  VPartitionAssigner small(o), large(o);
  small.prepare(a, 64ull << 20);
  large.prepare(b, 4ull << 30);
  EXPECT_EQ(small.serialize(), one);
  EXPECT_EQ(large.serialize(), one);
  EXPECT_FALSE(small.describe().empty());
}

TEST(Irregular, SeedMemoryDoesNotGrowWithTriangles) {
  // Same cell counts (patch size scaled with the mesh): seed memory stays the same although the
  // mesh has 4x the triangles, and the build makes a bounded number of passes.
  VPartitionOptions o;
  TestMesh small = test::holedTorus(300, 100), big = test::holedTorus(600, 200);
  MemoryCentroids s(small), b(big);
  o.patchTriangles = 100;
  PartitionSequence ss = PartitionSequence::build(s, o);
  o.patchTriangles = 400;
  PartitionSequence bs = PartitionSequence::build(b, o);
  std::printf("seed bytes: %llu (%llu tris) vs %llu (%llu tris); passes %u/%u\n",
              (unsigned long long)ss.stats().seedBytes, (unsigned long long)s.count(),
              (unsigned long long)bs.stats().seedBytes, (unsigned long long)b.count(),
              s.passes, b.passes);
  EXPECT_LT(double(bs.stats().seedBytes), 1.5 * double(ss.stats().seedBytes));
  // Seeds + grids + the density grid (bounded by its diag/256 resolution), not ~N.
  EXPECT_LT(double(bs.stats().seedBytes), 8.0 * 1048576);
  EXPECT_LE(b.passes, 6u);
  EXPECT_EQ(b.passes, bs.stats().passes);
}

TEST(Irregular, SampledInputKeepsShapeAndBalancedPatches) {
  // Above the whole-input limit (512 K triangles) the builder and the patch balancing run on a
  // stride sample from one pass; the cells and patches must still meet the same limits.
  TestMesh mesh = test::closedBlob(230);
  MemoryCentroids src(mesh);
  ASSERT_GT(src.count(), 600000u);
  VPartitionOptions o;
  o.patchTriangles = 400;
  VPartitionAssigner assigner(o);
  assigner.prepare(src, 64ull << 20);
  const PartitionSequence& seq = assigner.sequence();
  EXPECT_GT(seq.stats().sampleStride, 1u);
  EXPECT_EQ(seq.stats().passes, 1u);
  EXPECT_EQ(src.passes, 1u);  // prepare read the input once
  PartitionMetrics m = computeMetrics(seq, src);
  std::printf("%s", formatMetricsText(m).c_str());
  for (const LevelMetrics& l : m.levels) {
    SCOPED_TRACE("level " + std::to_string(l.level));
    EXPECT_EQ(l.cells, seq.cellCount(l.level));
    if (l.target >= 16) {
      EXPECT_NEAR(double(l.cells) / l.target, 1.0, 0.15);
      EXPECT_LE(l.maxTriangles / l.meanTriangles, 2.0);
    }
    EXPECT_LE(l.backwardStarMean, 8.0);
    EXPECT_LE(l.backwardStarMax, 16u);
  }
  std::map<uint64_t, uint32_t> patches;
  for (size_t t = 0; t < src.count(); ++t) ++patches[assigner.cellKey(&src.data()[4 * t])];
  uint32_t maxPatch = 0, minPatch = UINT32_MAX;
  for (auto& [key, count] : patches) maxPatch = std::max(maxPatch, count), minPatch = std::min(minPatch, count);
  double mean = double(src.count()) / double(patches.size());
  std::printf("sampled: patches %zu, min %u mean %.1f max %u\n", patches.size(), minPatch, mean, maxPatch);
  EXPECT_LE(maxPatch / mean, 2.0);
  EXPECT_GE(minPatch, o.patchTriangles / 8);
}

TEST(Irregular, TheSampleOfAnyInputFitsTheSmallestBillionCap) {
  // The sample grows with the input (a fixed number per cell) up to a ceiling that fits the
  // V-partition's share of --memory 256M beside its seeds, whatever the input's size: a billion
  // triangles at 512M asked for 315 MiB of centroids and the build was refused. The sample may
  // not depend on --memory (same bytes at every cap), so the ceiling is one constant.
  const uint64_t share = planMemory(256ull << 20, 2).assigner;
  uint64_t last = 0;
  for (uint64_t n = 1000; n <= (8ull << 30); n = n * 3 / 2 + 7) {
    const uint64_t limit = vp::sampleLimit(n, 2000);
    EXPECT_GE(limit, last) << n;
    EXPECT_LE(limit * 16, share / 2) << n << " triangles (half the share left for the seeds and tables)";
    last = limit;
  }
  // Below the ceiling the rule is unchanged (inputs up to ~203 M keep their partitions).
  EXPECT_EQ(vp::sampleLimit(200000000, 2000), uint64_t(std::ceil(128 * 200e6 / (2000 * 3.1))));
  EXPECT_LT(vp::sampleLimit(1000000000, 2000), uint64_t(std::ceil(128 * 1e9 / (2000 * 3.1))));
}

TEST(Irregular, TinyAndEmptyInputs) {
  MemoryCentroids empty;
  Box3 box;
  box.hi[0] = box.hi[1] = box.hi[2] = 1;
  empty.setBounds(box);
  PartitionSequence e = PartitionSequence::build(empty, {});
  ASSERT_EQ(e.levels(), 1u);
  float p[3] = {0.2f, 0.3f, 0.4f};
  EXPECT_EQ(e.cellOf(0, p), 0u);
  EXPECT_EQ(e.crossKey(0, p), 0u);
  // A mesh smaller than one patch: one level, one cell.
  TestMesh tiny = test::holedTorus(20, 8);
  MemoryCentroids t(tiny);
  PartitionSequence ts = PartitionSequence::build(t, {});
  EXPECT_EQ(ts.levels(), 1u);
  EXPECT_EQ(ts.cellCount(0), 1u);
  EXPECT_EQ(PartitionSequence::deserialize(ts.serialize()).serialize(), ts.serialize());
}

// ---- assignment: exact nearest, ties, thread safety, crossing keys, serialization ----------

TEST(Assign, CachedLookupIsExactNearestWithLowerIndexTies) {
  TestMesh mesh = test::warpedDensity(200, 120);
  MemoryCentroids src(mesh);
  VPartitionOptions o;
  o.patchTriangles = 60;
  PartitionSequence seq = PartitionSequence::build(src, o);
  test::Lcg rng(3);
  for (uint32_t l = 0; l < seq.levels(); ++l) {
    const std::vector<float>& seeds = seq.seeds(l);
    ASSERT_EQ(seeds.size(), 3u * seq.cellCount(l));
    for (size_t t = 0; t < src.count(); t += 7) {
      const float* c = &src.data()[4 * t];
      ASSERT_EQ(seq.cellOf(l, c), bruteNearest(seeds, c)) << "level " << l << " tri " << t;
    }
    // Points off the surface and far away.
    for (int k = 0; k < 2000; ++k) {
      float p[3] = {float(rng.next() * 30 - 10), float(rng.next() * 20 - 7),
                    float(rng.next() * 10 - 5)};
      if (k % 10 == 0) p[0] *= 1000;
      ASSERT_EQ(seq.cellOf(l, p), bruteNearest(seeds, p)) << "level " << l;
    }
  }
}

// A one-level irregular sequence with the given seeds, through the documented blob format.
PartitionSequence sequenceWithSeeds(const std::vector<float>& seeds, double cell) {
  std::string b("MTVPSEQ1", 8);
  auto put = [&](const auto& v) { b.append(reinterpret_cast<const char*>(&v), sizeof(v)); };
  put(uint32_t(1)); put(uint8_t(0)); put(uint32_t(1));
  put(uint8_t(0)); put(cell); put(uint64_t(1));
  for (int a = 0; a < 3; ++a) put(0.0);
  for (int a = 0; a < 3; ++a) put(uint32_t(1));
  put(uint8_t(0)); put(uint8_t(1)); put(uint32_t(seeds.size() / 3));
  b.append(reinterpret_cast<const char*>(seeds.data()), seeds.size() * 4);
  put(uint64_t(XXH64(b.data(), b.size(), 0)));
  return PartitionSequence::deserialize(b);
}

TEST(Assign, CoherentStreamsStayExactAcrossCellBorders) {
  // nearestCached answers points close to its last one from an anchor (a ball in which the
  // nearest seed cannot change): walks in small steps, across many Voronoi borders and query
  // cells, and every centroid in stream order, against the brute force.
  TestMesh mesh = test::warpedDensity(200, 120);
  MemoryCentroids src(mesh);
  VPartitionOptions o;
  o.patchTriangles = 60;
  PartitionSequence seq = PartitionSequence::build(src, o);
  test::Lcg rng(11);
  for (uint32_t l = 0; l < std::min(seq.levels(), 3u); ++l) {
    const std::vector<float>& seeds = seq.seeds(l);
    for (size_t t = 0; t < src.count(); ++t) {
      const float* c = &src.data()[4 * t];
      ASSERT_EQ(seq.cellOf(l, c), bruteNearest(seeds, c)) << "level " << l << " tri " << t;
    }
    const double step = seq.levelScale(l) * 0.01;
    float p[3] = {src.data()[0], src.data()[1], src.data()[2]};
    for (int k = 0; k < 100000; ++k) {
      // Jitter plus a drift along x: about 50 seed spacings over the walk.
      for (int a = 0; a < 3; ++a) p[a] = float(p[a] + step * ((rng.next() - 0.5) + (a == 0 ? 0.05 : 0)));
      ASSERT_EQ(seq.cellOf(l, p), bruteNearest(seeds, p)) << "level " << l << " step " << k;
    }
  }
}

TEST(Assign, TiesGoToTheLowerSeedIndex) {
  // Seeds 0..3 on a square around the origin, listed in a scrambled order, plus a duplicate.
  std::vector<float> seeds = {1, 0, 0, 0, 1, 0, -1, 0, 0, 0, -1, 0, 1, 0, 0, 5, 5, 5};
  for (double cell : {0.3, 1.0, 4.0}) {
    PartitionSequence seq = sequenceWithSeeds(seeds, cell);
    float origin[3] = {0, 0, 0};           // equidistant from seeds 0-4: lowest index wins
    float diag[3] = {0.5f, 0.5f, 0.2f};    // equidistant from 0 and 1
    float onDup[3] = {1.2f, 0, 0};         // seeds 0 and 4 coincide
    float farOut[3] = {-1e6f, 0, 0};       // far-away query (linear scan path)
    for (int rep = 0; rep < 2; ++rep) {    // second round hits the per-thread cache
      EXPECT_EQ(seq.cellOf(0, origin), 0u);
      EXPECT_EQ(seq.cellOf(0, diag), 0u);
      EXPECT_EQ(seq.cellOf(0, onDup), 0u);
      EXPECT_EQ(seq.cellOf(0, farOut), 2u);
    }
  }
}

TEST(Assign, ThreadsAgreeAndCrossKeyPacksLevels) {
  TestMesh mesh = test::closedBlob(60);
  MemoryCentroids src(mesh);
  VPartitionOptions o;
  o.patchTriangles = 100;
  PartitionSequence seq = PartitionSequence::build(src, o);
  ASSERT_GE(seq.levels(), 2u);
  const size_t n = src.count();
  std::vector<uint64_t> ref(n);
  for (size_t t = 0; t < n; ++t) ref[t] = seq.crossKey(0, &src.data()[4 * t]);
  std::vector<std::vector<uint64_t>> got(4, std::vector<uint64_t>(n));
  std::vector<std::thread> pool;
  for (int k = 0; k < 4; ++k)
    pool.emplace_back([&, k] {
      // Different visiting orders exercise different cache states.
      for (size_t i = 0; i < n; ++i) {
        size_t t = k == 0 ? n - 1 - i : (i * 7919 + k * 977) % n;  // 7919: prime, coprime to n
        got[k][t] = seq.crossKey(0, &src.data()[4 * t]);
      }
    });
  for (auto& th : pool) th.join();
  for (int k = 0; k < 4; ++k) EXPECT_EQ(got[k], ref);
  const float* c = &src.data()[0];
  EXPECT_EQ(seq.crossKey(0, c), (uint64_t(seq.cellOf(0, c)) << 32) | seq.cellOf(1, c));
  uint32_t last = seq.levels() - 1;
  EXPECT_EQ(seq.crossKey(last, c), uint64_t(seq.cellOf(last, c)) << 32);
  // The ingest assigner returns the V*0 key, balanced: same V0 cell (below the slab bits), and
  // the same V1 cell unless the piece was a merged sliver.
  VPartitionAssigner assigner(o);
  assigner.prepare(src, 0);
  size_t sameRegion = 0;
  for (size_t t = 0; t < n; ++t) {
    uint64_t key = assigner.cellKey(&src.data()[4 * t]);
    EXPECT_EQ(PartitionSequence::crossHigh(key) & 0xFFFFFFu, PartitionSequence::crossHigh(ref[t]));
    sameRegion += PartitionSequence::crossLow(key) == PartitionSequence::crossLow(ref[t]);
  }
  EXPECT_GT(sameRegion, n * 9 / 10);
}

TEST(Assign, SameCellsWithOrWithoutPrecomputedTables) {
  TestMesh mesh = test::components(150);
  MemoryCentroids src(mesh);
  VPartitionOptions o;
  o.patchTriangles = 120;
  PartitionSequence with = PartitionSequence::build(src, o);
  o.lookupTableBytes = 0;
  PartitionSequence without = PartitionSequence::build(src, o);
  EXPECT_EQ(with.serialize(), without.serialize());
  EXPECT_LT(without.memoryBytes(), with.memoryBytes());
  for (uint32_t l = 0; l < with.levels(); ++l)
    for (size_t i = 0; i < src.count(); ++i) {
      size_t t = (i * 7919) % src.count();
      if (src.count() % 7919 == 0) t = i;
      ASSERT_EQ(with.cellOf(l, &src.data()[4 * t]), without.cellOf(l, &src.data()[4 * t]));
    }
}

TEST(Assign, SerializeRoundTripAndCorruption) {
  TestMesh mesh = test::components(120);
  MemoryCentroids src(mesh);
  for (PartitionKind kind : {PartitionKind::Irregular, PartitionKind::Regular,
                             PartitionKind::Regular2D}) {
    VPartitionOptions o;
    o.kind = kind;
    o.patchTriangles = 200;
    PartitionSequence seq = PartitionSequence::build(src, o);
    std::string blob = seq.serialize();
    PartitionSequence back = PartitionSequence::deserialize(blob);
    ASSERT_EQ(back.levels(), seq.levels());
    EXPECT_EQ(back.kind(), kind);
    EXPECT_EQ(back.serialize(), blob);
    for (uint32_t l = 0; l < seq.levels(); ++l) {
      EXPECT_EQ(back.cellCount(l), seq.cellCount(l));
      for (size_t t = 0; t < src.count(); t += 13)
        ASSERT_EQ(back.crossKey(l, &src.data()[4 * t]), seq.crossKey(l, &src.data()[4 * t]));
    }
    std::string bad = blob;
    bad[bad.size() / 2] ^= 0x40;
    EXPECT_THROW(PartitionSequence::deserialize(bad), Error);
    EXPECT_THROW(PartitionSequence::deserialize(blob.substr(0, blob.size() - 9)), Error);
    EXPECT_THROW(PartitionSequence::deserialize("not a partition"), Error);
  }
}

// --level-ratio: each level aims at 1/k of the cells of the one below (BMT halves: k = 2), with
// the shape the default keeps (counts on target, cells within 2x the mean); the ratio travels in
// the serialized sequence (version 2), and a sequence of ratio 2 keeps its version-1 bytes.
TEST(IrregularLevelRatio, EachLevelAimsAtAQuarterAndTheRatioTravelsWithTheSequence) {
  TestMesh mesh = meshClosed();
  MemoryCentroids src(mesh);
  VPartitionOptions o;
  o.patchTriangles = 200;
  PartitionSequence halves = PartitionSequence::build(src, o);
  o.levelRatio = 4;
  PartitionSequence seq = PartitionSequence::build(src, o);
  EXPECT_EQ(halves.levelRatio(), 2u);
  ASSERT_EQ(seq.levelRatio(), 4u);
  ASSERT_GE(seq.levels(), 3u);
  EXPECT_LT(seq.levels(), halves.levels());
  EXPECT_EQ(seq.levelTarget(0), halves.levelTarget(0));
  PartitionMetrics m = computeMetrics(seq, src);
  std::printf("%s", formatMetricsText(m).c_str());
  for (const LevelMetrics& l : m.levels) {
    if (l.level > 0 && l.target >= 16) {
      EXPECT_NEAR(double(seq.levelTarget(l.level - 1)) / double(l.target), 4.0, 0.1) << "level " << l.level;
    }
  }
  // A V(i+1) cell covers about four Vi cells and their crossings (6-8 at ratio 2).
  expectLevelShapes(seq, m, 12.0, 20);
  EXPECT_LE(m.levels.back().cells, 12u);
  // The patches: V0 cells crossed by V1 cells four times their size, about the size asked for.
  EXPECT_NEAR(m.levels[0].crossMean / o.patchTriangles, 1.0, 0.35);

  std::string blob = seq.serialize(), blob2 = halves.serialize();
  uint32_t version = 0, version2 = 0;
  std::memcpy(&version, blob.data() + 8, 4);
  std::memcpy(&version2, blob2.data() + 8, 4);
  EXPECT_EQ(version, 2u);
  EXPECT_EQ(version2, 1u) << "a ratio-2 sequence is written as before";
  PartitionSequence back = PartitionSequence::deserialize(blob);
  EXPECT_EQ(back.levelRatio(), 4u);
  EXPECT_EQ(back.serialize(), blob);
  for (uint32_t l = 0; l < seq.levels(); ++l) {
    for (size_t t = 0; t < src.count(); t += 17) {
      ASSERT_EQ(back.crossKey(l, &src.data()[4 * t]), seq.crossKey(l, &src.data()[4 * t]));
    }
  }
  EXPECT_NE(back.describe().find("ratio 4"), std::string::npos) << back.describe();
  // A version-2 blob must carry a ratio other than 2, within range (checksum made right).
  for (uint8_t bad : {uint8_t(2), uint8_t(1), uint8_t(9)}) {
    std::string b = blob;
    b[13] = char(bad);
    uint64_t h = XXH64(b.data(), b.size() - 8, 0);
    std::memcpy(&b[b.size() - 8], &h, 8);
    try {
      PartitionSequence::deserialize(b);
      ADD_FAILURE() << "level ratio " << int(bad) << " accepted";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("level ratio"), std::string::npos) << e.what();
    }
  }
  // A version-2 blob of a regular kind: refused (only irregular sequences carry a ratio).
  {
    std::string b = blob;
    b[12] = char(uint8_t(PartitionKind::Regular));
    uint64_t h = XXH64(b.data(), b.size() - 8, 0);
    std::memcpy(&b[b.size() - 8], &h, 8);
    EXPECT_THROW(PartitionSequence::deserialize(b), Error);
  }
  // Out of range, or a regular kind: refused, before any pass over the input.
  o.levelRatio = 9;
  EXPECT_THROW(PartitionSequence::build(src, o), Error);
  o.levelRatio = 1;
  EXPECT_THROW(PartitionSequence::build(src, o), Error);
  o.levelRatio = 4;
  o.kind = PartitionKind::Regular;
  EXPECT_THROW(PartitionSequence::build(src, o), Error);
  EXPECT_THROW(VPartitionAssigner{o}, Error);
}

TEST(Options, ParseHelpers) {
  EXPECT_EQ(parsePartitionKind("irregular"), PartitionKind::Irregular);
  EXPECT_EQ(parsePartitionKind("regular"), PartitionKind::Regular);
  EXPECT_EQ(parsePartitionKind("regular2d"), PartitionKind::Regular2D);
  EXPECT_THROW(parsePartitionKind("voronoi"), Error);
  EXPECT_STREQ(partitionKindName(PartitionKind::Regular), "regular");
  EXPECT_EQ(parsePatchTriangles("1000"), 1000u);
  EXPECT_THROW(parsePatchTriangles("0"), Error);
  EXPECT_THROW(parsePatchTriangles("-5"), Error);
  EXPECT_THROW(parsePatchTriangles("12x"), Error);
  EXPECT_THROW(parsePatchTriangles(""), Error);
  EXPECT_EQ(VPartitionOptions{}.kind, PartitionKind::Irregular);
  auto a = makeVPartitionAssigner({});
  EXPECT_NE(a, nullptr);
}

// ---- regular partitions ----------------------------------------------------------------------

// Counts of non-empty cells per level and of V*i cells with their triangle counts.
struct RegularCounts {
  std::vector<std::map<uint32_t, uint32_t>> cells;
  std::vector<std::map<uint64_t, uint32_t>> cross;
};
RegularCounts countCells(const PartitionSequence& seq, const MemoryCentroids& src) {
  RegularCounts r;
  r.cells.resize(seq.levels());
  r.cross.resize(seq.levels());
  for (size_t t = 0; t < src.count(); ++t) {
    const float* c = &src.data()[4 * t];
    for (uint32_t l = 0; l < seq.levels(); ++l) {
      ++r.cells[l][seq.cellOf(l, c)];
      ++r.cross[l][seq.crossKey(l, c)];
    }
  }
  return r;
}

// n x n quads on the unit square, each split in 4 by its centre: no centroid lies on a grid line
// or a 45-degree line through grid points, so the expected counts are exact.
TestMesh xSplitSquare(uint32_t n) {
  TestMesh m;
  for (uint32_t j = 0; j <= n; ++j)
    for (uint32_t i = 0; i <= n; ++i) m.positions.insert(m.positions.end(), {double(i) / n, double(j) / n, 0.0});
  for (uint32_t j = 0; j < n; ++j)
    for (uint32_t i = 0; i < n; ++i) {
      uint32_t c = m.vertexCount();
      m.positions.insert(m.positions.end(), {(i + 0.5) / n, (j + 0.5) / n, 0.0});
      uint32_t a = j * (n + 1) + i, b = a + 1, d = a + n + 1, e = d + 1;
      m.triangles.insert(m.triangles.end(), {a, b, c, b, e, c, e, d, c, d, a, c});
    }
  return m;
}

TEST(Regular, FlatSquareGivesTheBintree) {
  // 64x64 quads on the unit square (16384 triangles); finest squares of side 1/8.
  TestMesh mesh = xSplitSquare(64);
  MemoryCentroids src(mesh);
  VPartitionOptions o;
  o.kind = PartitionKind::Regular2D;
  o.regularCellSize = 1.0 / 8;
  PartitionSequence seq = PartitionSequence::build(src, o);
  RegularCounts r = countCells(seq, src);
  // squares(1/8), diamonds(1/4), squares(1/4), diamonds(1/2), squares(1/2): stop at <= 8 cells.
  const size_t cells[] = {64, 40, 16, 12, 4};
  ASSERT_EQ(seq.levels(), 5u);
  for (uint32_t l = 0; l < 5; ++l) EXPECT_EQ(r.cells[l].size(), cells[l]) << "level " << l;
  for (const auto& [id, n] : r.cells[0]) EXPECT_EQ(n, 256u);  // every square: 8x8 quads
  // Level 1: interior diamonds (24 interior edges of the 4x4 grid of side 1/4) hold half a
  // square of 1/4 (512 triangles), the 16 border ones half that.
  std::map<uint32_t, int> sizes;
  for (const auto& [id, n] : r.cells[1]) ++sizes[n];
  EXPECT_EQ(sizes[512], 24);
  EXPECT_EQ(sizes[256], 16);
  // V*0: each finest square is cut along one diagonal into two right triangles (the bintree).
  EXPECT_EQ(r.cross[0].size(), 128u);
  for (const auto& [key, n] : r.cross[0]) EXPECT_EQ(n, 128u);
  // V*1 = diamonds(1/4) x squares(1/4): each square of 1/4 cut by both diagonals into 4.
  EXPECT_EQ(r.cross[1].size(), 16u * 4);
  for (const auto& [key, n] : r.cross[1]) EXPECT_EQ(n, 256u);
  // Backward stars: a diamond overlaps 4 finest squares (2 on the border), a square 4 diamonds.
  PartitionMetrics m = computeMetrics(seq, src);
  EXPECT_EQ(m.levels[0].backwardStarMax, 4u);
  EXPECT_EQ(m.levels[1].backwardStarMax, 4u);
  EXPECT_DOUBLE_EQ(m.levels[1].backwardStarMean, 4.0);
  // Seeds are the cell centres: a diamond's seed is an edge midpoint of the 1/4 grid.
  float seed[3];
  seq.seedOf(1, seq.cellOf(1, &src.data()[0]), seed);
  EXPECT_FLOAT_EQ(seed[2], 0.0f);
  EXPECT_TRUE(std::fmod(seed[0] * 8, 1.0f) == 0 && std::fmod(seed[1] * 8, 1.0f) == 0);
  EXPECT_TRUE((std::fmod(seed[0] * 4, 1.0f) == 0) != (std::fmod(seed[1] * 4, 1.0f) == 0));
}

TEST(Regular, CubeAndOctahedraCountsIn3D) {
  // A volume of points (the partition is of space; a surface only samples it): 32^3 points in
  // the unit cube, offsets chosen off every cell boundary plane.
  MemoryCentroids src;
  for (int k = 0; k < 32; ++k)
    for (int j = 0; j < 32; ++j)
      for (int i = 0; i < 32; ++i) {
        float c[3] = {float((i + 0.31) / 32), float((j + 0.43) / 32), float((k + 0.57) / 32)};
        src.add(c, 1e-3f);
      }
  Box3 box;
  box.hi[0] = box.hi[1] = box.hi[2] = 1;
  src.setBounds(box);
  VPartitionOptions o;
  o.kind = PartitionKind::Regular;
  o.regularCellSize = 1.0 / 8;
  PartitionSequence seq = PartitionSequence::build(src, o);
  RegularCounts r = countCells(seq, src);
  // cubes(1/8), edge octahedra(1/4), face octahedra(1/4), cubes(1/4), edge(1/2), face(1/2),
  // cubes(1/2) = 8 cells: stop. Octahedra: 3 per grid cube, plus partial ones on the border.
  const size_t cells[] = {512, 3 * 4 * 25, 3 * 16 * 5, 64, 3 * 2 * 9, 3 * 4 * 3, 8};
  ASSERT_EQ(seq.levels(), 7u);
  for (uint32_t l = 0; l < 7; ++l) EXPECT_EQ(r.cells[l].size(), cells[l]) << "level " << l;
  // Volumes: cube(1/8) = 1/512 of the points; an interior octahedron (1/4) = (1/4)^3 / 3.
  for (const auto& [id, n] : r.cells[0]) EXPECT_EQ(n, 64u);
  for (uint32_t l : {1u, 2u}) {
    uint32_t biggest = 0;
    for (const auto& [id, n] : r.cells[l]) biggest = std::max(biggest, n);
    EXPECT_NEAR(biggest, 32768.0 / 64 / 3, 20) << "level " << l;  // lattice sampling noise
  }
  // Each finest cube is cut by the edge octahedra of the 1/4 grid into 3 pieces.
  EXPECT_EQ(r.cross[0].size(), 3u * 512);
  PartitionMetrics m = computeMetrics(seq, src);
  for (const LevelMetrics& l : m.levels) EXPECT_LE(l.backwardStarMax, 16u) << l.level;
  std::printf("%s", formatMetricsText(m).c_str());
}

TEST(Regular, SurfaceCalibratesPatchSize) {
  TestMesh mesh = test::closedBlob(80);
  MemoryCentroids src(mesh);
  VPartitionOptions o;
  o.kind = PartitionKind::Regular;
  o.patchTriangles = 300;
  PartitionSequence seq = PartitionSequence::build(src, o);
  PartitionMetrics m = computeMetrics(seq, src);
  std::printf("%s", formatMetricsText(m).c_str());
  EXPECT_NEAR(m.levels[0].crossMean / 300, 1.0, 0.2);
  EXPECT_LE(m.levels.back().cells, 8u);
  EXPECT_LE(m.build.passes, 3u);
}

// ---- connected components over a (fake) patch store ----------------------------------------

// What ingest does, in memory: one patch per distinct V*0 key, own vertices, symmetric boundary
// entries for every vertex shared between patches.
std::vector<Patch> makePatches(const TestMesh& mesh, const PartitionSequence& seq) {
  std::map<uint64_t, std::vector<uint32_t>> byKey;
  for (uint32_t t = 0; t < mesh.triangleCount(); ++t) {
    const uint32_t* v = &mesh.triangles[3 * size_t(t)];
    float c[3];
    triangleCentroid(&mesh.positions[3 * size_t(v[0])], &mesh.positions[3 * size_t(v[1])],
                     &mesh.positions[3 * size_t(v[2])], c);
    byKey[seq.crossKey(0, c)].push_back(t);
  }
  std::vector<Patch> patches;
  std::vector<std::vector<std::pair<PatchId, uint32_t>>> holders(mesh.vertexCount());
  for (const auto& [key, tris] : byKey) {
    Patch p;
    p.id = PatchId(patches.size());
    p.cell = key;
    std::map<uint32_t, uint32_t> local;
    for (uint32_t t : tris)
      for (int k = 0; k < 3; ++k) {
        uint32_t g = mesh.triangles[3 * size_t(t) + k];
        auto [it, fresh] = local.try_emplace(g, p.vertexCount());
        if (fresh) {
          p.positions.insert(p.positions.end(), &mesh.positions[3 * size_t(g)], &mesh.positions[3 * size_t(g)] + 3);
          holders[g].push_back({p.id, it->second});
        }
        p.triangles.push_back(it->second);
      }
    patches.push_back(std::move(p));
  }
  for (const auto& h : holders)
    for (const auto& [pa, la] : h)
      for (const auto& [pb, lb] : h)
        if (pa != pb) patches[pa].boundary.push_back({la, pb, lb});
  for (Patch& p : patches)
    std::sort(p.boundary.begin(), p.boundary.end(), [](const BoundaryEntry& a, const BoundaryEntry& b) {
      return std::tie(a.local, a.neighbour) < std::tie(b.local, b.neighbour);
    });
  return patches;
}

std::vector<double> componentShare(const TestMesh& mesh, const PartitionSequence& seq) {
  std::vector<Patch> patches = makePatches(mesh, seq);
  std::vector<PatchId> ids;
  for (const Patch& p : patches) ids.push_back(p.id);
  return computeComponentShare(seq, ids, [&](PatchId id) { return patches[id]; });
}

TEST(Components, ConnectedSquareHasNoSplitCells) {
  // Cells of levels >= 1 are unions of several patches, joined only through boundary entries.
  TestMesh mesh = xSplitSquare(64);
  MemoryCentroids src(mesh);
  VPartitionOptions o;
  o.kind = PartitionKind::Regular2D;
  o.regularCellSize = 1.0 / 8;
  PartitionSequence seq = PartitionSequence::build(src, o);
  std::vector<double> share = componentShare(mesh, seq);
  ASSERT_EQ(share.size(), seq.levels());
  for (double s : share) EXPECT_EQ(s, 0.0);
  o.kind = PartitionKind::Irregular;
  o.patchTriangles = 150;
  PartitionSequence irr = PartitionSequence::build(src, o);
  for (double s : componentShare(mesh, irr)) EXPECT_EQ(s, 0.0);
}

TEST(Components, CellsAcrossTwoSheetsAreSplit) {
  // Two parallel sheets 0.02 apart: the Voronoi cells (3D) take triangles from both.
  TestMesh mesh = xSplitSquare(40);
  TestMesh upper = xSplitSquare(40);
  for (size_t v = 0; v < upper.positions.size(); v += 3) upper.positions[v + 2] = 0.02;
  mesh.append(upper);
  MemoryCentroids src(mesh);
  VPartitionOptions o;
  o.patchTriangles = 150;
  PartitionSequence seq = PartitionSequence::build(src, o);
  std::vector<double> share = componentShare(mesh, seq);
  PartitionMetrics m = computeMetrics(seq, src);
  addComponentShare(m, share);
  std::printf("%s", formatMetricsText(m).c_str());
  for (double s : share) EXPECT_GT(s, 0.5);
}

// ---- with the real patch store: ingest with the V-partition assigner, then `mtstore info` ------

TEST(Store, IngestKeysPatchesByV0CrossingAndInfoPrintsMetrics) {
  test::TempDir dir;
  TestMesh mesh = test::holedTorus(160, 60);
  {
    std::string obj;
    char line[128];
    for (uint32_t v = 0; v < mesh.vertexCount(); ++v) {
      std::snprintf(line, sizeof line, "v %.9g %.9g %.9g\n", mesh.positions[3 * v],
                    mesh.positions[3 * v + 1], mesh.positions[3 * v + 2]);
      obj += line;
    }
    for (size_t t = 0; t < mesh.triangleCount(); ++t) {
      std::snprintf(line, sizeof line, "f %u %u %u\n", mesh.triangles[3 * t] + 1,
                    mesh.triangles[3 * t + 1] + 1, mesh.triangles[3 * t + 2] + 1);
      obj += line;
    }
    test::writeFile(dir.file("torus.obj"), obj);
  }
  VPartitionOptions o;
  o.patchTriangles = 150;
  auto assigner = makeVPartitionAssigner(o);
  IngestOptions io;
  io.progress = false;
  io.keepAssignerLookups = true;  // cellKey() is asked below
  PatchStore::ingest(dir.file("torus.obj"), dir.file("store"), *assigner, io);
  auto store = PatchStore::open(dir.file("store"));
  EXPECT_EQ(store->blob("assigner"), assigner->serialize());
  {
    // By default the ingest frees the assigner's lookups once every face has its cell: the store
    // is the same, and the assigner still describes and serializes itself as before.
    auto released = makeVPartitionAssigner(o);
    io.keepAssignerLookups = false;
    PatchStore::ingest(dir.file("torus.obj"), dir.file("store2"), *released, io);
    auto store2 = PatchStore::open(dir.file("store2"));
    EXPECT_EQ(released->serialize(), assigner->serialize());
    EXPECT_EQ(released->describe(), assigner->describe());
    EXPECT_EQ(store2->blob("assigner"), store->blob("assigner"));
    ASSERT_EQ(store2->patchIds(), store->patchIds());
    for (PatchId id : store->patchIds()) {
      Patch a = store->patch(id), b = store2->patch(id);
      EXPECT_EQ(a.cell, b.cell);
      EXPECT_EQ(a.positions, b.positions);
      EXPECT_EQ(a.triangles, b.triangles);
    }
    auto* v = dynamic_cast<VPartitionAssigner*>(released.get());
    ASSERT_NE(v, nullptr);
    EXPECT_GT(dynamic_cast<VPartitionAssigner*>(assigner.get())->sequence().memoryBytes(), 0u);
    EXPECT_EQ(v->sequence().levels(), 0u);  // the seeds and grids are gone
  }
  PartitionSequence seq;
  ASSERT_TRUE(loadStoreSequence(*store, seq));
  // Every patch is one V*0 cell: all its triangles have the patch's key.
  std::set<uint64_t> keys;
  for (PatchId id : store->patchIds()) {
    Patch p = store->patch(id);
    EXPECT_TRUE(keys.insert(p.cell).second);
    for (uint32_t t = 0; t < p.triangleCount(); ++t) {
      float c[3];
      triangleCentroid(&p.positions[3 * size_t(p.triangles[3 * t])],
                       &p.positions[3 * size_t(p.triangles[3 * t + 1])],
                       &p.positions[3 * size_t(p.triangles[3 * t + 2])], c);
      ASSERT_EQ(assigner->cellKey(c), p.cell);
      // The V0 half is the crossing's (below the slab index in the top 8 bits); the V1 half too,
      // except for merged slivers.
      EXPECT_EQ(PartitionSequence::crossHigh(seq.crossKey(0, c)), PartitionSequence::crossHigh(p.cell) & 0xFFFFFFu);
    }
  }
  // V*0 cells, i.e. patches: no slivers, max/mean <= 2.
  StoreInfo info = store->info();
  EXPECT_LE(double(info.maxPatchTriangles) / info.meanPatchTriangles, 2.0);
  EXPECT_GE(info.minPatchTriangles, 150u / 4 / 2);
  std::string text = storePartitionMetrics(*store, false);
  std::string json = storePartitionMetrics(*store, true);
  std::printf("%s", text.c_str());
  EXPECT_NE(text.find("irregular"), std::string::npos);
  EXPECT_NE(json.find("\"multiComponentShare\""), std::string::npos);
}

// ---- metrics formatting ------------------------------------------------------------------------

TEST(Metrics, TextAndJson) {
  TestMesh mesh = test::holedTorus(200, 70);
  MemoryCentroids src(mesh);
  VPartitionOptions o;
  o.patchTriangles = 100;
  PartitionSequence seq = PartitionSequence::build(src, o);
  PartitionMetrics m = computeMetrics(seq, src);
  EXPECT_EQ(m.triangles, src.count());
  addComponentShare(m, std::vector<double>(seq.levels(), 0.25));
  std::string text = formatMetricsText(m), json = formatMetricsJson(m);
  EXPECT_NE(text.find("irregular"), std::string::npos);
  EXPECT_NE(text.find("25.0%"), std::string::npos);
  EXPECT_EQ(json.front(), '{');
  EXPECT_EQ(json.back(), '}');
  EXPECT_NE(json.find("\"backwardStarMean\""), std::string::npos);
  EXPECT_NE(json.find("\"multiComponentShare\":0.25"), std::string::npos);
}

}  // namespace
}  // namespace mt
