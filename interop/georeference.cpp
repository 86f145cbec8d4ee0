// Placement of a CRS model on the WGS84 globe: PROJ's exact transformation, a local affine fit
// (what and why: georeference.h).
#include "interop/georeference.h"

#include <proj.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <vector>

#include "base/error.h"

namespace mt::interop {

namespace {

// PROJ objects, released in reverse order of creation.
struct Proj {
  PJ_CONTEXT* ctx = nullptr;
  std::vector<PJ*> objects;
  Proj() : ctx(proj_context_create()) {
    if (!ctx) throw Error("PROJ: cannot create a context");
    // Transformations come from the installed database and grids only: never a download.
    proj_context_set_enable_network(ctx, 0);
    proj_log_level(ctx, PJ_LOG_NONE);
  }
  ~Proj() {
    for (auto it = objects.rbegin(); it != objects.rend(); ++it) proj_destroy(*it);
    proj_context_destroy(ctx);
  }
  Proj(const Proj&) = delete;
  Proj& operator=(const Proj&) = delete;

  PJ* keep(PJ* p, const std::string& what) {
    if (!p) {
      const int e = proj_context_errno(ctx);
      throw Error("CRS: " + what + (e ? std::string(": ") + proj_context_errno_string(ctx, e) : std::string()));
    }
    objects.push_back(p);
    return p;
  }
};

// The source CRS. A 2D CRS is not promoted: PROJ passes z through as the height above its datum's
// ellipsoid on the way to a 3D target (the test checks it against EPSG:4979).
PJ* sourceCrs(Proj& P, const std::string& crs) {
  PJ* src = P.keep(proj_create(P.ctx, crs.c_str()), "PROJ does not know the CRS \"" + crs + "\"");
  if (!proj_is_crs(src)) throw Error("CRS: \"" + crs + "\" is not a coordinate reference system");
  return src;
}

// source -> target, axes in east/north/up order on both sides.
PJ* transformation(Proj& P, PJ* src, const char* target, const std::string& crs) {
  PJ* dst = P.keep(proj_create(P.ctx, target), std::string("PROJ does not know ") + target);
  PJ* t = P.keep(proj_create_crs_to_crs_from_pj(P.ctx, src, dst, nullptr, nullptr),
                 "no transformation from \"" + crs + "\" to " + target);
  return P.keep(proj_normalize_for_visualization(P.ctx, t), "cannot normalize the axis order of \"" + crs + "\"");
}

void apply(Proj& P, PJ* t, const std::string& crs, const double p[3], double out[3]) {
  PJ_COORD c = proj_coord(p[0], p[1], p[2], 0);
  proj_errno_reset(t);
  PJ_COORD r = proj_trans(t, PJ_FWD, c);
  if (proj_errno(t) || !std::isfinite(r.xyz.x) || !std::isfinite(r.xyz.y) || !std::isfinite(r.xyz.z))
    throw Error("CRS \"" + crs + "\": PROJ cannot transform the point (" + std::to_string(p[0]) + ", " +
                std::to_string(p[1]) + ", " + std::to_string(p[2]) + ")" +
                (proj_errno(t) ? std::string(": ") + proj_context_errno_string(P.ctx, proj_errno(t)) : std::string()));
  out[0] = r.xyz.x, out[1] = r.xyz.y, out[2] = r.xyz.z;
}

}  // namespace

void applyPlacement(const GeoPlacement& g, const double p[3], double out[3]) {
  for (int r = 0; r < 3; ++r) out[r] = g.toEcef[12 + r] + g.toEcef[r] * p[0] + g.toEcef[4 + r] * p[1] + g.toEcef[8 + r] * p[2];
}

GeoPlacement placeOnGlobe(const std::string& crs, const double boxMin[3], const double boxMax[3]) {
  if (crs.empty()) throw Error("CRS: empty");
  Proj P;
  PJ* src = sourceCrs(P, crs);
  PJ* toEcef = transformation(P, src, "EPSG:4978", crs);
  PJ* toGeodetic = transformation(P, src, "EPSG:4979", crs);

  GeoPlacement g;
  if (const char* name = proj_get_name(src)) g.crsName = name;
  double half[3], largest = 0;
  for (int a = 0; a < 3; ++a) {
    if (!(boxMin[a] <= boxMax[a]) || !std::isfinite(boxMin[a]) || !std::isfinite(boxMax[a]))
      throw Error("CRS: the model's bounding box is empty or not finite");
    g.center[a] = 0.5 * (boxMin[a] + boxMax[a]);
    half[a] = 0.5 * (boxMax[a] - boxMin[a]);
    largest = std::max(largest, half[a]);
  }
  // The fit's lattice spans the box; a flat axis (a planar scan) still needs a step to measure the
  // map's derivative along it.
  double step[3];
  for (int a = 0; a < 3; ++a) step[a] = std::max(half[a], largest > 0 ? 1e-3 * largest : 1.0);

  double centerEcef[3], geodetic[3];
  apply(P, toEcef, crs, g.center, centerEcef);
  apply(P, toGeodetic, crs, g.center, geodetic);
  g.longitude = geodetic[0], g.latitude = geodetic[1], g.height = geodetic[2];

  // Least squares over the 3x3x3 lattice c + step * u, u in {-1, 0, 1}^3: the lattice is
  // symmetric, so the normal equations are diagonal: the translation is the mean, column a of the
  // linear part is sum(E_i u_ia) / sum(u_ia^2) / step_a. Differences from the centre's ECEF keep
  // the sums small (ECEF is ~6.4e6 m).
  double mean[3] = {0, 0, 0}, col[3][3] = {};
  for (int i = -1; i <= 1; ++i)
    for (int j = -1; j <= 1; ++j)
      for (int k = -1; k <= 1; ++k) {
        const int u[3] = {i, j, k};
        double p[3], e[3];
        for (int a = 0; a < 3; ++a) p[a] = g.center[a] + step[a] * u[a];
        apply(P, toEcef, crs, p, e);
        for (int r = 0; r < 3; ++r) {
          e[r] -= centerEcef[r];
          mean[r] += e[r] / 27;
          for (int a = 0; a < 3; ++a) col[a][r] += e[r] * u[a] / 18.0 / step[a];  // sum u^2 = 18
        }
      }
  // toEcef(p) = centerEcef + mean + J (p - center)
  for (int a = 0; a < 3; ++a)
    for (int r = 0; r < 3; ++r) g.toEcef[4 * a + r] = col[a][r];
  for (int r = 0; r < 3; ++r) {
    double t = centerEcef[r] + mean[r];
    for (int a = 0; a < 3; ++a) t -= col[a][r] * g.center[a];
    g.toEcef[12 + r] = t;
  }
  g.toEcef[15] = 1;

  // The local east, north, up at the centre, for the scale and the convergence.
  const double lon = g.longitude * M_PI / 180, lat = g.latitude * M_PI / 180;
  const double east[3] = {-std::sin(lon), std::cos(lon), 0};
  const double north[3] = {-std::sin(lat) * std::cos(lon), -std::sin(lat) * std::sin(lon), std::cos(lat)};
  auto dot = [](const double* x, const double* y) { return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]; };
  for (int a = 0; a < 3; ++a) g.unitScale[a] = std::sqrt(dot(col[a], col[a]));
  g.convergenceDegrees = std::atan2(dot(col[1], east), dot(col[1], north)) * 180 / M_PI;

  // The affine map against PROJ over a 9x9x9 lattice of the box (its corners included).
  for (int i = 0; i <= 8; ++i)
    for (int j = 0; j <= 8; ++j)
      for (int k = 0; k <= 8; ++k) {
        const int u[3] = {i, j, k};
        double p[3], exact[3], fit[3];
        for (int a = 0; a < 3; ++a) p[a] = boxMin[a] + (boxMax[a] - boxMin[a]) * u[a] / 8.0;
        apply(P, toEcef, crs, p, exact);
        applyPlacement(g, p, fit);
        g.maxError = std::max(g.maxError, std::hypot(fit[0] - exact[0], fit[1] - exact[1], fit[2] - exact[2]));
      }
  return g;
}

}  // namespace mt::interop
