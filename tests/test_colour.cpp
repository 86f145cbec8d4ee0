// Per-vertex colour from input to screen: Hoppe's attribute quadric (mtbuild/attribute_quadric.h),
// the colour-aware quadric simplifier keeping colour edges, the measured colour error
// (mtbuild/color_error.h) stored per node and monotone, files of the previous format version still
// read, mtgen's sharp colour field and --paint, and mtrender --color against images of the
// full-resolution model. (The readers' colour syntaxes are in test_readers.cpp.)
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <xxhash.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <set>
#include <string>
#include <vector>

#include "mtbuild/attribute_quadric.h"
#include "mtbuild/color_error.h"
#include "mtbuild/quadric_simplify.h"
#include "mtbuild/simplify_region.h"
#include "mtfile/mt_file.h"
#include "mtrender/image.h"
#include "patchstore/io/mesh_reader.h"
#include "tests/test_support.h"

using ::testing::HasSubstr;
using mt::test::runTool;
using mt::test::TempDir;

namespace {

// A flat n x n grid of unit cells (z = 0) with two colours split at column `edge`: red left,
// blue right (the triangles across the split interpolate). Border vertices optionally locked.
struct Grid {
  std::vector<double> positions;
  std::vector<uint32_t> triangles;
  std::vector<uint8_t> colors, locked;
  size_t vertexCount() const { return positions.size() / 3; }
  size_t triangleCount() const { return triangles.size() / 3; }
};
Grid colourEdgeGrid(int n, int edge) {
  Grid g;
  for (int y = 0; y <= n; ++y)
    for (int x = 0; x <= n; ++x) {
      g.positions.insert(g.positions.end(), {double(x), double(y), 0.0});
      const uint8_t red[4] = {220, 40, 30, 255}, blue[4] = {30, 60, 210, 255};
      const uint8_t* c = x < edge ? red : blue;
      g.colors.insert(g.colors.end(), c, c + 4);
      g.locked.push_back(x == 0 || y == 0 || x == n || y == n);
    }
  auto id = [n](int x, int y) { return uint32_t(y * (n + 1) + x); };
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      g.triangles.insert(g.triangles.end(), {id(x, y), id(x + 1, y), id(x + 1, y + 1)});
      g.triangles.insert(g.triangles.end(), {id(x, y), id(x + 1, y + 1), id(x, y + 1)});
    }
  return g;
}

// The colour error of a quadric simplification of `g` to `target` triangles at colorScale.
struct QuadricResult {
  std::vector<uint32_t> triangles;
  std::vector<double> positions;
  std::vector<uint8_t> colors;
  double colorError = 0;
};
QuadricResult simplifyGrid(const Grid& g, size_t targetTriangles, double colorScale) {
  QuadricResult r;
  r.triangles.resize(g.triangles.size());
  r.positions.resize(g.positions.size());
  r.colors = g.colors;
  std::vector<uint8_t> moved(g.vertexCount());
  mt::QuadricSimplifyOptions o;
  o.colors = g.colors.data();
  o.colorScale = colorScale;
  o.destinationColors = colorScale > 0 ? r.colors.data() : nullptr;
  const size_t n = mt::quadricSimplify(r.triangles.data(), r.positions.data(), moved.data(), g.triangles.data(),
                                       g.triangles.size(), g.positions.data(), g.vertexCount(), 3 * sizeof(double),
                                       g.locked.data(), targetTriangles * 3, o);
  r.triangles.resize(n);
  // Result vertices: the used ones, with their input ids as origin.
  std::vector<uint32_t> remap(g.vertexCount(), ~0u), origin;
  std::vector<double> pos;
  std::vector<uint8_t> col;
  for (uint32_t& v : r.triangles) {
    if (remap[v] == ~0u) {
      remap[v] = uint32_t(origin.size());
      origin.push_back(v);
      pos.insert(pos.end(), &r.positions[v * 3], &r.positions[v * 3] + 3);
      col.insert(col.end(), &r.colors[v * 4], &r.colors[v * 4] + 4);
    }
    v = remap[v];
  }
  mt::ColorErrorInput ce;
  ce.positions = g.positions.data();
  ce.colors = g.colors.data();
  ce.vertexCount = g.vertexCount();
  ce.triangles = g.triangles.data();
  ce.triangleCount = g.triangleCount();
  ce.resultPositions = pos.data();
  ce.resultColors = col.data();
  ce.origin = origin.data();
  ce.resultVertexCount = origin.size();
  ce.resultTriangles = r.triangles.data();
  ce.resultTriangleCount = r.triangles.size() / 3;
  r.colorError = mt::measureColorError(ce);
  return r;
}

}  // namespace

// A colour that is linear over a plane costs nothing anywhere on it, and the best colour at a point
// is that linear function (Hoppe 1999, section 5).
TEST(ColorQuadric, LinearColourOnAPlaneCostsNothing) {
  const int n = 6;
  std::vector<double> p;
  std::vector<uint8_t> c;
  for (int y = 0; y <= n; ++y)
    for (int x = 0; x <= n; ++x) {
      p.insert(p.end(), {double(x), double(y), 0.0});
      c.insert(c.end(), {uint8_t(40 * x), uint8_t(30 * y), uint8_t(200 - 10 * x - 10 * y), 255});
    }
  std::vector<uint32_t> t;
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      const uint32_t a = y * (n + 1) + x;
      t.insert(t.end(), {a, a + 1, a + n + 2, a, a + n + 2, a + n + 1});
    }
  mt::ColorQuadrics q;
  q.init(c.data(), 10.0, nullptr, p.data(), p.size() / 3, t.data(), t.size());
  ASSERT_TRUE(q.active());
  const uint32_t a = 3 * (n + 1) + 3, b = a + 1;  // an interior edge
  double k[10];
  q.reduced(a, b, k);
  for (const double* at : {&p[a * 3], &p[b * 3]}) {
    const double e = k[0] * at[0] * at[0] + k[1] * at[1] * at[1] + k[2] * at[2] * at[2] +
                     2 * (k[3] * at[0] * at[1] + k[4] * at[0] * at[2] + k[5] * at[1] * at[2]) +
                     2 * (k[6] * at[0] + k[7] * at[1] + k[8] * at[2]) + k[9];
    EXPECT_NEAR(e, 0, 1e-9);
  }
  // Collapsing b into a at the midpoint gives a the interpolated colour there.
  const double mid[3] = {3.5, 3, 0};
  q.collapse(a, b, mid);
  std::vector<uint8_t> out(c.size());
  q.write(out.data());
  EXPECT_EQ(out[a * 4 + 0], 140);  // 40 * 3.5
  EXPECT_EQ(out[a * 4 + 1], 90);   // 30 * 3
  EXPECT_EQ(out[a * 4 + 2], 135);  // 200 - 35 - 30
  // A locked survivor keeps its colour, and pays for it.
  std::vector<uint8_t> locked(p.size() / 3, 0);
  locked[a] = 1;
  mt::ColorQuadrics l;
  l.init(c.data(), 10.0, locked.data(), p.data(), p.size() / 3, t.data(), t.size());
  EXPECT_GT(l.fixedColorCost(a, b, mid), 0);
  EXPECT_EQ(l.fixedColorCost(b, a, mid), 0);
  l.collapse(a, b, mid);
  l.write(out.data());
  EXPECT_EQ(out[a * 4], c[a * 4]);
}

// On a flat grid the geometry says nothing: without colour the collapses smear the red/blue edge;
// with colour in the quadric (Hoppe 1999) the edge's vertices stay and the colour error is small.
TEST(QuadricSimplify, ColourEdgeSurvivesWithColourInTheCost) {
  const Grid g = colourEdgeGrid(40, 17);
  const size_t target = g.triangleCount() / 10;
  const QuadricResult blind = simplifyGrid(g, target, 0);
  const QuadricResult aware = simplifyGrid(g, target, 1.0);
  EXPECT_LE(aware.triangles.size() / 3, target + 8);
  EXPECT_LE(blind.triangles.size() / 3, target + 8);
  // The colours differ by ~260 levels: smearing the edge over a wide triangle shows as ~100 or more.
  EXPECT_GT(blind.colorError, 80) << "the test grid no longer shows a smeared colour edge";
  EXPECT_LT(aware.colorError, 0.25 * blind.colorError) << "aware " << aware.colorError << " blind " << blind.colorError;
  // The locked border keeps its colours.
  for (size_t v = 0; v < g.vertexCount(); ++v) {
    if (!g.locked[v]) continue;
    for (int k = 0; k < 4; ++k) ASSERT_EQ(aware.colors[v * 4 + k], g.colors[v * 4 + k]) << v;
  }
}

// Both simplifiers carry colours; the colour error is measured, 0 when nothing changed.
TEST(SimplifyRegion, ColoursCarriedAndTheirErrorMeasured) {
  const Grid g = colourEdgeGrid(30, 12);
  for (auto simplifier : {mt::RegionSimplifier::Meshopt, mt::RegionSimplifier::Quadric}) {
    SCOPED_TRACE(simplifier == mt::RegionSimplifier::Meshopt ? "meshopt" : "quadric");
    mt::SimplifyRegionOptions o;
    o.simplifier = simplifier;
    o.colors = g.colors.data();
    o.colorWeight = 1;
    o.targetTriangles = g.triangleCount() / 4;
    mt::SimplifiedRegion r = mt::simplifyRegion(g.positions.data(), g.vertexCount(), g.triangles.data(), g.triangleCount(),
                                                g.locked.data(), o);
    ASSERT_EQ(r.colors.size(), r.origin.size() * 4);
    EXPECT_GT(r.colorError, 0);
    EXPECT_LT(r.colorError, 200);
    if (simplifier == mt::RegionSimplifier::Meshopt) {  // half-edge collapses: every colour is an input vertex's
      for (size_t v = 0; v < r.origin.size(); ++v) ASSERT_EQ(0, std::memcmp(&r.colors[v * 4], &g.colors[r.origin[v] * 4], 4));
    }
    o.targetTriangles = g.triangleCount();  // nothing to do
    mt::SimplifiedRegion same = mt::simplifyRegion(g.positions.data(), g.vertexCount(), g.triangles.data(),
                                                   g.triangleCount(), g.locked.data(), o);
    EXPECT_EQ(same.colorError, 0);
    EXPECT_EQ(same.colors, g.colors);
  }
}

namespace {

// One coloured build for the tool tests (mtgen's sharp field, holes), quadric by default.
class ColourBuild : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir();
    auto g = runTool("mtgen", "-o " + dir_->file("c.ply") + " --triangles 60k --holes 3 --seed 5 --colors");
    ASSERT_EQ(g.exitCode, 0) << g.output;
    auto b = runTool("mtbuild", dir_->file("c.ply") + " -o " + mt() + " --patch-triangles 500 --threads 2");
    ASSERT_EQ(b.exitCode, 0) << b.output;
    buildLog_ = new std::string(b.output);
    auto w = runTool("mtbuild", dir_->file("c.ply") + " -o " + dir_->file("blind.mt") +
                                    " --patch-triangles 500 --threads 2 -q --color-weight 0");
    ASSERT_EQ(w.exitCode, 0) << w.output;
  }
  static void TearDownTestSuite() {
    delete dir_;
    delete buildLog_;
  }
  static std::string mt() { return dir_->file("c.mt"); }
  static TempDir* dir_;
  static std::string* buildLog_;
};
TempDir* ColourBuild::dir_ = nullptr;
std::string* ColourBuild::buildLog_ = nullptr;

// Max colour error per level.
std::vector<double> levelColourErrors(const std::string& path) {
  auto r = mt::MtFileReader::open(path);
  std::vector<double> e(r->header().levelCount, 0);
  for (size_t v = 0; v + 1 < r->nodes().size(); ++v)
    e[r->nodes()[v].level] = std::max(e[r->nodes()[v].level], double(r->nodes()[v].colorError));
  return e;
}

}  // namespace

TEST_F(ColourBuild, TheColourErrorIsStoredMonotoneAndVerified) {
  EXPECT_THAT(*buildLog_, HasSubstr("per-vertex colours: simplifying with the quadric simplifier"));
  auto r = mt::MtFileReader::open(mt());
  EXPECT_EQ(r->header().version, mt::format::kUntexturedVersion);
  ASSERT_TRUE(r->header().vertexFlags & mt::format::kHasColors);
  const auto& nodes = r->nodes();
  EXPECT_EQ(nodes.front().colorError, 0.0f);
  EXPECT_TRUE(std::isinf(nodes.back().colorError));
  size_t measured = 0;
  for (size_t v = 0; v < nodes.size(); ++v) {
    measured += nodes[v].level >= 1 && nodes[v].colorError > 0 && std::isfinite(nodes[v].colorError);
    for (uint32_t k = 0; k < nodes[v].backArcCount; ++k) {
      const uint32_t u = r->arcs()[r->backArcs()[nodes[v].firstBackArc + k]].from;
      ASSERT_GE(nodes[v].colorError, nodes[u].colorError) << "node " << v << " after " << u;
    }
  }
  EXPECT_GT(measured, nodes.size() / 2);
  auto info = runTool("mtinfo", mt());
  EXPECT_EQ(info.exitCode, 0);
  EXPECT_THAT(info.output, HasSubstr("colour err max"));
  auto verify = runTool("mtverify", mt() + " --cuts 8");
  EXPECT_EQ(verify.exitCode, 0) << verify.output;
  EXPECT_THAT(verify.output, HasSubstr("monotone errors  ok"));
}

// `--simplifier auto` (the default) on coloured input is the quadric simplifier in every choice it
// drives, the grid step included: the same bytes as the explicit choice.
TEST_F(ColourBuild, AutoOnColouredInputIsTheQuadricBuild) {
  auto q = runTool("mtbuild", dir_->file("c.ply") + " -o " + dir_->file("quadric.mt") +
                                  " --patch-triangles 500 --threads 2 -q --simplifier quadric");
  ASSERT_EQ(q.exitCode, 0) << q.output;
  const std::string a = mt::test::readFile(mt()), b = mt::test::readFile(dir_->file("quadric.mt"));
  auto ra = mt::MtFileReader::open(mt()), rb = mt::MtFileReader::open(dir_->file("quadric.mt"));
  EXPECT_EQ(ra->header().gridStep, rb->header().gridStep);
  EXPECT_TRUE(a == b) << "auto and quadric builds of the same coloured input differ";
}

// Colour in the collapse cost lowers the stored colour error of the coarse levels against the
// same build with colours carried but not weighed (--color-weight 0).
TEST_F(ColourBuild, ColourWeightLowersTheColourError) {
  const std::vector<double> aware = levelColourErrors(mt()), blind = levelColourErrors(dir_->file("blind.mt"));
  ASSERT_GE(aware.size(), 4u);
  ASSERT_EQ(aware.size(), blind.size());
  for (size_t l = 2; l + 1 < aware.size(); ++l) EXPECT_LT(aware[l], blind[l]) << "level " << l;
}

namespace {

// The file's bytes with the footer checksum recomputed (after an edit of the header or the index).
void resealAndWrite(std::string bytes, const std::string& path) {
  mt::format::FileHeader h;
  std::memcpy(&h, bytes.data(), sizeof h);
  mt::format::Footer f;
  const size_t footerAt = bytes.size() - sizeof f;
  std::memcpy(&f, bytes.data() + footerAt, sizeof f);
  f.version = h.version;
  XXH64_state_t* s = XXH64_createState();
  XXH64_reset(s, 0);
  XXH64_update(s, bytes.data(), sizeof h);
  XXH64_update(s, bytes.data() + h.metaOffset, footerAt - h.metaOffset);
  f.checksum = XXH64_digest(s);
  XXH64_freeState(s);
  std::memcpy(bytes.data() + footerAt, &f, sizeof f);
  mt::test::writeFile(path, bytes);
}

float* colorErrorOf(std::string& bytes, uint64_t node) {
  mt::format::FileHeader h;
  std::memcpy(&h, bytes.data(), sizeof h);
  return reinterpret_cast<float*>(bytes.data() + h.nodesOffset + node * sizeof(mt::format::NodeRecord) +
                                  offsetof(mt::format::NodeRecord, colorError));
}

}  // namespace

// A file of the previous version (its node word reserved, zero) still reads: colour error 0, said
// by mtinfo as not stored, and mtverify passes.
TEST_F(ColourBuild, Version4FilesStillRead) {
  std::string bytes = mt::test::readFile(mt());
  mt::format::FileHeader h;
  std::memcpy(&h, bytes.data(), sizeof h);
  h.version = 4;
  std::memcpy(bytes.data(), &h, sizeof h);
  for (uint64_t v = 0; v < h.nodeCount; ++v) *colorErrorOf(bytes, v) = 0;
  const std::string old = dir_->file("v4.mt");
  resealAndWrite(bytes, old);
  auto r = mt::MtFileReader::open(old);
  for (const auto& n : r->nodes()) EXPECT_EQ(n.colorError, 0.0f);
  auto info = runTool("mtinfo", old);
  EXPECT_EQ(info.exitCode, 0) << info.output;
  EXPECT_THAT(info.output, HasSubstr("colour error      not stored (file version 4"));
  auto verify = runTool("mtverify", old + " --cuts 4");
  EXPECT_EQ(verify.exitCode, 0) << verify.output;
}

// mtverify finds a colour error that drops below a predecessor's, and a sink that is not +inf.
TEST_F(ColourBuild, MtverifyFindsABrokenColourError) {
  const std::string original = mt::test::readFile(mt());
  auto r = mt::MtFileReader::open(mt());
  uint32_t node = 0;
  for (uint32_t v = 1; v + 1 < r->nodes().size() && !node; ++v)
    if (r->nodes()[v].level >= 2) node = v;
  ASSERT_NE(node, 0u);
  std::string bytes = original;
  *colorErrorOf(bytes, node) = 0;
  resealAndWrite(bytes, dir_->file("drop.mt"));
  auto a = runTool("mtverify", dir_->file("drop.mt") + " --cuts 0");
  EXPECT_NE(a.exitCode, 0);
  EXPECT_THAT(a.output, HasSubstr("colour error not monotone: node " + std::to_string(node)));
  bytes = original;
  *colorErrorOf(bytes, r->nodes().size() - 1) = 5;
  resealAndWrite(bytes, dir_->file("sink.mt"));
  auto b = runTool("mtverify", dir_->file("sink.mt") + " --cuts 0");
  EXPECT_NE(b.exitCode, 0);
  EXPECT_THAT(b.output, HasSubstr("the sink's colour error is 5"));
}

namespace {

mt::render::Image render(const std::string& mt, const std::string& dir, const std::string& extra, std::string* log = nullptr) {
  std::filesystem::remove_all(dir);
  const int frames = 60;
  auto r = runTool("mtrender", mt + " --headless --width 320 --height 240 --camera-path fixed --frames " + std::to_string(frames) +
                                   " --screenshots " + dir + " --screenshot-every 1000 --fixed-triangles 400000 --cache 64M " + extra);
  EXPECT_EQ(r.exitCode, 0) << r.output;
  if (log) *log = r.output;
  char name[64];
  std::snprintf(name, sizeof name, "/frame_%05d.png", frames - 1);
  return mt::render::readPng(dir + name);
}

// PSNR over the pixels the model covers in either image (the background is 20, 23, 28).
double coveredPsnr(const mt::render::Image& a, const mt::render::Image& b) {
  const uint8_t background[3] = {20, 23, 28};
  return mt::render::psnr(a, b, background).covered;
}

// Pixels whose colour is far from grey: max channel - min channel > 60.
size_t saturated(const mt::render::Image& img) {
  size_t n = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x) {
      const uint8_t* p = img.pixel(x, y);
      n += std::max({p[0], p[1], p[2]}) - std::min({p[0], p[1], p[2]}) > 60;
    }
  return n;
}

}  // namespace

// mtrender --color vertex draws the colours; a cut at 1 px screen error is within 30 dB of the
// full-resolution model (the finest cut: tolerance 0); the golden image of the full-resolution
// view is stable across machines up to llvmpipe's rounding.
TEST_F(ColourBuild, RendersTheColoursCloseToTheFullResolution) {
  const mt::render::Image full = render(mt(), dir_->file("full"), "--color vertex --tolerance 0.01");
  const mt::render::Image cut = render(mt(), dir_->file("cut"), "--color vertex --tolerance 1");
  const mt::render::Image shaded = render(mt(), dir_->file("shaded"), "--color shaded --tolerance 0.01");
  const size_t pixels = size_t(full.width) * full.height;
  EXPECT_GT(saturated(full), pixels / 20) << "the colours are not drawn";
  EXPECT_EQ(saturated(shaded), 0u) << "shaded draws no colour";
  const double psnr = coveredPsnr(cut, full);
  EXPECT_GE(psnr, 30.0) << "1 px cut against the full resolution";
  std::string log;
  const mt::render::Image tex = render(mt(), dir_->file("tex"), "--color texture --tolerance 0.01", &log);
  EXPECT_THAT(log, HasSubstr("no texture in " + mt() + ", using vertex colours"));
  EXPECT_EQ(tex.rgba, full.rgba);
  const mt::render::Image autoMode = render(mt(), dir_->file("auto"), "--tolerance 0.01");
  EXPECT_EQ(autoMode.rgba, full.rgba) << "the default draws a coloured file's colours";
  // The golden image (MT_UPDATE_GOLDEN=1 rewrites it): same tolerances as MtRender.GoldenImage.
  const std::string golden = std::string(MT_SOURCE_DIR) + "/tests/data/colour/golden_vertex.png";
  if (std::getenv("MT_UPDATE_GOLDEN")) mt::render::writePng(golden, full);
  const mt::render::Image ref = mt::render::readPng(golden);
  ASSERT_EQ(ref.width, full.width);
  ASSERT_EQ(ref.height, full.height);
  double sum = 0;
  size_t differ = 0;
  for (int y = 0; y < full.height; ++y)
    for (int x = 0; x < full.width; ++x) {
      int d = 0;
      for (int k = 0; k < 3; ++k) d = std::max(d, std::abs(int(full.pixel(x, y)[k]) - int(ref.pixel(x, y)[k])));
      sum += d;
      differ += d > 40;
    }
  EXPECT_LT(sum / double(pixels), 3.0) << "mean colour difference to the golden image";
  EXPECT_LT(double(differ), double(pixels) * 0.01) << "pixels differing by more than 40/255";
}

// mtgen's colour field has sharp features (many pixels of several distinct colours), is the same
// for the same position, and --paint puts it on any mesh.
TEST(MtgenColours, PaintGivesAColouredCopyWithSharpFeatures) {
  TempDir dir;
  auto g = runTool("mtgen", "-o " + dir.file("g.ply") + " --triangles 20k --seed 3");
  ASSERT_EQ(g.exitCode, 0) << g.output;
  auto p = runTool("mtgen", "-o " + dir.file("p.ply") + " --paint " + dir.file("g.ply"));
  ASSERT_EQ(p.exitCode, 0) << p.output;
  struct Sink : mt::MeshSink {
    mt::MeshHeader h;
    std::vector<mt::InputVertex> v;
    std::vector<uint32_t> t;
    void begin(const mt::MeshHeader& header) override { h = header; }
    void vertices(const mt::InputVertex* p, size_t n, uint64_t) override { v.insert(v.end(), p, p + n); }
    void triangles(const uint32_t* p, size_t n) override { t.insert(t.end(), p, p + 3 * n); }
  } in, out;
  mt::openMesh(dir.file("g.ply"))->read(in);
  mt::openMesh(dir.file("p.ply"))->read(out);
  ASSERT_TRUE(out.h.hasColors);
  ASSERT_EQ(out.v.size(), in.v.size());
  EXPECT_EQ(out.t, in.t);
  std::set<uint32_t> distinct;
  size_t steps = 0;  // edges whose ends differ by more than 100 levels in some channel
  for (size_t i = 0; i < out.v.size(); ++i) {
    for (int a = 0; a < 3; ++a) ASSERT_EQ(out.v[i].p[a], in.v[i].p[a]);
    distinct.insert(uint32_t(out.v[i].c[0]) << 16 | uint32_t(out.v[i].c[1]) << 8 | out.v[i].c[2]);
  }
  for (size_t t = 0; t < out.t.size(); t += 3)
    for (int k = 0; k < 3; ++k) {
      const uint8_t *a = out.v[out.t[t + k]].c, *b = out.v[out.t[t + (k + 1) % 3]].c;
      steps += std::abs(int(a[0]) - b[0]) > 100 || std::abs(int(a[1]) - b[1]) > 100 || std::abs(int(a[2]) - b[2]) > 100;
    }
  EXPECT_GE(distinct.size(), 8u);
  EXPECT_GT(steps, out.t.size() / 100) << "no sharp colour edges";
  // The generator's own --colors uses the same field, so its colours have the same sharp edges.
  auto c = runTool("mtgen", "-o " + dir.file("c.ply") + " --triangles 20k --seed 3 --colors");
  ASSERT_EQ(c.exitCode, 0) << c.output;
  auto bad = runTool("mtgen", "-o " + dir.file("p.obj") + " --paint " + dir.file("g.ply"));
  EXPECT_EQ(bad.exitCode, 1);
  EXPECT_THAT(bad.output, HasSubstr("--paint writes binary PLY"));
  EXPECT_FALSE(mt::test::fileExists(dir.file("p.obj")));
}
