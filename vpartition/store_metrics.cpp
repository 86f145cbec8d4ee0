// Partition metrics of a built patch store, for `mtstore info`: the sequence comes back from the
// store's "assigner" blob, the centroids are recomputed from the patches (the V*0 cells).
#include <cmath>

#include "base/error.h"
#include "vpartition/vpartition.h"

namespace mt {

StoreCentroids::StoreCentroids(const PatchStore& store) : store_(store), ids_(store.patchIds()) {
  StoreInfo info = store.info();
  triangles_ = info.triangles;
  bounds_ = info.bounds;
}

void StoreCentroids::forEach(const std::function<void(const float*, size_t)>& fn) const {
  std::vector<float> batch;
  for (PatchId id : ids_) {
    Patch p = store_.patch(id);
    batch.clear();
    for (uint32_t t = 0; t < p.triangleCount(); ++t) {
      const double* a = &p.positions[3 * size_t(p.triangles[3 * size_t(t)])];
      const double* b = &p.positions[3 * size_t(p.triangles[3 * size_t(t) + 1])];
      const double* c = &p.positions[3 * size_t(p.triangles[3 * size_t(t) + 2])];
      float cen[3];
      triangleCentroid(a, b, c, cen);
      double e1[3], e2[3];
      for (int k = 0; k < 3; ++k) { e1[k] = b[k] - a[k]; e2[k] = c[k] - a[k]; }
      double x = e1[1] * e2[2] - e1[2] * e2[1], y = e1[2] * e2[0] - e1[0] * e2[2],
             z = e1[0] * e2[1] - e1[1] * e2[0];
      batch.insert(batch.end(), {cen[0], cen[1], cen[2], float(0.5 * std::sqrt(x * x + y * y + z * z))});
    }
    if (!batch.empty()) fn(batch.data(), batch.size() / 4);
  }
}

bool loadStoreSequence(const PatchStore& store, PartitionSequence& out) {
  std::string bytes = store.blob("assigner");
  if (bytes.size() < 8 || bytes.compare(0, 8, "MTVPSEQ1") != 0) return false;
  out = PartitionSequence::deserialize(bytes);  // a damaged blob is an error, not "absent"
  return true;
}

std::string storePartitionMetrics(const PatchStore& store, bool json, bool components) {
  PartitionSequence seq;
  if (!loadStoreSequence(store, seq)) return "";
  StoreCentroids centroids(store);
  PartitionMetrics m = computeMetrics(seq, centroids);
  if (components) addComponentShare(m, computeComponentShare(seq, store));
  return json ? formatMetricsJson(m) : formatMetricsText(m);
}

}  // namespace mt
