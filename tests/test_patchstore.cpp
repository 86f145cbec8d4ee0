// Patch store: round trips, boundary lists, load/write-back semantics, crash safety.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <sstream>

#include "base/external_sort.h"
#include "base/process.h"
#include "base/size.h"
#include "patchstore/io/ply_writer.h"
#include "patchstore/patch_store.h"
#include "tests/test_support.h"
#include "vpartition/vpartition.h"

namespace mt {
namespace {

namespace fs = std::filesystem;
using test::TempDir;

// A small displaced torus (closed), optionally with round holes and shuffled faces, as PLY.
struct TestMesh {
  std::vector<double> positions;
  std::vector<uint32_t> triangles;
};

TestMesh makeTorus(int rings, int sides, int holes, bool shuffle, uint32_t seed = 1) {
  TestMesh m;
  std::mt19937 rng(seed);
  std::vector<std::array<double, 2>> holeCentres;
  std::uniform_real_distribution<double> uni(0, 1);
  for (int h = 0; h < holes; ++h) holeCentres.push_back({uni(rng) * rings, uni(rng) * sides});
  auto inHole = [&](double i, double j) {
    for (auto& c : holeCentres) {
      double di = std::min(std::abs(i - c[0]), rings - std::abs(i - c[0]));
      double dj = std::min(std::abs(j - c[1]), sides - std::abs(j - c[1]));
      if (di * di + dj * dj < 9.0) return true;
    }
    return false;
  };
  std::vector<int> index(size_t(rings) * sides, -1);
  std::vector<std::array<uint32_t, 3>> faces;
  auto vid = [&](int i, int j) { return size_t((i % rings) * sides + (j % sides)); };
  std::vector<std::array<size_t, 3>> raw;
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < sides; ++j) {
      if (inHole(i + 0.5, j + 0.5)) continue;
      raw.push_back({vid(i, j), vid(i + 1, j), vid(i + 1, j + 1)});
      raw.push_back({vid(i, j), vid(i + 1, j + 1), vid(i, j + 1)});
    }
  for (auto& f : raw)
    for (size_t v : f) index[v] = 0;
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < sides; ++j) {
      if (index[vid(i, j)] < 0) continue;
      index[vid(i, j)] = int(m.positions.size() / 3);
      double u = 2 * M_PI * i / rings, v = 2 * M_PI * j / sides;
      double r = 1 + 0.3 * std::cos(v) + 0.01 * std::sin(7 * u) * std::cos(5 * v);
      const float p[3] = {float(r * std::cos(u)), float(r * std::sin(u)), float(0.3 * std::sin(v))};
      m.positions.insert(m.positions.end(), p, p + 3);  // float-exact, as a float PLY stores it
    }
  if (shuffle) std::shuffle(raw.begin(), raw.end(), rng);
  for (auto& f : raw)
    for (size_t v : f) m.triangles.push_back(uint32_t(index[v]));
  return m;
}

void writePly(const TestMesh& m, const std::string& path) {
  PlyWriter w(path, {});
  for (size_t i = 0; i < m.positions.size(); i += 3) w.addVertex(&m.positions[i]);
  for (size_t i = 0; i < m.triangles.size(); i += 3) w.addTriangle(m.triangles[i], m.triangles[i + 1], m.triangles[i + 2]);
  w.finish();
}

// Triangles as sorted triples of exact coordinates: the multiset a round trip must keep.
using CoordTriangle = std::array<std::array<double, 3>, 3>;
std::vector<CoordTriangle> coordTriangles(const std::vector<double>& pos, const std::vector<uint32_t>& tris) {
  std::vector<CoordTriangle> out;
  for (size_t t = 0; t < tris.size(); t += 3) {
    CoordTriangle c;
    for (int k = 0; k < 3; ++k) c[k] = {pos[3 * tris[t + k]], pos[3 * tris[t + k] + 1], pos[3 * tris[t + k] + 2]};
    std::sort(c.begin(), c.end());
    out.push_back(c);
  }
  std::sort(out.begin(), out.end());
  return out;
}

// Reads a mesh back through the project's own readers into positions + triangles.
struct Collect : MeshSink {
  std::vector<double> positions;
  std::vector<uint32_t> tris;
  void vertices(const InputVertex* v, size_t n, uint64_t) override {
    for (size_t i = 0; i < n; ++i) positions.insert(positions.end(), v[i].p, v[i].p + 3);
  }
  void triangles(const uint32_t* idx, size_t n) override { tris.insert(tris.end(), idx, idx + 3 * n); }
};
// Compares two triangle multisets without printing thousands of coordinates on failure.
::testing::AssertionResult sameTriangles(const std::vector<CoordTriangle>& a, const std::vector<CoordTriangle>& b) {
  if (a == b) return ::testing::AssertionSuccess();
  size_t common = 0;
  for (size_t i = 0, j = 0; i < a.size() && j < b.size();) {
    if (a[i] == b[j]) ++common, ++i, ++j;
    else if (a[i] < b[j]) ++i;
    else ++j;
  }
  return ::testing::AssertionFailure() << "triangle multisets differ: " << a.size() << " vs " << b.size() << " triangles, "
                                       << common << " in common";
}

std::vector<CoordTriangle> readTriangles(const std::string& path) {
  Collect c;
  openMesh(path)->read(c);
  return coordTriangles(c.positions, c.tris);
}

std::unique_ptr<PatchStore> ingestMesh(const std::string& input, const std::string& dir, uint32_t patchTriangles,
                                       uint64_t memory = 64ull << 20) {
  auto assigner = makeGridAssigner(patchTriangles);
  IngestOptions o;
  o.memoryBytes = memory;
  o.progress = false;
  PatchStore::ingest(input, dir, *assigner, o);
  return PatchStore::open(dir);
}

TEST(PatchStore, RoundTripIsExactWithHolesAndShuffledFaces) {
  TempDir tmp;
  TestMesh m = makeTorus(120, 60, 6, true);
  writePly(m, tmp.file("in.ply"));
  ASSERT_TRUE(sameTriangles(readTriangles(tmp.file("in.ply")), coordTriangles(m.positions, m.triangles)));
  auto store = ingestMesh(tmp.file("in.ply"), tmp.file("store"), 500);
  EXPECT_GT(store->patchIds().size(), 8u);
  EXPECT_TRUE(store->check().ok);
  store->exportPly(tmp.file("out.ply"));
  EXPECT_TRUE(sameTriangles(readTriangles(tmp.file("out.ply")), coordTriangles(m.positions, m.triangles)));
  StoreInfo info = store->info();
  EXPECT_EQ(info.triangles, m.triangles.size() / 3);
}

// A version-1 store (fuzz/store, made by an earlier mtstore ingest: plain positions and indices in
// its geometry blocks) still opens, checks and exports; the same surface ingested now (packed
// blocks, version 2) exports the same triangles.
TEST(PatchStore, AVersionOneStoreStillReads) {
  TempDir tmp;
  std::filesystem::copy(std::string(MT_SOURCE_DIR) + "/fuzz/store", tmp.file("v1"));
  {
    std::ifstream manifest(tmp.file("v1/MANIFEST-000001"), std::ios::binary);
    uint32_t head[6];  // the record header (16 bytes), then the snapshot's magic and version
    ASSERT_TRUE(manifest.read(reinterpret_cast<char*>(head), sizeof head));
    ASSERT_EQ(head[5], 1u) << "fuzz/store is no longer a version-1 store";
  }
  auto old = PatchStore::open(tmp.file("v1"));
  EXPECT_TRUE(old->check().ok);
  ASSERT_GT(old->info().triangles, 0u);
  old->exportPly(tmp.file("v1.ply"));
  old.reset();
  auto now = ingestMesh(tmp.file("v1.ply"), tmp.file("v2"), 200);
  EXPECT_TRUE(now->check().ok);
  now->exportPly(tmp.file("v2.ply"));
  EXPECT_TRUE(sameTriangles(readTriangles(tmp.file("v1.ply")), readTriangles(tmp.file("v2.ply"))));
}

TEST(PatchStore, TinyMemoryCapGivesTheSameStore) {
  // Same input under a cap that forces every external sort to spill and the centroid pass to
  // work in chunks: identical patches, so the store does not depend on the cap.
  TempDir tmp;
  TestMesh m = makeTorus(400, 200, 4, true);
  writePly(m, tmp.file("in.ply"));
  auto big = ingestMesh(tmp.file("in.ply"), tmp.file("big"), 800, 1ull << 30);
  auto small = ingestMesh(tmp.file("in.ply"), tmp.file("small"), 800, 600 << 10);
  ASSERT_EQ(big->patchIds(), small->patchIds());
  for (PatchId id : big->patchIds()) {
    Patch a = big->patch(id), b = small->patch(id);
    EXPECT_EQ(a.positions, b.positions);
    EXPECT_EQ(a.triangles, b.triangles);
    ASSERT_EQ(a.boundary.size(), b.boundary.size());
    for (size_t i = 0; i < a.boundary.size(); ++i) {
      EXPECT_EQ(a.boundary[i].local, b.boundary[i].local);
      EXPECT_EQ(a.boundary[i].neighbour, b.boundary[i].neighbour);
      EXPECT_EQ(a.boundary[i].remote, b.boundary[i].remote);
    }
  }
}

// The segment files of a store, concatenated in name order: what "the same store" means below.
std::string segmentBytes(const std::string& dir) {
  std::vector<std::string> names;
  for (auto& e : fs::directory_iterator(dir))
    if (e.path().filename().string().rfind("SEG-", 0) == 0) names.push_back(e.path().string());
  std::sort(names.begin(), names.end());
  std::string all;
  for (auto& n : names) all += test::readFile(n);
  return all;
}

// A mesh as OBJ (no declared vertex count), and with its vertices renumbered at random.
void writeObj(const TestMesh& m, const std::string& path) {
  std::ostringstream o;
  o.precision(9);
  for (size_t i = 0; i < m.positions.size(); i += 3) o << "v " << m.positions[i] << ' ' << m.positions[i + 1] << ' ' << m.positions[i + 2] << '\n';
  for (size_t t = 0; t < m.triangles.size(); t += 3)
    o << "f " << m.triangles[t] + 1 << ' ' << m.triangles[t + 1] + 1 << ' ' << m.triangles[t + 2] + 1 << '\n';
  test::writeFile(path, o.str());
}
TestMesh shuffleVertices(const TestMesh& m, uint32_t seed) {
  std::vector<uint32_t> perm(m.positions.size() / 3);
  for (uint32_t i = 0; i < perm.size(); ++i) perm[i] = i;
  std::mt19937 rng(seed);
  std::shuffle(perm.begin(), perm.end(), rng);
  TestMesh out;
  out.positions.resize(m.positions.size());
  for (uint32_t i = 0; i < perm.size(); ++i)
    for (int a = 0; a < 3; ++a) out.positions[3 * size_t(perm[i]) + a] = m.positions[3 * size_t(i) + a];
  for (uint32_t v : m.triangles) out.triangles.push_back(perm[v]);
  return out;
}

IngestReport ingestIrregular(const std::string& input, const std::string& dir, uint64_t memory) {
  VPartitionOptions vo;
  vo.patchTriangles = 300;
  auto assigner = makeVPartitionAssigner(vo);
  IngestOptions o;
  o.memoryBytes = memory;
  o.progress = false;
  return PatchStore::ingest(input, dir, *assigner, o);
}

TEST(PatchStore, SameStoreBytesWhateverTheCapOrThePath) {
  // Above 512 K triangles the irregular V-partition samples its input (every stride-th face in
  // Morton order). A 1 GiB cap keeps the vertices in RAM (resident path; PLY: Morton codes during
  // the parse; OBJ: after it); 24 MiB forces the chunked path with every
  // sort spilling. Shuffled faces and vertices. All must give the same segment bytes.
  TempDir tmp;
  TestMesh m = shuffleVertices(makeTorus(700, 420, 5, true, 3), 11);
  ASSERT_GT(m.triangles.size() / 3, 520000u);
  writePly(m, tmp.file("in.ply"));
  writeObj(m, tmp.file("in.obj"));
  IngestReport ref = ingestIrregular(tmp.file("in.ply"), tmp.file("resident"), 1ull << 30);
  const std::string bytes = segmentBytes(tmp.file("resident"));
  ASSERT_FALSE(bytes.empty());
  {
    // One thread: the resident path's pipelines, parallel merges (cut into as many pieces as
    // the arena has threads) and sorts give the same bytes.
    tbb::task_arena one(1);
    one.execute([&] { ingestIrregular(tmp.file("in.ply"), tmp.file("one-thread"), 1ull << 30); });
  }
  EXPECT_TRUE(bytes == segmentBytes(tmp.file("one-thread"))) << "one thread";
  IngestReport chunked = ingestIrregular(tmp.file("in.ply"), tmp.file("chunked"), 24ull << 20);
  EXPECT_TRUE(bytes == segmentBytes(tmp.file("chunked"))) << "chunked path";
  EXPECT_EQ(ref.duplicateTriangles, chunked.duplicateTriangles);
  EXPECT_EQ(ref.nonManifoldEdges, chunked.nonManifoldEdges);
  EXPECT_EQ(ref.unreferencedVertices, chunked.unreferencedVertices);
  EXPECT_EQ(ref.assigner, chunked.assigner);
  // OBJ (no declared vertex count) is decimal text, kept as double: the same bytes as a double
  // PLY of the values its text gives.
  ingestIrregular(tmp.file("in.obj"), tmp.file("obj"), 1ull << 30);
  {
    TestMesh parsed = m;
    for (double& x : parsed.positions) {
      std::ostringstream o;
      o.precision(9);
      o << x;
      x = std::stod(o.str());
    }
    PlyWriteOptions d{};
    d.doublePrecision = true;
    PlyWriter w(tmp.file("in-double.ply"), d);
    for (size_t i = 0; i < parsed.positions.size(); i += 3) w.addVertex(&parsed.positions[i]);
    for (size_t i = 0; i < parsed.triangles.size(); i += 3)
      w.addTriangle(parsed.triangles[i], parsed.triangles[i + 1], parsed.triangles[i + 2]);
    w.finish();
  }
  ingestIrregular(tmp.file("in-double.ply"), tmp.file("double"), 1ull << 30);
  const std::string doubleBytes = segmentBytes(tmp.file("double"));
  EXPECT_FALSE(doubleBytes == bytes) << "double positions are stored as double";
  EXPECT_TRUE(doubleBytes == segmentBytes(tmp.file("obj"))) << "OBJ (no declared vertex count)";
  auto store = PatchStore::open(tmp.file("resident"));
  EXPECT_TRUE(store->check().ok);
  store->exportPly(tmp.file("out.ply"));
  EXPECT_TRUE(sameTriangles(readTriangles(tmp.file("out.ply")), coordTriangles(m.positions, m.triangles)));
}

// A binary little-endian PLY written by hand: optional extra vertex byte (a record size the
// in-place face reading must skip correctly), and quads where two consecutive triangles fan from
// one (the reader splits them back into the same two triangles).
void writeBinaryPly(const TestMesh& m, const std::string& path, bool extraVertexByte, bool quads) {
  std::vector<std::vector<uint32_t>> faces;
  for (size_t t = 0; t < m.triangles.size(); t += 3) {
    const uint32_t* a = &m.triangles[t];
    if (quads && t + 3 < m.triangles.size()) {
      const uint32_t* b = a + 3;
      if (a[0] == b[0] && a[2] == b[1]) {
        faces.push_back({a[0], a[1], a[2], b[2]});
        t += 3;
        continue;
      }
    }
    faces.push_back({a[0], a[1], a[2]});
  }
  std::string out = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(m.positions.size() / 3) +
                    "\nproperty float x\nproperty float y\nproperty float z\n" +
                    (extraVertexByte ? "property uchar flags\n" : "") + "element face " + std::to_string(faces.size()) +
                    "\nproperty list uchar int vertex_indices\nend_header\n";
  for (size_t i = 0; i < m.positions.size(); i += 3) {
    float f[3] = {float(m.positions[i]), float(m.positions[i + 1]), float(m.positions[i + 2])};
    out.append(reinterpret_cast<const char*>(f), 12);
    if (extraVertexByte) out.push_back(char(7));
  }
  for (auto& f : faces) {
    out.push_back(char(f.size()));
    for (uint32_t v : f) out.append(reinterpret_cast<const char*>(&v), 4);
  }
  test::writeFile(path, out);
}

TEST(PatchStore, FacesReadInPlaceFromBinaryPlyOrNot) {
  // A binary PLY of triangles has its faces read in place by the resident path (no face copy);
  // an extra vertex property moves the face block, and quads force the copy (the reader fans
  // them). The same triangles give the same store in every case.
  TempDir tmp;
  TestMesh m = makeTorus(300, 200, 3, false, 9);
  writeBinaryPly(m, tmp.file("plain.ply"), false, false);
  writeBinaryPly(m, tmp.file("extra.ply"), true, false);
  writeBinaryPly(m, tmp.file("quads.ply"), false, true);
  auto ingestGrid = [&](const std::string& in, const std::string& out, uint64_t memory) {
    auto assigner = makeGridAssigner(500);
    IngestOptions o;
    o.memoryBytes = memory;
    o.progress = false;
    return PatchStore::ingest(tmp.file(in), tmp.file(out), *assigner, o);
  };
  ingestGrid("plain.ply", "plain", 1ull << 30);
  const std::string bytes = segmentBytes(tmp.file("plain"));
  ingestGrid("extra.ply", "extra", 1ull << 30);
  EXPECT_TRUE(bytes == segmentBytes(tmp.file("extra"))) << "extra vertex property";
  IngestReport q = ingestGrid("quads.ply", "quads", 1ull << 30);
  EXPECT_GT(q.polygons, 1000u);
  EXPECT_TRUE(bytes == segmentBytes(tmp.file("quads"))) << "quads";
  ingestGrid("plain.ply", "chunked", 600 << 10);
  EXPECT_TRUE(bytes == segmentBytes(tmp.file("chunked"))) << "chunked path";
}

// A binary PLY of the mesh with the given vertex layout (normals and colours made up from the
// positions, so that every vertex's are its own).
void writeLayoutPly(const TestMesh& m, const std::string& path, const PlyWriteOptions& o) {
  PlyWriter w(path, o);
  for (size_t i = 0; i < m.positions.size(); i += 3) {
    const double* p = &m.positions[i];
    const double len = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]) + 1e-9;
    const float n[3] = {float(p[0] / len), float(p[1] / len), float(p[2] / len)};
    const uint8_t c[4] = {uint8_t(i % 251), uint8_t(i / 3 % 241), uint8_t(int(p[2] * 1000) & 255), 255};
    w.addVertex(p, o.normals ? n : nullptr, o.colors ? c : nullptr);
  }
  for (size_t i = 0; i < m.triangles.size(); i += 3) w.addTriangle(m.triangles[i], m.triangles[i + 1], m.triangles[i + 2]);
  w.finish();
}

TEST(PatchStore, ChunkedJoinThroughWindowsAndBucketsGivesTheResidentBytes) {
  // The chunked path joins every face with its corners' positions in a sweep with two windows of
  // positions, and the faces the windows miss through buckets of vertex chunks, carried from
  // chunk to chunk (ingest_join.h). With windows of 4096 vertices (IngestOptions::positionBytes),
  // a mesh in scan order goes mostly through the windows (its last ring refers back to its first:
  // window B; 1% of its vertices swapped with far ones: buckets), one with shuffled vertices
  // almost wholly through the buckets (carried over several chunks); normals, colours and double
  // positions are the records' other layouts; a binary PLY's vertex records are read in place when
  // they are vert.bin's, copied when not (an extra property). Every case: the resident path's
  // segment bytes and defect counts.
  TempDir tmp;
  TestMesh ordered = makeTorus(300, 110, 6, false, 4);
  {
    std::mt19937 rng(6);
    std::vector<uint32_t> perm(ordered.positions.size() / 3);
    for (uint32_t i = 0; i < perm.size(); ++i) perm[i] = i;
    for (size_t k = 0; k < perm.size() / 200; ++k) std::swap(perm[rng() % perm.size()], perm[rng() % perm.size()]);
    TestMesh swapped;
    swapped.positions.resize(ordered.positions.size());
    for (uint32_t i = 0; i < perm.size(); ++i)
      for (int a = 0; a < 3; ++a) swapped.positions[3 * size_t(perm[i]) + a] = ordered.positions[3 * size_t(i) + a];
    for (uint32_t v : ordered.triangles) swapped.triangles.push_back(perm[v]);
    ordered = swapped;
  }
  const TestMesh shuffled = shuffleVertices(ordered, 5);
  struct Case {
    const char* name;
    const TestMesh* mesh;
    PlyWriteOptions layout;
    bool extraProperty;
  };
  const Case cases[] = {{"ordered", &ordered, {}, false},
                        {"shuffled", &shuffled, {}, false},
                        {"attributes", &ordered, {false, true, true}, false},
                        {"double-shuffled", &shuffled, {true, false, false}, false},
                        {"extra", &ordered, {}, true}};
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const std::string in = tmp.file(std::string(c.name) + ".ply");
    if (c.extraProperty)
      writeBinaryPly(*c.mesh, in, true, false);
    else
      writeLayoutPly(*c.mesh, in, c.layout);
    auto ingest = [&](const std::string& out, uint64_t memory, uint64_t positions) {
      VPartitionOptions vo;
      vo.patchTriangles = 300;
      auto assigner = makeVPartitionAssigner(vo);
      IngestOptions o;
      o.memoryBytes = memory;
      o.positionBytes = positions;
      o.progress = false;
      return PatchStore::ingest(in, tmp.file(out), *assigner, o);
    };
    const IngestReport ref = ingest(std::string(c.name) + "-resident", 1ull << 30, 0);
    const IngestReport chunked = ingest(std::string(c.name) + "-chunked", 8ull << 20, 4096 * 24);
    EXPECT_EQ(ref.sweptFaces + ref.bucketedFaces, 0u) << "the resident path joins nothing";
    EXPECT_EQ(chunked.sweptFaces + chunked.bucketedFaces, 3 * (c.mesh->triangles.size() / 3)) << "three joins of every face (the sample picks them all below 512 K faces)";
    if (c.mesh == &ordered)
      EXPECT_GT(chunked.sweptFaces, 2 * chunked.bucketedFaces) << "scan order: mostly in the windows";
    else
      EXPECT_GT(chunked.bucketedFaces, 2 * chunked.sweptFaces) << "shuffled: mostly through the buckets";
    EXPECT_GT(chunked.bucketedFaces, 0u);
    EXPECT_EQ(chunked.verticesInPlace, !c.extraProperty);
    EXPECT_TRUE(chunked.facesInPlace);
    EXPECT_TRUE(segmentBytes(tmp.file(std::string(c.name) + "-resident")) == segmentBytes(tmp.file(std::string(c.name) + "-chunked")));
    EXPECT_EQ(ref.duplicateTriangles, chunked.duplicateTriangles);
    EXPECT_EQ(ref.nonManifoldEdges, chunked.nonManifoldEdges);
    EXPECT_EQ(ref.unreferencedVertices, chunked.unreferencedVertices);
  }
}

TEST(PatchStore, DefectsCountedAlikeOnBothPaths) {
  // Degenerate, duplicate and non-manifold faces and unreferenced vertices, counted by the
  // resident path (large cap) as by the chunked one (tiny cap), with the same patches.
  TempDir tmp;
  TestMesh m = makeTorus(200, 100, 2, true, 5);
  const size_t nt = m.triangles.size();
  for (size_t t = 0; t < 300; ++t) {  // duplicates (some reversed) and fins on existing edges
    const size_t f = (t * 7919) % (nt / 3);
    uint32_t a = m.triangles[3 * f], b = m.triangles[3 * f + 1], c = m.triangles[3 * f + 2];
    if (t % 3 == 0) m.triangles.insert(m.triangles.end(), {c, b, a});
    if (t % 3 == 1) m.triangles.insert(m.triangles.end(), {a, b, c});
    if (t % 3 == 2) m.triangles.insert(m.triangles.end(), {a, b, m.triangles[(3 * f + 300) % nt]});
  }
  m.triangles.insert(m.triangles.end(), {m.triangles[0], m.triangles[0], m.triangles[1]});  // degenerate
  for (int i = 0; i < 5; ++i) m.positions.insert(m.positions.end(), {9.0 + i, 9.0, 9.0});  // unreferenced
  writePly(m, tmp.file("in.ply"));
  auto assigner = makeGridAssigner(400);
  IngestOptions o;
  o.progress = false;
  o.memoryBytes = 1ull << 30;
  IngestReport big = PatchStore::ingest(tmp.file("in.ply"), tmp.file("big"), *assigner, o);
  o.memoryBytes = 600 << 10;
  auto assigner2 = makeGridAssigner(400);
  IngestReport small = PatchStore::ingest(tmp.file("in.ply"), tmp.file("small"), *assigner2, o);
  EXPECT_GT(big.duplicateTriangles, 150u);
  EXPECT_GT(big.nonManifoldEdges, 50u);
  EXPECT_EQ(big.degenerateTriangles, 1u);
  EXPECT_EQ(big.unreferencedVertices, 5u);
  EXPECT_EQ(big.duplicateTriangles, small.duplicateTriangles);
  EXPECT_EQ(big.nonManifoldEdges, small.nonManifoldEdges);
  EXPECT_EQ(big.unreferencedVertices, small.unreferencedVertices);
  EXPECT_TRUE(segmentBytes(tmp.file("big")) == segmentBytes(tmp.file("small")));
  EXPECT_TRUE(PatchStore::open(tmp.file("big"))->check().ok);
}

// Every vertex position held by several patches (the torus has no duplicate positions) must be
// listed in each of them, pointing at all the others, symmetrically.
TEST(PatchStore, BoundaryListsAreCompleteAndSymmetric) {
  TempDir tmp;
  TestMesh m = makeTorus(100, 50, 3, false);
  writePly(m, tmp.file("in.ply"));
  auto store = ingestMesh(tmp.file("in.ply"), tmp.file("store"), 300);
  std::map<std::array<double, 3>, std::set<std::pair<PatchId, uint32_t>>> holders;
  std::map<PatchId, Patch> patches;
  for (PatchId id : store->patchIds()) {
    Patch p = store->patch(id);
    for (uint32_t v = 0; v < p.vertexCount(); ++v)
      holders[{p.positions[3 * v], p.positions[3 * v + 1], p.positions[3 * v + 2]}].insert({id, v});
    patches[id] = std::move(p);
  }
  size_t shared = 0;
  for (auto& [pos, hs] : holders) {
    if (hs.size() > 1) ++shared;
    for (auto& [p, v] : hs) {
      std::set<std::pair<PatchId, uint32_t>> listed;
      for (const BoundaryEntry& e : patches[p].boundary)
        if (e.local == v) listed.insert({e.neighbour, e.remote});
      std::set<std::pair<PatchId, uint32_t>> expected = hs;
      expected.erase({p, v});
      EXPECT_EQ(listed, expected) << "patch " << p << " vertex " << v;
    }
  }
  EXPECT_GT(shared, 50u);
  EXPECT_TRUE(store->check().ok);
}

TEST(PatchStore, LoadLocksExactlyTheVerticesSharedWithUnloadedPatches) {
  TempDir tmp;
  TestMesh m = makeTorus(100, 50, 3, true);
  writePly(m, tmp.file("in.ply"));
  auto store = ingestMesh(tmp.file("in.ply"), tmp.file("store"), 300);
  std::vector<PatchId> ids = store->patchIds();
  std::map<std::array<double, 3>, std::set<PatchId>> holders;
  for (PatchId id : ids) {
    Patch p = store->patch(id);
    for (uint32_t v = 0; v < p.vertexCount(); ++v)
      holders[{p.positions[3 * v], p.positions[3 * v + 1], p.positions[3 * v + 2]}].insert(id);
  }
  std::mt19937 rng(7);
  for (int trial = 0; trial < 6; ++trial) {
    std::vector<PatchId> subset;
    for (PatchId id : ids)
      if (rng() % 3 == 0) subset.push_back(id);
    if (subset.empty()) subset.push_back(ids[0]);
    LoadedMesh l = store->load(subset);
    std::set<PatchId> in(subset.begin(), subset.end());
    std::set<std::array<double, 3>> seen;
    for (uint32_t v = 0; v < l.vertexCount(); ++v) {
      std::array<double, 3> pos = {l.positions[3 * v], l.positions[3 * v + 1], l.positions[3 * v + 2]};
      EXPECT_TRUE(seen.insert(pos).second) << "vertex unified twice";
      bool outside = false;
      for (PatchId h : holders[pos]) outside |= !in.count(h);
      EXPECT_EQ(bool(l.locked[v]), outside);
    }
    size_t expectTris = 0;
    for (PatchId id : subset) expectTris += store->meta(id).triangles;
    EXPECT_EQ(l.triangleCount(), expectTris);
  }
}

// Re-partition a loaded region by a different rule (slabs along x) and write it back.
ReplacementMesh repartition(const LoadedMesh& l, int slabs) {
  ReplacementMesh r;
  r.positions = l.positions;
  r.triangles = l.triangles;
  r.origin.resize(l.vertexCount());
  for (uint32_t v = 0; v < l.vertexCount(); ++v) r.origin[v] = v;
  for (uint32_t t = 0; t < l.triangleCount(); ++t) {
    double x = (l.positions[3 * l.triangles[3 * t]] + l.positions[3 * l.triangles[3 * t + 1]] +
                l.positions[3 * l.triangles[3 * t + 2]]) / 3;
    r.triangleCell.push_back(uint64_t(std::clamp(int((x + 1.4) / 2.8 * slabs), 0, slabs - 1)));
  }
  r.level = 1;
  return r;
}

TEST(PatchStore, WriteBackWithANewPartitionKeepsTheSurfaceAndTheLists) {
  TempDir tmp;
  TestMesh m = makeTorus(120, 60, 5, true);
  writePly(m, tmp.file("in.ply"));
  auto store = ingestMesh(tmp.file("in.ply"), tmp.file("store"), 400);
  auto before = coordTriangles(m.positions, m.triangles);
  std::vector<PatchId> ids = store->patchIds();
  std::vector<PatchId> subset(ids.begin(), ids.begin() + ids.size() / 2);
  LoadedMesh l = store->load(subset);
  std::vector<PatchId> created = store->writeBack(l, repartition(l, 5), true);
  EXPECT_FALSE(created.empty());
  for (PatchId id : subset) EXPECT_THROW(store->meta(id), Error);
  for (PatchId id : created) EXPECT_EQ(store->meta(id).level, 1u);
  CheckReport c = store->check();
  for (auto& p : c.problems) ADD_FAILURE() << p;
  store->exportPly(tmp.file("a.ply"));
  EXPECT_TRUE(sameTriangles(readTriangles(tmp.file("a.ply")), before));
  // Reopen: the update is durable; a second write-back over old and new patches still holds.
  store.reset();
  store = PatchStore::open(tmp.file("store"));
  ids = store->patchIds();
  std::vector<PatchId> second;
  for (size_t i = 0; i < ids.size(); i += 2) second.push_back(ids[i]);
  LoadedMesh l2 = store->load(second);
  store->writeBack(l2, repartition(l2, 3), false);
  store->sync();
  EXPECT_TRUE(store->check().ok);
  store->exportPly(tmp.file("b.ply"));
  EXPECT_TRUE(sameTriangles(readTriangles(tmp.file("b.ply")), before));
}

// A replacement split into a few cells (their keys found as they are met) and into more than 64
// (found by sorting them all): either way one new patch per key, in key order, and the surface kept.
TEST(PatchStore, WriteBackIntoManyCellsMakesOnePatchPerKeyInKeyOrder) {
  TempDir tmp;
  TestMesh m = makeTorus(120, 60, 5, true);
  writePly(m, tmp.file("in.ply"));
  auto store = ingestMesh(tmp.file("in.ply"), tmp.file("store"), 400);
  const auto before = coordTriangles(m.positions, m.triangles);
  for (int slabs : {5, 100}) {
    LoadedMesh l = store->load(store->patchIds());
    const ReplacementMesh r = repartition(l, slabs);
    const std::set<uint64_t> keys(r.triangleCell.begin(), r.triangleCell.end());
    if (slabs == 100) {
      ASSERT_GT(keys.size(), 64u);
    }
    const std::vector<PatchId> created = store->writeBack(l, r, true);
    ASSERT_EQ(created.size(), keys.size()) << slabs << " slabs";
    auto key = keys.begin();
    for (PatchId id : created) EXPECT_EQ(store->meta(id).cell, *key++) << "patch " << id;
    EXPECT_TRUE(store->check().ok);
    store->exportPly(tmp.file("out.ply"));
    EXPECT_TRUE(sameTriangles(readTriangles(tmp.file("out.ply")), before)) << slabs << " slabs";
  }
}

// Two neighbouring regions loaded at once and written back in the opposite order: the second
// write-back's view of its outside neighbours is stale, and must be refreshed, not trusted.
TEST(PatchStore, InterleavedWriteBacksOfNeighbouringRegions) {
  TempDir tmp;
  TestMesh m = makeTorus(120, 60, 4, true);
  writePly(m, tmp.file("in.ply"));
  auto store = ingestMesh(tmp.file("in.ply"), tmp.file("store"), 300);
  std::vector<PatchId> ids = store->patchIds();
  std::vector<PatchId> a, b;
  for (PatchId id : ids) (store->meta(id).bounds.lo[0] + store->meta(id).bounds.hi[0] < 0 ? a : b).push_back(id);
  LoadedMesh la = store->load(a), lb = store->load(b);
  ASSERT_FALSE(la.external.empty());
  store->writeBack(lb, repartition(lb, 3));
  store->writeBack(la, repartition(la, 4));
  store->sync();
  CheckReport c = store->check();
  for (auto& p : c.problems) ADD_FAILURE() << p;
  store->exportPly(tmp.file("x.ply"));
  EXPECT_TRUE(sameTriangles(readTriangles(tmp.file("x.ply")), coordTriangles(m.positions, m.triangles)));
}

TEST(PatchStore, WriteBackRefusesToMoveOrDropALockedVertex) {
  TempDir tmp;
  TestMesh m = makeTorus(60, 30, 0, false);
  writePly(m, tmp.file("in.ply"));
  auto store = ingestMesh(tmp.file("in.ply"), tmp.file("store"), 200);
  std::vector<PatchId> ids = store->patchIds();
  LoadedMesh l = store->load({ids[0]});
  ASSERT_FALSE(l.external.empty());
  ReplacementMesh moved = repartition(l, 2);
  moved.positions[3 * l.external[0].vertex] += 1e-3;
  EXPECT_THROW(store->writeBack(l, moved), Error);
  EXPECT_TRUE(store->check().ok);
}

// Fault injection: fail every write, fsync and rename of a write-back in turn; after each
// failure the reopened store exports either exactly the old surface with the old patches, or the
// new patches — never a mix, never a broken store.
TEST(PatchStore, EveryFailurePointLeavesTheOldOrTheNewStore) {
  TempDir tmp;
  TestMesh m = makeTorus(80, 40, 2, true);
  writePly(m, tmp.file("in.ply"));
  ingestMesh(tmp.file("in.ply"), tmp.file("base"), 300).reset();
  auto surface = coordTriangles(m.positions, m.triangles);
  std::vector<PatchId> oldIds = PatchStore::open(tmp.file("base"))->patchIds();

  auto attempt = [&](FaultInjectionEnv::Op op, int64_t n, FaultInjectionEnv& env) {
    fs::remove_all(tmp.file("s"));
    fs::copy(tmp.file("base"), tmp.file("s"), fs::copy_options::recursive);
    auto store = PatchStore::open(tmp.file("s"), &env);
    env.failAfter(op, n);
    bool failed = false;
    try {
      std::vector<PatchId> ids = store->patchIds();
      LoadedMesh l = store->load(std::vector<PatchId>(ids.begin(), ids.begin() + ids.size() / 2));
      store->writeBack(l, repartition(l, 4), true);
      for (int i = 0; i < 3; ++i) store->putBlob("x", std::string(400000, char('a' + i)));  // grow the log
      store->sync();
    } catch (const Error&) {
      failed = true;
    }
    store.reset();
    return failed;
  };
  FaultInjectionEnv counting(Env::Default());
  ASSERT_FALSE(attempt(FaultInjectionEnv::Op::Write, -1, counting));
  const int64_t counts[3] = {counting.writes, counting.syncs, counting.renames};
  const FaultInjectionEnv::Op ops[3] = {FaultInjectionEnv::Op::Write, FaultInjectionEnv::Op::Sync, FaultInjectionEnv::Op::Rename};
  int failures = 0;
  for (int o = 0; o < 3; ++o)
    for (int64_t n = 1; n <= counts[o]; ++n) {
      FaultInjectionEnv env(Env::Default());
      bool failed = attempt(ops[o], n, env);
      failures += failed;
      auto store = PatchStore::open(tmp.file("s"));
      CheckReport c = store->check();
      ASSERT_TRUE(c.ok) << "op " << o << " n " << n << ": " << (c.problems.empty() ? "" : c.problems[0]);
      std::vector<PatchId> ids = store->patchIds();
      bool isOld = ids == oldIds;
      bool isNew = !isOld && ids.front() != oldIds.front();
      EXPECT_TRUE(isOld || isNew) << "op " << o << " n " << n;
      store->exportPly(tmp.file("e.ply"));
      EXPECT_TRUE(sameTriangles(readTriangles(tmp.file("e.ply")), surface)) << "op " << o << " n " << n;
    }
  EXPECT_GT(failures, 3);
}

TEST(PatchStore, FailedIngestLeavesNothingUnderTheFinalName) {
  TempDir tmp;
  TestMesh m = makeTorus(60, 30, 0, false);
  writePly(m, tmp.file("in.ply"));
  for (auto op : {FaultInjectionEnv::Op::Write, FaultInjectionEnv::Op::Sync, FaultInjectionEnv::Op::Rename}) {
    FaultInjectionEnv env(Env::Default());
    env.failAfter(op, 1);
    auto assigner = makeGridAssigner(200);
    IngestOptions o;
    o.progress = false;
    EXPECT_THROW(PatchStore::ingest(tmp.file("in.ply"), tmp.file("store"), *assigner, o, &env), Error);
    EXPECT_FALSE(fs::exists(tmp.file("store")));
    for (auto& e : fs::directory_iterator(tmp.path())) EXPECT_EQ(e.path().filename().string().find("store"), std::string::npos) << e.path();
  }
}

TEST(PatchStore, CorruptedBlockIsReportedWithPatchAndOffset) {
  TempDir tmp;
  TestMesh m = makeTorus(60, 30, 0, false);
  writePly(m, tmp.file("in.ply"));
  ingestMesh(tmp.file("in.ply"), tmp.file("store"), 200).reset();
  std::string seg;
  for (auto& e : fs::directory_iterator(tmp.file("store")))
    if (e.path().filename().string().rfind("SEG-", 0) == 0) seg = e.path();
  ASSERT_FALSE(seg.empty());
  std::string bytes = test::readFile(seg);
  bytes[bytes.size() / 2] ^= 0x5A;
  test::writeFile(seg, bytes);
  auto store = PatchStore::open(tmp.file("store"));
  CheckReport c = store->check();
  ASSERT_FALSE(c.ok);
  EXPECT_NE(c.problems[0].find("checksum mismatch"), std::string::npos) << c.problems[0];
  EXPECT_NE(c.problems[0].find("patch "), std::string::npos);
  EXPECT_NE(c.problems[0].find("byte offset"), std::string::npos);
}

// The comparison sorter of the chunked ingest path, spilling in the foreground or, while the next
// buffer fills, in the background: both give every record once, in order, through many runs.
TEST(ExternalSorter, BackgroundSpillGivesTheSameOrderThroughManyRuns) {
  TempDir tmp;
  struct Rec {
    uint64_t key;
    uint32_t id;
  };
  struct Less {
    bool operator()(const Rec& a, const Rec& b) const { return a.key != b.key ? a.key < b.key : a.id < b.id; }
  };
  std::mt19937_64 rng(5);
  std::vector<Rec> input(200000);
  for (uint32_t i = 0; i < input.size(); ++i) input[i] = {rng() % 5000, i};  // many equal keys
  std::vector<Rec> expected = input;
  std::sort(expected.begin(), expected.end(), Less{});
  for (bool background : {false, true}) {
    ExternalSorter<Rec, Less> sorter(tmp.file(background ? "bg" : "fg"), 64 << 10, Less{}, background);
    for (const Rec& r : input) sorter.add(r);
    EXPECT_EQ(sorter.count(), input.size());
    // 200000 records of 16 bytes through a 64 KiB budget: dozens of runs on disk (then merged a
    // few at a time before the last merge: the bounded fan-in).
    size_t runs = 0;
    for (auto& e : fs::directory_iterator(tmp.path())) runs += e.path().filename().string().rfind(background ? "bg.run" : "fg.run", 0) == 0;
    EXPECT_GT(runs, 40u) << (background ? "background" : "foreground");
    sorter.finish();
    std::vector<Rec> got;
    Rec r;
    while (sorter.next(r)) got.push_back(r);
    ASSERT_EQ(got.size(), expected.size());
    for (size_t i = 0; i < got.size(); ++i) {
      ASSERT_EQ(got[i].key, expected[i].key) << i;
      ASSERT_EQ(got[i].id, expected[i].id) << i;
    }
  }
}

// TempWriter (base/temp_file.h): small writes go through its buffer, one of at least a buffer goes
// from the caller's memory, writeGather's pieces (more than one pwritev takes, empty ones among
// them) from theirs; in every mix the file holds exactly the bytes given, in order. Run again with
// MT_SCRATCH_DIRECT=1 (PatchStore.DirectScratchGivesTheSameStores), where all of it is buffered.
TEST(TempWriter, EveryMixOfWritesAndPiecesGivesTheBytesInOrder) {
  TempDir tmp;
  std::mt19937_64 rng(17);
  std::vector<char> source(3 << 20);
  for (char& c : source) c = char(rng());
  std::string expected;
  const std::string path = tmp.file("w.bin");
  {
    TempWriter w(path, 64 << 10);  // the smallest buffer it takes
    size_t at = 0;
    auto take = [&](size_t n) {
      const char* p = source.data() + at;
      expected.append(p, n);
      at = (at + n) % (source.size() - (1 << 20));
      return p;
    };
    for (int round = 0; round < 40; ++round) {
      const int kind = int(rng() % 4);
      if (kind == 0) {  // a small write
        const size_t n = rng() % 5000;
        w.write(take(n), n);
      } else if (kind == 1) {  // a write of a buffer or more
        const size_t n = (64 << 10) + rng() % (300 << 10);
        w.write(take(n), n);
      } else {  // pieces: up to 2500 of them (IOV_MAX is 1024), sizes 0 to 300 bytes, or some large
        std::vector<struct iovec> pieces(rng() % 2500);
        for (auto& v : pieces) {
          const size_t n = kind == 3 && rng() % 50 == 0 ? size_t(rng() % (200 << 10)) : size_t(rng() % 300);
          v = {const_cast<char*>(take(n)), n};
        }
        w.writeGather(pieces.data(), pieces.size());
      }
    }
    // Pieces that are all empty, after buffered bytes: nothing written, no error.
    w.write(take(3), 3);
    std::vector<struct iovec> empty(3, {source.data(), 0});
    w.writeGather(empty.data(), empty.size());
    EXPECT_EQ(w.bytes(), expected.size());
    w.close();
  }
  std::ifstream in(path, std::ios::binary);
  const std::string got((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_EQ(got.size(), expected.size());
  EXPECT_TRUE(got == expected) << "the file's bytes differ from what was written";
}

// Descriptors this process has open now.
size_t openDescriptors() {
  size_t n = 0;
  for (auto& e : fs::directory_iterator("/proc/self/fd")) n += !e.path().empty();
  return n;
}

// The descriptors a merge may use: the soft limit is raised towards the hard one (to at most
// 65536; a soft limit already higher is kept), and the fan-in follows from what it is.
TEST(ExternalSorter, TheFanInFollowsTheRaisedDescriptorLimit) {
  rlimit before{};
  ASSERT_EQ(getrlimit(RLIMIT_NOFILE, &before), 0);
  const uint64_t limit = openFileLimit();
  rlimit r{};
  ASSERT_EQ(getrlimit(RLIMIT_NOFILE, &r), 0);
  if (r.rlim_cur != RLIM_INFINITY) {
    EXPECT_EQ(uint64_t(r.rlim_cur), limit) << "the limit reported is the one in force";
  }
  EXPECT_GE(r.rlim_cur, before.rlim_cur) << "never lowered";
  const uint64_t hard = r.rlim_max == RLIM_INFINITY ? UINT64_MAX : uint64_t(r.rlim_max);
  EXPECT_GE(limit, std::min<uint64_t>(hard, 65536)) << "raised to the hard limit, or 65536";
  EXPECT_GE(maxMergeFanIn(), 128u);
  EXPECT_LE(maxMergeFanIn(), 1024u);
  // Eight descriptors a run, 256 for everything else.
  if (limit >= 256 + 8 * 1024) {
    EXPECT_EQ(maxMergeFanIn(), 1024u);
  }
  if (limit >= 256 + 8 * 128) {
    EXPECT_LE(256 + 8 * maxMergeFanIn(), limit);
  }
  EXPECT_EQ(mergeFanIn(uint64_t(2) << 30), maxMergeFanIn());
}

// The bounded fan-in (base/external_sort.h): hundreds of runs through a budget that gives a merge
// room for only a few readers at a time are merged a few at a time first, into the same order,
// with few files open while the result is read, and nothing left on disk after.
TEST(ExternalSorter, ManyRunsMergeInBoundedFanInToTheSameOrder) {
  TempDir tmp;
  EXPECT_EQ(mergeFanIn(64 << 10), 3u);
  EXPECT_EQ(mergeFanIn(1 << 30), maxMergeFanIn());
  EXPECT_EQ(mergeFanIn(0), 2u);
  struct Rec {
    uint64_t key;
    uint32_t id;
    uint32_t pad;
  };
  std::mt19937_64 rng(11);
  std::vector<Rec> input(300000);
  for (uint32_t i = 0; i < input.size(); ++i) input[i] = {rng() % 3000, i, 0};  // many equal keys
  std::vector<Rec> stable = input;
  std::stable_sort(stable.begin(), stable.end(), [](const Rec& a, const Rec& b) { return a.key < b.key; });
  auto countFiles = [&] {
    size_t n = 0;
    for (auto& e : fs::directory_iterator(tmp.path())) n += !e.path().empty();
    return n;
  };
  const size_t before = openDescriptors();
  {
    // Comparison sorter, a total order: 300000 x 16 bytes through 48 KiB, ~100 runs, fan-in 2.
    struct Less {
      bool operator()(const Rec& a, const Rec& b) const { return a.key != b.key ? a.key < b.key : a.id < b.id; }
    };
    ExternalSorter<Rec, Less> sorter(tmp.file("cmp"), 48 << 10);
    for (const Rec& r : input) sorter.add(r);
    EXPECT_GT(countFiles(), 90u);
    sorter.finish();
    EXPECT_LE(countFiles(), mergeFanIn(48 << 10));
    EXPECT_LE(openDescriptors(), before + 2 * mergeFanIn(48 << 10)) << "a reader and a hole-punching descriptor per run";
    Rec r;
    size_t i = 0;
    while (sorter.next(r)) {
      ASSERT_LT(i, stable.size());
      ASSERT_EQ(r.key, stable[i].key) << i;
      ASSERT_EQ(r.id, stable[i].id) << i;  // the total order is the stable one here
      if (++i == stable.size() / 2) {
        EXPECT_LE(openDescriptors(), before + 2 * mergeFanIn(48 << 10)) << "while the last merge reads";
      }
    }
    EXPECT_EQ(i, stable.size());
    EXPECT_EQ(countFiles(), 0u);
  }
  {
    // Stable key sorter: equal keys keep their input order through the extra passes; read whole
    // and in parts.
    struct KeyOf {
      uint64_t operator()(const Rec& r) const { return r.key; }
    };
    // 96 KiB: runs of 3072 records (98 of them), fan-in 5: a pass over all (98 -> 20), then one
    // over the first 19 only (20 -> 5, the last run kept as it is); in 3 parts, down to 2 runs.
    EXPECT_EQ(mergeFanIn(96 << 10), 5u);
    for (size_t parts : {size_t(0), size_t(3)}) {
      StableKeySorter<Rec, KeyOf> sorter(tmp.file("key"), 96 << 10, KeyOf{}, 12);
      for (const Rec& r : input) sorter.add(r);
      EXPECT_GT(countFiles(), 90u);
      sorter.finish();
      std::vector<Rec> got(stable.size());
      if (parts == 0) {
        Rec r;
        size_t i = 0;
        while (sorter.next(r)) {
          ASSERT_LT(i, got.size());
          got[i++] = r;
          if (i == 1) {
            EXPECT_EQ(countFiles(), mergeFanIn(96 << 10));
            EXPECT_LE(openDescriptors(), before + 2 * mergeFanIn(96 << 10)) << "while the last merge reads";
          }
        }
        EXPECT_EQ(i, got.size());
      } else {
        std::atomic<size_t> total{0}, open{0};
        sorter.mergeInParts(parts, [&](size_t, uint64_t first, const auto& nextRecord) {
          Rec r;
          uint64_t at = first;
          while (nextRecord(r)) {
            ASSERT_LT(at, got.size());
            got[at++] = r;
            if (++total == got.size() / 2) open = openDescriptors();
          }
        });
        EXPECT_EQ(total.load(), got.size());
        EXPECT_GT(open.load(), before);
        EXPECT_LE(open.load(), before + 2 * parts * std::max<size_t>(2, mergeFanIn(96 << 10) / parts)) << "every part's merge";
      }
      for (size_t i = 0; i < got.size(); ++i) {
        ASSERT_EQ(got[i].key, stable[i].key) << i << " parts " << parts;
        ASSERT_EQ(got[i].id, stable[i].id) << i << " parts " << parts;
      }
      EXPECT_EQ(countFiles(), 0u);
    }
  }
  // Group sorter: every key's records, whole and in Less order, over two passes; with a Less that
  // orders nothing (the ingest's addition order), the runs' order alone puts a group's records in
  // input order, so the extra passes must gather them run by run. 64 KiB: fan-in 2 (44 bytes a
  // record held), ~200 runs.
  auto groups = [&](auto less, const char* name) {
    KeyGroupSorter<Rec, decltype(less)> sorter(tmp.file(name), 64 << 10, less);
    std::vector<uint64_t> keys(input.size());
    for (size_t i = 0; i < input.size(); ++i) keys[i] = input[i].key;
    for (size_t at = 0; at < input.size(); at += 1000) sorter.addBatch(keys.data() + at, input.data() + at, std::min<size_t>(1000, input.size() - at));
    EXPECT_GT(countFiles(), 90u) << name;
    sorter.finish();
    EXPECT_EQ(countFiles(), 2u) << name;
    for (int pass = 0; pass < 2; ++pass) {
      if (pass) sorter.rewind(true);
      uint64_t key;
      std::vector<Rec> group;
      size_t i = 0;
      while (sorter.nextGroup(key, group)) {
        for (const Rec& r : group) {
          ASSERT_LT(i, stable.size());
          ASSERT_EQ(key, stable[i].key) << i << " " << name;
          ASSERT_EQ(r.id, stable[i].id) << i << " " << name;  // by key, then input order (= id order)
          ++i;
        }
      }
      EXPECT_EQ(i, stable.size()) << "pass " << pass << " " << name;
    }
  };
  struct ById {
    bool operator()(const Rec& a, const Rec& b) const { return a.id < b.id; }
  };
  struct AsAdded {
    bool operator()(const Rec&, const Rec&) const { return false; }
  };
  groups(ById{}, "byid");
  groups(AsAdded{}, "asadded");
}

TEST(ExternalSorter, BackgroundSpillErrorIsReportedNotLost) {
  // The scratch directory does not exist: the background spill fails, and the error reaches the
  // producer (at the next spill or at finish) naming the file.
  TempDir tmp;
  ExternalSorter<uint64_t, std::less<uint64_t>> sorter(tmp.file("missing/dir/s"), 8 << 10, {}, true);
  try {
    for (uint64_t i = 0; i < 100000; ++i) sorter.add(i * 7919 % 100003);
    sorter.finish();
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("missing/dir/s.run"), std::string::npos) << e.what();
  }
}

TEST(PatchStore, ParseSize) {
  EXPECT_EQ(parseSize("256M"), 256ull << 20);
  EXPECT_EQ(parseSize("4G"), 4ull << 30);
  EXPECT_EQ(parseSize("512MiB"), 512ull << 20);
  EXPECT_EQ(parseSize("1000"), 1000u);
  EXPECT_THROW(parseSize("lots"), Error);
  EXPECT_THROW(parseSize("5X"), Error);
  EXPECT_THROW(parseSize("-1M"), Error);
}

}  // namespace
}  // namespace mt
