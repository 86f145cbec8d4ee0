// Irregular V-partitioning (BMT section 4.2.2): seed sets Q0..Q(L-1) from streaming passes.
//
// "We sequentially scan the surface triangles, adding the barycenter of the triangle t to the seed
// set Q every time t is farther than r from all the other points of Q. Then, in a second
// sequential scan, we remove small patches and we apply a step of Lloyd's relaxation." All levels
// are seeded in the same scans, each with its own radius r_i and its own hash grid.
//
// Radii: level i should hold N / (T0 * k^i) cells, where T0 is the triangles of a V0 cell and k
// the level ratio (VPartitionOptions::levelRatio, 2 by default); BMT halves the triangles per level
// and the cells with them ("decreasing the triangle count, from a level to the next, by the same
// ratio as the number of seeds"), so on a surface r_(i+1) ~ sqrt(k) r_i. T0 = patchTriangles *
// kCrossPerCell because the patches are the V*0 cells, and each V0 cell is cut into
// ~kCrossPerCell pieces by the V1 cells (measured at k = 2, docs/vpartition.md).
//
// Passes (each one sequential scan of the centroid sample, each one function below):
//   1. surfaceArea: total area (the area channel) -> r_i from the mean area per cell, and a
//      coarse density grid (mean triangle area per diag/256 cell) so the radius follows the
//      local density;
//   2. seedLevels: Poisson-disk seeding of every level; if a level's seed count misses its
//      target by more than kCalibrationTolerance, r_i is rescaled (counts go as 1/r^2) and this
//      pass is repeated (at most kMaxCalibrations times; typically 1, since the packing density
//      of the stream order is not known in advance);
//   3. relaxSeeds: nearest-seed assignment: drop seeds whose cells are below kMinCellFraction of
//      the mean (their triangles go to the next nearest seed), split the biggest cells above
//      kSplitFactor times the mean, move the others to their cell's centroid (one Lloyd step, in
//      the triangle-count measure);
//   4. trimSeeds: recount with the moved seeds, drop the cells that became too small or empty
//      and the smallest ones above the level's limit, split cells still above kFinalSplitFactor;
//   5. dropSmallCells, only after such a split: recount and drop the too small cells again, so
//      every cell is non-empty and no smaller than kMinCellFraction of the mean.
// Memory: seeds + one hash grid per level (~1 seed per kCrossPerCell * patchTriangles triangles,
// times 2 for all levels), independent of the mesh size otherwise. Every pass is sequential per
// level (levels run on separate threads), so the seeds are the same whatever the thread count.
#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <iterator>
#include <thread>
#include <unordered_map>
#include <unordered_set>

#include "vpartition/level.h"
#include "vpartition/vpartition.h"

namespace mt {

namespace {

using vp::PartitionLevel;

constexpr double kCrossPerCell = 3.1;      // V*0 cells per V0 cell (measured, docs)
constexpr double kAreaPerSeed = 1.45;      // first guess of cell area / r^2 (measured on scans)
constexpr double kMinCellFraction = 0.35;  // "remove small patches": below this share of the mean
constexpr double kCalibrationTolerance = 0.05;
constexpr int kMaxCalibrations = 2;
constexpr double kCalibrationAim = 1.05;   // seed a bit over the target, then trim (pass 4)
constexpr double kTrimTolerance = 0.12;      // pass 4 trims levels above target * (1 + this)
constexpr double kSplitFactor = 1.6;       // pass 3 splits cells above this multiple of the mean
constexpr double kFinalSplitFactor = 1.9;  // pass 4 splits cells above this (then pass 5)
// The sample the passes run on (BMT 4.2.2 seeds ~1 per 1000 triangles, so a few hundred sampled
// centroids per V0 cell place and relax them as well as all of them: measured on the 53 M mtgen
// scan, docs/vpartition.md). Its size depends on the input only, never on --memory or threads.
constexpr uint64_t kMinSample = 512u << 10;  // inputs up to 512 K triangles are used whole
constexpr double kSamplePerCell = 128;    // above that, at least this many per V0 cell target
// ...but never more than this (64 MiB of centroids): the sample must fit the V-partition's share
// of the smallest --memory a billion-triangle input is built with (128 MiB of 256M) beside the
// seeds and some candidate tables, and the sample, unlike the tables, may not depend on --memory
// (same bytes at every cap). Inputs up to ~203 M triangles at mtbuild's 2000 per patch stay below
// it and keep their partitions; a billion gets ~26 per V0 cell target (each sampled centroid
// standing for ~240 triangles).
constexpr uint64_t kMaxSample = 4u << 20;
constexpr double kLevelSamplePerCell = 1024;  // coarser levels thin the stream down to this
constexpr double kCountTolerance = 0.15;   // a level's final count stays within this of target

// Runs fn(level) for every level, levels spread over threads; each level stays on one thread and
// sees the batches in order, which keeps the result independent of the thread count.
template <class Fn> void forLevels(uint32_t requested, uint32_t levels, const Fn& fn) {
  uint32_t hw = requested ? requested : std::max(1u, std::thread::hardware_concurrency());
  uint32_t threads = std::min<uint32_t>(levels, hw);
  if (threads <= 1) {
    for (uint32_t l = 0; l < levels; ++l) fn(l);
    return;
  }
  std::vector<std::thread> pool;
  for (uint32_t t = 1; t < threads; ++t)
    pool.emplace_back([&, t] { for (uint32_t l = t; l < levels; l += threads) fn(l); });
  for (uint32_t l = 0; l < levels; l += threads) fn(l);
  for (auto& th : pool) th.join();
}

// Local inverse density: mean triangle area around a point, from a coarse hash grid filled in the
// area pass (cell size diag/256, so at most a few hundred thousand cells on any surface whatever
// the triangle count), smoothed over the 3x3x3 neighbourhood. BMT wants "cells, within each
// partition, [with] approximatively the same number of triangles"; scans have density varying by
// 10x or more, so the seed radius follows sqrt(local mean area) instead of being one radius.
class DensityGrid {
 public:
  explicit DensityGrid(const Box3& box) {
    double e[3], d2 = 0;
    for (int a = 0; a < 3; ++a) { e[a] = box.hi[a] - box.lo[a]; d2 += e[a] * e[a]; lo_[a] = box.lo[a]; }
    double diag = std::sqrt(d2);
    inv_ = diag > 0 ? 256.0 / diag : 1.0;
  }
  void add(const float* xyza, size_t count) {
    for (size_t t = 0; t < count; ++t) {
      auto& c = cells_[key(xyza + 4 * t, 0, 0, 0)];
      c.area += std::max(0.0f, xyza[4 * t + 3]);
      c.count += 1;
    }
  }
  void finish(double globalMean) {
    global_ = globalMean;
    for (const auto& [k, v] : cells_) {
      (void)v;
      int64_t c[3] = {int64_t(k & kMask) - kBias, int64_t((k >> 21) & kMask) - kBias,
                      int64_t(k >> 42) - kBias};
      double area = 0, count = 0;
      for (int64_t dz = -1; dz <= 1; ++dz)
        for (int64_t dy = -1; dy <= 1; ++dy)
          for (int64_t dx = -1; dx <= 1; ++dx) {
            auto it = cells_.find(vp::packCell(c[0] + dx, c[1] + dy, c[2] + dz));
            if (it != cells_.end()) { area += it->second.area; count += it->second.count; }
          }
      mean_[k] = count > 0 && area > 0 ? float(area / count) : float(globalMean);
    }
    cells_.clear();
  }
  double meanArea(const float* p) const {
    auto it = mean_.find(key(p, 0, 0, 0));
    return it == mean_.end() ? global_ : it->second;
  }
  uint64_t bytes() const { return (cells_.size() + mean_.size()) * 48; }

 private:
  static constexpr int64_t kBias = int64_t(1) << 20;
  static constexpr uint64_t kMask = (1u << 21) - 1;
  uint64_t key(const float* p, int dx, int dy, int dz) const {
    return vp::packCell(int64_t(std::floor((p[0] - lo_[0]) * inv_)) + dx,
                        int64_t(std::floor((p[1] - lo_[1]) * inv_)) + dy,
                        int64_t(std::floor((p[2] - lo_[2]) * inv_)) + dz);
  }
  struct Sum { double area = 0; uint64_t count = 0; };
  double lo_[3], inv_ = 1, global_ = 1;
  std::unordered_map<uint64_t, Sum> cells_;
  std::unordered_map<uint64_t, float> mean_;
};

// Seeding state of one level: the seeds so far in a hash grid of cell size `cell` (the level's
// radius at the mean density). A triangle becomes a seed when no seed lies within its local
// radius r(p) = scale * sqrt(meanArea(p)).
class StreamSeeder {
 public:
  StreamSeeder(double cell, const Box3& box) : inv_(1.0 / cell) {
    for (int a = 0; a < 3; ++a) lo_[a] = box.lo[a];
  }
  void offer(const float* p, float r) {
    const float r2 = r * r;
    // Stream coherence: the seed that covered the previous triangle usually covers this one.
    if (last_ != UINT32_MAX && vp::dist2(p, &seeds_[3 * size_t(last_)]) <= r2) {
      ++covered_[last_];
      return;
    }
    int64_t c[3];
    for (int a = 0; a < 3; ++a) c[a] = int64_t(std::floor((p[a] - lo_[a]) * inv_));
    const int64_t k = std::max<int64_t>(1, int64_t(std::ceil(r * inv_)));
    // Without stream coherence (shuffled faces) the triangle's own cell usually holds a covering
    // seed already: look there before the (2k+1)^3 - 1 neighbours.
    if (auto it = head_.find(vp::packCell(c[0], c[1], c[2])); it != head_.end())
      for (uint32_t s = it->second; s != UINT32_MAX; s = next_[s])
        if (vp::dist2(p, &seeds_[3 * size_t(s)]) <= r2) {
          last_ = s;
          ++covered_[s];
          return;
        }
    for (int64_t dz = -k; dz <= k; ++dz)
      for (int64_t dy = -k; dy <= k; ++dy)
        for (int64_t dx = -k; dx <= k; ++dx) {
          if (dx == 0 && dy == 0 && dz == 0) continue;
          auto it = head_.find(vp::packCell(c[0] + dx, c[1] + dy, c[2] + dz));
          if (it == head_.end()) continue;
          for (uint32_t s = it->second; s != UINT32_MAX; s = next_[s])
            if (vp::dist2(p, &seeds_[3 * size_t(s)]) <= r2) {
              last_ = s;
              ++covered_[s];
              return;
            }
        }
    uint32_t id = uint32_t(seeds_.size() / 3);
    seeds_.insert(seeds_.end(), p, p + 3);
    radii_.push_back(r);
    covered_.push_back(1);
    auto [it, fresh] = head_.try_emplace(vp::packCell(c[0], c[1], c[2]), id);
    next_.push_back(fresh ? UINT32_MAX : it->second);
    it->second = id;
    last_ = id;
  }
  uint32_t count() const { return uint32_t(seeds_.size() / 3); }
  // Seeds that will likely survive the small-cell removal: the triangles a seed covered first in
  // the stream approximate its cell, so small components and slivers show up here already and
  // the calibration can aim at the count after removal.
  uint32_t viable(uint64_t triangles) const {
    double mean = double(triangles) / std::max(1u, count());
    uint32_t n = 0;
    for (uint32_t c : covered_) n += c >= kMinCellFraction * mean ? 1 : 0;
    return std::max(1u, n);
  }
  std::vector<float>& seeds() { return seeds_; }
  const std::vector<float>& radii() const { return radii_; }
  uint64_t bytes() const {
    return seeds_.capacity() * 4 + radii_.capacity() * 4 + next_.capacity() * 4 + head_.size() * 32;
  }

 private:
  double inv_, lo_[3];
  std::vector<float> seeds_, radii_;
  std::vector<uint32_t> covered_;
  std::unordered_map<uint64_t, uint32_t> head_;
  std::vector<uint32_t> next_;
  uint32_t last_ = UINT32_MAX;
};

// Per-seed sums of one level over one assignment pass.
struct CellSums {
  std::vector<uint32_t> count;
  std::vector<double> plain;       // 3 per seed: sum of x, y, z
  std::vector<double> second;      // 6 per seed (pass 3): sum of d d^T, d = centroid - seed
};

std::vector<CellSums> assignAll(const CentroidSource& src,
                                const std::vector<std::vector<float>>& seeds,
                                const std::vector<double>& radii, const Box3& box,
                                const std::vector<uint64_t>& thin, uint32_t threads, uint32_t& passes,
                                std::vector<std::vector<uint64_t>>* queryCells = nullptr) {
  uint32_t levels = uint32_t(seeds.size());
  std::vector<vp::SeedIndex> index(levels);
  std::vector<CellSums> sums(levels);
  for (uint32_t l = 0; l < levels; ++l) {
    uint32_t n = uint32_t(seeds[l].size() / 3);
    index[l].build(seeds[l].data(), n, radii[l], box.lo);
    sums[l].count.assign(n, 0);
    sums[l].plain.assign(3 * size_t(n), 0.0);
    sums[l].second.assign(6 * size_t(n), 0.0);
  }
  std::vector<std::unordered_set<uint64_t>> cells(queryCells ? levels : 0);
  uint64_t base = 0;  // stream index of the batch's first centroid
  src.forEach([&](const float* xyza, size_t count) {
    forLevels(threads, levels, [&](uint32_t l) {
      CellSums& s = sums[l];
      uint64_t previous = ~0ull;
      for (size_t t = size_t((thin[l] - base % thin[l]) % thin[l]); t < count; t += size_t(thin[l])) {
        const float* c = xyza + 4 * t;
        if (queryCells) {
          uint64_t key = index[l].queryCell(c);
          if (key != previous) cells[l].insert(key);  // stream coherence: skip repeats
          previous = key;
        }
        uint32_t id = index[l].nearestCached(c);
        ++s.count[id];
        for (int a = 0; a < 3; ++a) s.plain[3 * size_t(id) + a] += c[a];
        if (!s.second.empty()) {
          const float* q = &seeds[l][3 * size_t(id)];
          double d[3] = {double(c[0]) - q[0], double(c[1]) - q[1], double(c[2]) - q[2]};
          double* m = &s.second[6 * size_t(id)];
          m[0] += d[0] * d[0]; m[1] += d[0] * d[1]; m[2] += d[0] * d[2];
          m[3] += d[1] * d[1]; m[4] += d[1] * d[2]; m[5] += d[2] * d[2];
        }
      }
    });
    base += count;
  });
  ++passes;
  if (queryCells) {
    queryCells->resize(levels);
    for (uint32_t l = 0; l < levels; ++l) {
      (*queryCells)[l].assign(cells[l].begin(), cells[l].end());
      std::sort((*queryCells)[l].begin(), (*queryCells)[l].end());
    }
  }
  return sums;
}

// The two seeds that split cell i along its principal axis, at the centroids of the halves
// (+-0.87 sigma for an even spread); false for a degenerate cell.
bool splitCell(const CellSums& s, uint32_t i, const float* seed, float out[6]) {
  double k = s.count[i];
  if (k < 2) return false;
  double mu[3], e[3];
  for (int a = 0; a < 3; ++a) {
    mu[a] = s.plain[3 * size_t(i) + a] / k;
    e[a] = mu[a] - seed[a];  // moments are about the seed
  }
  const double* m2 = &s.second[6 * size_t(i)];
  double C[3][3] = {{m2[0], m2[1], m2[2]}, {m2[1], m2[3], m2[4]}, {m2[2], m2[4], m2[5]}};
  for (int a = 0; a < 3; ++a)
    for (int b = 0; b < 3; ++b) C[a][b] = C[a][b] / k - e[a] * e[b];
  double v[3] = {1, 0.7, 0.4}, lambda = 0;
  for (int it = 0; it < 32; ++it) {  // power iteration: fixed start, deterministic
    double w[3];
    for (int a = 0; a < 3; ++a) w[a] = C[a][0] * v[0] + C[a][1] * v[1] + C[a][2] * v[2];
    lambda = std::sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    if (!(lambda > 0)) return false;
    for (int a = 0; a < 3; ++a) v[a] = w[a] / lambda;
  }
  double off = 0.87 * std::sqrt(lambda);
  for (int a = 0; a < 3; ++a) {
    out[a] = float(mu[a] - off * v[a]);
    out[3 + a] = float(mu[a] + off * v[a]);
  }
  return off > 0;
}

// What every pass over the sample shares: the sample, its box, and per level the cell count aimed
// for and the thinning of the stream. Counts are in sample units, except the targets, which come
// from the whole input.
struct LevelPlan {
  const CentroidSource& src;
  Box3 box;
  uint64_t N = 0;                 // sampled centroids
  uint32_t levels = 0;
  uint32_t threads = 0;
  uint32_t maxCoarsestCells = 0;
  std::vector<double> target;     // cells aimed for, per level
  // Coarser levels have fewer, bigger cells: each level looks at every thin[l]-th centroid of
  // the stream, enough for kLevelSamplePerCell per target cell, so a pass costs about two
  // finest levels rather than `levels` of them. Nl[l]: the centroids level l sees.
  std::vector<uint64_t> thin, Nl;

  // The most cells level l may keep: target * (1 + tolerance), and maxCoarsestCells for the
  // coarsest level (which bounds the root's backward star).
  uint64_t limit(uint32_t l, double tolerance) const {
    uint64_t n = uint64_t(std::floor(target[l] * (1 + tolerance)));
    if (l + 1 == levels) n = std::min<uint64_t>(n, maxCoarsestCells);
    return n;
  }
};

// "Remove small patches": an empty cell, or one below kMinCellFraction of the level's mean (a
// level of one cell keeps it).
bool tooSmall(uint32_t count, uint32_t cells, double mean) {
  return count == 0 || (cells > 1 && count < kMinCellFraction * mean);
}

// Level targets: N / (T0 k^i) cells (k = the level ratio: each level's mesh keeps 1/k of the
// triangles of the one below, so its cells keep about as many triangles), down to the first level
// with <= maxCoarsestCells. k^i by products of integers: exact, so k = 2 gives the 2^i it always did.
std::vector<double> levelTargets(uint64_t Ntotal, uint32_t P, const VPartitionOptions& o) {
  const double T0 = P * kCrossPerCell;
  std::vector<double> target;
  double power = 1;
  for (uint32_t l = 0; l < o.maxLevels; ++l, power *= o.levelRatio) {
    double t = std::max(1.0, std::round(double(Ntotal) / (T0 * power)));
    target.push_back(t);
    if (t <= o.maxCoarsestCells) break;
  }
  return target;
}

void planThinning(LevelPlan& plan) {
  plan.thin.resize(plan.levels);
  plan.Nl.resize(plan.levels);
  for (uint32_t l = 0; l < plan.levels; ++l) {
    plan.thin[l] = std::max<uint64_t>(1, uint64_t(double(plan.N) / (kLevelSamplePerCell * plan.target[l])));
    plan.Nl[l] = (plan.N + plan.thin[l] - 1) / plan.thin[l];
  }
}

// Pass 1: the surface area, globally for the radii and locally for the density grid.
double surfaceArea(const CentroidSource& src, DensityGrid& density) {
  double area = 0;
  src.forEach([&](const float* xyza, size_t count) {
    for (size_t t = 0; t < count; ++t) area += std::max(0.0f, xyza[4 * t + 3]);
    density.add(xyza, count);
  });
  return area;
}

// One seeding scan of every level at the given radii (pass 2).
std::vector<StreamSeeder> seedOnce(const LevelPlan& plan, const DensityGrid& density, double meanArea,
                                   const std::vector<double>& radius) {
  std::vector<StreamSeeder> seeders;
  for (uint32_t l = 0; l < plan.levels; ++l)
    seeders.emplace_back(2 * radius[l], plan.box);  // cells of 2r: the own cell usually covers
  std::vector<float> local;  // sqrt(meanArea(p) / meanArea) per triangle of the batch
  uint64_t base = 0;
  plan.src.forEach([&](const float* xyza, size_t count) {
    local.resize(count);
    for (size_t t = 0; t < count; ++t) local[t] = float(std::sqrt(density.meanArea(xyza + 4 * t) / meanArea));
    forLevels(plan.threads, plan.levels, [&](uint32_t l) {
      float r = float(radius[l]);
      for (size_t t = size_t((plan.thin[l] - base % plan.thin[l]) % plan.thin[l]); t < count; t += size_t(plan.thin[l]))
        seeders[l].offer(xyza + 4 * t, r * local[t]);
    });
    base += count;
  });
  return seeders;
}

// Pass 2 (+ calibration repeats): stream seeding of all levels. `radius` is rescaled by the
// calibrations; indexCell gets each level's nearest-seed index cell.
std::vector<std::vector<float>> seedLevels(const LevelPlan& plan, const DensityGrid& density, double meanArea,
                                           std::vector<double>& radius, std::vector<double>& indexCell,
                                           PartitionBuildStats& stats) {
  for (int attempt = 0;; ++attempt) {
    std::vector<StreamSeeder> seeders = seedOnce(plan, density, meanArea, radius);
    ++stats.samplePasses;
    uint64_t bytes = density.bytes();
    bool off = false;
    for (uint32_t l = 0; l < plan.levels; ++l) {
      bytes += seeders[l].bytes();
      // Only levels with room to be off by a cell are worth another pass.
      // A level of n cells cannot be closer than ~1/n, and its count fluctuates by ~1/sqrt(n)
      // from one radius to the next, so small levels get a wider tolerance.
      double ratio = seeders[l].viable(plan.Nl[l]) / (plan.target[l] * kCalibrationAim);
      double tolerance = std::max(kCalibrationTolerance, 1.0 / std::sqrt(plan.target[l]));
      if (plan.target[l] >= 8 && std::fabs(ratio - 1) > tolerance) off = true;
    }
    stats.seedBytes = std::max(stats.seedBytes, bytes);
    if (off && attempt < kMaxCalibrations) {
      for (uint32_t l = 0; l < plan.levels; ++l)
        radius[l] *= std::sqrt(double(seeders[l].viable(plan.Nl[l])) / (plan.target[l] * kCalibrationAim));
      ++stats.calibrationPasses;
      continue;
    }
    std::vector<std::vector<float>> seeds(plan.levels);
    for (uint32_t l = 0; l < plan.levels; ++l) {
      // The nearest-seed index works best with grid cells about the seed spacing of the denser
      // parts (candidate lists stay short there, where most triangles are).
      std::vector<float> r = seeders[l].radii();
      assert(!r.empty());  // the first centroid a level sees always becomes a seed
      std::nth_element(r.begin(), r.begin() + r.size() / 5, r.end());
      indexCell[l] = std::max(double(r[r.size() / 5]), radius[l] * 1e-3);
      seeds[l] = std::move(seeders[l].seeds());
    }
    return seeds;
  }
}

// Pass 3's split budget: the biggest cells above kSplitFactor * mean, as many as keep the level
// under the trim limit of pass 4 (trimming would otherwise drop small separate components,
// dumping them into a neighbour's cell).
std::vector<uint8_t> cellsToSplit(const CellSums& s, double mean, uint64_t limit) {
  const uint32_t n = uint32_t(s.count.size());
  std::vector<uint8_t> split(n, 0);
  uint64_t kept = 0;
  std::vector<uint32_t> big;
  for (uint32_t i = 0; i < n; ++i) {
    if (tooSmall(s.count[i], n, mean)) continue;
    ++kept;
    if (s.count[i] > kSplitFactor * mean) big.push_back(i);
  }
  std::stable_sort(big.begin(), big.end(), [&](uint32_t a, uint32_t b) { return s.count[a] > s.count[b]; });
  for (uint32_t i : big) {
    if (kept + 1 > limit) break;
    split[i] = 1;
    ++kept;
  }
  return split;
}

// Pass 3 on one level: the new seeds, without the small cells, with the chosen big ones split.
std::vector<float> relaxLevel(const CellSums& s, const std::vector<float>& seeds, double mean, uint64_t limit,
                              PartitionBuildStats& stats) {
  const uint32_t n = uint32_t(s.count.size());
  const std::vector<uint8_t> split = cellsToSplit(s, mean, limit);
  std::vector<float> moved;
  moved.reserve(seeds.size());
  for (uint32_t i = 0; i < n; ++i) {
    if (tooSmall(s.count[i], n, mean)) {
      ++stats.removedSeeds;
      continue;
    }
    // Lloyd step in the triangle-count measure (plain centroid of the centroids, not the
    // area-weighted one): it pulls seeds towards denser parts, which evens out triangle
    // counts per cell, the quantity BMT wants constant.
    double k = s.count[i];
    double mu[3];
    for (int a = 0; a < 3; ++a) mu[a] = s.plain[3 * size_t(i) + a] / k;
    if (!split[i]) {
      for (int a = 0; a < 3; ++a) moved.push_back(float(mu[a]));
      continue;
    }
    // Too big a cell (a thin part whose both sides one ball covered, a region the stream
    // order packed loosely): split it along its principal axis. Pass 4 checks the result.
    float two[6];
    if (splitCell(s, i, &seeds[3 * size_t(i)], two)) {
      moved.insert(moved.end(), two, two + 6);
      ++stats.splitSeeds;
    } else {
      for (int a = 0; a < 3; ++a) moved.push_back(float(mu[a]));
    }
  }
  assert(!moved.empty());
  return moved;
}

// Pass 3: remove small cells, split big ones, one Lloyd step.
void relaxSeeds(const LevelPlan& plan, const std::vector<double>& indexCell,
                std::vector<std::vector<float>>& seeds, PartitionBuildStats& stats) {
  std::vector<CellSums> sums =
      assignAll(plan.src, seeds, indexCell, plan.box, plan.thin, plan.threads, stats.samplePasses);
  for (uint32_t l = 0; l < plan.levels; ++l) {
    const double mean = double(plan.Nl[l]) / uint32_t(sums[l].count.size());
    seeds[l] = relaxLevel(sums[l], seeds[l], mean, plan.limit(l, kTrimTolerance), stats);
  }
}

// Pass 4's kept cells of one level: the non-small ones, then, above `limit`, without the
// smallest (stable: equal counts keep the lower index). Ascending.
std::vector<uint32_t> keptCells(const CellSums& s, double mean, uint64_t limit) {
  const uint32_t n = uint32_t(s.count.size());
  std::vector<uint32_t> keep;
  for (uint32_t i = 0; i < n; ++i)
    if (!tooSmall(s.count[i], n, mean)) keep.push_back(i);
  if (keep.size() > limit) {
    std::vector<uint32_t> bySize = keep;
    std::stable_sort(bySize.begin(), bySize.end(), [&](uint32_t a, uint32_t b) { return s.count[a] < s.count[b]; });
    bySize.resize(keep.size() - limit);
    std::sort(bySize.begin(), bySize.end());
    std::vector<uint32_t> rest;
    std::set_difference(keep.begin(), keep.end(), bySize.begin(), bySize.end(), std::back_inserter(rest));
    keep.swap(rest);
  }
  assert(keep.size() <= limit);
  return keep;
}

// Pass 4 on one level; true when a cell was split (pass 5 must recount).
bool trimLevel(const LevelPlan& plan, uint32_t l, const CellSums& s, std::vector<float>& seeds,
               PartitionBuildStats& stats) {
  const uint32_t n = uint32_t(s.count.size());
  const double mean = double(plan.Nl[l]) / n;
  const std::vector<uint32_t> keep = keptCells(s, mean, std::max<uint64_t>(1, plan.limit(l, kTrimTolerance)));
  stats.removedSeeds += n - keep.size();
  // Cells still far above the mean (a Lloyd step can move a seed off a curved part, e.g.
  // into a small torus' hole, where it captures the whole ring) are split once more; pass 5
  // then recounts. Budget: the count may reach target * (1 + kCountTolerance).
  const double keptMean = double(plan.N) / keep.size();
  uint64_t room = plan.limit(l, kCountTolerance);
  room = room > keep.size() ? room - keep.size() : 0;
  bool split = false;
  std::vector<float> kept;
  kept.reserve(3 * keep.size());
  for (uint32_t i : keep) {
    float two[6];
    if (room > 0 && s.count[i] > kFinalSplitFactor * keptMean && splitCell(s, i, &seeds[3 * size_t(i)], two)) {
      kept.insert(kept.end(), two, two + 6);
      --room;
      ++stats.splitSeeds;
      split = true;
      continue;
    }
    kept.insert(kept.end(), &seeds[3 * size_t(i)], &seeds[3 * size_t(i)] + 3);
  }
  assert(!kept.empty());
  seeds = std::move(kept);
  return split;
}

// Pass 4: recount with the moved seeds; drop empty and too small cells, then, where a level
// still has more cells than aimed for (thin parts and separate components hold more seeds than
// their area predicts), the smallest cells down to the target. Removing a seed only grows its
// neighbours, so every kept cell stays non-empty; the coarsest level is cut to
// maxCoarsestCells, which bounds the root's backward star. Also gathers the query cells the
// mesh touches, for the shared candidate table of the final index (same frame: origin box.lo,
// cell indexCell[l]), so random-order lookups stay fast. True when pass 5 must run.
bool trimSeeds(const LevelPlan& plan, const std::vector<double>& indexCell, std::vector<std::vector<float>>& seeds,
               std::vector<std::vector<uint64_t>>& queryCells, PartitionBuildStats& stats) {
  std::vector<CellSums> sums =
      assignAll(plan.src, seeds, indexCell, plan.box, plan.thin, plan.threads, stats.samplePasses, &queryCells);
  bool recount = false;
  for (uint32_t l = 0; l < plan.levels; ++l) recount |= trimLevel(plan, l, sums[l], seeds[l], stats);
  return recount;
}

// Pass 5, only after a late split: drop the cells that became empty or too small.
void dropSmallCells(const LevelPlan& plan, const std::vector<double>& indexCell,
                    std::vector<std::vector<float>>& seeds, PartitionBuildStats& stats) {
  std::vector<CellSums> sums =
      assignAll(plan.src, seeds, indexCell, plan.box, plan.thin, plan.threads, stats.samplePasses);
  for (uint32_t l = 0; l < plan.levels; ++l) {
    const CellSums& s = sums[l];
    const uint32_t n = uint32_t(s.count.size());
    const double mean = double(plan.Nl[l]) / n;
    std::vector<float> kept;
    for (uint32_t i = 0; i < n; ++i) {
      if (tooSmall(s.count[i], n, mean)) {
        ++stats.removedSeeds;
        continue;
      }
      kept.insert(kept.end(), &seeds[l][3 * size_t(i)], &seeds[l][3 * size_t(i)] + 3);
    }
    assert(!kept.empty());
    seeds[l] = std::move(kept);
  }
}

// The finished levels, with the candidate tables of the finest levels that fit the budget
// (~64 bytes per query cell: slot + candidates; ingest asks V0 and V1).
void addLevels(PartitionSequence& seq, const LevelPlan& plan, const std::vector<double>& indexCell,
               std::vector<std::vector<float>>& seeds, std::vector<std::vector<uint64_t>>& queryCells,
               uint64_t tableBudget) {
  assert(queryCells.size() == plan.levels);
  for (uint32_t l = 0; l < plan.levels; ++l) {
    auto L = std::make_unique<PartitionLevel>();
    L->type = PartitionLevel::Seeds;
    L->scale = indexCell[l];
    L->target = uint64_t(plan.target[l]);
    L->seeds = std::move(seeds[l]);
    for (int a = 0; a < 3; ++a) L->origin[a] = plan.box.lo[a];
    uint64_t tableBytes = 64 * queryCells[l].size();
    if (tableBytes <= tableBudget) {
      tableBudget -= tableBytes;
      L->queryCells = std::move(queryCells[l]);
    } else {
      tableBudget = 0;
    }
    seq.addLevel(std::move(L));
  }
}

// Nothing to partition: one cell, seeded at the box centre, so cellOf() still works.
void addSingleCell(PartitionSequence& seq, const Box3& box) {
  auto L = std::make_unique<PartitionLevel>();
  L->scale = 1;
  L->target = 1;
  for (int a = 0; a < 3; ++a) L->seeds.push_back(float(0.5 * (box.lo[a] + box.hi[a])));
  seq.addLevel(std::move(L));
}

}  // namespace

namespace vp {

uint64_t sampleLimit(uint64_t triangles, uint32_t patchTriangles) {
  const double cells = double(triangles) / (double(patchTriangles) * kCrossPerCell);
  return std::min<uint64_t>(kMaxSample, std::max<uint64_t>(kMinSample, uint64_t(std::ceil(kSamplePerCell * cells))));
}

CentroidSample sampleCentroids(const CentroidSource& src, uint32_t patchTriangles) {
  CentroidSample s;
  s.total = src.count();
  s.bounds = src.bounds();
  const uint32_t P = patchTriangles ? patchTriangles : kDefaultPatchTriangles;
  const uint64_t limit = sampleLimit(s.total, P);
  s.stride = std::max<uint64_t>(1, (s.total + limit - 1) / limit);
  // Every stride-th centroid of the stream: the source order is spatially coherent (ingest
  // streams Morton order), so this is a stratified sample of the surface, in stream order.
  // Ingest picks them straight from its Morton sort (CentroidSource::sample).
  s.xyza = src.sample(s.stride);
  s.xyza.shrink_to_fit();
  return s;
}

}  // namespace vp

PartitionSequence buildIrregularSequence(const CentroidSource& src, const VPartitionOptions& o) {
  return buildIrregularFromSample(
      vp::sampleCentroids(src, o.patchTriangles ? o.patchTriangles : kDefaultPatchTriangles), o);
}

PartitionSequence buildIrregularFromSample(const vp::CentroidSample& sample, const VPartitionOptions& o) {
  auto start = std::chrono::steady_clock::now();
  PartitionBuildStats stats;
  stats.passes = 1;  // the one pass over the input that took the sample
  stats.sampleStride = sample.stride;
  const uint32_t P = o.patchTriangles ? o.patchTriangles : kDefaultPatchTriangles;
  // Every pass below runs over the in-memory sample.
  vp::SampleSource src(sample);
  LevelPlan plan{src, src.bounds()};
  plan.N = src.count();
  plan.threads = o.threads;
  plan.maxCoarsestCells = o.maxCoarsestCells;
  const uint64_t Ntotal = sample.total;

  DensityGrid density(plan.box);
  double area = surfaceArea(src, density);
  ++stats.samplePasses;

  PartitionSequence seq;
  seq.setKind(PartitionKind::Irregular);
  seq.setLevelRatio(o.levelRatio);
  if (plan.N == 0) {
    addSingleCell(seq, plan.box);
    seq.mutableStats() = stats;
    return seq;
  }
  if (!(area > 0)) {
    // Degenerate input (all triangles zero-area): use the bounding box faces as the area. An
    // extent is at least 1/1000 of the largest: on a box with two zero extents (a line), 1e-30
    // made the seed radius ~1e-15 of the box and the seed index enumerate ~1e15 cells.
    double e[3], largest = 1e-30;
    for (int a = 0; a < 3; ++a) largest = std::max(largest, plan.box.hi[a] - plan.box.lo[a]);
    for (int a = 0; a < 3; ++a) e[a] = std::max(1e-3 * largest, plan.box.hi[a] - plan.box.lo[a]);
    area = 2 * (e[0] * e[1] + e[1] * e[2] + e[0] * e[2]) * double(plan.N) / double(Ntotal);
  }
  // Input triangles per sampled one: the sample's area stands for weight times as much surface.
  const double weight = double(Ntotal) / double(plan.N);
  plan.target = levelTargets(Ntotal, P, o);
  plan.levels = uint32_t(plan.target.size());
  planThinning(plan);
  // Level radius at the mean density; locally r_l(p) = radius[l] * sqrt(meanArea(p) / meanArea).
  const double meanArea = area / double(plan.N);
  density.finish(meanArea);
  stats.seedBytes = density.bytes();
  std::vector<double> radius(plan.levels);
  for (uint32_t l = 0; l < plan.levels; ++l) radius[l] = std::sqrt(area * weight / (plan.target[l] * kAreaPerSeed));
  std::vector<double> indexCell(plan.levels);

  std::vector<std::vector<float>> seeds = seedLevels(plan, density, meanArea, radius, indexCell, stats);
  relaxSeeds(plan, indexCell, seeds, stats);
  std::vector<std::vector<uint64_t>> queryCells;
  if (trimSeeds(plan, indexCell, seeds, queryCells, stats)) dropSmallCells(plan, indexCell, seeds, stats);
  addLevels(seq, plan, indexCell, seeds, queryCells, o.lookupTableBytes);

  stats.seedBytes = std::max(stats.seedBytes, seq.memoryBytes() + density.bytes());
  stats.sampleBytes = sample.bytes();
  stats.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  seq.mutableStats() = stats;
  return seq;
}

}  // namespace mt
