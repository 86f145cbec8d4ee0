// Internal to vpartition: one level's cell function (regular grid cells or nearest irregular seed)
// and the static nearest-seed index behind the irregular levels.
#pragma once

#include <cassert>
#include <cmath>
#include <cstdint>
#include <vector>
#include <algorithm>
#include <functional>

#include "patchstore/cell_assigner.h"

namespace mt::vp {

// Squared distance in float: the one distance every nearest-seed decision uses, so the cached
// path, the exact ring search and the builders all agree bit for bit (determinism).
inline float dist2(const float* a, const float* b) {
  float dx = a[0] - b[0], dy = a[1] - b[1], dz = a[2] - b[2];
  return dx * dx + dy * dy + dz * dz;
}

// Packs a clamped integer cell coordinate triple into one 63-bit hash key.
inline uint64_t packCell(int64_t x, int64_t y, int64_t z) {
  constexpr int64_t kBias = int64_t(1) << 20, kMax = (int64_t(1) << 21) - 1;
  auto c = [&](int64_t v) { v += kBias; return uint64_t(v < 0 ? 0 : v > kMax ? kMax : v); };
  return c(x) | (c(y) << 21) | (c(z) << 42);
}

// A uniform hash grid over a fixed seed set, answering exact nearest-seed queries (ties: lower
// seed index) and radius queries. cellOf() goes through a per-thread cache of candidate lists per
// small query cell (see assign.cpp), which is what makes ~20 M lookups/s/core possible.
class SeedIndex {
 public:
  // origin: the frame of the grid and of the query cells (so callers can name query cells
  // before the seeds are final); nullptr: the seeds' minimum corner.
  void build(const float* seeds, uint32_t count, double cellSize, const double* origin = nullptr);
  // Key of the query cell holding p (cells of half the grid size, same origin).
  uint64_t queryCell(const float p[3]) const;
  // Precomputes the candidate lists of these query cells into a shared read-only table, so
  // queries there skip the per-thread cache (random-order queries stay fast).
  void precompute(const std::vector<uint64_t>& queryCells);
  uint32_t size() const { return count_; }
  double cellSize() const { return size_; }
  // Exact nearest seed by ring search; UINT32_MAX when there are no seeds.
  uint32_t nearest(const float p[3]) const;
  // Appends the seeds within `radius` of p, ascending by index.
  void within(const double p[3], double radius, std::vector<uint32_t>& out) const;
  // The cached path: exact nearest, same answer as nearest(). Thread-safe.
  uint32_t nearestCached(const float p[3]) const;
  uint64_t bytes() const {
    return table_.capacity() * sizeof(Slot) + order_.capacity() * 4 +
           shared_.capacity() * sizeof(Slot) + sharedCand_.capacity() * 4;
  }

 private:
  struct Slot { uint64_t key; uint32_t begin, end; };
  const Slot* find(uint64_t key) const;
  const Slot* findShared(uint64_t key) const;
  // Candidate list of a query cell (ascending seed indices); empty when it would be too long.
  void candidates(uint64_t key, std::vector<uint32_t>& out) const;
  int64_t coord(double v, int a) const { return int64_t(std::floor((v - origin_[a]) * inv_)); }

  const float* seeds_ = nullptr;  // owned by the PartitionLevel
  uint32_t count_ = 0;
  double size_ = 1, inv_ = 1, origin_[3] = {0, 0, 0};
  int64_t lo_[3] = {0, 0, 0}, hi_[3] = {0, 0, 0};  // occupied seed cell range
  std::vector<Slot> table_;       // open addressing, key ~0 = empty
  uint64_t mask_ = 0;
  std::vector<uint32_t> order_;   // seed indices grouped by cell, ascending within a cell
  std::vector<Slot> shared_;      // precomputed query cells: key -> sharedCand_ range
  uint64_t sharedMask_ = 0;
  std::vector<uint32_t> sharedCand_;
  uint64_t uid_ = 0;              // identifies this index in the per-thread caches
};

// One partition Vi.
struct PartitionLevel {
  enum Type : uint8_t { Seeds = 0, Cube = 1, EdgeOct = 2, FaceOct = 3, Square = 4, Diamond = 5 };
  Type type = Seeds;
  double scale = 0;        // irregular: seed radius r_i; regular: grid spacing h
  uint64_t target = 0;     // irregular: the cell count aimed for
  // irregular
  std::vector<float> seeds;  // xyz per seed
  SeedIndex index;
  // regular: a grid of n[] cubes of side `scale` from `origin`; 2D kinds use axes axis0/axis1
  double origin[3] = {0, 0, 0};
  uint32_t n[3] = {1, 1, 1};
  uint8_t axis0 = 0, axis1 = 1;

  std::vector<uint64_t> queryCells;  // builder only: query cells the mesh touches (precomputed)
  void finishSeeds() {
    index.build(seeds.data(), uint32_t(seeds.size() / 3), scale, origin);
    if (!queryCells.empty()) index.precompute(queryCells);
    queryCells.clear();
    queryCells.shrink_to_fit();
  }
  uint32_t cellCount() const;
  uint32_t cellOf(const float c[3]) const;
  void seedOf(uint32_t cell, float out[3]) const;
};

// A stride sample of a centroid stream (every stride-th centroid, in stream order), which the
// irregular builder and the ingest assigner's balancing run on instead of re-reading the input:
// one pass over the input instead of 5-9 (irregular.cpp). Inputs up to sampleLimit() are kept
// whole (stride 1), so small meshes are partitioned exactly as from the full stream.
struct CentroidSample {
  std::vector<float> xyza;  // 4 floats per sampled triangle: centroid, area
  uint64_t total = 0;       // triangles in the input
  uint64_t stride = 1;
  Box3 bounds;              // of the input
  uint64_t count() const { return xyza.size() / 4; }
  // Input triangles each sampled one stands for.
  double weight() const { return count() ? double(total) / double(count()) : 1.0; }
  uint64_t bytes() const { return xyza.capacity() * sizeof(float); }
};
uint64_t sampleLimit(uint64_t triangles, uint32_t patchTriangles);
CentroidSample sampleCentroids(const CentroidSource& src, uint32_t patchTriangles);

// The sample as a CentroidSource (batches of 64 K, in sample order).
class SampleSource : public CentroidSource {
 public:
  explicit SampleSource(const CentroidSample& s) : s_(s) {}
  uint64_t count() const override { return s_.count(); }
  Box3 bounds() const override { return s_.bounds; }
  void forEach(const std::function<void(const float* xyza, size_t count)>& fn) const override {
    for (uint64_t i = 0; i < s_.count(); i += 65536) fn(&s_.xyza[4 * i], size_t(std::min<uint64_t>(65536, s_.count() - i)));
  }

 private:
  const CentroidSample& s_;
};

// The regular cell functions (regular.cpp).
uint32_t regularCellCount(const PartitionLevel& level);
uint32_t regularCellOf(const PartitionLevel& level, const float c[3]);
void regularSeedOf(const PartitionLevel& level, uint32_t cell, float out[3]);

}  // namespace mt::vp
