// Cuts of an MT file (see mt_cut.h for the vocabulary and the crack-free rule).
#include "mtbuild/mt_cut.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>
#include <tbb/parallel_sort.h>
#include <xxhash.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <queue>
#include <thread>
#include <unordered_map>

#include "base/error.h"

namespace mt {

using format::ArcRecord;
using format::NodeRecord;

namespace {

uint32_t sinkOf(const MtFileReader& r) { return uint32_t(r.nodes().size() - 1); }

// Calls f(predecessor node) for every arc entering `node`.
template <class F>
void forEachPredecessor(const MtFileReader& r, uint32_t node, F&& f) {
  const NodeRecord& n = r.nodes()[node];
  for (uint32_t k = 0; k < n.backArcCount; ++k) f(r.arcs()[r.backArcs()[n.firstBackArc + k]].from);
}
template <class F>
void forEachSuccessor(const MtFileReader& r, uint32_t node, F&& f) {
  const NodeRecord& n = r.nodes()[node];
  for (uint32_t k = 0; k < n.arcCount; ++k) f(r.arcs()[n.firstArc + k].to);
}

void requireNodes(const MtFileReader& r) {
  if (r.nodes().size() < 2) fail(r.path(), "the DAG has fewer than 2 nodes (no source and sink)");
}

std::vector<uint64_t> arcTriangles(const MtFileReader& r) {
  std::vector<uint64_t> t(r.arcs().size(), 0);
  for (size_t a = 0; a < r.arcs().size(); ++a) {
    const ArcRecord& arc = r.arcs()[a];
    for (uint32_t k = 0; k < arc.patchCount; ++k) t[a] += r.patches()[r.patchRefs()[arc.firstPatchRef + k]].triangles;
  }
  return t;
}

// Greedy refinement from the coarsest cut (BMT 3.1 "Updating a cut"): a node may leave the set
// once none of its successors is in it; the removable node of largest priority goes first, while
// its priority exceeds `threshold` and the triangle budget allows.
Cut refineGreedy(const MtFileReader& r, const std::function<double(uint32_t)>& priority, double threshold,
                 uint64_t maxTriangles) {
  requireNodes(r);
  const uint32_t sink = sinkOf(r);
  const size_t n = r.nodes().size();
  std::vector<uint64_t> arcTris = arcTriangles(r);
  Cut cut = coarsestCut(r);
  std::vector<uint32_t> successorsIn(n, 0);  // arcs to nodes still in the set
  uint64_t triangles = 0;
  for (size_t a = 0; a < r.arcs().size(); ++a) {
    const ArcRecord& arc = r.arcs()[a];
    if (arc.to == sink)
      triangles += arcTris[a];
    else
      ++successorsIn[arc.from];
  }
  using Item = std::pair<double, uint32_t>;  // (priority, node): ties go to the larger id, deterministic
  std::priority_queue<Item> heap;
  for (uint32_t v = 1; v < sink; ++v)
    if (successorsIn[v] == 0) heap.push({priority(v), v});
  while (!heap.empty()) {
    auto [p, v] = heap.top();
    if (!(p > threshold)) break;
    const NodeRecord& node = r.nodes()[v];
    uint64_t add = 0;
    for (uint32_t k = 0; k < node.backArcCount; ++k) add += arcTris[r.backArcs()[node.firstBackArc + k]];
    uint64_t next = triangles - std::min<uint64_t>(triangles, node.triangles) + add;
    if (next > maxTriangles) break;
    heap.pop();
    triangles = next;
    cut.inSet[v] = 0;
    forEachPredecessor(r, v, [&](uint32_t u) {
      if (--successorsIn[u] == 0 && u != 0) heap.push({priority(u), u});
    });
  }
  return cut;
}

struct GridKeyHash {
  size_t operator()(const GridKey& k) const {
    uint64_t h = uint64_t(k[0]) * 0x9E3779B97F4A7C15ull ^ uint64_t(k[1]) * 0xC2B2AE3D27D4EB4Full ^
                 uint64_t(k[2]) * 0x165667B19E3779F9ull;
    return size_t(h ^ (h >> 29));
  }
};

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

}  // namespace

// ---- Node sets -----------------------------------------------------------------------------

std::vector<uint32_t> topologicalOrder(const MtFileReader& r) {
  const size_t n = r.nodes().size();
  std::vector<uint32_t> indegree(n, 0), order;
  order.reserve(n);
  for (const ArcRecord& a : r.arcs()) ++indegree[a.to];
  for (uint32_t v = 0; v < n; ++v)
    if (indegree[v] == 0) order.push_back(v);
  for (size_t i = 0; i < order.size(); ++i)
    forEachSuccessor(r, order[i], [&](uint32_t s) {
      if (--indegree[s] == 0) order.push_back(s);
    });
  if (order.size() != n) {
    for (uint32_t v = 0; v < n; ++v)
      if (indegree[v] != 0) fail(r.path(), "the DAG has a cycle through node " + std::to_string(v));
  }
  return order;
}

bool isValidCut(const MtFileReader& r, const std::vector<uint8_t>& inSet, std::string* why) {
  auto no = [&](const std::string& reason) {
    if (why) *why = reason;
    return false;
  };
  const size_t n = r.nodes().size();
  if (n < 2) return no("the DAG has fewer than 2 nodes");
  if (inSet.size() != n) return no("set has " + std::to_string(inSet.size()) + " entries for " + std::to_string(n) + " nodes");
  if (!inSet[0]) return no("the source (node 0) is not in the set");
  if (inSet[n - 1]) return no("the sink (node " + std::to_string(n - 1) + ") is in the set");
  for (const ArcRecord& a : r.arcs())
    if (inSet[a.to] && !inSet[a.from])
      return no("node " + std::to_string(a.to) + " is in the set but its predecessor " + std::to_string(a.from) + " is not");
  return true;
}

uint32_t closeUnderPredecessors(const MtFileReader& r, std::vector<uint8_t>& inSet) {
  uint32_t added = 0;
  std::vector<uint32_t> stack;
  if (!inSet.empty() && !inSet[0]) inSet[0] = 1, ++added;
  for (uint32_t v = 0; v < inSet.size(); ++v)
    if (inSet[v]) stack.push_back(v);
  while (!stack.empty()) {
    uint32_t v = stack.back();
    stack.pop_back();
    forEachPredecessor(r, v, [&](uint32_t u) {
      if (!inSet[u]) inSet[u] = 1, ++added, stack.push_back(u);
    });
  }
  return added;
}

std::vector<uint32_t> cutArcs(const MtFileReader& r, const std::vector<uint8_t>& inSet) {
  std::vector<uint32_t> out;
  for (uint32_t a = 0; a < r.arcs().size(); ++a)
    if (inSet[r.arcs()[a].from] && !inSet[r.arcs()[a].to]) out.push_back(a);
  return out;
}

Cut finestCut(const MtFileReader& r) {
  requireNodes(r);
  Cut c;
  c.inSet.assign(r.nodes().size(), 0);
  c.inSet[0] = 1;
  return c;
}

Cut coarsestCut(const MtFileReader& r) {
  requireNodes(r);
  Cut c;
  c.inSet.assign(r.nodes().size(), 1);
  c.inSet.back() = 0;
  return c;
}

Cut randomCut(const MtFileReader& r, std::mt19937_64& rng) {
  requireNodes(r);
  const uint32_t sink = sinkOf(r);
  // Portable draws (the std distributions are implementation-defined): tests need the same cuts
  // on every standard library.
  auto uniform = [&] { return double(rng() >> 11) * 0x1.0p-53; };
  Cut cut = finestCut(r);
  if (sink <= 1) return cut;
  const uint32_t mode = uint32_t(rng() % 3);
  const double p = uniform();
  if (mode == 0) {  // closure of a random subset
    for (uint32_t v = 1; v < sink; ++v) cut.inSet[v] = uniform() < p;
    closeUnderPredecessors(r, cut.inSet);
  } else if (mode == 1) {  // one fragment pasted onto the full resolution (plus what it depends on)
    cut.inSet[1 + rng() % (sink - 1)] = 1;
    closeUnderPredecessors(r, cut.inSet);
  } else {  // coarsest, with random nodes refined away together with their descendants
    std::vector<uint8_t> refined(r.nodes().size(), 0);
    for (uint32_t v : topologicalOrder(r)) {
      if (v == 0 || v == sink) continue;
      bool out = uniform() < p;
      forEachPredecessor(r, v, [&](uint32_t u) { out = out || refined[u]; });
      refined[v] = out;
      cut.inSet[v] = !out;
    }
  }
  return cut;
}

Cut cutByError(const MtFileReader& r, double maxError) {
  requireNodes(r);
  const uint32_t sink = sinkOf(r);
  Cut cut;
  cut.inSet.assign(r.nodes().size(), 0);
  for (uint32_t v : topologicalOrder(r)) {
    if (v == sink) continue;
    bool allowed = v == 0 || double(r.nodes()[v].error) <= maxError;
    bool predecessorsIn = true;
    forEachPredecessor(r, v, [&](uint32_t u) { predecessorsIn = predecessorsIn && cut.inSet[u]; });
    cut.inSet[v] = allowed && predecessorsIn;
    if (allowed && !predecessorsIn) ++cut.excludedByClosure;
  }
  return cut;
}

Cut cutByTriangles(const MtFileReader& r, uint64_t maxTriangles) {
  return refineGreedy(r, [&](uint32_t v) { return double(r.nodes()[v].error); }, -INFINITY, maxTriangles);
}

double screenSpaceError(const NodeRecord& node, const ViewParams& view) {
  double d[3], axis[3], dist2 = 0, axis2 = 0;
  for (int a = 0; a < 3; ++a) {
    d[a] = node.center[a] - view.eye[a];
    axis[a] = view.target[a] - view.eye[a];
    dist2 += d[a] * d[a];
    axis2 += axis[a] * axis[a];
  }
  const double dist = std::sqrt(dist2), radius = double(node.radius);
  const double halfFov = view.fovDegrees * M_PI / 360.0;
  if (view.cullOutsideView && dist > radius && axis2 > 0) {
    // Angle between the view axis and the sphere's centre, minus the sphere's angular radius.
    double cosAngle = (d[0] * axis[0] + d[1] * axis[1] + d[2] * axis[2]) / (dist * std::sqrt(axis2));
    double angle = std::acos(std::clamp(cosAngle, -1.0, 1.0)) - std::asin(std::min(1.0, radius / dist));
    if (angle > std::atan(std::sqrt(2.0) * std::tan(halfFov))) return 0;
  }
  const double nearest = std::max(dist - radius, view.nearDistance);
  return double(node.error) / nearest * view.widthPixels / (2 * std::tan(halfFov));
}

Cut cutViewDependent(const MtFileReader& r, const ViewParams& view) {
  return refineGreedy(r, [&](uint32_t v) { return screenSpaceError(r.nodes()[v], view); }, view.pixelTolerance,
                      view.maxTriangles);
}

CutStats cutStats(const MtFileReader& r, const std::vector<uint8_t>& inSet) {
  CutStats s;
  std::vector<uint8_t> front(r.nodes().size(), 0);
  for (uint32_t v = 0; v < inSet.size(); ++v) s.nodes += inSet[v] != 0;
  for (uint32_t a : cutArcs(r, inSet)) {
    const ArcRecord& arc = r.arcs()[a];
    ++s.arcs;
    s.patches += arc.patchCount;
    for (uint32_t k = 0; k < arc.patchCount; ++k) s.triangles += r.patches()[r.patchRefs()[arc.firstPatchRef + k]].triangles;
    if (!front[arc.from]) {
      front[arc.from] = 1;
      ++s.frontNodes;
      s.maxError = std::max(s.maxError, double(r.nodes()[arc.from].error));
    }
  }
  return s;
}

// ---- Assembling ----------------------------------------------------------------------------

namespace {

// The patches on the arcs, in arc order then patchRefs order (a patch on two of the arcs twice).
std::vector<uint32_t> cutPatchIds(const MtFileReader& r, const std::vector<uint32_t>& arcs) {
  std::vector<uint32_t> patchIds;
  for (uint32_t a : arcs) {
    const ArcRecord& arc = r.arcs().at(a);
    for (uint32_t k = 0; k < arc.patchCount; ++k) patchIds.push_back(r.patchRefs()[arc.firstPatchRef + k]);
  }
  return patchIds;
}

}  // namespace

__extension__ typedef unsigned __int128 Wide;  // for the multiply-high that maps a hash to a slot

// Mixes all bits of a hash into the high ones, which the multiply-high uses. (The edge table's
// slot index must also not come from the bits that chose the part, a hash range.)
uint64_t remix(uint64_t h) {
  h ^= h >> 33;
  h *= 0xff51afd7ed558ccdull;
  h ^= h >> 33;
  h *= 0xc4ceb9fe1a85ec53ull;
  return h ^ (h >> 33);
}

// Grid point -> welded vertex id: open addressing with linear probing, at most 2/3 full (grown
// when it would be fuller). 16-byte slots instead of std::unordered_map's node per vertex, a
// malloc each: the 53M finest cut took 48.6 s and 4.0 GB with it, 12.4 s and 2.75 GB with this
// (with the batched decode below).
class WeldIndex {
 public:
  explicit WeldIndex(uint64_t expected) : slots_(std::max<uint64_t>(1024, expected + expected / 2)) {}
  // The id of point k, inserting `next` when it is new (then *inserted is true).
  uint32_t findOrInsert(const GridKey& k, uint32_t next, bool* inserted) {
    if (3 * (used_ + 1) > 2 * slots_.size()) grow();
    for (size_t i = home(k);; i = i + 1 == slots_.size() ? 0 : i + 1) {
      Slot& s = slots_[i];
      if (s.id == kEmpty) {
        s.key = k, s.id = next, ++used_;
        *inserted = true;
        return next;
      }
      if (s.key == k) {
        *inserted = false;
        return s.id;
      }
    }
  }

 private:
  static constexpr uint32_t kEmpty = ~0u;
  struct Slot {
    GridKey key{};
    uint32_t id = kEmpty;
  };
  // hash -> [0, size) by a multiply-high (any size, no modulo)
  size_t home(const GridKey& k) const { return size_t((Wide(remix(GridKeyHash{}(k))) * slots_.size()) >> 64); }
  void grow() {
    std::vector<Slot> old(slots_.size() * 2);
    old.swap(slots_);
    for (const Slot& s : old)
      if (s.id != kEmpty)
        for (size_t i = home(s.key);; i = i + 1 == slots_.size() ? 0 : i + 1)
          if (slots_[i].id == kEmpty) {
            slots_[i] = s;
            break;
          }
  }
  std::vector<Slot> slots_;
  size_t used_ = 0;
};

WeldedMesh assembleCut(const MtFileReader& r, const std::vector<uint32_t>& arcs) {
  const std::vector<uint32_t> patchIds = cutPatchIds(r, arcs);
  const QuantizationGrid grid = r.grid();
  const bool normals = r.header().vertexFlags & format::kHasNormals;
  const bool colors = r.header().vertexFlags & format::kHasColors;
  WeldedMesh m;
  m.patches = patchIds.size();
  // Sizes from the patch index (a guess only: a damaged record cannot overrun anything).
  uint64_t vertexGuess = 0, triangleGuess = 0;
  for (uint32_t id : patchIds) {
    const format::PatchRecord& record = r.patches().at(id);
    vertexGuess += record.vertices, triangleGuess += record.triangles;
  }
  WeldIndex index(std::min<uint64_t>(vertexGuess, uint64_t(1) << 32));
  m.triangles.reserve(size_t(std::min<uint64_t>(3 * triangleGuess, uint64_t(1) << 34)));
  m.trianglePatch.reserve(size_t(std::min<uint64_t>(triangleGuess, uint64_t(1) << 32)));
  std::vector<uint32_t> normalUses;
  std::vector<uint32_t> local;
  // Decoded in parallel a batch at a time (so only one batch of decoded patches is held), welded
  // in order so the result does not depend on thread timing. TBB rethrows the first damaged
  // patch's error in this thread.
  constexpr size_t kBatch = 1024;
  std::vector<DecodedPatch> decoded;
  for (size_t first = 0; first < patchIds.size(); first += kBatch) {
    const size_t count = std::min(kBatch, patchIds.size() - first);
    decoded.assign(count, DecodedPatch{});
    tbb::parallel_for(size_t(0), count, [&](size_t i) { decoded[i] = r.readPatch(patchIds[first + i]); });
    for (size_t i = 0; i < count; ++i) {
      DecodedPatch& d = decoded[i];
      const bool hasN = normals && d.normals.size() == d.q.size();
      const bool hasC = colors && d.colors.size() == size_t(d.vertexCount()) * 4;
      local.resize(d.vertexCount());
      for (uint32_t v = 0; v < d.vertexCount(); ++v) {
        GridKey k = {d.q[3 * v], d.q[3 * v + 1], d.q[3 * v + 2]};
        bool inserted;
        const uint32_t w = index.findOrInsert(k, m.vertexCount(), &inserted);
        if (inserted) {
          for (int a = 0; a < 3; ++a) {
            m.q.push_back(k[a]);
            m.positions.push_back(grid.dequantize(a, k[a]));
          }
          if (normals) m.normals.insert(m.normals.end(), 3, 0.f), normalUses.push_back(0);
          if (colors) {
            for (int c = 0; c < 4; ++c) m.colors.push_back(hasC ? d.colors[4 * v + c] : 255);
          }
        }
        if (hasN) {
          for (int a = 0; a < 3; ++a) m.normals[3 * w + a] += d.normals[3 * v + a];
          ++normalUses[w];
        }
        local[v] = w;
      }
      for (uint32_t t = 0; t < d.triangleCount(); ++t) {
        uint32_t a = local[d.triangles[3 * t]], b = local[d.triangles[3 * t + 1]], c = local[d.triangles[3 * t + 2]];
        if (a == b || b == c || a == c) {
          ++m.degenerateTriangles;
          continue;
        }
        m.triangles.insert(m.triangles.end(), {a, b, c});
        m.trianglePatch.push_back(patchIds[first + i]);
      }
      d = DecodedPatch{};  // release as we go
    }
  }
  // Shared vertices get the mean of the patches' normals (patches computed them independently).
  for (uint32_t v = 0; v < normalUses.size(); ++v) {
    float* n = &m.normals[3 * v];
    float len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (len > 0)
      for (int a = 0; a < 3; ++a) n[a] /= len;
  }
  return m;
}

// ---- Conformity -----------------------------------------------------------------------------

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

// ---- Conformity in bounded memory -----------------------------------------------------------

namespace {

constexpr uint64_t kSlotBytes = 32;
constexpr double kMaxLoad = 0.75;   // a part with more distinct edges than this overflows
constexpr double kPlanLoad = 0.6;   // what planning aims at: room for the estimate to be low
constexpr size_t kMinSlots = 4096;  // a silly budget still gets a working table
constexpr uint64_t kFlushEvery = 4096;  // new edges a thread counts before adding them to the part's total

// An undirected edge: the lexicographically smaller endpoint's q, then the larger's.
using EdgeKey = std::array<uint32_t, 6>;

struct alignas(32) EdgeSlot {
  EdgeKey key;
  uint32_t uses;   // 0: empty
  uint32_t patch;  // the lowest patch id using the edge (names it in firstProblem, deterministically)
};
static_assert(sizeof(EdgeSlot) == kSlotBytes, "EdgeSlot layout");

constexpr uint32_t kClaimed = UINT32_MAX;  // `uses` of a slot whose key is being written
constexpr uint32_t kMaxUses = UINT32_MAX - 1;

uint64_t edgeHash(const EdgeKey& k) { return XXH3_64bits(k.data(), sizeof k); }

// Insert-only open addressing with linear probing, filled by many threads at once: a slot is
// claimed by a CAS of `uses` 0 -> kClaimed, its key written, then published by storing the count
// (release); a thread meeting a claimed slot waits for it (a few stores) before comparing keys.
// No locks, and no thread ever sees a half-written key.
class EdgeTable {
 public:
  enum class Add { New, Counted, Full };
  explicit EdgeTable(size_t slots) : slots_(slots), count_(slots) {}

  size_t capacity() const { return count_; }
  const EdgeSlot& operator[](size_t i) const { return slots_[i]; }

  void clear() {
    tbb::parallel_for(tbb::blocked_range<size_t>(0, count_, 1 << 16), [&](const tbb::blocked_range<size_t>& b) {
      std::memset(static_cast<void*>(&slots_[b.begin()]), 0, b.size() * sizeof(EdgeSlot));
    });
  }

  // Where the probe for an edge of this hash starts (callers prefetch it ahead of add).
  size_t home(uint64_t hash) const { return size_t((Wide(remix(hash)) * count_) >> 64); }
  void prefetch(size_t slot) const { __builtin_prefetch(&slots_[slot], 1); }

  // Counts `uses` more uses of `key` by `patch`.
  Add add(const EdgeKey& key, size_t home, uint32_t patch, uint32_t uses) {
    for (size_t probe = 0, i = home; probe < count_; ++probe, i = i + 1 == count_ ? 0 : i + 1) {
      EdgeSlot& s = slots_[i];
      std::atomic_ref<uint32_t> state(s.uses);
      uint32_t u = state.load(std::memory_order_acquire);
      if (u == 0 && state.compare_exchange_strong(u, kClaimed, std::memory_order_acquire)) {
        s.key = key;
        std::atomic_ref<uint32_t>(s.patch).store(patch, std::memory_order_relaxed);
        state.store(std::min(uses, kMaxUses), std::memory_order_release);
        return Add::New;
      }
      while (u == kClaimed) {  // the claiming thread may have been preempted (shared cores)
        std::this_thread::yield();
        u = state.load(std::memory_order_acquire);
      }
      if (s.key != key) continue;
      while (u < kMaxUses && !state.compare_exchange_weak(u, u > kMaxUses - uses ? kMaxUses : u + uses, std::memory_order_relaxed)) {
      }
      std::atomic_ref<uint32_t> first(s.patch);
      uint32_t f = first.load(std::memory_order_relaxed);
      while (patch < f && !first.compare_exchange_weak(f, patch, std::memory_order_relaxed)) {
      }
      return Add::Counted;
    }
    return Add::Full;
  }

 private:
  std::vector<EdgeSlot> slots_;
  size_t count_;
};

// The edges a pass counts: smaller endpoint inside `box`, hash inside [hashLo, hashHi].
struct EdgePart {
  GridBox box = GridBox::everything();
  uint64_t hashLo = 0, hashHi = UINT64_MAX;
};

bool inside(const GridBox& b, const uint32_t* q) {
  return q[0] >= b.lo[0] && q[0] <= b.hi[0] && q[1] >= b.lo[1] && q[1] <= b.hi[1] && q[2] >= b.lo[2] && q[2] <= b.hi[2];
}
bool meets(const GridBox& a, const GridBox& b) {
  for (int k = 0; k < 3; ++k)
    if (a.lo[k] > b.hi[k] || b.lo[k] > a.hi[k]) return false;
  return true;
}
bool lexLess(const uint32_t* a, const uint32_t* b) {
  return a[0] != b[0] ? a[0] < b[0] : a[1] != b[1] ? a[1] < b[1] : a[2] < b[2];
}
bool sameQ(const uint32_t* a, const uint32_t* b) { return a[0] == b[0] && a[1] == b[1] && a[2] == b[2]; }

// One patch's edges in a part, each with its number of uses in the patch: most edges are used
// twice within their patch, so the shared table sees each once (half the random accesses).
struct PatchEdges {
  struct Edge {
    EdgeKey key;
    uint64_t hash;
    size_t home;
    uint32_t uses;
  };
  std::vector<uint64_t> pairs;  // (smaller local index << 32 | larger), one per use
  std::vector<Edge> edges;

  void collect(const DecodedPatch& d, const EdgePart& part) {
    pairs.clear();
    edges.clear();
    for (uint32_t t = 0; t < d.triangleCount(); ++t) {
      const uint32_t* v = &d.triangles[3 * t];
      const uint32_t* q[3] = {&d.q[3 * v[0]], &d.q[3 * v[1]], &d.q[3 * v[2]]};
      if (sameQ(q[0], q[1]) || sameQ(q[1], q[2]) || sameQ(q[0], q[2])) continue;  // assembleCut drops it
      for (int c = 0; c < 3; ++c) {
        const uint64_t a = v[c], b = v[(c + 1) % 3];
        pairs.push_back(a < b ? a << 32 | b : b << 32 | a);
      }
    }
    std::sort(pairs.begin(), pairs.end());
    // Two local vertices at one q give two entries of one edge here; the table adds them up.
    for (size_t i = 0; i < pairs.size();) {
      size_t j = i + 1;
      while (j < pairs.size() && pairs[j] == pairs[i]) ++j;
      const uint32_t* a = &d.q[3 * (pairs[i] >> 32)];
      const uint32_t* b = &d.q[3 * (pairs[i] & 0xffffffffu)];
      if (lexLess(b, a)) std::swap(a, b);
      if (inside(part.box, a)) {
        Edge e{{a[0], a[1], a[2], b[0], b[1], b[2]}, 0, 0, uint32_t(j - i)};
        e.hash = edgeHash(e.key);
        if (e.hash >= part.hashLo && e.hash <= part.hashHi) edges.push_back(e);
      }
      i = j;
    }
  }
};

// A patch's position in the cut's patch list, where its box centre is, and how many triangles
// (of the index) it brings: what the k-d split weighs.
struct PlanItem {
  std::array<uint32_t, 3> centre;
  uint64_t triangles;
  uint32_t position;
};

// Splits `box` (holding the items' centres) into `leaves` parts along the longest side of the
// centres' extent, each cut at the weight (triangles) that gives both sides their share of the
// leaves, so the parts come out about equal and no more than needed; parts in k-d order.
void planSpatialParts(const GridBox& box, PlanItem* begin, PlanItem* end, uint64_t leaves, std::vector<EdgePart>& parts) {
  uint64_t weight = 0;
  GridBox extent;
  for (PlanItem* p = begin; p != end; ++p) {
    weight += p->triangles;
    for (int k = 0; k < 3; ++k)
      extent.lo[k] = std::min(extent.lo[k], p->centre[k]), extent.hi[k] = std::max(extent.hi[k], p->centre[k]);
  }
  int axis = 0;
  for (int k = 1; k < 3; ++k)
    if (uint64_t(extent.hi[k]) - extent.lo[k] > uint64_t(extent.hi[axis]) - extent.lo[axis]) axis = k;
  if (leaves <= 1 || end - begin <= 1 || extent.hi[axis] == extent.lo[axis]) {
    parts.push_back({box});  // one part, or all centres at one point: an overflow will split it
    return;
  }
  std::sort(begin, end, [&](const PlanItem& a, const PlanItem& b) {
    return a.centre[axis] != b.centre[axis] ? a.centre[axis] < b.centre[axis] : a.position < b.position;
  });
  const uint64_t leftLeaves = leaves / 2;
  const double leftWeight = double(weight) * double(leftLeaves) / double(leaves);
  PlanItem* at = begin;
  for (uint64_t before = 0; at + 1 < end && double(before + at->triangles) < leftWeight; ++at) before += at->triangles;
  // Centres below `splitAt` go left. At least the smallest centre goes left and the largest right.
  const uint32_t splitAt = std::max(at->centre[axis], begin->centre[axis] + 1);
  PlanItem* split = std::partition_point(begin, end, [&](const PlanItem& p) { return p.centre[axis] < splitAt; });
  GridBox left = box, right = box;
  left.hi[axis] = splitAt - 1;
  right.lo[axis] = splitAt;
  planSpatialParts(left, begin, split, leftLeaves, parts);
  planSpatialParts(right, split, end, leaves - leftLeaves, parts);
}

// Counts the cut's edges part by part in one table of at most tableBytes; after each part has
// been counted, `sweep` reads the table. Returns the statistics.
EdgeCountStats countCutEdges(const MtFileReader& r, const std::vector<uint32_t>& arcs, const EdgeCountOptions& o,
                             uint64_t tableBytes, const std::function<void(const EdgeTable&)>& sweep) {
  const auto start = std::chrono::steady_clock::now();
  EdgeCountStats st;
  const std::vector<uint32_t> patchIds = cutPatchIds(r, arcs);
  st.patches = patchIds.size();
  for (uint32_t id : patchIds) st.triangles += r.patches()[id].triangles;
  if (o.patchBoxes && o.patchBoxes->size() != r.patches().size())
    throw Error("EdgeCountOptions::patchBoxes has " + std::to_string(o.patchBoxes->size()) + " boxes for " +
                std::to_string(r.patches().size()) + " patches");

  // The whole budget when the cut needs several parts (fewer parts, fewer patches read twice at
  // their borders); a cut that fits gets a table for its estimate (an overflow splits it).
  const double estimate = o.edgesPerTriangle * double(st.triangles);
  const uint64_t budgetSlots = tableBytes / kSlotBytes;
  const uint64_t wantedSlots = uint64_t(std::ceil(estimate / kPlanLoad)) + 1;
  const size_t slots = size_t(std::max<uint64_t>(kMinSlots, std::min(budgetSlots, wantedSlots)));
  EdgeTable table(slots);
  st.tableBytes = slots * kSlotBytes;
  const uint64_t limit = uint64_t(kMaxLoad * double(slots));
  const double planEdges = kPlanLoad * double(slots);

  // Grid boxes by position in patchIds: the caller's, or one decode pass, only once needed.
  std::vector<GridBox> ownBoxes;
  bool haveBoxes = false;
  auto ensureBoxes = [&] {
    if (haveBoxes || o.patchBoxes) return void(haveBoxes = true);
    ownBoxes.resize(patchIds.size());
    tbb::parallel_for(size_t(0), patchIds.size(), [&](size_t i) { ownBoxes[i] = patchBox(r.readPatch(patchIds[i])); });
    st.patchReads += patchIds.size();
    haveBoxes = true;
  };
  auto boxAt = [&](size_t i) -> const GridBox& { return o.patchBoxes ? (*o.patchBoxes)[patchIds[i]] : ownBoxes[i]; };

  // Plan. Parts are a stack, so a split part's halves are counted next, in order.
  std::vector<EdgePart> parts;
  if (estimate <= planEdges) {
    parts.push_back({});
  } else if (o.spatialParts) {
    ensureBoxes();
    std::vector<PlanItem> items;
    for (uint32_t i = 0; i < patchIds.size(); ++i) {
      const GridBox& b = boxAt(i);
      if (b.empty()) continue;
      PlanItem p{{}, r.patches()[patchIds[i]].triangles, i};
      for (int k = 0; k < 3; ++k) p.centre[k] = uint32_t(b.lo[k] + (uint64_t(b.hi[k]) - b.lo[k]) / 2);
      items.push_back(p);
    }
    planSpatialParts(GridBox::everything(), items.data(), items.data() + items.size(),
                     uint64_t(std::ceil(estimate / planEdges)), parts);
  } else {
    const uint64_t n = uint64_t(std::ceil(estimate / planEdges));
    const uint64_t width = UINT64_MAX / n;
    for (uint64_t k = 0; k < n; ++k) parts.push_back({GridBox::everything(), k * width, k + 1 == n ? UINT64_MAX : (k + 1) * width - 1});
  }
  std::reverse(parts.begin(), parts.end());

  std::vector<uint32_t> members;  // positions in patchIds of the patches that can hold the part's edges
  tbb::enumerable_thread_specific<PatchEdges> scratch;
  bool tableUsed = false;
  while (!parts.empty()) {
    const EdgePart part = parts.back();
    parts.pop_back();
    members.clear();
    const bool wholeGrid = part.box.lo == GridBox::everything().lo && part.box.hi == GridBox::everything().hi;
    for (uint32_t i = 0; i < patchIds.size(); ++i)
      if (!haveBoxes || (!boxAt(i).empty() && (wholeGrid || meets(boxAt(i), part.box)))) members.push_back(i);

    if (tableUsed) table.clear();
    tableUsed = true;
    std::atomic<uint64_t> distinct{0}, reads{0};
    std::atomic<bool> overflow{false};
    tbb::parallel_for(tbb::blocked_range<size_t>(0, members.size()), [&](const tbb::blocked_range<size_t>& range) {
      PatchEdges& local = scratch.local();
      for (size_t m = range.begin(); m != range.end(); ++m) {
        if (overflow.load(std::memory_order_relaxed)) return;
        const uint32_t id = patchIds[members[m]];
        const DecodedPatch d = r.readPatch(id);
        reads.fetch_add(1, std::memory_order_relaxed);
        local.collect(d, part);
        uint64_t added = 0;
        auto flush = [&] {
          if (distinct.fetch_add(added, std::memory_order_relaxed) + added > limit) overflow.store(true);
          added = 0;
        };
        // Random accesses over the whole table: start fetching a few edges ahead.
        constexpr size_t kAhead = 8;
        const size_t n = local.edges.size();
        for (size_t k = 0; k < std::min(n, kAhead); ++k) table.prefetch(local.edges[k].home = table.home(local.edges[k].hash));
        for (size_t k = 0; k < n; ++k) {
          if (k + kAhead < n) table.prefetch(local.edges[k + kAhead].home = table.home(local.edges[k + kAhead].hash));
          const PatchEdges::Edge& e = local.edges[k];
          const EdgeTable::Add result = table.add(e.key, e.home, id, e.uses);
          if (result == EdgeTable::Add::Full) {  // more than `limit` distinct edges: overflow below
            overflow.store(true);
            return;
          }
          if (result == EdgeTable::Add::New && ++added == kFlushEvery) flush();
        }
        flush();
      }
    });
    st.patchReads += reads.load();
    // The part overflowed iff it has more than `limit` distinct edges: the flushed partial sums and
    // a full table are both lower bounds, so the decision does not depend on thread timing.
    if (overflow.load() || distinct.load() > limit) {
      ++st.splitParts;
      GridBox data;  // where the part's patches are, inside the part's box
      if (o.spatialParts) {
        ensureBoxes();
        for (uint32_t i : members) {
          const GridBox& b = boxAt(i);
          if (b.empty() || !meets(b, part.box)) continue;
          for (int k = 0; k < 3; ++k)
            data.lo[k] = std::min(data.lo[k], std::max(b.lo[k], part.box.lo[k])),
            data.hi[k] = std::max(data.hi[k], std::min(b.hi[k], part.box.hi[k]));
        }
      }
      EdgePart low = part, high = part;
      int axis = 0;
      for (int k = 1; k < 3; ++k)
        if (uint64_t(data.hi[k]) - data.lo[k] > uint64_t(data.hi[axis]) - data.lo[axis]) axis = k;
      if (!data.empty() && data.hi[axis] > data.lo[axis]) {
        const uint32_t mid = uint32_t(data.lo[axis] + (uint64_t(data.hi[axis]) - data.lo[axis]) / 2);
        low.box.hi[axis] = mid;
        high.box.lo[axis] = mid + 1;
      } else {
        if (part.hashHi == part.hashLo) fail(r.path(), "more edges share one hash than the edge table holds");
        const uint64_t mid = part.hashLo + (part.hashHi - part.hashLo) / 2;
        low.hashHi = mid;
        high.hashLo = mid + 1;
      }
      parts.push_back(high);
      parts.push_back(low);
      continue;
    }
    sweep(table);
    ++st.parts;
  }
  st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return st;
}

std::string formatGridPoint(const QuantizationGrid& grid, const uint32_t* q) {
  char buf[128];
  std::snprintf(buf, sizeof buf, "(%.9g,%.9g,%.9g)", grid.dequantize(0, q[0]), grid.dequantize(1, q[1]),
                grid.dequantize(2, q[2]));
  return buf;
}

}  // namespace

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

// ---- Payload check --------------------------------------------------------------------------

std::vector<PatchDamage> checkAllPatches(const MtFileReader& r,
                                         const std::function<void(uint32_t, const DecodedPatch&)>& onPatch) {
  std::vector<PatchDamage> damaged;
  std::mutex lock;
  tbb::parallel_for(uint32_t(0), uint32_t(r.patches().size()), [&](uint32_t p) {
    DecodedPatch d;
    try {
      d = r.readPatch(p);
    } catch (const Error& e) {
      std::lock_guard<std::mutex> g(lock);
      damaged.push_back({p, e.what()});
      return;
    }
    if (onPatch) onPatch(p, d);
  });
  std::sort(damaged.begin(), damaged.end(), [](const PatchDamage& a, const PatchDamage& b) { return a.patch < b.patch; });
  return damaged;
}

}  // namespace mt
