// Georeferenced scans: coordinates far from the origin (UTM-like metres) with centimetre detail.
// Whatever the input format, the finest cut of the build must hold every input triangle, each
// vertex within the grid step of its input position: no precision is lost on the way (text is
// parsed and stored as double; the MT grid is relative to the model's box). And the placement of a
// model in a CRS on the WGS84 globe (interop/georeference.h) against PROJ's exact answers and the
// ellipsoid's closed-form geodetic -> ECEF formula.
#include <gtest/gtest.h>
#include <proj.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "base/error.h"
#include "interop/georeference.h"
#include "mtfile/mt_file.h"
#include "patchstore/io/ply_writer.h"
#include "patchstore/io/mesh_reader.h"
#include "tests/test_support.h"

namespace mt {
namespace {

using test::runTool;
using test::TempDir;

// An n x n grid at `spacing`, its corner at (x0, y0, z0), with a small height pattern.
struct Grid {
  int n;
  double x0, y0, z0, spacing;
  double x(int i) const { return x0 + spacing * i; }
  double y(int j) const { return y0 + spacing * j; }
  double z(int i, int j) const { return z0 + spacing * 0.1 * ((i * 7 + j * 3) % 5); }
  size_t triangles() const { return size_t(2) * (n - 1) * (n - 1); }
  template <class Fn>
  void faces(Fn fn) const {
    for (int j = 0; j + 1 < n; ++j)
      for (int i = 0; i + 1 < n; ++i) {
        int a = j * n + i, b = a + 1, c = a + n, d = c + 1;
        fn(a, b, d);
        fn(a, d, c);
      }
  }
};

void writeText(const Grid& g, const std::string& path, const std::string& format) {
  std::ostringstream o;
  o.precision(17);
  const size_t nv = size_t(g.n) * g.n;
  if (format == "off") o << "OFF\n" << nv << ' ' << g.triangles() << " 0\n";
  if (format == "ply")
    o << "ply\nformat ascii 1.0\nelement vertex " << nv << "\nproperty float x\nproperty float y\nproperty float z\n"
      << "element face " << g.triangles() << "\nproperty list uchar int vertex_indices\nend_header\n";
  for (int j = 0; j < g.n; ++j)
    for (int i = 0; i < g.n; ++i) o << (format == "obj" ? "v " : "") << g.x(i) << ' ' << g.y(j) << ' ' << g.z(i, j) << '\n';
  g.faces([&](int a, int b, int c) {
    if (format == "obj") o << "f " << a + 1 << ' ' << b + 1 << ' ' << c + 1 << '\n';
    else o << "3 " << a << ' ' << b << ' ' << c << '\n';
  });
  test::writeFile(path, o.str());
}

void writeBinary(const Grid& g, const std::string& path, bool doublePrecision) {
  PlyWriteOptions options;
  options.doublePrecision = doublePrecision;
  PlyWriter w(path, options);
  for (int j = 0; j < g.n; ++j)
    for (int i = 0; i < g.n; ++i) {
      double p[3] = {g.x(i), g.y(j), g.z(i, j)};
      if (!doublePrecision)
        for (double& c : p) c = double(float(c));
      w.addVertex(p);
    }
  g.faces([&](int a, int b, int c) { w.addTriangle(uint32_t(a), uint32_t(b), uint32_t(c)); });
  w.finish();
}

struct Collect : MeshSink {
  std::vector<double> positions;
  std::vector<uint32_t> tris;
  void vertices(const InputVertex* v, size_t n, uint64_t) override {
    for (size_t i = 0; i < n; ++i) positions.insert(positions.end(), v[i].p, v[i].p + 3);
  }
  void triangles(const uint32_t* idx, size_t n) override { tris.insert(tris.end(), idx, idx + 3 * n); }
};

// Builds, verifies and extracts the finest cut; every triangle must be there and every vertex
// within the grid step of the grid point it stands for.
void expectFinestCutKeepsEverything(const Grid& g, const std::string& input, bool floatInput) {
  const std::string mt = input + ".mt", cut = input + ".cut.ply";
  auto b = runTool("mtbuild", input + " -o " + mt + " -q");
  ASSERT_EQ(b.exitCode, 0) << b.output;
  auto v = runTool("mtverify", mt);
  EXPECT_EQ(v.exitCode, 0) << v.output;
  auto x = runTool("mtextract", mt + " --error 0 -o " + cut);
  ASSERT_EQ(x.exitCode, 0) << x.output;
  EXPECT_EQ(x.output.find("degenerate"), std::string::npos) << x.output;
  auto reader = MtFileReader::open(mt);
  const double step = reader->header().gridStep;
  EXPECT_LT(step, g.spacing / 2) << input;
  Collect c;
  openMesh(cut)->read(c);
  EXPECT_EQ(c.tris.size() / 3, g.triangles()) << input;
  EXPECT_EQ(c.positions.size() / 3, size_t(g.n) * g.n) << input;
  double worst = 0;
  for (size_t k = 0; k < c.positions.size(); k += 3) {
    const int i = int(std::lround((c.positions[k] - g.x0) / g.spacing));
    const int j = int(std::lround((c.positions[k + 1] - g.y0) / g.spacing));
    double p[3] = {g.x(i), g.y(j), g.z(i, j)};
    if (floatInput)
      for (double& q : p) q = double(float(q));
    for (int a = 0; a < 3; ++a) worst = std::max(worst, std::abs(c.positions[k + a] - p[a]));
  }
  EXPECT_LE(worst, step) << input << ": a vertex moved by " << worst << ", the grid step is " << step;
}

TEST(Georeferenced, CentimetreGridAtUtmCoordinatesKeepsEveryTriangleInEveryFormat) {
  TempDir tmp;
  // 1 cm at (6 000 000, 4 000 000): float32 resolution there is 0.5 m.
  const Grid g{200, 6000000.0, 4000000.0, 123.25, 0.01};
  for (const std::string format : {"off", "obj", "ply"}) {
    const std::string in = tmp.file("utm." + format);
    writeText(g, in, format);
    expectFinestCutKeepsEverything(g, in, false);
  }
  writeBinary(g, tmp.file("utm-double.ply"), true);
  expectFinestCutKeepsEverything(g, tmp.file("utm-double.ply"), false);
}

TEST(Georeferenced, FloatPlyAtUtmCoordinatesKeepsWhatFloatCanHold) {
  // A float32 binary PLY cannot hold centimetres at 4e6 m, but a 0.5 m grid is exact there: all of
  // its triangles must come through.
  TempDir tmp;
  const Grid g{150, 500000.0, 4000000.0, 80.0, 0.5};
  writeBinary(g, tmp.file("utm-float.ply"), false);
  expectFinestCutKeepsEverything(g, tmp.file("utm-float.ply"), true);
  // Nothing was lost, so nothing is said, even though float32 is coarser than the grid there.
  auto b = runTool("mtbuild", tmp.file("utm-float.ply") + " -o " + tmp.file("again.mt") + " -q");
  ASSERT_EQ(b.exitCode, 0) << b.output;
  EXPECT_EQ(b.output.find("warning"), std::string::npos) << b.output;
}

TEST(Georeferenced, FloatPlyThatLostTheCentimetresIsReportedNotSilentlyWelded) {
  // The 1 cm grid at (6e6, 4e6) written as float32: its 40000 points fall on ~100 float positions
  // 0.5 m apart. The build goes on with what the file holds, but says why most triangles vanished
  // and what to do, with --quiet too.
  TempDir tmp;
  const Grid g{200, 6000000.0, 4000000.0, 123.25, 0.01};
  writeBinary(g, tmp.file("cm-float.ply"), false);
  auto b = runTool("mtbuild", tmp.file("cm-float.ply") + " -o " + tmp.file("cm.mt") + " -q");
  ASSERT_EQ(b.exitCode, 0) << b.output;
  EXPECT_NE(b.output.find("warning: " + tmp.file("cm-float.ply") + ": float32 positions are only 0.5 apart"),
            std::string::npos)
      << b.output;
  EXPECT_NE(b.output.find("write the positions as double"), std::string::npos) << b.output;
  // The same grid as double keeps its centimetres: no warning.
  writeBinary(g, tmp.file("cm-double.ply"), true);
  auto d = runTool("mtbuild", tmp.file("cm-double.ply") + " -o " + tmp.file("cm-double.mt") + " -q");
  ASSERT_EQ(d.exitCode, 0) << d.output;
  EXPECT_EQ(d.output.find("warning"), std::string::npos) << d.output;
}

TEST(Georeferenced, MtinfoPrintsTheHeaderDoublesExactly) {
  // At 4e6 m, 9 significant digits are centimetres: the origin, step and box must read back to
  // the header's doubles bit for bit, in the text and in --json.
  TempDir tmp;
  const Grid g{40, 500000.123456, 4000000.987654, 100.001, 0.003};
  writeBinary(g, tmp.file("utm.ply"), true);
  ASSERT_EQ(runTool("mtbuild", tmp.file("utm.ply") + " -o " + tmp.file("utm.mt") + " -q").exitCode, 0);
  const auto reader = MtFileReader::open(tmp.file("utm.mt"));
  const auto& h = reader->header();
  const auto info = runTool("mtinfo", tmp.file("utm.mt") + " --json");
  ASSERT_EQ(info.exitCode, 0) << info.output;
  const nlohmann::json j = nlohmann::json::parse(info.output);
  for (int a = 0; a < 3; ++a) {
    EXPECT_EQ(j["boundsMin"][a].get<double>(), h.boundsMin[a]) << a;
    EXPECT_EQ(j["boundsMax"][a].get<double>(), h.boundsMax[a]) << a;
    EXPECT_EQ(j["gridOrigin"][a].get<double>(), h.gridOrigin[a]) << a;
  }
  EXPECT_EQ(j["gridStep"].get<double>(), h.gridStep);
  const auto text = runTool("mtinfo", tmp.file("utm.mt"));
  const std::string line = text.output.substr(text.output.find("bounding box"));
  double b[6];
  ASSERT_EQ(std::sscanf(line.c_str(), "bounding box (%lf, %lf, %lf) - (%lf, %lf, %lf)", b, b + 1, b + 2, b + 3, b + 4, b + 5), 6) << line;
  for (int a = 0; a < 3; ++a) {
    EXPECT_EQ(b[a], h.boundsMin[a]);
    EXPECT_EQ(b[3 + a], h.boundsMax[a]);
  }
}

// ---- placement on the globe ----------------------------------------------------------------------

// WGS84 geodetic (degrees, degrees, metres above the ellipsoid) -> ECEF metres: the closed form.
void geodeticToEcef(double lonDeg, double latDeg, double h, double out[3]) {
  const double a = 6378137.0, f = 1 / 298.257223563, e2 = f * (2 - f);
  const double lon = lonDeg * M_PI / 180, lat = latDeg * M_PI / 180;
  const double n = a / std::sqrt(1 - e2 * std::sin(lat) * std::sin(lat));
  out[0] = (n + h) * std::cos(lat) * std::cos(lon);
  out[1] = (n + h) * std::cos(lat) * std::sin(lon);
  out[2] = (n * (1 - e2) + h) * std::sin(lat);
}

// PROJ's own answers for UTM zone 33N (WGS84): the point's geodetic position, and the projection's
// scale factor and meridian convergence there (proj_factors).
struct Utm33 {
  PJ_CONTEXT* ctx = proj_context_create();
  PJ* toGeodetic = nullptr;
  PJ* crs = nullptr;
  Utm33() {
    proj_context_set_enable_network(ctx, 0);
    PJ* t = proj_create_crs_to_crs(ctx, "EPSG:32633", "EPSG:4979", nullptr);
    toGeodetic = proj_normalize_for_visualization(ctx, t);
    proj_destroy(t);
    crs = proj_create(ctx, "EPSG:32633");
  }
  ~Utm33() {
    proj_destroy(crs);
    proj_destroy(toGeodetic);
    proj_context_destroy(ctx);
  }
  // -> lon, lat (degrees), h
  void geodetic(const double p[3], double out[3]) const {
    PJ_COORD c = proj_trans(toGeodetic, PJ_FWD, proj_coord(p[0], p[1], p[2], 0));
    out[0] = c.xyz.x, out[1] = c.xyz.y, out[2] = c.xyz.z;
  }
  void ecef(const double p[3], double out[3]) const {
    double g[3];
    geodetic(p, g);
    geodeticToEcef(g[0], g[1], g[2], out);
  }
  PJ_FACTORS factors(double lonDeg, double latDeg) const {
    return proj_factors(crs, proj_coord(proj_torad(lonDeg), proj_torad(latDeg), 0, 0));
  }
};

double distance(const double a[3], const double b[3]) { return std::hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]); }

TEST(Georeference, AUtmModelLandsWhereProjAndTheEllipsoidPutIt) {
  const Utm33 utm;
  // A 3 m scan on zone 33's central meridian (15 E) at 100 m above the ellipsoid.
  const double lo[3] = {499998.5, 3999998.5, 99.5}, hi[3] = {500001.5, 4000001.5, 100.5};
  const interop::GeoPlacement g = interop::placeOnGlobe("EPSG:32633", lo, hi);
  EXPECT_NE(g.crsName.find("UTM zone 33N"), std::string::npos) << g.crsName;
  double geo[3];
  utm.geodetic(g.center, geo);
  EXPECT_NEAR(g.longitude, 15.0, 1e-9);  // on the central meridian
  EXPECT_NEAR(g.latitude, geo[1], 1e-12);
  EXPECT_NEAR(g.latitude, 36.1447, 1e-4);
  EXPECT_NEAR(g.height, 100.0, 1e-6);  // z is the height above the ellipsoid
  // Every corner and the centre where the closed form puts PROJ's geodetic position, to 1 um.
  for (int c = 0; c < 9; ++c) {
    double p[3], fit[3], exact[3];
    for (int a = 0; a < 3; ++a) p[a] = c == 8 ? g.center[a] : ((c >> a) & 1 ? hi[a] : lo[a]);
    interop::applyPlacement(g, p, fit);
    utm.ecef(p, exact);
    EXPECT_LT(distance(fit, exact), 1e-6) << "corner " << c;
  }
  EXPECT_LT(g.maxError, 1e-6);
  // On the central meridian: grid north is true north, the scale factor is k0 = 0.9996 (so a
  // grid metre is 1/0.9996 true metres, 1.6e-5 more at 100 m up), z is the ellipsoid's normal.
  EXPECT_NEAR(g.convergenceDegrees, 0.0, 1e-6);
  const double k = utm.factors(15.0, g.latitude).meridional_scale;
  EXPECT_NEAR(k, 0.9996, 1e-9);
  EXPECT_NEAR(g.unitScale[0], (1 / k) * (1 + 100 / 6.37e6), 1e-6);
  EXPECT_NEAR(g.unitScale[1], g.unitScale[0], 1e-6);
  EXPECT_NEAR(g.unitScale[2], 1.0, 1e-9);
  const double lat = g.latitude * M_PI / 180, lon = g.longitude * M_PI / 180;
  const double up[3] = {std::cos(lat) * std::cos(lon), std::cos(lat) * std::sin(lon), std::sin(lat)};
  EXPECT_GT(g.toEcef[8] * up[0] + g.toEcef[9] * up[1] + g.toEcef[10] * up[2], 1 - 1e-12);
}

TEST(Georeference, OffTheCentralMeridianTheGridTurnsAndScalesAsProjSays) {
  const Utm33 utm;
  // 150 km east of the central meridian: convergence about 1 degree, scale factor 1.00022.
  const double lo[3] = {649990, 3999990, 0}, hi[3] = {650010, 4000010, 20};
  const interop::GeoPlacement g = interop::placeOnGlobe("EPSG:32633", lo, hi);
  const PJ_FACTORS f = utm.factors(g.longitude, g.latitude);
  EXPECT_GT(std::abs(g.convergenceDegrees), 0.5);
  EXPECT_NEAR(g.convergenceDegrees, proj_todeg(f.meridian_convergence), 1e-6);
  EXPECT_NEAR(g.unitScale[0], (1 / f.meridional_scale) * (1 + g.height / 6.37e6), 2e-6);
  EXPECT_NEAR(g.unitScale[1], g.unitScale[0], 1e-6);  // conformal
}

TEST(Georeference, TheStatedErrorBoundsTheAffineMapAndGrowsWithTheBox) {
  const Utm33 utm;
  double previous = 0;
  for (double halfWidth : {1.5, 50.0, 500.0, 5000.0}) {
    const double lo[3] = {520000 - halfWidth, 4000000 - halfWidth, 0}, hi[3] = {520000 + halfWidth, 4000000 + halfWidth, 50};
    const interop::GeoPlacement g = interop::placeOnGlobe("EPSG:32633", lo, hi);
    // What an affine map misses is the Earth's curvature: a corner sqrt(2) * halfWidth away lies
    // (2 halfWidth^2)/(2R) below the tangent plane (a least-squares fit splits that), and a
    // horizontal metre at height z is (R + z)/R metres (the bilinear x z / R over the 50 m).
    const double R = 6.37e6, sag = halfWidth * halfWidth / R, shear = halfWidth * 25 / R;
    EXPECT_GT(g.maxError, 0.1 * (sag + shear)) << halfWidth;
    EXPECT_LT(g.maxError, 2 * (sag + shear) + 1e-7) << halfWidth;
    EXPECT_GT(g.maxError, previous);
    previous = g.maxError;
    // Random points of the box: the affine map is within the stated error of PROJ (+ 10%: the
    // error is sampled on a 9x9x9 lattice).
    uint64_t s = 12345;
    auto uniform = [&] { return double((s = s * 6364136223846793005ull + 1442695040888963407ull) >> 11) / 9007199254740992.0; };
    for (int i = 0; i < 200; ++i) {
      double p[3], fit[3], exact[3];
      for (int a = 0; a < 3; ++a) p[a] = lo[a] + (hi[a] - lo[a]) * uniform();
      interop::applyPlacement(g, p, fit);
      utm.ecef(p, exact);
      EXPECT_LE(distance(fit, exact), 1.1 * g.maxError + 1e-9) << halfWidth;
    }
  }
}

TEST(Georeference, AnUnknownCrsIsRefusedWithPROJsReason) {
  const double lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1};
  try {
    interop::placeOnGlobe("EPSG:999999", lo, hi);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("EPSG:999999"), std::string::npos) << e.what();
  }
  EXPECT_THROW(interop::placeOnGlobe("not a crs", lo, hi), Error);
  // A geographic CRS is a CRS too: x, y are longitude and latitude in degrees.
  const double geoLo[3] = {15.0, 36.0, 0}, geoHi[3] = {15.0001, 36.0001, 10};
  const interop::GeoPlacement g = interop::placeOnGlobe("EPSG:4326", geoLo, geoHi);
  EXPECT_NEAR(g.longitude, 15.00005, 1e-9);
  EXPECT_NEAR(g.latitude, 36.00005, 1e-9);
}

}  // namespace
}  // namespace mt
