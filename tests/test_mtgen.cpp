// Tests of mtgen, the procedural scan generator: counts, topology (closed, manifold, holes as
// boundary loops, components), shuffle, determinism, density, normals, every output format, and
// bad options. The output is read back with small parsers written here, independent of the
// project's readers.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <map>
#include <numeric>
#include <set>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

#include "tests/test_support.h"
#include "testing/scan_generator.h"

namespace {

using mt::test::fileExists;
using mt::test::readFile;
using mt::test::runTool;
using mt::test::TempDir;
using Triangle = std::array<uint32_t, 3>;

struct Mesh {
  std::vector<std::array<double, 3>> positions;
  std::vector<std::array<float, 3>> normals;
  std::vector<std::array<uint8_t, 4>> colors;
  std::vector<Triangle> triangles;
  bool doubleCoordinates = false;
  std::string vertexBytes;  // binary PLY only: the raw vertex section
};

// ---- tiny parsers -----------------------------------------------------------------------------

Mesh parseBinaryPly(const std::string& bytes) {
  Mesh mesh;
  size_t headerEnd = bytes.find("end_header\n");
  if (headerEnd == std::string::npos) throw std::runtime_error("no end_header");
  std::istringstream header(bytes.substr(0, headerEnd));
  std::string line, element;
  uint64_t vertices = 0, faces = 0;
  std::vector<std::pair<std::string, std::string>> vertexProps;  // (type, name)
  std::string indexType;
  while (std::getline(header, line)) {
    std::istringstream ls(line);
    std::string word;
    ls >> word;
    if (word == "format" ) {
      std::string f;
      ls >> f;
      if (f != "binary_little_endian") throw std::runtime_error("not binary LE: " + f);
    } else if (word == "element") {
      ls >> element;
      (element == "vertex" ? vertices : faces) = 0;
      ls >> (element == "vertex" ? vertices : faces);
    } else if (word == "property") {
      std::string type, name;
      ls >> type;
      if (type == "list") {
        std::string countType;
        ls >> countType >> indexType;
        if (countType != "uchar") throw std::runtime_error("face count type");
      } else {
        ls >> name;
        if (element == "vertex") vertexProps.push_back({type, name});
      }
    }
  }
  size_t at = headerEnd + std::strlen("end_header\n");
  size_t recordSize = 0;
  for (auto& [type, name] : vertexProps) recordSize += type == "double" ? 8 : type == "float" ? 4 : 1;
  mesh.vertexBytes = bytes.substr(at, recordSize * vertices);
  for (uint64_t v = 0; v < vertices; ++v) {
    std::array<double, 3> p{};
    std::array<float, 3> n{};
    std::array<uint8_t, 4> c{};
    for (auto& [type, name] : vertexProps) {
      double value = 0;
      if (type == "double") {
        std::memcpy(&value, &bytes.at(at + 7) - 7, 8);
        at += 8;
      } else if (type == "float") {
        float f;
        std::memcpy(&f, &bytes.at(at + 3) - 3, 4);
        value = f;
        at += 4;
      } else {
        value = uint8_t(bytes.at(at));
        at += 1;
      }
      if (name == "x") p[0] = value;
      if (name == "y") p[1] = value;
      if (name == "z") p[2] = value;
      if (name == "nx") n[0] = float(value);
      if (name == "ny") n[1] = float(value);
      if (name == "nz") n[2] = float(value);
      if (name == "red") c[0] = uint8_t(value);
      if (name == "green") c[1] = uint8_t(value);
      if (name == "blue") c[2] = uint8_t(value);
      if (name == "alpha") c[3] = uint8_t(value);
      if (name == "x") mesh.doubleCoordinates = type == "double";
    }
    mesh.positions.push_back(p);
    mesh.normals.push_back(n);
    mesh.colors.push_back(c);
  }
  for (uint64_t f = 0; f < faces; ++f) {
    if (uint8_t(bytes.at(at)) != 3) throw std::runtime_error("face is not a triangle");
    Triangle t;
    std::memcpy(t.data(), &bytes.at(at + 12) - 11, 12);
    at += 13;
    mesh.triangles.push_back(t);
  }
  if (at != bytes.size()) throw std::runtime_error("trailing bytes");
  return mesh;
}

Mesh parseAsciiPly(const std::string& text, bool normals, bool colors) {
  Mesh mesh;
  std::istringstream in(text);
  std::string line;
  uint64_t vertices = 0, faces = 0;
  while (std::getline(in, line) && line != "end_header") {
    std::istringstream ls(line);
    std::string word, element;
    ls >> word;
    if (word == "element") {
      ls >> element;
      ls >> (element == "vertex" ? vertices : faces);
    }
  }
  for (uint64_t v = 0; v < vertices; ++v) {
    float x, y, z;
    in >> x >> y >> z;
    mesh.positions.push_back({x, y, z});
    if (normals) {
      std::array<float, 3> n;
      in >> n[0] >> n[1] >> n[2];
      mesh.normals.push_back(n);
    }
    if (colors) {
      unsigned r, g, b, a;
      in >> r >> g >> b >> a;
      mesh.colors.push_back({uint8_t(r), uint8_t(g), uint8_t(b), uint8_t(a)});
    }
  }
  for (uint64_t f = 0; f < faces; ++f) {
    unsigned n;
    Triangle t;
    in >> n >> t[0] >> t[1] >> t[2];
    if (n != 3) throw std::runtime_error("not a triangle");
    mesh.triangles.push_back(t);
  }
  if (!in) throw std::runtime_error("ascii PLY truncated");
  return mesh;
}

Mesh parseObj(const std::string& text) {
  Mesh mesh;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::string word;
    ls >> word;
    if (word == "v") {
      float x, y, z;
      ls >> x >> y >> z;
      mesh.positions.push_back({x, y, z});
    } else if (word == "vn") {
      std::array<float, 3> n;
      ls >> n[0] >> n[1] >> n[2];
      mesh.normals.push_back(n);
    } else if (word == "f") {
      Triangle t;
      for (auto& index : t) {
        std::string corner;
        ls >> corner;
        index = uint32_t(std::stoul(corner.substr(0, corner.find('/')))) - 1;
      }
      mesh.triangles.push_back(t);
    }
  }
  return mesh;
}

Mesh parseOff(const std::string& text) {
  Mesh mesh;
  std::istringstream in(text);
  std::string magic;
  uint64_t vertices, faces, edges;
  in >> magic >> vertices >> faces >> edges;
  if (magic != "OFF") throw std::runtime_error("not OFF");
  for (uint64_t v = 0; v < vertices; ++v) {
    float x, y, z;
    in >> x >> y >> z;
    mesh.positions.push_back({x, y, z});
  }
  for (uint64_t f = 0; f < faces; ++f) {
    unsigned n;
    Triangle t;
    in >> n >> t[0] >> t[1] >> t[2];
    mesh.triangles.push_back(t);
  }
  if (!in) throw std::runtime_error("OFF truncated");
  return mesh;
}

// STL: a triangle soup, returned as corner positions (9 floats per triangle).
std::vector<std::array<float, 9>> parseStl(const std::string& text) {
  std::vector<std::array<float, 9>> soup;
  std::istringstream in(text);
  std::string word;
  std::array<float, 9> tri{};
  int corner = 0;
  while (in >> word) {
    if (word == "vertex") {
      in >> tri[3 * corner] >> tri[3 * corner + 1] >> tri[3 * corner + 2];
      if (++corner == 3) soup.push_back(tri), corner = 0;
    }
  }
  return soup;
}

// ---- topology ---------------------------------------------------------------------------------

uint64_t edgeKey(uint32_t a, uint32_t b) { return (uint64_t(std::min(a, b)) << 32) | std::max(a, b); }

struct Topology {
  uint64_t boundaryEdges = 0, nonManifoldEdges = 0, inconsistentlyOriented = 0;
  uint64_t boundaryLoops = 0;
  bool boundaryVerticesRegular = true;  // every boundary vertex has exactly 2 boundary edges
  uint64_t nonManifoldVertices = 0;     // faces around the vertex are not one fan
  uint64_t unreferencedVertices = 0, outOfRange = 0, repeatedIndex = 0, zeroArea = 0;
  uint64_t components = 0;
};

struct UnionFind {
  std::vector<uint32_t> parent;
  explicit UnionFind(size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0u); }
  uint32_t find(uint32_t x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  }
  void join(uint32_t a, uint32_t b) { parent[find(a)] = find(b); }
};

Topology analyze(const Mesh& mesh) {
  Topology t;
  const size_t n = mesh.positions.size();
  std::unordered_map<uint64_t, int> undirected;
  std::unordered_map<uint64_t, int> directed;
  std::vector<uint8_t> used(n, 0);
  std::vector<std::array<uint32_t, 3>> links;  // (vertex, opposite a, opposite b)
  UnionFind uf(n);
  for (const Triangle& tri : mesh.triangles) {
    bool ok = true;
    for (uint32_t v : tri)
      if (v >= n) ++t.outOfRange, ok = false;
    if (!ok) continue;
    if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2]) {
      ++t.repeatedIndex;
      continue;
    }
    const auto& a = mesh.positions[tri[0]];
    const auto& b = mesh.positions[tri[1]];
    const auto& c = mesh.positions[tri[2]];
    double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    double cr[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
    if (cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2] == 0) ++t.zeroArea;
    for (int k = 0; k < 3; ++k) {
      uint32_t u = tri[k], v = tri[(k + 1) % 3], w = tri[(k + 2) % 3];
      ++undirected[edgeKey(u, v)];
      ++directed[(uint64_t(u) << 32) | v];
      used[u] = 1;
      uf.join(u, v);
      links.push_back({u, v, w});
    }
  }
  for (auto& [key, count] : directed)
    if (count > 1) ++t.inconsistentlyOriented;
  std::unordered_map<uint32_t, std::vector<uint32_t>> boundaryAdjacency;
  for (auto& [key, count] : undirected) {
    if (count > 2) ++t.nonManifoldEdges;
    if (count == 1) {
      ++t.boundaryEdges;
      uint32_t a = uint32_t(key >> 32), b = uint32_t(key);
      boundaryAdjacency[a].push_back(b);
      boundaryAdjacency[b].push_back(a);
    }
  }
  // Boundary loops: connected components of the boundary-edge graph (each a cycle when every
  // boundary vertex has degree 2).
  std::set<uint32_t> seen;
  for (auto& [v, adjacent] : boundaryAdjacency) {
    if (adjacent.size() != 2) t.boundaryVerticesRegular = false;
    if (seen.count(v)) continue;
    ++t.boundaryLoops;
    std::vector<uint32_t> stack{v};
    seen.insert(v);
    while (!stack.empty()) {
      uint32_t x = stack.back();
      stack.pop_back();
      for (uint32_t y : boundaryAdjacency[x])
        if (seen.insert(y).second) stack.push_back(y);
    }
  }
  // Vertex manifoldness: the link edges (opposite each vertex) must form one path or cycle.
  std::sort(links.begin(), links.end());
  for (size_t i = 0; i < links.size();) {
    size_t j = i;
    while (j < links.size() && links[j][0] == links[i][0]) ++j;
    std::map<uint32_t, std::vector<uint32_t>> adjacency;
    for (size_t k = i; k < j; ++k) {
      adjacency[links[k][1]].push_back(links[k][2]);
      adjacency[links[k][2]].push_back(links[k][1]);
    }
    std::set<uint32_t> reached{adjacency.begin()->first};
    std::vector<uint32_t> stack{adjacency.begin()->first};
    bool degreeOk = true;
    for (auto& [node, adj] : adjacency)
      if (adj.size() > 2) degreeOk = false;
    while (!stack.empty()) {
      uint32_t x = stack.back();
      stack.pop_back();
      for (uint32_t y : adjacency[x])
        if (reached.insert(y).second) stack.push_back(y);
    }
    if (!degreeOk || reached.size() != adjacency.size()) ++t.nonManifoldVertices;
    i = j;
  }
  std::set<uint32_t> roots;
  for (size_t v = 0; v < n; ++v) {
    if (!used[v]) ++t.unreferencedVertices;
    else roots.insert(uf.find(uint32_t(v)));
  }
  t.components = roots.size();
  return t;
}

// ---- helpers ----------------------------------------------------------------------------------

struct Generated {
  Mesh mesh;
  std::string bytes;
  std::string output;  // mtgen's stderr
};

Generated generate(const TempDir& dir, const std::string& args, const std::string& name = "out.ply") {
  std::string path = dir.file(name);
  auto result = runTool("mtgen", "-o " + path + " " + args);
  EXPECT_EQ(result.exitCode, 0) << result.output;
  Generated g;
  g.output = result.output;
  g.bytes = readFile(path);
  g.mesh = parseBinaryPly(g.bytes);
  return g;
}

std::vector<Triangle> sortedTriangles(std::vector<Triangle> triangles) {
  std::sort(triangles.begin(), triangles.end());
  return triangles;
}

double edgeLengthRatio(const Mesh& mesh) {
  double lo = 1e300, hi = 0;
  for (const Triangle& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) {
      const auto& a = mesh.positions[t[k]];
      const auto& b = mesh.positions[t[(k + 1) % 3]];
      double l = std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]));
      lo = std::min(lo, l), hi = std::max(hi, l);
    }
  return hi / lo;
}

void expectClosedManifold(const Topology& t) {
  EXPECT_EQ(t.boundaryEdges, 0u);
  EXPECT_EQ(t.nonManifoldEdges, 0u);
  EXPECT_EQ(t.nonManifoldVertices, 0u);
  EXPECT_EQ(t.inconsistentlyOriented, 0u);
  EXPECT_EQ(t.unreferencedVertices, 0u);
  EXPECT_EQ(t.outOfRange, 0u);
  EXPECT_EQ(t.repeatedIndex, 0u);
  EXPECT_EQ(t.zeroArea, 0u);
}

// ---- tests ------------------------------------------------------------------------------------

TEST(Mtgen, TriangleCountWithinOnePercent) {
  TempDir dir;
  struct Case {
    std::string arg;
    double want;
  };
  for (const Case& c : {Case{"1000", 1000}, Case{"2.5k", 2500}, Case{"12345", 12345}, Case{"100k", 100000},
                        Case{"1M", 1000000}}) {
    for (const std::string extra : {"", " --holes 5", " --components 3", " --density varying --holes 3"}) {
      Generated g = generate(dir, "--triangles " + c.arg + extra);
      double got = double(g.mesh.triangles.size());
      EXPECT_NEAR(got, c.want, 0.01 * c.want) << c.arg << extra;
    }
  }
}

TEST(Mtgen, ClosedManifoldWithoutHoles) {
  TempDir dir;
  for (const std::string args : {"--triangles 20k", "--triangles 30k --density varying", "--triangles 50 --seed 3"}) {
    Generated g = generate(dir, args);
    Topology t = analyze(g.mesh);
    expectClosedManifold(t);
    EXPECT_EQ(t.components, 1u) << args;
    // Euler characteristic of a torus: V - E + F = 0.
    int64_t edges = int64_t(g.mesh.triangles.size()) * 3 / 2;
    EXPECT_EQ(int64_t(g.mesh.positions.size()) - edges + int64_t(g.mesh.triangles.size()), 0) << args;
  }
}

TEST(Mtgen, HolesAreBoundaryLoopsOnAManifold) {
  TempDir dir;
  for (const std::string args : {"--triangles 50k --holes 1", "--triangles 50k --holes 7 --seed 5",
                                  "--triangles 200k --holes 60 --density varying",
                                  "--triangles 100k --holes 9 --components 3 --seed 11"}) {
    Generated g = generate(dir, args);
    Topology t = analyze(g.mesh);
    size_t holes = size_t(std::stoul(args.substr(args.find("--holes ") + 8)));
    EXPECT_GT(t.boundaryEdges, 0u) << args;
    EXPECT_EQ(t.nonManifoldEdges, 0u) << args;
    EXPECT_EQ(t.nonManifoldVertices, 0u) << args;
    EXPECT_TRUE(t.boundaryVerticesRegular) << args;  // loops are simple closed cycles
    EXPECT_EQ(t.boundaryLoops, holes) << args;       // holes never merge or touch
    EXPECT_EQ(t.inconsistentlyOriented, 0u) << args;
    EXPECT_EQ(t.unreferencedVertices, 0u) << args;
    EXPECT_EQ(t.outOfRange, 0u) << args;
    EXPECT_EQ(t.repeatedIndex, 0u) << args;
    EXPECT_EQ(t.zeroArea, 0u) << args;
  }
}

TEST(Mtgen, HolesStayManifoldAcrossSeeds) {
  TempDir dir;
  for (int seed = 1; seed <= 12; ++seed) {
    std::string args = "--triangles 40k --holes 25 --seed " + std::to_string(seed) +
                       (seed % 2 ? " --density varying" : "") + (seed % 3 == 0 ? " --components 2" : "");
    Generated g = generate(dir, args);
    Topology t = analyze(g.mesh);
    EXPECT_EQ(t.boundaryLoops, 25u) << args;
    EXPECT_TRUE(t.boundaryVerticesRegular) << args;
    EXPECT_EQ(t.nonManifoldEdges + t.nonManifoldVertices + t.unreferencedVertices + t.inconsistentlyOriented, 0u)
        << args;
    EXPECT_EQ(t.components, seed % 3 == 0 ? 2u : 1u) << args;
  }
}

TEST(Mtgen, HoleSizesVary) {
  TempDir dir;
  Generated g = generate(dir, "--triangles 200k --holes 12 --seed 2");
  // Boundary loop lengths: measure per loop via the boundary graph.
  std::unordered_map<uint64_t, int> count;
  for (const Triangle& t : g.mesh.triangles)
    for (int k = 0; k < 3; ++k) ++count[edgeKey(t[k], t[(k + 1) % 3])];
  std::unordered_map<uint32_t, std::vector<uint32_t>> adjacency;
  for (auto& [key, c] : count)
    if (c == 1) adjacency[uint32_t(key >> 32)].push_back(uint32_t(key)), adjacency[uint32_t(key)].push_back(uint32_t(key >> 32));
  std::set<uint32_t> seen;
  std::vector<size_t> lengths;
  for (auto& [v, adj] : adjacency) {
    if (seen.count(v)) continue;
    size_t length = 0;
    std::vector<uint32_t> stack{v};
    seen.insert(v);
    while (!stack.empty()) {
      uint32_t x = stack.back();
      stack.pop_back();
      ++length;
      for (uint32_t y : adjacency[x])
        if (seen.insert(y).second) stack.push_back(y);
    }
    lengths.push_back(length);
  }
  ASSERT_EQ(lengths.size(), 12u);
  std::sort(lengths.begin(), lengths.end());
  EXPECT_LE(lengths.front(), 20u);                     // a small hole, a few edges around
  EXPECT_GE(lengths.back(), 10 * lengths.front());    // and a large one
}

TEST(Mtgen, ComponentsAreSeparate) {
  TempDir dir;
  for (uint32_t c : {2u, 3u, 5u, 8u}) {
    Generated g = generate(dir, "--triangles 40k --components " + std::to_string(c) + " --seed " + std::to_string(c));
    Topology t = analyze(g.mesh);
    expectClosedManifold(t);
    EXPECT_EQ(t.components, c);
  }
  // Components have different sizes and do not overlap (bounding spheres apart).
  Generated g = generate(dir, "--triangles 40k --components 4");
  UnionFind uf(g.mesh.positions.size());
  for (const Triangle& t : g.mesh.triangles) uf.join(t[0], t[1]), uf.join(t[1], t[2]);
  std::map<uint32_t, std::vector<uint32_t>> members;
  for (uint32_t v = 0; v < g.mesh.positions.size(); ++v) members[uf.find(v)].push_back(v);
  ASSERT_EQ(members.size(), 4u);
  struct Sphere {
    double c[3], r;
    size_t vertices;
  };
  std::vector<Sphere> spheres;
  for (auto& [root, vs] : members) {
    Sphere s{{0, 0, 0}, 0, vs.size()};
    for (uint32_t v : vs)
      for (int a = 0; a < 3; ++a) s.c[a] += g.mesh.positions[v][a] / double(vs.size());
    for (uint32_t v : vs) {
      const auto& p = g.mesh.positions[v];
      s.r = std::max(s.r, std::hypot(p[0] - s.c[0], p[1] - s.c[1], p[2] - s.c[2]));
    }
    spheres.push_back(s);
  }
  for (size_t i = 0; i < spheres.size(); ++i)
    for (size_t j = i + 1; j < spheres.size(); ++j) {
      const Sphere &a = spheres[i], &b = spheres[j];
      EXPECT_GT(std::hypot(a.c[0] - b.c[0], a.c[1] - b.c[1], a.c[2] - b.c[2]), a.r + b.r);
    }
  auto [smallest, largest] = std::minmax_element(spheres.begin(), spheres.end(),
                                                 [](const Sphere& a, const Sphere& b) { return a.vertices < b.vertices; });
  EXPECT_GT(double(largest->vertices), 1.3 * double(smallest->vertices));
}

TEST(Mtgen, ShuffleKeepsTrianglesAndVerticesButChangesOrder) {
  TempDir dir;
  for (const std::string args : {"--triangles 30k", "--triangles 30k --holes 6 --components 2 --seed 9"}) {
    Generated plain = generate(dir, args, "plain.ply");
    Generated shuffled = generate(dir, args + " --shuffle", "shuffled.ply");
    EXPECT_EQ(plain.mesh.vertexBytes, shuffled.mesh.vertexBytes) << args;
    EXPECT_EQ(sortedTriangles(plain.mesh.triangles), sortedTriangles(shuffled.mesh.triangles)) << args;
    EXPECT_NE(plain.mesh.triangles, shuffled.mesh.triangles) << args;
    // Really scattered, not a rotation: few consecutive faces stay consecutive.
    std::unordered_map<uint64_t, size_t> position;
    auto key = [](const Triangle& t) { return (uint64_t(t[0]) << 42) ^ (uint64_t(t[1]) << 21) ^ t[2]; };
    for (size_t i = 0; i < shuffled.mesh.triangles.size(); ++i) position[key(shuffled.mesh.triangles[i])] = i;
    size_t adjacent = 0;
    for (size_t i = 0; i + 1 < plain.mesh.triangles.size(); ++i) {
      size_t a = position[key(plain.mesh.triangles[i])], b = position[key(plain.mesh.triangles[i + 1])];
      if (a + 1 == b) ++adjacent;
    }
    EXPECT_LT(adjacent, plain.mesh.triangles.size() / 100) << args;
  }
}

TEST(Mtgen, DeterministicBySeed) {
  TempDir dir;
  std::string args = "--triangles 50k --holes 4 --components 2 --density varying --shuffle --normals --colors";
  Generated a = generate(dir, args + " --seed 7", "a.ply");
  Generated b = generate(dir, args + " --seed 7 --threads 1", "b.ply");
  Generated c = generate(dir, args + " --seed 8", "c.ply");
  EXPECT_EQ(a.bytes, b.bytes);  // same options, any thread count: identical bytes
  EXPECT_NE(a.bytes, c.bytes);
  Generated d = generate(dir, "--triangles 50k --seed 7", "d.ply");
  Generated e = generate(dir, "--triangles 50k --seed 8", "e.ply");
  EXPECT_NE(d.mesh.vertexBytes, e.mesh.vertexBytes);  // the shape itself depends on the seed
}

TEST(Mtgen, VaryingDensityVariesEdgeLength) {
  TempDir dir;
  Generated uniform = generate(dir, "--triangles 100k", "u.ply");
  Generated varying = generate(dir, "--triangles 100k --density varying", "v.ply");
  double u = edgeLengthRatio(uniform.mesh), v = edgeLengthRatio(varying.mesh);
  EXPECT_GT(v, 3 * u) << "uniform " << u << " varying " << v;
  expectClosedManifold(analyze(varying.mesh));
}

TEST(Mtgen, NormalsAreUnitAndOutward) {
  TempDir dir;
  Generated g = generate(dir, "--triangles 20k --normals --holes 3 --density varying");
  ASSERT_EQ(g.mesh.normals.size(), g.mesh.positions.size());
  // Compare with the area-weighted face normals around each vertex.
  std::vector<std::array<double, 3>> faceSum(g.mesh.positions.size(), {0, 0, 0});
  for (const Triangle& t : g.mesh.triangles) {
    const auto &a = g.mesh.positions[t[0]], &b = g.mesh.positions[t[1]], &c = g.mesh.positions[t[2]];
    double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
    for (uint32_t v : t)
      for (int k = 0; k < 3; ++k) faceSum[v][k] += n[k];
  }
  size_t agree = 0;
  for (size_t v = 0; v < g.mesh.normals.size(); ++v) {
    const auto& n = g.mesh.normals[v];
    EXPECT_NEAR(std::sqrt(double(n[0]) * n[0] + double(n[1]) * n[1] + double(n[2]) * n[2]), 1.0, 1e-5);
    if (n[0] * faceSum[v][0] + n[1] * faceSum[v][1] + n[2] * faceSum[v][2] > 0) ++agree;
  }
  EXPECT_GT(agree, g.mesh.normals.size() * 99 / 100);
}

TEST(Mtgen, ColorsAndDoublePrecision) {
  TempDir dir;
  Generated colored = generate(dir, "--triangles 10k --colors", "c.ply");
  std::set<uint8_t> reds;
  for (const auto& c : colored.mesh.colors) {
    EXPECT_EQ(c[3], 255);
    reds.insert(c[0]);
  }
  EXPECT_GT(reds.size(), 20u);  // a smooth ramp, not a constant

  Generated single = generate(dir, "--triangles 10k", "f.ply");
  Generated dbl = generate(dir, "--triangles 10k --double", "d.ply");
  EXPECT_TRUE(dbl.mesh.doubleCoordinates);
  ASSERT_EQ(dbl.mesh.positions.size(), single.mesh.positions.size());
  EXPECT_EQ(dbl.mesh.triangles, single.mesh.triangles);
  size_t moreThanFloat = 0;
  for (size_t v = 0; v < dbl.mesh.positions.size(); ++v)
    for (int k = 0; k < 3; ++k) {
      double x = dbl.mesh.positions[v][k];
      EXPECT_EQ(float(x), float(single.mesh.positions[v][k]));
      if (double(float(x)) != x) ++moreThanFloat;
    }
  EXPECT_GT(moreThanFloat, dbl.mesh.positions.size());
}

TEST(Mtgen, TextFormatsParseBackToTheSameMesh) {
  TempDir dir;
  const std::string args = "--triangles 6000 --holes 3 --components 2 --seed 4";
  Generated ref = generate(dir, args + " --normals", "ref.ply");
  auto sameVertices = [&](const Mesh& m, const std::string& what) {
    ASSERT_EQ(m.positions.size(), ref.mesh.positions.size()) << what;
    for (size_t v = 0; v < m.positions.size(); ++v)
      for (int k = 0; k < 3; ++k) ASSERT_EQ(float(m.positions[v][k]), float(ref.mesh.positions[v][k])) << what;
  };
  {
    auto r = runTool("mtgen", "-o " + dir.file("a.ply") + " " + args + " --normals --colors --format ply-ascii");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    Mesh m = parseAsciiPly(readFile(dir.file("a.ply")), true, true);
    sameVertices(m, "ply-ascii");
    EXPECT_EQ(m.triangles, ref.mesh.triangles);
    for (size_t v = 0; v < m.normals.size(); ++v) EXPECT_EQ(m.normals[v], ref.mesh.normals[v]);
  }
  {
    auto r = runTool("mtgen", "-o " + dir.file("a.obj") + " " + args + " --normals --format obj");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    Mesh m = parseObj(readFile(dir.file("a.obj")));
    sameVertices(m, "obj");
    EXPECT_EQ(m.triangles, ref.mesh.triangles);
    ASSERT_EQ(m.normals.size(), ref.mesh.normals.size());
    for (size_t v = 0; v < m.normals.size(); ++v) EXPECT_EQ(m.normals[v], ref.mesh.normals[v]);
  }
  {
    auto r = runTool("mtgen", "-o " + dir.file("a.off") + " " + args + " --format off");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    Mesh m = parseOff(readFile(dir.file("a.off")));
    sameVertices(m, "off");
    EXPECT_EQ(m.triangles, ref.mesh.triangles);
  }
  {
    auto r = runTool("mtgen", "-o " + dir.file("a.stl") + " " + args + " --format stl");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    auto soup = parseStl(readFile(dir.file("a.stl")));
    ASSERT_EQ(soup.size(), ref.mesh.triangles.size());
    for (size_t t = 0; t < soup.size(); ++t)
      for (int k = 0; k < 3; ++k)
        for (int a = 0; a < 3; ++a)
          ASSERT_EQ(soup[t][3 * k + a], float(ref.mesh.positions[ref.mesh.triangles[t][k]][a])) << t;
  }
  {  // shuffled STL is the same soup in another order
    auto r = runTool("mtgen", "-o " + dir.file("b.stl") + " " + args + " --format stl --shuffle");
    ASSERT_EQ(r.exitCode, 0) << r.output;
    auto a = parseStl(readFile(dir.file("a.stl"))), b = parseStl(readFile(dir.file("b.stl")));
    EXPECT_NE(a, b);
    std::sort(a.begin(), a.end());
    std::sort(b.begin(), b.end());
    EXPECT_EQ(a, b);
  }
}

TEST(Mtgen, BadOptionsFailCleanly) {
  TempDir dir;
  const std::string out = dir.file("bad.ply");
  for (const std::string args :
       {"--triangles 0", "--triangles -5", "--triangles abc", "--triangles 1X", "--format xyz", "--density wavy",
        "--components 0", "--triangles 30 --components 2", "--triangles 2000 --holes 500", "--double --format obj",
        "--colors --format stl", "--normals --format off", "--no-such-option"}) {
    auto r = runTool("mtgen", "-o " + out + " " + args);
    EXPECT_EQ(r.exitCode, 1) << args << ": " << r.output;
    EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << args << ": " << r.output;
    EXPECT_FALSE(fileExists(out)) << args;
  }
  auto r = runTool("mtgen", "--triangles 1k");  // no output path
  EXPECT_EQ(r.exitCode, 1) << r.output;
  r = runTool("mtgen", "-o " + dir.file("no/such/dir/x.ply") + " --triangles 1k");
  EXPECT_EQ(r.exitCode, 1) << r.output;
  EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << r.output;
  r = runTool("mtgen", "-o " + dir.file("no/such/dir/x.obj") + " --triangles 1k --format obj");
  EXPECT_EQ(r.exitCode, 1) << r.output;
  // Nothing but the scratch directory's own contents.
  r = runTool("mtgen", "-o " + dir.file("ok.ply") + " --triangles 1k");
  EXPECT_EQ(r.exitCode, 0);
  EXPECT_TRUE(fileExists(dir.file("ok.ply")));
  EXPECT_FALSE(fileExists(dir.file("no")));
}

TEST(Mtgen, HelpExplainsEveryOption) {
  auto r = runTool("mtgen", "--help");
  EXPECT_EQ(r.exitCode, 0);
  for (const char* option : {"--output", "--triangles", "--seed", "--holes", "--components", "--density", "--shuffle",
                             "--normals", "--colors", "--format", "--double"})
    EXPECT_NE(r.output.find(option), std::string::npos) << option;
}

TEST(Mtgen, ReportsASummaryLine) {
  TempDir dir;
  auto r = runTool("mtgen", "-o " + dir.file("s.ply") + " --triangles 10k");
  ASSERT_EQ(r.exitCode, 0);
  EXPECT_NE(r.output.find("10000 triangles"), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("bytes"), std::string::npos) << r.output;
}

// ---- scan pathologies -------------------------------------------------------------------------
// Each --pathology is measured on the output alone, with a counter that is zero on the default
// output (DefaultOutputHasNoPathology) and clearly positive with the option.

double length(const std::array<double, 3>& a, const std::array<double, 3>& b) {
  return std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]));
}

double medianEdge(const Mesh& mesh) {
  std::vector<double> lengths;
  for (const Triangle& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) lengths.push_back(length(mesh.positions[t[k]], mesh.positions[t[(k + 1) % 3]]));
  std::nth_element(lengths.begin(), lengths.begin() + lengths.size() / 2, lengths.end());
  return lengths[lengths.size() / 2];
}

double percentile(std::vector<double> values, double q) {
  if (values.empty()) return 0;
  size_t at = std::min(values.size() - 1, size_t(q * double(values.size())));
  std::nth_element(values.begin(), values.begin() + at, values.end());
  return values[at];
}

struct PathologyCounts {
  uint64_t closePairs = 0;       // distinct vertices 0 < distance < 1e-3 median edge
  uint64_t duplicateVertices = 0;  // vertices at exactly the position of another one
  uint64_t needles = 0;          // shortest edge < 0.12 of the longest, no angle above 150 degrees
  uint64_t caps = 0;             // an angle above 150 degrees
  uint64_t tJunctions = 0;       // a vertex on the interior of an edge of the other side
  double medianAspect = 0;       // longest / shortest edge of a triangle, median
  double areaJump = 0;           // area ratio of the two triangles of an edge, 90th percentile
  uint64_t components = 0;
  uint64_t boundaryEdges = 0, nonManifoldEdges = 0, inconsistentlyOriented = 0;
};

PathologyCounts measurePathologies(const Mesh& mesh) {
  PathologyCounts m;
  const double edge = medianEdge(mesh);
  // Vertex pairs closer than 1e-3 edge, and exact duplicates: a hash grid of that cell size.
  const double cell = 1e-3 * edge;
  std::unordered_map<uint64_t, std::vector<uint32_t>> cells;
  auto cellKey = [](int64_t x, int64_t y, int64_t z) {
    return uint64_t(x) * 0x9E3779B97F4A7C15ull ^ uint64_t(y) * 0xC2B2AE3D27D4EB4Full ^ uint64_t(z) * 0x165667B19E3779F9ull;
  };
  std::vector<std::array<int64_t, 3>> at(mesh.positions.size());
  for (uint32_t v = 0; v < mesh.positions.size(); ++v) {
    for (int a = 0; a < 3; ++a) at[v][a] = int64_t(std::floor(mesh.positions[v][a] / cell));
    cells[cellKey(at[v][0], at[v][1], at[v][2])].push_back(v);
  }
  std::vector<uint8_t> duplicate(mesh.positions.size(), 0);
  for (uint32_t v = 0; v < mesh.positions.size(); ++v)
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          auto it = cells.find(cellKey(at[v][0] + dx, at[v][1] + dy, at[v][2] + dz));
          if (it == cells.end()) continue;
          for (uint32_t w : it->second) {
            if (w == v) continue;
            double d = length(mesh.positions[v], mesh.positions[w]);
            if (d == 0) duplicate[v] = 1;
            else if (d < cell && w > v) ++m.closePairs;
          }
        }
  for (uint8_t d : duplicate) m.duplicateVertices += d;

  // Triangle shapes.
  std::vector<double> aspects, areas(mesh.triangles.size(), 0);
  for (size_t f = 0; f < mesh.triangles.size(); ++f) {
    const Triangle& t = mesh.triangles[f];
    double l[3], maxCos = -1;
    for (int k = 0; k < 3; ++k) l[k] = length(mesh.positions[t[k]], mesh.positions[t[(k + 1) % 3]]);
    for (int k = 0; k < 3; ++k) {  // angle opposite edge k from the law of cosines
      double a = l[(k + 1) % 3], b = l[(k + 2) % 3];
      if (a > 0 && b > 0) maxCos = std::max(maxCos, -(a * a + b * b - l[k] * l[k]) / (2 * a * b));
    }
    double shortest = std::min({l[0], l[1], l[2]}), longest = std::max({l[0], l[1], l[2]});
    bool cap = maxCos > -std::cos(150.0 * mtgen::kPi / 180.0);  // maxCos is -cos(largest angle)
    if (cap) ++m.caps;
    else if (shortest < 0.12 * longest) ++m.needles;
    if (shortest > 0) aspects.push_back(longest / shortest);
    double s = 0.5 * (l[0] + l[1] + l[2]);
    areas[f] = std::sqrt(std::max(0.0, s * (s - l[0]) * (s - l[1]) * (s - l[2])));
  }
  m.medianAspect = percentile(aspects, 0.5);

  // Edges: counts, orientation, area jumps, boundary pattern of T-junctions.
  std::unordered_map<uint64_t, std::vector<uint32_t>> edgeFaces;
  std::unordered_map<uint64_t, int> directed;
  for (uint32_t f = 0; f < mesh.triangles.size(); ++f) {
    const Triangle& t = mesh.triangles[f];
    for (int k = 0; k < 3; ++k) {
      edgeFaces[edgeKey(t[k], t[(k + 1) % 3])].push_back(f);
      ++directed[(uint64_t(t[k]) << 32) | t[(k + 1) % 3]];
    }
  }
  for (auto& [key, count] : directed) m.inconsistentlyOriented += count > 1;
  std::vector<double> jumps;
  std::unordered_map<uint32_t, std::vector<uint32_t>> boundaryNeighbours;
  for (auto& [key, faces] : edgeFaces) {
    if (faces.size() > 2) ++m.nonManifoldEdges;
    if (faces.size() == 2 && areas[faces[0]] > 0 && areas[faces[1]] > 0)
      jumps.push_back(std::max(areas[faces[0]], areas[faces[1]]) / std::min(areas[faces[0]], areas[faces[1]]));
    if (faces.size() == 1) {
      ++m.boundaryEdges;
      uint32_t a = uint32_t(key >> 32), b = uint32_t(key);
      boundaryNeighbours[a].push_back(b);
      boundaryNeighbours[b].push_back(a);
    }
  }
  m.areaJump = percentile(jumps, 0.9);
  // T-junction: boundary vertex v with boundary edges v-a, v-b, where a-b is a boundary edge too
  // and v lies on the segment a-b (within float rounding).
  for (auto& [v, around] : boundaryNeighbours) {
    if (around.size() != 2) continue;
    uint32_t a = around[0], b = around[1];
    auto ab = edgeFaces.find(edgeKey(a, b));
    if (ab == edgeFaces.end() || ab->second.size() != 1) continue;
    double lab = length(mesh.positions[a], mesh.positions[b]);
    double detour = length(mesh.positions[a], mesh.positions[v]) + length(mesh.positions[v], mesh.positions[b]) - lab;
    if (detour < 1e-4 * lab) ++m.tJunctions;
  }
  UnionFind uf(mesh.positions.size());
  for (const Triangle& t : mesh.triangles) uf.join(t[0], t[1]), uf.join(t[1], t[2]);
  std::set<uint32_t> roots;
  for (const Triangle& t : mesh.triangles) roots.insert(uf.find(t[0]));
  m.components = roots.size();
  return m;
}

std::string describe(const PathologyCounts& m) {
  std::ostringstream out;
  out << "close " << m.closePairs << " duplicates " << m.duplicateVertices << " needles " << m.needles << " caps "
      << m.caps << " tjunctions " << m.tJunctions << " aspect " << m.medianAspect << " areaJump " << m.areaJump
      << " components " << m.components << " boundary " << m.boundaryEdges << " nonmanifold " << m.nonManifoldEdges
      << " misoriented " << m.inconsistentlyOriented;
  return out.str();
}

const std::string kPathologyBase = "--triangles 60k --holes 4 --seed 3";

TEST(MtgenPathology, DefaultOutputHasNoPathology) {
  TempDir dir;
  for (const std::string& args : {kPathologyBase, kPathologyBase + " --density varying --components 2",
                                  kPathologyBase + " --pathology none"}) {
    PathologyCounts m = measurePathologies(generate(dir, args).mesh);
    SCOPED_TRACE(args + ": " + describe(m));
    EXPECT_EQ(m.closePairs, 0u);
    EXPECT_EQ(m.duplicateVertices, 0u);
    EXPECT_EQ(m.needles, 0u);
    EXPECT_EQ(m.caps, 0u);
    EXPECT_EQ(m.tJunctions, 0u);
    EXPECT_LT(m.medianAspect, 2.5);
    EXPECT_LT(m.areaJump, 1.3);
    EXPECT_EQ(m.nonManifoldEdges + m.inconsistentlyOriented, 0u);
  }
}

// The default bytes are what every earlier measurement was made on: pathologies must not change
// them. FNV-1a of two default outputs, recorded before the pathologies existed.
TEST(MtgenPathology, DefaultBytesUnchanged) {
  TempDir dir;
  auto fnv = [](const std::string& bytes) {
    uint64_t h = 0xCBF29CE484222325ull;
    for (unsigned char c : bytes) h = (h ^ c) * 0x100000001B3ull;
    return h;
  };
  EXPECT_EQ(fnv(generate(dir, "--triangles 20k --holes 3 --components 2 --seed 5").bytes), 0x2f00b94362df55ebull);
  // --colors: since the sharp colour field (testing/color_field.h); the geometry is the same bytes.
  EXPECT_EQ(fnv(generate(dir, "--triangles 20k --density varying --shuffle --normals --colors").bytes), 0xb190bc56a75d8fbbull);
}

Generated generatePathology(const TempDir& dir, const std::string& pathology, const std::string& name = "p.ply",
                            const std::string& base = kPathologyBase) {
  return generate(dir, base + " --pathology " + pathology, name);
}

// Topology every pathology keeps: indices valid, each triangle three distinct vertices, every
// vertex used, consistently oriented, no edge of more than two triangles.
void expectSoundIndices(const Mesh& mesh, const std::string& what) {
  Topology t = analyze(mesh);
  EXPECT_EQ(t.outOfRange + t.repeatedIndex + t.unreferencedVertices + t.zeroArea, 0u) << what;
  EXPECT_EQ(t.nonManifoldEdges, 0u) << what;
  EXPECT_EQ(t.inconsistentlyOriented, 0u) << what;
}

// Triangles of two meshes with the same index lists whose normals point opposite ways.
size_t flippedAgainst(const Mesh& mesh, const Mesh& reference) {
  size_t flipped = 0;
  auto normal = [](const Mesh& m, const Triangle& t) {
    const auto &a = m.positions[t[0]], &b = m.positions[t[1]], &c = m.positions[t[2]];
    double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    return std::array<double, 3>{e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
  };
  for (size_t f = 0; f < mesh.triangles.size(); ++f) {
    auto n = normal(mesh, mesh.triangles[f]), r = normal(reference, reference.triangles[f]);
    if (n[0] * r[0] + n[1] * r[1] + n[2] * r[2] < 0) ++flipped;
  }
  return flipped;
}

TEST(MtgenPathology, CloseVerticesArePairsFarBelowAnEdge) {
  TempDir dir;
  Generated plain = generate(dir, kPathologyBase, "plain.ply");
  Generated close = generatePathology(dir, "close");
  PathologyCounts m = measurePathologies(close.mesh);
  SCOPED_TRACE(describe(m));
  const size_t vertices = close.mesh.positions.size();
  EXPECT_GT(m.closePairs, vertices / 100);  // ~2% of the vertices
  EXPECT_LT(m.closePairs, vertices / 25);
  EXPECT_EQ(m.duplicateVertices, 0u);  // distinct positions, only very close
  // Only positions change: same vertices, same triangles, none turned over.
  ASSERT_EQ(vertices, plain.mesh.positions.size());
  EXPECT_EQ(close.mesh.triangles, plain.mesh.triangles);
  EXPECT_EQ(flippedAgainst(close.mesh, plain.mesh), 0u);
  size_t moved = 0;
  for (size_t v = 0; v < vertices; ++v) moved += close.mesh.positions[v] != plain.mesh.positions[v];
  // Each moved vertex makes a pair with the neighbour it went to (and rarely a second one with
  // another vertex moved to the same neighbour).
  EXPECT_GE(m.closePairs, moved);
  EXPECT_LE(m.closePairs, moved + moved / 20);
  expectSoundIndices(close.mesh, "close");
}

TEST(MtgenPathology, SliversAreNeedlesAndCaps) {
  TempDir dir;
  Generated plain = generate(dir, kPathologyBase, "plain.ply");
  Generated slivers = generatePathology(dir, "slivers");
  PathologyCounts m = measurePathologies(slivers.mesh);
  SCOPED_TRACE(describe(m));
  const size_t triangles = slivers.mesh.triangles.size();
  EXPECT_GT(m.needles, triangles / 200);
  EXPECT_GT(m.caps, triangles / 200);
  EXPECT_EQ(m.closePairs, 0u);  // a needle's short edge is 3-10% of an edge, not a near-duplicate
  EXPECT_EQ(slivers.mesh.triangles, plain.mesh.triangles);
  EXPECT_EQ(flippedAgainst(slivers.mesh, plain.mesh), 0u);
  expectSoundIndices(slivers.mesh, "slivers");
}

TEST(MtgenPathology, AnisotropicCellsAreLong) {
  TempDir dir;
  for (const std::string& base : {kPathologyBase, kPathologyBase + " --density varying"}) {
    Generated g = generatePathology(dir, "anisotropic", "p.ply", base);
    PathologyCounts m = measurePathologies(g.mesh);
    PathologyCounts plain = measurePathologies(generate(dir, base, "plain.ply").mesh);
    SCOPED_TRACE(base + ": " + describe(m));
    EXPECT_GT(m.medianAspect, 4.0);  // 6:1 cells (less where the varying density stretches the other way)
    EXPECT_GT(m.medianAspect, 2.0 * plain.medianAspect);
    EXPECT_NEAR(double(g.mesh.triangles.size()), 60000, 600);
    expectSoundIndices(g.mesh, "anisotropic " + base);
  }
}

TEST(MtgenPathology, UnevenSpacingJumpsBetweenNeighbours) {
  TempDir dir;
  Generated g = generatePathology(dir, "uneven");
  PathologyCounts m = measurePathologies(g.mesh);
  SCOPED_TRACE(describe(m));
  EXPECT_GT(m.areaJump, 2.0);  // 1 in 10 edges joins triangles of areas more than 2x apart
  // Smoothly varying density is not uneven: neighbours stay alike.
  EXPECT_LT(measurePathologies(generate(dir, kPathologyBase + " --density varying", "v.ply").mesh).areaJump, 1.3);
  expectSoundIndices(g.mesh, "uneven");
}

TEST(MtgenPathology, OverlapIsASecondSheetJustAboveTheSurface) {
  TempDir dir;
  // No holes here: a sheet over a hole (a second pass covering an occlusion) is far from the surface.
  for (const std::string& base : {std::string("--triangles 60k --seed 3"),
                                  std::string("--triangles 60k --seed 4 --components 3 --density varying")}) {
    Generated g = generatePathology(dir, "overlap", "p.ply", base);
    const Mesh& mesh = g.mesh;
    const size_t tori = base.find("--components 3") != std::string::npos ? 3 : 1;
    PathologyCounts m = measurePathologies(mesh);
    SCOPED_TRACE(base + ": " + describe(m));
    EXPECT_EQ(m.components, 2 * tori);
    EXPECT_NEAR(double(mesh.triangles.size()), 60000, 600);  // the budget includes the sheets
    // Components by size: the sheets are the small ones (~4% of the triangles each) and open.
    UnionFind uf(mesh.positions.size());
    for (const Triangle& t : mesh.triangles) uf.join(t[0], t[1]), uf.join(t[1], t[2]);
    std::map<uint32_t, size_t> size;
    for (const Triangle& t : mesh.triangles) ++size[uf.find(t[0])];
    std::vector<std::pair<size_t, uint32_t>> bySize;
    for (auto& [root, n] : size) bySize.push_back({n, root});
    std::sort(bySize.begin(), bySize.end());
    std::set<uint32_t> sheets;
    size_t sheetTriangles = 0;
    for (size_t k = 0; k < tori; ++k) sheets.insert(bySize[k].second), sheetTriangles += bySize[k].first;
    EXPECT_GT(sheetTriangles, mesh.triangles.size() * 3 / 100);
    EXPECT_LT(sheetTriangles, mesh.triangles.size() * 6 / 100);
    // Every sheet vertex is within its local spacing (longest edge) of the surface's vertices, and
    // none on top of one: two passes a fraction of the spacing apart.
    const double edge = medianEdge(mesh);
    std::vector<double> spacing(mesh.positions.size(), 0);  // longest edge at each vertex
    for (const Triangle& t : mesh.triangles)
      for (int k = 0; k < 3; ++k) {
        double l = length(mesh.positions[t[k]], mesh.positions[t[(k + 1) % 3]]);
        spacing[t[k]] = std::max(spacing[t[k]], l), spacing[t[(k + 1) % 3]] = std::max(spacing[t[(k + 1) % 3]], l);
      }
    std::unordered_map<uint64_t, std::vector<uint32_t>> cells;
    auto key = [&](const std::array<double, 3>& p, int dx, int dy, int dz) {
      return uint64_t(int64_t(std::floor(p[0] / edge)) + dx) * 0x9E3779B97F4A7C15ull ^
             uint64_t(int64_t(std::floor(p[1] / edge)) + dy) * 0xC2B2AE3D27D4EB4Full ^
             uint64_t(int64_t(std::floor(p[2] / edge)) + dz) * 0x165667B19E3779F9ull;
    };
    std::vector<uint8_t> onSheet(mesh.positions.size(), 0);
    for (uint32_t v = 0; v < mesh.positions.size(); ++v) {
      onSheet[v] = sheets.count(uf.find(v)) > 0;
      if (!onSheet[v]) cells[key(mesh.positions[v], 0, 0, 0)].push_back(v);
    }
    size_t sheetVertices = 0, near = 0, onTop = 0;
    for (uint32_t v = 0; v < mesh.positions.size(); ++v) {
      if (!onSheet[v]) continue;
      ++sheetVertices;
      double best = 1e300;
      for (int dx = -3; dx <= 3; ++dx)
        for (int dy = -3; dy <= 3; ++dy)
          for (int dz = -3; dz <= 3; ++dz) {
            auto it = cells.find(key(mesh.positions[v], dx, dy, dz));
            if (it != cells.end())
              for (uint32_t w : it->second) best = std::min(best, length(mesh.positions[v], mesh.positions[w]));
          }
      near += best < spacing[v];
      onTop += best < 0.05 * spacing[v];
    }
    EXPECT_GT(near, sheetVertices * 95 / 100);
    EXPECT_EQ(onTop, 0u);
    expectSoundIndices(mesh, "overlap " + base);
  }
}

TEST(MtgenPathology, SeamsDuplicateVerticesAndWeldBackToTheSurface) {
  TempDir dir;
  Generated plain = generate(dir, kPathologyBase, "plain.ply");
  Generated g = generatePathology(dir, "seams");
  PathologyCounts m = measurePathologies(g.mesh);
  SCOPED_TRACE(describe(m));
  EXPECT_EQ(g.mesh.triangles.size(), plain.mesh.triangles.size());
  const size_t copies = g.mesh.positions.size() - plain.mesh.positions.size();  // one row and one column
  EXPECT_GT(copies, 100u);
  EXPECT_EQ(m.duplicateVertices, 2 * copies - 2);  // each copy and its original; 4 at the corner
  // Welding equal positions gives back the watertight surface: same boundary as without seams,
  // and each side's triangles used their own copy (so before welding, the seams are boundary).
  std::map<std::array<double, 3>, uint32_t> first;
  Mesh welded = g.mesh;
  for (auto& t : welded.triangles)
    for (auto& v : t) v = first.emplace(g.mesh.positions[v], v).first->second;
  Topology weldedTopology = analyze(welded), plainTopology = analyze(plain.mesh);
  EXPECT_EQ(weldedTopology.boundaryEdges, plainTopology.boundaryEdges);
  EXPECT_EQ(weldedTopology.nonManifoldEdges, 0u);
  EXPECT_EQ(m.boundaryEdges, plainTopology.boundaryEdges + 2 * copies - 2);  // both seam loops, both sides
  expectSoundIndices(g.mesh, "seams");
}

TEST(MtgenPathology, TJunctionsSitOnTheEdgesOfTheOtherSide) {
  TempDir dir;
  for (const std::string& base : {std::string("--triangles 60k --seed 3"), kPathologyBase}) {
    Generated g = generatePathology(dir, "tjunctions", "p.ply", base);
    PathologyCounts m = measurePathologies(g.mesh);
    SCOPED_TRACE(base + ": " + describe(m));
    EXPECT_GT(m.tJunctions, 300u);
    EXPECT_NEAR(double(g.mesh.triangles.size()), 60000, 600);
    if (base.find("--holes") == std::string::npos) {
      // Without holes every boundary edge is a T-junction's: a-m and m-b above, a-b below.
      EXPECT_EQ(m.boundaryEdges, 3 * m.tJunctions);
    }
    expectSoundIndices(g.mesh, "tjunctions " + base);
  }
}

TEST(MtgenPathology, NoiseIsHighFrequencyAndSmall) {
  TempDir dir;
  Generated plain = generate(dir, kPathologyBase, "plain.ply");
  Generated g = generatePathology(dir, "noise");
  ASSERT_EQ(g.mesh.positions.size(), plain.mesh.positions.size());
  EXPECT_EQ(g.mesh.triangles, plain.mesh.triangles);
  const double edge = medianEdge(plain.mesh);
  std::vector<std::array<double, 3>> delta(g.mesh.positions.size());
  double sum = 0, biggest = 0;
  for (size_t v = 0; v < delta.size(); ++v) {
    for (int a = 0; a < 3; ++a) delta[v][a] = g.mesh.positions[v][a] - plain.mesh.positions[v][a];
    double d = std::hypot(delta[v][0], delta[v][1], delta[v][2]);
    sum += d, biggest = std::max(biggest, d);
  }
  double mean = sum / double(delta.size());
  EXPECT_GT(mean, 0.05 * edge);
  EXPECT_LT(biggest, 0.3 * edge);
  // High frequency: the offsets of the two ends of an edge are unrelated, so their difference is
  // as large as the offsets themselves (a smooth displacement would make it much smaller).
  double differences = 0;
  size_t edges = 0;
  for (const Triangle& t : plain.mesh.triangles)
    for (int k = 0; k < 3; ++k) {
      const auto &a = delta[t[k]], &b = delta[t[(k + 1) % 3]];
      differences += std::hypot(a[0] - b[0], a[1] - b[1], a[2] - b[2]), ++edges;
    }
  EXPECT_GT(differences / double(edges), 1.1 * mean);
  EXPECT_EQ(flippedAgainst(g.mesh, plain.mesh), 0u);
  expectSoundIndices(g.mesh, "noise");
}

TEST(MtgenPathology, AllTogetherEveryOneMeasurable) {
  TempDir dir;
  Generated g = generatePathology(dir, "all", "p.ply", kPathologyBase + " --components 2");
  PathologyCounts m = measurePathologies(g.mesh);
  SCOPED_TRACE(describe(m));
  EXPECT_GT(m.closePairs, 100u);
  EXPECT_GT(m.caps, 100u);
  EXPECT_GT(m.duplicateVertices, 100u);
  EXPECT_GT(m.tJunctions, 100u);
  EXPECT_GT(m.medianAspect, 4.0);
  EXPECT_GT(m.areaJump, 2.0);
  EXPECT_EQ(m.components, 4u);  // two tori, two sheets
  EXPECT_NEAR(double(g.mesh.triangles.size()), 60000, 1200);
  expectSoundIndices(g.mesh, "all");
  // A list is the union of its names.
  Generated listed = generatePathology(dir, "close,slivers,anisotropic,uneven,overlap,seams,tjunctions,noise", "l.ply",
                                       kPathologyBase + " --components 2");
  EXPECT_EQ(listed.bytes, g.bytes);
}

// Every output path computes a vertex the same way: rows in the streaming pipeline (PLY, OBJ),
// single vertices for triangle soups (STL) and faces by index (--shuffle); any thread count.
TEST(MtgenPathology, EveryPathGivesTheSameVertices) {
  TempDir dir;
  const std::string args = "--triangles 20k --holes 5 --components 2 --seed 6 --pathology all";
  Generated ref = generate(dir, args + " --normals --colors", "ref.ply");
  Generated one = generate(dir, args + " --normals --colors --threads 1", "one.ply");
  EXPECT_EQ(ref.bytes, one.bytes);
  Generated shuffled = generate(dir, args + " --shuffle", "shuffled.ply");
  EXPECT_EQ(sortedTriangles(shuffled.mesh.triangles), sortedTriangles(ref.mesh.triangles));
  ASSERT_EQ(shuffled.mesh.positions, ref.mesh.positions);
  for (const std::string& order : {std::string(""), std::string(" --shuffle")}) {
    auto r = runTool("mtgen", "-o " + dir.file("a.stl") + " " + args + order);
    ASSERT_EQ(r.exitCode, 0) << r.output;
    auto soup = parseStl(readFile(dir.file("a.stl")));
    const Mesh& faces = order.empty() ? ref.mesh : shuffled.mesh;
    ASSERT_EQ(soup.size(), faces.triangles.size());
    for (size_t t = 0; t < soup.size(); ++t)
      for (int k = 0; k < 3; ++k)
        for (int a = 0; a < 3; ++a)
          ASSERT_EQ(soup[t][3 * k + a], float(faces.positions[faces.triangles[t][k]][a])) << t << order;
  }
  auto r = runTool("mtgen", "-o " + dir.file("a.obj") + " " + args + " --normals");
  ASSERT_EQ(r.exitCode, 0) << r.output;
  Mesh obj = parseObj(readFile(dir.file("a.obj")));
  EXPECT_EQ(obj.triangles, ref.mesh.triangles);
  ASSERT_EQ(obj.normals.size(), ref.mesh.normals.size());
  for (size_t v = 0; v < obj.normals.size(); ++v) {
    EXPECT_EQ(obj.normals[v], ref.mesh.normals[v]);
    EXPECT_NEAR(std::hypot(double(obj.normals[v][0]), double(obj.normals[v][1]), double(obj.normals[v][2])), 1.0, 1e-5);
  }
}

TEST(MtgenPathology, BadNamesFailCleanly) {
  TempDir dir;
  const std::string out = dir.file("bad.ply");
  for (const std::string args : {"--pathology nosie", "--pathology close,", "--pathology ,seams", "--pathology ALL"}) {
    auto r = runTool("mtgen", "-o " + out + " --triangles 1k " + args);
    EXPECT_EQ(r.exitCode, 1) << args << ": " << r.output;
    EXPECT_EQ(std::count(r.output.begin(), r.output.end(), '\n'), 1) << args << ": " << r.output;
    EXPECT_NE(r.output.find("--pathology"), std::string::npos) << r.output;
    EXPECT_FALSE(fileExists(out)) << args;
  }
  auto r = runTool("mtgen", "--help");
  for (const mtgen::PathologyInfo& p : mtgen::kPathologies)
    EXPECT_NE(r.output.find(std::string(p.name) + ": "), std::string::npos) << p.name;
}

// Small meshes keep every pathology (and the minimum component size) valid.
TEST(MtgenPathology, TinyMeshesStayValid) {
  TempDir dir;
  for (const std::string args : {"--triangles 18", "--triangles 200 --seed 2", "--triangles 2.5k --holes 5",
                                  "--triangles 5k --components 4 --density varying"}) {
    Generated g = generate(dir, args + " --pathology all");
    expectSoundIndices(g.mesh, args);
  }
}

// ---- the generator's building blocks -----------------------------------------------------------

TEST(ScanGenerator, FeistelPermutationIsABijection) {
  for (uint64_t size : {1ull, 2ull, 3ull, 7ull, 64ull, 100ull, 1000ull, 4097ull, 65536ull, 100003ull}) {
    mtgen::FeistelPermutation perm(size, 42);
    std::vector<uint8_t> hit(size, 0);
    for (uint64_t i = 0; i < size; ++i) {
      uint64_t j = perm(i);
      ASSERT_LT(j, size);
      ASSERT_EQ(hit[j], 0) << size;
      hit[j] = 1;
    }
  }
  mtgen::FeistelPermutation a(1000, 1), b(1000, 2);
  size_t same = 0;
  for (uint64_t i = 0; i < 1000; ++i) same += a(i) == b(i);
  EXPECT_LT(same, 20u);  // the key matters
}

TEST(ScanGenerator, CountsMatchTheFormulaAndSinglePositionsMatchRows) {
  mtgen::GeneratorOptions o;
  o.triangles = 20000;
  o.holes = 5;
  o.components = 2;
  o.varyingDensity = true;
  mtgen::ScanGenerator gen(o);
  uint64_t kept = 0, gridFaces = 0;
  for (uint64_t f = 0; f < gen.gridFaceCount(); ++f) {
    uint32_t tri[3];
    kept += gen.gridTriangle(f, tri);
    ++gridFaces;
  }
  EXPECT_EQ(kept, gen.triangleCount());
  // The per-row lattice path and the single-vertex path give bit-identical positions.
  const mtgen::Component& c = gen.components()[1];
  mtgen::ScanGenerator::RowLattice lattice;
  for (uint32_t row : {0u, 1u, c.rows / 2, c.rows - 1}) {
    auto rp = mtgen::ScanGenerator::rowParams(c, row);
    lattice.fill(c, rp);
    for (uint32_t col = 0; col < c.cols; ++col) {
      double a[3], b[3];
      mtgen::ScanGenerator::position(c, rp, lattice, mtgen::ScanGenerator::colParams(c, col), a);
      gen.position(1, row, col, b);
      ASSERT_EQ(std::memcmp(a, b, sizeof a), 0);
    }
  }
}

}  // namespace
