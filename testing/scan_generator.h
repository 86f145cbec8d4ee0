// The procedural scan-like surface behind `mtgen`: pure functions from (component, row, column) to
// a vertex and from a face index to a triangle, so that a mesh of any size can be streamed in any
// order with memory O(rows) per component and never O(triangles).
//
// Shape. Each component is a torus (major radius 1, minor radius r) sampled on a U x V grid that is
// periodic in both directions, hence closed and manifold by construction. Every vertex is pushed
// along the torus normal by a sum of periodic 2D gradient-noise octaves, from a few bumps per
// circumference down to a wavelength of ~2.5 grid edges, so there is detail at every scale like a
// dense scan. The noise is evaluated in the *unwarped* angle space, so --density varying changes
// only how the same surface is sampled, never its shape.
//
// Holes are axis-aligned ellipses in grid space (round on the surface at their centre) and remove
// whole grid cells. Hole centres are on a quarter-cell lattice and the membership test is exact
// integer arithmetic, which is what makes the manifold guarantee hold (see holeRowCells()).
//
// Indices. Vertices are emitted row by row (row = position around the major circle), skipping the
// vertices strictly inside a hole. A vertex's output index is firstVertex + keptBeforeRow[row] +
// column - (dropped vertices left of it in its row); the per-row hole intervals are stored in CSR
// arrays whose size is O(rows + hole rows).
//
// Scan pathologies (--pathology): what real laser and photogrammetry scans have and a clean grid
// does not. Each is off by default (and then not a single operation of the default path changes,
// so default outputs keep their bytes) and each is again a pure function of the grid position:
//   close        a few vertices moved to within 2e-5..5e-4 of an edge length of a neighbour
//   slivers      a few vertices moved almost onto a neighbour (needles) or onto the far edge of one
//                of their triangles (caps, angles near 180 degrees)
//   anisotropic  cells 6x longer around the major circle than around the minor one
//   uneven       rows and columns spaced irregularly, gaps from 0.2 to 1.8 of the mean
//   overlap      a second scan pass: an open sheet over part of each component, sampled on its own
//                grid, 0.35 of an edge above the surface
//   seams        the periodic grid seams are not welded: row 0 and column 0 are duplicated, same
//                positions, each side's triangles using their own copy
//   tjunctions   a few rows of cells are split along their lower edge (a finer scan meeting a
//                coarser one): the midpoint is a vertex above the line and absent below
//   noise        per-vertex random displacement along the normal, up to 0.25 of an edge
// Moved vertices (close, slivers) are never adjacent to each other and stay strictly inside the
// convex hexagon of their grid neighbours, so no triangle flips.
//
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "testing/scan_surface.h"

namespace mtgen {

class ScanGenerator {
 public:
  explicit ScanGenerator(const GeneratorOptions& options) : options_(options) { build(); }

  const GeneratorOptions& options() const { return options_; }
  uint64_t vertexCount() const { return vertexCount_; }
  uint64_t triangleCount() const { return triangleCount_; }
  uint64_t gridFaceCount() const { return gridFaceCount_; }  // faces before cutting holes
  const std::vector<Component>& components() const { return components_; }

  // ---- vertices -------------------------------------------------------------------------------
  static double unit(uint64_t hash) { return double(hash >> 11) * 0x1.0p-53; }  // [0, 1)

  // Parameter fraction in [0,1) of a row / column, before the density warp.
  static double rowFraction(const Component& c, uint32_t row) {
    if (c.sheet) return c.u0 + c.du * double(row);
    if (c.uneven) return (double(row) + kUnevenJitter * unit(hashKey(c.key ^ 0x0E7E'0001ull, row))) / double(c.rows);
    return double(row) / double(c.rows);
  }
  static double colFraction(const Component& c, uint32_t col) {
    if (c.sheet) return c.v0 + c.dv * double(col);
    if (c.uneven) return (double(col) + kUnevenJitter * unit(hashKey(c.key ^ 0x0E7E'0002ull, col))) / double(c.cols);
    return double(col) / double(c.cols);
  }

  static RowParams rowParams(const Component& c, uint32_t row) {
    RowParams p;
    double fraction = c.warpU.value(rowFraction(c, row));
    p.cosTheta = std::cos(kTwoPi * fraction);
    p.sinTheta = std::sin(kTwoPi * fraction);
    p.row = row;
    if (c.noise) p.step = kTwoPi * c.warpU.slope(fraction) * (c.sheet ? c.du : 1.0 / double(c.rows));
    for (int o = 0; o < c.octaves; ++o)
      p.octave[o] = axisSample(fraction, c.octave[o].shiftU, c.octave[o].periodU, c.octave[o].seedU);
    return p;
  }
  static ColParams colParams(const Component& c, uint32_t col) {
    ColParams p;
    double fraction = c.warpV.value(colFraction(c, col));
    p.cosPhi = std::cos(kTwoPi * fraction);
    p.sinPhi = std::sin(kTwoPi * fraction);
    p.col = col;
    if (c.noise) p.step = kTwoPi * c.warpV.slope(fraction) * (c.sheet ? c.dv : 1.0 / double(c.cols));
    for (int o = 0; o < c.octaves; ++o)
      p.octave[o] = axisSample(fraction, c.octave[o].shiftV, c.octave[o].periodV, c.octave[o].seedV);
    return p;
  }

  // noise: a random offset along the normal, relative to the shorter local edge (tube units).
  static double noiseAt(const Component& c, const RowParams& r, const ColParams& q) {
    double edgeU = (c.major + c.minor * q.cosPhi) * r.step, edgeV = c.minor * q.step;
    double h = unit(hashKey(c.key ^ 0x0015'E000ull, (uint64_t(r.row) << 32) | q.col));
    return kNoiseAmplitude * std::min(edgeU, edgeV) * (2.0 * h - 1.0);
  }

  // Gradient noise of octave o at a point of row u, reduced to a linear function along the column
  // direction on lattice line iv: value = c0 + c1 * (offset from the line). Both vertex paths
  // (whole rows, single vertices) go through this function and octaveValue() with the same
  // operations in the same order, so they give bit-identical positions.
  static void latticeLine(const Octave& o, const AxisSample& u, uint32_t iv, double& c0, double& c1) {
    uint32_t hv = mix32(iv ^ o.seedV);
    const double* ga = gradient(mix32(u.hash0 ^ hv));
    const double* gb = gradient(mix32(u.hash1 ^ hv));
    double a0 = ga[0] * u.offset, b0 = gb[0] * (u.offset - 1.0);
    c0 = a0 + u.fade * (b0 - a0);
    c1 = ga[1] + u.fade * (gb[1] - ga[1]);
  }
  static double octaveValue(const double line0[2], const double line1[2], const AxisSample& v) {
    double n0 = line0[0] + line0[1] * v.offset;
    double n1 = line1[0] + line1[1] * (v.offset - 1.0);
    return n0 + v.fade * (n1 - n0);
  }

  // Displacement along the torus normal (sum of octaves) of a single vertex.
  static double displacement(const Component& c, const RowParams& r, const ColParams& q) {
    double d = 0;
    for (int o = 0; o < c.octaves; ++o) {
      double line0[2], line1[2];
      latticeLine(c.octave[o], r.octave[o], q.octave[o].index0, line0[0], line0[1]);
      latticeLine(c.octave[o], r.octave[o], q.octave[o].index1, line1[0], line1[1]);
      d += c.octave[o].amplitude * octaveValue(line0, line1, q.octave[o]);
    }
    return d;
  }

  // The lattice lines of every octave for one row, so that a whole row costs two hashes per
  // lattice line instead of eight per vertex and octave. O(columns) memory.
  class RowLattice {
   public:
    void fill(const Component& c, const RowParams& r) {
      size_t total = 0;
      for (int o = 0; o < c.octaves; ++o) start_[o] = total, total += 2 * size_t(c.octave[o].periodV);
      coefficients_.resize(total);
      for (int o = 0; o < c.octaves; ++o) {
        double* line = &coefficients_[start_[o]];
        for (uint32_t iv = 0; iv < c.octave[o].periodV; ++iv)
          latticeLine(c.octave[o], r.octave[o], iv, line[2 * iv], line[2 * iv + 1]);
      }
    }
    double displacement(const Component& c, const ColParams& q) const {
      double d = 0;
      for (int o = 0; o < c.octaves; ++o) {
        const double* line = &coefficients_[start_[o]];
        const AxisSample& v = q.octave[o];
        d += c.octave[o].amplitude * octaveValue(line + 2 * v.index0, line + 2 * v.index1, v);
      }
      return d;
    }

   private:
    std::vector<double> coefficients_;
    size_t start_[kMaxOctaves] = {};
  };

  // World position of grid vertex (row, col); also returns the displacement (for colours). Every
  // code path that needs a position goes through here, so positions are bit-identical everywhere.
  // (This is the grid vertex before close/slivers move it: see finalPosition().)
  static void position(const Component& c, const RowParams& r, const ColParams& q, double out[3],
                       double* displacementOut = nullptr) {
    double d = displacement(c, r, q);
    if (c.noise) d += noiseAt(c, r, q);
    placeVertex(c, r, q, d, out);
    if (displacementOut) *displacementOut = d;
  }
  // The same, with the row's lattice precomputed (the streaming path).
  static void position(const Component& c, const RowParams& r, const RowLattice& lattice, const ColParams& q,
                       double out[3], double* displacementOut = nullptr) {
    double d = lattice.displacement(c, q);
    if (c.noise) d += noiseAt(c, r, q);
    placeVertex(c, r, q, d, out);
    if (displacementOut) *displacementOut = d;
  }
  static void placeVertex(const Component& c, const RowParams& r, const ColParams& q, double d, double out[3]) {
    double tube = c.minor + d;
    if (c.sheet) tube += c.lift;
    double ring = c.major + tube * q.cosPhi;
    double local[3] = {c.scale * ring * r.cosTheta, c.scale * ring * r.sinTheta, c.scale * tube * q.sinPhi};
    const double* m = c.rotation;
    out[0] = c.center[0] + (m[0] * local[0] + m[1] * local[1] + m[2] * local[2]);
    out[1] = c.center[1] + (m[3] * local[0] + m[4] * local[1] + m[5] * local[2]);
    out[2] = c.center[2] + (m[6] * local[0] + m[7] * local[1] + m[8] * local[2]);
  }
  // close, slivers: the move of grid vertex (row, col), kind 0 when it stays. Candidates are on
  // even rows and columns (never two adjacent), not on the last row or column (whose neighbours
  // wrap to row or column 0), not on a T-junction line, with all six triangles around them.
  static Move moveOf(const Component& c, uint32_t row, uint32_t col) {
    Move m;
    if (!c.moves() || (row | col) & 1 || row + 1 >= c.rows || col + 1 >= c.cols || c.isLine(row)) return m;
    uint64_t h = hashKey(c.key ^ 0x30FE'0000ull, (uint64_t(row) << 32) | col);
    double pick = unit(h);
    if (pick >= c.closeShare + c.sliverShare) return m;
    uint32_t rowBefore = row == 0 ? c.rows - 1 : row - 1, colBefore = col == 0 ? c.cols - 1 : col - 1;
    if (cellRemoved(c, row, col) || cellRemoved(c, rowBefore, colBefore) || cellRemoved(c, rowBefore, col) ||
        cellRemoved(c, row, colBefore))
      return m;
    uint64_t h2 = mix64(h);
    double strength = unit(h2);
    m.dir = uint8_t((h2 & 0xFFFF) % 6);
    if (pick < c.closeShare) {
      m.kind = 1;
      m.keep = 2e-5 * std::pow(25.0, strength);  // 2e-5 .. 5e-4 of the edge
    } else if ((h2 >> 16) & 1) {
      m.kind = 1;  // needle
      m.keep = 0.03 + 0.07 * strength;
    } else {
      m.kind = 2;  // cap
      m.keep = 0.02 + 0.06 * strength;
    }
    return m;
  }
  // Applies a move to p, given the neighbours dir and dir+1 (unmoved grid positions).
  static void applyMove(const Move& m, const double n0[3], const double n1[3], double p[3]) {
    for (int a = 0; a < 3; ++a) {
      double target = m.kind == 1 ? n0[a] : 0.5 * (n0[a] + n1[a]);
      p[a] = target + m.keep * (p[a] - target);
    }
  }
  static uint32_t wrap(int64_t value, uint32_t period) {
    return uint32_t(value < 0 ? value + period : value >= int64_t(period) ? value - period : value);
  }

  // World position of grid vertex (row, col) of a component, every pathology applied; row = rows
  // and col = cols are the seam copies of row and column 0.
  static void finalPosition(const Component& c, uint32_t row, uint32_t col, double out[3]) {
    if (row >= c.rows) row -= c.rows;
    if (col >= c.cols) col -= c.cols;
    position(c, rowParams(c, row), colParams(c, col), out);
    Move m = moveOf(c, row, col);
    if (m.kind == 0) return;
    double n[2][3];
    for (int k = 0; k < 2; ++k) {
      const int* d = kNeighbour[(m.dir + k) % 6];
      uint32_t r = wrap(int64_t(row) + d[0], c.rows), q = wrap(int64_t(col) + d[1], c.cols);
      position(c, rowParams(c, r), colParams(c, q), n[k]);
    }
    applyMove(m, n[0], n[1], out);
  }
  void position(const VertexRef& v, double out[3]) const {
    const Component& c = components_[v.component];
    finalPosition(c, v.row, v.col, out);
    if (!v.midpoint) return;
    double b[3];
    finalPosition(c, v.row, v.col + 1, b);
    for (int a = 0; a < 3; ++a) out[a] = 0.5 * (out[a] + b[a]);
  }
  // Grid vertex (row, col); a col with kMidpointBit set is the T-junction vertex right of it.
  void position(uint32_t component, uint32_t row, uint32_t col, double out[3]) const {
    position(VertexRef{component, row, col & ~kMidpointBit, (col & kMidpointBit) != 0}, out);
  }

  // Dropped-vertex intervals of a vertex row (empty for rows not crossing a hole).
  static const Interval* droppedBegin(const Component& c, uint32_t row) {
    return c.droppedVertices.data() + c.vertexRowStart[row];
  }
  static const Interval* droppedEnd(const Component& c, uint32_t row) {
    return c.droppedVertices.data() + c.vertexRowStart[row + 1];
  }

  // Output index of a kept vertex (col may be the seam copy, cols).
  static uint32_t vertexIndex(const Component& c, uint32_t row, uint32_t col) {
    uint64_t index = c.firstVertex + c.keptBeforeRow[row] + col;
    for (const Interval* e = droppedBegin(c, row); e != droppedEnd(c, row) && e->hi < col; ++e)
      index -= e->hi - e->lo + 1;
    return uint32_t(index);
  }
  // Output index of the T-junction vertex right of (row, col), row a line: written after the
  // row's grid vertices (line rows never lose a vertex to a hole).
  static uint32_t midpointIndex(const Component& c, uint32_t row, uint32_t col) {
    return uint32_t(c.firstVertex + c.keptBeforeRow[row] + c.vertexCols() + col);
  }

  static bool cellRemoved(const Component& c, uint32_t row, uint32_t col) {
    const Interval* e = c.removedCells.data() + c.cellRowStart[row];
    const Interval* end = c.removedCells.data() + c.cellRowStart[row + 1];
    for (; e != end && e->lo <= col; ++e)
      if (col <= e->hi) return true;
    return false;
  }

  // ---- faces ----------------------------------------------------------------------------------
  // The vertex row and column after row / col, across the periodic seam (onto the seam copy when
  // the seam is left unwelded).
  static uint32_t nextRow(const Component& c, uint32_t row) {
    return row + 1 == c.rows ? (c.seamRow ? c.rows : 0) : row + 1;
  }
  static uint32_t nextCol(const Component& c, uint32_t col) {
    return col + 1 == c.cols ? (c.seamCol ? c.cols : 0) : col + 1;
  }

  // The triangles of cell (row, col), oriented with the outward normal: two, or three when the
  // cell is on a T-junction line (its lower edge split at the midpoint m:
  // (v00,v11,v01) becomes (v00,v11,m) and (m,v11,v01)). Returns the count.
  static int cellTriangles(const Component& c, uint32_t row, uint32_t col, uint32_t out[9]) {
    uint32_t row1 = nextRow(c, row), col1 = nextCol(c, col);
    uint32_t v00 = vertexIndex(c, row, col), v10 = vertexIndex(c, row1, col);
    uint32_t v11 = vertexIndex(c, row1, col1), v01 = vertexIndex(c, row, col1);
    out[0] = v00, out[1] = v10, out[2] = v11;
    out[3] = v00, out[4] = v11, out[5] = v01;
    if (!c.isLine(row)) return 2;
    uint32_t m = midpointIndex(c, row, col);
    out[5] = m;
    out[6] = m, out[7] = v11, out[8] = v01;
    return 3;
  }

  // Appends the kept triangles of cell row `row`, in grid order, to `out` (3 indices each).
  static void cellRowTriangles(const Component& c, uint32_t row, std::vector<uint32_t>& out) {
    uint32_t row1 = nextRow(c, row);
    bool plain = c.vertexRowStart[row] == c.vertexRowStart[row + 1] &&
                 c.vertexRowStart[row1] == c.vertexRowStart[row1 + 1] &&
                 c.cellRowStart[row] == c.cellRowStart[row + 1] && !c.isLine(row);
    if (plain) {  // no hole touches this row: indices are base + column
      uint32_t base0 = uint32_t(c.firstVertex + c.keptBeforeRow[row]);
      uint32_t base1 = uint32_t(c.firstVertex + c.keptBeforeRow[row1]);
      size_t at = out.size();
      out.resize(at + 6 * size_t(c.cols));
      uint32_t* t = out.data() + at;
      for (uint32_t col = 0; col < c.cols; ++col, t += 6) {
        uint32_t col1 = nextCol(c, col);
        uint32_t v00 = base0 + col, v10 = base1 + col, v11 = base1 + col1, v01 = base0 + col1;
        t[0] = v00, t[1] = v10, t[2] = v11, t[3] = v00, t[4] = v11, t[5] = v01;
      }
      return;
    }
    uint32_t tri[9];
    for (uint32_t col = 0; col < c.cols; ++col) {
      if (cellRemoved(c, row, col)) continue;
      int n = cellTriangles(c, row, col, tri);
      out.insert(out.end(), tri, tri + 3 * n);
    }
  }

  // Triangle of global grid face index f (0 .. gridFaceCount()-1); false when f lies in a hole.
  // Component, cell and triangle are computed directly from f: this is what --shuffle uses. Faces
  // are numbered in grid order, 2 per cell and 3 per split cell (tjunctions), so that f in order
  // gives the same triangles in the same order as cellRowTriangles() row by row.
  bool gridTriangle(uint64_t f, uint32_t out[3], VertexRef* corners) const {
    size_t ci = size_t(std::upper_bound(faceStarts_.begin(), faceStarts_.end(), f) - faceStarts_.begin()) - 1;
    const Component& c = components_[ci];
    uint64_t local = f - c.firstGridFace;
    uint32_t row, col, which;
    if (c.lines.empty()) {
      uint32_t cell = uint32_t(local >> 1);  // < rows*cols < 2^31: 32-bit division is enough
      row = cell / c.cols, col = cell % c.cols, which = uint32_t(local & 1);
    } else {  // row r starts at 2 r cols + cols (lines before r): at most one step per line back
      auto rowStart = [&](uint32_t r) { return 2ull * r * c.cols + uint64_t(c.cols) * c.lineIndex(r); };
      row = uint32_t(std::min<uint64_t>(c.rows - 1, local / (2ull * c.cols)));
      while (rowStart(row) > local) --row;
      uint64_t offset = local - rowStart(row);
      uint32_t perCell = c.isLine(row) ? 3 : 2;
      col = uint32_t(offset / perCell), which = uint32_t(offset % perCell);
    }
    if (cellRemoved(c, row, col)) return false;
    uint32_t tri[9];
    cellTriangles(c, row, col, tri);
    const uint32_t* t = tri + 3 * which;
    out[0] = t[0], out[1] = t[1], out[2] = t[2];
    if (corners) {  // grid coordinates of the corners, for triangle soups
      uint32_t row1 = nextRow(c, row), col1 = nextCol(c, col);
      const uint32_t component = uint32_t(ci);
      const VertexRef v00{component, row, col}, v10{component, row1, col}, v11{component, row1, col1},
          v01{component, row, col1}, m{component, row, col, true};
      const bool split = c.isLine(row);
      const VertexRef refs[9] = {v00, v10, v11, v00, v11, split ? m : v01, m, v11, v01};
      for (int k = 0; k < 3; ++k) corners[k] = refs[3 * which + uint32_t(k)];
    }
    return true;
  }
  // The same with corners as (component, row, col), kMidpointBit in col marking a T-junction vertex.
  bool gridTriangle(uint64_t f, uint32_t out[3], uint32_t corners[3][3] = nullptr) const {
    VertexRef refs[3];
    if (!gridTriangle(f, out, corners ? refs : nullptr)) return false;
    if (corners)
      for (int k = 0; k < 3; ++k)
        corners[k][0] = refs[k].component, corners[k][1] = refs[k].row,
        corners[k][2] = refs[k].col | (refs[k].midpoint ? kMidpointBit : 0);
    return true;
  }

 private:
  void build();
  std::vector<uint64_t> splitBudget(std::vector<uint64_t>& sheetBudget) const;
  std::vector<std::vector<double>> dealHoleSizes(const std::vector<uint64_t>& budget) const;
  void fitComponent(uint32_t index, uint64_t budget, const std::vector<double>& holeSizes);
  void placeComponents();
  void numberComponents();
  void shapeComponent(Component& c, uint32_t index, uint32_t count) const;
  void chooseGrid(Component& c, uint64_t gridFaces) const;
  bool placeHoles(Component& c, uint32_t index, const std::vector<double>& sizes) const;
  void setNoise(Component& c, uint32_t index) const;
  void setPathologies(Component& c, uint32_t index) const;
  static void chooseLines(Component& c);
  Component makeSheet(uint32_t parent, int64_t triangles) const;
  static void buildHoleTables(Component& c);
  static void fitGridAroundHoles(Component& c, int64_t wantTriangles);

  GeneratorOptions options_;
  std::vector<Component> components_;
  std::vector<uint64_t> faceStarts_;
  uint64_t vertexCount_ = 0, triangleCount_ = 0, gridFaceCount_ = 0;
};

}  // namespace mtgen
