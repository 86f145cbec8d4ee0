// Hoppe 1999's attribute quadric for per-vertex colour (see attribute_quadric.h).
#include "mtbuild/attribute_quadric.h"

#include <cassert>
#include <cmath>
#include <cstring>

namespace mt {

void ColorQuadrics::Q::add(const Q& o) {
  for (int i = 0; i < 6; ++i) gpp[i] += o.gpp[i];
  for (int j = 0; j < kChannels; ++j) {
    for (int k = 0; k < 3; ++k) g[j][k] += o.g[j][k];
    d[j] += o.d[j];
  }
  for (int k = 0; k < 3; ++k) bp[k] += o.bp[k];
  c += o.c, w += o.w;
}

void ColorQuadrics::init(const uint8_t* colors, double colorScale, const uint8_t* locked, const double* positions,
                         size_t vertexCount, const uint32_t* triangles, size_t indexCount) {
  scale_ = colors && colorScale > 0 ? colorScale : 0;
  if (!active()) return;
  rgba_.assign(colors, colors + vertexCount * kChannels);
  locked_.assign(vertexCount, 0);
  if (locked)
    for (size_t v = 0; v < vertexCount; ++v) locked_[v] = locked[v] ? 1 : 0;
  q_.assign(vertexCount, Q());
  const double unit = scale_ / 255.0;
  for (size_t t = 0; t + 2 < indexCount; t += 3) {
    const uint32_t* f = triangles + t;
    const double *p0 = positions + size_t(f[0]) * 3, *p1 = positions + size_t(f[1]) * 3, *p2 = positions + size_t(f[2]) * 3;
    double e1[3], e2[3];
    for (int k = 0; k < 3; ++k) e1[k] = p1[k] - p0[k], e2[k] = p2[k] - p0[k];
    // The gradient g of a linear function over the face with values a0, a1, a2 at its corners lies
    // in the face's plane: g = x e1 + y e2 with g.e1 = a1 - a0, g.e2 = a2 - a0 (a 2x2 Gram system;
    // its determinant is |e1 x e2|^2 = 4 area^2). Hoppe's section 4 solves the same as 4x4.
    const double g11 = e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2], g22 = e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2];
    const double g12 = e1[0] * e2[0] + e1[1] * e2[1] + e1[2] * e2[2];
    const double det = g11 * g22 - g12 * g12;
    if (!(det > 1e-24 * g11 * g22)) continue;  // degenerate: no plane, no gradient (the geometric quadric skips it too)
    const double w = 0.5 * std::sqrt(det);      // the face's area, the geometric planes' weight
    Q face;
    face.w = w;
    for (int j = 0; j < kChannels; ++j) {
      const double a0 = unit * rgba_[size_t(f[0]) * kChannels + j], a1 = unit * rgba_[size_t(f[1]) * kChannels + j],
                   a2 = unit * rgba_[size_t(f[2]) * kChannels + j];
      const double r1 = a1 - a0, r2 = a2 - a0;
      const double x = (g22 * r1 - g12 * r2) / det, y = (g11 * r2 - g12 * r1) / det;
      double g[3];
      for (int k = 0; k < 3; ++k) g[k] = x * e1[k] + y * e2[k];
      const double d = a0 - (g[0] * p0[0] + g[1] * p0[1] + g[2] * p0[2]);
      face.gpp[0] += w * g[0] * g[0], face.gpp[1] += w * g[1] * g[1], face.gpp[2] += w * g[2] * g[2];
      face.gpp[3] += w * g[0] * g[1], face.gpp[4] += w * g[0] * g[2], face.gpp[5] += w * g[1] * g[2];
      for (int k = 0; k < 3; ++k) face.g[j][k] = w * g[k], face.bp[k] += w * d * g[k];
      face.d[j] = w * d;
      face.c += w * d * d;
    }
    for (int k = 0; k < 3; ++k) q_[f[k]].add(face);
  }
}

void ColorQuadrics::reduced(uint32_t a, uint32_t b, double out[10]) const {
  Q q = q_[a];
  q.add(q_[b]);
  for (int i = 0; i < 10; ++i) out[i] = 0;
  if (!(q.w > 0)) return;
  const double inv = 1 / q.w;
  // A' = Gpp - sum G_j G_j^T / W, b' = Bp - sum D_j G_j / W, c' = C - sum D_j^2 / W.
  double a00 = q.gpp[0], a11 = q.gpp[1], a22 = q.gpp[2], a01 = q.gpp[3], a02 = q.gpp[4], a12 = q.gpp[5];
  double b0 = q.bp[0], b1 = q.bp[1], b2 = q.bp[2], c = q.c;
  for (int j = 0; j < kChannels; ++j) {
    const double* g = q.g[j];
    a00 -= g[0] * g[0] * inv, a11 -= g[1] * g[1] * inv, a22 -= g[2] * g[2] * inv;
    a01 -= g[0] * g[1] * inv, a02 -= g[0] * g[2] * inv, a12 -= g[1] * g[2] * inv;
    b0 -= q.d[j] * g[0] * inv, b1 -= q.d[j] * g[1] * inv, b2 -= q.d[j] * g[2] * inv;
    c -= q.d[j] * q.d[j] * inv;
  }
  out[0] = a00, out[1] = a11, out[2] = a22, out[3] = a01, out[4] = a02, out[5] = a12;
  out[6] = b0, out[7] = b1, out[8] = b2, out[9] = c;
}

void ColorQuadrics::best(const Q& q, const double p[3], double s[kChannels]) const {
  for (int j = 0; j < kChannels; ++j)
    s[j] = q.w > 0 ? (q.g[j][0] * p[0] + q.g[j][1] * p[1] + q.g[j][2] * p[2] + q.d[j]) / q.w : 0;
}

double ColorQuadrics::fixedColorCost(uint32_t s, uint32_t r, const double p[3]) const {
  if (!locked_[s]) return 0;
  Q q = q_[s];
  q.add(q_[r]);
  double best[kChannels];
  this->best(q, p, best);
  double e = 0;
  for (int j = 0; j < kChannels; ++j) {
    const double diff = scale_ / 255.0 * rgba_[size_t(s) * kChannels + j] - best[j];
    e += diff * diff;
  }
  return q.w * e;
}

void ColorQuadrics::collapse(uint32_t s, uint32_t r, const double p[3]) {
  q_[s].add(q_[r]);
  if (locked_[s]) return;
  double best[kChannels];
  this->best(q_[s], p, best);
  for (int j = 0; j < kChannels; ++j) {
    const double level = best[j] / scale_ * 255.0;
    rgba_[size_t(s) * kChannels + j] = uint8_t(level <= 0 ? 0 : level >= 255 ? 255 : std::lround(level));
  }
}

void ColorQuadrics::write(uint8_t* out) const {
  if (active()) std::memcpy(out, rgba_.data(), rgba_.size());
}

}  // namespace mt
