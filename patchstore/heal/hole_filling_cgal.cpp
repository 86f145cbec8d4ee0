// All CGAL code of the healing passes, in this one translation unit: CGAL's fairing (Eigen sparse
// solvers) costs ~30 s and 1.7 GB to compile, so it is built once, in its own small library.
//
// Hole filling is CGAL's triangulate_refine_and_fair_hole: P. Liepa, "Filling holes in meshes"
// (SGP 2003): a minimum-weight triangulation of the loop (dihedral angle, then area), refined so
// the patch's density matches the surroundings, then faired (minimizing a discrete bi-Laplacian
// energy with the loop and its 1-ring fixed), so the patch blends with the surface around it.
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/orient_polygon_soup.h>
#include <CGAL/Polygon_mesh_processing/triangulate_hole.h>
#include <CGAL/Surface_mesh.h>

#include <array>
#include <iterator>
#include <map>
#include <vector>

#include "patchstore/heal/heal.h"

namespace mt::heal {

namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;
using Mesh = CGAL::Surface_mesh<Point>;
using VertexIndex = Mesh::Vertex_index;
using HalfedgeIndex = Mesh::Halfedge_index;
using FaceIndex = Mesh::Face_index;
namespace PMP = CGAL::Polygon_mesh_processing;

// CGAL's default random generator is seeded from the clock, and the Delaunay triangulation that
// triangulate_hole builds spatially sorts its points with it: reseed before every hole, so the
// same store and options always give the same patch (the project's determinism rule).
void reseed() { CGAL::get_default_random() = CGAL::Random(0); }

}  // namespace

HoleFill fillHoleBand(const HoleBand& band) {
  reseed();
  HoleFill out;
  const size_t n = band.positions.size() / 3;
  std::vector<Point> points;
  for (size_t i = 0; i < n; ++i) points.emplace_back(band.positions[3 * i], band.positions[3 * i + 1], band.positions[3 * i + 2]);
  std::vector<std::array<size_t, 3>> polygons;
  for (size_t i = 0; i < band.triangles.size(); i += 3)
    polygons.push_back({band.triangles[i], band.triangles[i + 1], band.triangles[i + 2]});
  // The band's outer rim can touch itself (a vertex reached from two loop vertices through
  // separate fans): orient_polygon_soup duplicates such points so the band is a valid halfedge
  // mesh. Loop vertices have their whole umbrella in the band, so they keep their index unless
  // the input itself is non-manifold there (then the loop check below refuses the hole).
  PMP::orient_polygon_soup(points, polygons);
  Mesh mesh;
  for (const Point& p : points) mesh.add_vertex(p);
  for (const auto& f : polygons)
    if (mesh.add_face(VertexIndex(uint32_t(f[0])), VertexIndex(uint32_t(f[1])), VertexIndex(uint32_t(f[2]))) == Mesh::null_face())
      return out;
  const size_t m = band.loop.size();
  if (m < 3) return out;
  VertexIndex a(band.loop[0]), b(band.loop[1]);
  // Loop edge a -> b belongs to a band triangle, so the hole's border halfedge runs b -> a;
  // if the soup was reoriented it runs a -> b and the new faces are flipped back below.
  auto [hba, found1] = CGAL::halfedge(b, a, mesh);
  auto [hab, found2] = CGAL::halfedge(a, b, mesh);
  HalfedgeIndex h;
  bool flipped = false;
  if (found1 && mesh.is_border(hba)) {
    h = hba;
  } else if (found2 && mesh.is_border(hab)) {
    h = hab;
    flipped = true;
  } else {
    return out;
  }
  // The border cycle must be exactly the loop.
  size_t length = 0;
  std::vector<uint8_t> isLoop(points.size(), 0);
  for (uint32_t v : band.loop) isLoop[v] = 1;
  HalfedgeIndex g = h;
  do {
    if (!isLoop[size_t(mesh.target(g))] || ++length > m) return out;
    g = mesh.next(g);
  } while (g != h);
  if (length != m) return out;

  std::vector<FaceIndex> faces;
  std::vector<VertexIndex> added;
  auto result = PMP::triangulate_refine_and_fair_hole(mesh, h, std::back_inserter(faces), std::back_inserter(added));
  out.faired = std::get<0>(result);
  std::map<uint32_t, uint32_t> newIndex;
  for (VertexIndex v : added) {
    newIndex[uint32_t(v)] = uint32_t(n + newIndex.size());
    const Point& p = mesh.point(v);
    out.newPositions.insert(out.newPositions.end(), {p.x(), p.y(), p.z()});
  }
  for (FaceIndex f : faces) {
    std::array<uint32_t, 3> tri;
    int c = 0;
    for (VertexIndex v : CGAL::vertices_around_face(mesh.halfedge(f), mesh)) {
      if (c == 3) return HoleFill{};
      uint32_t id = uint32_t(v);
      if (id < n) tri[c++] = id;
      else if (newIndex.count(id)) tri[c++] = newIndex[id];
      else return HoleFill{};  // a point orient_polygon_soup duplicated: cannot be mapped back
    }
    if (c != 3) return HoleFill{};
    if (flipped) std::swap(tri[1], tri[2]);
    out.newTriangles.insert(out.newTriangles.end(), tri.begin(), tri.end());
  }
  out.ok = true;
  return out;
}

ReferenceFill referenceFillHoles(const std::vector<double>& positions, const std::vector<uint32_t>& triangles,
                                 uint32_t maxEdges) {
  ReferenceFill out;
  Mesh mesh;
  for (size_t i = 0; i < positions.size(); i += 3) mesh.add_vertex(Point(positions[i], positions[i + 1], positions[i + 2]));
  for (size_t i = 0; i < triangles.size(); i += 3)
    if (mesh.add_face(VertexIndex(triangles[i]), VertexIndex(triangles[i + 1]), VertexIndex(triangles[i + 2])) == Mesh::null_face())
      return out;
  std::vector<HalfedgeIndex> toFill;
  std::vector<uint8_t> seen(mesh.number_of_halfedges(), 0);
  for (HalfedgeIndex h : mesh.halfedges()) {
    if (!mesh.is_border(h) || seen[size_t(h)]) continue;
    size_t length = 0;
    HalfedgeIndex g = h;
    do {
      seen[size_t(g)] = 1;
      ++length;
      g = mesh.next(g);
    } while (g != h);
    ++out.holes;
    if (length <= maxEdges) toFill.push_back(h);
    else ++out.larger;
  }
  for (HalfedgeIndex h : toFill) {
    std::vector<FaceIndex> faces;
    std::vector<VertexIndex> added;
    reseed();
    PMP::triangulate_refine_and_fair_hole(mesh, h, std::back_inserter(faces), std::back_inserter(added));
    ++out.filled;
  }
  for (VertexIndex v : mesh.vertices()) {
    const Point& p = mesh.point(v);
    out.positions.insert(out.positions.end(), {p.x(), p.y(), p.z()});
  }
  for (FaceIndex f : mesh.faces())
    for (VertexIndex v : CGAL::vertices_around_face(mesh.halfedge(f), mesh)) out.triangles.push_back(uint32_t(v));
  out.ok = true;
  return out;
}

}  // namespace mt::heal
