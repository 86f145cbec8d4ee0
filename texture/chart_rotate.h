// Charts turned to their minimum-area bounding rectangle before packing: a chart is packed as its
// axis-aligned box, so a chart lying diagonally in its plane (the projection's axes are arbitrary,
// charts.cpp) wastes up to half its rectangle. The minimum-area enclosing rectangle of a point set
// has a side collinear with an edge of its convex hull (H. Freeman, R. Shapira, "Determining the
// minimum-area encasing rectangle for an arbitrary closed curve", CACM 18(7), 1975), so trying the
// hull's edges finds it (O(h^2) here: a chart's hull has few vertices; rotating calipers would
// make it O(h)).
#pragma once

#include <cstddef>

#include "texture/charts.h"

namespace mt::tex {

struct BoxFrame {
  double c = 1, s = 0;  // the rectangle's first axis (cos, sin): a point (x, y) goes to (x c + y s, -x s + y c)
  double area = 0;      // the rectangle's area in that frame
};

// The frame of the minimum-area rectangle around points (2 per point); the identity frame unless a
// hull edge's frame has a smaller area (so the result's area is never larger than the unrotated
// box's).
BoxFrame minAreaBox(const double* xy, size_t pointCount);

// Turns each chart's corners (charts.corner2D) into its minimum-area frame. Deterministic.
void rotateChartsToMinAreaBoxes(Charts& charts);

}  // namespace mt::tex
