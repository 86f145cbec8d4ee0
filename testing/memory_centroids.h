// testing/memory_centroids.h: a CentroidSource (patchstore/cell_assigner.h) over a mesh held in
// memory: the centroids and areas of its triangles, served in batches like ingest's temp-file
// reader, for the V-partition tests and benchmark.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <functional>
#include <vector>

#include "patchstore/cell_assigner.h"
#include "testing/test_meshes.h"
#include "vpartition/vpartition.h"  // triangleCentroid

namespace mt::test {

// The centroids (+ areas) of a mesh, served in batches like ingest's temp-file reader.
class MemoryCentroids : public CentroidSource {
 public:
  MemoryCentroids() = default;
  explicit MemoryCentroids(const TestMesh& m, size_t batch = 65536) : batch_(batch) {
    xyza_.reserve(m.triangleCount() * 4);
    for (uint64_t t = 0; t < m.triangleCount(); ++t) {
      const double* a = &m.positions[3 * size_t(m.triangles[3 * t])];
      const double* b = &m.positions[3 * size_t(m.triangles[3 * t + 1])];
      const double* c = &m.positions[3 * size_t(m.triangles[3 * t + 2])];
      float cen[3];
      triangleCentroid(a, b, c, cen);
      double e1[3], e2[3];
      for (int k = 0; k < 3; ++k) { e1[k] = b[k] - a[k]; e2[k] = c[k] - a[k]; }
      double cr[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2],
                      e1[0] * e2[1] - e1[1] * e2[0]};
      add(cen, float(0.5 * std::sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2])));
    }
    for (uint32_t v = 0; v < m.vertexCount(); ++v) grow(&m.positions[3 * size_t(v)]);
  }
  void add(const float c[3], float area) {
    xyza_.insert(xyza_.end(), {c[0], c[1], c[2], area});
    double d[3] = {c[0], c[1], c[2]};
    grow(d);
  }
  void setBounds(const Box3& b) { box_ = b; haveBox_ = true; }
  void setBatch(size_t batch) { batch_ = batch; }
  uint64_t count() const override { return xyza_.size() / 4; }
  Box3 bounds() const override { return box_; }
  void forEach(const std::function<void(const float*, size_t)>& fn) const override {
    ++passes;
    for (size_t i = 0; i < count(); i += batch_) fn(&xyza_[4 * i], std::min(batch_, count() - i));
  }
  const std::vector<float>& data() const { return xyza_; }
  mutable uint32_t passes = 0;

 private:
  void grow(const double* p) {
    if (haveBox_) return;
    for (int a = 0; a < 3; ++a) {
      if (empty_ || p[a] < box_.lo[a]) box_.lo[a] = p[a];
      if (empty_ || p[a] > box_.hi[a]) box_.hi[a] = p[a];
    }
    empty_ = false;
  }
  std::vector<float> xyza_;
  Box3 box_;
  bool empty_ = true, haveBox_ = false;
  size_t batch_ = 65536;
};


}  // namespace mt::test
