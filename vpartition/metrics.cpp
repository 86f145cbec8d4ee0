// Shape metrics of a partition sequence (BMT section 3.2): a well-behaving DAG needs (1) path
// length logarithmic in the number of nodes -- the number of levels against log_k(cells of V0), k
// the level ratio -- and (2) uniform cells, so that "the floor of each fragment of V(i+1) intersects a roughly
// constant number of fragments of Vi" -- the backward star, read off the V*i cells: every
// distinct (Vi, V(i+1)) pair of a triangle is one V*i cell, and a V(i+1) cell overlaps as many Vi
// cells as it has V*i cells. One pass over the centroids; memory ~ the V*i cells of all levels.
#include <algorithm>
#include <cinttypes>
#include <cstdio>
#include <limits>
#include <sstream>
#include <unordered_map>

#include "vpartition/vpartition.h"

namespace mt {

PartitionMetrics computeMetrics(const PartitionSequence& seq, const CentroidSource& src) {
  PartitionMetrics m;
  m.kind = seq.kind();
  m.build = seq.stats();
  const uint32_t L = seq.levels();
  std::vector<std::unordered_map<uint64_t, uint32_t>> cross(L);
  std::vector<uint32_t> ids(L + 1, 0);
  src.forEach([&](const float* xyza, size_t count) {
    for (size_t t = 0; t < count; ++t) {
      const float* c = xyza + 4 * t;
      for (uint32_t l = 0; l < L; ++l) ids[l] = seq.cellOf(l, c);
      for (uint32_t l = 0; l < L; ++l) ++cross[l][(uint64_t(ids[l]) << 32) | ids[l + 1]];
      ++m.triangles;
    }
  });
  for (uint32_t l = 0; l < L; ++l) {
    LevelMetrics lm;
    lm.level = l;
    std::unordered_map<uint32_t, uint64_t> cells;      // Vi cell -> triangles
    std::unordered_map<uint32_t, uint32_t> star;       // V(i+1) cell -> Vi cells overlapped
    uint32_t cmin = std::numeric_limits<uint32_t>::max(), cmax = 0;
    for (const auto& [key, n] : cross[l]) {
      cells[PartitionSequence::crossHigh(key)] += n;
      ++star[PartitionSequence::crossLow(key)];
      cmin = std::min(cmin, n);
      cmax = std::max(cmax, n);
    }
    lm.crossCells = cross[l].size();
    lm.crossMin = lm.crossCells ? cmin : 0;
    lm.crossMax = cmax;
    lm.crossMean = lm.crossCells ? double(m.triangles) / lm.crossCells : 0;
    lm.cells = cells.size();
    uint64_t tmin = std::numeric_limits<uint64_t>::max(), tmax = 0;
    for (const auto& [cell, n] : cells) { tmin = std::min(tmin, n); tmax = std::max(tmax, n); }
    lm.minTriangles = lm.cells ? uint32_t(tmin) : 0;
    lm.maxTriangles = uint32_t(tmax);
    lm.meanTriangles = lm.cells ? double(m.triangles) / lm.cells : 0;
    uint32_t smax = 0;
    for (const auto& [cell, n] : star) smax = std::max(smax, n);
    lm.backwardStarMax = smax;
    lm.backwardStarMean = star.empty() ? 0 : double(lm.crossCells) / star.size();
    m.levels.push_back(lm);
  }
  for (uint32_t l = 0; l < L; ++l) m.levels[l].target = seq.levelTarget(l);
  return m;
}

void addComponentShare(PartitionMetrics& metrics, const std::vector<double>& share) {
  for (size_t l = 0; l < metrics.levels.size() && l < share.size(); ++l)
    metrics.levels[l].multiComponentShare = share[l];
}

std::string formatMetricsText(const PartitionMetrics& m) {
  std::ostringstream s;
  char line[256];
  std::snprintf(line, sizeof line, "V-partition: %s, %zu levels, %" PRIu64 " triangles",
                partitionKindName(m.kind), m.levels.size(), m.triangles);
  s << line;
  if (m.build.passes) {  // known right after a build, not for a sequence read back from a store
    std::snprintf(line, sizeof line,
                  "; built in %u passes over the input + %u over a 1/%" PRIu64 " sample (%u calibration), %.2f s, %" PRIu64
                  " seeds removed, %.1f MiB seeds+grids",
                  m.build.passes, m.build.samplePasses, m.build.sampleStride, m.build.calibrationPasses, m.build.seconds,
                  m.build.removedSeeds, m.build.seedBytes / 1048576.0);
    s << line;
  }
  s << "\n";
  s << "level    cells   target   tri/cell min/mean/max      V*cells   tri/V*cell min/mean/max"
       "   bstar mean/max  multi-comp\n";
  for (const LevelMetrics& l : m.levels) {
    char comp[32] = "-";
    if (l.multiComponentShare >= 0) std::snprintf(comp, sizeof comp, "%.1f%%", 100 * l.multiComponentShare);
    char tgt[32] = "-";
    if (l.target) std::snprintf(tgt, sizeof tgt, "%" PRIu64, l.target);
    std::snprintf(line, sizeof line,
                  "%5u %8" PRIu64 " %8s %8u/%9.1f/%8u %12" PRIu64 " %8u/%9.1f/%8u %8.2f/%-4u %10s\n",
                  l.level, l.cells, tgt, l.minTriangles, l.meanTriangles, l.maxTriangles,
                  l.crossCells, l.crossMin, l.crossMean, l.crossMax, l.backwardStarMean,
                  l.backwardStarMax, comp);
    s << line;
  }
  return s.str();
}

std::string formatMetricsJson(const PartitionMetrics& m) {
  std::ostringstream s;
  s.precision(6);
  s << "{\"kind\":\"" << partitionKindName(m.kind) << "\",\"triangles\":" << m.triangles
    << ",\"passes\":" << m.build.passes << ",\"samplePasses\":" << m.build.samplePasses
    << ",\"sampleStride\":" << m.build.sampleStride << ",\"calibrationPasses\":" << m.build.calibrationPasses
    << ",\"removedSeeds\":" << m.build.removedSeeds << ",\"seedBytes\":" << m.build.seedBytes
    << ",\"seconds\":" << m.build.seconds << ",\"levels\":[";
  for (size_t i = 0; i < m.levels.size(); ++i) {
    const LevelMetrics& l = m.levels[i];
    s << (i ? "," : "") << "{\"level\":" << l.level << ",\"cells\":" << l.cells
      << ",\"target\":" << l.target << ",\"minTriangles\":" << l.minTriangles
      << ",\"meanTriangles\":" << l.meanTriangles << ",\"maxTriangles\":" << l.maxTriangles
      << ",\"crossCells\":" << l.crossCells << ",\"crossMin\":" << l.crossMin
      << ",\"crossMean\":" << l.crossMean << ",\"crossMax\":" << l.crossMax
      << ",\"backwardStarMean\":" << l.backwardStarMean
      << ",\"backwardStarMax\":" << l.backwardStarMax;
    if (l.multiComponentShare >= 0) s << ",\"multiComponentShare\":" << l.multiComponentShare;
    s << "}";
  }
  s << "]}";
  return s.str();
}

}  // namespace mt
