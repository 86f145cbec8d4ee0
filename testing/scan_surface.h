// testing/scan_surface.h: the pieces of the procedural scan-like surface behind `mtgen`
// (testing/scan_generator.h): options, scan pathologies, hashing, the face permutation, the noise
// octaves, holes and the per-component description. Plain data and small pure functions; no
// TBB and nothing else of ours, so tests and benchmarks use it without linking more.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
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
bool parsePathologies(const std::string& text, uint32_t& bits, std::string& bad);

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

}  // namespace mtgen
