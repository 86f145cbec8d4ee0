// What the fuzzers of fuzz/ found, each kept as a regression test of the normal suite (the
// sanitizer stage of scripts/test.sh runs these under ASan+UBSan, where the undefined behaviour
// itself is caught, not only a wrong answer), and the bounds the readers put on damaged counts.
// docs/hardening.md lists the findings.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <set>
#include <string>
#include <vector>

#include <xxhash.h>

#include <fstream>

#include "base/error.h"
#include "base/exit_code.h"
#include "mtfile/mt_file.h"
#include "mtfile/patch_codec.h"
#include "mtrender/camera.h"
#include "patchstore/io/mesh_reader.h"
#include "patchstore/store_impl.h"
#include "test_support.h"

using mt::test::TempDir;
using mt::test::readFile;
using mt::test::runShell;
using mt::test::runTool;
using mt::test::writeFile;

// fuzz_patch_meshopt: a stored (not zstd-compressed) stream with raw size 0 reached memcpy with
// the empty vector's null data pointer (UBSan: null passed to a nonnull parameter) before the
// "raw stream too short" check. Now refused first.
TEST(FuzzRegressions, MeshoptPayloadWithAnEmptyStoredStreamIsRefused) {
  const std::vector<uint8_t> payload = {
    0x52, 0x00, 0x00, 0x00, 0x6e, 0x00, 0x00, 0x00, 0x2f, 0x00, 0x00, 0x00, 0x53, 0x00, 0x00, 0x00,
    0x02, 0x00, 0x00, 0x00, 0x70, 0x00, 0x00, 0x0c, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x8e, 0x00, 0x00, 0x00, 0x4a, 0x01, 0x00, 0x31, 0x00, 0x00, 0x00, 0x00, 0x00, 0x78, 0x08, 0x00,
    0x44, 0xee, 0x42, 0xcf, 0x32, 0x85, 0x86, 0xf8, 0x52, 0x2b, 0xea, 0x04, 0x47, 0x8a, 0xf7, 0xbf,
    0xed, 0xda, 0x7d, 0xa4, 0x51, 0x2f, 0xf1, 0xf0, 0x95, 0x04, 0xfd, 0x96, 0xf2, 0xa0, 0x80, 0x04,
    0x1c, 0xae, 0x81, 0x99, 0xb0, 0xc0, 0x3a, 0x4d, 0x51, 0xfe, 0x71, 0x38, 0xdb, 0x98, 0x26, 0xc7,
    0x34, 0xea, 0x65, 0x8b, 0x06, 0x10, 0xe4, 0xcd, 0x81, 0xaf, 0x25, 0xd6, 0xef, 0xcb, 0x0e, 0x32,
    0x3a, 0xd0, 0x0c, 0x0e, 0x7e, 0x77, 0x82, 0x16, 0xd6, 0x65, 0x39, 0x3d, 0x57, 0x4c, 0x4f, 0xc0,
    0xfa, 0xb7, 0xfb, 0x8b, 0x28, 0xf7, 0x99, 0x36, 0x8b, 0xf0, 0x00,
  };
  mt::QuantizationGrid grid;
  EXPECT_THROW(mt::decodePatch(payload.data(), payload.size(), mt::format::Codec::Meshopt, grid), mt::Error);
}

// fuzz_patch_meshopt (a timeout): a 105-byte payload whose header claims 3.7M triangles of 38
// vertices, index code range-coded: the decoder read the whole count from zeros past the stream's
// end before checking for the overrun (1.4 s of CPU under ASan). It now stops at the first byte
// past the end, and the refusal names the triangle it had reached: this checks that the decoder
// stopped within the stream's bytes, not after decoding the claimed count (which the old decoder
// did, refusing the same payload only at the end, with no triangle named).
TEST(FuzzRegressions, MeshoptPayloadClaimingMillionsOfTrianglesIsRefusedAtTheStreamsEnd) {
  const std::vector<uint8_t> payload = {
    0x26, 0x00, 0x00, 0x00, 0xaf, 0x0d, 0x39, 0x00, 0x3d, 0x00, 0x00, 0x00, 0x0c, 0x00, 0x00, 0x00,
    0x03, 0x00, 0x00, 0x00, 0x70, 0x00, 0x00, 0x00, 0x0c, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x42, 0x00, 0x4a, 0x00, 0x7b, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x78, 0x08, 0x00, 0x00,
    0x52, 0xc0, 0xb7, 0x27, 0xc8, 0x92, 0x58, 0xa6, 0xf5, 0x26, 0x3c, 0x2d, 0xec, 0x27, 0x02, 0x00,
    0x00, 0x00, 0x00, 0x00, 0xeb, 0xeb, 0xeb, 0xeb, 0xeb, 0xeb, 0xeb, 0xeb, 0xeb, 0xeb, 0xeb, 0xeb,
    0xeb, 0xeb, 0xeb, 0xeb, 0xeb, 0xeb, 0xeb, 0xeb, 0xeb, 0xeb, 0xeb, 0xeb, 0xeb, 0xeb, 0xeb, 0xeb,
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x01,
  };
  mt::QuantizationGrid grid;
  try {
    mt::decodePatch(payload.data(), payload.size(), mt::format::Codec::Meshopt, grid);
    ADD_FAILURE() << "decoded";
  } catch (const mt::Error& e) {
    const std::string what = e.what();
    unsigned long long at = 0, of = 0;
    const size_t pos = what.find("index stream truncated at triangle ");
    ASSERT_NE(pos, std::string::npos) << what;
    ASSERT_EQ(std::sscanf(what.c_str() + pos, "index stream truncated at triangle %llu of %llu", &at, &of), 2) << what;
    EXPECT_EQ(of, 0x390dafu) << what;  // the header's claim (bytes 4-7)
    // Every triangle's code is 8 binary decisions of an adaptive model; what the 105 bytes can
    // hold is far below one triangle per payload bit.
    EXPECT_LT(at, payload.size() * 8) << what;
  }
}

// fuzz_camera_path: "-1e308" in unit space overflowed to -inf once scaled by the radius, and the
// pose was accepted; a word after the six numbers ("0 0 0 0 0 0# x") was ignored.
TEST(FuzzRegressions, CameraPathWithNonFiniteOrTrailingWordsIsRefused) {
  TempDir tmp;
  const glm::dvec3 centre(1, 2, 3);
  const std::vector<std::pair<std::string, std::string>> bad = {
      {"overflow", "mtrender-camera-path 1\n# seed\nspace unit\nfov 45\n0 -3 1  0 0 0\n1 -2 1  0 0-1e308\n"},
      {"trailing", "0 -3 1  0 0 0# ace 2\n"},
      {"same_point", "space object\n1 1 1 1 1 1\n"},
  };
  for (const auto& [name, text] : bad) {
    writeFile(tmp.file(name), text);
    try {
      mt::render::loadCameraPath(tmp.file(name), centre, 4.0);
      ADD_FAILURE() << name << ": accepted";
    } catch (const mt::Error& e) {
      EXPECT_NE(std::string(e.what()).find(tmp.file(name) + ": line "), std::string::npos) << e.what();
    }
  }
  // The seed paths still load.
  writeFile(tmp.file("good"), "space unit\nfov 30\n0 -3 1 0 0 0\n1 -2 1 0 0 0 0 0 1\n");
  EXPECT_EQ(mt::render::loadCameraPath(tmp.file("good"), centre, 4.0).poses.size(), 2u);
}

// The patch decoders' bound on a payload's counts. It was 64 triangles per payload byte, which a
// large, perfectly flat, regular patch exceeds (Draco codes a 128 x 128 grid at 135 triangles per
// byte): such a patch of a valid file was refused as damaged. The bound is now the count the
// file's index states (PatchRecord::triangles, which the header must equal) and the format's
// limit (kMaxPayloadTriangles, 3 vertices per triangle), checked before anything is allocated.
TEST(PayloadBounds, ALargeFlatRegularPatchDecodesAndDamagedCountsAreRefused) {
  const int n = 128;
  std::vector<double> p;
  std::vector<uint32_t> t;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) p.insert(p.end(), {double(i), double(j), 0.0});
  for (int j = 0; j + 1 < n; ++j)
    for (int i = 0; i + 1 < n; ++i) {
      const uint32_t a = uint32_t(j * n + i), b = a + 1, c = a + uint32_t(n), d = c + 1;
      t.insert(t.end(), {a, b, d, a, d, c});
    }
  const double lo[3] = {0, 0, 0}, hi[3] = {n, n, 1};
  const mt::QuantizationGrid grid = mt::QuantizationGrid::fromBounds(lo, hi, 1.0);
  mt::PatchInput in;
  in.positions = p.data();
  in.vertexCount = p.size() / 3;
  in.triangles = t.data();
  in.triangleCount = t.size() / 3;
  auto corners = [](const mt::DecodedPatch& d) {
    std::multiset<std::vector<uint32_t>> out;
    for (size_t k = 0; k < d.triangles.size(); k += 3) {
      std::vector<uint32_t> tri;
      for (int c = 0; c < 3; ++c) tri.insert(tri.end(), &d.q[3 * d.triangles[k + c]], &d.q[3 * d.triangles[k + c]] + 3);
      out.insert(tri);
    }
    return out;
  };
  std::multiset<std::vector<uint32_t>> expected;
  for (size_t k = 0; k < t.size(); k += 3) {
    std::vector<uint32_t> tri;
    for (int c = 0; c < 3; ++c)
      for (int a = 0; a < 3; ++a) tri.push_back(uint32_t(p[3 * t[k + c] + a]));
    expected.insert(tri);
  }
  const uint32_t triangles = uint32_t(in.triangleCount);
  for (auto codec : {mt::format::Codec::Meshopt, mt::format::Codec::Draco}) {
    SCOPED_TRACE(codec == mt::format::Codec::Draco ? "draco" : "meshopt");
    mt::PatchCodecOptions o;
    o.codec = codec;
    const std::vector<uint8_t> payload = mt::encodePatch(in, grid, o);
    if (codec == mt::format::Codec::Draco) {
      EXPECT_GT(double(triangles) / double(payload.size()), 64.0) << payload.size();
    }
    mt::DecodedPatch d = mt::decodePatch(payload.data(), payload.size(), codec, grid, triangles);
    ASSERT_EQ(d.triangleCount(), triangles);
    // Rotation of each triangle's corners may differ from the input's: compare as rotated sets.
    auto canon = [](std::multiset<std::vector<uint32_t>> s) {
      std::multiset<std::vector<uint32_t>> out;
      for (auto tri : s) {
        std::vector<uint32_t> best = tri;
        for (int r = 1; r < 3; ++r) {
          std::rotate(tri.begin(), tri.begin() + 3, tri.end());
          best = std::min(best, tri);
        }
        out.insert(best);
      }
      return out;
    };
    EXPECT_EQ(canon(corners(d)), canon(expected));
    EXPECT_EQ(mt::decodePatch(payload.data(), payload.size(), codec, grid).triangleCount(), triangles);

    // The index says otherwise: refused before decoding, naming both counts.
    try {
      mt::decodePatch(payload.data(), payload.size(), codec, grid, triangles - 1);
      ADD_FAILURE() << "a header that differs from the index was accepted";
    } catch (const mt::Error& e) {
      EXPECT_NE(std::string(e.what()).find("its header says " + std::to_string(triangles) + " triangles, the index " +
                                           std::to_string(triangles - 1)),
                std::string::npos)
          << e.what();
    }
    // Counts beyond the format's limits: refused, whatever the index says.
    std::vector<uint8_t> damaged = payload;
    mt::format::PayloadHeader h;
    std::memcpy(&h, damaged.data(), sizeof h);
    h.triangleCount = mt::format::kMaxPayloadTriangles + 1;
    std::memcpy(damaged.data(), &h, sizeof h);
    EXPECT_THROW(mt::decodePatch(damaged.data(), damaged.size(), codec, grid, h.triangleCount), mt::Error);
    EXPECT_THROW(mt::decodePatch(damaged.data(), damaged.size(), codec, grid), mt::Error);
    h.triangleCount = triangles;
    h.vertexCount = 3 * triangles + 1;
    std::memcpy(damaged.data(), &h, sizeof h);
    EXPECT_THROW(mt::decodePatch(damaged.data(), damaged.size(), codec, grid, triangles), mt::Error);
  }
}

// A file whose index and payload disagree on a patch's triangle count, with every checksum right (a
// writer's bug, not damage on disk): mtinfo --check, mtverify and mtextract each refuse it as a
// corrupt file, naming the patch and both counts.
TEST(PayloadBounds, AnIndexCountThePayloadDisagreesWithIsNamedByEveryTool) {
  TempDir tmp;
  ASSERT_EQ(runTool("mtgen", "-o " + tmp.file("in.ply") + " -t 2k -s 5").exitCode, 0);
  ASSERT_EQ(runTool("mtbuild", tmp.file("in.ply") + " -o " + tmp.file("a.mt") + " --patch-triangles 100 --threads 1 -q").exitCode, 0);
  std::string bytes = readFile(tmp.file("a.mt"));
  uint32_t patch = 0, triangles = 0;
  {
    auto r = mt::MtFileReader::open(tmp.file("a.mt"));
    patch = uint32_t(r->patches().size() - 1);  // on the top level's arc: in every cut
    triangles = r->patches()[patch].triangles;
    const uint64_t record = r->header().patchesOffset + uint64_t(patch) * sizeof(mt::format::PatchRecord);
    const uint32_t claimed = triangles + 1;
    std::memcpy(&bytes[record + offsetof(mt::format::PatchRecord, triangles)], &claimed, 4);
    // The footer's checksum over the header and the index, made right again.
    mt::format::FileHeader h;
    std::memcpy(&h, bytes.data(), sizeof h);
    const size_t footer = bytes.size() - mt::format::kFooterSize;
    XXH64_state_t* st = XXH64_createState();
    XXH64_reset(st, 0);
    XXH64_update(st, &h, sizeof h);
    XXH64_update(st, bytes.data() + h.metaOffset, footer - h.metaOffset);
    const uint64_t sum = XXH64_digest(st);
    XXH64_freeState(st);
    std::memcpy(&bytes[footer + offsetof(mt::format::Footer, checksum)], &sum, 8);
  }
  mt::test::writeFile(tmp.file("b.mt"), bytes);
  const std::string said = "its header says " + std::to_string(triangles) + " triangles, the index " + std::to_string(triangles + 1);
  for (const std::string& command :
       {std::string("mtinfo --check"), std::string("mtverify"), "mtextract --error 1e30 -o " + tmp.file("out.ply")}) {
    auto r = runShell(mt::test::binDir() + "/" + command + " " + tmp.file("b.mt"));
    EXPECT_EQ(r.exitCode, mt::kExitCorruption) << command << ": " << r.output;
    EXPECT_NE(r.output.find("patch " + std::to_string(patch)), std::string::npos) << command << ": " << r.output;
    EXPECT_NE(r.output.find(said), std::string::npos) << command << ": " << r.output;
  }
  EXPECT_FALSE(std::filesystem::exists(tmp.file("out.ply")));
}

// fuzz_store_segment: a geometry block whose header claims 2^29 vertices (checksums are off in the
// fuzzing build; a block made on purpose has a right one) had its arrays allocated from the counts
// (6 GB) before the block was found to hold far fewer bytes. Now the counts are checked against the
// block's size first; a boundary block's count likewise.
TEST(FuzzRegressions, StoreBlockWithHugeCountsIsRefusedBeforeAllocating) {
  for (const bool doublePrecision : {false, true}) {
    mt::VertexLayout layout;
    layout.doublePrecision = doublePrecision;
    layout.colors = true;
    for (const uint32_t vertices : {0x20000000u, 0xFFFFFFFFu}) {
      const mt::store_format::GeometryHeader h{vertices, 1, mt::layoutFlags(layout), 0};
      std::string block(reinterpret_cast<const char*>(&h), sizeof h);
      block.append(64, '\0');
      mt::Patch p;
      try {
        mt::decodeGeometry(block, layout, p, "SEG-000001.dat: patch 3");
        ADD_FAILURE() << "accepted";
      } catch (const mt::Error& e) {
        const std::string said =
            "SEG-000001.dat: patch 3: geometry block of 80 bytes is too short for its " + std::to_string(vertices) + " vertices";
        EXPECT_NE(std::string(e.what()).find(said), std::string::npos) << e.what();
      }
      EXPECT_EQ(p.positions.capacity(), 0u);
    }
  }
  // fuzz_store_segment: a block of no vertices and no triangles reached memcpy with an empty
  // vector's null pointer (UBSan: null passed as a nonnull argument; the sanitizer stage catches it).
  for (const bool doublePrecision : {false, true}) {
    mt::VertexLayout layout;
    layout.doublePrecision = doublePrecision;
    layout.normals = layout.colors = true;
    const mt::store_format::GeometryHeader h{0, 0, mt::layoutFlags(layout), 0};
    mt::Patch p;
    mt::decodeGeometry(std::string(reinterpret_cast<const char*>(&h), sizeof h), layout, p, "SEG-000001.dat: patch 4");
    EXPECT_EQ(p.vertexCount(), 0u);
    EXPECT_EQ(p.triangleCount(), 0u);
  }
  const uint32_t entries = 0xFFFFFFFFu;
  std::string block(reinterpret_cast<const char*>(&entries), 4);
  block.append(24, '\0');
  EXPECT_THROW(mt::decodeBoundary(block, "SEG-000001.dat: patch 3"), mt::Error);
}

// Geometry blocks pack their positions and triangles (kGeomPackedPositions, kGeomPackedTriangles):
// every value comes back exactly and every index in its place (corner order included, which the
// per-corner texture coordinates follow), the block is several times smaller than the plain form,
// a block of the plain form (stores written before) still reads, and a damaged code is refused
// naming the block.
TEST(FuzzRegressions, StoreBlockPacksPositionsAndTrianglesExactlyAndReadsThePlainForm) {
  namespace sf = mt::store_format;
  mt::VertexLayout layout;
  layout.texcoords = true;
  mt::Patch p;
  const uint32_t nv = 3000;
  uint32_t seed = 7;
  auto next = [&] { return seed = seed * 1664525u + 1013904223u; };
  for (uint32_t v = 0; v < nv; ++v)  // a noisy sheet, as a scan's patch: floats that differ in their low bits
    for (int a = 0; a < 3; ++a) p.positions.push_back(double(float((v % 60) * 0.01 + a * (v / 60) * 0.01 + (next() >> 8) * 1e-9)));
  for (uint32_t t = 0; t < 5000; ++t) {
    // Mostly neighbouring indices, some far jumps, corners in every rotation.
    const uint32_t base = (t / 2 + (next() >> 28)) % (nv - 2);
    uint32_t tri[3] = {base, base + 1, (next() % 8 == 0) ? next() % nv : base + 2};
    const uint32_t r = next() % 3;
    for (int c = 0; c < 3; ++c) p.triangles.push_back(tri[(c + r) % 3]);
    p.triangleMaterial.push_back(t % 3);
    for (int c = 0; c < 6; ++c) p.cornerUV.push_back(float(t * 6 + c) / 65536.0f);
  }
  const std::string block = mt::encodeGeometry(p, layout);
  sf::GeometryHeader h;
  std::memcpy(&h, block.data(), sizeof h);
  EXPECT_EQ(h.flags & (sf::kGeomPackedTriangles | sf::kGeomPackedPositions), sf::kGeomPackedTriangles | sf::kGeomPackedPositions);
  uint32_t positionCode, triangleCode;
  std::memcpy(&positionCode, block.data() + sizeof h, 4);
  const size_t trianglesAt = sizeof h + 4 + positionCode;
  std::memcpy(&triangleCode, block.data() + trianglesAt, 4);
  const size_t cornerBytes = p.triangleCount() * 28 + 4;
  ASSERT_EQ(block.size(), trianglesAt + 4 + triangleCode + cornerBytes);
  const size_t plainPositions = size_t(nv) * 12, plainTriangles = p.triangles.size() * 4;
  EXPECT_LT(positionCode, plainPositions) << positionCode << " bytes of packed positions against " << plainPositions;
  EXPECT_LT(triangleCode * 2, plainTriangles) << triangleCode << " bytes of packed triangles against " << plainTriangles;
  mt::Patch q;
  mt::decodeGeometry(block, layout, q, "SEG-000002.dat: patch 9");
  EXPECT_EQ(q.positions, p.positions);
  EXPECT_EQ(q.triangles, p.triangles);
  EXPECT_EQ(q.cornerUV, p.cornerUV);
  EXPECT_EQ(q.triangleMaterial, p.triangleMaterial);

  // The plain form: the header without the flags, the floats and the indices as they are.
  sf::GeometryHeader plainHeader = h;
  plainHeader.flags &= ~(sf::kGeomPackedTriangles | sf::kGeomPackedPositions);
  std::string plain(reinterpret_cast<const char*>(&plainHeader), sizeof plainHeader);
  const std::vector<float> floats(p.positions.begin(), p.positions.end());
  plain.append(reinterpret_cast<const char*>(floats.data()), plainPositions);
  plain.append(reinterpret_cast<const char*>(p.triangles.data()), plainTriangles);
  plain.append(block.substr(block.size() - cornerBytes));
  mt::Patch r;
  mt::decodeGeometry(plain, layout, r, "SEG-000002.dat: patch 9");
  EXPECT_EQ(r.positions, p.positions);
  EXPECT_EQ(r.triangles, p.triangles);
  EXPECT_EQ(r.cornerUV, p.cornerUV);

  // Damaged: a code's byte count lowered (the rest taken for what follows) or beyond the block, a
  // byte of a code changed, and a vertex count far beyond what the packed positions can hold.
  auto refused = [&](std::string bad, const char* what) {
    mt::Patch b;
    try {
      mt::decodeGeometry(bad, layout, b, "SEG-000002.dat: patch 9");
      ADD_FAILURE() << what << ": accepted";
    } catch (const mt::Error& e) {
      EXPECT_NE(std::string(e.what()).find("SEG-000002.dat: patch 9"), std::string::npos) << what << ": " << e.what();
    }
    EXPECT_LT(b.positions.capacity(), 1u << 20) << what;
  };
  for (const size_t at : {sizeof h, trianglesAt})
    for (const int64_t delta : {int64_t(-40), int64_t(1) << 20}) {
      std::string bad = block;
      uint32_t n;
      std::memcpy(&n, bad.data() + at, 4);
      n = uint32_t(int64_t(n) + delta);
      std::memcpy(bad.data() + at, &n, 4);
      refused(bad, at == sizeof h ? "positions' byte count" : "triangles' byte count");
    }
  {
    std::string bad = block;
    bad[trianglesAt + 4] = char(0x00);  // the index sequence's header byte
    refused(bad, "triangle code header");
  }
  {
    std::string bad = block;
    sf::GeometryHeader huge = h;
    huge.vertexCount = 0x20000000u;
    std::memcpy(bad.data(), &huge, sizeof huge);
    refused(bad, "vertex count");
  }
}

// The glTF reader (fuzz_reader_gltf and inputs made for it): a JSON member of the wrong type threw
// nlohmann's exception, which named no file; byte counts that were believed before the bytes were
// seen (a view of a meshopt fallback buffer, a meshopt view's byteLength or compressed length)
// allocated terabytes; a byteStride above 2^32 was cut to 32 bits; an accessor without a bufferView
// (all zeros) delivered 3e9 positions; a node transform of 1e308 gave infinite positions; nodes
// sharing children repeated their subtrees exponentially; a number too large for a double escaped
// as nlohmann's out_of_range (terminate in the fuzzer). Each is now
// refused, naming the file and the element.
TEST(FuzzRegressions, GltfWithWrongTypesOrUnbackedCountsIsRefusedNamingTheElement) {
  TempDir tmp;
  const std::string data = R"("data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA")";
  const std::string buffer = R"({"byteLength":36,"uri":)" + data + "}";
  const std::string fallback = R"({"byteLength":1000000000000000,"extensions":{"EXT_meshopt_compression":{"fallback":true}}})";
  const std::string mesh = R"("meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}])";
  auto doc = [&](const std::string& buffers, const std::string& view, const std::string& accessor,
                 const std::string& rest = R"("meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}])") {
    return R"({"asset":{"version":"2.0"},"buffers":[)" + buffers + R"(],"bufferViews":[)" + view + R"(],"accessors":[)" +
           accessor + "]," + rest + "}";
  };
  const std::string view = R"({"buffer":0,"byteLength":36})";
  const std::string vec3 = R"({"bufferView":0,"componentType":5126,"count":3,"type":"VEC3")";
  auto meshopt = [&](const std::string& length, const std::string& ext) {
    return R"({"buffer":1,"byteLength":)" + length + R"(,"extensions":{"EXT_meshopt_compression":{)" + ext + "}}}";
  };
  std::vector<std::pair<std::string, std::string>> bad = {
      {doc(buffer, view, R"({"bufferView":0,"componentType":5126,"count":3,"type":5})"), "accessor 0 (POSITION of mesh 0 primitive 0): type is not a string"},
      {doc(buffer, view, vec3 + R"(,"normalized":"yes"})"), "normalized is not true or false"},
      {doc(buffer + "," + fallback, meshopt("36", R"("buffer":0,"byteLength":36,"byteStride":12,"count":3,"mode":7)"), vec3 + "}"),
       "buffer view 0 (EXT_meshopt_compression): mode is not a string"},
      {doc(fallback, R"({"buffer":0,"byteLength":10000000000000})", R"({"componentType":5126,"count":3,"type":"VEC3"})",
           R"("meshes":[{"primitives":[{"attributes":{"POSITION":0},"extensions":{"KHR_draco_mesh_compression":{"bufferView":0,"attributes":{"POSITION":0}}}}]}])"),
       "buffer view 0 reads buffer 0, which has no data"},
      {doc(buffer + "," + fallback, meshopt("100000000000000", R"("buffer":0,"byteLength":36,"byteStride":12,"count":3,"mode":"ATTRIBUTES")"), vec3 + "}"),
       "does not fit the view's 100000000000000 bytes"},
      {doc(buffer + "," + fallback, meshopt("36", R"("buffer":1,"byteLength":3000000000,"byteStride":12,"count":3,"mode":"ATTRIBUTES")"), vec3 + "}"),
       "(EXT_meshopt_compression) reads buffer 1, which has no data"},
      {doc(buffer + "," + fallback, meshopt("36000", R"("buffer":0,"byteLength":36,"byteStride":12,"count":3000,"mode":"ATTRIBUTES")"), vec3 + "}"),
       "byteStride 12 x count 3000 is more than 36 compressed bytes can hold"},
      {doc(buffer, R"({"buffer":0,"byteLength":36,"byteStride":4294967308})", vec3 + "}"), "buffer view 0: byteStride 4294967308 is larger than glTF's 252"},
      {doc(buffer, view, R"({"componentType":5126,"count":3000000000,"type":"VEC3"})"), "accessor 0 (POSITION of mesh 0 primitive 0) has no bufferView"},
      {doc(buffer, view, vec3 + "}", mesh + R"(,"nodes":[{"mesh":0,"scale":[1e308,1,1],"translation":[1e308,0,0]}],"scenes":[{"nodes":[0]}])"),
       "element 1: the node transform makes its position non-finite"},
  };
  // A number beyond a double's range (nlohmann's out_of_range, not a parse_error).
  bad.push_back({R"({"asset":{"version":"2.0"},"x":429496729599901e308000000})", "bad JSON (from byte offset 0): number overflow"});
  // Nodes sharing their children: 2^40 instances of one mesh from 40 nodes (glTF's nodes are trees).
  std::string nodes = R"("nodes":[)";
  for (int i = 0; i < 40; ++i) nodes += "{\"children\":[" + std::to_string(i + 1) + "," + std::to_string(i + 1) + "]},";
  nodes += R"({"mesh":0}],"scenes":[{"nodes":[0]}])";
  bad.push_back({doc(buffer, view, vec3 + "}", R"("meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],)" + nodes),
                 "node 40 is reached twice (a second parent or a cycle"});
  struct Count : mt::MeshSink {
    uint64_t delivered = 0;
    void begin(const mt::MeshHeader&) override {}
    void vertices(const mt::InputVertex*, size_t n, uint64_t) override { delivered += n; }
    void triangles(const uint32_t*, size_t) override {}
  };
  for (size_t i = 0; i < bad.size(); ++i) {
    const std::string path = tmp.file("bad" + std::to_string(i) + ".gltf");
    writeFile(path, bad[i].first);
    try {
      Count sink;
      mt::openMesh(path)->read(sink);
      ADD_FAILURE() << i << ": accepted, " << sink.delivered << " vertices";
    } catch (const mt::Error& e) {
      EXPECT_EQ(std::string(e.what()).rfind(path + ": ", 0), 0u) << i << ": " << e.what();
      EXPECT_NE(std::string(e.what()).find(bad[i].second), std::string::npos) << i << ": " << e.what();
    }
  }
  // The document they were made from reads.
  writeFile(tmp.file("good.gltf"), doc(buffer, view, vec3 + "}"));
  Count sink;
  mt::openMesh(tmp.file("good.gltf"))->read(sink);
  EXPECT_EQ(sink.delivered, 3u);
}
