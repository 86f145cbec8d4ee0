// testing/scan_generator.cpp: construction of the procedural scan-like surface (the component
// shapes, grids, holes, pathologies and layout); the per-vertex and per-face functions are
// inline in testing/scan_generator.h.
#include "testing/scan_generator.h"

#include <stdexcept>
#include <string>

namespace mtgen {

// "close,seams" or "all" -> bits; false (and the offending word in `bad`) on an unknown name.
bool parsePathologies(const std::string& text, uint32_t& bits, std::string& bad) {
  bits = 0;
  if (text.empty()) return true;
  size_t at = 0;
  while (at <= text.size()) {
    size_t comma = text.find(',', at);
    std::string word = text.substr(at, comma == std::string::npos ? std::string::npos : comma - at);
    if (word == "all") {
      bits |= kAllPathologies;
    } else if (word != "none") {
      uint32_t bit = 0;
      for (const PathologyInfo& p : kPathologies)
        if (word == p.name) bit = p.bit;
      if (bit == 0) {
        bad = word;
        return false;
      }
      bits |= bit;
    }
    if (comma == std::string::npos) break;
    at = comma + 1;
  }
  return true;
}
// ---------------------------------------------------------------------------------------------
// Construction.

void ScanGenerator::shapeComponent(Component& c, uint32_t index, uint32_t count) const {
  Rng rng(hashKey(options_.seed, 0xC0'0000ull + index));
  if (count == 1) {
    c.scale = 1.0;
    c.minor = 0.4;
  } else {  // components of clearly different sizes and proportions
    c.scale = 0.45 + 0.9 * rng.uniform();
    c.minor = 0.3 + 0.14 * rng.uniform();
    // Random rotation from a uniform random unit quaternion (Shoemake).
    double u1 = rng.uniform(), u2 = rng.uniform(), u3 = rng.uniform();
    double a = std::sqrt(1 - u1), b = std::sqrt(u1);
    double qx = a * std::sin(kTwoPi * u2), qy = a * std::cos(kTwoPi * u2);
    double qz = b * std::sin(kTwoPi * u3), qw = b * std::cos(kTwoPi * u3);
    double* m = c.rotation;
    m[0] = 1 - 2 * (qy * qy + qz * qz), m[1] = 2 * (qx * qy - qz * qw), m[2] = 2 * (qx * qz + qy * qw);
    m[3] = 2 * (qx * qy + qz * qw), m[4] = 1 - 2 * (qx * qx + qz * qz), m[5] = 2 * (qy * qz - qx * qw);
    m[6] = 2 * (qx * qz - qy * qw), m[7] = 2 * (qy * qz + qx * qw), m[8] = 1 - 2 * (qx * qx + qy * qy);
  }
  if (options_.varyingDensity) {
    c.warpU.amount = 9.0 / 11.0;  // edge length along the major circle varies 10x
    c.warpV.amount = 0.5;         // and 3x along the minor circle
  }
}

// Picks U x V with 2UV as close as possible to gridFaces and U/V close to the circumference ratio
// (square-ish cells on the surface).
void ScanGenerator::chooseGrid(Component& c, uint64_t gridFaces) const {
  uint64_t cells = std::max<uint64_t>(9, (gridFaces + 1) / 2);
  double aspect = c.major / c.minor;
  if (options_.pathologies & kAnisotropic) aspect /= kAnisotropy;  // fewer, hence longer, rows
  double idealRows = std::sqrt(double(cells) * aspect);
  uint64_t lo = std::max<uint64_t>(3, uint64_t(idealRows * 0.85));
  uint64_t hi = std::max<uint64_t>(lo, uint64_t(idealRows * 1.15) + 1);
  uint64_t bestRows = 3, bestCols = 3;
  double bestCost = 1e300;
  for (uint64_t rows = lo; rows <= hi; ++rows) {
    uint64_t cols = std::max<uint64_t>(3, (cells + rows / 2) / rows);
    double error = std::fabs(double(rows * cols) - double(cells));
    double shape = std::fabs(std::log(double(rows) / double(cols) / aspect));
    double cost = error + 1e-3 * shape;
    if (cost < bestCost) bestCost = cost, bestRows = rows, bestCols = cols;
  }
  c.rows = uint32_t(bestRows);
  c.cols = uint32_t(bestCols);
}

// Octaves from a few bumps per circumference down to a lattice spacing of >= 2.5 grid edges.
// Amplitude halves with wavelength (a rough, stone-like fractal surface) and the sum stays below
// ~0.2 of the tube radius, so the displaced torus never self-intersects.
void ScanGenerator::setNoise(Component& c, uint32_t index) const {
  Rng rng(hashKey(options_.seed, 0x401'5E00'0000ull + index));
  const uint32_t baseV = 3;
  const uint32_t baseU = std::max<uint32_t>(3, uint32_t(std::lround(baseV * c.major / c.minor)));
  c.octaves = 0;
  c.amplitudeSum = 0;
  double amplitude = 0.16 * c.minor;
  for (uint32_t period = 1; c.octaves < kMaxOctaves; period *= 2) {
    if (c.octaves > 0 && double(baseV * period) * 2.5 > double(c.cols)) break;
    if (c.octaves > 0 && double(baseU * period) * 2.5 > double(c.rows)) break;
    Octave& o = c.octave[c.octaves++];
    o.periodU = baseU * period;
    o.periodV = baseV * period;
    o.amplitude = amplitude;
    o.shiftU = rng.uniform();
    o.shiftV = rng.uniform();
    o.seedU = uint32_t(rng.next());
    o.seedV = uint32_t(rng.next());
    c.amplitudeSum += amplitude;
    amplitude *= 0.5;
  }
}

// Places the component's holes (sizes in [0,1], 0 = smallest, 1 = largest) by seeded rejection
// sampling; false when they do not fit. Holes keep 2 cells from each other and 1 from the grid
// seams (row/column 0), so no two holes share a vertex and no hole wraps around.
bool ScanGenerator::placeHoles(Component& c, uint32_t index, const std::vector<double>& sizes) const {
  c.holes.clear();
  if (sizes.empty()) return true;
  const double rows = c.rows, cols = c.cols;
  const double area = 4 * kPi * kPi * c.major * c.minor;
  const double meanEdge = std::sqrt(area / (rows * cols));
  const double smallest = 1.6 * meanEdge;  // a ring of a few edges
  double largest = std::max(smallest, 0.55 * c.minor);
  auto radiusOf = [&](double size, double top) { return smallest * std::pow(top / smallest, size); };
  // Keep the total hole area under 20% of the surface: scale the largest size down if needed.
  for (int guard = 0; guard < 200; ++guard) {
    double total = 0;
    for (double s : sizes) total += kPi * radiusOf(s, largest) * radiusOf(s, largest);
    if (total <= 0.2 * area || largest <= smallest) break;
    largest = std::max(smallest, largest * 0.95);
  }
  // Place the largest holes first: they are the hardest to fit.
  std::vector<uint32_t> order(sizes.size());
  for (uint32_t k = 0; k < order.size(); ++k) order[k] = k;
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return sizes[a] > sizes[b]; });

  constexpr int kAttempts = 600, kAttemptsPerShrink = 50;
  // Cells kept between two holes, and between a hole and a seam (so 2 across the seam too).
  constexpr int64_t kMargin = 2, kSeamMargin = 1;
  constexpr double kQ = double(int64_t(1) << 36);
  for (uint32_t k : order) {
    Rng rng(hashKey(options_.seed, (uint64_t(index) << 32) ^ (0x401Eull << 20) ^ k));
    double wanted = radiusOf(sizes[k], largest);
    bool placed = false;
    for (int attempt = 0; attempt < kAttempts && !placed; ++attempt) {
      Hole h;
      h.qRow = int64_t(rng.below(4 * uint64_t(c.rows)));
      h.qCol = int64_t(rng.below(4 * uint64_t(c.cols)));
      // Cell sizes on the surface at the centre, including the density warp.
      double s = double(h.qRow) / (4 * rows), t = double(h.qCol) / (4 * cols);
      double phi = kTwoPi * c.warpV.value(t);
      double cellU = kTwoPi * (c.major + c.minor * std::cos(phi)) * c.warpU.slope(s) / rows;
      double cellV = kTwoPi * c.minor * c.warpV.slope(t) / cols;
      double radius = wanted * std::pow(0.8, attempt / kAttemptsPerShrink);
      radius = std::max(radius, 1.2 * std::max(cellU, cellV));  // always contains a cell centre
      // Ellipse round on the surface: (X cellU/4)^2 + (Y cellV/4)^2 <= radius^2, scaled to integers.
      h.weightRow = std::max<int64_t>(1, std::llround(kQ * cellU * cellU / (radius * radius)));
      h.weightCol = std::max<int64_t>(1, std::llround(kQ * cellV * cellV / (radius * radius)));
      h.threshold = 16 * int64_t(kQ);
      h.radius = radius;
      // Quick rejection of centres too close to a seam, before the exact test on the cells.
      double halfRows = radius / cellU + 1, halfCols = radius / cellV + 1;
      if (h.qRow / 4.0 - halfRows < kSeamMargin - 1 || h.qRow / 4.0 + halfRows > rows - kSeamMargin + 1) continue;
      if (h.qCol / 4.0 - halfCols < kSeamMargin - 1 || h.qCol / 4.0 + halfCols > cols - kSeamMargin + 1) continue;
      // Exact bounding box and cell count from the integer predicate.
      int64_t rowLo = INT64_MAX, rowHi = INT64_MIN, colLo = INT64_MAX, colHi = INT64_MIN;
      uint64_t cells = 0;
      for (int64_t a = int64_t(h.qRow / 4.0 - halfRows); a <= int64_t(h.qRow / 4.0 + halfRows); ++a) {
        int64_t lo, hi;
        if (!holeRowCells(h, a, lo, hi)) continue;
        rowLo = std::min(rowLo, a), rowHi = std::max(rowHi, a);
        colLo = std::min(colLo, lo), colHi = std::max(colHi, hi);
        cells += uint64_t(hi - lo + 1);
      }
      if (cells == 0) continue;
      if (rowLo < kSeamMargin || rowHi > int64_t(c.rows) - 1 - kSeamMargin) continue;
      if (colLo < kSeamMargin || colHi > int64_t(c.cols) - 1 - kSeamMargin) continue;
      bool clear = true;
      for (const Hole& o : c.holes) {
        bool apartRows = rowHi + kMargin < int64_t(o.rowLo) || int64_t(o.rowHi) + kMargin < rowLo;
        bool apartCols = colHi + kMargin < int64_t(o.colLo) || int64_t(o.colHi) + kMargin < colLo;
        if (!apartRows && !apartCols) { clear = false; break; }
      }
      if (!clear) continue;
      h.rowLo = uint32_t(rowLo), h.rowHi = uint32_t(rowHi), h.colLo = uint32_t(colLo), h.colHi = uint32_t(colHi);
      h.cells = cells;
      c.holes.push_back(h);
      placed = true;
    }
    if (!placed) return false;
  }
  return true;
}

// Final count adjustment with the holes fixed in cell coordinates: on small grids the hole layout
// jumps with the grid size, so instead pick rows x columns near the current grid such that every
// hole still clears the seams; the removed cell count does not change, so the kept count is
// 2 (rows cols - removed) and can be matched closely.
void ScanGenerator::fitGridAroundHoles(Component& c, int64_t wantTriangles) {
  uint64_t removed = 0;
  uint32_t minRows = 3, minCols = 3;
  for (const Hole& h : c.holes) {
    removed += h.cells;
    minRows = std::max(minRows, h.rowHi + 2);  // keep the seam margin of one cell
    minCols = std::max(minCols, h.colHi + 2);
  }
  const int64_t cells = wantTriangles / 2 + int64_t(removed);
  const double aspect = double(c.rows) / double(c.cols);
  uint32_t bestRows = c.rows, bestCols = c.cols;
  int64_t current = 2 * (int64_t(c.rows) * c.cols - int64_t(removed));
  double bestCost = double(current > wantTriangles ? current - wantTriangles : wantTriangles - current);
  for (uint32_t rows = std::max(minRows, uint32_t(c.rows * 0.9)); rows <= uint32_t(c.rows * 1.1) + 1; ++rows) {
    uint32_t cols = std::max<uint32_t>(minCols, uint32_t((cells + rows / 2) / rows));
    int64_t kept = 2 * (int64_t(rows) * cols - int64_t(removed));
    double cost = double(kept > wantTriangles ? kept - wantTriangles : wantTriangles - kept) +
                  1e-3 * std::fabs(std::log(double(rows) / double(cols) / aspect));
    if (cost < bestCost) bestCost = cost, bestRows = rows, bestCols = cols;
  }
  c.rows = bestRows, c.cols = bestCols;
}

void ScanGenerator::buildHoleTables(Component& c) {
  struct Entry {
    uint32_t row;
    Interval span;
  };
  std::vector<Entry> cellEntries, vertexEntries;
  for (const Hole& h : c.holes) {
    int64_t prevLo = 0, prevHi = -1;
    bool prev = false;
    for (int64_t a = h.rowLo; a <= int64_t(h.rowHi) + 1; ++a) {
      int64_t lo = 0, hi = -1;
      bool here = a <= int64_t(h.rowHi) && holeRowCells(h, a, lo, hi);
      if (here) cellEntries.push_back({uint32_t(a), {uint32_t(lo), uint32_t(hi)}});
      // Vertex row a lies between cell rows a-1 and a; a vertex is dropped when all four cells
      // around it are removed.
      if (here && prev) {
        int64_t vlo = std::max(lo, prevLo) + 1, vhi = std::min(hi, prevHi);
        if (vlo <= vhi) vertexEntries.push_back({uint32_t(a), {uint32_t(vlo), uint32_t(vhi)}});
      }
      prev = here, prevLo = lo, prevHi = hi;
    }
  }
  if (c.sheet) {  // an open grid: the cells across the wrap-around are not there (no vertex is lost)
    for (uint32_t a = 0; a + 1 < c.rows; ++a) cellEntries.push_back({a, {c.cols - 1, c.cols - 1}});
    cellEntries.push_back({c.rows - 1, {0, c.cols - 1}});
  }
  auto byRowThenColumn = [](const Entry& a, const Entry& b) {
    return a.row != b.row ? a.row < b.row : a.span.lo < b.span.lo;
  };
  auto toCsr = [&](std::vector<Entry>& entries, uint32_t rows, std::vector<uint32_t>& start,
                   std::vector<Interval>& spans) {
    std::sort(entries.begin(), entries.end(), byRowThenColumn);
    start.assign(size_t(rows) + 1, 0);
    for (const Entry& e : entries) ++start[e.row + 1];
    for (uint32_t r = 0; r < rows; ++r) start[r + 1] += start[r];
    spans.clear();
    for (const Entry& e : entries) spans.push_back(e.span);
  };
  toCsr(cellEntries, c.rows, c.cellRowStart, c.removedCells);
  toCsr(vertexEntries, c.vertexRows(), c.vertexRowStart, c.droppedVertices);

  c.keptBeforeRow.assign(size_t(c.vertexRows()) + 1, 0);
  for (uint32_t r = 0; r < c.vertexRows(); ++r) {
    uint64_t dropped = 0;
    for (uint32_t e = c.vertexRowStart[r]; e < c.vertexRowStart[r + 1]; ++e)
      dropped += c.droppedVertices[e].hi - c.droppedVertices[e].lo + 1;
    c.keptBeforeRow[r + 1] = c.keptBeforeRow[r] + c.vertexCols() - dropped + (c.isLine(r) ? c.cols : 0);
  }
  uint64_t removed = 0;
  for (uint32_t r = 0; r < c.rows; ++r)
    for (uint32_t e = c.cellRowStart[r]; e < c.cellRowStart[r + 1]; ++e)
      removed += c.removedCells[e].hi - c.removedCells[e].lo + 1;
  c.extraFaces = uint64_t(c.lines.size()) * c.cols;
  c.keptVertices = c.keptBeforeRow[c.vertexRows()];
  c.keptTriangles = 2ull * c.rows * c.cols - 2 * removed + c.extraFaces;
}

// The per-component switches and the hash key of the pathologies (holes and grid are chosen).
void ScanGenerator::setPathologies(Component& c, uint32_t index) const {
  const uint32_t p = options_.pathologies;
  c.key = hashKey(options_.seed, 0x9A70'0000'0000ull + index);
  c.uneven = (p & kUneven) != 0;
  c.noise = (p & kNoise) != 0;
  c.seamRow = c.seamCol = (p & kSeams) != 0;
  c.closeShare = p & kClose ? kCloseShare : 0.0;
  c.sliverShare = p & kSlivers ? kSliverShare : 0.0;
  if (p & kTJunctions) chooseLines(c);
}

// T-junction lines: up to kMaxTJunctionLines vertex rows spread over the component, each with no
// hole in the cell rows either side (so every split cell and its neighbour below exist) and away
// from the row seam.
void ScanGenerator::chooseLines(Component& c) {
  c.lines.clear();
  if (c.rows < 8) return;
  auto clear = [&](uint32_t r) {
    for (const Hole& h : c.holes)
      if (int64_t(r) >= int64_t(h.rowLo) && int64_t(r) - 1 <= int64_t(h.rowHi)) return false;
    return true;
  };
  const uint32_t count = std::min<uint32_t>(kMaxTJunctionLines, c.rows / 8);
  for (uint32_t k = 0; k < count; ++k) {
    uint32_t from = uint32_t((2ull * k + 1) * c.rows / (2ull * count)), to = uint32_t((2ull * k + 2) * c.rows / (2ull * count));
    for (uint32_t r = std::max<uint32_t>(from, 2); r < to && r + 2 <= c.rows; ++r)
      if (clear(r) && (c.lines.empty() || c.lines.back() + 2 < r)) {
        c.lines.push_back(r);
        break;
      }
  }
}

// overlap: the second scan pass over component `parent`, about `triangles` triangles, a quarter
// of the way around the tube and as far around the major circle as the budget allows (at most
// half), at a random place that does not cross the seams.
Component ScanGenerator::makeSheet(uint32_t parent, int64_t triangles) const {
  const Component& p = components_[parent];
  Component s = p;
  s.holes.clear();
  s.lines.clear();
  s.seamRow = s.seamCol = false;
  s.uneven = false;
  s.closeShare = s.sliverShare = 0;
  s.sheet = true;
  s.parent = parent;
  s.key = hashKey(options_.seed, 0x5EE7'0000'0000ull + parent);
  s.du = kSheetSpacing / double(p.rows);
  s.dv = kSheetSpacing / double(p.cols);
  s.cols = std::max<uint32_t>(3, uint32_t(std::lround(0.25 / s.dv)));
  uint32_t rows = uint32_t(std::max<int64_t>(2, std::llround(double(triangles) / (2.0 * (s.cols - 1))))) + 1;
  s.rows = std::max<uint32_t>(3, std::min(rows, uint32_t(0.5 / s.du)));
  Rng rng(s.key);
  s.u0 = 0.02 + (0.96 - s.du * s.rows) * rng.uniform();
  s.v0 = 0.02 + (0.96 - s.dv * s.cols) * rng.uniform();
  s.lift = kSheetLift * std::min(kTwoPi * p.major / double(p.rows), kTwoPi * p.minor / double(p.cols));
  buildHoleTables(s);
  return s;
}

// The triangle budget of each component, split by surface area (the same sampling density on
// every component); with overlap, the sheets' share (sheetBudget) comes out of it.
std::vector<uint64_t> ScanGenerator::splitBudget(std::vector<uint64_t>& sheetBudget) const {
  const GeneratorOptions& o = options_;
  const uint32_t count = uint32_t(components_.size());
  std::vector<double> weight(count);
  double totalWeight = 0;
  for (uint32_t i = 0; i < count; ++i) {
    const Component& c = components_[i];
    totalWeight += weight[i] = c.major * c.minor * c.scale * c.scale;
  }
  std::vector<uint64_t> budget(count);
  uint64_t assigned = 0;
  for (uint32_t i = 0; i < count; ++i) {
    budget[i] = std::max(kMinComponentTriangles, uint64_t(double(o.triangles) * weight[i] / totalWeight));
    assigned += budget[i];
  }
  for (uint32_t i = 0; assigned < o.triangles; i = (i + 1) % count) ++budget[i], ++assigned;
  sheetBudget.assign(count, 0);
  if (o.pathologies & kOverlap)
    for (uint32_t i = 0; i < count; ++i) {
      sheetBudget[i] = uint64_t(std::llround(kSheetShare * double(budget[i])));
      budget[i] = std::max(kMinComponentTriangles, budget[i] - sheetBudget[i]);
    }
  return budget;
}

// Hole sizes are stratified over [0,1] (so there are always small and large ones) and dealt to
// the components in proportion to their triangle budgets (D'Hondt: the next hole goes to the
// component with the most triangles per hole so far), so small components are not overfilled.
std::vector<std::vector<double>> ScanGenerator::dealHoleSizes(const std::vector<uint64_t>& budget) const {
  const GeneratorOptions& o = options_;
  const uint32_t count = uint32_t(budget.size());
  std::vector<std::vector<double>> holeSizes(count);
  for (uint32_t k = 0; k < o.holes; ++k) {
    Rng rng(hashKey(o.seed, 0x5123'0000'0000ull + k));
    double size = o.holes == 1 ? 0.5 : (double(k) + rng.uniform()) / double(o.holes);
    uint32_t target = 0;
    double bestQuotient = -1;
    for (uint32_t i = 0; i < count; ++i) {
      double quotient = double(budget[i]) / double(holeSizes[i].size() + 1);
      if (quotient > bestQuotient) bestQuotient = quotient, target = i;
    }
    holeSizes[target].push_back(size);
  }
  return holeSizes;
}

// Grid, holes, pathologies and noise of component i for `budget` kept triangles. Holes remove
// cells, so the grid grows until the kept triangles match the budget. The hole layout is re-drawn
// for each grid, so on small grids the count jumps a little with the grid size: a few fixed-point
// steps, then a scan of nearby grid sizes if still more than 0.1% off.
void ScanGenerator::fitComponent(uint32_t i, uint64_t budget, const std::vector<double>& holeSizes) {
  const GeneratorOptions& o = options_;
  Component& c = components_[i];
  int64_t want = int64_t(budget);
  if (o.pathologies & kTJunctions) {  // the split cells' third triangles come out of the budget
    chooseGrid(c, uint64_t(want));
    int64_t extra = int64_t(std::min<uint32_t>(kMaxTJunctionLines, c.rows / 8)) * c.cols;
    want = std::max(int64_t(kMinComponentTriangles), want - extra);
  }
  Component best;
  int64_t bestError = INT64_MAX;
  auto tryGrid = [&](int64_t grid) -> int64_t {  // returns kept triangles, -1 if holes do not fit
    chooseGrid(c, uint64_t(std::max<int64_t>(grid, int64_t(kMinComponentTriangles))));
    if (!placeHoles(c, i, holeSizes)) return -1;
    uint64_t removed = 0;
    for (const Hole& h : c.holes) removed += h.cells;
    int64_t kept = int64_t(c.gridFaces() - 2 * removed);
    int64_t error = kept > want ? kept - want : want - kept;
    if (error < bestError) bestError = error, best = c;
    return kept;
  };
  int64_t grid = want;
  for (int step = 0; step < 5 && bestError > want / 1000; ++step) {
    int64_t kept = tryGrid(grid);
    if (kept < 0 || holeSizes.empty()) break;
    grid += want - kept;
  }
  if (bestError == INT64_MAX) {  // the holes did not fit: try nearby grid shapes
    int64_t spread = std::max<int64_t>(8, want / 30), stride = std::max<int64_t>(2, spread / 64);
    for (int64_t delta = -spread; delta <= spread && bestError == INT64_MAX; delta += stride)
      tryGrid(grid + delta);
  }
  if (bestError == INT64_MAX)
    throw std::invalid_argument("cannot fit " + std::to_string(holeSizes.size()) + " holes into a component of " +
                                std::to_string(want) + " triangles: ask for fewer holes or more triangles");
  if (bestError > want / 1000) fitGridAroundHoles(best, want);
  c = best;
  if (o.pathologies) setPathologies(c, i);
  buildHoleTables(c);
  setNoise(c, i);
}

// Places components on a cubic lattice with spacing larger than any component's bounding sphere,
// so they never overlap, with a little jitter so the layout does not look machined.
void ScanGenerator::placeComponents() {
  const uint32_t count = uint32_t(components_.size());
  double reach = 0;
  for (const Component& c : components_)
    reach = std::max(reach, c.scale * (c.major + c.minor + c.amplitudeSum));
  uint32_t side = 1;
  while (side * side * side < count) ++side;
  double spacing = 2.3 * reach;
  for (uint32_t i = 0; i < count && count > 1; ++i) {
    Component& c = components_[i];
    Rng rng(hashKey(options_.seed, 0x9A5E'0000ull + i));
    uint32_t cell[3] = {i % side, (i / side) % side, i / (side * side)};
    for (int axis = 0; axis < 3; ++axis)
      c.center[axis] = (double(cell[axis]) - 0.5 * (side - 1)) * spacing + (rng.uniform() - 0.5) * 0.1 * reach;
  }
}

// The first output vertex and grid face of each component, and the totals.
void ScanGenerator::numberComponents() {
  uint64_t vertices = 0, triangles = 0, faces = 0;
  for (Component& c : components_) {
    c.firstVertex = vertices;
    c.firstGridFace = faces;
    faceStarts_.push_back(faces);
    vertices += c.keptVertices;
    triangles += c.keptTriangles;
    faces += c.gridFaces();
  }
  vertexCount_ = vertices, triangleCount_ = triangles, gridFaceCount_ = faces;
  if (vertexCount_ >= (uint64_t(1) << 31)) throw std::invalid_argument("too many vertices for 32-bit indices");
}

void ScanGenerator::build() {
  const GeneratorOptions& o = options_;
  if (o.triangles == 0) throw std::invalid_argument("--triangles must be at least 1");
  if (o.triangles > kMaxTriangles) throw std::invalid_argument("--triangles must be at most 4G");
  if (o.components == 0) throw std::invalid_argument("--components must be at least 1");
  if (o.triangles < kMinComponentTriangles * o.components)
    throw std::invalid_argument("--triangles must be at least " + std::to_string(kMinComponentTriangles) +
                                " per component");
  const uint32_t count = o.components;
  components_.resize(count);
  for (uint32_t i = 0; i < count; ++i) shapeComponent(components_[i], i, count);
  std::vector<uint64_t> sheetBudget;
  const std::vector<uint64_t> budget = splitBudget(sheetBudget);
  const std::vector<std::vector<double>> holeSizes = dealHoleSizes(budget);
  for (uint32_t i = 0; i < count; ++i) fitComponent(i, budget[i], holeSizes[i]);
  placeComponents();
  if (o.pathologies & kOverlap)  // after placement: a sheet shares its component's centre and rotation
    for (uint32_t i = 0; i < count; ++i)
      components_.push_back(makeSheet(i, std::max<int64_t>(8, int64_t(sheetBudget[i]))));
  numberComponents();
}

}  // namespace mtgen
