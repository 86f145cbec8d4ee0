// Placing a model given in a coordinate reference system (a CRS string PROJ knows: "EPSG:32633",
// a WKT, a PROJJSON, a PROJ string) on the WGS84 globe: Earth-centred, Earth-fixed metres
// (EPSG:4978), the frame of 3D Tiles and CesiumJS.
//
// PROJ (Debian libproj-dev) does the exact transformation of any point; a tileset takes one 4x4
// root transform, so the model gets a local affine map fitted to PROJ over the model's box: it
// carries the grid's scale factor, the meridian convergence and the tilt of the local up, all
// taken from PROJ by converting a 3x3x3 lattice of the box's points (no formula of our own). What
// an affine map cannot follow is the curvature of the Earth (a point d from the centre lies
// d^2/(2R) below the tangent plane: 0.2 um at 1.5 m, 0.8 mm at 100 m, 8 cm at 1 km) and the
// change of the scale factor across the box; `maxError` measures it: the largest distance between
// the affine map and PROJ's exact answer over a 9x9x9 lattice of the box.
//
// Axes: the model's x, y are the CRS's easting and northing (longitude and latitude for a
// geographic CRS: PROJ's "normalized for visualization" order, whatever the CRS's own axis order),
// z the height. With a 2D CRS, PROJ takes z as the height above the CRS datum's ellipsoid; give a
// compound CRS (e.g. "EPSG:32633+3855", EGM2008 heights) when z is an orthometric height and PROJ
// has the geoid grid.
#pragma once

#include <string>

namespace mt::interop {

struct GeoPlacement {
  // Column-major 4x4 (the 3D Tiles `transform` layout): model coordinates -> ECEF metres.
  double toEcef[16] = {};
  // The model point the fit is centred on (the box's centre) and where PROJ puts it: degrees,
  // degrees, metres above the WGS84 ellipsoid.
  double center[3] = {0, 0, 0};
  double longitude = 0, latitude = 0, height = 0;
  // ECEF metres per model unit along the model's x, y, z (the grid scale factor's inverse on x, y
  // for a projected CRS in metres), and the angle of the model's +y east of true north, in the
  // local east/north plane (the meridian convergence, sign as PROJ's proj_factors).
  double unitScale[3] = {0, 0, 0};
  double convergenceDegrees = 0;
  // The largest distance in metres between the affine map and PROJ's transformation over the box.
  double maxError = 0;
  std::string crsName;  // PROJ's name of the CRS
};

// The placement of the box [boxMin, boxMax] (model coordinates in CRS). Throws mt::Error with PROJ's
// message when PROJ does not know the CRS or cannot transform the box's points to ECEF.
GeoPlacement placeOnGlobe(const std::string& crs, const double boxMin[3], const double boxMax[3]);

// toEcef applied to a point: the affine map.
void applyPlacement(const GeoPlacement& g, const double p[3], double out[3]);

}  // namespace mt::interop
