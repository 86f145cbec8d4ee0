// mtrender/closed_surface.h: when normal-cone (back-face) culling cannot change the image.
//
// The renderer lights both sides of every triangle (scans are open surfaces: their inside shows
// through holes and past their rims), so a patch whose triangles all face away from the eye is
// still seen unless something nearer hides it. Culling it by its normal cone (Derzapf et al. 4.2,
// BMT 5.1) is therefore sound only where back faces are hidden by construction: on a closed,
// consistently and outward oriented surface (every directed edge used once, its reverse once,
// positive volume) seen from OUTSIDE the solid it bounds, a ray from the eye enters the solid
// through a front face before it can reach a back face. Anywhere else (a scan with holes or an
// open rim, a non-manifold or inside-out mesh, an eye inside the solid) the cones are not used.
//
// What is known without reading the whole model: the coarsest cut (the arcs into the sink, a few
// thousand triangles, read once at open). Its borders are the input's borders (mtfile/mt_cut.h's
// crack-free rule: a boundary edge of any cut runs along a real boundary of the input, and the
// builder's simplifier keeps a hole's rim on the rim under the link condition, so a hole never
// closes), so the finest cut is closed exactly when the coarsest is. The eye test uses the same
// coarse mesh: outside when a ray from the eye crosses it an even number of times and the eye is
// farther from it than the coarsest cut's largest node error (the fine surface lies within that
// distance of the coarse one, so the two solids agree about such an eye).
#pragma once

#include <cstdint>
#include <vector>

#include "mtfile/mt_file.h"

namespace mt::render {

class ClosedSurface {
 public:
  ClosedSurface() = default;
  // Reads and welds the file's coarsest cut. A damaged coarsest patch leaves the file "not closed"
  // (no cone culling): the renderer reports that patch itself when it loads it.
  static ClosedSurface ofFile(const MtFileReader& reader);
  // From a welded mesh (positions 3 per vertex, triangles 3 per triangle) and the margin (tests).
  static ClosedSurface ofMesh(std::vector<double> positions, std::vector<uint32_t> triangles, double margin);

  // Every directed edge used once and its reverse once, and the enclosed volume positive.
  bool closed() const { return closed_; }
  // Cone culling is sound for this eye: the surface is closed and the eye is outside its solid,
  // farther than the margin from it.
  bool eyeOutside(const double eye[3]) const;
  double margin() const { return margin_; }
  uint32_t triangleCount() const { return uint32_t(tri_.size() / 3); }

 private:
  bool closed_ = false;
  std::vector<double> pos_;
  std::vector<uint32_t> tri_;
  double margin_ = 0;
  double boxMin_[3] = {0, 0, 0}, boxMax_[3] = {0, 0, 0};
};

}  // namespace mt::render
