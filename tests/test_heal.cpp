// Healing passes (patchstore/heal): each pass on a store of many small patches (so defects and
// holes cross patch borders) against an in-core reference run on the whole exported mesh; the
// store's check() after every pass; dirty inputs come out clean (a re-ingest counts no defects).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numeric>
#include <random>
#include <set>

#include "patchstore/heal/heal.h"
#include "patchstore/heal/region.h"
#include "patchstore/io/ply_writer.h"
#include "patchstore/patch_store.h"
#include "tests/test_support.h"

namespace mt {
namespace {

using test::TempDir;

struct Mesh {
  std::vector<double> positions;
  std::vector<uint32_t> triangles;
  uint32_t vertexCount() const { return uint32_t(positions.size() / 3); }
  uint32_t add(double x, double y, double z) {
    // float-exact, as a float PLY stores it
    positions.insert(positions.end(), {double(float(x)), double(float(y)), double(float(z))});
    return vertexCount() - 1;
  }
  void tri(uint32_t a, uint32_t b, uint32_t c) { triangles.insert(triangles.end(), {a, b, c}); }
};

// A closed torus on an R x S grid; vertex (i, j) is i * S + j.
Mesh torus(int rings, int sides, double shift = 0) {
  Mesh m;
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < sides; ++j) {
      double u = 2 * M_PI * i / rings, v = 2 * M_PI * j / sides;
      double r = 1 + 0.3 * std::cos(v) + 0.01 * std::sin(7 * u) * std::cos(5 * v);
      m.add(r * std::cos(u) + shift, r * std::sin(u), 0.3 * std::sin(v));
    }
  auto id = [&](int i, int j) { return uint32_t((i % rings) * sides + (j % sides)); };
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < sides; ++j) {
      m.tri(id(i, j), id(i + 1, j), id(i + 1, j + 1));
      m.tri(id(i, j), id(i + 1, j + 1), id(i, j + 1));
    }
  return m;
}

void shuffleFaces(Mesh& m, uint32_t seed) {
  std::vector<std::array<uint32_t, 3>> f(m.triangles.size() / 3);
  for (size_t t = 0; t < f.size(); ++t) f[t] = {m.triangles[3 * t], m.triangles[3 * t + 1], m.triangles[3 * t + 2]};
  std::mt19937 rng(seed);
  std::shuffle(f.begin(), f.end(), rng);
  m.triangles.clear();
  for (auto& t : f) m.tri(t[0], t[1], t[2]);
}

void writePly(const Mesh& m, const std::string& path) {
  PlyWriter w(path, {});
  for (size_t i = 0; i < m.positions.size(); i += 3) w.addVertex(&m.positions[i]);
  for (size_t i = 0; i < m.triangles.size(); i += 3) w.addTriangle(m.triangles[i], m.triangles[i + 1], m.triangles[i + 2]);
  w.finish();
}

struct Collect : MeshSink {
  Mesh m;
  void vertices(const InputVertex* v, size_t n, uint64_t) override {
    for (size_t i = 0; i < n; ++i) m.positions.insert(m.positions.end(), v[i].p, v[i].p + 3);
  }
  void triangles(const uint32_t* idx, size_t n) override { m.triangles.insert(m.triangles.end(), idx, idx + 3 * n); }
};
Mesh readMesh(const std::string& path) {
  Collect c;
  openMesh(path)->read(c);
  return c.m;
}
Mesh exported(const PatchStore& store, const std::string& path) {
  store.exportPly(path);
  return readMesh(path);
}

IngestOptions quietOptions() {
  IngestOptions o;
  o.memoryBytes = 64ull << 20;
  o.progress = false;
  return o;
}
std::unique_ptr<PatchStore> ingest(const std::string& input, const std::string& dir, uint32_t patchTriangles,
                                   IngestReport* report = nullptr) {
  auto assigner = makeGridAssigner(patchTriangles);
  IngestReport r = PatchStore::ingest(input, dir, *assigner, quietOptions());
  if (report) *report = r;
  return PatchStore::open(dir);
}
// Re-ingests a healed store's export: the defect counts ingest measures must all be zero.
void expectClean(const PatchStore& store, const TempDir& tmp, const std::string& name) {
  store.exportPly(tmp.file(name + ".ply"));
  IngestReport r;
  ingest(tmp.file(name + ".ply"), tmp.file(name + ".store"), 100000, &r);
  EXPECT_EQ(r.degenerateTriangles, 0u) << name;
  EXPECT_EQ(r.duplicateTriangles, 0u) << name;
  EXPECT_EQ(r.unreferencedVertices, 0u) << name;
  EXPECT_EQ(r.nonManifoldEdges, 0u) << name;
}

::testing::AssertionResult checked(const PatchStore& store) {
  CheckReport r = store.check();
  if (r.ok) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << r.problems.size() << " problems, first: " << r.problems[0];
}

heal::HealOptions options() {
  heal::HealOptions o;
  o.memoryBytes = 16ull << 20;
  return o;
}

struct UnionFind {
  std::vector<uint32_t> parent;
  explicit UnionFind(size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
  uint32_t find(uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  }
  void unite(uint32_t a, uint32_t b) { parent[find(a)] = find(b); }
};

uint64_t borderLoops(const Mesh& m) {
  auto r = heal::referenceFillHoles(m.positions, m.triangles, 0);
  EXPECT_TRUE(r.ok);
  return r.holes;
}

// ---------------------------------------------------------------------------------------------

// Two halves of a torus whose seam vertices are duplicated (as two scans meeting): the halves
// are cut along two rings, so the duplicates sit in different patches along both seams.
Mesh seamTorus(int rings, int sides, double offset) {
  Mesh m = torus(rings, sides);
  Mesh out;
  out.positions = m.positions;
  std::map<uint32_t, uint32_t> copy;
  auto dup = [&](uint32_t v) {
    auto it = copy.find(v);
    if (it != copy.end()) return it->second;
    uint32_t c = out.add(m.positions[3 * v] + offset, m.positions[3 * v + 1], m.positions[3 * v + 2]);
    return copy[v] = c;
  };
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < sides; ++j)
      for (int h = 0; h < 2; ++h) {
        uint32_t* f = &m.triangles[3 * (2 * (i * sides + j) + h)];
        std::array<uint32_t, 3> t{f[0], f[1], f[2]};
        if (i >= rings / 2)  // the second half uses copies of its seam rings (0 and rings/2)
          for (auto& v : t)
            if (v / sides == 0 || v / sides == uint32_t(rings / 2)) v = dup(v);
        out.tri(t[0], t[1], t[2]);
      }
  shuffleFaces(out, 7);
  return out;
}

uint64_t referenceWeld(const Mesh& m, double eps) {
  UnionFind uf(m.vertexCount());
  for (uint32_t a = 0; a < m.vertexCount(); ++a)
    for (uint32_t b = a + 1; b < m.vertexCount(); ++b) {
      double d2 = 0;
      for (int k = 0; k < 3; ++k) d2 += std::pow(m.positions[3 * a + k] - m.positions[3 * b + k], 2);
      if (eps == 0 ? d2 == 0 : d2 < eps * eps) uf.unite(a, b);
    }
  uint64_t merged = 0;
  for (uint32_t v = 0; v < m.vertexCount(); ++v) merged += uf.find(v) != v;
  return merged;
}

TEST(Heal, WeldExactDuplicatesAlongSeamsAcrossPatches) {
  TempDir tmp;
  Mesh m = seamTorus(60, 24, 0);
  writePly(m, tmp.file("in.ply"));
  auto store = ingest(tmp.file("in.ply"), tmp.file("s"), 120);
  ASSERT_GT(store->patchIds().size(), 20u);
  Mesh before = exported(*store, tmp.file("before.ply"));
  EXPECT_EQ(borderLoops(before), 4u);  // two seams, each open on both halves
  uint64_t expected = referenceWeld(before, 0);
  EXPECT_EQ(expected, 48u);
  heal::PassReport r = heal::weld(*store, 0, options());
  EXPECT_EQ(r.get("merged"), expected) << r.line();
  EXPECT_TRUE(checked(*store));
  Mesh after = exported(*store, tmp.file("after.ply"));
  EXPECT_EQ(after.vertexCount(), before.vertexCount() - expected);
  EXPECT_EQ(after.triangles.size(), before.triangles.size());
  EXPECT_EQ(borderLoops(after), 0u);  // closed again: the seams are stitched
  EXPECT_EQ(heal::weld(*store, 0, options()).get("merged"), 0u);
  expectClean(*store, tmp, "healed");
}

TEST(Heal, WeldWithEpsilonMatchesInCore) {
  TempDir tmp;
  Mesh m = seamTorus(60, 24, 2e-4);  // copies 2e-4 off; grid spacing is ~0.08
  writePly(m, tmp.file("in.ply"));
  auto store = ingest(tmp.file("in.ply"), tmp.file("s"), 120);
  Mesh before = exported(*store, tmp.file("before.ply"));
  EXPECT_EQ(referenceWeld(before, 1e-4), 0u);
  heal::PassReport small = heal::weld(*store, 1e-4, options());
  EXPECT_EQ(small.get("merged"), 0u);
  uint64_t expected = referenceWeld(before, 1e-3);
  EXPECT_EQ(expected, 48u);
  heal::PassReport r = heal::weld(*store, 1e-3, options());
  EXPECT_EQ(r.get("merged"), expected) << r.line();
  EXPECT_TRUE(checked(*store));
  Mesh after = exported(*store, tmp.file("after.ply"));
  EXPECT_EQ(borderLoops(after), 0u);
  // Each cluster became its member with the smallest position: the first half's vertex wins
  // where the copy is 2e-4 further along x.
  std::set<std::array<double, 3>> in;
  for (size_t i = 0; i < before.positions.size(); i += 3) in.insert({before.positions[i], before.positions[i + 1], before.positions[i + 2]});
  for (size_t i = 0; i < after.positions.size(); i += 3)
    ASSERT_TRUE(in.count({after.positions[i], after.positions[i + 1], after.positions[i + 2]}));
}

// ---------------------------------------------------------------------------------------------

TEST(Heal, DegenerateDuplicateAndUnreferencedMatchInCoreAndComeOutClean) {
  TempDir tmp;
  Mesh m = torus(60, 30);
  std::mt19937 rng(3);
  const uint32_t nv = m.vertexCount(), nt = uint32_t(m.triangles.size() / 3);
  for (int k = 0; k < 30; ++k) {  // degenerate faces on existing vertices
    uint32_t t = rng() % nt;
    m.tri(m.triangles[3 * t], m.triangles[3 * t], m.triangles[3 * t + 1]);
  }
  for (int k = 0; k < 10; ++k) {  // degenerate faces that are a vertex's only use
    uint32_t t = rng() % nt;
    uint32_t a = m.triangles[3 * t];
    uint32_t w = m.add(m.positions[3 * a] * 1.1, m.positions[3 * a + 1] * 1.1, m.positions[3 * a + 2]);
    m.tri(a, w, w);
  }
  for (int k = 0; k < 40; ++k) {  // duplicates: rotated and reversed copies
    uint32_t t = rng() % nt;
    const uint32_t* f = &m.triangles[3 * t];
    if (k % 2) m.tri(f[1], f[2], f[0]);
    else m.tri(f[0], f[2], f[1]);
  }
  for (int k = 0; k < 25; ++k) m.add(5 + k, 5, 5);  // unreferenced
  shuffleFaces(m, 11);
  (void)nv;
  writePly(m, tmp.file("in.ply"));
  IngestReport in;
  auto store = ingest(tmp.file("in.ply"), tmp.file("s"), 150, &in);
  EXPECT_EQ(in.degenerateTriangles, 40u);
  EXPECT_GT(in.duplicateTriangles, 0u);
  EXPECT_EQ(in.unreferencedVertices, 25u);
  ASSERT_TRUE(checked(*store));

  // References on the exported mesh.
  Mesh before = exported(*store, tmp.file("before.ply"));
  uint64_t degenerate = 0, onlyDegenerate = 0;
  std::vector<int> useful(before.vertexCount(), 0);
  std::set<std::array<uint32_t, 3>> seen;
  uint64_t duplicates = 0;
  for (size_t t = 0; t < before.triangles.size(); t += 3) {
    const uint32_t* f = &before.triangles[t];
    if (f[0] == f[1] || f[1] == f[2] || f[0] == f[2]) {
      ++degenerate;
      continue;
    }
    for (int c = 0; c < 3; ++c) useful[f[c]] = 1;
    std::array<uint32_t, 3> k{f[0], f[1], f[2]};
    std::sort(k.begin(), k.end());
    duplicates += !seen.insert(k).second;
  }
  for (int u : useful) onlyDegenerate += !u;

  EXPECT_EQ(heal::removeUnreferenced(*store, options()).get("vertices"), 0u);  // ingest dropped them
  heal::PassReport d = heal::removeDegenerate(*store, options());
  EXPECT_EQ(d.get("triangles"), degenerate) << d.line();
  EXPECT_EQ(d.get("vertices"), onlyDegenerate) << d.line();
  EXPECT_TRUE(checked(*store));
  heal::PassReport u = heal::removeDuplicateFaces(*store, options());
  EXPECT_EQ(u.get("triangles"), duplicates) << u.line();
  EXPECT_EQ(u.get("vertices"), 0u);
  EXPECT_TRUE(checked(*store));
  EXPECT_EQ(heal::removeUnreferenced(*store, options()).get("vertices"), 0u);
  EXPECT_EQ(heal::removeDegenerate(*store, options()).get("triangles"), 0u);
  EXPECT_EQ(heal::removeDuplicateFaces(*store, options()).get("triangles"), 0u);
  Mesh after = exported(*store, tmp.file("after.ply"));
  EXPECT_EQ(after.triangles.size() / 3, before.triangles.size() / 3 - degenerate - duplicates);
  EXPECT_EQ(after.vertexCount(), before.vertexCount() - onlyDegenerate);
  // Closed and manifold (a kept reversed duplicate may flip a face, so count edge uses instead of
  // asking CGAL for border cycles).
  std::map<std::pair<uint32_t, uint32_t>, int> edgeUse;
  for (size_t t = 0; t < after.triangles.size(); t += 3)
    for (int k = 0; k < 3; ++k) ++edgeUse[std::minmax(after.triangles[t + k], after.triangles[t + (k + 1) % 3])];
  for (auto& [e, n] : edgeUse) ASSERT_EQ(n, 2);
  expectClean(*store, tmp, "healed");
}

// ---------------------------------------------------------------------------------------------

TEST(Heal, SmallComponentsAcrossPatchesMatchInCore) {
  TempDir tmp;
  Mesh m = torus(50, 24);
  // Long thin strips floating above the torus, 4 * len triangles each, crossing many patches.
  for (int len : {3, 10, 25, 37, 38, 60}) {
    double z = 1 + 0.05 * len;
    std::vector<uint32_t> row[3];
    for (int i = 0; i <= len; ++i)
      for (int r = 0; r < 3; ++r) row[r].push_back(m.add(-1.2 + 2.4 * i / len, 0.05 * r, z));
    for (int i = 0; i < len; ++i)
      for (int r = 0; r < 2; ++r) {
        m.tri(row[r][i], row[r][i + 1], row[r + 1][i + 1]);
        m.tri(row[r][i], row[r + 1][i + 1], row[r + 1][i]);
      }
  }
  shuffleFaces(m, 5);
  writePly(m, tmp.file("in.ply"));
  auto store = ingest(tmp.file("in.ply"), tmp.file("s"), 100);
  Mesh before = exported(*store, tmp.file("before.ply"));
  const uint64_t minTriangles = 150;
  UnionFind uf(before.vertexCount());
  for (size_t t = 0; t < before.triangles.size(); t += 3) {
    uf.unite(before.triangles[t], before.triangles[t + 1]);
    uf.unite(before.triangles[t], before.triangles[t + 2]);
  }
  std::map<uint32_t, uint64_t> size;
  for (size_t t = 0; t < before.triangles.size(); t += 3) ++size[uf.find(before.triangles[t])];
  uint64_t components = 0, triangles = 0;
  for (auto& [root, n] : size)
    if (n < minTriangles) ++components, triangles += n;
  EXPECT_EQ(components, 4u);  // 12, 40, 100, 148 triangles; 152 and 240 stay
  heal::PassReport r = heal::removeSmallComponents(*store, minTriangles, options());
  EXPECT_EQ(r.get("components"), components) << r.line();
  EXPECT_EQ(r.get("triangles"), triangles) << r.line();
  EXPECT_EQ(r.get("vertices"), 3u * (3 + 10 + 25 + 37 + 4)) << r.line();
  EXPECT_TRUE(checked(*store));
  Mesh after = exported(*store, tmp.file("after.ply"));
  EXPECT_EQ(after.triangles.size() / 3, before.triangles.size() / 3 - triangles);
  EXPECT_EQ(heal::removeSmallComponents(*store, minTriangles, options()).get("components"), 0u);
}

// ---------------------------------------------------------------------------------------------

struct NonManifoldCounts {
  uint64_t edges = 0, vertices = 0, added = 0;
};
// The same rule as fixNonManifold, in core: fans joined across edges with exactly two triangles.
NonManifoldCounts referenceNonManifold(const Mesh& m) {
  NonManifoldCounts c;
  std::map<std::pair<uint32_t, uint32_t>, int> edgeUse;
  std::vector<std::vector<uint32_t>> around(m.vertexCount());
  for (uint32_t t = 0; t < m.triangles.size() / 3; ++t) {
    const uint32_t* f = &m.triangles[3 * t];
    for (int k = 0; k < 3; ++k) {
      ++edgeUse[std::minmax(f[k], f[(k + 1) % 3])];
      around[f[k]].push_back(t);
    }
  }
  for (auto& [e, n] : edgeUse) c.edges += n > 2;
  for (uint32_t v = 0; v < m.vertexCount(); ++v) {
    const auto& ts = around[v];
    UnionFind uf(ts.size());
    std::map<uint32_t, std::vector<uint32_t>> partner;
    for (uint32_t i = 0; i < ts.size(); ++i)
      for (int k = 0; k < 3; ++k)
        if (m.triangles[3 * ts[i] + k] != v) partner[m.triangles[3 * ts[i] + k]].push_back(i);
    for (auto& [x, list] : partner)
      if (list.size() == 2 && edgeUse[std::minmax(v, x)] == 2) uf.unite(list[0], list[1]);
    std::set<uint32_t> roots;
    for (uint32_t i = 0; i < ts.size(); ++i) roots.insert(uf.find(i));
    if (roots.size() > 1) ++c.vertices, c.added += roots.size() - 1;
  }
  return c;
}

TEST(Heal, NonManifoldEdgesAndVerticesAreSplitAsInCore) {
  TempDir tmp;
  const int rings = 50, sides = 24;
  Mesh m = torus(rings, sides);
  std::mt19937 rng(9);
  const uint32_t nt = uint32_t(m.triangles.size() / 3);
  for (int k = 0; k < 12; ++k) {  // fins: a third triangle on an edge
    const uint32_t* f = &m.triangles[3 * (rng() % nt)];
    double p[3];
    for (int a = 0; a < 3; ++a) p[a] = (m.positions[3 * f[0] + a] + m.positions[3 * f[1] + a]) / 2 * 1.15;
    uint32_t w = m.add(p[0], p[1], p[2] + 0.02);
    m.tri(f[0], f[1], w);
  }
  for (int k = 0; k < 8; ++k) {  // flaps touching the surface at one vertex only
    uint32_t v = m.triangles[3 * (rng() % nt)];
    const double* p = &m.positions[3 * v];
    uint32_t a = m.add(p[0] * 1.2, p[1] * 1.2, p[2] + 0.03), b = m.add(p[0] * 1.2, p[1] * 1.2 + 0.03, p[2] + 0.05);
    m.tri(v, a, b);
  }
  // Two sheets crossing along a ring of edges (four triangles per edge).
  for (int j = 0; j < sides; ++j) {
    uint32_t a = uint32_t(10 * sides + j), b = uint32_t(10 * sides + (j + 1) % sides);
    uint32_t w = m.add(m.positions[3 * a] * 1.3, m.positions[3 * a + 1] * 1.3, m.positions[3 * a + 2] * 1.3);
    m.tri(a, b, w);
    m.tri(b, a, m.add(m.positions[3 * a] * 1.3, m.positions[3 * a + 1] * 1.3, m.positions[3 * a + 2] * 1.3 + 0.01));
  }
  shuffleFaces(m, 13);
  writePly(m, tmp.file("in.ply"));
  IngestReport in;
  auto store = ingest(tmp.file("in.ply"), tmp.file("s"), 120, &in);
  EXPECT_GT(in.nonManifoldEdges, 0u);
  Mesh before = exported(*store, tmp.file("before.ply"));
  NonManifoldCounts ref = referenceNonManifold(before);
  EXPECT_EQ(ref.edges, in.nonManifoldEdges);
  heal::PassReport r = heal::fixNonManifold(*store, options());
  EXPECT_EQ(r.get("edges"), ref.edges) << r.line();
  EXPECT_EQ(r.get("vertices"), ref.vertices) << r.line();
  EXPECT_EQ(r.get("added"), ref.added) << r.line();
  EXPECT_TRUE(checked(*store));
  Mesh after = exported(*store, tmp.file("after.ply"));
  EXPECT_EQ(after.vertexCount(), before.vertexCount() + ref.added);
  NonManifoldCounts left = referenceNonManifold(after);
  EXPECT_EQ(left.edges, 0u);
  EXPECT_EQ(left.vertices, 0u);
  EXPECT_EQ(heal::fixNonManifold(*store, options()).get("vertices"), 0u);
  expectClean(*store, tmp, "healed");
}

// ---------------------------------------------------------------------------------------------

TEST(Heal, FillHolesMatchesWholeMeshCgalIncludingHolesAcrossPatches) {
  TempDir tmp;
  auto gen = test::runTool("mtgen", "-o " + tmp.file("in.ply") + " -t 40k --holes 16 --shuffle");
  ASSERT_EQ(gen.exitCode, 0) << gen.output;
  auto store = ingest(tmp.file("in.ply"), tmp.file("s"), 150);
  ASSERT_GT(store->patchIds().size(), 100u);
  Mesh before = exported(*store, tmp.file("before.ply"));
  const uint32_t maxEdges = 40;
  heal::ReferenceFill ref = heal::referenceFillHoles(before.positions, before.triangles, maxEdges);
  ASSERT_TRUE(ref.ok);
  EXPECT_EQ(ref.holes, 16u);
  ASSERT_GT(ref.filled, 3u);
  ASSERT_GT(ref.larger, 3u);

  // How many of the holes to fill cross patch borders: their border edges lie in several patches.
  std::vector<heal::EdgeUse> border;
  heal::edgeCensus(*store, options(), [](uint32_t c) { return c == 1; }, [&](const heal::EdgeUse& e) { border.push_back(e); }, "");
  std::map<uint64_t, uint32_t> vertexIndex;
  for (auto& e : border) vertexIndex.emplace(e.a, uint32_t(vertexIndex.size())), vertexIndex.emplace(e.b, uint32_t(vertexIndex.size()));
  UnionFind uf(vertexIndex.size());
  for (auto& e : border) uf.unite(vertexIndex[e.a], vertexIndex[e.b]);
  std::map<uint32_t, std::set<PatchId>> patchesOf;
  std::map<uint32_t, uint32_t> edgesOf;
  for (auto& e : border) patchesOf[uf.find(vertexIndex[e.a])].insert(e.patch), ++edgesOf[uf.find(vertexIndex[e.a])];
  int crossing = 0;
  for (auto& [loop, ps] : patchesOf) crossing += ps.size() > 1 && edgesOf[loop] <= maxEdges;
  EXPECT_GE(crossing, 2);

  heal::PassReport r = heal::fillHoles(*store, maxEdges, options());
  EXPECT_EQ(r.get("holes"), ref.holes) << r.line();
  EXPECT_EQ(r.get("filled"), ref.filled) << r.line();
  EXPECT_EQ(r.get("larger"), ref.larger) << r.line();
  EXPECT_EQ(r.get("skipped"), 0u) << r.line();
  EXPECT_EQ(r.get("across-patches"), uint64_t(crossing)) << r.line();
  EXPECT_TRUE(checked(*store));
  Mesh after = exported(*store, tmp.file("after.ply"));
  // Every hole of at most maxEdges edges is closed, the larger ones stay.
  heal::ReferenceFill left = heal::referenceFillHoles(after.positions, after.triangles, maxEdges);
  ASSERT_TRUE(left.ok);  // still a manifold CGAL accepts
  EXPECT_EQ(left.holes, ref.larger);
  EXPECT_EQ(left.larger, ref.larger);
  // The same triangulation and refinement as CGAL on the whole mesh, up to its tie-breaking.
  double added = double(after.triangles.size() - before.triangles.size()) / 3;
  double refAdded = double(ref.triangles.size() - before.triangles.size()) / 3;
  EXPECT_NEAR(added, refAdded, 0.05 * refAdded);
  EXPECT_EQ(r.get("triangles"), uint64_t(added));
  expectClean(*store, tmp, "healed");
  EXPECT_EQ(heal::fillHoles(*store, maxEdges, options()).get("filled"), 0u);
}

// An open tube along z (no caps): its two end holes, filled and faired, bulge past z = 0 and
// z = height, outside the input's box. The store's box must grow to hold them, or the MT grid
// built from it has no cell for the caps' vertices.
TEST(Heal, FilledHolesOutsideTheInputsBoxGrowTheStoresBoxAndBuild) {
  TempDir tmp;
  Mesh m;
  const int rings = 12, sides = 24;
  const double height = 1.0;
  for (int i = 0; i <= rings; ++i)
    for (int j = 0; j < sides; ++j) {
      double a = 2 * M_PI * j / sides;
      m.add(std::cos(a), std::sin(a), height * i / rings);
    }
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < sides; ++j) {
      uint32_t a = uint32_t(i * sides + j), b = uint32_t(i * sides + (j + 1) % sides);
      m.tri(a, b, b + sides);
      m.tri(a, b + sides, a + sides);
    }
  writePly(m, tmp.file("tube.ply"));
  ASSERT_EQ(test::runTool("mtstore", "ingest " + tmp.file("tube.ply") + " -o " + tmp.file("s") + " --patch-triangles 100 -q").exitCode, 0);
  Box3 input = PatchStore::open(tmp.file("s"))->info().bounds;
  auto heal = test::runTool("mtstore", "heal " + tmp.file("s") + " --fill-holes 100 -q");
  ASSERT_EQ(heal.exitCode, 0) << heal.output;
  EXPECT_NE(heal.output.find("fill-holes: holes 2, filled 2"), std::string::npos) << heal.output;
  auto store = PatchStore::open(tmp.file("s"));
  Mesh after = exported(*store, tmp.file("after.ply"));
  Box3 box = store->info().bounds;
  double zMin = 0, zMax = 0;
  for (size_t i = 0; i < after.positions.size(); i += 3) {
    zMin = std::min(zMin, after.positions[i + 2]), zMax = std::max(zMax, after.positions[i + 2]);
    for (int a = 0; a < 3; ++a) {
      ASSERT_GE(after.positions[i + a], box.lo[a]) << "vertex " << i / 3 << " axis " << a;
      ASSERT_LE(after.positions[i + a], box.hi[a]) << "vertex " << i / 3 << " axis " << a;
    }
  }
  ASSERT_TRUE(zMin < input.lo[2] || zMax > input.hi[2]) << "the faired caps stay within the tube's box: no test";
  auto build = test::runTool("mtbuild", tmp.file("s") + " -o " + tmp.file("tube.mt") + " -q");
  ASSERT_EQ(build.exitCode, 0) << build.output;
  auto verify = test::runTool("mtverify", tmp.file("tube.mt"));
  EXPECT_EQ(verify.exitCode, 0) << verify.output;
}

// ---------------------------------------------------------------------------------------------

void referenceTaubin(Mesh& m, int iterations, double lambda, double mu) {
  std::vector<std::set<uint32_t>> ring(m.vertexCount());
  for (size_t t = 0; t < m.triangles.size(); t += 3)
    for (int k = 0; k < 3; ++k) {
      uint32_t a = m.triangles[t + k], b = m.triangles[t + (k + 1) % 3];
      if (a != b) ring[a].insert(b), ring[b].insert(a);
    }
  for (int i = 0; i < 2 * iterations; ++i) {
    double f = i % 2 ? mu : lambda;
    std::vector<double> next = m.positions;
    for (uint32_t v = 0; v < m.vertexCount(); ++v) {
      if (ring[v].empty()) continue;
      for (int a = 0; a < 3; ++a) {
        double sum = 0;
        for (uint32_t w : ring[v]) sum += m.positions[3 * w + a];
        next[3 * v + a] = m.positions[3 * v + a] + f * (sum / double(ring[v].size()) - m.positions[3 * v + a]);
      }
    }
    m.positions.swap(next);
  }
}

TEST(Heal, TaubinSmoothingEqualsInCoreRunBordersIncluded) {
  TempDir tmp;
  auto gen = test::runTool("mtgen", "-o " + tmp.file("in.ply") + " -t 12k --holes 4 --shuffle");
  ASSERT_EQ(gen.exitCode, 0) << gen.output;
  auto store = ingest(tmp.file("in.ply"), tmp.file("s"), 100);
  Mesh ref = exported(*store, tmp.file("before.ply"));
  double diag = 0;
  Box3 b = store->info().bounds;
  for (int a = 0; a < 3; ++a) diag += (b.hi[a] - b.lo[a]) * (b.hi[a] - b.lo[a]);
  diag = std::sqrt(diag);
  referenceTaubin(ref, 3, 0.5, -0.53);
  heal::PassReport r = heal::smooth(*store, 3, options());
  EXPECT_EQ(r.get("iterations"), 3u);
  EXPECT_TRUE(checked(*store));  // every copy of a shared vertex moved to the same place
  Mesh after = exported(*store, tmp.file("after.ply"));
  ASSERT_EQ(after.positions.size(), ref.positions.size());
  ASSERT_EQ(after.triangles, ref.triangles);
  double worst = 0, moved = 0;
  Mesh orig = readMesh(tmp.file("before.ply"));
  for (size_t i = 0; i < ref.positions.size(); ++i) {
    worst = std::max(worst, std::abs(after.positions[i] - ref.positions[i]));
    moved = std::max(moved, std::abs(after.positions[i] - orig.positions[i]));
  }
  EXPECT_LT(worst, 1e-5 * diag);
  EXPECT_GT(moved, 1e-4 * diag);  // it did smooth
}

// ---------------------------------------------------------------------------------------------

TEST(Heal, CommandLineRunsPassesInOrderAndReportsErrors) {
  TempDir tmp;
  Mesh m = seamTorus(40, 16, 0);
  m.tri(0, 0, 1);
  writePly(m, tmp.file("in.ply"));
  ASSERT_EQ(test::runTool("mtstore", "ingest " + tmp.file("in.ply") + " -o " + tmp.file("s") + " --patch-triangles 100 -q").exitCode, 0);
  auto help = test::runTool("mtstore", "heal --help");
  EXPECT_EQ(help.exitCode, 0);
  for (const char* opt : {"--weld", "--remove-degenerate", "--remove-duplicate-faces", "--remove-unreferenced",
                          "--remove-small-components", "--fix-nonmanifold", "--fill-holes", "--smooth", "--memory"})
    EXPECT_NE(help.output.find(opt), std::string::npos) << opt;
  auto run = test::runTool("mtstore", "heal " + tmp.file("s") + " --remove-degenerate --weld 0 --remove-unreferenced --fill-holes 50 --memory 32M -q");
  EXPECT_EQ(run.exitCode, 0) << run.output;
  size_t a = run.output.find("remove-degenerate: triangles 1"), b = run.output.find("weld: merged 32"),
         c = run.output.find("remove-unreferenced: vertices 0"), d = run.output.find("fill-holes: holes 0");
  EXPECT_NE(a, std::string::npos) << run.output;
  EXPECT_NE(b, std::string::npos) << run.output;
  EXPECT_NE(c, std::string::npos) << run.output;
  EXPECT_NE(d, std::string::npos) << run.output;
  EXPECT_TRUE(a < b && b < c && c < d) << run.output;
  EXPECT_EQ(test::runTool("mtstore", "check " + tmp.file("s")).exitCode, 0);
  auto none = test::runTool("mtstore", "heal " + tmp.file("s"));
  EXPECT_EQ(none.exitCode, 1);
  EXPECT_NE(none.output.find("no pass given"), std::string::npos) << none.output;
  auto missing = test::runTool("mtstore", "heal " + tmp.file("nope") + " --weld 0");
  EXPECT_EQ(missing.exitCode, 1);
  EXPECT_NE(missing.output.find("not a patch store"), std::string::npos) << missing.output;
  auto badEps = test::runTool("mtstore", "heal " + tmp.file("s") + " --weld -1");
  EXPECT_NE(badEps.exitCode, 0);
}

}  // namespace
}  // namespace mt
