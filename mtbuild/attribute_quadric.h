// Per-vertex colour in the quadric simplifier: Hoppe's attribute quadric (H. Hoppe, "New quadric
// metric for simplifying meshes with appearance attributes", IEEE Visualization 1999), the
// memory-efficient variant of Garland & Heckbert 1998 ("Simplifying surfaces with color and texture
// using quadric error metrics").
//
// Why Hoppe's and not G&H 1998: G&H 1998 measure the distance in R^(3+m) to the face's affine
// 2-plane, so the geometric part of the error depends on how colour is scaled against length (a
// colour step tilts the plane and the geometric distance shrinks). Hoppe 1999 (section 3) keeps the
// geometric term exactly the squared distance to the face's plane (the existing G&H 1997 quadric of
// quadric_simplify.cpp, untouched) and adds, per attribute j, the squared difference between the
// vertex's value s_j and the face's linear interpolation of s_j at the point's projection into the
// face's plane:
//     E(p, s) = (n.p + d)^2 + sum_j (g_j.p + d_j - s_j)^2,       g_j in the face's plane,
// where g_j.p + d_j takes the face's three vertex values at its corners (section 4: g_j, d_j solve
// a 4x4 system; here the equivalent 2x2 Gram system over the face's edges). Per vertex it keeps,
// summed over its faces with the face's area as weight (as the geometric quadric):
//     Gpp = sum w g_j g_j^T (3x3), G_j = sum w g_j, Bp = sum w d_j g_j, D_j = sum w d_j,
//     C = sum w d_j^2, W = sum w:            6 + 3m + 3 + m + 1 + 1 doubles (27 for RGBA)
// against (3+m)(3+m+1)/2 + (3+m) + 1 = 36 for G&H 1998's full quadric.
//
// The simplifier places vertices in 3D only: for a position p the best values are
//     s_j*(p) = (G_j.p + D_j) / W                        (dE/ds_j = 0, Hoppe section 5)
// and the error at them is a quadric in p alone (the Schur complement of the s block):
//     E*(p) = p^T (Gpp - sum G_j G_j^T / W) p + 2 (Bp - sum D_j G_j / W).p + C - sum D_j^2 / W,
// so the collapse's optimal position, its grid corner and its cost all come from the existing 3x3
// machinery with E* added to the geometric quadric; and E(p, s) = E*(p) + W |s - s*(p)|^2 prices a
// survivor whose colour may not change (a region's locked border vertex: its colour is shared with
// patches outside the region).
//
// Scale: colours (RGBA8) enter as s = colorScale * c / 255, so colorScale is the length (model
// units) that a full-range colour difference weighs as much as. The caller chooses it per region
// (simplify_region.cpp: a multiple of the region's mean edge length, so the balance between colour
// and shape is the same at every level).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace mt {

class ColorQuadrics {
 public:
  static constexpr int kChannels = 4;  // RGBA
  // One vertex's attribute quadric (the sums above).
  struct Q {
    double gpp[6] = {0, 0, 0, 0, 0, 0};  // 00, 11, 22, 01, 02, 12
    double g[kChannels][3] = {};
    double bp[3] = {0, 0, 0};
    double d[kChannels] = {};
    double c = 0, w = 0;
    void add(const Q& o);
  };

  bool active() const { return scale_ > 0; }
  // colors: 4 bytes per vertex (RGBA8), or null (then inactive); locked: 1 byte per vertex (a
  // locked vertex keeps its colour), or null. positions: the simplifier's local positions, 3 per
  // vertex; triangles: indexCount indices. Builds every vertex's quadric from its faces.
  void init(const uint8_t* colors, double colorScale, const uint8_t* locked, const double* positions, size_t vertexCount,
            const uint32_t* triangles, size_t indexCount);
  // E* of the pair (a, b)'s summed quadric as 10 coefficients in quadric_simplify.cpp's order
  // (a00, a11, a22, a01, a02, a12, b0, b1, b2, c), to add to the geometric quadric.
  void reduced(uint32_t a, uint32_t b, double out[10]) const;
  // The extra cost of collapsing r into s at p when s keeps its colour (W |s - s*(p)|^2; 0 when
  // s may take its best colour).
  double fixedColorCost(uint32_t s, uint32_t r, const double p[3]) const;
  // After the collapse of r into s at p: s's quadric absorbs r's and, unless locked, s takes the
  // best colour at p.
  void collapse(uint32_t s, uint32_t r, const double p[3]);
  // Every vertex's colour now (RGBA8, 4 per vertex): the input's for untouched and locked vertices.
  void write(uint8_t* out) const;

 private:
  void best(const Q& q, const double p[3], double s[kChannels]) const;
  double scale_ = 0;
  std::vector<Q> q_;
  std::vector<uint8_t> rgba_;   // every vertex's colour now, kChannels per vertex
  std::vector<uint8_t> locked_;
};

}  // namespace mt
