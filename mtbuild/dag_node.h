// The geometry of one DAG node (BMT sections 3.1, 5.1): its bounding sphere, grown to contain
// its predecessors', and the normal cone of its fragment. Plain data, no state.
#pragma once

#include <cstdint>
#include <vector>

namespace mt {

struct Sphere {
  double c[3] = {0, 0, 0};
  double r = 0;
};

// Smallest-enough sphere around points (3 doubles each): the box centre and the farthest point.
Sphere sphereOf(const std::vector<double>& positions);

// Grows s (keeping its centre) to contain t.
void enclose(Sphere& s, const Sphere& t);

// Whether s contains t (up to a relative rounding slack of the distance computation).
bool contains(const Sphere& s, const Sphere& t);

// Normal cone of a fragment's triangles: the mean normal and the cosine of the widest deviation;
// cutoff -1 when the triangles face every way (no back-face culling possible).
void normalCone(const std::vector<double>& positions, const std::vector<uint32_t>& triangles, float axis[3],
                float& cutoff);

}  // namespace mt
