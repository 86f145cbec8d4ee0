// --fill-holes MAXEDGES, out of core.
//
// 1. Border edges: the edge census (region.cpp) counts every undirected edge over the whole store
//    by global vertex key; an edge used by one triangle is a border edge, wherever the patch
//    borders fall (an edge cut by a patch border is seen from both sides and counts 2).
// 2. Loops: border edges are few (hole rims and open borders), so they are chained in RAM, tail
//    to head in the direction of their triangles. A vertex with several outgoing border edges
//    (two holes touching) makes its loops "skipped": they are not simple polygons.
// 3. Each loop of at most MAXEDGES edges is filled with every patch that holds one of its
//    vertices loaded (so the band of triangles around it is complete even when the loop crosses
//    patch borders), by CGAL's triangulate_refine_and_fair_hole (hole_filling_cgal.cpp) on that
//    band; the new triangles go to the patch holding most of the loop's edges.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <map>
#include <set>
#include <unordered_map>

#include "base/progress.h"
#include "patchstore/heal/region.h"

namespace mt::heal {

namespace {

struct BorderEdge {
  uint64_t tail, head;
  PatchId patch;
};

// Step 1: the border edges, tail to head in the direction of their triangle, sorted by tail.
std::vector<BorderEdge> borderEdges(const PatchStore& store, const HealOptions& options) {
  std::vector<BorderEdge> border;
  edgeCensus(store, options, [](uint32_t c) { return c == 1; },
             [&](const EdgeUse& e) { border.push_back({e.forward ? e.a : e.b, e.forward ? e.b : e.a, e.patch}); },
             "fill-holes: border edges");
  std::sort(border.begin(), border.end(), [](const BorderEdge& a, const BorderEdge& b) { return a.tail < b.tail; });
  return border;
}

struct Loop {
  std::vector<size_t> edges;  // indices into the border edges, in walking order
};

struct Loops {
  std::vector<Loop> fillable;  // simple and at most maxEdges long
  uint64_t holes = 0, skipped = 0, larger = 0;
};

// Step 2: the border edges chained into loops, every edge in exactly one.
Loops chainLoops(const std::vector<BorderEdge>& border, uint32_t maxEdges) {
  std::unordered_map<uint64_t, uint32_t> outDegree;
  for (const BorderEdge& e : border) ++outDegree[e.tail];
  auto firstFrom = [&](uint64_t v) {
    auto it = std::lower_bound(border.begin(), border.end(), v, [](const BorderEdge& e, uint64_t x) { return e.tail < x; });
    return it != border.end() && it->tail == v ? size_t(it - border.begin()) : border.size();
  };
  std::vector<uint8_t> visited(border.size(), 0);
  Loops loops;
  for (size_t s = 0; s < border.size(); ++s) {
    if (visited[s]) continue;
    Loop loop;
    bool simple = true;
    size_t cur = s;
    for (;;) {
      visited[cur] = 1;
      loop.edges.push_back(cur);
      if (outDegree[border[cur].tail] != 1) simple = false;
      uint64_t head = border[cur].head;
      if (head == border[s].tail) break;
      size_t next = firstFrom(head);
      if (next == border.size() || visited[next]) {  // open chain or a branch already walked
        simple = false;
        break;
      }
      cur = next;
    }
    ++loops.holes;
    if (!simple) ++loops.skipped;
    else if (loop.edges.size() > maxEdges) ++loops.larger;
    else loops.fillable.push_back(std::move(loop));
  }
  return loops;
}

// The band around a loop: every triangle with a loop vertex (all loaded: no loop vertex is
// locked), in band indices; regionOf maps them back. False when the loop is no longer a border
// of the band (an earlier edit moved a patch-local index under us): each edge must be there
// once, in its direction, and never the other way.
bool holeBand(const Region& r, const std::vector<uint32_t>& lv, const std::vector<uint8_t>& onLoop, HoleBand& hb,
              std::vector<uint32_t>& regionOf) {
  std::vector<uint32_t> band(r.vertexCount(), kNoVertex);
  auto bandIndex = [&](uint32_t u) {
    if (band[u] == kNoVertex) {
      band[u] = uint32_t(regionOf.size());
      regionOf.push_back(u);
      hb.positions.insert(hb.positions.end(), &r.positions[3 * u], &r.positions[3 * u] + 3);
    }
    return band[u];
  };
  for (uint32_t u : lv) bandIndex(u);
  for (size_t t = 0; t < r.trianglePatch.size(); ++t) {
    const uint32_t* f = &r.triangles[3 * t];
    if (onLoop[f[0]] || onLoop[f[1]] || onLoop[f[2]])
      for (int c = 0; c < 3; ++c) hb.triangles.push_back(bandIndex(f[c]));
  }
  for (uint32_t u : lv) hb.loop.push_back(band[u]);
  std::map<std::pair<uint32_t, uint32_t>, int> directed;
  for (size_t i = 0; i < hb.triangles.size(); i += 3)
    for (int c = 0; c < 3; ++c) ++directed[{hb.triangles[i + c], hb.triangles[i + (c + 1) % 3]}];
  bool ok = true;
  for (size_t i = 0; i < hb.loop.size() && ok; ++i) {
    uint32_t a = hb.loop[i], b = hb.loop[(i + 1) % hb.loop.size()];
    ok = directed[{a, b}] == 1 && directed[{b, a}] == 0;
  }
  return ok;
}

// Attributes of the new vertices (edit vertices from first): normals from the new faces around
// them, colours the loop's mean.
void newVertexAttributes(const PatchStore& store, const Region& r, const std::vector<uint32_t>& lv, const HoleFill& fill,
                         uint32_t nb, const std::function<uint32_t(uint32_t)>& regionVertex, RegionEdit& e) {
  const size_t nNew = fill.newPositions.size() / 3;
  if (store.layout().normals) {
    std::vector<double> acc(nNew * 3, 0.0);
    for (size_t i = 0; i < fill.newTriangles.size(); i += 3) {
      const double* p[3];
      for (int c = 0; c < 3; ++c) p[c] = &e.positions[3 * regionVertex(fill.newTriangles[i + c])];
      double u[3], v[3], n[3];
      for (int a = 0; a < 3; ++a) u[a] = p[1][a] - p[0][a], v[a] = p[2][a] - p[0][a];
      n[0] = u[1] * v[2] - u[2] * v[1], n[1] = u[2] * v[0] - u[0] * v[2], n[2] = u[0] * v[1] - u[1] * v[0];
      for (int c = 0; c < 3; ++c)
        if (fill.newTriangles[i + c] >= nb)
          for (int a = 0; a < 3; ++a) acc[3 * (fill.newTriangles[i + c] - nb) + a] += n[a];
    }
    for (size_t i = 0; i < nNew; ++i) {
      double len = std::sqrt(acc[3 * i] * acc[3 * i] + acc[3 * i + 1] * acc[3 * i + 1] + acc[3 * i + 2] * acc[3 * i + 2]);
      for (int a = 0; a < 3; ++a) e.normals.push_back(len > 0 ? float(acc[3 * i + a] / len) : 0.f);
    }
  }
  if (store.layout().colors) {
    double sum[4] = {0, 0, 0, 0};
    for (uint32_t u : lv)
      for (int a = 0; a < 4; ++a) sum[a] += r.colors[4 * u + a];
    for (size_t i = 0; i < nNew; ++i)
      for (int a = 0; a < 4; ++a) e.colors.push_back(uint8_t(std::lround(sum[a] / double(lv.size()))));
  }
}

struct FillCounts {
  uint64_t filled = 0, across = 0, triangles = 0, vertices = 0, skipped = 0;
};

// Step 3 for one loop: load every patch around it, fill the band, commit. Vertices are named by
// their owner's (patch, index): those stay valid while holes are filled, since filling only
// appends vertices to patches and never drops one.
void fillLoop(PatchStore& store, const std::vector<BorderEdge>& border, const Loop& loop, FillCounts& counts) {
  std::set<PatchId> ids;
  std::map<PatchId, uint32_t> edgesIn;
  for (size_t i : loop.edges) {
    ids.insert(border[i].patch);
    ids.insert(gidPatch(border[i].tail));
    ++edgesIn[border[i].patch];
  }
  auto loopVertices = [&](const Region& r) {
    std::vector<uint32_t> out;
    for (size_t i : loop.edges) out.push_back(r.vertexOf(gidPatch(border[i].tail), gidLocal(border[i].tail)));
    return out;
  };
  Region r = loadUnlocked(store, {ids.begin(), ids.end()}, [&](const Region& rr, uint32_t u) {
    auto lv = loopVertices(rr);
    return std::find(lv.begin(), lv.end(), u) != lv.end();
  });
  std::vector<uint32_t> lv = loopVertices(r);
  bool ok = true;
  std::vector<uint8_t> onLoop(r.vertexCount(), 0);
  for (uint32_t u : lv) {
    if (u == kNoVertex || r.locked[u] || onLoop[u]) ok = false;
    else onLoop[u] = 1;
  }
  HoleBand hb;
  std::vector<uint32_t> regionOf;
  HoleFill fill;
  if (ok) ok = holeBand(r, lv, onLoop, hb, regionOf);
  if (ok) fill = fillHoleBand(hb);
  if (!ok || !fill.ok) {
    ++counts.skipped;
    return;
  }
  // The new triangles go to the patch with most of the loop's edges (lowest id on ties).
  PatchId home = edgesIn.begin()->first;
  for (auto& [q, n] : edgesIn)
    if (n > edgesIn[home]) home = q;
  RegionEdit e = identityEdit(r);
  const uint32_t nb = uint32_t(regionOf.size());
  std::vector<uint32_t> newIds;
  const size_t nNew = fill.newPositions.size() / 3;
  for (size_t i = 0; i < nNew; ++i) {
    newIds.push_back(e.vertexCount());
    e.positions.insert(e.positions.end(), &fill.newPositions[3 * i], &fill.newPositions[3 * i] + 3);
    e.origin.push_back(kNoVertex);
  }
  auto regionVertex = [&](uint32_t b) { return b < nb ? regionOf[b] : newIds[b - nb]; };
  for (size_t i = 0; i < fill.newTriangles.size(); i += 3) {
    const uint32_t v[3] = {regionVertex(fill.newTriangles[i]), regionVertex(fill.newTriangles[i + 1]),
                           regionVertex(fill.newTriangles[i + 2])};
    e.addTriangle(v, uint32_t(r.indexOf(home)), store.layout().texcoords);  // a filled hole has no texture
  }
  newVertexAttributes(store, r, lv, fill, nb, regionVertex, e);
  commitRegion(store, r, e);
  ++counts.filled;
  if (edgesIn.size() > 1) ++counts.across;
  counts.triangles += fill.newTriangles.size() / 3;
  counts.vertices += nNew;
}

}  // namespace

PassReport fillHoles(PatchStore& store, uint32_t maxEdges, const HealOptions& options) {
  auto start = std::chrono::steady_clock::now();
  const std::vector<BorderEdge> border = borderEdges(store, options);
  const Loops loops = chainLoops(border, maxEdges);
  FillCounts counts;
  Progress progress(options.progress, "fill-holes: fill", loops.fillable.size(), "holes");
  size_t done = 0;
  for (const Loop& loop : loops.fillable) {
    progress.update(++done);
    fillLoop(store, border, loop, counts);
  }
  progress.finish(done);
  store.sync();
  double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return {"fill-holes",
          {{"holes", loops.holes}, {"filled", counts.filled}, {"across-patches", counts.across}, {"larger", loops.larger},
           {"skipped", loops.skipped + counts.skipped}, {"triangles", counts.triangles}, {"vertices", counts.vertices}},
          seconds};
}

}  // namespace mt::heal
