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
// No TBB here: tests include this header without linking TBB.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace mtgen {

constexpr double kPi = 3.14159265358979323846;
constexpr double kTwoPi = 2.0 * kPi;
constexpr int kMaxOctaves = 16;
// The smallest torus grid that is still a simple closed manifold (3 x 3 cells, 18 triangles).
constexpr uint64_t kMinComponentTriangles = 18;
// Indices are written as 32-bit integers; keep the vertex count (about half the triangle count)
// well inside int32 so every PLY reader accepts the file.
constexpr uint64_t kMaxTriangles = 4'000'000'000ull;

// ---------------------------------------------------------------------------------------------
// Scan pathologies, as bits of GeneratorOptions::pathologies.

enum Pathology : uint32_t {
  kClose = 1u << 0,
  kSlivers = 1u << 1,
  kAnisotropic = 1u << 2,
  kUneven = 1u << 3,
  kOverlap = 1u << 4,
  kSeams = 1u << 5,
  kTJunctions = 1u << 6,
  kNoise = 1u << 7,
};

struct PathologyInfo {
  const char* name;
  uint32_t bit;
  const char* help;
};

inline constexpr PathologyInfo kPathologies[] = {
    {"close", kClose, "about 2% of the vertices moved to within 2e-5..5e-4 of an edge length of a grid neighbour"},
    {"slivers", kSlivers,
     "about 4% of the vertices moved almost onto a neighbour (needles, shortest edge 3-10% of the others) or "
     "almost onto the far edge of one of their triangles (caps, an angle near 180 degrees)"},
    {"anisotropic", kAnisotropic, "cells 6x longer around the major circle than around the minor one"},
    {"uneven", kUneven, "rows and columns spaced irregularly, each gap 0.2 to 1.8 of the mean"},
    {"overlap", kOverlap,
     "a second scan pass: an open sheet over ~4% of each component, on its own grid (0.9x the spacing, not "
     "aligned), 0.35 of an edge above the surface; the triangle budget includes it"},
    {"seams", kSeams,
     "the grid's two seams left unwelded: row 0 and column 0 are duplicated (same positions, distinct indices, "
     "each side's triangles use their own copy)"},
    {"tjunctions", kTJunctions,
     "up to 6 rows of cells split along their lower edge: the edge midpoints are vertices of the cells above and "
     "not of those below (T-junctions, 1 extra triangle per cell)"},
    {"noise", kNoise, "every vertex displaced along the normal by a random amount of up to 0.25 of an edge"},
};
constexpr uint32_t kAllPathologies = kClose | kSlivers | kAnisotropic | kUneven | kOverlap | kSeams | kTJunctions | kNoise;

// "close,seams" or "all" -> bits; false (and the offending word in `bad`) on an unknown name.
inline bool parsePathologies(const std::string& text, uint32_t& bits, std::string& bad) {
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

// Strengths of the pathologies (fractions of an edge length or of the vertices).
constexpr double kCloseShare = 0.08;    // of the candidate vertices (every other row and column)
constexpr double kSliverShare = 0.16;
constexpr double kAnisotropy = 6.0;
constexpr double kUnevenJitter = 0.8;   // row r sits at r + 0.8 h(r), h in [0,1)
constexpr double kSheetShare = 0.04;    // of a component's triangles
constexpr double kSheetSpacing = 0.9;   // the second pass is sampled 0.9x as wide
constexpr double kSheetLift = 0.35;     // edges above the surface
constexpr double kNoiseAmplitude = 0.25;
constexpr uint32_t kMaxTJunctionLines = 6;
// Old-style corner coordinates (component, row, col) mark a T-junction vertex by this bit of col.
constexpr uint32_t kMidpointBit = 0x8000'0000u;

// ---------------------------------------------------------------------------------------------
// Hashing and random numbers: everything is derived from the seed by hashing, so the output does
// not depend on evaluation order or thread count.

inline uint64_t mix64(uint64_t x) {  // splitmix64 finalizer
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

inline uint64_t hashKey(uint64_t a, uint64_t b) { return mix64(a ^ mix64(b)); }

inline uint32_t mix32(uint32_t x) {  // "lowbias32" integer hash
  x ^= x >> 16;
  x *= 0x7FEB352Du;
  x ^= x >> 15;
  x *= 0x846CA68Bu;
  x ^= x >> 16;
  return x;
}

class Rng {
 public:
  explicit Rng(uint64_t seed) : state_(seed) {}
  uint64_t next() { return mix64(state_ += 0x9E3779B97F4A7C15ull); }
  double uniform() { return double(next() >> 11) * 0x1.0p-53; }  // [0, 1)
  uint64_t below(uint64_t n) { return n ? next() % n : 0; }

 private:
  uint64_t state_;
};

// ---------------------------------------------------------------------------------------------
// A keyed bijection of [0, size): a Feistel-like network on the smallest power of two that covers
// size (split into a left and a right part of up to one bit different width; each step xors one
// part with a keyed hash of the other, which is invertible whatever the widths), made exact by
// cycle walking (re-encrypt until the value is in range; the domain is < 2x size, so the expected
// walk is < 2 steps). O(1) memory, each face computed directly from its index.
class FeistelPermutation {
 public:
  FeistelPermutation(uint64_t size, uint64_t key) : size_(size) {
    int bits = 2;
    while (bits < 62 && (uint64_t(1) << bits) < size) ++bits;
    rightBits_ = bits / 2;
    leftBits_ = bits - rightBits_;
    for (int r = 0; r < kSteps; ++r) keys_[r] = hashKey(key, 0xFE15'7E10ull + uint64_t(r)) | 1;
  }
  uint64_t size() const { return size_; }
  uint64_t operator()(uint64_t index) const {
    uint64_t x = index;
    do x = encrypt(x);
    while (x >= size_);
    return x;
  }

 private:
  static constexpr int kSteps = 6;
  // Keyed hash of `value` to its top `bits` bits (one multiply: Feistel needs no stronger round).
  static uint64_t roundHash(uint64_t value, uint64_t key, int bits) {
    return (((value ^ key) * 0x9E3779B97F4A7C15ull) ^ (key >> 7)) * key >> (64 - bits);
  }
  uint64_t encrypt(uint64_t x) const {
    uint64_t left = x >> rightBits_, right = x & ((uint64_t(1) << rightBits_) - 1);
    for (int r = 0; r < kSteps; r += 2) {
      left ^= roundHash(right, keys_[r], leftBits_);
      right ^= roundHash(left, keys_[r + 1], rightBits_);
    }
    return (left << rightBits_) | right;
  }
  uint64_t size_;
  int leftBits_ = 1, rightBits_ = 1;
  uint64_t keys_[kSteps];
};

// ---------------------------------------------------------------------------------------------
// Parameterization warp: s in [0,1) -> s + a/(2 pi) sin(2 pi s). Monotone for a < 1, fixes 0 and 1,
// and its slope 1 + a cos(2 pi s) ranges over [1-a, 1+a], so a = 9/11 gives a 10x variation of the
// edge length along that direction.
struct Warp {
  double amount = 0.0;
  double value(double s) const { return amount == 0.0 ? s : s + amount / kTwoPi * std::sin(kTwoPi * s); }
  double slope(double s) const { return 1.0 + amount * std::cos(kTwoPi * s); }
};

// One noise octave: periodic gradient noise with periodU x periodV lattice cells over the torus.
struct Octave {
  uint32_t periodU = 1, periodV = 1;
  double amplitude = 0.0;
  double shiftU = 0.0, shiftV = 0.0;  // random lattice offsets, so octaves do not line up
  uint32_t seedU = 0, seedV = 0;
};

// The lattice cell of one octave along one axis, shared by a whole grid row (or column).
struct AxisSample {
  uint32_t index0 = 0, index1 = 0;  // the two bounding lattice lines (periodic)
  uint32_t hash0 = 0, hash1 = 0;    // their hashes (used along the row direction)
  double offset = 0.0;              // position inside the lattice cell, [0,1)
  double fade = 0.0;                // quintic fade of offset
};

inline AxisSample axisSample(double fraction, double shift, uint32_t period, uint32_t seed) {
  double x = (fraction + shift) * double(period);
  double cell = std::floor(x);
  AxisSample a;
  a.offset = x - cell;
  a.index0 = uint32_t(uint64_t(cell) % period);
  a.index1 = a.index0 + 1 == period ? 0 : a.index0 + 1;
  a.hash0 = mix32(a.index0 ^ seed);
  a.hash1 = mix32(a.index1 ^ seed);
  double t = a.offset;
  a.fade = t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
  return a;
}

struct RowParams {
  double cosTheta = 1, sinTheta = 0;
  uint32_t row = 0;
  double step = 0;  // angle between this row and the next (radians), for the noise amplitude
  AxisSample octave[kMaxOctaves];
};
struct ColParams {
  double cosPhi = 1, sinPhi = 0;
  uint32_t col = 0;
  double step = 0;
  AxisSample octave[kMaxOctaves];
};

// A vertex of the output: grid vertex (row, col) of a component, or the T-junction vertex at the
// midpoint of grid vertices (row, col) and (row, col + 1).
struct VertexRef {
  uint32_t component = 0, row = 0, col = 0;
  bool midpoint = false;
};

// How a close/slivers vertex is moved: to target + keep * (position - target), where target is
// grid neighbour `dir` (kind 1) or the midpoint of neighbours dir and dir+1 (kind 2).
struct Move {
  uint8_t kind = 0, dir = 0;
  double keep = 1;
};
// The six grid neighbours joined to a vertex by an edge, in order around it (cells are split
// along the (row+1, col+1) diagonal), as (row, col) offsets.
inline constexpr int kNeighbour[6][2] = {{1, 0}, {1, 1}, {0, 1}, {-1, 0}, {-1, -1}, {0, -1}};

// One of 8 unit gradient directions, chosen by the top bits of a hash.
inline const double* gradient(uint32_t hash) {
  static constexpr double kDiag = 0.70710678118654752;
  static constexpr double kGradients[8][2] = {{1, 0},      {-1, 0},     {0, 1},     {0, -1},
                                              {kDiag, kDiag}, {-kDiag, kDiag}, {kDiag, -kDiag}, {-kDiag, -kDiag}};
  return kGradients[hash >> 29];
}

// ---------------------------------------------------------------------------------------------
// Holes.

struct Interval {  // inclusive range of columns
  uint32_t lo = 0, hi = 0;
};

// An ellipse of grid cells. Coordinates are in quarter cells: the centre of cell (row a, column b)
// is (4a+2, 4b+2). Cell (a,b) is in the hole iff weightRow*X^2 + weightCol*Y^2 <= threshold with
// X = 4a+2-qRow, Y = 4b+2-qCol, all in exact integer arithmetic.
struct Hole {
  int64_t qRow = 0, qCol = 0;
  int64_t weightRow = 1, weightCol = 1, threshold = 0;
  uint32_t rowLo = 0, rowHi = 0, colLo = 0, colHi = 0;  // bounding box of its cells
  uint64_t cells = 0;
  double radius = 0;  // on the unit-scale torus, for reporting
};

inline int64_t floorDiv(int64_t a, int64_t b) { return a / b - ((a % b != 0) && ((a < 0) != (b < 0))); }
inline int64_t ceilDiv(int64_t a, int64_t b) { return -floorDiv(-a, b); }
inline int64_t isqrt(int64_t n) {
  int64_t r = int64_t(std::sqrt(double(n)));
  while (r * r > n) --r;
  while ((r + 1) * (r + 1) <= n) ++r;
  return r;
}

// The cells of cell row `row` inside hole h, as the column range [lo, hi]; false when none.
// Why the result is manifold: the four cells around a grid vertex have centres X1,X1+4 x Y1,Y1+4,
// and both diagonal pairs have the same sum wR(X1^2+(X1+4)^2) + wC(Y1^2+(Y1+4)^2). So the hole
// can never contain one diagonal pair while missing both cells of the other (that would need one
// sum <= 2T and the other > 2T): no vertex is pinched. Each row is an interval centred on qCol,
// so the cell set is row- and column-convex and connected, i.e. a disc with one boundary loop.
inline bool holeRowCells(const Hole& h, int64_t row, int64_t& lo, int64_t& hi) {
  int64_t x = 4 * row + 2 - h.qRow;
  if (x * x > h.threshold / h.weightRow) return false;
  int64_t rest = h.threshold - h.weightRow * x * x;
  int64_t m = isqrt(rest / h.weightCol);  // |Y| <= m
  lo = ceilDiv(h.qCol - 2 - m, 4);
  hi = floorDiv(h.qCol - 2 + m, 4);
  return lo <= hi;
}

// ---------------------------------------------------------------------------------------------

struct GeneratorOptions {
  uint64_t triangles = 1'000'000;
  uint64_t seed = 1;
  uint32_t holes = 0;
  uint32_t components = 1;
  bool varyingDensity = false;
  uint32_t pathologies = 0;  // Pathology bits
};

struct Component {
  // Grid: U rows around the major circle, V columns around the minor circle; cell (a,b) spans rows
  // a, a+1 and columns b, b+1 (mod U, V) and holds two triangles.
  uint32_t rows = 0, cols = 0;
  double major = 1.0, minor = 0.4;
  double scale = 1.0;
  double center[3] = {0, 0, 0};
  double rotation[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  Warp warpU, warpV;
  int octaves = 0;
  Octave octave[kMaxOctaves];
  double amplitudeSum = 0;  // bound on |displacement|, for colours and placement

  std::vector<Hole> holes;
  // CSR per row: removed cells of cell row a are removedCells[cellRowStart[a] .. cellRowStart[a+1]),
  // dropped vertices of vertex row i are droppedVertices[vertexRowStart[i] .. [i+1]), sorted.
  std::vector<uint32_t> cellRowStart, vertexRowStart;
  std::vector<Interval> removedCells, droppedVertices;
  std::vector<uint64_t> keptBeforeRow;  // kept vertices in rows < i, size rows+1

  uint64_t keptVertices = 0, keptTriangles = 0;
  uint64_t firstVertex = 0;    // global output index of this component's first vertex
  uint64_t firstGridFace = 0;  // global index of its first grid face (holes included)
  // Grid faces, then the third triangle of every split cell (tjunctions).
  uint64_t gridFaces() const { return 2ull * rows * cols + extraFaces; }

  // Pathologies (all off by default).
  uint64_t key = 0;             // hash key of this component's pathology choices
  bool uneven = false, noise = false;
  bool seamRow = false, seamCol = false;  // an unwelded copy of row 0 / column 0 at index rows / cols
  double closeShare = 0, sliverShare = 0;
  std::vector<uint32_t> lines;  // tjunctions: vertex rows whose cells above are split, sorted
  uint64_t extraFaces = 0;
  // overlap: an open sheet over part of component `parent`, sampled at fractions u0 + du row,
  // v0 + dv col of the parent's parameterization, `lift` above it (unit-torus units).
  bool sheet = false;
  uint32_t parent = 0;
  double u0 = 0, du = 0, v0 = 0, dv = 0, lift = 0;

  uint32_t vertexRows() const { return rows + (seamRow ? 1 : 0); }
  uint32_t vertexCols() const { return cols + (seamCol ? 1 : 0); }
  bool moves() const { return closeShare > 0 || sliverShare > 0; }
  bool isLine(uint32_t row) const { return !lines.empty() && std::binary_search(lines.begin(), lines.end(), row); }
  uint32_t lineIndex(uint32_t row) const {
    return uint32_t(std::lower_bound(lines.begin(), lines.end(), row) - lines.begin());
  }
};

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

// ---------------------------------------------------------------------------------------------
// Construction.

inline void ScanGenerator::shapeComponent(Component& c, uint32_t index, uint32_t count) const {
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
inline void ScanGenerator::chooseGrid(Component& c, uint64_t gridFaces) const {
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
inline void ScanGenerator::setNoise(Component& c, uint32_t index) const {
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
inline bool ScanGenerator::placeHoles(Component& c, uint32_t index, const std::vector<double>& sizes) const {
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
inline void ScanGenerator::fitGridAroundHoles(Component& c, int64_t wantTriangles) {
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

inline void ScanGenerator::buildHoleTables(Component& c) {
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
inline void ScanGenerator::setPathologies(Component& c, uint32_t index) const {
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
inline void ScanGenerator::chooseLines(Component& c) {
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
inline Component ScanGenerator::makeSheet(uint32_t parent, int64_t triangles) const {
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

inline void ScanGenerator::build() {
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

  // Split the triangle budget by surface area (same sampling density on every component).
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
  // overlap: the sheets' share comes out of the components' budgets.
  std::vector<uint64_t> sheetBudget(count, 0);
  if (o.pathologies & kOverlap)
    for (uint32_t i = 0; i < count; ++i) {
      sheetBudget[i] = uint64_t(std::llround(kSheetShare * double(budget[i])));
      budget[i] = std::max(kMinComponentTriangles, budget[i] - sheetBudget[i]);
    }

  // Hole sizes are stratified over [0,1] (so there are always small and large ones) and dealt to
  // the components in proportion to their triangle budgets (D'Hondt: the next hole goes to the
  // component with the most triangles per hole so far), so small components are not overfilled.
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

  for (uint32_t i = 0; i < count; ++i) {
    Component& c = components_[i];
    // Holes remove cells, so grow the grid until the kept triangles match the budget. The hole
    // layout is re-drawn for each grid, so on small grids the count jumps a little with the grid
    // size: a few fixed-point steps, then a scan of nearby grid sizes if still more than 0.1% off.
    int64_t want = int64_t(budget[i]);
    if (o.pathologies & kTJunctions) {  // the split cells' third triangles come out of the budget
      chooseGrid(c, uint64_t(want));
      int64_t extra = int64_t(std::min<uint32_t>(kMaxTJunctionLines, c.rows / 8)) * c.cols;
      want = std::max(int64_t(kMinComponentTriangles), want - extra);
    }
    Component best;
    int64_t bestError = INT64_MAX;
    auto tryGrid = [&](int64_t grid) -> int64_t {  // returns kept triangles, -1 if holes do not fit
      chooseGrid(c, uint64_t(std::max<int64_t>(grid, int64_t(kMinComponentTriangles))));
      if (!placeHoles(c, i, holeSizes[i])) return -1;
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
      if (kept < 0 || holeSizes[i].empty()) break;
      grid += want - kept;
    }
    if (bestError == INT64_MAX) {  // the holes did not fit: try nearby grid shapes
      int64_t spread = std::max<int64_t>(8, want / 30), stride = std::max<int64_t>(2, spread / 64);
      for (int64_t delta = -spread; delta <= spread && bestError == INT64_MAX; delta += stride)
        tryGrid(grid + delta);
    }
    if (bestError == INT64_MAX)
      throw std::invalid_argument("cannot fit " + std::to_string(holeSizes[i].size()) + " holes into a component of " +
                                  std::to_string(want) + " triangles: ask for fewer holes or more triangles");
    if (bestError > want / 1000) fitGridAroundHoles(best, want);
    c = best;
    if (o.pathologies) setPathologies(c, i);
    buildHoleTables(c);
    setNoise(c, i);
  }

  // Place components on a cubic lattice with spacing larger than any component's bounding sphere,
  // so they never overlap, with a little jitter so the layout does not look machined.
  double reach = 0;
  for (const Component& c : components_)
    reach = std::max(reach, c.scale * (c.major + c.minor + c.amplitudeSum));
  uint32_t side = 1;
  while (side * side * side < count) ++side;
  double spacing = 2.3 * reach;
  for (uint32_t i = 0; i < count && count > 1; ++i) {
    Component& c = components_[i];
    Rng rng(hashKey(o.seed, 0x9A5E'0000ull + i));
    uint32_t cell[3] = {i % side, (i / side) % side, i / (side * side)};
    for (int axis = 0; axis < 3; ++axis)
      c.center[axis] = (double(cell[axis]) - 0.5 * (side - 1)) * spacing + (rng.uniform() - 0.5) * 0.1 * reach;
  }

  if (o.pathologies & kOverlap)  // after placement: a sheet shares its component's centre and rotation
    for (uint32_t i = 0; i < count; ++i)
      components_.push_back(makeSheet(i, std::max<int64_t>(8, int64_t(sheetBudget[i]))));

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

}  // namespace mtgen
