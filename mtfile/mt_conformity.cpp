// The conformity check of a cut (the crack-free rule in mt_cut.h): on an assembled cut by
// sorting its edges, and in bounded memory from the cut's arcs by sweeping the edge table that
// mt_edge_count.cpp fills part by part. Both give the same counts.
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cassert>
#include <cstdio>

#include "base/error.h"
#include "mtfile/mt_cut.h"
#include "mtfile/mt_edge_count.h"

namespace mt {

using cut_internal::countCutEdges;
using cut_internal::EdgeKey;
using cut_internal::EdgeSlot;
using cut_internal::EdgeTable;

namespace {

std::string formatPoint(const WeldedMesh& m, uint32_t v) {
  char buf[128];
  std::snprintf(buf, sizeof buf, "(%.9g,%.9g,%.9g)", m.positions[3 * v], m.positions[3 * v + 1], m.positions[3 * v + 2]);
  return buf;
}

// ConformityReport::firstProblem, the same words for both checks: the edge, where it is, and
// which rule it breaks.
std::string problemText(uint64_t uses, const std::string& a, const std::string& b, const std::string& where) {
  const bool boundary = uses == 1;
  return (boundary ? "boundary edge " : "non-manifold edge (used " + std::to_string(uses) + " times) ") + a + "-" + b + where +
         (boundary ? " is not on the input's boundary" : " is not one of the input's non-manifold edges");
}

GridKey keyOf(const WeldedMesh& m, uint32_t v) { return {m.q[3 * v], m.q[3 * v + 1], m.q[3 * v + 2]}; }

// Undirected edges as (min << 32 | max), sorted: equal runs are one edge and its use count.
std::vector<uint64_t> sortedEdgeKeys(const WeldedMesh& m) {
  std::vector<uint64_t> keys(m.triangles.size());
  tbb::parallel_for(size_t(0), size_t(m.triangleCount()), [&](size_t t) {
    for (int c = 0; c < 3; ++c) {
      uint64_t a = m.triangles[3 * t + c], b = m.triangles[3 * t + (c + 1) % 3];
      keys[3 * t + c] = a < b ? (a << 32 | b) : (b << 32 | a);
    }
  });
  tbb::parallel_sort(keys.begin(), keys.end());
  return keys;
}

// Calls f(key, uses) for every distinct edge.
template <class F>
void forEachEdge(const std::vector<uint64_t>& keys, F&& f) {
  for (size_t i = 0; i < keys.size();) {
    size_t j = i + 1;
    while (j < keys.size() && keys[j] == keys[i]) ++j;
    f(keys[i], uint64_t(j - i));
    i = j;
  }
}

bool contains(const std::vector<GridKey>& sorted, const GridKey& k) {
  return std::binary_search(sorted.begin(), sorted.end(), k);
}

std::string formatGridPoint(const QuantizationGrid& grid, const uint32_t* q) {
  char buf[128];
  std::snprintf(buf, sizeof buf, "(%.9g,%.9g,%.9g)", grid.dequantize(0, q[0]), grid.dequantize(1, q[1]),
                grid.dequantize(2, q[2]));
  return buf;
}

}  // namespace

// ---- On an assembled cut --------------------------------------------------------------------

EdgeReport countEdges(const WeldedMesh& m) {
  EdgeReport e;
  forEachEdge(sortedEdgeKeys(m), [&](uint64_t, uint64_t uses) {
    ++e.edges;
    e.boundaryEdges += uses == 1;
    e.nonManifoldEdges += uses > 2;
  });
  return e;
}

ConformityReference makeConformityReference(const WeldedMesh& finest) {
  ConformityReference ref;
  forEachEdge(sortedEdgeKeys(finest), [&](uint64_t key, uint64_t uses) {
    ++ref.edges.edges;
    if (uses == 2) return;
    auto& list = uses == 1 ? ref.boundaryVertices : ref.nonManifoldVertices;
    (uses == 1 ? ref.edges.boundaryEdges : ref.edges.nonManifoldEdges)++;
    list.push_back(keyOf(finest, uint32_t(key >> 32)));
    list.push_back(keyOf(finest, uint32_t(key)));
  });
  for (auto* list : {&ref.boundaryVertices, &ref.nonManifoldVertices}) {
    std::sort(list->begin(), list->end());
    list->erase(std::unique(list->begin(), list->end()), list->end());
  }
  return ref;
}

ConformityReport checkConforming(const WeldedMesh& cut, const ConformityReference& ref, const MtFileReader* reader) {
  ConformityReport rep;
  uint64_t firstKey = 0, firstUses = 0;
  forEachEdge(sortedEdgeKeys(cut), [&](uint64_t key, uint64_t uses) {
    ++rep.edges.edges;
    if (uses == 2) return;
    const uint32_t a = uint32_t(key >> 32), b = uint32_t(key);
    const bool boundary = uses == 1;
    (boundary ? rep.edges.boundaryEdges : rep.edges.nonManifoldEdges)++;
    const auto& allowed = boundary ? ref.boundaryVertices : ref.nonManifoldVertices;
    if (contains(allowed, keyOf(cut, a)) && contains(allowed, keyOf(cut, b))) return;
    (boundary ? rep.newBoundaryEdges : rep.newNonManifoldEdges)++;
    if (!firstUses) firstKey = key, firstUses = uses;
  });
  if (firstUses) {
    // Name a patch holding the edge, so the damage can be traced to a node of the DAG.
    const uint32_t a = uint32_t(firstKey >> 32), b = uint32_t(firstKey);
    std::string where;
    for (uint32_t t = 0; t < cut.triangleCount(); ++t) {
      const uint32_t* tri = &cut.triangles[3 * t];
      bool hasA = tri[0] == a || tri[1] == a || tri[2] == a, hasB = tri[0] == b || tri[1] == b || tri[2] == b;
      if (!hasA || !hasB) continue;
      const uint32_t patch = cut.trianglePatch[t];
      where = " of patch " + std::to_string(patch);
      if (reader && patch < reader->patches().size())
        where += " (node " + std::to_string(reader->arcs()[reader->patches()[patch].arc].from) + ")";
      break;
    }
    rep.firstProblem = problemText(firstUses, formatPoint(cut, a), formatPoint(cut, b), where);
  }
  return rep;
}

// ---- In bounded memory ----------------------------------------------------------------------

GridBox patchBox(const DecodedPatch& d) {
  GridBox b;
  for (size_t i = 0; i < d.q.size(); i += 3)
    for (int k = 0; k < 3; ++k) b.lo[k] = std::min(b.lo[k], d.q[i + k]), b.hi[k] = std::max(b.hi[k], d.q[i + k]);
  return b;
}

uint64_t referenceBytes(const ConformityReference& ref) {
  return (ref.boundaryVertices.capacity() + ref.nonManifoldVertices.capacity()) * sizeof(GridKey);
}

ConformityReference makeConformityReference(const MtFileReader& r, const std::vector<uint32_t>& arcs,
                                            const EdgeCountOptions& o, EdgeCountStats* stats) {
  ConformityReference ref;
  // The lists grow while the table exists, so they get a fixed share: a quarter of the budget,
  // growth included (a vector that grows holds its old and new buffers for a moment).
  const uint64_t listShare = o.memoryBytes / 4;
  auto makeRoom = [&](std::vector<GridKey>& list, const std::vector<GridKey>& other, uint64_t more) {
    const uint64_t need = list.size() + more;
    if (need <= list.capacity()) return;
    auto peak = [&](uint64_t capacity) { return (list.capacity() + capacity + other.capacity()) * sizeof(GridKey); };
    uint64_t capacity = std::max<uint64_t>(need, list.capacity() + list.capacity() / 2);
    if (peak(capacity) > listShare) capacity = need;
    if (peak(capacity) > listShare)
      fail(r.path(), "the input's boundary and non-manifold vertices (" + std::to_string(ref.boundaryVertices.size()) +
                         " and " + std::to_string(ref.nonManifoldVertices.size()) + " so far, 12 bytes each) need more than a "
                         "quarter of the memory budget (" + std::to_string(o.memoryBytes >> 20) + " MiB); give it more memory");
    list.reserve(size_t(capacity));
  };
  EdgeCountStats st = countCutEdges(r, arcs, o, o.memoryBytes - listShare, [&](const EdgeTable& t) {
    EdgeReport part = tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, t.capacity(), 1 << 16), EdgeReport{},
        [&](const tbb::blocked_range<size_t>& b, EdgeReport e) {
          for (size_t i = b.begin(); i != b.end(); ++i) {
            const uint32_t uses = t[i].uses;
            e.edges += uses != 0;
            e.boundaryEdges += uses == 1;
            e.nonManifoldEdges += uses > 2;
          }
          return e;
        },
        [](EdgeReport a, const EdgeReport& b) { return a += b; });
    ref.edges += part;
    makeRoom(ref.boundaryVertices, ref.nonManifoldVertices, 2 * part.boundaryEdges);
    makeRoom(ref.nonManifoldVertices, ref.boundaryVertices, 2 * part.nonManifoldEdges);
    const size_t boundaryFrom = ref.boundaryVertices.size(), nonManifoldFrom = ref.nonManifoldVertices.size();
    for (size_t i = 0; i < t.capacity(); ++i) {
      const EdgeSlot& s = t[i];
      if (s.uses == 0 || s.uses == 2) continue;
      auto& list = s.uses == 1 ? ref.boundaryVertices : ref.nonManifoldVertices;
      list.push_back({s.key[0], s.key[1], s.key[2]});
      list.push_back({s.key[3], s.key[4], s.key[5]});
    }
    // Most duplicates (a vertex is on two boundary edges) are within one part: drop them now so
    // the lists stay near their final size.
    for (auto [list, from] : {std::pair{&ref.boundaryVertices, boundaryFrom}, std::pair{&ref.nonManifoldVertices, nonManifoldFrom}}) {
      std::sort(list->begin() + from, list->end());
      list->erase(std::unique(list->begin() + from, list->end()), list->end());
    }
  });
  // The table is gone: the whole budget is free for the final sort.
  for (auto* list : {&ref.boundaryVertices, &ref.nonManifoldVertices}) {
    tbb::parallel_sort(list->begin(), list->end());
    list->erase(std::unique(list->begin(), list->end()), list->end());
    list->shrink_to_fit();
  }
  if (stats) *stats = st;
  return ref;
}

ConformityReport checkConforming(const MtFileReader& r, const std::vector<uint32_t>& arcs,
                                 const ConformityReference& ref, const EdgeCountOptions& o, EdgeCountStats* stats) {
  // What a sweep finds; the first problem is the violating edge with the smallest key, so the
  // report does not depend on how the edges were split into parts or ranges.
  struct Tally {
    EdgeReport edges;
    uint64_t newBoundary = 0, newNonManifold = 0;
    bool found = false;
    EdgeKey firstKey{};
    uint32_t firstUses = 0, firstPatch = 0;
    void add(const Tally& b) {
      edges += b.edges;
      newBoundary += b.newBoundary;
      newNonManifold += b.newNonManifold;
      if (b.found && (!found || b.firstKey < firstKey))
        found = true, firstKey = b.firstKey, firstUses = b.firstUses, firstPatch = b.firstPatch;
    }
  };
  auto allowed = [](const std::vector<GridKey>& list, const uint32_t* q) { return contains(list, {q[0], q[1], q[2]}); };
  Tally total;
  const uint64_t lists = referenceBytes(ref);
  EdgeCountStats st = countCutEdges(r, arcs, o, o.memoryBytes > lists ? o.memoryBytes - lists : 0, [&](const EdgeTable& t) {
    total.add(tbb::parallel_reduce(
        tbb::blocked_range<size_t>(0, t.capacity(), 1 << 16), Tally{},
        [&](const tbb::blocked_range<size_t>& b, Tally acc) {
          for (size_t i = b.begin(); i != b.end(); ++i) {
            const EdgeSlot& s = t[i];
            if (s.uses == 0) continue;
            ++acc.edges.edges;
            if (s.uses == 2) continue;
            const bool boundary = s.uses == 1;
            (boundary ? acc.edges.boundaryEdges : acc.edges.nonManifoldEdges)++;
            const auto& list = boundary ? ref.boundaryVertices : ref.nonManifoldVertices;
            if (allowed(list, &s.key[0]) && allowed(list, &s.key[3])) continue;
            (boundary ? acc.newBoundary : acc.newNonManifold)++;
            if (!acc.found || s.key < acc.firstKey)
              acc.found = true, acc.firstKey = s.key, acc.firstUses = s.uses, acc.firstPatch = s.patch;
          }
          return acc;
        },
        [](Tally a, const Tally& b) {
          a.add(b);
          return a;
        }));
  });
  ConformityReport rep;
  rep.edges = total.edges;
  rep.newBoundaryEdges = total.newBoundary;
  rep.newNonManifoldEdges = total.newNonManifold;
  if (total.found) {
    const QuantizationGrid grid = r.grid();
    rep.firstProblem = problemText(total.firstUses, formatGridPoint(grid, &total.firstKey[0]),
                                   formatGridPoint(grid, &total.firstKey[3]),
                                   " of patch " + std::to_string(total.firstPatch) + " (node " +
                                       std::to_string(r.arcs()[r.patches()[total.firstPatch].arc].from) + ")");
  }
  if (stats) *stats = st;
  return rep;
}

}  // namespace mt
