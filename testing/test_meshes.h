// testing/test_meshes.h: small procedural scan-like meshes held in memory (grid surfaces, bumpy
// tori with and without holes, a closed blob, several components with debris, a height field of
// varying density) for the V-partition tests and benchmark. Deterministic.
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

namespace mt::test {

struct TestMesh {
  std::vector<double> positions;   // 3 per vertex
  std::vector<uint32_t> triangles; // 3 per triangle
  uint32_t vertexCount() const { return uint32_t(positions.size() / 3); }
  uint64_t triangleCount() const { return triangles.size() / 3; }
  void append(const TestMesh& m) {
    uint32_t base = vertexCount();
    positions.insert(positions.end(), m.positions.begin(), m.positions.end());
    for (uint32_t v : m.triangles) triangles.push_back(base + v);
  }
};


// A (u,v) grid surface of nu x nv quads; wrapU/wrapV close it; keep(u,v) drops quads (holes).
TestMesh gridSurface(uint32_t nu, uint32_t nv, bool wrapU, bool wrapV,
                     const std::function<void(double, double, double*)>& at,
                     const std::function<bool(double, double)>& keep = {});

// A bumpy torus (major radius R, minor r) of nu x nv quads around `centre`.
TestMesh torus(double R, double r, uint32_t nu, uint32_t nv, const double centre[3],
               const std::function<bool(double, double)>& keep = {});

// Closed: a displaced cube-sphere (6 faces of n x n quads, welded along the cube edges).
TestMesh closedBlob(uint32_t n);

// Deterministic pseudo-random numbers in [0,1).
struct Lcg {
  uint64_t s;
  explicit Lcg(uint64_t seed) : s(seed * 2862933555777941757ull + 3037000493ull) {}
  double next() {
    s = s * 6364136223846793005ull + 1442695040888963407ull;
    return double(s >> 11) * (1.0 / 9007199254740992.0);
  }
};


// A torus with ~60 round holes of varied size (a scan with missing regions).
TestMesh holedTorus(uint32_t nu, uint32_t nv);

// Several components: tori of different sizes (same density) plus small debris pieces.
TestMesh components(double density);

// A height field whose sampling density varies ~20x across it (close-up vs distant scan).
TestMesh warpedDensity(uint32_t nu, uint32_t nv);

}  // namespace mt::test
