// A patch's own parametrization (levels above the finest): charts grown over edge-adjacent
// triangles while their normals stay within a cone around the chart's first triangle's normal,
// each projected orthographically on the plane across that normal. A simplified patch is a few
// thousand triangles of a smooth-ish surface, so a handful of charts covers it with little
// stretch (at most 1/cos(maxAngle) along one direction); the input's own charts, however
// fragmented, play no part (a fragmented parametrization never stops the simplification).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace mt::tex {

struct Charts {
  uint32_t count = 0;
  std::vector<uint32_t> chartOf;  // per triangle
  std::vector<double> corner2D;   // 6 per triangle: the corners in their chart's plane, world units
};

// Deterministic: charts are seeded in triangle order, grown breadth first.
Charts makeCharts(const double* positions, size_t vertexCount, const uint32_t* triangles, size_t triangleCount,
                  double maxAngleDegrees = 60);

}  // namespace mt::tex
