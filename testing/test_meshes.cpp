#include "testing/test_meshes.h"

#include <algorithm>
#include <cmath>

namespace mt::test {

TestMesh gridSurface(uint32_t nu, uint32_t nv, bool wrapU, bool wrapV,
                     const std::function<void(double, double, double*)>& at,
                     const std::function<bool(double, double)>& keep) {
  TestMesh m;
  uint32_t pu = wrapU ? nu : nu + 1, pv = wrapV ? nv : nv + 1;
  for (uint32_t j = 0; j < pv; ++j)
    for (uint32_t i = 0; i < pu; ++i) {
      double p[3];
      at(double(i) / nu, double(j) / nv, p);
      m.positions.insert(m.positions.end(), p, p + 3);
    }
  auto id = [&](uint32_t i, uint32_t j) { return (j % pv) * pu + (i % pu); };
  for (uint32_t j = 0; j < nv; ++j)
    for (uint32_t i = 0; i < nu; ++i) {
      if (keep && !keep((i + 0.5) / nu, (j + 0.5) / nv)) continue;
      uint32_t a = id(i, j), b = id(i + 1, j), c = id(i + 1, j + 1), d = id(i, j + 1);
      m.triangles.insert(m.triangles.end(), {a, b, c, a, c, d});
    }
  return m;
}

TestMesh torus(double R, double r, uint32_t nu, uint32_t nv, const double centre[3],
               const std::function<bool(double, double)>& keep) {
  return gridSurface(nu, nv, true, true, [&](double u, double v, double* p) {
    double a = 2 * M_PI * u, b = 2 * M_PI * v;
    double rr = r * (1 + 0.08 * std::sin(7 * a) * std::sin(5 * b));  // scan-like bumps
    p[0] = centre[0] + (R + rr * std::cos(b)) * std::cos(a);
    p[1] = centre[1] + (R + rr * std::cos(b)) * std::sin(a);
    p[2] = centre[2] + rr * std::sin(b);
  }, keep);
}

// Closed: a displaced cube-sphere (6 faces of n x n quads, welded along the cube edges).
TestMesh closedBlob(uint32_t n) {
  TestMesh m;
  // Build per face, then weld exact-equal positions (cube edge points map identically).
  for (int face = 0; face < 6; ++face) {
    TestMesh f = gridSurface(n, n, false, false, [&](double u, double v, double* p) {
      double s = 2 * u - 1, t = 2 * v - 1, q[3];
      int axis = face / 2;
      double sign = face % 2 ? 1 : -1;
      q[axis] = sign;
      q[(axis + 1) % 3] = sign > 0 ? s : t;
      q[(axis + 2) % 3] = sign > 0 ? t : s;
      double len = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]);
      for (int k = 0; k < 3; ++k) q[k] /= len;
      double d = 1 + 0.15 * std::sin(4 * q[0]) * std::cos(3 * q[1]) + 0.05 * std::sin(9 * q[2]);
      p[0] = 1.6 * d * q[0];
      p[1] = d * q[1];
      p[2] = 0.8 * d * q[2];
    });
    m.append(f);
  }
  return m;
}

// A torus with ~60 round holes of varied size (a scan with missing regions).
TestMesh holedTorus(uint32_t nu, uint32_t nv) {
  struct Hole { double u, v, r; };
  std::vector<Hole> holes;
  Lcg rng(7);
  for (int k = 0; k < 60; ++k) holes.push_back({rng.next(), rng.next(), 0.01 + 0.04 * rng.next()});
  double c[3] = {0, 0, 0};
  return torus(3, 1, nu, nv, c, [holes](double u, double v) {
    for (const Hole& h : holes) {
      double du = std::remainder(u - h.u, 1.0) * 3, dv = std::remainder(v - h.v, 1.0);
      if (du * du + dv * dv < h.r * h.r) return false;
    }
    return true;
  });
}

// Several components: tori of different sizes (same density) plus small debris pieces.
TestMesh components(double density) {
  TestMesh m;
  const double sizes[5] = {1.0, 1.6, 0.7, 2.2, 1.2};
  for (int k = 0; k < 5; ++k) {
    double R = 2 * sizes[k], r = 0.6 * sizes[k];
    double area = 4 * M_PI * M_PI * R * r;
    uint32_t nv = std::max<uint32_t>(6, uint32_t(std::sqrt(area * density / 2 * r / R)));
    uint32_t nu = std::max<uint32_t>(6, uint32_t(area * density / 2 / nv));
    double c[3] = {k * 7.0, (k % 2) * 5.0, (k % 3) * 2.0};
    m.append(torus(R, r, nu, nv, c));
  }
  Lcg rng(11);
  for (int k = 0; k < 40; ++k) {  // debris: 4x4-quad flakes
    double o[3] = {rng.next() * 30, rng.next() * 10 - 3, rng.next() * 6 - 2};
    m.append(gridSurface(4, 4, false, false, [&](double u, double v, double* p) {
      p[0] = o[0] + 0.15 * u; p[1] = o[1] + 0.15 * v; p[2] = o[2] + 0.02 * u * v;
    }));
  }
  return m;
}

// A height field whose sampling density varies ~20x across it (close-up vs distant scan).
TestMesh warpedDensity(uint32_t nu, uint32_t nv) {
  return gridSurface(nu, nv, false, false, [](double u, double v, double* p) {
    double x = (std::exp(3 * u) - 1) / (std::exp(3.0) - 1);
    p[0] = 10 * x;
    p[1] = 6 * v;
    p[2] = 0.8 * std::sin(2 * p[0]) * std::cos(1.5 * p[1]);
  });
}


}  // namespace mt::test
