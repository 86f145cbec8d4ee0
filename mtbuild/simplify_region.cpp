// Region simplification with per-vertex locks on meshoptimizer 0.18 (see simplify_region.h).
#include "mtbuild/simplify_region.h"

#include <meshoptimizer.h>

#include <algorithm>
#include <cfloat>
#include <string>

#include "mtbuild/surface_distance.h"
#include "patchstore/error.h"
#include "patchstore/patch_store.h"

namespace mt {

namespace {

// Runs meshopt_simplify with `lock` frozen; returns the kept triangle list (input indices).
std::vector<uint32_t> simplifyLocked(const std::vector<float>& pos, size_t vertexCount, const uint32_t* triangles,
                                     size_t indexCount, const std::vector<uint8_t>& lock, size_t targetIndexCount,
                                     float* relError) {
  // One unreferenced duplicate per locked vertex: meshopt 0.18 then sees a position shared by two
  // vertices without a matching attribute seam and classifies it Kind_Locked (never collapsed,
  // but still a valid collapse target). Vertices are compared by float position, so two input
  // vertices that round to the same float are also kept: conservative, never wrong.
  std::vector<float> p(pos.begin(), pos.begin() + vertexCount * 3);
  for (size_t v = 0; v < vertexCount; ++v)
    if (lock[v]) p.insert(p.end(), &pos[v * 3], &pos[v * 3 + 3]);
  std::vector<uint32_t> out(indexCount);
  // Error limit: none (FLT_MAX); the target count decides, the error is measured afterwards.
  size_t n = meshopt_simplify(out.data(), triangles, indexCount, p.data(), p.size() / 3, 12, targetIndexCount,
                              FLT_MAX, 0, relError);
  out.resize(n);
  return out;
}

}  // namespace

SimplifiedRegion simplifyRegion(const double* positions, size_t vertexCount, const uint32_t* triangles,
                                size_t triangleCount, const uint8_t* locked, const SimplifyRegionOptions& options) {
  size_t indexCount = triangleCount * 3;
  for (size_t i = 0; i < indexCount; ++i)
    if (triangles[i] >= vertexCount)
      throw Error("simplifyRegion: triangle " + std::to_string(i / 3) + " uses vertex " +
                  std::to_string(triangles[i]) + " of " + std::to_string(vertexCount));

  // meshopt works in float: center the region first so far-from-origin scans keep their precision
  // (positions are only used to rank collapses; the output copies the double input positions).
  double lo[3] = {DBL_MAX, DBL_MAX, DBL_MAX}, hi[3] = {-DBL_MAX, -DBL_MAX, -DBL_MAX};
  for (size_t v = 0; v < vertexCount; ++v)
    for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], positions[v * 3 + a]), hi[a] = std::max(hi[a], positions[v * 3 + a]);
  std::vector<float> pos(vertexCount * 3);
  for (size_t v = 0; v < vertexCount; ++v)
    for (int a = 0; a < 3; ++a) pos[v * 3 + a] = float(positions[v * 3 + a] - 0.5 * (lo[a] + hi[a]));

  std::vector<uint8_t> used(vertexCount, 0), lock(vertexCount, 0);
  for (size_t i = 0; i < indexCount; ++i) used[triangles[i]] = 1;
  if (locked)
    for (size_t v = 0; v < vertexCount; ++v) lock[v] = locked[v] ? 1 : 0;

  size_t targetIndexCount = std::min(options.targetTriangles, triangleCount) * 3;
  float relError = 0;
  std::vector<uint32_t> out;
  // Two things meshopt 0.18 does not promise and the builder needs: (1) a locked vertex can vanish
  // when all its triangles collapse away (a locked corner whose other two vertices merge); (2) a
  // border collapse can create a non-manifold edge (two hole borders pinched together), which a
  // cut would show as a crack-like defect the input did not have. Either way: lock the input
  // triangles around the offending vertices and redo. Deterministic; usually runs once.
  auto edgeKey = [](uint32_t a, uint32_t b) { return a < b ? (uint64_t(a) << 32) | b : (uint64_t(b) << 32) | a; };
  std::vector<uint64_t> inputEdges;
  inputEdges.reserve(indexCount);
  for (size_t t = 0; t < indexCount; t += 3)
    for (int k = 0; k < 3; ++k) inputEdges.push_back(edgeKey(triangles[t + k], triangles[t + (k + 1) % 3]));
  std::sort(inputEdges.begin(), inputEdges.end());
  auto inputUses = [&](uint64_t e) {
    auto range = std::equal_range(inputEdges.begin(), inputEdges.end(), e);
    return size_t(range.second - range.first);
  };
  for (int attempt = 0;; ++attempt) {
    out = simplifyLocked(pos, vertexCount, triangles, indexCount, lock, targetIndexCount, &relError);
    std::vector<uint8_t> kept(vertexCount, 0), bad(vertexCount, 0);
    for (uint32_t v : out) kept[v] = 1;
    bool problem = false;
    for (size_t v = 0; v < vertexCount; ++v)
      if (lock[v] && used[v] && !kept[v]) bad[v] = 1, problem = true;
    std::vector<uint64_t> outEdges;
    outEdges.reserve(out.size());
    for (size_t t = 0; t < out.size(); t += 3)
      for (int k = 0; k < 3; ++k) outEdges.push_back(edgeKey(out[t + k], out[t + (k + 1) % 3]));
    std::sort(outEdges.begin(), outEdges.end());
    for (size_t i = 0; i + 2 < outEdges.size(); ++i)
      if (outEdges[i] == outEdges[i + 2] && inputUses(outEdges[i]) <= 2) {
        bad[outEdges[i] >> 32] = bad[outEdges[i] & 0xFFFFFFFFu] = 1;
        problem = true;
      }
    if (!problem) break;
    if (attempt == 8) throw Error("simplifyRegion: could not keep locked vertices and manifold edges");
    for (size_t t = 0; t < indexCount; t += 3)
      if (bad[triangles[t]] || bad[triangles[t + 1]] || bad[triangles[t + 2]])
        lock[triangles[t]] = lock[triangles[t + 1]] = lock[triangles[t + 2]] = 1;
  }

  SimplifiedRegion r;
  std::vector<uint32_t> remap(vertexCount, ~0u);
  for (uint32_t v : out) remap[v] = 0;
  for (size_t v = 0; v < vertexCount; ++v)
    if (remap[v] == 0) {
      remap[v] = uint32_t(r.origin.size());
      r.origin.push_back(uint32_t(v));
      r.positions.insert(r.positions.end(), positions + v * 3, positions + v * 3 + 3);
    }
  r.triangles.resize(out.size());
  for (size_t i = 0; i < out.size(); ++i) r.triangles[i] = remap[out[i]];
  if (vertexCount) r.quadricError = double(relError) * double(meshopt_simplifyScale(pos.data(), vertexCount, 12));

  if (options.measureError && out.size() < indexCount) {
    // (a) input -> result: removed vertices; kept vertices are on the result.
    TriangleGrid resultGrid(r.positions.data(), r.origin.size(), r.triangles.data(), r.triangleCount());
    double a = 0;
    for (size_t v = 0; v < vertexCount; ++v)
      if (used[v] && remap[v] == ~0u) a = std::max(a, resultGrid.distance(positions + v * 3));
    // (b) result -> input: result centroids (its vertices are input vertices, distance 0).
    TriangleGrid inputGrid(positions, vertexCount, triangles, triangleCount);
    std::vector<uint8_t> all(r.origin.size(), 1);
    double b = sampledDistance(r.positions.data(), r.triangles.data(), r.triangleCount(), inputGrid, all.data());
    r.error = std::max(a, b);
  }
  return r;
}

SimplifiedRegion simplifyRegion(const LoadedMesh& mesh, const SimplifyRegionOptions& options) {
  return simplifyRegion(mesh.positions.data(), mesh.vertexCount(), mesh.triangles.data(), mesh.triangleCount(),
                        mesh.locked.empty() ? nullptr : mesh.locked.data(), options);
}

}  // namespace mt
