// Parse throughput of the streaming mesh readers on generated grid meshes (items/s = triangles/s).
// The files are written once into $TMPDIR (or /tmp) and removed at exit; after the first
// iteration they sit in the page cache, so the figures measure parsing, not the disk.
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <string>

#include "patchstore/io/ply_writer.h"
#include "patchstore/io/mesh_reader.h"

namespace {

// A side x side vertex grid with 2 (side-1)^2 triangles and a little relief.
constexpr uint32_t kBinarySide = 1415;  // ~4M triangles
constexpr uint32_t kTextSide = 709;     // ~1M triangles

double height(uint32_t x, uint32_t y) { return double((x * 7 + y * 13) % 17) * 0.125; }

std::string tempPath(const char* name) {
  const char* dir = std::getenv("TMPDIR");
  return std::string(dir && *dir ? dir : "/tmp") + "/bench_readers_" + std::to_string(getpid()) + "_" + name;
}

void writeBinaryPly(const std::string& path, uint32_t side) {
  mt::PlyWriter w(path, mt::PlyWriteOptions{});
  for (uint32_t y = 0; y < side; ++y)
    for (uint32_t x = 0; x < side; ++x) {
      double p[3] = {x * 0.01, y * 0.01, height(x, y)};
      w.addVertex(p);
    }
  for (uint32_t y = 0; y + 1 < side; ++y)
    for (uint32_t x = 0; x + 1 < side; ++x) {
      uint32_t i = y * side + x;
      w.addTriangle(i, i + 1, i + side);
      w.addTriangle(i + 1, i + side + 1, i + side);
    }
  w.finish();
}

// Ascii PLY and OBJ share the body shape; only the header and the line prefixes differ.
void writeText(const std::string& path, uint32_t side, bool obj) {
  FILE* f = std::fopen(path.c_str(), "w");
  if (!f) std::abort();
  uint64_t tris = 2ull * (side - 1) * (side - 1);
  if (!obj)
    std::fprintf(f,
                 "ply\nformat ascii 1.0\nelement vertex %u\nproperty float x\nproperty float y\n"
                 "property float z\nelement face %llu\nproperty list uchar int vertex_indices\nend_header\n",
                 side * side, static_cast<unsigned long long>(tris));
  const char* vp = obj ? "v " : "";
  const char* fp = obj ? "f " : "3 ";
  const uint32_t base = obj ? 1 : 0;
  for (uint32_t y = 0; y < side; ++y)
    for (uint32_t x = 0; x < side; ++x) std::fprintf(f, "%s%.6g %.6g %.6g\n", vp, x * 0.01, y * 0.01, height(x, y));
  for (uint32_t y = 0; y + 1 < side; ++y)
    for (uint32_t x = 0; x + 1 < side; ++x) {
      uint32_t i = y * side + x + base;
      std::fprintf(f, "%s%u %u %u\n%s%u %u %u\n", fp, i, i + 1, i + side, fp, i + 1, i + side + 1, i + side);
    }
  std::fclose(f);
}

struct Files {
  std::string binaryPly = tempPath("binary.ply"), asciiPly = tempPath("ascii.ply"), obj = tempPath("mesh.obj");
  Files() {
    writeBinaryPly(binaryPly, kBinarySide);
    writeText(asciiPly, kTextSide, false);
    writeText(obj, kTextSide, true);
  }
  ~Files() {
    std::remove(binaryPly.c_str());
    std::remove(asciiPly.c_str());
    std::remove(obj.c_str());
  }
};

const Files& files() {
  static Files f;
  return f;
}

// Touches every delivered value so the work cannot be optimised away, and nothing more.
struct ChecksumSink : mt::MeshSink {
  double sum = 0;
  uint64_t indices = 0;
  void vertices(const mt::InputVertex* v, size_t count, uint64_t) override {
    for (size_t i = 0; i < count; ++i) sum += v[i].p[0] + v[i].p[2];
  }
  void triangles(const uint32_t* t, size_t count) override {
    for (size_t i = 0; i < count * 3; ++i) indices += t[i];
  }
};

void readFile(benchmark::State& state, const std::string& path) {
  uint64_t triangles = 0, bytes = 0;
  for (auto _ : state) {
    ChecksumSink sink;
    mt::ReadStats s = mt::openMesh(path)->read(sink);
    benchmark::DoNotOptimize(sink.sum);
    benchmark::DoNotOptimize(sink.indices);
    triangles += s.triangles;
    bytes += s.bytes;
  }
  state.SetItemsProcessed(int64_t(triangles));
  state.SetBytesProcessed(int64_t(bytes));
}

void BM_BinaryPly(benchmark::State& state) { readFile(state, files().binaryPly); }
void BM_AsciiPly(benchmark::State& state) { readFile(state, files().asciiPly); }
void BM_Obj(benchmark::State& state) { readFile(state, files().obj); }

BENCHMARK(BM_BinaryPly)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_AsciiPly)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Obj)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
