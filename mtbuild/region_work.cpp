// The per-region work of the level loop: see region_work.h and processRegion() in build.h.
#include "mtbuild/region_work.h"

#include <algorithm>
#include <chrono>
#include <string>

#include "base/error.h"
#include "mtbuild/dag_node.h"
#include "mtbuild/region_texture.h"
#include "mtbuild/simplify_region.h"

namespace mt {

namespace {

using Clock = std::chrono::steady_clock;

// The floor patches of an assembled region, rebuilt exactly (same local vertex order, same
// triangles) from the assembly: PatchStore::assemble appends each patch's triangles in id order
// and records each patch's local -> unified vertex map in unifiedOf. So a worker that only got the
// assembled mesh (mtcluster ranks have no store) encodes the same payloads as one that read them.
std::vector<Patch> floorPatches(const LoadedMesh& m) {
  if (m.unifiedOf.size() != m.patches.size()) fail("region", "assembled mesh has no per-patch vertex maps");
  std::vector<Patch> out(m.patches.size());
  std::vector<uint32_t> localOf(m.vertexCount(), kNoVertex);
  size_t t = 0;
  for (size_t k = 0; k < m.patches.size(); ++k) {
    Patch& p = out[k];
    p.id = m.patches[k];
    const std::vector<uint32_t>& map = m.unifiedOf[k];
    for (uint32_t v = 0; v < map.size(); ++v) {
      uint32_t u = map[v];
      if (u >= m.vertexCount() || localOf[u] != kNoVertex)
        fail("region", "patch " + std::to_string(p.id) + ": vertex " + std::to_string(v) + " maps to a unified vertex twice");
      localOf[u] = v;
      p.positions.insert(p.positions.end(), &m.positions[3 * size_t(u)], &m.positions[3 * size_t(u)] + 3);
      if (!m.normals.empty()) p.normals.insert(p.normals.end(), &m.normals[3 * size_t(u)], &m.normals[3 * size_t(u)] + 3);
      if (!m.colors.empty()) p.colors.insert(p.colors.end(), &m.colors[4 * size_t(u)], &m.colors[4 * size_t(u)] + 4);
    }
    for (; t < m.trianglePatch.size() && m.trianglePatch[t] == p.id; ++t) {
      for (int c = 0; c < 3; ++c) p.triangles.push_back(localOf[m.triangles[3 * t + c]]);
      if (!m.triangleMaterial.empty()) {
        p.cornerUV.insert(p.cornerUV.end(), &m.cornerUV[6 * t], &m.cornerUV[6 * t] + 6);
        p.triangleMaterial.push_back(m.triangleMaterial[t]);
      }
    }
    if (!m.atlases.empty()) p.atlas = m.atlases[k];
    for (uint32_t u : map) localOf[u] = kNoVertex;
  }
  if (t != m.trianglePatch.size()) fail("region", "assembled triangles are not grouped by patch");
  return out;
}

}  // namespace

std::vector<EncodedPatch> encodePatches(const std::vector<Patch>& patches, const QuantizationGrid& grid,
                                        const PatchCodecOptions& codec) {
  std::vector<EncodedPatch> out;
  for (const Patch& p : patches) {
    PatchInput in;
    in.positions = p.positions.data();
    in.vertexCount = p.vertexCount();
    in.triangles = p.triangles.data();
    in.triangleCount = p.triangleCount();
    in.normals = p.normals.empty() ? nullptr : p.normals.data();
    in.colors = p.colors.empty() ? nullptr : p.colors.data();
    EncodedPatch e;
    e.storeId = p.id;
    e.payload = encodePatch(in, grid, codec);
    e.triangles = p.triangleCount();
    e.vertices = p.vertexCount();
    out.push_back(std::move(e));
  }
  return out;
}

// Heap peaks measured per region (a counting operator new, 1 thread, load + processRegion, 778
// regions of m1M, m1M at --patch-triangles 8000 and arm3.3M; 4.7k to 125k floor triangles, 0.52
// to 0.58 vertices per triangle, no normals or colours): working 210-286 bytes per floor triangle
// (at most 543 per vertex), held 41-72 (at most 134 per vertex). The larger of the two terms,
// each 3-12% above the largest measured, covers a region whose patches share fewer vertices.
RegionBytes estimateRegionBytes(uint64_t triangles, uint64_t vertices, bool colors) {
  RegionBytes b;
  b.working = std::max(300 * triangles, 560 * vertices);
  b.held = std::max(80 * triangles, 150 * vertices);
  // Colours, counted from the structures rather than measured: the attribute quadric (27 doubles),
  // the current and output colours and the lock copy (9), the colours in the floor, the assembly
  // and the result (12), the colour error's sorted input faces (12 bytes a triangle, ~2 triangles a
  // vertex): ~260 bytes a vertex while simplified, 12 held.
  if (colors) b.working += 280 * vertices, b.held += 12 * vertices;
  return b;
}

uint64_t taskBytes(const LoadedMesh& m) {
  uint64_t n = m.positions.size() * 8 + m.normals.size() * 4 + m.colors.size() + m.triangles.size() * 4 +
               m.trianglePatch.size() * 4 + m.locked.size() + m.patches.size() * 4;
  for (const auto& u : m.unifiedOf) n += u.size() * 4;
  return n;
}
uint64_t resultBytes(const RegionResult& r) {
  uint64_t n = 0;
  for (const EncodedPatch& e : r.encoded) n += e.payload.size() + e.texture.size() + 24;
  const ReplacementMesh& m = r.replacement;
  return n + m.positions.size() * 8 + m.normals.size() * 4 + m.colors.size() + m.triangles.size() * 4 +
         m.origin.size() * 4 + m.triangleCell.size() * 8;
}

// The root's target: 1/k of the region, as any level's, while that keeps more than
// ctx.rootTriangles (further root levels follow: LevelBuilder::endLevel), then
// ctx.rootTriangles / 2 in one step. So the coarse end of the DAG is a chain of whole-model nodes
// 2x (k x) apart, as the levels below are: going from the partition's last level (a few tens of
// thousands of triangles in up to 8 nodes) to rootTriangles / 2 in one step left no cut between
// them (arm3.3M: 51,820 triangles at error 1.03, then the root's 1,998 at 6.24; every budget from
// 2 k to 51 k drew the 1,998).
static size_t rootTarget(size_t n, size_t ratio, uint64_t rootTriangles) {
  const size_t step = n / ratio;
  return step > rootTriangles ? step : std::min<size_t>(n / 2, size_t(rootTriangles / 2));
}

// A root step. On a scan whose welded input keeps non-manifold edges (which both simplifiers
// freeze), a step deeper than a halving can break the builder's rules on every run
// (simplifyRegion then keeps the region whole: a 53 M armadillo scan's root stayed at level 10's
// 51,858 triangles when it went to rootTriangles / 2 in one step) or, past the first root level,
// reach the count only by folding the model (deviations of a third of its size). So every step of
// a further root level is held to task.rootDeviationLimit (the first root level's is not, as the
// one step to the root was not before the chain). A 1/k step over the limit, or one that kept the
// region whole, is replaced by the root's own step (to rootTriangles / 2), and one that stopped
// far above its target is tried beside it (on noisy and CAD scans the simplifier gets further from
// the same input with the lower target: scangen's blade ended at 11,944 triangles with the 1/k
// steps alone, against 8,320 with the one step). When that too failed, the root is halved instead
// (unless the 1/k step was the halving), and a halving over the limit keeps the region whole,
// which ends the level loop (LevelBuilder::commitRegion drops a level that does not gain).
static SimplifiedRegion settleRoot(SimplifiedRegion sr, const LoadedMesh& lm, SimplifyRegionOptions so, const RegionTask& task,
                                   const RegionContext& ctx) {
  const size_t n = lm.triangleCount();
  const double limit = task.rootDeviationLimit;
  const bool firstRoot = task.level <= ctx.partitionLevels;
  const size_t ownTarget = std::max<size_t>(1, std::min<size_t>(n / 2, size_t(ctx.rootTriangles / 2)));
  const bool ownStep = so.targetTriangles <= ownTarget;
  const bool keptWhole = sr.triangleCount() == n;
  // Past the first root level every step is held to the limit, the root's own included.
  auto withinLimit = [&](const SimplifiedRegion& r) { return firstRoot || limit <= 0 || r.error <= limit; };
  const bool overLimit = !withinLimit(sr);
  if (!keptWhole && !overLimit && !ownStep && n >= 2 && sr.triangleCount() * 4 > so.targetTriangles * 5) {
    // The 1/k step stopped well above its target (rules broken on every run: a CAD or noisy
    // scan): with the root's own, lower target the simplifier can get further from the same input
    // (scangen's blade: 13,665 -> 11,944 at 1/2, 10,554 at the own step). The smaller result is
    // kept when it is within the limit and not below half the 1/k target (the chain's steps stay
    // at most 2k apart).
    SimplifyRegionOptions own = so;
    own.targetTriangles = ownTarget;
    SimplifiedRegion deeper = simplifyRegion(lm, own);
    deeper.attempts += sr.attempts;
    sr.attempts = deeper.attempts;
    if (deeper.triangleCount() < sr.triangleCount() && 2 * deeper.triangleCount() >= so.targetTriangles && withinLimit(deeper))
      return deeper;
    return sr;
  }
  if ((!keptWhole && !overLimit) || n < 2) return sr;
  const size_t firstTarget = so.targetTriangles;
  uint32_t attempts = 0;  // every run counts (LevelReport::simplifierRuns)
  if ((overLimit || keptWhole) && !ownStep) {
    attempts += sr.attempts;
    so.targetTriangles = ownTarget;
    sr = simplifyRegion(lm, so);
    if (sr.triangleCount() != n && withinLimit(sr)) {
      sr.attempts += attempts;
      return sr;
    }
  }
  if (so.targetTriangles < n / 2 && firstTarget != n / 2) {
    attempts += sr.attempts;
    so.targetTriangles = n / 2;
    sr = simplifyRegion(lm, so);
  }
  if (limit > 0 && sr.error > limit && sr.triangleCount() != n) {
    attempts += sr.attempts;
    so.targetTriangles = n;  // no collapse: the region as it is
    sr = simplifyRegion(lm, so);
  }
  sr.attempts += attempts;
  return sr;
}

RegionResult processRegion(const RegionTask& task, const RegionContext& ctx) {
  auto start = Clock::now();
  RegionResult out;
  const LoadedMesh& lm = task.mesh;
  const uint32_t L = ctx.partitionLevels;
  // The floor patches become the payloads of the arcs into this region's node.
  PatchCodecOptions codec = ctx.codec;
  codec.simplified = isSimplifiedOutput(task.level - 1);
  const std::vector<Patch> floor = floorPatches(lm);
  out.encoded = encodePatches(floor, ctx.grid, codec);
  // Textured stores: the floor's atlases and texture payloads (region_texture.h).
  FloorAtlases atlases;
  if (ctx.texture) {
    atlases = floorAtlases(floor, *ctx.texture);
    encodeTextures(floor, atlases, ctx.grid, *ctx.texture, codec.codec, out.encoded);
  }
  // Simplify to about 1/k with the region's border locked (BMT 4: half, k = 2; k is the
  // partition's level ratio, whose next level aims at 1/k of the cells), split by V*(level).
  SimplifyRegionOptions so;
  so.simplifier = ctx.simplifier;
  so.colorWeight = ctx.colorWeight;
  so.gridStep = ctx.grid.step;
  for (int a = 0; a < 3; ++a) so.gridOrigin[a] = ctx.grid.origin[a];
  // At least one triangle: a region that had some must keep some, or its node would carry no
  // patch and have no arc to the sink (a one-triangle input built such a file).
  const size_t n = lm.triangleCount();
  const size_t ratio = ctx.sequence->levelRatio();
  so.targetTriangles = std::max<size_t>(1, task.root ? rootTarget(n, ratio, ctx.rootTriangles) : n / ratio);
  SimplifiedRegion sr = simplifyRegion(lm, so);
  if (task.root) sr = settleRoot(std::move(sr), lm, so, task, ctx);
  out.deviation = sr.error;
  out.simplifierRuns = sr.attempts;
  out.colorDeviation = sr.colorError;
  ReplacementMesh& rep = out.replacement;
  rep.level = task.level;
  rep.origin = sr.origin;
  rep.triangles = sr.triangles;
  for (uint32_t o : sr.origin)
    if (!lm.normals.empty()) rep.normals.insert(rep.normals.end(), &lm.normals[3 * o], &lm.normals[3 * o] + 3);
  rep.colors = std::move(sr.colors);  // the input's, or the quadric's best colours (empty without colours)
  rep.triangleCell.resize(sr.triangleCount());
  // A root level's output goes to the next root level whole (low half 0: one region), in patches
  // by the coarsest partition level's cells (at most maxCoarsestCells, 8): one patch of a whole
  // root node (up to ~26 k triangles in the root chain) would be drawn whole by a renderer whose
  // frame budget is below it, and be read and decoded whole.
  const bool splitRoot = task.root && L > 0;
  for (uint32_t t = 0; t < sr.triangleCount(); ++t) {
    uint64_t high = task.root ? 0 : task.region, low = 0;
    if (task.level + 1 < L || splitRoot) {
      float c[3];
      triangleCentroid(&sr.positions[3 * sr.triangles[3 * t]], &sr.positions[3 * sr.triangles[3 * t + 1]],
                       &sr.positions[3 * sr.triangles[3 * t + 2]], c);
      if (splitRoot)
        high = ctx.sequence->cellOf(L - 1, c);
      else
        low = ctx.sequence->cellOf(task.level + 1, c);
    }
    // The triangle belongs to region R by construction (BMT 4: "this simplified mesh portion ...
    // corresponds to a blue patch"), whatever its new centroid.
    rep.triangleCell[t] = high << 32 | low;
  }
  Sphere sphere = sphereOf(sr.positions);
  for (int a = 0; a < 3; ++a) out.sphere[a] = sphere.c[a];
  out.sphere[3] = sphere.r;
  normalCone(sr.positions, sr.triangles, out.coneAxis, out.coneCutoff);
  rep.positions = std::move(sr.positions);
  // The new patches' own atlases, baked from the floor.
  if (ctx.texture) out.textureError = bakeRegion(lm, atlases, sr.error, task.floorError + sr.error, *ctx.texture, rep);
  out.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return out;
}

}  // namespace mt
