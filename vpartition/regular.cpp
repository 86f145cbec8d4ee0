// Regular V-partitioning (BMT section 4.2.1).
//
// 3D: seeds on a) cube centres, b) face centres, c) edge centres of a cubic grid of spacing H.
// Their Voronoi cells are a) the cubes, b) octahedra around each face (the two pyramids from the
// adjacent cube centres over the face: volume H^3/3, 3 per cube), c) octahedra around each edge
// (edge endpoints + the 4 cube centres around the edge: volume H^3/3, 3 per cube). Going from
// coarse to fine the sequence is cubes(H) -> face octahedra(H) -> edge octahedra(H) -> cubes(H/2),
// the diamonds of the Slow Growing Subdivision used by TetraPuzzle. Level 0 is the finest, so
// level l >= 1 is, with H = 2^(m+1) h0, m = (l-1)/3: edge(H), face(H), cube(H) for (l-1)%3 = 0,1,2.
//
// 2D (Figure 6): square centres (squares of side H), then edge midpoints (45-degree diamonds of
// area H^2/2), then square centres of H/2: fine to coarse squares(h0), diamonds(2h0), squares(2h0),
// ... Every square of side h0 is cut by the diamonds(2h0) along one diagonal, so V*0 is the
// right-triangle bintree.
//
// Every cell function is a closed form (no search), and ties on Voronoi boundaries go to the lower
// axis / lower side, so the assignment is deterministic.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>
#include <unordered_set>

#include "base/error.h"
#include "vpartition/level.h"
#include "vpartition/vpartition.h"

namespace mt {
namespace vp {

namespace {

struct GridPoint {
  uint32_t i[3];  // cube index per axis, clamped to the grid
  double f[3];    // position inside the cube in [0,1] (outside when clamped)
};

GridPoint locate(const PartitionLevel& L, const float c[3]) {
  GridPoint g;
  double inv = 1.0 / L.scale;
  for (int a = 0; a < 3; ++a) {
    double u = (double(c[a]) - L.origin[a]) * inv;
    double fl = std::floor(u);
    if (!(fl >= 0)) fl = 0;  // also NaN
    if (fl > double(L.n[a] - 1)) fl = double(L.n[a] - 1);
    g.i[a] = uint32_t(fl);
    g.f[a] = u - fl;
  }
  return g;
}

// Distance of f from the nearest integer among {0, 1} (the cube's faces along that axis).
inline double offInteger(double f) { return f > 0.5 ? std::fabs(1 - f) : std::fabs(f); }

}  // namespace

uint32_t regularCellCount(const PartitionLevel& L) {
  uint64_t n0 = L.n[0], n1 = L.n[1], n2 = L.n[2];
  switch (L.type) {
    case PartitionLevel::Cube: return uint32_t(n0 * n1 * n2);
    case PartitionLevel::EdgeOct:
    case PartitionLevel::FaceOct: return uint32_t(3 * (n0 + 1) * (n1 + 1) * (n2 + 1));
    case PartitionLevel::Square: return uint32_t(uint64_t(L.n[L.axis0]) * L.n[L.axis1]);
    case PartitionLevel::Diamond:
      return uint32_t(2 * uint64_t(L.n[L.axis0] + 1) * (L.n[L.axis1] + 1));
    default: assert(false); return 0;
  }
}

uint32_t regularCellOf(const PartitionLevel& L, const float c[3]) {
  GridPoint g = locate(L, c);
  const uint32_t* n = L.n;
  switch (L.type) {
    case PartitionLevel::Cube: return g.i[0] + n[0] * (g.i[1] + n[1] * g.i[2]);
    case PartitionLevel::FaceOct: {
      // The pyramid (cube centre over a face) containing the point: the axis where it is farthest
      // from the centre; the face octahedron is the union of the two pyramids on that face.
      int axis = 0;
      double best = -1;
      for (int a = 0; a < 3; ++a) {
        double d = std::fabs(g.f[a] - 0.5);
        if (d > best) { best = d; axis = a; }
      }
      uint32_t j[3] = {g.i[0], g.i[1], g.i[2]};
      j[axis] += g.f[axis] > 0.5 ? 1 : 0;
      return uint32_t(axis + 3 * (j[0] + (n[0] + 1) * (j[1] + uint64_t(n[1] + 1) * j[2])));
    }
    case PartitionLevel::EdgeOct: {
      // Squared distance to the nearest edge along axis a is (f_a - 1/2)^2 + sum_{b != a} d_b^2
      // with d = distance to the nearest integer; minimal for the axis with the largest d_a.
      int axis = 0;
      double best = -1;
      for (int a = 0; a < 3; ++a) {
        double d = offInteger(g.f[a]);
        if (d > best) { best = d; axis = a; }
      }
      uint32_t j[3];
      for (int a = 0; a < 3; ++a) j[a] = g.i[a] + (a != axis && g.f[a] > 0.5 ? 1 : 0);
      return uint32_t(axis + 3 * (j[0] + (n[0] + 1) * (j[1] + uint64_t(n[1] + 1) * j[2])));
    }
    case PartitionLevel::Square: return g.i[L.axis0] + n[L.axis0] * g.i[L.axis1];
    case PartitionLevel::Diamond: {
      int ax[2] = {L.axis0, L.axis1};
      int which = offInteger(g.f[ax[1]]) > offInteger(g.f[ax[0]]) ? 1 : 0;
      uint32_t j[2];
      for (int k = 0; k < 2; ++k)
        j[k] = g.i[ax[k]] + (k != which && g.f[ax[k]] > 0.5 ? 1 : 0);
      return uint32_t(which + 2 * (j[0] + uint64_t(n[ax[0]] + 1) * j[1]));
    }
    default: assert(false); return 0;
  }
}

void regularSeedOf(const PartitionLevel& L, uint32_t cell, float out[3]) {
  const uint32_t* n = L.n;
  double p[3] = {0.5, 0.5, 0.5};  // in grid units
  switch (L.type) {
    case PartitionLevel::Cube: {
      p[0] += cell % n[0]; cell /= n[0];
      p[1] += cell % n[1]; p[2] += cell / n[1];
      break;
    }
    case PartitionLevel::FaceOct:
    case PartitionLevel::EdgeOct: {
      int axis = int(cell % 3);
      cell /= 3;
      double j[3];
      j[0] = cell % (n[0] + 1); cell /= (n[0] + 1);
      j[1] = cell % (n[1] + 1); j[2] = cell / (n[1] + 1);
      for (int a = 0; a < 3; ++a) {
        bool half = (L.type == PartitionLevel::FaceOct) ? (a != axis) : (a == axis);
        p[a] = j[a] + (half ? 0.5 : 0.0);
      }
      break;
    }
    case PartitionLevel::Square: {
      p[3 - L.axis0 - L.axis1] = 0;  // 2D: the seed lies in the plane through the origin
      p[L.axis0] += cell % n[L.axis0];
      p[L.axis1] += cell / n[L.axis0];
      break;
    }
    case PartitionLevel::Diamond: {
      int which = int(cell % 2);
      cell /= 2;
      double j0 = cell % (n[L.axis0] + 1), j1 = cell / (n[L.axis0] + 1);
      p[3 - L.axis0 - L.axis1] = 0;
      p[L.axis0] = j0 + (which == 0 ? 0.5 : 0.0);
      p[L.axis1] = j1 + (which == 1 ? 0.5 : 0.0);
      break;
    }
    default: assert(false);
  }
  for (int a = 0; a < 3; ++a) out[a] = float(L.origin[a] + p[a] * L.scale);
}

}  // namespace vp

namespace {

using vp::PartitionLevel;

// Level l of the fine-to-coarse regular sequence over spacing h0 (see the file comment).
std::unique_ptr<PartitionLevel> makeRegularLevel(bool twoD, uint32_t l, double h0,
                                                 const double origin[3], const Box3& box,
                                                 const uint8_t axes[2]) {
  auto L = std::make_unique<PartitionLevel>();
  if (twoD) {
    L->type = (l % 2 == 0) ? PartitionLevel::Square : PartitionLevel::Diamond;
    L->scale = std::ldexp(h0, int((l + 1) / 2));
  } else if (l == 0) {
    L->type = PartitionLevel::Cube;
    L->scale = h0;
  } else {
    static const PartitionLevel::Type phases[3] = {PartitionLevel::EdgeOct,
                                                    PartitionLevel::FaceOct, PartitionLevel::Cube};
    L->type = phases[(l - 1) % 3];
    L->scale = std::ldexp(h0, int((l - 1) / 3 + 1));
  }
  L->axis0 = axes[0];
  L->axis1 = axes[1];
  uint64_t volume = 3;
  for (int a = 0; a < 3; ++a) {
    L->origin[a] = origin[a];
    double cells = std::ceil((box.hi[a] - origin[a]) / L->scale);
    if (!(cells >= 1)) cells = 1;
    if (cells > 1e6) throw Error("regular V-partition: grid of spacing " + std::to_string(L->scale) +
                                 " is too fine for the bounding box; use larger --patch-triangles");
    L->n[a] = uint32_t(cells);
    volume *= uint64_t(L->n[a] + 1);
  }
  if (volume >= 0xFFFFFFFFull)
    throw Error("regular V-partition: more than 2^32 grid cells at spacing " +
                std::to_string(L->scale) + "; use larger --patch-triangles");
  return L;
}

bool isSingleCell(const PartitionLevel& L) {
  return L.type == PartitionLevel::Cube && L.n[0] == 1 && L.n[1] == 1 && L.n[2] == 1;
}

}  // namespace

PartitionSequence buildRegularSequence(const CentroidSource& src, const VPartitionOptions& o) {
  auto start = std::chrono::steady_clock::now();
  const bool twoD = o.kind == PartitionKind::Regular2D;
  checkLevelRatio(o.levelRatio, o.kind);
  const uint32_t P = o.patchTriangles ? o.patchTriangles : kDefaultPatchTriangles;
  Box3 box = src.bounds();
  double ext[3];
  for (int a = 0; a < 3; ++a) ext[a] = std::max(0.0, box.hi[a] - box.lo[a]);
  // 2D: the plane of the two largest extents (ties: lower axis).
  uint8_t axes[2] = {0, 1};
  {
    int order[3] = {0, 1, 2};
    std::stable_sort(order, order + 3, [&](int a, int b) { return ext[a] > ext[b]; });
    axes[0] = uint8_t(std::min(order[0], order[1]));
    axes[1] = uint8_t(std::max(order[0], order[1]));
  }
  double diag = std::sqrt(ext[0] * ext[0] + ext[1] * ext[1] + ext[2] * ext[2]);
  if (!(diag > 0)) diag = 1;
  const uint64_t N = src.count();
  const double targetCross = std::max(1.0, double(N) / P);

  // Initial spacing: assume the surface area is about that of the bounding box's faces, and a
  // crossing cell is ~1/2 (2D) or ~1/3 (3D: three edge octahedra cut a cube) of a finest cell.
  double h0 = o.regularCellSize;
  bool calibrate = !(h0 > 0);
  if (calibrate) {
    double area = twoD ? ext[axes[0]] * ext[axes[1]]
                       : 2 * (ext[0] * ext[1] + ext[1] * ext[2] + ext[0] * ext[2]);
    if (!(area > 0)) area = diag * diag;
    h0 = std::sqrt(area * (twoD ? 2.0 : 2.0) / targetCross);
    if (!(h0 > 0)) h0 = diag;
  }

  PartitionSequence seq;
  seq.setKind(o.kind);
  PartitionBuildStats stats;
  // One counting pass per try: the V*0 cell count (to calibrate h0, since the surface's real area
  // and orientation decide how many grid cells it crosses) and the occupied cells of every
  // candidate level (to stop at the first level with <= maxCoarsestCells cells).
  for (int attempt = 0;; ++attempt) {
    double origin[3];
    uint64_t salt = o.seed ? o.seed * 0x9E3779B97F4A7C15ull : 0;
    for (int a = 0; a < 3; ++a) {
      double frac = salt ? double((salt >> (8 + 16 * a)) & 0xFFFF) / 65536.0 : 0.0;
      origin[a] = box.lo[a] - frac * h0;
    }
    std::vector<std::unique_ptr<PartitionLevel>> cand;
    for (uint32_t l = 0; l < o.maxLevels; ++l) {
      cand.push_back(makeRegularLevel(twoD, l, h0, origin, box, axes));
      if (isSingleCell(*cand.back()) ||
          (twoD && cand.back()->type == PartitionLevel::Square &&
           cand.back()->n[axes[0]] == 1 && cand.back()->n[axes[1]] == 1))
        break;
    }
    std::vector<std::unordered_set<uint32_t>> occupied(cand.size());
    std::unordered_set<uint64_t> cross;
    // Stream coherence: consecutive triangles mostly share cells, so skip repeated inserts.
    std::vector<uint32_t> last(cand.size(), UINT32_MAX);
    uint64_t lastCross = ~0ull;
    src.forEach([&](const float* xyza, size_t count) {
      for (size_t t = 0; t < count; ++t) {
        const float* c = xyza + 4 * t;
        uint32_t prev = 0;
        for (size_t l = 0; l < cand.size(); ++l) {
          uint32_t id = vp::regularCellOf(*cand[l], c);
          if (id != last[l]) occupied[l].insert(id);
          last[l] = id;
          if (l == 1) {
            uint64_t key = (uint64_t(prev) << 32) | id;
            if (key != lastCross) cross.insert(key);
            lastCross = key;
          }
          prev = id;
        }
      }
    });
    ++stats.passes;
    uint64_t bytes = cross.size() * 16;
    for (auto& s : occupied) bytes += s.size() * 16;
    stats.seedBytes = std::max(stats.seedBytes, bytes);
    double ratio = cross.empty() ? 1.0 : double(cross.size()) / targetCross;
    if (calibrate && attempt < 2 && std::fabs(ratio - 1) > 0.1) {
      // Crossing cells on a surface scale as 1/h^2.
      h0 *= std::sqrt(std::clamp(ratio, 1e-4, 1e4));
      ++stats.calibrationPasses;
      continue;
    }
    for (size_t l = 0; l < cand.size(); ++l) {
      size_t cells = occupied[l].size();
      seq.addLevel(std::move(cand[l]));
      if (cells <= o.maxCoarsestCells) break;
    }
    break;
  }
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  seq.mutableStats() = stats;
  return seq;
}

}  // namespace mt
