// Quadric edge collapse with optimal placement and per-vertex locks (see quadric_simplify.h).
#include "mtbuild/quadric_simplify.h"

#include "mtbuild/attribute_quadric.h"
#include "mtbuild/surface_distance.h"

#include <algorithm>
#include <cassert>
#include <cfloat>
#include <cmath>
#include <cstring>
#include <vector>

namespace mt {

namespace {

// G&H section 5: the squared distance to a set of planes n.p + d = 0 is p^T A p + 2 b.p + c with
// A = sum n n^T, b = sum d n, c = sum d^2. Each face plane is weighted by the face's area, so a
// quadric measures area x squared distance and does not depend on how finely a region is sampled.
struct Quadric {
  double a00 = 0, a11 = 0, a22 = 0, a01 = 0, a02 = 0, a12 = 0, b0 = 0, b1 = 0, b2 = 0, c = 0;

  void addPlane(const double n[3], double d, double w) {
    a00 += w * n[0] * n[0], a11 += w * n[1] * n[1], a22 += w * n[2] * n[2];
    a01 += w * n[0] * n[1], a02 += w * n[0] * n[2], a12 += w * n[1] * n[2];
    b0 += w * d * n[0], b1 += w * d * n[1], b2 += w * d * n[2];
    c += w * d * d;
  }
  void add(const double* k) {  // 10 coefficients in member order (ColorQuadrics::reduced)
    a00 += k[0], a11 += k[1], a22 += k[2], a01 += k[3], a02 += k[4], a12 += k[5], b0 += k[6], b1 += k[7], b2 += k[8], c += k[9];
  }
  void add(const Quadric& q) {
    a00 += q.a00, a11 += q.a11, a22 += q.a22, a01 += q.a01, a02 += q.a02, a12 += q.a12;
    b0 += q.b0, b1 += q.b1, b2 += q.b2, c += q.c;
  }
  double at(const double p[3]) const {
    const double x = p[0], y = p[1], z = p[2];
    double e = a00 * x * x + a11 * y * y + a22 * z * z + 2 * (a01 * x * y + a02 * x * z + a12 * y * z) +
               2 * (b0 * x + b1 * y + b2 * z) + c;
    return e > 0 ? e : 0;  // rounding can make a zero error slightly negative
  }
  // G&H section 4: the point of least error solves A p = -b. A is singular on a flat or
  // cylindrical neighbourhood (a line or plane of minima); a small Tikhonov term pulling toward
  // `toward` (the edge midpoint) picks the minimum nearest the edge there and keeps the system
  // well conditioned. Returns false when the quadric is empty.
  bool minimum(const double toward[3], double p[3]) const {
    const double trace = a00 + a11 + a22;
    if (!(trace > 0)) return false;
    const double l = 1e-4 * trace;
    const double m00 = a00 + l, m11 = a11 + l, m22 = a22 + l;
    const double r0 = -b0 + l * toward[0], r1 = -b1 + l * toward[1], r2 = -b2 + l * toward[2];
    const double c00 = m11 * m22 - a12 * a12, c01 = a02 * a12 - a01 * m22, c02 = a01 * a12 - a02 * m11;
    const double c11 = m00 * m22 - a02 * a02, c12 = a01 * a02 - m00 * a12, c22 = m00 * m11 - a01 * a01;
    const double det = m00 * c00 + a01 * c01 + a02 * c02;
    if (!(std::fabs(det) > 1e-12 * trace * trace * trace)) return false;
    p[0] = (c00 * r0 + c01 * r1 + c02 * r2) / det;
    p[1] = (c01 * r0 + c11 * r1 + c12 * r2) / det;
    p[2] = (c02 * r0 + c12 * r1 + c22 * r2) / det;
    return std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]);
  }
};

void sub(const double* a, const double* b, double* o) { o[0] = a[0] - b[0], o[1] = a[1] - b[1], o[2] = a[2] - b[2]; }
void cross(const double* a, const double* b, double* o) {
  o[0] = a[1] * b[2] - a[2] * b[1], o[1] = a[2] * b[0] - a[0] * b[2], o[2] = a[0] * b[1] - a[1] * b[0];
}
double dot(const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }
// floor(x) as an integer for |x| < 2^62 without a libm call (grid indices fit 32 bits).
int64_t floorToInt(double x) {
  const int64_t i = int64_t(x);  // toward zero
  return i - (double(i) > x ? 1 : 0);
}

// Sorts a vertex's neighbour list (a dozen ids): insertion sort beats std::sort's set-up there.
void sortSmall(std::vector<uint32_t>& n) {
  if (n.size() > 48) return std::sort(n.begin(), n.end());
  for (size_t i = 1; i < n.size(); ++i) {
    const uint32_t x = n[i];
    size_t j = i;
    for (; j > 0 && n[j - 1] > x; --j) n[j] = n[j - 1];
    n[j] = x;
  }
}

double dist2(const double* a, const double* b) {
  double d[3];
  sub(a, b, d);
  return dot(d, d);
}

// Twice the area vector of triangle (a, b, c).
void areaVector(const double* a, const double* b, const double* c, double* n) {
  double e1[3], e2[3];
  sub(b, a, e1), sub(c, a, e2), cross(e1, e2, n);
}

// Shape quality in [0, 1]: 4 sqrt(3) area / (sum of squared edge lengths); 1 for equilateral.
double quality(const double* a, const double* b, const double* c, const double* n) {
  const double l = dist2(a, b) + dist2(b, c) + dist2(c, a);
  return l > 0 ? 2 * std::sqrt(3.0) * std::sqrt(dot(n, n)) / l : 0;
}

struct Cell {
  int64_t c[3];
  bool operator==(const Cell& o) const { return c[0] == o.c[0] && c[1] == o.c[1] && c[2] == o.c[2]; }
};

// Grid cell -> number of live vertices in it: open addressing with linear probing, 16-byte slots
// (a node-based hash map was 5% of the build). Cells are kept relative to the cell of the region
// box's low corner, so each component fits 32 bits (the grid has at most 31 bits per axis). A
// count that drops to 0 keeps its slot; at most one new cell per collapse is added, so 2 x the
// vertex count bounds the keys and the table never grows past half full.
class CellCounts {
 public:
  void init(const int64_t lo[3], size_t vertexCount) {
    for (int a = 0; a < 3; ++a) lo_[a] = lo[a];
    size_t n = 16;
    while (n < 4 * vertexCount) n *= 2;
    slots_.assign(n, Slot{{0, 0, 0}, kEmpty});
    mask_ = n - 1;
  }
  // The count of cell c (at or above the low corner), added with 0 when missing.
  uint32_t& operator[](const Cell& c) {
    Slot& s = find(c);
    if (s.count == kEmpty) s.count = 0;
    return s.count;
  }
  // The count of cell c, without adding it.
  uint32_t count(const Cell& c) {
    const Slot& s = find(c);
    return s.count == kEmpty ? 0 : s.count;
  }

 private:
  static constexpr uint32_t kEmpty = ~0u;
  struct Slot {
    uint32_t k[3];
    uint32_t count;
  };
  // The slot of c: its own, or the empty slot where it would go (key filled in).
  Slot& find(const Cell& c) {
    uint32_t k[3];
    for (int a = 0; a < 3; ++a) k[a] = uint32_t(c.c[a] - lo_[a]);
    const uint64_t h = (uint64_t(k[0]) * 0x9E3779B97F4A7C15ull) ^ (uint64_t(k[1]) * 0xC2B2AE3D27D4EB4Full) ^
                       (uint64_t(k[2]) * 0x165667B19E3779F9ull);
    for (size_t i = size_t(h ^ (h >> 29)) & mask_;; i = (i + 1) & mask_) {
      Slot& s = slots_[i];
      if (s.count == kEmpty) {
        s.k[0] = k[0], s.k[1] = k[1], s.k[2] = k[2];
        return s;
      }
      if (s.k[0] == k[0] && s.k[1] == k[1] && s.k[2] == k[2]) return s;
    }
  }
  int64_t lo_[3] = {0, 0, 0};
  size_t mask_ = 0;
  std::vector<Slot> slots_;
};

// A collapse of edge (s, r): r disappears, s survives at p (local coordinates).
struct Candidate {
  double cost;
  uint32_t s, r;
  uint32_t versionS, versionR;
  double p[3];  // local
  double g[3];  // global (on the grid when moved and a grid is given)
  bool moves;
};
// A heap entry, 16 bytes (the heap outgrows the caches; its sift-downs were a third of the time
// with 32-byte entries): the collapse is recomputed from (s, r, allowMove) when popped, since
// candidate() is a pure function of the two vertices' state. The versions are truncated (15 and 16
// bits), so a popped entry is also checked against the recomputed cost.
struct Entry {
  // The cost (a float, never negative, so its bits order as its value) above s: one integer
  // comparison orders by (cost, s).
  uint64_t key;
  uint32_t r;
  uint16_t versionS;  // low 15 bits; the top bit: the cost includes the shape penalty
  uint16_t versionR;  // low 15 bits; the top bit: the collapse may move the vertex
  uint32_t s() const { return uint32_t(key); }
  float cost() const {
    const uint32_t bits = uint32_t(key >> 32);
    float f;
    std::memcpy(&f, &bits, sizeof f);
    return f;
  }
  void setCost(float f) {
    uint32_t bits;
    std::memcpy(&bits, &f, sizeof bits);
    key = uint64_t(bits) << 32 | s();
  }
  bool allowMove() const { return versionR >> 15; }
  bool penalized() const { return versionS >> 15; }
};
static_assert(sizeof(Entry) == 16, "heap entries stay small");
// Heap order: least cost first; ties by vertex ids, so the order never depends on push order.
struct Later {
  bool operator()(const Entry& x, const Entry& y) const { return x.key != y.key ? x.key > y.key : x.r > y.r; }
};
Entry entryOf(const Candidate& c, bool allowMove) {
  assert(c.cost >= 0);
  Entry e{c.s, c.r, uint16_t(c.versionS & 0x7fff), uint16_t((c.versionR & 0x7fff) | (allowMove ? 0x8000 : 0))};
  e.setCost(float(c.cost));
  return e;
}

// A 4-ary min-heap on Later (half the depth of a binary heap, and a node's children share a
// cache line: the pops of stale entries were 10% of the simplifier with std::pop_heap).
void siftUp(std::vector<Entry>& h, size_t i) {
  const Entry e = h[i];
  while (i > 0) {
    const size_t parent = (i - 1) / 4;
    if (!Later()(h[parent], e)) break;
    h[i] = h[parent];
    i = parent;
  }
  h[i] = e;
}
void siftDown(std::vector<Entry>& h, size_t i) {
  const size_t n = h.size();
  const Entry e = h[i];
  for (;;) {
    const size_t first = 4 * i + 1;
    if (first >= n) break;
    size_t best = first;
    const size_t last = std::min(first + 4, n);
    for (size_t c = first + 1; c < last; ++c)
      if (Later()(h[best], h[c])) best = c;
    if (!Later()(e, h[best])) break;
    h[i] = h[best];
    i = best;
  }
  h[i] = e;
}
void heapPush(std::vector<Entry>& h, const Entry& e) {
  h.push_back(e);
  siftUp(h, h.size() - 1);
}
Entry heapPop(std::vector<Entry>& h) {
  const Entry top = h[0];
  h[0] = h.back();
  h.pop_back();
  if (!h.empty()) siftDown(h, 0);
  return top;
}
void heapMake(std::vector<Entry>& h) {
  for (size_t i = h.size() / 4 + 1; i-- > 0;)
    if (i < h.size()) siftDown(h, i);
}

enum class Verdict { Ok, Refused, GridTaken };

constexpr double kMinQuality = 0.05;  // a face below this is a sliver; none is made from a better one
// A collapse that makes a face of quality q below kFairQuality costs cost * kFairQuality / q (the
// shape penalty of vcg's TriEdgeCollapseQuadric, which Nexus uses, with its threshold 0.3): at a
// given triangle count, well-shaped triangles follow the surface more closely on average.
constexpr double kFairQuality = 0.3;
// A collapse costs at least kAwayWeight x (its ends' total face area) x the squared distance from
// an old position of its ends to the faces it makes (check()'s away2_): as if that much surface
// were that far off. A quadric sums area x squared distance, so a thin feature (a needle, a
// claw's tip, a fin's rim: a few faces whose planes run along it) is cheap to collapse along its
// length although its tip then ends far from the result; the input->cut maximum comes from
// such spots. Where the old positions lie near the new faces (most collapses) the quadric's
// cost stands. 0.5, measured against 0.15-2 and against adding the term (docs/mtbuild.md).
// The same floor covers the other way, surface made far from the old one: away2_ also takes the
// squared distance from the midpoint of each edge the collapse makes to the old faces around its
// ends. An edge whose ends stay on the surface can span a concavity (a dimple, a groove) and run
// off it along its length, which the ends' distances do not see; the cut->input maximum comes
// from such spots (docs/mtbuild.md, "Sixth pass").
constexpr double kAwayWeight = 0.5;

class Simplifier {
 public:
  Simplifier(const uint32_t* indices, size_t indexCount, const double* positions, size_t vertexCount, size_t stride,
             const uint8_t* locked, const QuadricSimplifyOptions& options, double* outPositions, uint8_t* moved);
  void run(size_t targetTriangles);
  size_t write(uint32_t* destination) const;
  QuadricSimplifyStats stats;
  const ColorQuadrics& colors() const { return colors_; }

 private:
  void buildLists();
  void buildQuadrics();
  bool candidate(uint32_t a, uint32_t b, bool allowMove, Candidate& c) const;
  uint32_t find(uint32_t v);
  void park(const Entry& e);
  void wake(uint32_t v);
  size_t unpark();
  Verdict check(const Candidate& c);
  void collapse(const Candidate& c);
  Cell cellOf(const double* global) const;
  Cell cellOfVertex(uint32_t v) const { return cellOf(out_ + size_t(v) * 3); }
  void bestCorner(const Quadric& q, double* global, double* local) const;
  void appendTriangle(uint32_t v, uint32_t t);
  void neighbours(uint32_t v, std::vector<uint32_t>& n) const;

  const QuadricSimplifyOptions& options_;
  size_t nv_;
  double center_[3] = {0, 0, 0};
  double lo_[3] = {0, 0, 0}, hi_[3] = {0, 0, 0};  // the input's bounding box, local
  int64_t cellLo_[3] = {0, 0, 0}, cellHi_[3] = {0, 0, 0};  // the grid cells of the box's corners
  std::vector<double> pos_;  // local (centred) positions: the quadrics stay precise far from the origin
  double* out_;              // global positions (the caller's destinationPositions)
  uint8_t* moved_;
  std::vector<uint8_t> frozen_, locked_;
  // On an open border (a scan hole) at the start: such a vertex never moves. It may go along the
  // border onto a neighbour on it, or stay (mtfile/mt_cut.h: a cut's boundary edges must join
  // boundary vertices of the finest cut, compared by grid position).
  std::vector<uint8_t> border_;  // frozen: never removed nor moved (locks and non-manifold spots)
  std::vector<uint32_t> tri_;
  std::vector<uint8_t> dead_;
  std::vector<uint32_t> start_, count_, cap_, pool_, live_, version_;
  std::vector<Quadric> quadric_;
  ColorQuadrics colors_;  // per-vertex colour (attribute_quadric.h); inactive without colours
  std::vector<Entry> heap_;
  // A removed vertex's survivor (into_[v] == v while v lives): a heap entry keeps naming the
  // vertices it was pushed for, and stands for the edge between their survivors.
  std::vector<uint32_t> into_;
  // Refused collapses, parked until a collapse changes either end (then they go back to the heap)
  // or the heap runs dry (a new round). Each parked entry is on two singly linked lists, its s's
  // and its r's: parkedNext_[2i] and [2i + 1].
  std::vector<Entry> parked_;
  std::vector<uint32_t> parkedNext_, parkedHead_;
  std::vector<uint8_t> parkedLive_;
  void push(const Candidate& c, bool allowMove) {
    heapPush(heap_, entryOf(c, allowMove));
  }
  bool current(const Entry& e) const {
    return count_[e.r] && (version_[e.s()] & 0x7fff) == (e.versionS & 0x7fffu) && (version_[e.r] & 0x7fff) == (e.versionR & 0x7fffu);
  }
  CellCounts cells_;  // grid cell -> number of live vertices in it
  size_t liveTriangles_ = 0;
  // Scratch of check(), kept for collapse().
  std::vector<uint32_t> ts_, tr_, edge_, ns_, nr_, nb_;
  // check()'s neighbour marks: a vertex is in s's (r's) neighbourhood when markS_ (markR_) holds
  // the check's stamp, with usesS_ (usesR_) triangles there.
  std::vector<uint32_t> markS_, markR_, usesS_, usesR_;
  uint32_t stamp_ = 0;
  double minQuality_ = 1;  // the worst quality of a face the checked collapse changes
  // The squared distance from the collapse's old positions to its new faces, or from its new
  // edges' midpoints to its old faces, whichever is larger (kAwayWeight).
  double away2_ = 0;
};

Simplifier::Simplifier(const uint32_t* indices, size_t indexCount, const double* positions, size_t vertexCount,
                       size_t stride, const uint8_t* locked, const QuadricSimplifyOptions& options,
                       double* outPositions, uint8_t* moved)
    : options_(options), nv_(vertexCount), out_(outPositions), moved_(moved) {
  double lo[3] = {DBL_MAX, DBL_MAX, DBL_MAX}, hi[3] = {-DBL_MAX, -DBL_MAX, -DBL_MAX};
  for (size_t v = 0; v < nv_; ++v) {
    const double* p = reinterpret_cast<const double*>(reinterpret_cast<const char*>(positions) + v * stride);
    for (int a = 0; a < 3; ++a) out_[v * 3 + a] = p[a], lo[a] = std::min(lo[a], p[a]), hi[a] = std::max(hi[a], p[a]);
  }
  if (nv_)
    for (int a = 0; a < 3; ++a) center_[a] = 0.5 * (lo[a] + hi[a]);
  pos_.resize(nv_ * 3);
  for (size_t i = 0; i < nv_ * 3; ++i) pos_[i] = out_[i] - center_[i % 3];
  if (nv_)
    for (int a = 0; a < 3; ++a) lo_[a] = lo[a] - center_[a], hi_[a] = hi[a] - center_[a];
  if (moved_) std::memset(moved_, 0, nv_);
  locked_.assign(nv_, 0);
  if (locked)
    for (size_t v = 0; v < nv_; ++v) locked_[v] = locked[v] ? 1 : 0;
  frozen_ = locked_;
  tri_.assign(indices, indices + indexCount);
  dead_.assign(indexCount / 3, 0);
  version_.assign(nv_, 0);
  markS_.assign(nv_, 0), markR_.assign(nv_, 0), usesS_.assign(nv_, 0), usesR_.assign(nv_, 0);
  buildLists();
  buildQuadrics();
  colors_.init(options_.colors, options_.colorScale, locked, pos_.data(), nv_, tri_.data(), tri_.size());
  if (options_.gridStep > 0 && nv_) {
    const Cell l = cellOf(lo), h = cellOf(hi);
    for (int a = 0; a < 3; ++a) cellLo_[a] = l.c[a], cellHi_[a] = h.c[a];
    cells_.init(cellLo_, nv_);
    for (uint32_t v = 0; v < nv_; ++v)
      if (live_[v]) ++cells_[cellOfVertex(v)];
  }
}

// Vertex -> triangle lists in one pool (counting sort). A list that outgrows its room moves to the
// end of the pool with twice the room, so a collapse appends in amortized constant time.
void Simplifier::buildLists() {
  const size_t nt = tri_.size() / 3;
  count_.assign(nv_, 0);
  for (uint32_t v : tri_) ++count_[v];
  start_.assign(nv_, 0);
  size_t at = 0;
  for (size_t v = 0; v < nv_; ++v) start_[v] = uint32_t(at), at += count_[v];
  cap_ = count_;
  pool_.resize(at);
  std::vector<uint32_t> fill(start_);
  for (size_t t = 0; t < nt; ++t) {
    const uint32_t* f = &tri_[t * 3];
    // A triangle with a repeated corner is kept as it is: its corners are frozen.
    if (f[0] == f[1] || f[1] == f[2] || f[2] == f[0]) frozen_[f[0]] = frozen_[f[1]] = frozen_[f[2]] = 1;
    for (int k = 0; k < 3; ++k) pool_[fill[f[k]]++] = uint32_t(t);
  }
  live_ = count_;
  liveTriangles_ = nt;
}

// Face quadrics (G&H 5) and, on open borders, G&H 6.2's boundary planes: the plane through a
// border edge perpendicular to its face, heavily weighted, so a hole's border keeps its shape while
// it simplifies (the region's own border is locked; scan holes are not). Vertices on an edge used
// by three or more triangles, or on more than two border edges, are frozen: no collapse around
// them can keep the surface a manifold that the link condition describes.
void Simplifier::buildQuadrics() {
  quadric_.assign(nv_, Quadric());
  border_.assign(nv_, 0);
  const size_t nt = tri_.size() / 3;
  for (size_t t = 0; t < nt; ++t) {
    const uint32_t* f = &tri_[t * 3];
    double n[3];
    areaVector(&pos_[f[0] * 3], &pos_[f[1] * 3], &pos_[f[2] * 3], n);
    const double len = std::sqrt(dot(n, n));
    if (!(len > 0)) continue;
    for (double& x : n) x /= len;
    const double d = -dot(n, &pos_[f[0] * 3]);
    for (int k = 0; k < 3; ++k) quadric_[f[k]].addPlane(n, d, 0.5 * len);
  }
  std::vector<uint32_t> nb;
  for (uint32_t a = 0; a < nv_; ++a) {
    nb.clear();
    for (uint32_t i = start_[a]; i < start_[a] + count_[a]; ++i)
      for (int k = 0; k < 3; ++k)
        if (tri_[pool_[i] * 3 + k] != a) nb.push_back(tri_[pool_[i] * 3 + k]);
    sortSmall(nb);
    uint32_t borderEdges = 0;
    for (size_t i = 0; i < nb.size();) {
      size_t j = i;
      while (j < nb.size() && nb[j] == nb[i]) ++j;
      const uint32_t b = nb[i], uses = uint32_t(j - i);
      i = j;
      if (uses > 2) frozen_[a] = frozen_[b] = 1;
      if (uses != 1) continue;
      ++borderEdges;
      if (b < a) continue;  // each border edge's planes once, from its lower vertex
      for (uint32_t k = start_[a]; k < start_[a] + count_[a]; ++k) {
        const uint32_t* f = &tri_[pool_[k] * 3];
        if (f[0] != b && f[1] != b && f[2] != b) continue;
        double fn[3], e[3], n[3];
        areaVector(&pos_[f[0] * 3], &pos_[f[1] * 3], &pos_[f[2] * 3], fn);
        sub(&pos_[b * 3], &pos_[a * 3], e);
        cross(e, fn, n);
        const double len = std::sqrt(dot(n, n));
        if (!(len > 0)) break;
        for (double& x : n) x /= len;
        const double w = options_.boundaryWeight * dot(e, e), d = -dot(n, &pos_[a * 3]);
        quadric_[a].addPlane(n, d, w);
        quadric_[b].addPlane(n, d, w);
        break;
      }
    }
    if (borderEdges > 2) frozen_[a] = 1;
    if (borderEdges > 0) border_[a] = 1;
  }
}

Cell Simplifier::cellOf(const double* g) const {
  Cell c;
  for (int a = 0; a < 3; ++a) c.c[a] = floorToInt((g[a] - options_.gridOrigin[a]) / options_.gridStep + 0.5);
  return c;
}

// Puts the new point on the grid point of least quadric error among the 8 corners of the grid cube
// around it (global g, local p; both updated). Rounding to the nearest grid point instead moves the
// point off the local planes by a quarter step on average, as much as the simplification itself
// costs at a few levels (the step is 1/8 of the mean input edge); the best corner lies on or next
// to them. Corners are kept within the grid cells of the input's box, which the grid covers.
void Simplifier::bestCorner(const Quadric& q, double* g, double* p) const {
  // The corners are base + d with d in {0, step}^3 per axis (0 on an axis where the box's cells
  // leave one choice). With x = base (local), q(x + d) = q(x) + 2 (A x + b).d + d^T A d: one full
  // evaluation, then a few additions per corner.
  double x[3], d[3];
  int64_t index[3];
  for (int a = 0; a < 3; ++a) {
    const int64_t i = floorToInt((g[a] - options_.gridOrigin[a]) / options_.gridStep);
    const int64_t i0 = std::min(std::max(i, cellLo_[a]), cellHi_[a]), i1 = std::min(std::max(i + 1, cellLo_[a]), cellHi_[a]);
    index[a] = i0;
    x[a] = options_.gridOrigin[a] + options_.gridStep * double(i0) - center_[a];
    d[a] = options_.gridStep * double(i1 - i0);
  }
  const double e0 = q.at(x);
  const double gx = 2 * (q.a00 * x[0] + q.a01 * x[1] + q.a02 * x[2] + q.b0) * d[0];
  const double gy = 2 * (q.a01 * x[0] + q.a11 * x[1] + q.a12 * x[2] + q.b1) * d[1];
  const double gz = 2 * (q.a02 * x[0] + q.a12 * x[1] + q.a22 * x[2] + q.b2) * d[2];
  const double xx = q.a00 * d[0] * d[0], yy = q.a11 * d[1] * d[1], zz = q.a22 * d[2] * d[2];
  const double xy = 2 * q.a01 * d[0] * d[1], xz = 2 * q.a02 * d[0] * d[2], yz = 2 * q.a12 * d[1] * d[2];
  // Corner k = (i, j, l) bits: e0 + i X + j Y + l Z + ij xy + il xz + jl yz, each sum taken in
  // that order (the terms that are zero dropped).
  const double X = gx + xx, Y = gy + yy, Z = gz + zz;
  const double e[8] = {e0,
                       e0 + X,
                       e0 + Y,
                       e0 + X + Y + xy,
                       e0 + Z,
                       e0 + X + Z + xz,
                       e0 + Y + Z + yz,
                       e0 + X + Y + Z + xy + xz + yz};
  double best = e[0];
  int bestCorner = 0;
  for (int corner = 1; corner < 8; ++corner)
    if (e[corner] < best) best = e[corner], bestCorner = corner;
  for (int a = 0; a < 3; ++a) {
    const int64_t i = index[a] + (d[a] > 0 ? (bestCorner >> a) & 1 : 0);
    g[a] = options_.gridOrigin[a] + options_.gridStep * double(i);
    p[a] = g[a] - center_[a];
  }
}

// The collapse of edge (a, b) and its cost (G&H 4): toward a frozen end without moving it; else to
// the quadric's minimum when it lies within one edge length of the edge's midpoint (farther means
// the minimum is set by noise far from this neighbourhood, as vcg also refuses), else to the best
// of the two ends and the midpoint; a new point is clamped to the input's bounding box. allowMove false: only the ends (the grid cell of a new point
// was taken).
bool Simplifier::candidate(uint32_t a, uint32_t b, bool allowMove, Candidate& c) const {
  if (frozen_[a] && frozen_[b]) return false;
  // A free rim vertex goes only onto a vertex on a border: a frozen interior vertex (a
  // non-manifold spot) would carry the rim off the input's rim vertices.
  if ((frozen_[a] && !border_[a] && border_[b]) || (frozen_[b] && !border_[b] && border_[a])) return false;
  Quadric q = quadric_[a];
  q.add(quadric_[b]);
  if (colors_.active()) {  // the colour error at the best colours, as a quadric in the position
    double k[10];
    colors_.reduced(a, b, k);
    q.add(k);
  }
  const double *pa = &pos_[a * 3], *pb = &pos_[b * 3];
  c.moves = false;
  if (frozen_[a] || frozen_[b]) {
    c.s = frozen_[a] ? a : b;
    c.cost = q.at(&pos_[c.s * 3]);
  } else if (border_[a] || border_[b]) {
    // Toward the border end without moving it; both on the border: the end of least error.
    if (border_[a] && border_[b]) {
      const double ea = q.at(pa), eb = q.at(pb);
      c.s = ea < eb || (ea == eb && a < b) ? a : b;
      c.cost = c.s == a ? ea : eb;
    } else {
      c.s = border_[a] ? a : b;
      c.cost = q.at(&pos_[c.s * 3]);
    }
  } else {
    double mid[3], p[3];
    for (int k = 0; k < 3; ++k) mid[k] = 0.5 * (pa[k] + pb[k]);
    const double l2 = dist2(pa, pb);
    bool ok = allowMove && q.minimum(mid, p) && dist2(p, mid) <= l2;
    if (allowMove && !ok) std::memcpy(p, mid, sizeof p), ok = true;  // compared with the ends below
    // Never outside the input's box: the quantization grid covers the input's box only.
    for (int k = 0; k < 3; ++k) p[k] = std::min(std::max(p[k], lo_[k]), hi_[k]);
    double g[3];
    for (int k = 0; k < 3; ++k) g[k] = p[k] + center_[k];
    if (ok && options_.gridStep > 0) bestCorner(q, g, p);
    const double ea = q.at(pa), eb = q.at(pb), ep = ok ? q.at(p) : DBL_MAX;
    if (ep < std::min(ea, eb)) {
      std::memcpy(c.p, p, sizeof c.p);
      std::memcpy(c.g, g, sizeof c.g);
      c.moves = true;
      const double da = dist2(p, pa), db = dist2(p, pb);  // the nearer end keeps its id (attributes)
      c.s = da < db || (da == db && a < b) ? a : b;
      c.cost = ep;
    } else {
      c.s = ea < eb || (ea == eb && a < b) ? a : b;
      c.cost = c.s == a ? ea : eb;
    }
  }
  if (!c.moves) {
    std::memcpy(c.p, &pos_[c.s * 3], sizeof c.p);
    std::memcpy(c.g, out_ + size_t(c.s) * 3, sizeof c.g);
  }
  c.r = c.s == a ? b : a;
  if (colors_.active()) c.cost += colors_.fixedColorCost(c.s, c.r, c.p);
  c.versionS = version_[c.s], c.versionR = version_[c.r];
  return true;
}

void Simplifier::neighbours(uint32_t v, std::vector<uint32_t>& n) const {
  n.clear();
  for (uint32_t i = start_[v]; i < start_[v] + count_[v]; ++i) {
    const uint32_t t = pool_[i];
    if (dead_[t]) continue;
    for (int k = 0; k < 3; ++k)
      if (tri_[t * 3 + k] != v) n.push_back(tri_[t * 3 + k]);
  }
  sortSmall(n);
}

// Whether collapse c may be done now. The link condition (Dey, Edelsbrunner et al. 1999, as used
// for G&H's "valid pairs" restricted to edges): the common neighbours of s and r are exactly the
// apexes of the edge's triangles, and an interior edge does not join two border vertices; with it
// the result stays a manifold with no duplicate face. Then the region rules (locks, chords), the
// face rules (no flip, no new sliver) and the grid rule (a moved vertex takes a free cell).
Verdict Simplifier::check(const Candidate& c) {
  const uint32_t s = c.s, r = c.r;
  minQuality_ = 1;
  double awayR = DBL_MAX, awayS = c.moves ? DBL_MAX : 0;
  auto liveOf = [&](uint32_t v, std::vector<uint32_t>& out) {
    out.clear();
    for (uint32_t i = start_[v]; i < start_[v] + count_[v]; ++i)
      if (!dead_[pool_[i]]) out.push_back(pool_[i]);
  };
  auto has = [&](uint32_t t, uint32_t v) { return tri_[t * 3] == v || tri_[t * 3 + 1] == v || tri_[t * 3 + 2] == v; };
  liveOf(s, ts_), liveOf(r, tr_);
  edge_.clear();
  for (uint32_t t : ts_)
    if (has(t, r)) edge_.push_back(t);
  if (edge_.empty() || edge_.size() > 2) return Verdict::Refused;
  // Neighbours with multiplicity (a neighbour seen once is across a border edge), by stamps: no
  // sorting (neighbour lists were sorted here and were a tenth of the simplifier).
  const uint32_t stampS = ++stamp_, stampR = ++stamp_;
  auto gather = [&](uint32_t v, const std::vector<uint32_t>& tris, uint32_t stamp, std::vector<uint32_t>& mark,
                    std::vector<uint32_t>& uses, std::vector<uint32_t>& list) {
    list.clear();
    for (uint32_t t : tris)
      for (int k = 0; k < 3; ++k) {
        const uint32_t w = tri_[t * 3 + k];
        if (w == v) continue;
        if (mark[w] != stamp) mark[w] = stamp, uses[w] = 0, list.push_back(w);
        ++uses[w];
      }
    bool border = false;
    for (uint32_t w : list) border |= uses[w] == 1;
    return border;
  };
  const bool sBorder = gather(s, ts_, stampS, markS_, usesS_, ns_), rBorder = gather(r, tr_, stampR, markR_, usesR_, nr_);
  if (edge_.size() == 2 && sBorder && rBorder) return Verdict::Refused;
  uint32_t apex[2] = {~0u, ~0u};
  for (size_t i = 0; i < edge_.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      const uint32_t v = tri_[edge_[i] * 3 + k];
      if (v != s && v != r) apex[i] = v;
    }
  if (edge_.size() == 2 && apex[0] == apex[1]) return Verdict::Refused;  // a duplicate face
  for (size_t i = 0; i < edge_.size(); ++i)
    if (live_[apex[i]] <= 1) return Verdict::Refused;  // the apex would lose its last triangle
  size_t common = 0;
  for (uint32_t w : nr_) common += markS_[w] == stampS;
  if (common != edge_.size()) return Verdict::Refused;
  // A locked survivor gains r's neighbours: none of them may be locked (a chord across the region
  // border could duplicate an edge of a patch outside it).
  if (locked_[s])
    for (uint32_t w : nr_)
      if (w != s && locked_[w] && markS_[w] != stampS) return Verdict::Refused;
  // Faces that change: r's (r becomes s), and s's when s moves.
  for (int pass = 0; pass < (c.moves ? 2 : 1); ++pass)
    for (uint32_t t : pass == 0 ? tr_ : ts_) {
      if (has(t, s) && has(t, r)) continue;
      const double* q[3];
      const double* n[3];
      for (int k = 0; k < 3; ++k) {
        const uint32_t v = tri_[t * 3 + k];
        q[k] = &pos_[v * 3];
        n[k] = v == r || v == s ? c.p : q[k];
      }
      double before[3], after[3];
      areaVector(q[0], q[1], q[2], before);
      areaVector(n[0], n[1], n[2], after);
      if (!(dot(before, after) > 0)) return Verdict::Refused;
      const double qa = quality(n[0], n[1], n[2], after);
      if (qa < kMinQuality && qa < quality(q[0], q[1], q[2], before)) return Verdict::Refused;
      minQuality_ = std::min(minQuality_, qa);
      // How far the ends' old positions are from the new faces (kAwayWeight): r's from the faces
      // it becomes part of, a moved s's from all of them.
      awayR = std::min(awayR, squaredPointTriangleDistance(&pos_[r * 3], n[0], n[1], n[2]));
      if (c.moves) awayS = std::min(awayS, squaredPointTriangleDistance(&pos_[s * 3], n[0], n[1], n[2]));
    }
  // How far the edges the collapse makes (s's new edges: to r's neighbours, and to all of them
  // when s moves) are from the old surface, by their midpoints against the old faces of s and r.
  double edgeAway = 0;
  auto edgeTo = [&](uint32_t a) {
    double m[3];
    for (int k = 0; k < 3; ++k) m[k] = 0.5 * (c.p[k] + pos_[a * 3 + k]);
    double nearest = DBL_MAX;
    for (int pass = 0; pass < 2; ++pass)
      for (uint32_t t : pass == 0 ? tr_ : ts_)
        nearest = std::min(nearest, squaredPointTriangleDistance(m, &pos_[tri_[t * 3] * 3], &pos_[tri_[t * 3 + 1] * 3],
                                                                 &pos_[tri_[t * 3 + 2] * 3]));
    edgeAway = std::max(edgeAway, nearest);
  };
  for (uint32_t a : nr_)
    if (a != s && markS_[a] != stampS) edgeTo(a);
  if (c.moves)
    for (uint32_t a : ns_)
      if (a != r) edgeTo(a);
  away2_ = std::max({awayR == DBL_MAX ? 0 : awayR, awayS == DBL_MAX ? 0 : awayS, edgeAway});
  if (c.moves && options_.gridStep > 0) {
    const Cell k = cellOf(c.g);
    uint32_t n = cells_.count(k);
    n -= cellOfVertex(s) == k;
    n -= cellOfVertex(r) == k;
    if (n > 0) return Verdict::GridTaken;
  }
  return Verdict::Ok;
}

void Simplifier::appendTriangle(uint32_t v, uint32_t t) {
  if (count_[v] == cap_[v]) {
    const uint32_t room = std::max<uint32_t>(8, cap_[v] * 2), at = uint32_t(pool_.size());
    pool_.resize(pool_.size() + room);
    std::copy(pool_.begin() + start_[v], pool_.begin() + start_[v] + count_[v], pool_.begin() + at);
    start_[v] = at, cap_[v] = room;
  }
  pool_[start_[v] + count_[v]++] = t;
}

// Performs collapse c (check() has just filled ts_, tr_ and edge_ for it).
void Simplifier::collapse(const Candidate& c) {
  const uint32_t s = c.s, r = c.r;
  for (uint32_t t : edge_) {
    dead_[t] = 1;
    for (int k = 0; k < 3; ++k) --live_[tri_[t * 3 + k]];
    --liveTriangles_;
  }
  // s's list without its dead triangles, then r's live ones, renamed.
  uint32_t n = 0;
  for (uint32_t i = start_[s]; i < start_[s] + count_[s]; ++i)
    if (!dead_[pool_[i]]) pool_[start_[s] + n++] = pool_[i];
  count_[s] = n;
  for (uint32_t t : tr_) {
    if (dead_[t]) continue;
    for (int k = 0; k < 3; ++k)
      if (tri_[t * 3 + k] == r) tri_[t * 3 + k] = s;
    appendTriangle(s, t);
  }
  live_[s] += live_[r];
  live_[r] = 0;
  count_[r] = 0;
  if (options_.gridStep > 0) {
    for (uint32_t v : {s, r}) {
      uint32_t& n = cells_[cellOfVertex(v)];
      assert(n > 0);
      --n;
    }
  }
  std::memcpy(&pos_[s * 3], c.p, sizeof c.p);
  std::memcpy(out_ + size_t(s) * 3, c.g, sizeof c.g);
  if (c.moves && moved_) moved_[s] = 1;
  if (options_.gridStep > 0) ++cells_[cellOfVertex(s)];
  quadric_[s].add(quadric_[r]);
  if (colors_.active()) colors_.collapse(s, r, c.p);
  ++version_[s], ++version_[r];
  into_[r] = s;
  wake(s), wake(r);
  ++stats.collapses;
  stats.maxCost = std::max(stats.maxCost, c.cost);
}

uint32_t Simplifier::find(uint32_t v) {
  while (into_[v] != v) v = into_[v] = into_[into_[v]];  // path halving
  return v;
}

void Simplifier::park(const Entry& e) {
  const uint32_t i = uint32_t(parked_.size());
  parked_.push_back(e);
  parkedLive_.push_back(1);
  parkedNext_.push_back(parkedHead_[e.s()]);
  parkedNext_.push_back(parkedHead_[e.r]);
  parkedHead_[e.s()] = parkedHead_[e.r] = i;
}

// Back to the heap with every refused collapse at v (its neighbourhood has just changed).
void Simplifier::wake(uint32_t v) {
  for (uint32_t i = parkedHead_[v]; i != ~0u;) {
    const Entry& e = parked_[i];
    const uint32_t next = parkedNext_[2 * size_t(i) + (e.s() == v ? 0 : 1)];
    if (parkedLive_[i]) parkedLive_[i] = 0, heapPush(heap_, e);
    i = next;
  }
  parkedHead_[v] = ~0u;
}

// A new round: every parked collapse back to the heap. Returns how many.
size_t Simplifier::unpark() {
  size_t n = 0;
  for (size_t i = 0; i < parked_.size(); ++i)
    if (parkedLive_[i]) heap_.push_back(parked_[i]), ++n;
  parked_.clear(), parkedNext_.clear(), parkedLive_.clear();
  std::fill(parkedHead_.begin(), parkedHead_.end(), ~0u);
  heapMake(heap_);
  return n;
}

// Collapses in cost order until the target, with lazy updates: a collapse pushes nothing. The
// entries of the edges around it keep their old costs, which are lower bounds (a vertex's quadric
// only grows), and each is recomputed when it reaches the top: most never do before the target,
// and one that a vertex's later collapses made stale again is recomputed once, not each time (an
// eager heap recomputed ~7 edges per collapse; 80% of its pops were stale). A refused collapse
// is parked until either end changes, or for the next round (at most 3) when the heap runs dry;
// a collapse whose new point's grid cell is taken is offered again without the move.
void Simplifier::run(size_t targetTriangles) {
  std::vector<uint32_t> nb;
  for (uint32_t v = 0; v < nv_; ++v) {
    neighbours(v, nb);
    nb.erase(std::unique(nb.begin(), nb.end()), nb.end());
    for (uint32_t w : nb) {
      Candidate c;
      if (w > v && candidate(v, w, true, c)) heap_.push_back(entryOf(c, true));
    }
  }
  heapMake(heap_);
  into_.resize(nv_);
  for (uint32_t v = 0; v < nv_; ++v) into_[v] = v;
  parkedHead_.assign(nv_, ~0u);
  for (int round = 0; liveTriangles_ > targetTriangles;) {
    if (heap_.empty()) {
      if (round == 3 || unpark() == 0) break;
      ++round;
      continue;
    }
    const Entry e = heap_.front();
    Candidate c;
    // Stale (an end collapsed or moved since the push; or a truncated version wrapped): the entry
    // takes the current cost of the edge it stands for, in place (one sift-down, not a pop and a
    // push), or leaves when that edge has collapsed.
    if (!current(e) || !candidate(e.s(), e.r, e.allowMove(), c) || c.s != e.s() ||
        (!e.penalized() && float(c.cost) != e.cost())) {
      const uint32_t a = find(e.s()), b = find(e.r);
      // An end with no triangle left (a collapse can take a vertex's last ones, a small closed
      // piece's, and leave it its own representative) has no edge to collapse, and an entry for
      // it is never current(): recomputing it here would recompute it forever.
      if (a != b && count_[a] && count_[b] && candidate(a, b, true, c)) {
        heap_.front() = entryOf(c, true);
        siftDown(heap_, 0);
      } else {
        heapPop(heap_);
      }
      continue;
    }
    heapPop(heap_);
    const Verdict verdict = check(c);
    // The shape penalty and the distance floor (kAwayWeight) need the neighbourhood, so they are
    // applied when popped (the raw cost is a lower bound): a penalized collapse that is no longer
    // the cheapest goes back in.
    if (verdict == Verdict::Ok && !e.penalized() && (minQuality_ < kFairQuality || away2_ > 0)) {
      double cost = c.cost;
      if (minQuality_ < kFairQuality) cost *= kFairQuality / std::max(minQuality_, 1e-6);
      const Quadric &qs = quadric_[c.s], &qr = quadric_[c.r];
      cost = std::max(cost, kAwayWeight * (qs.a00 + qs.a11 + qs.a22 + qr.a00 + qr.a11 + qr.a22) * away2_);
      Entry p = e;
      p.setCost(float(cost));
      p.versionS |= 0x8000;
      if (!heap_.empty() && !Later()(heap_.front(), p)) {
        heapPush(heap_, p);
        continue;
      }
    }
    if (verdict == Verdict::Ok) {
      collapse(c);
    } else if (verdict == Verdict::GridTaken) {
      Candidate d;
      if (candidate(c.s, c.r, false, d)) push(d, false);
    } else {
      ++stats.rejected;
      park(e);
    }
  }
}

size_t Simplifier::write(uint32_t* destination) const {
  size_t n = 0;
  for (size_t t = 0; t < dead_.size(); ++t)
    if (!dead_[t])
      for (int k = 0; k < 3; ++k) destination[n++] = tri_[t * 3 + k];
  return n;
}

}  // namespace

namespace {

// One run of the simplifier on (indices, positions) down to targetIndexCount.
size_t simplifyOnce(uint32_t* destination, double* destinationPositions, uint8_t* moved, const uint32_t* indices,
                    size_t indexCount, const double* positions, size_t vertexCount, size_t positionStride,
                    const uint8_t* locked, size_t targetIndexCount, const QuadricSimplifyOptions& options,
                    QuadricSimplifyStats& stats) {
  Simplifier s(indices, indexCount, positions, vertexCount, positionStride, locked, options, destinationPositions,
               moved);
  s.run(targetIndexCount / 3);
  stats.collapses += s.stats.collapses;
  stats.rejected += s.stats.rejected;
  stats.maxCost = std::max(stats.maxCost, s.stats.maxCost);
  if (options.destinationColors) s.colors().write(options.destinationColors);
  return s.write(destination);
}

}  // namespace

size_t quadricSimplify(uint32_t* destination, double* destinationPositions, uint8_t* moved, const uint32_t* indices,
                       size_t indexCount, const double* positions, size_t vertexCount, size_t positionStride,
                       const uint8_t* locked, size_t targetIndexCount, const QuadricSimplifyOptions& options,
                       QuadricSimplifyStats* stats) {
  assert(indexCount % 3 == 0);
  assert(positionStride >= 3 * sizeof(double));
  assert(options.passes >= 1);
  for (size_t i = 0; i < indexCount; ++i) assert(indices[i] < vertexCount);
  QuadricSimplifyStats total;
  const int passes = targetIndexCount < indexCount ? std::max(options.passes, 1) : 1;
  // Each pass reads the previous one's triangles, positions and colours (the quadrics, boundary
  // planes and colour quadrics are rebuilt from them) and writes the next; the last writes the
  // caller's buffers. A vertex unmoved by every pass keeps its input position bit for bit. One
  // pass is the first and the last: it reads the caller's input and writes the caller's buffers.
  std::vector<uint32_t> tris;
  std::vector<double> pos;
  std::vector<uint8_t> colors, passMoved;
  const double from = double(indexCount / 3), to = double(targetIndexCount / 3);
  size_t count = indexCount;
  for (int pass = 1; pass <= passes; ++pass) {
    const bool last = pass == passes;
    // The geometric interpolation: every pass removes about the same share of what it gets.
    const size_t target =
        last ? targetIndexCount : 3 * size_t(std::llround(from * std::pow(to / from, double(pass) / passes)));
    QuadricSimplifyOptions o = options;
    std::vector<uint8_t> nextColors;
    if (pass > 1 && options.colors) o.colors = colors.data();
    if (!last && options.colors) nextColors.resize(vertexCount * 4), o.destinationColors = nextColors.data();
    std::vector<uint32_t> outTris(last ? 0 : count);
    std::vector<double> outPos(last ? 0 : vertexCount * 3);
    // The first pass writes the caller's moved flags (it clears them first); later ones add theirs.
    if (pass > 1 && moved) passMoved.resize(vertexCount);
    uint8_t* passMovedOut = pass == 1 ? moved : (moved ? passMoved.data() : nullptr);
    const uint32_t* in = pass == 1 ? indices : tris.data();
    const double* inPos = pass == 1 ? positions : pos.data();
    const size_t stride = pass == 1 ? positionStride : 3 * sizeof(double);
    count = simplifyOnce(last ? destination : outTris.data(), last ? destinationPositions : outPos.data(),
                         passMovedOut, in, count, inPos, vertexCount, stride, locked, target, o, total);
    if (pass > 1 && moved)
      for (size_t v = 0; v < vertexCount; ++v) moved[v] |= passMoved[v];
    if (!last) {
      outTris.resize(count);
      tris.swap(outTris), pos.swap(outPos), colors.swap(nextColors);
    }
  }
  if (stats) *stats = total;
  return count;
}

}  // namespace mt
