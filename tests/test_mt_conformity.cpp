// The crack-free check in bounded memory (mtfile/mt_cut.h "Conformity in bounded memory")
// against the in-memory one (assembleCut + makeConformityReference + checkConforming), on MT
// files built by mtgen + mtbuild: the same reference and the same counts for every cut, whatever
// the budget and the way the edges are split into parts (k-d boxes, hash ranges, parts that
// overflow and are split again), and the same verdict on deliberately broken cuts, with a first
// problem that is a real violating edge.
#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cstdio>
#include <map>
#include <random>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "base/error.h"
#include "mtfile/mt_cut.h"
#include "mtfile/mt_file.h"
#include "tests/test_support.h"

namespace mt::test {
namespace {

std::string buildMt(const TempDir& tmp, const std::string& mtgen, const std::string& mtbuild) {
  const std::string in = mtgen.empty() ? writeNonManifoldPly(tmp) : tmp.file("in.ply");
  if (!mtgen.empty()) {
    CommandResult g = runTool("mtgen", "-o " + in + " " + mtgen);
    EXPECT_EQ(g.exitCode, 0) << g.output;
  }
  const std::string out = tmp.file("c.mt");
  CommandResult b = runTool("mtbuild", in + " -o " + out + " -q " + mtbuild);
  EXPECT_EQ(b.exitCode, 0) << b.output;
  return out;
}

// The file's patch boxes, as mtverify gathers them during its payload pass.
std::vector<GridBox> allPatchBoxes(const MtFileReader& r) {
  std::vector<GridBox> boxes(r.patches().size(), GridBox::everything());
  EXPECT_TRUE(checkAllPatches(r, [&](uint32_t p, const DecodedPatch& d) { boxes[p] = patchBox(d); }).empty());
  return boxes;
}

void expectSameReport(const ConformityReport& bounded, const ConformityReport& inMemory, const std::string& what) {
  EXPECT_EQ(bounded.edges.edges, inMemory.edges.edges) << what;
  EXPECT_EQ(bounded.edges.boundaryEdges, inMemory.edges.boundaryEdges) << what;
  EXPECT_EQ(bounded.edges.nonManifoldEdges, inMemory.edges.nonManifoldEdges) << what;
  EXPECT_EQ(bounded.newBoundaryEdges, inMemory.newBoundaryEdges) << what;
  EXPECT_EQ(bounded.newNonManifoldEdges, inMemory.newNonManifoldEdges) << what;
  EXPECT_EQ(bounded.firstProblem.empty(), inMemory.firstProblem.empty()) << what << ": " << bounded.firstProblem;
}

std::string point(const MtFileReader& r, const GridKey& q) {
  const QuantizationGrid g = r.grid();
  char buf[128];
  std::snprintf(buf, sizeof buf, "(%.9g,%.9g,%.9g)", g.dequantize(0, q[0]), g.dequantize(1, q[1]), g.dequantize(2, q[2]));
  return buf;
}

// Every edge of the assembled cut that breaks the rule, as "boundary edge A-B" / "non-manifold
// edge (used N times) A-B" (smaller q first, as the bounded check prints it), each with the
// patches holding it: the bounded check's firstProblem must start with one of these.
std::map<std::string, std::set<uint32_t>> violations(const MtFileReader& r, const WeldedMesh& m, const ConformityReference& ref) {
  auto key = [&](uint32_t v) { return GridKey{m.q[3 * v], m.q[3 * v + 1], m.q[3 * v + 2]}; };
  std::map<std::pair<GridKey, GridKey>, std::vector<uint32_t>> uses;  // edge -> patch per use
  for (uint32_t t = 0; t < m.triangleCount(); ++t)
    for (int c = 0; c < 3; ++c) {
      GridKey a = key(m.triangles[3 * t + c]), b = key(m.triangles[3 * t + (c + 1) % 3]);
      if (b < a) std::swap(a, b);
      uses[{a, b}].push_back(m.trianglePatch[t]);
    }
  auto in = [](const std::vector<GridKey>& list, const GridKey& k) { return std::binary_search(list.begin(), list.end(), k); };
  std::map<std::string, std::set<uint32_t>> out;
  for (const auto& [edge, patches] : uses) {
    if (patches.size() == 2) continue;
    const bool boundary = patches.size() == 1;
    const auto& list = boundary ? ref.boundaryVertices : ref.nonManifoldVertices;
    if (in(list, edge.first) && in(list, edge.second)) continue;
    const std::string what = boundary ? "boundary edge " : "non-manifold edge (used " + std::to_string(patches.size()) + " times) ";
    out[what + point(r, edge.first) + "-" + point(r, edge.second)].insert(patches.begin(), patches.end());
  }
  return out;
}

// firstProblem names a real violating edge, the lowest patch holding it and that patch's node.
void expectRealViolation(const MtFileReader& r, const ConformityReport& rep, const std::map<std::string, std::set<uint32_t>>& all) {
  ASSERT_FALSE(rep.firstProblem.empty());
  const size_t of = rep.firstProblem.find(" of patch ");
  ASSERT_NE(of, std::string::npos) << rep.firstProblem;
  auto it = all.find(rep.firstProblem.substr(0, of));
  ASSERT_NE(it, all.end()) << "not a violating edge: " << rep.firstProblem;
  const uint32_t patch = *it->second.begin();
  const std::string tail = " of patch " + std::to_string(patch) + " (node " + std::to_string(r.arcs()[r.patches()[patch].arc].from) + ") ";
  EXPECT_EQ(rep.firstProblem.compare(of, tail.size(), tail), 0) << rep.firstProblem << " / expected" << tail;
}

struct Variant {
  const char* name;
  uint64_t memory;
  bool boxes;       // pass the file's patch boxes (else the check computes them)
  bool spatial;
  double edgesPerTriangle;
};
EdgeCountOptions optionsOf(const Variant& v, const std::vector<GridBox>& boxes) {
  EdgeCountOptions o;
  o.memoryBytes = v.memory;
  o.patchBoxes = v.boxes ? &boxes : nullptr;
  o.spatialParts = v.spatial;
  o.edgesPerTriangle = v.edgesPerTriangle;
  return o;
}
// 512 KiB: a table of 12288 slots (the lists take a quarter while the reference is built): the
// finest cut of these 14-24k triangle meshes needs several parts.
const Variant kVariants[] = {
    {"one part", uint64_t(1) << 30, true, true, 1.5},
    {"k-d parts", 512 << 10, true, true, 1.5},
    {"k-d parts, boxes computed", 512 << 10, false, true, 1.5},
    {"hash parts", 512 << 10, true, false, 1.5},
    {"parts planned too big, split", 512 << 10, true, true, 0.2},
    {"hash parts planned too big, split", 512 << 10, false, false, 0.2},
};

TEST(BoundedConformity, SameReferenceAndCountsAsInMemoryOnClosedHoledMultiComponentAndNonManifoldMeshes) {
  struct Case {
    const char* name;
    const char* mtgen;  // empty: writeNonManifoldPly
    const char* mtbuild;
    bool nonManifold;
  };
  const Case cases[] = {
      {"closed", "--triangles 20k --seed 11", "--patch-triangles 300", false},
      {"holes", "--triangles 24k --holes 16 --shuffle --seed 12", "--patch-triangles 300", false},
      {"components", "--triangles 24k --components 4 --density varying --seed 13", "--patch-triangles 300", false},
      {"non-manifold", "", "--patch-triangles 300", true},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    TempDir tmp;
    auto r = MtFileReader::open(buildMt(tmp, c.mtgen, c.mtbuild));
    const std::vector<GridBox> boxes = allPatchBoxes(*r);
    const std::vector<uint32_t> finest = cutArcs(*r, finestCut(*r).inSet);
    const ConformityReference ref = makeConformityReference(assembleCut(*r, finest));
    EXPECT_EQ(ref.edges.nonManifoldEdges > 0, c.nonManifold);

    std::vector<std::pair<std::string, std::vector<uint32_t>>> cuts = {{"finest", finest},
                                                                       {"coarsest", cutArcs(*r, coarsestCut(*r).inSet)}};
    std::mt19937_64 rng(5);
    for (int k = 0; k < 3; ++k) cuts.push_back({"random " + std::to_string(k), cutArcs(*r, randomCut(*r, rng).inSet)});
    std::vector<ConformityReport> inMemory;
    for (const auto& [name, arcs] : cuts) inMemory.push_back(checkConforming(assembleCut(*r, arcs), ref, r.get()));

    for (const Variant& v : kVariants) {
      SCOPED_TRACE(v.name);
      const EdgeCountOptions o = optionsOf(v, boxes);
      EdgeCountStats st;
      const ConformityReference bounded = makeConformityReference(*r, finest, o, &st);
      EXPECT_EQ(bounded.edges.edges, ref.edges.edges);
      EXPECT_EQ(bounded.edges.boundaryEdges, ref.edges.boundaryEdges);
      EXPECT_EQ(bounded.edges.nonManifoldEdges, ref.edges.nonManifoldEdges);
      EXPECT_TRUE(bounded.boundaryVertices == ref.boundaryVertices);
      EXPECT_TRUE(bounded.nonManifoldVertices == ref.nonManifoldVertices);
      EXPECT_EQ(st.triangles, cutStats(*r, finestCut(*r).inSet).triangles);
      EXPECT_LE(st.tableBytes, v.memory);
      if (v.memory < (1 << 20)) {
        EXPECT_GE(st.parts, 3u) << "the budget must force several parts";
        EXPECT_GE(st.patchReads, st.patches);
      } else {
        EXPECT_EQ(st.parts, 1u);
        EXPECT_EQ(st.patchReads, st.patches) << "one part, boxes given: each patch read once";
      }
      if (v.edgesPerTriangle < 1) {
        EXPECT_GT(st.splitParts, 0u) << "an underestimate must overflow parts";
      }
      if (v.spatial && v.boxes && v.memory < (1 << 20) && v.edgesPerTriangle >= 1) {
        EXPECT_LT(double(st.patchReads), 2.5 * double(st.patches)) << "k-d parts read only the patches near them";
      }

      for (size_t k = 0; k < cuts.size(); ++k) {
        const ConformityReport rep = checkConforming(*r, cuts[k].second, bounded, o, &st);
        expectSameReport(rep, inMemory[k], cuts[k].first);
        EXPECT_TRUE(rep.conforming()) << cuts[k].first << ": " << rep.firstProblem;
      }
    }
  }
}

// Broken cuts: the finest cut without one arc's patches (a hole bordered by interior vertices),
// and with one arc's patches twice (every edge of them used three or four times). Both checks
// must call them non-conforming with the same counts; the bounded one names a real violating
// edge, and the same one whatever the budget.
TEST(BoundedConformity, BrokenCutsAreNonConformingInBothWithARealFirstProblem) {
  TempDir tmp;
  auto r = MtFileReader::open(buildMt(tmp, "--triangles 30k --holes 6 --seed 7", "--patch-triangles 300"));
  const std::vector<GridBox> boxes = allPatchBoxes(*r);
  const std::vector<uint32_t> finest = cutArcs(*r, finestCut(*r).inSet);
  ASSERT_GE(finest.size(), 4u);
  const ConformityReference ref = makeConformityReference(assembleCut(*r, finest));

  std::vector<uint32_t> missing = finest, twice = finest;
  missing.erase(missing.begin() + long(finest.size() / 2));
  twice.push_back(finest[finest.size() / 3]);
  // A coarse cut with one level-1 node's fragment pasted twice.
  std::vector<uint32_t> coarseTwice = cutArcs(*r, coarsestCut(*r).inSet);
  coarseTwice.push_back(coarseTwice.front());

  for (const auto& [name, arcs] : {std::pair{"missing arc", missing}, std::pair{"arc twice", twice}, std::pair{"coarse arc twice", coarseTwice}}) {
    SCOPED_TRACE(name);
    const WeldedMesh mesh = assembleCut(*r, arcs);
    const ConformityReport inMemory = checkConforming(mesh, ref, r.get());
    ASSERT_FALSE(inMemory.conforming());
    const auto all = violations(*r, mesh, ref);
    ASSERT_EQ(all.size(), inMemory.newBoundaryEdges + inMemory.newNonManifoldEdges);
    std::string first;
    for (const Variant& v : kVariants) {
      SCOPED_TRACE(v.name);
      const EdgeCountOptions o = optionsOf(v, boxes);
      EdgeCountStats st;
      const ConformityReport rep = checkConforming(*r, arcs, ref, o, &st);
      expectSameReport(rep, inMemory, name);
      EXPECT_FALSE(rep.conforming());
      expectRealViolation(*r, rep, all);
      if (first.empty()) first = rep.firstProblem;
      EXPECT_EQ(rep.firstProblem, first) << "the smallest violating edge, whatever the parts";
      EXPECT_EQ(checkConforming(*r, arcs, ref, o).firstProblem, rep.firstProblem) << "deterministic";
      if (v.memory < (1 << 20) && std::string(name) != "coarse arc twice") {
        EXPECT_GT(st.parts, 1u);
      }
    }
    const bool hole = std::string(name) == "missing arc";
    EXPECT_NE(first.find(hole ? "is not on the input's boundary" : "is not one of the input's non-manifold edges"), std::string::npos) << first;
  }
}

// A damaged payload on the cut throws its readPatch error, as assembleCut does; the reference's
// lists beyond a quarter of the budget are a clear error, not a budget overrun.
TEST(BoundedConformity, DamagedPatchesAndTooSmallABudgetAreClearErrors) {
  TempDir tmp;
  const std::string mt = buildMt(tmp, "--triangles 30k --holes 20 --seed 9", "--patch-triangles 300");
  {
    auto r = MtFileReader::open(mt);
    const std::vector<uint32_t> finest = cutArcs(*r, finestCut(*r).inSet);
    EdgeCountOptions o;
    o.memoryBytes = 16 << 10;  // lists may take 4 KiB: 341 vertices; the holes have more
    try {
      makeConformityReference(*r, finest, o);
      ADD_FAILURE() << "expected an error";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find("quarter of the memory budget"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(mt), std::string::npos) << e.what();
    }
  }
  // Damage the middle of patch 3's payload (a level-0 patch: it is on the finest cut).
  std::string bytes = readFile(mt);
  {
    auto r = MtFileReader::open(mt);
    ASSERT_EQ(r->arcs()[r->patches()[3].arc].from, 0u);
    bytes[r->patches()[3].offset + r->patches()[3].size / 2] ^= 0x10;
  }
  writeFile(mt, bytes);
  auto r = MtFileReader::open(mt);
  const std::vector<uint32_t> finest = cutArcs(*r, finestCut(*r).inSet);
  std::vector<GridBox> boxes(r->patches().size(), GridBox::everything());
  ASSERT_EQ(checkAllPatches(*r, [&](uint32_t p, const DecodedPatch& d) { boxes[p] = patchBox(d); }).size(), 1u);
  EXPECT_THROW(assembleCut(*r, finest), Error);
  for (uint64_t memory : {uint64_t(1) << 30, uint64_t(512) << 10})
    for (bool withBoxes : {true, false}) {
      EdgeCountOptions o;
      o.memoryBytes = memory;
      o.patchBoxes = withBoxes ? &boxes : nullptr;
      try {
        makeConformityReference(*r, finest, o);
        ADD_FAILURE() << "expected an error (memory " << memory << ", boxes " << withBoxes << ")";
      } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("patch 3"), std::string::npos) << e.what();
      }
    }
}

// The bounded check's plan, its overflow splits and its report depend only on the file, the arcs
// and the options: the same for 1, 2 and 4 threads, on a broken cut whose parts overflow.
TEST(BoundedConformity, PartsSplitsAndReportDoNotDependOnThreads) {
  TempDir tmp;
  auto r = MtFileReader::open(buildMt(tmp, "--triangles 20k --holes 4 --seed 21", "--patch-triangles 300"));
  const std::vector<uint32_t> finest = cutArcs(*r, finestCut(*r).inSet);
  std::vector<uint32_t> twice = finest;
  twice.push_back(finest[finest.size() / 2]);
  const ConformityReference ref = makeConformityReference(assembleCut(*r, finest));
  const std::vector<GridBox> boxes = allPatchBoxes(*r);
  for (const Variant& v : {kVariants[4], kVariants[5]}) {
    SCOPED_TRACE(v.name);
    const EdgeCountOptions o = optionsOf(v, boxes);
    std::string first;
    uint32_t parts = 0, splits = 0;
    uint64_t newEdges = 0;
    for (int threads : {1, 2, 4}) {
      tbb::global_control limit(tbb::global_control::max_allowed_parallelism, size_t(threads));
      EdgeCountStats st;
      const ConformityReport rep = checkConforming(*r, twice, ref, o, &st);
      ASSERT_FALSE(rep.conforming());
      EXPECT_GT(st.splitParts, 0u) << "the underestimate must overflow parts";
      if (threads == 1) {
        first = rep.firstProblem, parts = st.parts, splits = st.splitParts;
        newEdges = rep.newBoundaryEdges + rep.newNonManifoldEdges;
        continue;
      }
      EXPECT_EQ(rep.firstProblem, first) << threads << " threads";
      EXPECT_EQ(st.parts, parts) << threads << " threads";
      EXPECT_EQ(st.splitParts, splits) << threads << " threads";
      EXPECT_EQ(rep.newBoundaryEdges + rep.newNonManifoldEdges, newEdges) << threads << " threads";
    }
  }
}

}  // namespace
}  // namespace mt::test
