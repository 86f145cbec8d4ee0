// Region simplification (mtbuild/simplify_region.h): locked vertices stay exactly, free borders
// (scan holes) simplify, the count lands near the target, the result stays manifold, and the
// measured error is real (>= the true vertex deviation) and grows as the target shrinks.
#include <gtest/gtest.h>

#include <map>
#include <set>
#include <utility>

#include "mtbuild/scan_grid.h"
#include "mtbuild/simplify_region.h"
#include "mtbuild/surface_distance.h"
#include "patchstore/error.h"
#include "patchstore/patch_store.h"

using namespace mt;

namespace {

struct EdgeStats {
  size_t boundaryEdges = 0, nonManifoldEdges = 0;
  std::set<uint32_t> boundaryVertices;
};

EdgeStats edgeStats(const std::vector<uint32_t>& tris) {
  std::map<std::pair<uint32_t, uint32_t>, int> count;
  for (size_t t = 0; t < tris.size(); t += 3)
    for (int k = 0; k < 3; ++k) {
      uint32_t a = tris[t + k], b = tris[t + (k + 1) % 3];
      count[{std::min(a, b), std::max(a, b)}]++;
    }
  EdgeStats s;
  for (auto& [e, c] : count) {
    if (c == 1) {
      s.boundaryEdges++;
      s.boundaryVertices.insert(e.first);
      s.boundaryVertices.insert(e.second);
    }
    if (c > 2) {
      s.nonManifoldEdges++;
    }
  }
  return s;
}

// A 20k-triangle region with holes; lock the outer rim (the region border) and a sprinkling of
// interior vertices (~5% in all), as the level loop would.
struct Region {
  ScanGrid g;
  std::vector<uint8_t> locked;
};

Region makeRegion(uint32_t holes = 3) {
  Region r;
  ScanGridOptions o;
  o.nx = o.ny = 101;
  o.holes = holes;
  o.holeRadius = 5;
  r.g = makeScanGrid(o);
  r.locked.assign(r.g.vertexCount(), 0);
  for (uint32_t v = 0; v < r.g.vertexCount(); ++v) {
    double x = r.g.positions[v * 3], y = r.g.positions[v * 3 + 1];
    if (x < 0.5 || y < 0.5 || x > 99.5 || y > 99.5) r.locked[v] = 1;  // rim
    if (v % 97 == 0) r.locked[v] = 1;                                  // scattered
  }
  return r;
}

TEST(SimplifyRegion, LockedVerticesKeepIdentityAndPosition) {
  Region r = makeRegion();
  size_t lockedCount = 0;
  for (uint8_t l : r.locked) lockedCount += l;
  ASSERT_GT(lockedCount, r.g.vertexCount() / 40);
  SimplifyRegionOptions opt;
  opt.targetTriangles = r.g.triangleCount() / 2;
  SimplifiedRegion s = simplifyRegion(r.g.positions.data(), r.g.vertexCount(), r.g.triangles.data(),
                                      r.g.triangleCount(), r.locked.data(), opt);
  std::set<uint32_t> kept(s.origin.begin(), s.origin.end());
  for (uint32_t v = 0; v < r.g.vertexCount(); ++v)
    if (r.locked[v]) {
      EXPECT_TRUE(kept.count(v)) << "locked vertex " << v << " removed";
    }
  for (size_t i = 0; i < s.origin.size(); ++i) {
    if (i) {
      ASSERT_LT(s.origin[i - 1], s.origin[i]);
    }
    for (int k = 0; k < 3; ++k) ASSERT_EQ(s.positions[i * 3 + k], r.g.positions[s.origin[i] * 3 + k]);  // bit-exact
  }
  for (uint32_t i : s.triangles) ASSERT_LT(i, s.vertexCount());
  std::set<uint32_t> referenced(s.triangles.begin(), s.triangles.end());
  EXPECT_EQ(referenced.size(), s.vertexCount()) << "every output vertex is used";
}

TEST(SimplifyRegion, ReachesTargetAndSimplifiesHoleBorders) {
  Region r = makeRegion();
  EdgeStats before = edgeStats(r.g.triangles);
  SimplifyRegionOptions opt;
  opt.targetTriangles = r.g.triangleCount() / 4;
  SimplifiedRegion s = simplifyRegion(r.g.positions.data(), r.g.vertexCount(), r.g.triangles.data(),
                                      r.g.triangleCount(), r.locked.data(), opt);
  EXPECT_LE(s.triangleCount(), opt.targetTriangles * 11 / 10);
  EXPECT_GE(s.triangleCount(), opt.targetTriangles * 8 / 10);
  // hole borders: boundary vertices that are not locked (the rim is) must drop substantially
  auto freeBoundary = [&](const std::set<uint32_t>& b, const std::vector<uint32_t>* origin) {
    size_t n = 0;
    for (uint32_t v : b) n += !r.locked[origin ? (*origin)[v] : v];
    return n;
  };
  EdgeStats after = edgeStats(s.triangles);
  size_t holeBefore = freeBoundary(before.boundaryVertices, nullptr);
  size_t holeAfter = freeBoundary(after.boundaryVertices, &s.origin);
  ASSERT_GT(holeBefore, 50u);
  EXPECT_LT(holeAfter, holeBefore) << "scan holes must simplify";
  opt.targetTriangles = r.g.triangleCount() / 16;
  SimplifiedRegion s16 = simplifyRegion(r.g.positions.data(), r.g.vertexCount(), r.g.triangles.data(),
                                        r.g.triangleCount(), r.locked.data(), opt);
  EXPECT_LT(freeBoundary(edgeStats(s16.triangles).boundaryVertices, &s16.origin), holeBefore * 3 / 4)
      << "meshopt ranks border collapses late (boundary-plane quadrics): measured 121 -> 97 -> 72";
  EXPECT_EQ(edgeStats(s16.triangles).nonManifoldEdges, 0u);
  // still manifold, holes are neither closed nor torn open: non-manifold edges stay 0
  EXPECT_EQ(before.nonManifoldEdges, 0u);
  EXPECT_EQ(after.nonManifoldEdges, 0u);
}

TEST(SimplifyRegion, AllBordersFreeWithoutLocks) {
  Region r = makeRegion(0);
  SimplifyRegionOptions opt;
  opt.targetTriangles = 500;
  SimplifiedRegion s = simplifyRegion(r.g.positions.data(), r.g.vertexCount(), r.g.triangles.data(),
                                      r.g.triangleCount(), nullptr, opt);
  EXPECT_LE(s.triangleCount(), 550u);
  EXPECT_LT(edgeStats(s.triangles).boundaryVertices.size(), 200u) << "the 400-vertex rim simplified";
}

TEST(SimplifyRegion, MeasuredErrorIsRealAndGrowsAsTargetShrinks) {
  Region r = makeRegion();
  double previous = -1;
  for (size_t div : {2, 4, 16, 64}) {
    SimplifyRegionOptions opt;
    opt.targetTriangles = r.g.triangleCount() / div;
    SimplifiedRegion s = simplifyRegion(r.g.positions.data(), r.g.vertexCount(), r.g.triangles.data(),
                                        r.g.triangleCount(), r.locked.data(), opt);
    EXPECT_GE(s.error, 0);
    EXPECT_GE(s.error, previous * 0.999) << "div " << div;
    previous = s.error;
    // independent check: brute-force distance of every input vertex to the result
    TriangleGrid grid(s.positions.data(), s.vertexCount(), s.triangles.data(), s.triangleCount());
    double worst = 0;
    for (uint32_t v = 0; v < r.g.vertexCount(); ++v) worst = std::max(worst, grid.distance(&r.g.positions[v * 3]));
    EXPECT_GE(s.error, worst - 1e-12) << "div " << div;
  }
  EXPECT_GT(previous, 0.05);  // 64x fewer triangles on a relief of amplitude 4: visible error
}

TEST(SimplifyRegion, LoadedMeshOverloadAndEdgeCases) {
  Region r = makeRegion(1);
  LoadedMesh m;
  m.positions = r.g.positions;
  m.triangles = r.g.triangles;
  m.locked = r.locked;
  SimplifyRegionOptions opt;
  opt.targetTriangles = 1000;
  SimplifiedRegion s = simplifyRegion(m, opt);
  EXPECT_LT(s.triangleCount(), 1500u);
  // target above the input: unchanged, error 0
  opt.targetTriangles = r.g.triangleCount() * 2;
  SimplifiedRegion same = simplifyRegion(m, opt);
  EXPECT_EQ(same.triangleCount(), r.g.triangleCount());
  EXPECT_EQ(same.error, 0);
  // everything locked: nothing can move
  m.locked.assign(m.positions.size() / 3, 1);
  opt.targetTriangles = 10;
  EXPECT_EQ(simplifyRegion(m, opt).triangleCount(), r.g.triangleCount());
  // bad index
  m.triangles[5] = 1u << 30;
  EXPECT_THROW(simplifyRegion(m, opt), Error);
}

TEST(SurfaceDistance, ExactOnSimpleCases) {
  double p[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0};
  uint32_t t[6] = {0, 1, 2, 1, 3, 2};
  TriangleGrid g(p, 4, t, 2);
  double a[3] = {0.3, 0.3, 2.0}, b[3] = {2, 0.5, 0}, c[3] = {-3, -4, 0};
  EXPECT_NEAR(g.distance(a), 2.0, 1e-12);
  EXPECT_NEAR(g.distance(b), 1.0, 1e-12);
  EXPECT_NEAR(g.distance(c), 5.0, 1e-12);
}

}  // namespace
