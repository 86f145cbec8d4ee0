// The MT inspection tools (mtinfo, mtverify, mtextract) and the cut library they share
// (mtfile/mt_cut.h), on small MT files written here with MtFileWriter: a wavy scan-like grid cut
// in 4x4 level-0 tiles (the source's fragment), four level-1 nodes each simplifying a 2x2 group of
// tiles with the group's border locked (BMT section 4), one level-2 node over everything, a sink.
// Deliberately broken variants (a flipped payload byte, a non-monotone error, a moved border
// vertex) prove that the checks can fail.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <dirent.h>
#include <map>
#include <random>
#include <set>
#include <string>
#include <tuple>
#include <vector>

#include "base/error.h"
#include "mtfile/mt_cut.h"
#include "mtfile/mt_file.h"
#include "mtbuild/simplify_region.h"
#include "patchstore/io/mesh_reader.h"
#include "testing/scan_grid.h"
#include "tests/test_support.h"

using namespace mt;
using namespace mt::format;
using mt::test::runTool;
using mt::test::TempDir;

namespace {

// ---- Building a test MT --------------------------------------------------------------------

struct TestMtOptions {
  uint32_t holes = 0;
  bool normals = false;
  bool nonMonotone = false;       // level-2 error below its predecessors'
  bool moveBorderVertex = false;  // group 0's level-1 patch stores one vertex shared with group 1 off its q
  Codec codec = Codec::Meshopt;
};

struct TestMt {
  uint64_t triangles[3] = {0, 0, 0};  // per level
  uint32_t patches[3] = {0, 0, 0};
  float errors[7] = {};
  uint64_t inputTriangles = 0;
};

struct SubMesh {
  std::vector<double> positions;
  std::vector<uint32_t> triangles;
  std::vector<uint32_t> original;  // per vertex: its index in the full mesh
};

// The triangles `tris` (3 full-mesh indices each) with compact vertices.
SubMesh extract(const std::vector<double>& positions, const std::vector<uint32_t>& tris) {
  SubMesh s;
  std::map<uint32_t, uint32_t> local;
  for (uint32_t v : tris) {
    auto [it, inserted] = local.try_emplace(v, uint32_t(s.original.size()));
    if (inserted) {
      s.original.push_back(v);
      s.positions.insert(s.positions.end(), &positions[3 * v], &positions[3 * v + 3]);
    }
    s.triangles.push_back(it->second);
  }
  return s;
}

void sphereOf(const std::vector<double>& p, double center[3], float& radius) {
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (size_t i = 0; i < p.size(); i += 3)
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], p[i + a]), hi[a] = std::max(hi[a], p[i + a]);
  for (int a = 0; a < 3; ++a) center[a] = (lo[a] + hi[a]) / 2;
  double r = 0;
  for (size_t i = 0; i < p.size(); i += 3)
    r = std::max(r, std::sqrt(std::pow(p[i] - center[0], 2) + std::pow(p[i + 1] - center[1], 2) + std::pow(p[i + 2] - center[2], 2)));
  radius = float(r * (1 + 1e-6));
}

TestMt writeTestMt(const std::string& path, const TestMtOptions& opt) {
  ScanGridOptions go;
  go.nx = go.ny = 65;  // 64 x 64 cells, 8192 triangles
  go.holes = opt.holes;
  go.holeRadius = 3;
  ScanGrid g = makeScanGrid(go);
  TestMt out;
  out.inputTriangles = g.triangleCount();

  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (size_t i = 0; i < g.positions.size(); i += 3)
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], g.positions[i + a]), hi[a] = std::max(hi[a], g.positions[i + a]);
  QuantizationGrid grid = QuantizationGrid::fromBounds(lo, hi, 1.0 / 512);
  FileHeader h{};
  h.codec = uint32_t(opt.codec);
  h.vertexFlags = opt.normals ? kHasNormals : 0;
  h.levelCount = 3;
  h.inputTriangles = g.triangleCount();
  h.inputVertices = g.vertexCount();
  for (int a = 0; a < 3; ++a) h.boundsMin[a] = lo[a], h.boundsMax[a] = hi[a], h.gridOrigin[a] = grid.origin[a];
  h.gridStep = grid.step;
  h.gridBits = grid.bits;
  h.quantizationError = grid.maxError();
  PatchCodecOptions co;
  co.codec = opt.codec;
  co.normals = opt.normals;

  // Tiles of 16 x 16 cells by triangle centroid; groups of 2 x 2 tiles.
  std::vector<std::vector<uint32_t>> tileTris(16), groupTris(4);
  std::vector<uint8_t> groupMask(g.vertexCount(), 0);
  for (uint32_t t = 0; t < g.triangleCount(); ++t) {
    double c[2] = {0, 0};
    for (int k = 0; k < 3; ++k)
      for (int a = 0; a < 2; ++a) c[a] += g.positions[3 * g.triangles[3 * t + k] + a] / 3;
    int tx = std::clamp(int(c[0] / 16), 0, 3), ty = std::clamp(int(c[1] / 16), 0, 3);
    int tile = ty * 4 + tx, group = (ty / 2) * 2 + tx / 2;
    for (int k = 0; k < 3; ++k) {
      tileTris[tile].push_back(g.triangles[3 * t + k]);
      groupTris[group].push_back(g.triangles[3 * t + k]);
      groupMask[g.triangles[3 * t + k]] |= uint8_t(1u << group);
    }
  }

  MtFileWriter w(path, h);
  auto append = [&](const std::vector<double>& pos, const std::vector<uint32_t>& tris) {
    std::vector<uint8_t> payload =
        encodePatch({pos.data(), pos.size() / 3, tris.data(), tris.size() / 3, nullptr, nullptr}, grid, co);
    return w.appendPatch(payload.data(), payload.size(), uint32_t(tris.size() / 3), uint32_t(pos.size() / 3));
  };
  std::vector<NodeRecord> nodes(7);
  for (NodeRecord& n : nodes) n = NodeRecord{}, n.coneCutoff = -1;
  std::vector<DagArc> arcs;
  const float qErr = float(grid.maxError());

  // Source: the full resolution, one patch per tile, on the arc to the tile's group node.
  nodes[0].level = 0;
  nodes[0].error = qErr;
  sphereOf(g.positions, nodes[0].center, nodes[0].radius);
  for (int group = 0; group < 4; ++group) arcs.push_back({0, uint32_t(1 + group), {}});
  for (int tile = 0; tile < 16; ++tile) {
    SubMesh s = extract(g.positions, tileTris[tile]);
    int group = (tile / 4 / 2) * 2 + (tile % 4) / 2;
    arcs[group].patches.push_back(append(s.positions, s.triangles));
    out.triangles[0] += s.triangles.size() / 3;
    out.patches[0]++;
  }

  // Level 1: each group simplified to ~1/4 with the vertices other groups use locked.
  std::vector<uint32_t> level1Tris;  // full-mesh indices (half-edge collapse keeps input vertices)
  for (int group = 0; group < 4; ++group) {
    SubMesh s = extract(g.positions, groupTris[group]);
    std::vector<uint8_t> locked(s.original.size());
    for (size_t v = 0; v < locked.size(); ++v) locked[v] = (groupMask[s.original[v]] & ~(1u << group)) != 0;
    SimplifyRegionOptions so;
    so.targetTriangles = s.triangles.size() / 3 / 4;
    SimplifiedRegion sr = simplifyRegion(s.positions.data(), s.original.size(), s.triangles.data(), s.triangles.size() / 3,
                                         locked.data(), so);
    for (uint32_t v : sr.triangles) level1Tris.push_back(s.original[sr.origin[v]]);
    std::vector<double> pos = sr.positions;
    if (opt.moveBorderVertex && group == 0) {
      // A vertex shared with group 1 only (the x = 32 border, away from the corner), moved 3 grid
      // steps: group 1's tiles and patch keep it where it was.
      bool moved = false;
      for (uint32_t v = 0; v < sr.vertexCount() && !moved; ++v)
        if (groupMask[s.original[sr.origin[v]]] == 0b11 && pos[3 * v + 1] > 8 && pos[3 * v + 1] < 24) {
          pos[3 * v] += 3 * grid.step;
          moved = true;
        }
      EXPECT_TRUE(moved);
    }
    uint32_t node = 1 + group;
    nodes[node].level = 1;
    nodes[node].region = uint32_t(group);
    nodes[node].error = nodes[0].error + float(sr.error) + qErr;
    sphereOf(s.positions, nodes[node].center, nodes[node].radius);  // its floor (its fragment is inside)
    arcs.push_back({node, 5, {append(pos, sr.triangles)}});
    out.triangles[1] += sr.triangleCount();
    out.patches[1]++;
  }

  // Level 2: everything, simplified freely to ~1/4 again.
  {
    SubMesh s = extract(g.positions, level1Tris);
    SimplifyRegionOptions so;
    so.targetTriangles = s.triangles.size() / 3 / 4;
    SimplifiedRegion sr = simplifyRegion(s.positions.data(), s.original.size(), s.triangles.data(), s.triangles.size() / 3,
                                         nullptr, so);
    float maxBelow = 0;
    for (int k = 1; k <= 4; ++k) maxBelow = std::max(maxBelow, nodes[k].error);
    nodes[5].level = 2;
    nodes[5].error = maxBelow + float(sr.error) + qErr;
    if (opt.nonMonotone) nodes[5].error = nodes[1].error * 0.5f;
    sphereOf(s.positions, nodes[5].center, nodes[5].radius);
    for (int k = 1; k <= 4; ++k) {  // contain the level-1 spheres
      double d = std::sqrt(std::pow(nodes[k].center[0] - nodes[5].center[0], 2) + std::pow(nodes[k].center[1] - nodes[5].center[1], 2) +
                           std::pow(nodes[k].center[2] - nodes[5].center[2], 2));
      nodes[5].radius = std::max(nodes[5].radius, float((d + nodes[k].radius) * (1 + 1e-6)));
    }
    arcs.push_back({5, 6, {append(sr.positions, sr.triangles)}});
    out.triangles[2] += sr.triangleCount();
    out.patches[2]++;
  }
  nodes[6].level = 3;
  nodes[6].error = INFINITY;
  for (int k = 0; k < 7; ++k) out.errors[k] = nodes[k].error;
  w.finish(nodes, arcs);
  return out;
}

// ---- A minimal JSON reader (enough to check that mtinfo --json parses and holds numbers) ----

struct Json {
  enum Kind { Null, Number, String, Bool, Array, Object } kind = Null;
  double number = 0;
  std::string text;
  std::vector<Json> items;
  std::map<std::string, Json> fields;
  const Json& operator[](const std::string& k) const {
    static const Json none;
    auto it = fields.find(k);
    return it == fields.end() ? none : it->second;
  }
};

class JsonParser {
 public:
  explicit JsonParser(const std::string& s) : s_(s) {}
  Json parseAll() {
    Json j = value();
    space();
    if (i_ != s_.size()) throw Error("json: trailing text at " + std::to_string(i_));
    return j;
  }

 private:
  void space() {
    while (i_ < s_.size() && std::isspace(static_cast<unsigned char>(s_[i_]))) ++i_;
  }
  void expect(char c) {
    space();
    if (i_ >= s_.size() || s_[i_] != c) throw Error(std::string("json: expected '") + c + "' at " + std::to_string(i_));
    ++i_;
  }
  std::string str() {
    expect('"');
    std::string out;
    while (i_ < s_.size() && s_[i_] != '"') {
      if (s_[i_] == '\\') ++i_;
      out += s_[i_++];
    }
    expect('"');
    return out;
  }
  Json value() {
    space();
    Json j;
    if (i_ >= s_.size()) throw Error("json: unexpected end");
    char c = s_[i_];
    if (c == '{') {
      j.kind = Json::Object;
      ++i_;
      space();
      if (s_[i_] == '}') return ++i_, j;
      do {
        std::string k = str();
        expect(':');
        j.fields[k] = value();
        space();
      } while (s_[i_] == ',' && ++i_);
      expect('}');
    } else if (c == '[') {
      j.kind = Json::Array;
      ++i_;
      space();
      if (s_[i_] == ']') return ++i_, j;
      do {
        j.items.push_back(value());
        space();
      } while (s_[i_] == ',' && ++i_);
      expect(']');
    } else if (c == '"') {
      j.kind = Json::String;
      j.text = str();
    } else if (s_.compare(i_, 4, "null") == 0) {
      i_ += 4;
    } else if (s_.compare(i_, 4, "true") == 0 || s_.compare(i_, 5, "false") == 0) {
      j.kind = Json::Bool;
      i_ += s_[i_] == 't' ? 4 : 5;
    } else {
      size_t used = 0;
      j.kind = Json::Number;
      j.number = std::stod(s_.substr(i_), &used);
      i_ += used;
    }
    return j;
  }
  const std::string& s_;
  size_t i_ = 0;
};

// ---- Reading a PLY back -----------------------------------------------------------------------

struct PlyMesh {
  std::vector<double> positions;
  std::vector<uint32_t> triangles;
};

PlyMesh readPly(const std::string& path) {
  struct Sink : MeshSink {
    PlyMesh m;
    void vertices(const InputVertex* v, size_t n, uint64_t) override {
      for (size_t i = 0; i < n; ++i) m.positions.insert(m.positions.end(), v[i].p, v[i].p + 3);
    }
    void triangles(const uint32_t* t, size_t n) override { m.triangles.insert(m.triangles.end(), t, t + 3 * n); }
  } sink;
  openMesh(path)->read(sink);
  return sink.m;
}

// The PLY as a WeldedMesh on the file's grid, so mt_cut's conformity check can judge it.
WeldedMesh toWelded(const PlyMesh& ply, const MtFileReader& r) {
  WeldedMesh m;
  QuantizationGrid grid = r.grid();
  for (size_t i = 0; i < ply.positions.size(); i += 3)
    for (int a = 0; a < 3; ++a) {
      m.q.push_back(uint32_t(std::llround((ply.positions[i + a] - grid.origin[a]) / grid.step)));
      m.positions.push_back(ply.positions[i + a]);
    }
  m.triangles = ply.triangles;
  m.trianglePatch.assign(ply.triangles.size() / 3, 0);
  return m;
}

bool outputLeftBehind(const TempDir& dir, const std::string& prefix) {
  bool found = false;
  if (DIR* d = opendir(dir.path().c_str())) {
    while (dirent* e = readdir(d)) found |= std::string(e->d_name).rfind(prefix, 0) == 0;
    closedir(d);
  }
  return found;
}

uint64_t extractTriangles(const std::string& mt, const std::string& args, const std::string& ply) {
  auto res = runTool("mtextract", mt + " " + args + " -o " + ply);
  EXPECT_EQ(res.exitCode, 0) << res.output;
  return readPly(ply).triangles.size() / 3;
}

// ---- Library ------------------------------------------------------------------------------

TEST(MtCut, ValidCutsAndSelections) {
  TempDir dir;
  TestMt t = writeTestMt(dir.file("a.mt"), {});
  auto r = MtFileReader::open(dir.file("a.mt"));
  EXPECT_TRUE(isValidCut(*r, finestCut(*r).inSet));
  EXPECT_TRUE(isValidCut(*r, coarsestCut(*r).inSet));
  std::string why;
  std::vector<uint8_t> bad = {1, 0, 0, 0, 0, 1, 0};  // level 2 without its level-1 predecessors
  EXPECT_FALSE(isValidCut(*r, bad, &why));
  EXPECT_NE(why.find("predecessor"), std::string::npos) << why;
  EXPECT_EQ(closeUnderPredecessors(*r, bad), 4u);
  EXPECT_TRUE(isValidCut(*r, bad));
  EXPECT_FALSE(isValidCut(*r, {0, 0, 0, 0, 0, 0, 0}));
  EXPECT_FALSE(isValidCut(*r, {1, 1, 1, 1, 1, 1, 1}));

  EXPECT_EQ(cutStats(*r, finestCut(*r).inSet).triangles, t.triangles[0]);
  EXPECT_EQ(cutStats(*r, coarsestCut(*r).inSet).triangles, t.triangles[2]);
  EXPECT_EQ(cutArcs(*r, finestCut(*r).inSet).size(), 4u);
  EXPECT_EQ(cutArcs(*r, coarsestCut(*r).inSet).size(), 1u);

  std::mt19937_64 rng(7);
  std::set<std::vector<uint8_t>> seen;
  for (int k = 0; k < 40; ++k) {
    Cut c = randomCut(*r, rng);
    EXPECT_TRUE(isValidCut(*r, c.inSet, &why)) << why;
    seen.insert(c.inSet);
  }
  EXPECT_GE(seen.size(), 6u) << "random cuts should vary";

  // By error: monotone in E, between finest and coarsest, within E.
  uint64_t last = UINT64_MAX;
  std::vector<double> thresholds = {0.0, 1e9};
  for (int k = 0; k < 6; ++k) thresholds.push_back(t.errors[k]);
  std::sort(thresholds.begin(), thresholds.end());
  for (double e : thresholds) {
    Cut c = cutByError(*r, e);
    ASSERT_TRUE(isValidCut(*r, c.inSet));
    EXPECT_EQ(c.excludedByClosure, 0u);
    CutStats s = cutStats(*r, c.inSet);
    EXPECT_LE(s.triangles, last);
    EXPECT_GE(s.triangles, t.triangles[2]);
    EXPECT_LE(s.triangles, t.triangles[0]);
    if (e >= t.errors[0]) {
      EXPECT_LE(s.maxError, e);
    }
    last = s.triangles;
  }
  EXPECT_EQ(cutStats(*r, cutByError(*r, 0).inSet).triangles, t.triangles[0]);
  EXPECT_EQ(cutStats(*r, cutByError(*r, 1e9).inSet).triangles, t.triangles[2]);

  // By triangles: within budget whenever the budget admits the coarsest cut, more with more.
  uint64_t prev = 0;
  for (uint64_t n : {t.triangles[2], t.triangles[1], (t.triangles[1] + t.triangles[0]) / 2, t.triangles[0], t.triangles[0] * 2}) {
    Cut c = cutByTriangles(*r, n);
    ASSERT_TRUE(isValidCut(*r, c.inSet));
    CutStats s = cutStats(*r, c.inSet);
    EXPECT_LE(s.triangles, n);
    EXPECT_GE(s.triangles, prev);
    prev = s.triangles;
  }
  EXPECT_EQ(prev, t.triangles[0]);
  EXPECT_EQ(cutStats(*r, cutByTriangles(*r, 10).inSet).triangles, t.triangles[2]) << "below the coarsest: the coarsest";
}

TEST(MtCut, EveryCutOfAGoodFileIsConforming) {
  TempDir dir;
  for (uint32_t holes : {0u, 3u}) {
    writeTestMt(dir.file("a.mt"), {holes, holes > 0});
    auto r = MtFileReader::open(dir.file("a.mt"));
    WeldedMesh finest = assembleCut(*r, cutArcs(*r, finestCut(*r).inSet));
    ConformityReference ref = makeConformityReference(finest);
    EXPECT_GT(ref.edges.boundaryEdges, 0u) << "the outer rim";
    EXPECT_EQ(ref.edges.nonManifoldEdges, 0u);
    if (holes) {
      EXPECT_FALSE(finest.normals.empty());
    }
    // The DAG has 16 + 1 valid node sets: {source} + any subset of level 1, or everything.
    for (uint32_t mask = 0; mask <= 16; ++mask) {
      std::vector<uint8_t> in(7, 0);
      in[0] = 1;
      for (int k = 0; k < 4; ++k) in[1 + k] = mask == 16 || (mask >> k & 1);
      in[5] = mask == 16;
      ASSERT_TRUE(isValidCut(*r, in));
      WeldedMesh m = assembleCut(*r, cutArcs(*r, in));
      EXPECT_EQ(m.triangleCount(), cutStats(*r, in).triangles);
      ConformityReport rep = checkConforming(m, ref, r.get());
      EXPECT_TRUE(rep.conforming()) << "holes " << holes << " mask " << mask << ": " << rep.firstProblem;
      EdgeReport e = countEdges(m);
      EXPECT_EQ(e.nonManifoldEdges, 0u);
    }
  }
}

TEST(MtCut, CrackTestDetectsAMovedBorderVertexAndAMissingPatch) {
  TempDir dir;
  writeTestMt(dir.file("good.mt"), {});
  writeTestMt(dir.file("moved.mt"), {0, false, false, true});
  auto good = MtFileReader::open(dir.file("good.mt"));
  auto moved = MtFileReader::open(dir.file("moved.mt"));
  ConformityReference ref = makeConformityReference(assembleCut(*good, cutArcs(*good, finestCut(*good).inSet)));

  std::vector<uint8_t> group0 = {1, 1, 0, 0, 0, 0, 0};  // group 0 coarse, the rest at full resolution
  EXPECT_TRUE(checkConforming(assembleCut(*good, cutArcs(*good, group0)), ref).conforming());
  ConformityReport rep = checkConforming(assembleCut(*moved, cutArcs(*moved, group0)), ref, moved.get());
  EXPECT_FALSE(rep.conforming());
  EXPECT_GE(rep.newBoundaryEdges, 4u) << "both sides of the moved vertex open up";
  EXPECT_NE(rep.firstProblem.find("not on the input's boundary"), std::string::npos) << rep.firstProblem;
  EXPECT_NE(rep.firstProblem.find("(node "), std::string::npos) << rep.firstProblem;

  // A missing patch: drop one tile's patch from the finest cut.
  std::vector<uint32_t> arcs = cutArcs(*good, finestCut(*good).inSet);
  WeldedMesh full = assembleCut(*good, arcs);
  WeldedMesh holed;
  holed.q = full.q, holed.positions = full.positions;
  for (uint32_t t = 0; t < full.triangleCount(); ++t)
    if (full.trianglePatch[t] != 5) {
      holed.triangles.insert(holed.triangles.end(), &full.triangles[3 * t], &full.triangles[3 * t + 3]);
      holed.trianglePatch.push_back(full.trianglePatch[t]);
    }
  EXPECT_FALSE(checkConforming(holed, ref).conforming());

  // A patch present twice (two overlapping fragments): non-manifold edges.
  WeldedMesh twice = full;
  for (uint32_t t = 0; t < full.triangleCount(); ++t)
    if (full.trianglePatch[t] == 5) {
      twice.triangles.insert(twice.triangles.end(), &full.triangles[3 * t], &full.triangles[3 * t + 3]);
      twice.trianglePatch.push_back(5);
    }
  rep = checkConforming(twice, ref);
  EXPECT_GT(rep.newNonManifoldEdges, 0u);
  EXPECT_NE(rep.firstProblem.find("non-manifold"), std::string::npos) << rep.firstProblem;
}

// The bounded-memory check (mt_cut.h "Conformity in bounded memory") on a broken file, with a
// budget that splits the 8192-triangle finest cut into several parts: on each of the 17 valid
// node sets, the same reference and counts as the in-memory check; the moved vertex is found.
TEST(MtCut, BoundedCheckFindsTheMovedBorderVertexLikeTheInMemoryOne) {
  TempDir dir;
  writeTestMt(dir.file("moved.mt"), {0, false, false, true});
  auto r = MtFileReader::open(dir.file("moved.mt"));
  const std::vector<uint32_t> finest = cutArcs(*r, finestCut(*r).inSet);
  const ConformityReference ref = makeConformityReference(assembleCut(*r, finest));
  EdgeCountOptions o;
  o.memoryBytes = 256 << 10;
  EdgeCountStats st;
  const ConformityReference bounded = makeConformityReference(*r, finest, o, &st);
  EXPECT_GT(st.parts, 1u);
  EXPECT_TRUE(bounded.boundaryVertices == ref.boundaryVertices);
  EXPECT_TRUE(bounded.nonManifoldVertices == ref.nonManifoldVertices);
  EXPECT_EQ(bounded.edges.edges, ref.edges.edges);
  uint32_t cracked = 0;
  for (uint32_t mask = 0; mask <= 16; ++mask) {
    std::vector<uint8_t> in(7, 0);
    in[0] = 1;
    for (int k = 0; k < 4; ++k) in[1 + k] = mask == 16 || (mask >> k & 1);
    in[5] = mask == 16;
    const ConformityReport a = checkConforming(assembleCut(*r, cutArcs(*r, in)), ref, r.get());
    const ConformityReport b = checkConforming(*r, cutArcs(*r, in), bounded, o);
    EXPECT_EQ(b.edges.edges, a.edges.edges) << mask;
    EXPECT_EQ(b.edges.boundaryEdges, a.edges.boundaryEdges) << mask;
    EXPECT_EQ(b.edges.nonManifoldEdges, a.edges.nonManifoldEdges) << mask;
    EXPECT_EQ(b.newBoundaryEdges, a.newBoundaryEdges) << mask;
    EXPECT_EQ(b.newNonManifoldEdges, a.newNonManifoldEdges) << mask;
    if (!b.conforming()) {
      ++cracked;
      EXPECT_NE(b.firstProblem.find("is not on the input's boundary"), std::string::npos) << b.firstProblem;
      EXPECT_NE(b.firstProblem.find(" (node "), std::string::npos) << b.firstProblem;
    }
  }
  EXPECT_GT(cracked, 0u) << "group 0 coarse next to group 1 at full resolution opens the moved vertex";
}

TEST(MtCut, ViewDependentRefinesNearTheEye) {
  TempDir dir;
  writeTestMt(dir.file("a.mt"), {});
  auto r = MtFileReader::open(dir.file("a.mt"));
  ViewParams v;
  v.eye[0] = -5, v.eye[1] = -5, v.eye[2] = 10;
  v.target[0] = 64, v.target[1] = 64, v.target[2] = 0;
  v.widthPixels = 1000;
  v.pixelTolerance = 4;
  Cut c = cutViewDependent(*r, v);
  ASSERT_TRUE(isValidCut(*r, c.inSet));
  EXPECT_GT(screenSpaceError(r->nodes()[1], v), screenSpaceError(r->nodes()[4], v));
  EXPECT_FALSE(c.inSet[1]) << "group 0, at the eye, is at full resolution";
  EXPECT_TRUE(c.inSet[4]) << "group 3, far away, is coarse";
  // Behind the eye: nothing needs refinement, the coarsest cut.
  v.target[0] = -100, v.target[1] = -100;
  EXPECT_EQ(cutViewDependent(*r, v).inSet, coarsestCut(*r).inSet);
}

// ---- mtinfo -----------------------------------------------------------------------------------

TEST(MtInfo, CountsTextAndJson) {
  TempDir dir;
  const std::string mt = dir.file("a.mt");
  TestMt t = writeTestMt(mt, {});
  auto text = runTool("mtinfo", mt);
  ASSERT_EQ(text.exitCode, 0) << text.output;
  EXPECT_NE(text.output.find("3 levels, 7 nodes, 9 arcs, depth 3"), std::string::npos) << text.output;
  EXPECT_NE(text.output.find("meshopt"), std::string::npos);

  auto res = runTool("mtinfo", mt + " --json");
  ASSERT_EQ(res.exitCode, 0) << res.output;
  Json j = JsonParser(res.output).parseAll();
  EXPECT_EQ(j["levels"].number, 3);
  EXPECT_EQ(j["nodes"].number, 7);
  EXPECT_EQ(j["arcs"].number, 9);
  EXPECT_EQ(j["patches"].number, 21);
  EXPECT_EQ(j["codec"].text, "meshopt");
  EXPECT_EQ(j["inputTriangles"].number, double(t.inputTriangles));
  EXPECT_EQ(j["storedTriangles"].number, double(t.triangles[0] + t.triangles[1] + t.triangles[2]));
  EXPECT_EQ(j["fileBytes"].number, double(test::readFile(mt).size()));
  EXPECT_NEAR(j["bytesPerInputTriangle"].number, j["fileBytes"].number / double(t.inputTriangles), 1e-6);
  EXPECT_DOUBLE_EQ(j["gridStep"].number, 1.0 / 512);
  EXPECT_EQ(j["dag"]["depth"].number, 3);
  EXPECT_EQ(j["dag"]["backwardStarMax"].number, 4);
  EXPECT_NEAR(j["dag"]["backwardStarMean"].number, 1.6, 1e-9);
  EXPECT_EQ(j["dag"]["forwardStarMax"].number, 1);
  ASSERT_EQ(j["perLevel"].items.size(), 3u);
  const uint32_t levelNodes[3] = {1, 4, 1};
  for (int l = 0; l < 3; ++l) {
    const Json& L = j["perLevel"].items[l];
    EXPECT_EQ(L["level"].number, l);
    EXPECT_EQ(L["nodes"].number, levelNodes[l]);
    EXPECT_EQ(L["patches"].number, t.patches[l]);
    EXPECT_EQ(L["triangles"].number, double(t.triangles[l]));
    EXPECT_LE(L["errorMin"].number, L["errorMax"].number);
  }
  EXPECT_FLOAT_EQ(float(j["perLevel"].items[2]["errorMax"].number), t.errors[5]);
  EXPECT_EQ(runTool("mtinfo", mt + " --check").exitCode, 0);
}

// One payload byte flipped: open still works (the index is intact); --check and mtverify name it.
std::string flipPayloadByte(const std::string& mt, uint32_t patch) {
  std::string bytes = test::readFile(mt);
  auto r = MtFileReader::open(mt);
  bytes[r->patches()[patch].offset + r->patches()[patch].size / 2] ^= 0x10;
  test::writeFile(mt, bytes);
  return mt;
}

TEST(MtInfo, DamagedFiles) {
  TempDir dir;
  const std::string mt = dir.file("a.mt");
  writeTestMt(mt, {});
  flipPayloadByte(mt, 5);
  EXPECT_EQ(runTool("mtinfo", mt).exitCode, 0) << "metadata is fine";
  auto res = runTool("mtinfo", mt + " --check");
  EXPECT_EQ(res.exitCode, 3);
  EXPECT_NE(res.output.find(mt + ": patch 5 is damaged"), std::string::npos) << res.output;
  EXPECT_NE(res.output.find("[node 0, level 0]"), std::string::npos) << res.output;
  EXPECT_NE(res.output.find("1 damaged"), std::string::npos) << res.output;

  // Damaged metadata (a byte of the DAG section): one line naming the file, exit 3.
  std::string bytes = test::readFile(mt);
  bytes[bytes.size() - kFooterSize - 40] ^= 0x01;
  test::writeFile(mt, bytes);
  res = runTool("mtinfo", mt);
  EXPECT_EQ(res.exitCode, 3);
  EXPECT_NE(res.output.find("mtinfo: " + mt + ": checksum mismatch"), std::string::npos) << res.output;
  EXPECT_EQ(std::count(res.output.begin(), res.output.end(), '\n'), 1) << res.output;

  res = runTool("mtinfo", dir.file("missing.mt"));
  EXPECT_EQ(res.exitCode, 1);
  EXPECT_NE(res.output.find("missing.mt: no such file"), std::string::npos) << res.output;
}

// ---- mtverify -------------------------------------------------------------------------------

TEST(MtVerify, PassesOnGoodFiles) {
  TempDir dir;
  for (bool holes : {false, true}) {
    const std::string mt = dir.file(holes ? "holes.mt" : "a.mt");
    writeTestMt(mt, {holes ? 3u : 0u, holes, false, false, holes ? Codec::Draco : Codec::Meshopt});
    auto res = runTool("mtverify", mt + " --cuts 12");
    EXPECT_EQ(res.exitCode, 0) << res.output;
    EXPECT_NE(res.output.find("14 of 14 conforming"), std::string::npos) << res.output;
    EXPECT_NE(res.output.find("\nOK"), std::string::npos) << res.output;
  }
}

TEST(MtVerify, FlippedPayloadByte) {
  TempDir dir;
  const std::string mt = dir.file("a.mt");
  writeTestMt(mt, {});
  flipPayloadByte(mt, 5);
  flipPayloadByte(mt, 17);
  auto res = runTool("mtverify", mt);
  EXPECT_EQ(res.exitCode, 3) << res.output;
  EXPECT_NE(res.output.find(mt + ": patch 5 is damaged"), std::string::npos) << res.output;
  EXPECT_NE(res.output.find(mt + ": patch 17 is damaged"), std::string::npos) << "keeps going: " << res.output;
  EXPECT_NE(res.output.find("2 damaged"), std::string::npos) << res.output;
  EXPECT_NE(res.output.find("FAILED"), std::string::npos) << res.output;
}

TEST(MtVerify, NonMonotoneError) {
  TempDir dir;
  const std::string mt = dir.file("a.mt");
  TestMt t = writeTestMt(mt, {0, false, true});
  auto res = runTool("mtverify", mt);
  EXPECT_EQ(res.exitCode, 3) << res.output;
  EXPECT_NE(res.output.find("error not monotone: node 5 (level 2)"), std::string::npos) << res.output;
  EXPECT_NE(res.output.find("monotone errors  PROBLEMS"), std::string::npos) << res.output;
  EXPECT_NE(res.output.find("crack-free cuts  10 of 10"), std::string::npos) << "only the errors are wrong: " << res.output;

  // mtextract keeps its bound on such a file: node 5 is within E but left out, with a warning.
  auto r = MtFileReader::open(mt);
  double e = t.errors[5];
  Cut c = cutByError(*r, e);
  EXPECT_FALSE(c.inSet[5]);
  EXPECT_GT(c.excludedByClosure, 0u);
  char eText[32];
  std::snprintf(eText, sizeof eText, "%.17g", e);  // exact: std::to_string's 6 decimals may round below the source's error
  auto ex = runTool("mtextract", mt + " --error " + eText + " -o " + dir.file("c.ply"));
  EXPECT_EQ(ex.exitCode, 0) << ex.output;
  EXPECT_NE(ex.output.find("not monotone"), std::string::npos) << ex.output;
}

TEST(MtVerify, MovedBorderVertexIsACrack) {
  TempDir dir;
  const std::string mt = dir.file("a.mt");
  writeTestMt(mt, {0, false, false, true});
  auto res = runTool("mtverify", mt + " --cuts 40 --seed 3");
  EXPECT_EQ(res.exitCode, 3) << res.output;
  EXPECT_NE(res.output.find("crack in random cut"), std::string::npos) << res.output;
  EXPECT_NE(res.output.find("is not on the input's boundary"), std::string::npos) << res.output;
  EXPECT_NE(res.output.find("monotone errors  ok"), std::string::npos) << res.output;
  EXPECT_NE(res.output.find("nested spheres   ok"), std::string::npos) << res.output;
}

// --memory changes how the crack check splits its work, never what it reports: a budget small
// enough for several parts per cut gives the very same output, on a good and on a broken file.
TEST(MtVerify, MemoryBudgetDoesNotChangeTheOutput) {
  TempDir dir;
  const std::string good = dir.file("good.mt"), moved = dir.file("moved.mt");
  writeTestMt(good, {3, false});
  writeTestMt(moved, {0, false, false, true});
  for (const std::string& mt : {good, moved}) {
    auto big = runTool("mtverify", mt + " --cuts 40 --seed 3");
    auto small = runTool("mtverify", mt + " --cuts 40 --seed 3 --memory 256K");
    EXPECT_EQ(big.exitCode, mt == good ? 0 : 3) << big.output;
    EXPECT_EQ(small.exitCode, big.exitCode) << small.output;
    EXPECT_EQ(small.output, big.output);
  }
  auto bad = runTool("mtverify", good + " --memory 12Q");
  EXPECT_EQ(bad.exitCode, 1);
  EXPECT_NE(bad.output.find("invalid size unit in '12Q'"), std::string::npos) << bad.output;
}

TEST(MtVerify, HelpAndBadArguments) {
  auto help = runTool("mtverify", "--help");
  EXPECT_EQ(help.exitCode, 0);
  for (const char* s : {"--cuts", "--seed", "--memory", "crack"}) EXPECT_NE(help.output.find(s), std::string::npos) << s;
  EXPECT_EQ(help.output.find("60 bytes"), std::string::npos) << "cuts are no longer held whole";
  EXPECT_EQ(runTool("mtverify", "").exitCode, 1);
  EXPECT_EQ(runTool("mtverify", "/nonexistent.mt").exitCode, 1);
  auto info = runTool("mtinfo", "--help");
  EXPECT_EQ(info.exitCode, 0);
  for (const char* s : {"--json", "--check"}) EXPECT_NE(info.output.find(s), std::string::npos) << s;
}

// ---- mtextract ------------------------------------------------------------------------------

TEST(MtExtract, ByErrorIsMonotoneWeldedAndConforming) {
  TempDir dir;
  const std::string mt = dir.file("a.mt");
  TestMt t = writeTestMt(mt, {3, true});
  auto r = MtFileReader::open(mt);
  ConformityReference ref = makeConformityReference(assembleCut(*r, cutArcs(*r, finestCut(*r).inSet)));
  std::vector<double> es = {0};
  for (int k = 0; k < 6; ++k) es.push_back(t.errors[k] * 1.0001);
  std::sort(es.begin(), es.end());
  uint64_t last = UINT64_MAX;
  for (double e : es) {
    const std::string ply = dir.file("cut.ply");
    auto res = runTool("mtextract", mt + " --error " + std::to_string(e) + " -o " + ply);
    ASSERT_EQ(res.exitCode, 0) << res.output;
    EXPECT_NE(res.output.find("triangles"), std::string::npos);
    EXPECT_NE(res.output.find("max error"), std::string::npos);
    PlyMesh m = readPly(ply);
    uint64_t tris = m.triangles.size() / 3;
    EXPECT_LE(tris, last) << "E " << e;
    EXPECT_GE(tris, t.triangles[2]);
    EXPECT_LE(tris, t.triangles[0]);
    last = tris;
    std::set<std::tuple<double, double, double>> distinct;
    for (size_t i = 0; i < m.positions.size(); i += 3) distinct.insert({m.positions[i], m.positions[i + 1], m.positions[i + 2]});
    EXPECT_EQ(distinct.size(), m.positions.size() / 3) << "welded: no duplicate positions";
    ConformityReport rep = checkConforming(toWelded(m, *r), ref);
    EXPECT_TRUE(rep.conforming()) << "E " << e << ": " << rep.firstProblem;
  }
  EXPECT_EQ(last, t.triangles[2]);
  EXPECT_EQ(extractTriangles(mt, "--error 0", dir.file("f.ply")), t.triangles[0]);
}

TEST(MtExtract, ByTrianglesAndViewDependent) {
  TempDir dir;
  const std::string mt = dir.file("a.mt");
  TestMt t = writeTestMt(mt, {});
  for (uint64_t n : {t.triangles[2], t.triangles[1] + 100, (t.triangles[0] + t.triangles[1]) / 2, t.triangles[0]})
    EXPECT_LE(extractTriangles(mt, "--triangles " + std::to_string(n), dir.file("n.ply")), n);
  EXPECT_EQ(extractTriangles(mt, "--triangles " + std::to_string(t.triangles[0]), dir.file("n.ply")), t.triangles[0]);
  auto res = runTool("mtextract", mt + " --triangles 5 -o " + dir.file("small.ply"));
  EXPECT_EQ(res.exitCode, 0);
  EXPECT_NE(res.output.find("warning: the coarsest cut has"), std::string::npos) << res.output;

  // View-dependent: denser near the eye (x, y < 32) than far (x, y >= 32).
  const std::string ply = dir.file("view.ply");
  res = runTool("mtextract", mt + " --eye -5,-5,10 --target 64,64,0 --fov 60 --width 1000 --pixels 4 -o " + ply);
  ASSERT_EQ(res.exitCode, 0) << res.output;
  EXPECT_NE(res.output.find("screen-space error"), std::string::npos) << res.output;
  PlyMesh m = readPly(ply);
  uint64_t nearTris = 0, farTris = 0;
  for (size_t k = 0; k < m.triangles.size(); k += 3) {
    double cx = 0, cy = 0;
    for (int c = 0; c < 3; ++c) cx += m.positions[3 * m.triangles[k + c]] / 3, cy += m.positions[3 * m.triangles[k + c] + 1] / 3;
    if (cx < 32 && cy < 32) ++nearTris;
    if (cx >= 32 && cy >= 32) ++farTris;
  }
  EXPECT_GT(nearTris, 2 * farTris) << nearTris << " near, " << farTris << " far";
  // With a budget below what the tolerance wants, the budget wins.
  uint64_t budgeted = extractTriangles(mt, "--eye -5,-5,10 --target 64,64,0 --pixels 0.01 --triangles " +
                                               std::to_string(t.triangles[1] + 1000), dir.file("vb.ply"));
  EXPECT_LE(budgeted, t.triangles[1] + 1000);
}

TEST(MtExtract, BadArgumentsLeaveNoOutput) {
  TempDir dir;
  const std::string mt = dir.file("a.mt");
  writeTestMt(mt, {});
  const std::string out = dir.file("cut.ply");
  struct Case {
    std::string args, needle;
  } cases[] = {
      {dir.file("missing.mt") + " --error 1", "missing.mt: no such file"},
      {mt + " --error 1 --triangles 100", "--error and --triangles are exclusive"},
      {mt, "give --error E, --triangles N or --eye/--target"},
      {mt + " --eye 1,2,3 --error 1", "exclusive"},
      {mt + " --eye 1,2", "--eye and --target go together"},
      {mt + " --eye 1,2 --target 3,4,5", "--eye wants X,Y,Z"},
      {mt + " --eye 1,2,x --target 3,4,5", "is not a number"},
      {mt + " --error -1", "--error: must be a finite number >= 0"},
  };
  for (const Case& c : cases) {
    auto res = runTool("mtextract", c.args + " -o " + out);
    EXPECT_EQ(res.exitCode, 1) << c.args << "\n" << res.output;
    EXPECT_NE(res.output.find(c.needle), std::string::npos) << c.args << "\n" << res.output;
    EXPECT_FALSE(outputLeftBehind(dir, "cut.ply")) << c.args;
  }
  EXPECT_EQ(runTool("mtextract", mt + " --error 1").exitCode, 1) << "-o is required";

  // A damaged payload inside the cut: exit 3 naming the patch, nothing written.
  flipPayloadByte(mt, 3);
  auto res = runTool("mtextract", mt + " --error 0 -o " + out);
  EXPECT_EQ(res.exitCode, 3);
  EXPECT_NE(res.output.find("patch 3 is damaged"), std::string::npos) << res.output;
  EXPECT_FALSE(outputLeftBehind(dir, "cut.ply"));
  // Damaged metadata.
  std::string bytes = test::readFile(mt);
  bytes[bytes.size() - kFooterSize - 8] ^= 0x01;
  test::writeFile(mt, bytes);
  res = runTool("mtextract", mt + " --error 1 -o " + out);
  EXPECT_EQ(res.exitCode, 3);
  EXPECT_NE(res.output.find(mt + ": checksum mismatch"), std::string::npos) << res.output;
  EXPECT_FALSE(outputLeftBehind(dir, "cut.ply"));

  auto help = runTool("mtextract", "--help");
  EXPECT_EQ(help.exitCode, 0);
  for (const char* s : {"--error", "--triangles", "--eye", "--target", "--fov", "--width", "--pixels", "--output"})
    EXPECT_NE(help.output.find(s), std::string::npos) << s;
}

}  // namespace
