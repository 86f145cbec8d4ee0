// Cuts of an MT file as node sets (see mt_cut.h for the vocabulary): their validity, the cut
// selections (by error, triangle budget or view, at random for tests), their statistics, and the
// payload check. Assembling a cut is in mt_weld.cpp, its conformity in mt_conformity.cpp.
#include "mtfile/mt_cut.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <mutex>
#include <queue>

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
    assert(cut.inSet[v] && successorsIn[v] == 0 && "only a node with no successor in the set leaves it");
    triangles = next;
    cut.inSet[v] = 0;
    forEachPredecessor(r, v, [&](uint32_t u) {
      if (--successorsIn[u] == 0 && u != 0) heap.push({priority(u), u});
    });
  }
  return cut;
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

// ---- Payload check --------------------------------------------------------------------------

std::vector<PatchDamage> checkAllPatches(const MtFileReader& r,
                                         const std::function<void(uint32_t, const DecodedPatch&)>& onPatch) {
  std::vector<PatchDamage> damaged;
  std::mutex lock;
  tbb::parallel_for(uint32_t(0), uint32_t(r.patches().size()), [&](uint32_t p) {
    DecodedPatch d;
    try {
      d = r.readPatch(p);
      if (r.hasTextures()) r.readTexture(p, d);  // checksum, coordinates, image format
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
