// Patch codec (mtfile/patch_codec.h): exact round trip of grid coordinates and triangles for both
// codecs, with and without normals/colours; shared border vertices quantize identically.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <map>
#include <meshoptimizer.h>
#include <random>
#include <set>
#include <tuple>

#include "base/error.h"
#include "mtfile/fan_order.h"
#include "mtfile/mt_file.h"
#include "mtfile/patch_codec.h"
#include "mtfile/patch_codec_detail.h"
#include "mtfile/range_coder.h"
#include "mtbuild/simplify_region.h"
#include "test_support.h"
#include "testing/scan_grid.h"

using namespace mt;

namespace {

using Tri = std::array<std::array<uint32_t, 3>, 3>;

// Triangles as a multiset of grid-coordinate triples, rotated to a canonical first corner (the
// winding is kept: rotation only).
std::multiset<Tri> triangleSet(const std::vector<uint32_t>& q, const std::vector<uint32_t>& tris) {
  std::multiset<Tri> out;
  for (size_t t = 0; t < tris.size(); t += 3) {
    Tri c;
    for (int k = 0; k < 3; ++k) c[k] = {q[tris[t + k] * 3], q[tris[t + k] * 3 + 1], q[tris[t + k] * 3 + 2]};
    int m = int(std::min_element(c.begin(), c.end()) - c.begin());
    std::rotate(c.begin(), c.begin() + m, c.end());
    out.insert(c);
  }
  return out;
}

QuantizationGrid gridFor(double step) {
  double lo[3] = {-50, -50, -50}, hi[3] = {200, 200, 50};
  return QuantizationGrid::fromBounds(lo, hi, step);
}

std::vector<uint32_t> quantizeAll(const std::vector<double>& p, const QuantizationGrid& g) {
  std::vector<uint32_t> q(p.size());
  for (size_t i = 0; i < p.size(); i += 3) g.quantize(&p[i], &q[i]);
  return q;
}

using Codec = format::Codec;

class CodecRoundTrip : public ::testing::TestWithParam<std::tuple<format::Codec, bool, bool>> {};

TEST_P(CodecRoundTrip, ExactGridCoordinatesAndTriangles) {
  auto [codec, normals, colors] = GetParam();
  ScanGridOptions o;
  o.nx = o.ny = 40;
  o.holes = 2;
  o.holeRadius = 3;
  ScanGrid g = makeScanGrid(o);
  QuantizationGrid grid = gridFor(1.0 / 32);
  std::vector<uint8_t> rgba(g.vertexCount() * 4);
  for (size_t i = 0; i < rgba.size(); ++i) rgba[i] = uint8_t(i * 37 + (i >> 3));

  PatchInput in;
  in.positions = g.positions.data();
  in.vertexCount = g.vertexCount();
  in.triangles = g.triangles.data();
  in.triangleCount = g.triangleCount();
  in.colors = colors ? rgba.data() : nullptr;
  PatchCodecOptions opt;
  opt.codec = codec;
  opt.normals = normals;
  std::vector<uint8_t> payload = encodePatch(in, grid, opt);
  DecodedPatch d = decodePatch(payload.data(), payload.size(), codec, grid);

  std::vector<uint32_t> q = quantizeAll(g.positions, grid);
  ASSERT_EQ(d.triangleCount(), g.triangleCount());
  EXPECT_EQ(triangleSet(d.q, d.triangles), triangleSet(q, g.triangles));
  // float positions are origin + step * q
  for (size_t i = 0; i < d.q.size(); ++i)
    ASSERT_EQ(d.positions[i], float(grid.origin[i % 3] + grid.step * double(d.q[i])));
  // and within the quantization error of some input vertex: check via the set of q
  std::set<std::array<uint32_t, 3>> inputQ;
  for (size_t i = 0; i < q.size(); i += 3) inputQ.insert({q[i], q[i + 1], q[i + 2]});
  for (size_t v = 0; v < d.vertexCount(); ++v) ASSERT_TRUE(inputQ.count({d.q[v * 3], d.q[v * 3 + 1], d.q[v * 3 + 2]}));

  EXPECT_EQ(d.normals.empty(), !normals);
  EXPECT_EQ(d.colors.empty(), !colors);
  if (normals || colors) {
    // Map decoded vertices back to input vertices by grid position (unique on this grid).
    std::map<std::array<uint32_t, 3>, uint32_t> byQ;
    for (uint32_t v = 0; v < g.vertexCount(); ++v) byQ[{q[v * 3], q[v * 3 + 1], q[v * 3 + 2]}] = v;
    for (size_t v = 0; v < d.vertexCount(); ++v) {
      uint32_t src = byQ.at({d.q[v * 3], d.q[v * 3 + 1], d.q[v * 3 + 2]});
      if (colors) {
        for (int k = 0; k < 4; ++k) ASSERT_EQ(d.colors[v * 4 + k], rgba[src * 4 + k]);
      }
      if (normals) {
        float len = std::sqrt(d.normals[v * 3] * d.normals[v * 3] + d.normals[v * 3 + 1] * d.normals[v * 3 + 1] +
                              d.normals[v * 3 + 2] * d.normals[v * 3 + 2]);
        ASSERT_NEAR(len, 1.f, 1e-4f);
        ASSERT_GT(d.normals[v * 3 + 2], 0.2f) << "a height field's normals point up";
      }
    }
  }
}

INSTANTIATE_TEST_SUITE_P(AllCodecs, CodecRoundTrip,
                         ::testing::Combine(::testing::Values(format::Codec::Meshopt, format::Codec::Draco),
                                            ::testing::Bool(), ::testing::Bool()));

TEST(Codec, GivenNormalsSurviveOctahedral8) {
  ScanGrid g = makeScanGrid({});
  std::vector<float> n(g.vertexCount() * 3);
  for (size_t v = 0; v < g.vertexCount(); ++v) {
    float x = std::sin(float(v)), y = std::cos(float(v) * 0.7f), z = std::sin(float(v) * 1.3f) - 0.2f;
    float l = std::sqrt(x * x + y * y + z * z);
    n[v * 3] = x / l, n[v * 3 + 1] = y / l, n[v * 3 + 2] = z / l;
  }
  QuantizationGrid grid = gridFor(1.0 / 16);
  std::vector<uint32_t> q = quantizeAll(g.positions, grid);
  std::map<std::array<uint32_t, 3>, uint32_t> byQ;
  for (uint32_t v = 0; v < g.vertexCount(); ++v) byQ[{q[v * 3], q[v * 3 + 1], q[v * 3 + 2]}] = v;
  for (Codec codec : {Codec::Meshopt, Codec::Draco}) {
    PatchInput in{g.positions.data(), g.vertexCount(), g.triangles.data(), g.triangleCount(), n.data(), nullptr};
    PatchCodecOptions opt;
    opt.codec = codec;
    opt.normals = true;
    auto payload = encodePatch(in, grid, opt);
    DecodedPatch d = decodePatch(payload.data(), payload.size(), codec, grid);
    for (size_t v = 0; v < d.vertexCount(); ++v) {
      uint32_t src = byQ.at({d.q[v * 3], d.q[v * 3 + 1], d.q[v * 3 + 2]});
      float dot = 0;
      for (int k = 0; k < 3; ++k) dot += d.normals[v * 3 + k] * n[src * 3 + k];
      ASSERT_GT(dot, std::cos(2.0f * 3.14159f / 180.f)) << "octahedral 8-bit error is under ~1.5 degrees";
    }
  }
}

TEST(Codec, SharedBorderVerticesQuantizeIdentically) {
  // Two patches cut from one mesh along a column: the border vertices are the same doubles in
  // both, so they must decode to the same grid coordinates and the same floats (crack-free).
  ScanGridOptions o;
  o.nx = 30, o.ny = 20;
  o.offset[0] = 123456.789;  // far from the origin: float positions would not be exact
  o.offset[1] = -98765.4321;
  ScanGrid g = makeScanGrid(o);
  double lo[3] = {123400, -98800, -50}, hi[3] = {123600, -98700, 50};
  QuantizationGrid grid = QuantizationGrid::fromBounds(lo, hi, 1.0 / 1024);
  std::vector<uint32_t> left, right;
  for (size_t t = 0; t < g.triangles.size(); t += 3) {
    double cx = 0;
    for (int k = 0; k < 3; ++k) cx += g.positions[g.triangles[t + k] * 3];
    auto& dst = cx / 3 < o.offset[0] + 14.5 ? left : right;
    dst.insert(dst.end(), &g.triangles[t], &g.triangles[t + 3]);
  }
  std::set<uint32_t> lv(left.begin(), left.end()), rv(right.begin(), right.end()), shared;
  std::set_intersection(lv.begin(), lv.end(), rv.begin(), rv.end(), std::inserter(shared, shared.end()));
  ASSERT_GT(shared.size(), 10u);
  for (Codec codec : {Codec::Meshopt, Codec::Draco}) {
    PatchCodecOptions opt;
    opt.codec = codec;
    PatchInput a{g.positions.data(), g.vertexCount(), left.data(), left.size() / 3, nullptr, nullptr};
    PatchInput b{g.positions.data(), g.vertexCount(), right.data(), right.size() / 3, nullptr, nullptr};
    auto pa = encodePatch(a, grid, opt), pb = encodePatch(b, grid, opt);
    DecodedPatch da = decodePatch(pa.data(), pa.size(), codec, grid);
    DecodedPatch db = decodePatch(pb.data(), pb.size(), codec, grid);
    std::set<std::array<float, 3>> fa, fb;
    for (size_t v = 0; v < da.vertexCount(); ++v) fa.insert({da.positions[v * 3], da.positions[v * 3 + 1], da.positions[v * 3 + 2]});
    for (size_t v = 0; v < db.vertexCount(); ++v) fb.insert({db.positions[v * 3], db.positions[v * 3 + 1], db.positions[v * 3 + 2]});
    for (uint32_t v : shared) {
      uint32_t q[3];
      grid.quantize(&g.positions[v * 3], q);
      std::array<float, 3> f = {float(grid.dequantize(0, q[0])), float(grid.dequantize(1, q[1])),
                                float(grid.dequantize(2, q[2]))};
      EXPECT_TRUE(fa.count(f) && fb.count(f)) << "shared vertex " << v << " decodes differently";
      for (int k = 0; k < 3; ++k) EXPECT_LE(std::fabs(grid.dequantize(k, q[k]) - g.positions[v * 3 + k]), grid.step / 2 + 1e-9);
    }
  }
}

TEST(Codec, EmptyPatchAndSingleTriangle) {
  QuantizationGrid grid = gridFor(0.5);
  double p[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  uint32_t t[3] = {0, 1, 2};
  for (Codec codec : {Codec::Meshopt, Codec::Draco}) {
    PatchCodecOptions opt;
    opt.codec = codec;
    auto one = encodePatch({p, 3, t, 1, nullptr, nullptr}, grid, opt);
    DecodedPatch d = decodePatch(one.data(), one.size(), codec, grid);
    EXPECT_EQ(d.triangleCount(), 1u);
    EXPECT_EQ(d.vertexCount(), 3u);
    if (codec == Codec::Meshopt) {  // Draco refuses meshes without faces; the builder never writes one
      auto none = encodePatch({p, 3, t, 0, nullptr, nullptr}, grid, opt);
      EXPECT_EQ(decodePatch(none.data(), none.size(), codec, grid).triangleCount(), 0u);
    }
  }
}

// Version-2 meshopt payloads range-code the position residuals: residuals of every width (0 to
// ~2^29 grid steps here) round-trip exactly, and the payload says how its positions are coded.
TEST(Codec, RangeCodedPositionsAnyResidualWidth) {
  QuantizationGrid grid = gridFor(1e-6);  // 250 units at 1e-6: coordinates up to ~2^28
  ScanGrid g = makeScanGrid({});
  std::vector<double> p = g.positions;
  for (size_t v = 0; v < p.size() / 3; ++v)  // a few huge jumps among small ones
    if (v % 13 == 0) p[v * 3 + (v % 3)] += double(v % 7) * 20.0 - 40.0;
  PatchInput in{p.data(), g.vertexCount(), g.triangles.data(), g.triangleCount(), nullptr, nullptr};
  std::vector<uint8_t> payload = encodePatch(in, grid, {});
  format::PayloadHeader h;
  std::memcpy(&h, payload.data(), sizeof h);
  EXPECT_TRUE(h.flags & format::kPayloadRangePositions);
  DecodedPatch d = decodePatch(payload.data(), payload.size(), Codec::Meshopt, grid);
  EXPECT_EQ(triangleSet(d.q, d.triangles), triangleSet(quantizeAll(p, grid), g.triangles));
}

// The patch of the version-2 fixture below: a 5x5 grid, uneven heights, triangles out of order.
void smallIrregularPatch(std::vector<double>& p, std::vector<uint32_t>& t) {
  for (int y = 0; y < 5; ++y)
    for (int x = 0; x < 5; ++x) {
      p.push_back(x + 0.1 * ((x * 7 + y * 3) % 5));
      p.push_back(y);
      p.push_back(0.3 * ((x * y) % 3));
    }
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 4; ++x) {
      uint32_t a = uint32_t(y * 5 + x);
      t.insert(t.end(), {a, a + 1, a + 6, a, a + 6, a + 5});
    }
  for (size_t i = 0; i + 6 < t.size(); i += 12)
    for (int k = 0; k < 3; ++k) std::swap(t[i + k], t[t.size() - 3 - i + k]);
}

// Version-3 readers still decode version-2 payloads (LZMA-rate position model, index code in the
// zstd frame): this one was written by the version-2 encoder (grid step 1/64 from (-1,-1,-1)).
TEST(Codec, Version2PayloadStillDecodes) {
  const std::vector<uint8_t> v2 = {
    0x19, 0x00, 0x00, 0x00, 0x20, 0x00, 0x00, 0x00, 0x40, 0x00, 0x00, 0x00, 0x40, 0x00, 0x00, 0x00,
    0x40, 0x00, 0x00, 0x00, 0x10, 0x00, 0x00, 0x00, 0x41, 0x00, 0x00, 0x00, 0x4a, 0x00, 0x00, 0x00,
    0x28, 0xb5, 0x2f, 0xfd, 0x20, 0x41, 0x09, 0x02, 0x00, 0x35, 0x00, 0x00, 0x00, 0x60, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x00, 0x00, 0xe1, 0xf0, 0x20, 0x10, 0x10, 0x10, 0x14, 0x00, 0x00, 0x10, 0x00,
    0x10, 0x60, 0x10, 0x13, 0x48, 0x10, 0x10, 0x12, 0xfe, 0x02, 0x00, 0x10, 0x13, 0xa0, 0x10, 0x13,
    0xfe, 0x04, 0x00, 0x10, 0x15, 0x20, 0xcb, 0xff, 0x06, 0x02, 0x00, 0x76, 0x87, 0x56, 0x67, 0x78,
    0xa9, 0x86, 0x65, 0x89, 0x68, 0x98, 0x01, 0x69, 0x00, 0x00, 0x26, 0x00, 0x94, 0x00, 0x08, 0x3e,
    0x3a, 0x7f, 0x8b, 0xa0, 0x7d, 0x63, 0xf8, 0x2c, 0x3d, 0xd4, 0xe6, 0x44, 0xa5, 0xc0, 0x90, 0x5b,
    0x9d, 0xf9, 0x4c, 0x98, 0xc2, 0xe5, 0x13, 0x3e, 0xa9, 0x12, 0x1b, 0xe5, 0xd3, 0xea, 0x37, 0xbb,
    0x46, 0x30, 0xc3, 0x43, 0x97, 0x49, 0x2f, 0x40, 0x6a, 0x74, 0x05, 0x8c, 0x92, 0x1d, 0xef, 0x57,
    0x5c, 0xf9, 0xbf, 0xac, 0xf8, 0x90, 0x15, 0xf6, 0x6a, 0x80, 0x1f, 0xe1, 0x0a, 0x00};
  std::vector<double> p;
  std::vector<uint32_t> t;
  smallIrregularPatch(p, t);
  double lo[3] = {-1, -1, -1}, hi[3] = {10, 10, 10};
  QuantizationGrid grid = QuantizationGrid::fromBounds(lo, hi, 1.0 / 64);
  format::PayloadHeader h;
  std::memcpy(&h, v2.data(), sizeof h);
  EXPECT_EQ(h.flags, format::kPayloadRangePositions);
  DecodedPatch d = decodePatch(v2.data(), v2.size(), Codec::Meshopt, grid);
  EXPECT_EQ(triangleSet(d.q, d.triangles), triangleSet(quantizeAll(p, grid), t));
  // and the version-3 encoding of the same patch is smaller and decodes to the same triangles
  std::vector<uint8_t> v3 = encodePatch({p.data(), 25, t.data(), t.size() / 3, nullptr, nullptr}, grid, {});
  EXPECT_LT(v3.size(), v2.size());
  DecodedPatch d3 = decodePatch(v3.data(), v3.size(), Codec::Meshopt, grid);
  EXPECT_EQ(triangleSet(d3.q, d3.triangles), triangleSet(d.q, d.triangles));
}

// A simplified, irregular patch (fan order is what the builder gives such patches), 47x47 grid
// halved.
SimplifiedRegion simplifiedPatch() {
  ScanGridOptions o;
  o.nx = o.ny = 47;
  o.jitter = 0.1;
  o.seed = 3;
  ScanGrid grid0 = makeScanGrid(o);
  SimplifyRegionOptions so;
  so.targetTriangles = grid0.triangleCount() / 2;
  so.measureError = false;
  return simplifyRegion(grid0.positions.data(), grid0.vertexCount(), grid0.triangles.data(), grid0.triangleCount(),
                        nullptr, so);
}

// Version 4: the triangles are coded by the connectivity code when that is smaller than zstd over
// the meshopt index code (an irregular, simplified patch), the sizes are then stored without a
// zstd frame when there are no attributes, and with colours the frame holds them; every variant
// round-trips exactly, and payloadBytes accounts for every byte.
TEST(Codec, Version4ConnectivityCodeRoundTrip) {
  SimplifiedRegion g = simplifiedPatch();
  std::vector<uint8_t> rgba(g.vertexCount() * 4);
  for (size_t i = 0; i < rgba.size(); ++i) rgba[i] = uint8_t((i * 13) ^ (i >> 5));
  QuantizationGrid grid = gridFor(1.0 / 16);
  for (bool colors : {false, true}) {
    PatchInput in{g.positions.data(), g.vertexCount(), g.triangles.data(), g.triangleCount(), nullptr,
                  colors ? rgba.data() : nullptr};
    PatchCodecOptions opt;
    opt.simplified = true;  // fan order, as the builder codes simplified patches
    std::vector<uint8_t> payload = encodePatch(in, grid, opt);
    format::PayloadHeader h;
    std::memcpy(&h, payload.data(), sizeof h);
    EXPECT_TRUE(h.flags & format::kPayloadPositionContexts);
    EXPECT_TRUE(h.flags & format::kPayloadConnectivity) << "colors " << colors;
    EXPECT_FALSE(h.flags & format::kPayloadRangeIndices);
    uint32_t zSize;
    std::memcpy(&zSize, payload.data() + sizeof h + 4, 4);
    EXPECT_EQ(zSize == 0, !colors);
    DecodedPatch d = decodePatch(payload.data(), payload.size(), Codec::Meshopt, grid);
    EXPECT_EQ(triangleSet(d.q, d.triangles), triangleSet(quantizeAll(g.positions, grid), g.triangles));
    if (colors) {
      // the colours follow their vertices
      std::map<std::array<uint32_t, 3>, std::array<uint8_t, 4>> byPosition;
      std::vector<uint32_t> q = quantizeAll(g.positions, grid);
      for (size_t v = 0; v < g.vertexCount(); ++v)
        byPosition[{q[v * 3], q[v * 3 + 1], q[v * 3 + 2]}] = {rgba[v * 4], rgba[v * 4 + 1], rgba[v * 4 + 2], rgba[v * 4 + 3]};
      for (size_t v = 0; v < d.vertexCount(); ++v) {
        std::array<uint8_t, 4> c = {d.colors[v * 4], d.colors[v * 4 + 1], d.colors[v * 4 + 2], d.colors[v * 4 + 3]};
        EXPECT_EQ((byPosition[{d.q[v * 3], d.q[v * 3 + 1], d.q[v * 3 + 2]}]), c);
      }
    }
    PayloadBytes b = payloadBytes(payload.data(), payload.size(), Codec::Meshopt);
    EXPECT_EQ(b.header + b.index + b.attributes + b.positions + b.other, payload.size());
    EXPECT_EQ(b.other, 0u);
    EXPECT_GT(b.index, g.triangleCount() / 8);  // more than one bit per triangle
    EXPECT_LT(b.index, g.triangleCount() / 2);  // and less than four
  }
}

// Version-4 readers still decode version-3 payloads (the meshopt index code range-coded, the
// sizes stored without a zstd frame): this one was written by the version-3 encoder (the patch
// and grid of Version2PayloadStillDecodes).
TEST(Codec, Version3PayloadStillDecodes) {
  const std::vector<uint8_t> v3 = {
    0x19, 0x00, 0x00, 0x00, 0x20, 0x00, 0x00, 0x00, 0x40, 0x00, 0x00, 0x00, 0x40, 0x00, 0x00, 0x00,
    0x40, 0x00, 0x00, 0x00, 0x70, 0x00, 0x00, 0x00, 0x0c, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x35, 0x00, 0x00, 0x00, 0x60, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x78, 0x10, 0x00, 0x08,
    0x72, 0x56, 0x45, 0xda, 0xe4, 0x40, 0x2e, 0xae, 0xd1, 0x20, 0x5e, 0x37, 0x16, 0x71, 0x21, 0xc7,
    0x84, 0x85, 0xaa, 0x01, 0xed, 0x83, 0x03, 0xa0, 0x7d, 0xc4, 0xaa, 0x76, 0x94, 0x49, 0x9e, 0x4c,
    0xee, 0x3d, 0x43, 0xf4, 0x96, 0xd4, 0x9a, 0x44, 0x72, 0x75, 0x18, 0x18, 0x1e, 0x2e, 0x02, 0x81,
    0xfc, 0xe3, 0x78, 0xa9, 0x37, 0xc9, 0x94, 0x8b, 0xee, 0xbf, 0x92, 0xb0, 0x8e, 0x28, 0x72, 0xb4,
    0x40, 0x4e, 0x06};
  std::vector<double> p;
  std::vector<uint32_t> t;
  smallIrregularPatch(p, t);
  double lo[3] = {-1, -1, -1}, hi[3] = {10, 10, 10};
  QuantizationGrid grid = QuantizationGrid::fromBounds(lo, hi, 1.0 / 64);
  format::PayloadHeader h;
  std::memcpy(&h, v3.data(), sizeof h);
  EXPECT_EQ(h.flags, format::kPayloadRangePositions | format::kPayloadRangeIndices | format::kPayloadPositionContexts);
  DecodedPatch d = decodePatch(v3.data(), v3.size(), Codec::Meshopt, grid);
  EXPECT_EQ(triangleSet(d.q, d.triangles), triangleSet(quantizeAll(p, grid), t));
  PayloadBytes b = payloadBytes(v3.data(), v3.size(), Codec::Meshopt);
  EXPECT_EQ(b.header + b.index + b.attributes + b.positions + b.other, v3.size());
  EXPECT_EQ(b.other, 0u);
  // and the version-4 encoding of the same patch is smaller and decodes to the same triangles
  std::vector<uint8_t> v4 = encodePatch({p.data(), 25, t.data(), t.size() / 3, nullptr, nullptr}, grid, {});
  std::memcpy(&h, v4.data(), sizeof h);
  EXPECT_TRUE(h.flags & format::kPayloadConnectivity);
  EXPECT_LT(v4.size(), v3.size());
  DecodedPatch d4 = decodePatch(v4.data(), v4.size(), Codec::Meshopt, grid);
  EXPECT_EQ(triangleSet(d4.q, d4.triangles), triangleSet(d.q, d.triangles));
}

// The connectivity code takes any triangle list whose vertices are numbered by first use:
// degenerate and repeated triangles, non-manifold edges, both windings, several components,
// triangles that touch no earlier one. Each comes back exactly, in order, rotated only.
TEST(Codec, ConnectivityCodeTakesAnyTriangleList) {
  std::mt19937 rng(11);
  for (int round = 0; round < 60; ++round) {
    uint32_t vertices = 3 + rng() % 200, triangles = 1 + rng() % 400;
    std::vector<uint32_t> raw(triangles * 3);
    for (size_t i = 0; i < raw.size(); ++i) {
      // mostly near the previous triangle's vertices, sometimes anywhere, sometimes a repeat
      uint32_t base = i >= 3 ? raw[i - 3] : 0;
      uint32_t r = rng() % 10;
      raw[i] = r < 6 ? (base + rng() % 5) % vertices : r < 9 ? rng() % vertices : (i ? raw[i - 1] : 0);
    }
    std::vector<uint32_t> remap(vertices), tri(raw.size());
    size_t used = meshopt_optimizeVertexFetchRemap(remap.data(), raw.data(), raw.size(), vertices);
    meshopt_remapIndexBuffer(tri.data(), raw.data(), raw.size(), remap.data());
    std::vector<uint8_t> bytes, tail(8, 0xA5);
    std::vector<uint32_t> coded;
    {
      codec_detail::RangeEncoder rc(bytes);
      codec_detail::encodeConnectivity(rc, tri.data(), tri.size(), used, coded);
      rc.finish();
    }
    ASSERT_EQ(coded.size(), tri.size());
    for (size_t t = 0; t < tri.size(); t += 3) {
      std::array<uint32_t, 3> a = {tri[t], tri[t + 1], tri[t + 2]}, b = {coded[t], coded[t + 1], coded[t + 2]};
      bool rotation = false;
      for (int r = 0; r < 3; ++r) rotation |= a == std::array<uint32_t, 3>{b[r], b[(r + 1) % 3], b[(r + 2) % 3]};
      ASSERT_TRUE(rotation) << "round " << round << " triangle " << t / 3;
    }
    std::vector<uint32_t> decoded;
    codec_detail::RangeDecoder rd(bytes.data(), bytes.data() + bytes.size());
    codec_detail::decodeConnectivity(rd, triangles, uint32_t(used), decoded);
    ASSERT_EQ(decoded, coded) << "round " << round;
    EXPECT_EQ(rd.overrun(), 0u);
  }
  // 20000 triangles that share only vertex 0 (a non-manifold star): vertex 0 collects 20000 open
  // half-edges each way, which the decoder must still handle in linear time.
  std::vector<uint32_t> star;
  for (uint32_t t = 0; t < 20000; ++t) star.insert(star.end(), {0, 1 + 2 * t, 2 + 2 * t});
  std::vector<uint8_t> bytes;
  std::vector<uint32_t> coded, decoded;
  {
    codec_detail::RangeEncoder rc(bytes);
    codec_detail::encodeConnectivity(rc, star.data(), star.size(), 40001, coded);
    rc.finish();
  }
  codec_detail::RangeDecoder rd(bytes.data(), bytes.data() + bytes.size());
  codec_detail::decodeConnectivity(rd, 20000, 40001, decoded);
  EXPECT_EQ(decoded, coded);
  EXPECT_EQ(rd.overrun(), 0u);
}

// RangeEncoder::finishedSize (the encoder compares its codings by it, then goes on coding) is the
// size finish() leaves, at any point of a stream: after each of many bits, with skewed
// probabilities that make long carry runs, and coded after bytes already in the vector.
TEST(Codec, RangeEncoderFinishedSizeIsTheSizeFinishLeaves) {
  std::mt19937 rng(11);
  for (int round = 0; round < 40; ++round) {
    std::vector<uint8_t> prefix(size_t(round % 3) * 5, 0x5A);
    std::vector<uint8_t> bytes = prefix;
    codec_detail::RangeEncoder rc(bytes);
    std::vector<codec_detail::CountedBit> probs(8);
    std::vector<uint32_t> bits;
    const uint32_t skew = 1 + uint32_t(round % 5) * 200;  // 1 in skew bits is a 1: long carry runs
    for (int i = 0; i < 3000; ++i) {
      uint32_t b = rng() % skew == 0 ? 1u : 0u;
      if (round % 2) b ^= 1u;
      bits.push_back(b);
      rc.bit(probs[size_t(i) % probs.size()], b);
      if (i % 97 != 0) continue;
      // What finish() would leave now: code the same bits into a fresh encoder and finish it.
      std::vector<uint8_t> copy = prefix;
      codec_detail::RangeEncoder again(copy);
      std::vector<codec_detail::CountedBit> p2(8);
      for (size_t k = 0; k < bits.size(); ++k) again.bit(p2[k % p2.size()], bits[k]);
      again.finish();
      ASSERT_EQ(rc.finishedSize(), copy.size() - prefix.size()) << "round " << round << " bit " << i;
    }
    size_t predicted = rc.finishedSize();
    rc.finish();
    EXPECT_EQ(predicted, bytes.size() - prefix.size()) << "round " << round;
  }
}

// A connectivity-coded payload, truncated or with any byte changed, throws mt::Error or decodes to
// valid indices; never crashes.
TEST(Codec, DamagedConnectivityPayloadsThrowOrStayValid) {
  SimplifiedRegion g = simplifiedPatch();
  QuantizationGrid grid = gridFor(1.0 / 16);
  PatchCodecOptions opt;
  opt.simplified = true;
  std::vector<uint8_t> payload =
      encodePatch({g.positions.data(), g.vertexCount(), g.triangles.data(), g.triangleCount(), nullptr, nullptr}, grid, opt);
  format::PayloadHeader h;
  std::memcpy(&h, payload.data(), sizeof h);
  ASSERT_TRUE(h.flags & format::kPayloadConnectivity);
  for (size_t cut : {size_t(24), size_t(40), size_t(60), payload.size() / 3, payload.size() / 2, payload.size() - 1})
    EXPECT_THROW(decodePatch(payload.data(), cut, Codec::Meshopt, grid), Error) << "cut at " << cut;
  for (size_t i = 0; i < payload.size(); i += std::max<size_t>(1, payload.size() / 300)) {
    for (uint8_t flip : {uint8_t(0x01), uint8_t(0x80), uint8_t(0x5A)}) {
      auto damaged = payload;
      damaged[i] ^= flip;
      try {
        DecodedPatch d = decodePatch(damaged.data(), damaged.size(), Codec::Meshopt, grid);
        for (uint32_t idx : d.triangles) ASSERT_LT(idx, d.vertexCount());
      } catch (const Error&) {
      }
    }
  }
}

// The strip option (PatchCodecOptions::strips, mtbuild --index-order strip): every patch kind the
// builder codes (a level-0 grid in scan order, the same grid shuffled, a simplified patch; with and
// without attributes) is stored as a strip and decodes to exactly the triangles, winding and
// grid coordinates of the input, the same ones the list coding gives back.
TEST(Codec, StripsRoundTripExactlyAndGiveTheListsTriangles) {
  ScanGridOptions o;
  o.nx = o.ny = 45;
  o.jitter = 0.1;
  o.holes = 2;
  o.holeRadius = 3;
  o.seed = 5;
  ScanGrid grid0 = makeScanGrid(o);
  SimplifyRegionOptions so;
  so.targetTriangles = grid0.triangleCount() / 2;
  so.measureError = false;
  SimplifiedRegion simplified = simplifyRegion(grid0.positions.data(), grid0.vertexCount(), grid0.triangles.data(),
                                               grid0.triangleCount(), nullptr, so);
  std::vector<uint32_t> shuffled = grid0.triangles;
  {
    std::vector<uint32_t> order(grid0.triangleCount());
    for (uint32_t t = 0; t < order.size(); ++t) order[t] = t;
    std::shuffle(order.begin(), order.end(), std::mt19937(9));
    for (size_t t = 0; t < order.size(); ++t)
      for (int k = 0; k < 3; ++k) shuffled[t * 3 + k] = grid0.triangles[order[t] * 3 + k];
  }
  struct Case {
    const char* name;
    const std::vector<double>* positions;
    const std::vector<uint32_t>* triangles;
    bool simplified;
  } cases[] = {{"level 0", &grid0.positions, &grid0.triangles, false},
               {"shuffled", &grid0.positions, &shuffled, false},
               {"simplified", &simplified.positions, &simplified.triangles, true}};
  QuantizationGrid grid = gridFor(1.0 / 16);
  for (const Case& c : cases) {
    size_t nv = c.positions->size() / 3, nt = c.triangles->size() / 3;
    std::vector<uint8_t> rgba(nv * 4);
    for (size_t i = 0; i < rgba.size(); ++i) rgba[i] = uint8_t(i * 29 + (i >> 4));
    std::vector<uint32_t> q = quantizeAll(*c.positions, grid);
    for (bool attributes : {false, true}) {
      SCOPED_TRACE(std::string(c.name) + (attributes ? ", normals and colours" : ""));
      PatchInput in{c.positions->data(), nv, c.triangles->data(), nt, nullptr, attributes ? rgba.data() : nullptr};
      PatchCodecOptions opt;
      opt.simplified = c.simplified;
      opt.normals = attributes;
      std::vector<uint8_t> list = encodePatch(in, grid, opt);
      opt.strips = true;
      std::vector<uint8_t> strip = encodePatch(in, grid, opt);
      format::PayloadHeader h;
      std::memcpy(&h, strip.data(), sizeof h);
      EXPECT_TRUE(h.flags & format::kPayloadStrip);
      EXPECT_FALSE(h.flags & format::kPayloadRangeIndices);
      std::memcpy(&h, list.data(), sizeof h);
      EXPECT_FALSE(h.flags & format::kPayloadStrip);

      DecodedPatch ds = decodePatch(strip.data(), strip.size(), Codec::Meshopt, grid);
      DecodedPatch dl = decodePatch(list.data(), list.size(), Codec::Meshopt, grid);
      ASSERT_EQ(ds.triangleCount(), nt);
      EXPECT_EQ(triangleSet(ds.q, ds.triangles), triangleSet(q, *c.triangles));
      EXPECT_EQ(triangleSet(ds.q, ds.triangles), triangleSet(dl.q, dl.triangles));
      ASSERT_EQ(ds.vertexCount(), dl.vertexCount());
      for (size_t i = 0; i < ds.q.size(); ++i)
        ASSERT_EQ(ds.positions[i], float(grid.origin[i % 3] + grid.step * double(ds.q[i])));
      // Attributes follow their vertex through the strip's renumbering.
      std::map<std::array<uint32_t, 3>, uint32_t> listVertex;
      for (uint32_t v = 0; v < dl.vertexCount(); ++v) listVertex[{dl.q[v * 3], dl.q[v * 3 + 1], dl.q[v * 3 + 2]}] = v;
      ASSERT_EQ(ds.colors.size(), dl.colors.size());
      ASSERT_EQ(ds.normals.size(), dl.normals.size());
      for (uint32_t v = 0; v < ds.vertexCount() && attributes; ++v) {
        uint32_t w = listVertex.at({ds.q[v * 3], ds.q[v * 3 + 1], ds.q[v * 3 + 2]});
        for (int k = 0; k < 4; ++k) ASSERT_EQ(ds.colors[v * 4 + k], dl.colors[w * 4 + k]);
        for (int k = 0; k < 3; ++k) ASSERT_EQ(ds.normals[v * 3 + k], dl.normals[w * 3 + k]);
      }
      PayloadBytes b = payloadBytes(strip.data(), strip.size(), Codec::Meshopt);
      EXPECT_EQ(b.header + b.index + b.attributes + b.positions + b.other, strip.size());
    }
  }
}

// End to end: `mtbuild --index-order strip` stores every patch as a strip, mtverify passes, and
// every patch decodes to the same triangles as in the default (list) build of the same input,
// whose DAG is the same.
TEST(Codec, StripBuildVerifiesAndHoldsTheListBuildsTriangles) {
  mt::test::TempDir dir;
  std::string mesh = dir.file("m.ply"), listMt = dir.file("list.mt"), stripMt = dir.file("strip.mt");
  auto gen = mt::test::runTool("mtgen", "-o " + mesh + " --triangles 60k --holes 4 --seed 3");
  ASSERT_EQ(gen.exitCode, 0) << gen.output;
  for (const auto& [out, order] : {std::pair{listMt, "list"}, std::pair{stripMt, "strip"}}) {
    auto b = mt::test::runTool("mtbuild", mesh + " -o " + out + " --threads 2 -q --patch-triangles 1000 --index-order " + order);
    ASSERT_EQ(b.exitCode, 0) << b.output;
  }
  auto verify = mt::test::runTool("mtverify", stripMt + " --cuts 32 --quiet");
  EXPECT_EQ(verify.exitCode, 0) << verify.output;
  auto bad = mt::test::runTool("mtbuild", mesh + " -o " + dir.file("x.mt") + " --index-order fans");
  EXPECT_NE(bad.exitCode, 0);
  EXPECT_NE(bad.output.find("--index-order"), std::string::npos) << bad.output;

  auto list = MtFileReader::open(listMt), strip = MtFileReader::open(stripMt);
  ASSERT_EQ(list->patches().size(), strip->patches().size());
  ASSERT_GT(strip->patches().size(), 10u);
  ASSERT_EQ(list->nodes().size(), strip->nodes().size());
  for (size_t i = 0; i < list->nodes().size(); ++i) EXPECT_EQ(list->nodes()[i].error, strip->nodes()[i].error);
  for (uint32_t i = 0; i < strip->patches().size(); ++i) {
    std::vector<uint8_t> raw = strip->readPayload(i);
    format::PayloadHeader h;
    std::memcpy(&h, raw.data(), sizeof h);
    if (h.triangleCount > 0) {
      EXPECT_TRUE(h.flags & format::kPayloadStrip) << "patch " << i;
    }
    DecodedPatch ds = strip->readPatch(i), dl = list->readPatch(i);
    ASSERT_EQ(triangleSet(ds.q, ds.triangles), triangleSet(dl.q, dl.triangles)) << "patch " << i;
  }
}

TEST(Codec, BadInputAndDamagedPayloadsThrow) {
  QuantizationGrid grid = gridFor(0.5);
  double p[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  uint32_t bad[3] = {0, 1, 7};
  EXPECT_THROW(encodePatch({p, 3, bad, 1, nullptr, nullptr}, grid, {}), Error);
  double far[9] = {1e9, 0, 0, 1, 0, 0, 0, 1, 0};
  uint32_t t[3] = {0, 1, 2};
  EXPECT_THROW(encodePatch({far, 3, t, 1, nullptr, nullptr}, grid, {}), Error);

  ScanGrid g = makeScanGrid({});
  for (Codec codec : {Codec::Meshopt, Codec::Draco}) {
    PatchCodecOptions opt;
    opt.codec = codec;
    auto payload = encodePatch({g.positions.data(), g.vertexCount(), g.triangles.data(), g.triangleCount(), nullptr, nullptr},
                               grid, opt);
    // truncations and byte flips must throw mt::Error or decode to something valid, never crash
    for (size_t cut : {size_t(0), size_t(10), size_t(30), payload.size() / 2, payload.size() - 1})
      EXPECT_THROW(decodePatch(payload.data(), cut, codec, grid), Error) << "cut at " << cut;
    for (size_t i = 0; i < payload.size(); i += std::max<size_t>(1, payload.size() / 97)) {
      auto damaged = payload;
      damaged[i] ^= 0x5A;
      try {
        DecodedPatch d = decodePatch(damaged.data(), damaged.size(), codec, grid);
        for (uint32_t idx : d.triangles) ASSERT_LT(idx, d.vertexCount());
      } catch (const Error&) {
      }
    }
  }
}

// ---- fan order (mtfile/fan_order.h) ---------------------------------------------------------

// The triangles as a multiset of index triples rotated to their smallest corner (winding kept).
std::multiset<std::array<uint32_t, 3>> rotatedSet(const std::vector<uint32_t>& tris) {
  std::multiset<std::array<uint32_t, 3>> out;
  for (size_t t = 0; t < tris.size(); t += 3) {
    std::array<uint32_t, 3> c = {tris[t], tris[t + 1], tris[t + 2]};
    std::rotate(c.begin(), std::min_element(c.begin(), c.end()), c.end());
    out.insert(c);
  }
  return out;
}

// Consecutive triangles sharing two vertices: what the index codec's edge FIFO rewards.
double edgeSharingFraction(const std::vector<uint32_t>& tris) {
  size_t shared = 0;
  for (size_t t = 3; t < tris.size(); t += 3) {
    int common = 0;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) common += tris[t + i] == tris[t - 3 + j];
    shared += common >= 2;
  }
  return tris.size() > 3 ? double(shared) / double(tris.size() / 3 - 1) : 1.0;
}

size_t indexCodeBytes(const std::vector<uint32_t>& tris, size_t vertexCount) {
  std::vector<uint32_t> remap(vertexCount), fetched(tris.size());
  size_t used = meshopt_optimizeVertexFetchRemap(remap.data(), tris.data(), tris.size(), vertexCount);
  meshopt_remapIndexBuffer(fetched.data(), tris.data(), tris.size(), remap.data());
  std::vector<uint8_t> code(meshopt_encodeIndexBufferBound(tris.size(), used));
  return meshopt_encodeIndexBuffer(code.data(), code.size(), fetched.data(), fetched.size());
}

TEST(FanOrder, ReordersAShuffledScanIntoCoherentFansKeepingEveryTriangleAndItsWinding) {
  ScanGridOptions o;
  o.holes = 3;
  ScanGrid g = makeScanGrid(o);
  // Shuffle the triangles (and rotate some), as a scan in no useful order would come.
  std::vector<uint32_t> shuffled = g.triangles;
  std::mt19937 rng(5);
  for (size_t t = g.triangleCount(); t-- > 1;) {
    size_t u = rng() % (t + 1);
    for (int k = 0; k < 3; ++k) std::swap(shuffled[3 * t + k], shuffled[3 * u + k]);
  }
  for (size_t t = 0; t < shuffled.size(); t += 6) std::rotate(&shuffled[t], &shuffled[t + 1], &shuffled[t + 3]);
  std::vector<uint32_t> ordered(shuffled.size());
  fanOrderTriangles(ordered.data(), shuffled.data(), shuffled.size(), g.vertexCount());
  EXPECT_EQ(rotatedSet(ordered), rotatedSet(shuffled)) << "not the same triangles with the same winding";
  EXPECT_LT(edgeSharingFraction(shuffled), 0.05);
  EXPECT_GT(edgeSharingFraction(ordered), 0.75);
  // The codec's measure: within 15% of meshoptimizer's strip-biased cache order, far below the shuffle.
  std::vector<uint32_t> strip(shuffled.size());
  meshopt_optimizeVertexCacheStrip(strip.data(), shuffled.data(), shuffled.size(), g.vertexCount());
  const size_t fan = indexCodeBytes(ordered, g.vertexCount()), ref = indexCodeBytes(strip, g.vertexCount());
  EXPECT_LT(double(fan), 1.15 * double(ref)) << "fan " << fan << " bytes, cache-strip " << ref;
  EXPECT_LT(3 * fan, indexCodeBytes(shuffled, g.vertexCount()));
}

TEST(FanOrder, DegenerateNonManifoldAndEmptyInputsArePermutedExactly) {
  // Three triangles on one edge (non-manifold), a degenerate one, a duplicate, an isolated one.
  const std::vector<uint32_t> tris = {0, 1, 2, 1, 0, 3, 0, 1, 4, 2, 2, 5, 0, 1, 2, 6, 7, 8, 3, 1, 9};
  std::vector<uint32_t> out(tris.size());
  fanOrderTriangles(out.data(), tris.data(), tris.size(), 10);
  EXPECT_EQ(rotatedSet(out), rotatedSet(tris));
  fanOrderTriangles(nullptr, nullptr, 0, 0);  // nothing to do, nothing read or written
  const std::vector<uint32_t> one = {2, 0, 1};
  std::vector<uint32_t> oneOut(3);
  fanOrderTriangles(oneOut.data(), one.data(), 3, 3);
  EXPECT_EQ(rotatedSet(oneOut), rotatedSet(one));
}

}  // namespace
