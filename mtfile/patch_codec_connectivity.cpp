// The connectivity code of meshopt payloads with kPayloadConnectivity (mt_format.h has the exact
// bitstream): the triangle list in its given order, range-coded triangle by triangle.
//
// meshopt_encodeIndexBuffer (Giesen 2013, Stokes 2014) attaches each triangle to a recent edge (a
// 16-entry edge FIFO) and names its third vertex as the next new one, a recent one (a 16-entry
// vertex FIFO) or an explicit delta. On a traversal that grows a region (fan order), about half of
// the triangles close onto a vertex that entered long ago: the vertex FIFO has lost it and the
// delta costs a byte or two. This coder keeps the edge FIFO and replaces the vertex FIFO with what
// Edgebreaker (Rossignac 1999, "Edgebreaker: connectivity compression for triangle meshes",
// section 3) uses: the boundary of the region decoded so far. A triangle (a, b, c) attached to the
// edge a->b whose third vertex is not new closes onto the boundary: its neighbour across c-a holds
// the half-edge a->c, the one across b-c holds c->b, and such a half-edge is "open" (its twin not
// decoded yet). So c is named as the most recent open half-edge leaving a (Edgebreaker's R/E) or
// entering b (L), and only the rest (Edgebreaker's S, patch borders, non-manifold) need an
// explicit vertex. Measured on the patches of a 0.8M scan-derived build: docs/mt-format.md.
#include <cassert>
#include <cstring>
#include <memory>
#include <string>

#include "mtfile/patch_codec_detail.h"
#include "mtfile/range_coder.h"

namespace mt::codec_detail {

namespace {

constexpr uint32_t kNil = ~0u;

// The open half-edges of the decoded region, per vertex: out[u] lists v for every open u->v, in[v]
// lists u, most recent first (one pool of nodes, each in two doubly linked lists). A hash map
// from the directed edge to its most recent open node (and each node to the previous open copy
// of the same edge, for non-manifold input) closes a twin in constant time, so no input, however
// damaged, makes the decoder slower than linear.
class OpenEdges {
 public:
  OpenEdges(size_t vertexCount, size_t triangleCount) : outHead_(vertexCount, kNil), inHead_(vertexCount, kNil) {
    pool_.reserve(triangleCount * 3);
    size_t n = 16;
    while (n < triangleCount * 4) n *= 2;  // at most 3 open keys per triangle: load <= 3/4
    keys_.assign(n, ~0ull);
    vals_.resize(n);
    mask_ = n - 1;
  }
  // Adds the directed edge u->v of a new triangle: closes its twin v->u if that is open, else
  // opens u->v.
  void add(uint32_t u, uint32_t v) {
    uint32_t* twin = slot(key(v, u), false);
    if (twin && *twin != kNil) {
      Node& t = pool_[*twin];
      unlink(outHead_[v], t.outPrev, t.outNext, &Node::outPrev, &Node::outNext);
      unlink(inHead_[u], t.inPrev, t.inNext, &Node::inPrev, &Node::inNext);
      *twin = t.same;
      return;
    }
    uint32_t id = uint32_t(pool_.size());
    uint32_t* same = slot(key(u, v), true);
    pool_.push_back({u, v, kNil, outHead_[u], kNil, inHead_[v], *same});
    if (outHead_[u] != kNil) pool_[outHead_[u]].outPrev = id;
    if (inHead_[v] != kNil) pool_[inHead_[v]].inPrev = id;
    outHead_[u] = inHead_[v] = *same = id;
  }
  uint32_t firstOut(uint32_t u) const { return outHead_[u] == kNil ? kNil : pool_[outHead_[u]].v; }
  uint32_t firstIn(uint32_t v) const { return inHead_[v] == kNil ? kNil : pool_[inHead_[v]].u; }

 private:
  struct Node {
    uint32_t u, v;
    uint32_t outPrev, outNext, inPrev, inNext;
    uint32_t same;  // the previous open node of the same directed edge
  };
  static uint64_t key(uint32_t a, uint32_t b) { return (uint64_t(a) << 32) | b; }
  // The map's value for key k (kNil: none open); with insert, a new key starts at kNil.
  uint32_t* slot(uint64_t k, bool insert) {
    for (uint64_t i = ((k * 0x9E3779B97F4A7C15ull) >> 20) & mask_;; i = (i + 1) & mask_) {
      if (keys_[i] == k) return &vals_[i];
      if (keys_[i] == ~0ull) {
        if (!insert) return nullptr;
        keys_[i] = k, vals_[i] = kNil;
        return &vals_[i];
      }
    }
  }
  void unlink(uint32_t& head, uint32_t prev, uint32_t next, uint32_t Node::*prevField, uint32_t Node::*nextField) {
    if (prev == kNil) head = next;
    else pool_[prev].*nextField = next;
    if (next != kNil) pool_[next].*prevField = prev;
  }
  std::vector<uint32_t> outHead_, inHead_;
  std::vector<Node> pool_;
  std::vector<uint64_t> keys_;
  std::vector<uint32_t> vals_;
  uint64_t mask_;
};

// The 16 most recent candidate edges: the twins of the edges of recent triangles, each stored
// in the direction a later triangle attached to it walks it.
struct EdgeFifo {
  uint32_t e[16][2];
  uint32_t offset = 0;
  EdgeFifo() { std::memset(e, 0xff, sizeof e); }
  void push(uint32_t a, uint32_t b) {
    e[offset][0] = a, e[offset][1] = b;
    offset = (offset + 1) & 15;
  }
  const uint32_t* slot(uint32_t i) const { return e[(offset - 1 - i) & 15]; }
};

// Third-vertex symbols of an attached triangle.
enum : uint32_t { kNew = 0, kOpenOut = 1, kOpenIn = 2, kExplicit = 3 };
constexpr uint32_t kNoEdge = 16;  // the triangle is not attached to a FIFO edge

struct ConnectivityModel {
  // ctx = edge bucket of the previous triangle (slot 0, slot 1, other or none) * 4 + its symbol
  CountedBit slot0[16], slot1[16], slotRest[16][16];
  CountedBit third[12][4];  // [this triangle's slot bucket * 4 + previous symbol][tree node]
  CountedBit fresh[3];      // a corner of a free triangle is the next new vertex
  CountedBit length[64], mantissa[33][32];  // explicit vertex: d = next - 1 - v
};

inline uint32_t bucket(uint32_t slot) { return slot < 2 ? slot : 2; }

void encodeExplicit(RangeEncoder& rc, ConnectivityModel& m, uint32_t d) {
  uint32_t k = d ? 32 - uint32_t(__builtin_clz(d)) : 0;
  rc.tree(m.length, k, 6);
  for (uint32_t i = k >= 2 ? k - 1 : 0; i-- > 0;) rc.bit(m.mantissa[k][i], (d >> i) & 1);
}

// False when the code names no vertex decoded so far.
bool decodeExplicit(RangeDecoder& rc, ConnectivityModel& m, uint32_t next, uint32_t& v) {
  uint32_t k = rc.tree(m.length, 6);
  if (k > 32) return false;
  uint32_t d = k;
  if (k >= 2) {
    d = 1;
    for (uint32_t i = k - 1; i-- > 0;) d = (d << 1) | rc.bit(m.mantissa[k][i]);
  }
  if (d >= next) return false;
  v = next - 1 - d;
  return true;
}

}  // namespace

void encodeConnectivity(RangeEncoder& rc, const uint32_t* indices, size_t indexCount, size_t vertexCount,
                        std::vector<uint32_t>& coded) {
  auto m = std::make_unique<ConnectivityModel>();
  OpenEdges open(vertexCount, indexCount / 3);
  EdgeFifo fifo;
  coded.resize(indexCount);
  uint32_t next = 0, ctx = 3 * 4 + kExplicit;
  for (size_t t = 0; t < indexCount; t += 3) {
    const uint32_t* tri = indices + t;
    uint32_t slot = kNoEdge, rot = 0;
    for (uint32_t i = 0; i < 16 && slot == kNoEdge; ++i) {
      const uint32_t* e = fifo.slot(i);
      for (uint32_t r = 0; r < 3; ++r)
        if (e[0] == tri[r] && e[1] == tri[(r + 1) % 3]) {
          slot = i, rot = r;
          break;
        }
    }
    rc.bit(m->slot0[ctx], slot != 0);
    if (slot != 0) {
      rc.bit(m->slot1[ctx], slot != 1);
      if (slot != 1) rc.tree(m->slotRest[ctx], slot - 2, 4);
    }
    uint32_t a = tri[rot], b = tri[(rot + 1) % 3], c = tri[(rot + 2) % 3], sym = kExplicit;
    if (slot != kNoEdge) {
      assert(c <= next);  // a and b are known: c is known or the next new vertex
      sym = c == next ? kNew : c == open.firstOut(a) ? kOpenOut : c == open.firstIn(b) ? kOpenIn : kExplicit;
      rc.tree(m->third[bucket(slot) * 4 + (ctx & 3)], sym, 2);
      if (sym == kNew) ++next;
      else if (sym == kExplicit) encodeExplicit(rc, *m, next - 1 - c);
    } else {
      for (uint32_t k = 0; k < 3; ++k) {
        uint32_t v = tri[k];
        assert(v <= next);  // vertices are numbered by first use
        rc.bit(m->fresh[k], v != next);
        if (v == next) ++next;
        else encodeExplicit(rc, *m, next - 1 - v);
      }
    }
    coded[t] = a, coded[t + 1] = b, coded[t + 2] = c;
    open.add(a, b), open.add(b, c), open.add(c, a);
    if (slot == kNoEdge) fifo.push(b, a);
    fifo.push(c, b), fifo.push(a, c);
    ctx = (slot == kNoEdge ? 3 : bucket(slot)) * 4 + sym;
  }
  assert(next == vertexCount);
}

void decodeConnectivity(RangeDecoder& rc, uint32_t triangleCount, uint32_t vertexCount,
                        std::vector<uint32_t>& triangles) {
  auto m = std::make_unique<ConnectivityModel>();
  OpenEdges open(vertexCount, triangleCount);
  EdgeFifo fifo;
  triangles.resize(size_t(triangleCount) * 3);
  uint32_t next = 0, ctx = 3 * 4 + kExplicit;
  for (size_t t = 0; t < triangles.size(); t += 3) {
    uint32_t slot = 0;
    if (rc.bit(m->slot0[ctx])) {
      slot = 1;
      if (rc.bit(m->slot1[ctx])) slot = 2 + rc.tree(m->slotRest[ctx], 4);
    }
    if (slot > kNoEdge) bad("connectivity code names edge slot " + std::to_string(slot));
    uint32_t v[3], sym = kExplicit;
    if (slot != kNoEdge) {
      const uint32_t* e = fifo.slot(slot);
      if (e[0] == kNil) bad("connectivity code names an empty edge slot");
      v[0] = e[0], v[1] = e[1];
      sym = rc.tree(m->third[bucket(slot) * 4 + (ctx & 3)], 2);
      if (sym == kNew) {
        v[2] = next++;
      } else if (sym == kOpenOut) {
        v[2] = open.firstOut(v[0]);
      } else if (sym == kOpenIn) {
        v[2] = open.firstIn(v[1]);
      } else if (!decodeExplicit(rc, *m, next, v[2])) {
        bad("connectivity code names a vertex not decoded yet");
      }
      if (v[2] == kNil) bad("connectivity code names an open edge that does not exist");
    } else {
      for (uint32_t k = 0; k < 3; ++k) {
        if (!rc.bit(m->fresh[k])) v[k] = next++;
        else if (!decodeExplicit(rc, *m, next, v[k])) bad("connectivity code names a vertex not decoded yet");
      }
    }
    if (next > vertexCount) bad("connectivity code has more vertices than the header");
    // A valid stream is never read past its end: stop at once rather than decode the rest of a
    // damaged count from zeros.
    if (rc.overrun() > 0) bad("connectivity stream truncated");
    triangles[t] = v[0], triangles[t + 1] = v[1], triangles[t + 2] = v[2];
    open.add(v[0], v[1]), open.add(v[1], v[2]), open.add(v[2], v[0]);
    if (slot == kNoEdge) fifo.push(v[1], v[0]);
    fifo.push(v[2], v[1]), fifo.push(v[0], v[2]);
    ctx = (slot == kNoEdge ? 3 : bucket(slot)) * 4 + sym;
  }
  if (rc.overrun() > 0) bad("connectivity stream truncated");
  if (next != vertexCount) bad("vertices not referenced by any triangle");
}

}  // namespace mt::codec_detail
