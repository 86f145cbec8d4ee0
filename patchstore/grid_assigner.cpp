// The default cell assignment: a uniform grid of cubic cells over the bounding box. The cell size
// comes from the surface area (a cell of side s cuts about s^2 of a smooth surface), then is
// corrected once by counting the occupied cells, since scans fill their box very unevenly.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <unordered_set>

#include "base/error.h"
#include "patchstore/cell_assigner.h"

namespace mt {

namespace {

class GridAssigner : public CellAssigner {
 public:
  explicit GridAssigner(uint32_t trianglesPerCell) : target_(trianglesPerCell ? trianglesPerCell : 2048) {}

  void prepare(const CentroidSource& centroids, uint64_t) override {
    box_ = centroids.bounds();
    double area = 0;
    centroids.forEach([&](const float* c, size_t n) {
      for (size_t i = 0; i < n; ++i) area += c[4 * i + 3];
    });
    double extent = std::max({box_.hi[0] - box_.lo[0], box_.hi[1] - box_.lo[1], box_.hi[2] - box_.lo[2], 1e-30});
    double triangles = double(std::max<uint64_t>(1, centroids.count()));
    double side = area > 0 ? std::sqrt(area * target_ / triangles) : extent / std::cbrt(triangles / target_);
    setSide(side);
    // One correction from the occupied-cell count (bounded: about triangles / target cells).
    std::unordered_set<uint64_t> occupied;
    centroids.forEach([&](const float* c, size_t n) {
      for (size_t i = 0; i < n; ++i) occupied.insert(cellKey(c + 4 * i));
    });
    double mean = triangles / double(std::max<size_t>(1, occupied.size()));
    setSide(side_ * std::sqrt(target_ / mean));
  }

  uint64_t cellKey(const float c[3]) const override {
    uint64_t key = 0;
    for (int a = 0; a < 3; ++a) {
      double t = std::floor((double(c[a]) - box_.lo[a]) * inverse_);
      uint64_t i = uint64_t(std::clamp(t, 0.0, double(cells_[a] - 1)));
      key = key << 21 | i;
    }
    return key;
  }

  std::string describe() const override {
    char buf[128];
    std::snprintf(buf, sizeof buf, "grid %ux%ux%u (cell %.4g, target %u triangles)", cells_[0], cells_[1], cells_[2],
                  side_, target_);
    return buf;
  }

 private:
  void setSide(double side) {
    double extent = std::max({box_.hi[0] - box_.lo[0], box_.hi[1] - box_.lo[1], box_.hi[2] - box_.lo[2], 1e-30});
    side_ = std::max(side, extent / double(kMaxCells));
    inverse_ = 1.0 / side_;
    for (int a = 0; a < 3; ++a) cells_[a] = uint32_t(std::clamp(std::ceil((box_.hi[a] - box_.lo[a]) * inverse_), 1.0, double(kMaxCells)));
  }
  static constexpr uint32_t kMaxCells = 1u << 21;
  uint32_t target_;
  Box3 box_;
  double side_ = 1, inverse_ = 1;
  uint32_t cells_[3] = {1, 1, 1};
};

}  // namespace

std::unique_ptr<CellAssigner> makeGridAssigner(uint32_t trianglesPerCell) {
  return std::make_unique<GridAssigner>(trianglesPerCell);
}

}  // namespace mt
