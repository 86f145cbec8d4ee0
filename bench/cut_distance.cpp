// Exact surface distances between a cut and its input, without sampling noise: the quick
// companion of bench/quality.sh (which uses MeshLab's Monte Carlo Hausdorff filter, the
// independent reference). Samples of the mesh measured FROM: the centroids of an n x n split of
// every triangle (area-weighted), n points along every edge (length-weighted) and every vertex a
// triangle uses (an unreferenced vertex is no part of the surface). Distances are exact
// point-to-surface distances (mtbuild/surface_distance.h), so two runs on the same files print the
// same digits and differences of a fraction of a percent between builds are real. MeshLab's
// filter (bench/hausdorff.sh) takes all vertices, S samples on the edges and S on the faces and
// averages over all of them; the first line's means blend the three parts the same way (S from
// --samples, default 2 M), which tracks MeshLab's ratios between two cuts to ~0.3%.
//
// Usage: bench_cut_distance INPUT CUT [--split-cut N] [--split-input N] [--samples S]
//                                      [--threads T] [--grid OX OY OZ STEP]
//   --split-cut/--split-input: n for samples on the cut (default 3) and on the input (default 1).
//   --grid: the MT's grid (mtinfo): also splits the cut's vertices into those on an input
//           vertex's grid point (kept, never moved) and the others, with their mean distances.
// Prints: the cut's triangle count, blended mean and max cut->input, then input->cut; the face,
// edge and vertex means apart; the cut's shape (mean quality, share below 0.3, edge length,
// spread of triangle areas).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

#include "base/error.h"
#include "mtbuild/surface_distance.h"
#include "patchstore/io/mesh_reader.h"

using namespace mt;

namespace {

struct Mesh {
  std::vector<double> positions;
  std::vector<uint32_t> triangles;
};

class Collect : public MeshSink {
 public:
  explicit Collect(Mesh& m) : m_(m) {}
  void vertices(const InputVertex* v, size_t count, uint64_t) override {
    for (size_t i = 0; i < count; ++i) m_.positions.insert(m_.positions.end(), v[i].p, v[i].p + 3);
  }
  void triangles(const uint32_t* indices, size_t count) override {
    for (size_t i = 0; i < count; ++i) {
      const uint32_t* t = indices + 3 * i;
      if (t[0] != t[1] && t[1] != t[2] && t[2] != t[0]) m_.triangles.insert(m_.triangles.end(), t, t + 3);
    }
  }

 private:
  Mesh& m_;
};

Mesh load(const std::string& path) {
  Mesh m;
  Collect sink(m);
  openMesh(path)->read(sink);
  return m;
}

struct Stats {
  double weightedSum = 0, weight = 0, max = 0;  // faces: area-weighted
  double edgeSum = 0, edgeWeight = 0;            // edges: length-weighted
  double vertexSum = 0;
  size_t vertices = 0;
  double at[3] = {0, 0, 0};  // where the maximum is
  void top(double d, const double* p) {
    if (d > max) max = d, at[0] = p[0], at[1] = p[1], at[2] = p[2];
  }
};

// Samples of `from` (n x n sub-triangle centroids per triangle, plus the vertices its triangles use)
// against the surface of `to`, on `threads` threads (one grid each: queries are not thread-safe).
Stats distances(const Mesh& from, const Mesh& to, int n, int threads) {
  const size_t nt = from.triangles.size() / 3, nv = from.positions.size() / 3;
  std::vector<uint64_t> edges;
  edges.reserve(3 * nt);
  for (size_t t = 0; t < nt; ++t)
    for (int c = 0; c < 3; ++c) {
      const uint64_t a = from.triangles[3 * t + c], b = from.triangles[3 * t + (c + 1) % 3];
      edges.push_back(a < b ? a << 32 | b : b << 32 | a);
    }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  // Only vertices some triangle uses are samples of the surface: a PLY may list others (a scan's
  // stray points, vertices the reader dropped a degenerate triangle of), which are no part of it.
  std::vector<uint8_t> used(nv, 0);
  for (uint32_t v : from.triangles) used[v] = 1;
  std::vector<Stats> part(static_cast<size_t>(threads));
  std::vector<std::thread> pool;
  for (int k = 0; k < threads; ++k)
    pool.emplace_back([&, k] {
      TriangleGrid grid(to.positions.data(), to.positions.size() / 3, to.triangles.data(), to.triangles.size() / 3);
      Stats& s = part[size_t(k)];
      for (size_t t = size_t(k); t < nt; t += size_t(threads)) {
        const double* p[3];
        for (int c = 0; c < 3; ++c) p[c] = &from.positions[3 * size_t(from.triangles[3 * t + c])];
        double e1[3], e2[3], cr[3];
        for (int a = 0; a < 3; ++a) e1[a] = p[1][a] - p[0][a], e2[a] = p[2][a] - p[0][a];
        cr[0] = e1[1] * e2[2] - e1[2] * e2[1], cr[1] = e1[2] * e2[0] - e1[0] * e2[2], cr[2] = e1[0] * e2[1] - e1[1] * e2[0];
        const double area = 0.5 * std::sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]);
        const double w = area / double(n * n);
        // Sub-triangle centroids: upward (i, j) and downward ones of an n x n split.
        for (int i = 0; i < n; ++i)
          for (int j = 0; i + j < n; ++j)
            for (int down = 0; down < (i + j + 1 < n ? 2 : 1); ++down) {
              const double u = (down ? (3 * i + 2) : (3 * i + 1)) / (3.0 * n);
              const double v = (down ? (3 * j + 2) : (3 * j + 1)) / (3.0 * n);
              double q[3];
              for (int a = 0; a < 3; ++a) q[a] = p[0][a] + u * (p[1][a] - p[0][a]) + v * (p[2][a] - p[0][a]);
              const double d = grid.distance(q);
              s.weightedSum += w * d, s.weight += w, s.top(d, q);
            }
      }
      for (size_t v = size_t(k); v < nv; v += size_t(threads)) {
        if (!used[v]) continue;
        const double d = grid.distance(&from.positions[3 * v]);
        s.top(d, &from.positions[3 * v]), s.vertexSum += d, ++s.vertices;
      }
      // Each edge once: n samples at the centres of n equal pieces, weighted by length.
      for (size_t e = size_t(k); e < edges.size(); e += size_t(threads)) {
        const double *pa = &from.positions[3 * (edges[e] >> 32)], *pb = &from.positions[3 * (edges[e] & 0xffffffffu)];
        const double len = std::sqrt((pa[0] - pb[0]) * (pa[0] - pb[0]) + (pa[1] - pb[1]) * (pa[1] - pb[1]) +
                                     (pa[2] - pb[2]) * (pa[2] - pb[2]));
        for (int i = 0; i < n; ++i) {
          const double u = (i + 0.5) / n;
          double q[3];
          for (int x = 0; x < 3; ++x) q[x] = pa[x] + u * (pb[x] - pa[x]);
          const double d = grid.distance(q);
          s.edgeSum += len / n * d, s.edgeWeight += len / n, s.top(d, q);
        }
      }
    });
  for (std::thread& t : pool) t.join();
  Stats all;
  for (const Stats& s : part) {
    all.weightedSum += s.weightedSum, all.weight += s.weight, all.top(s.max, s.at);
    all.edgeSum += s.edgeSum, all.edgeWeight += s.edgeWeight, all.vertexSum += s.vertexSum, all.vertices += s.vertices;
  }
  return all;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> files;
  int splitCut = 3, splitInput = 1, threads = 2;
  long meshlabSamples = 2000000;
  double grid[4] = {0, 0, 0, 0};
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--split-cut" && i + 1 < argc) splitCut = std::atoi(argv[++i]);
    else if (a == "--split-input" && i + 1 < argc) splitInput = std::atoi(argv[++i]);
    else if (a == "--threads" && i + 1 < argc) threads = std::atoi(argv[++i]);
    else if (a == "--samples" && i + 1 < argc) meshlabSamples = std::atol(argv[++i]);
    else if (a == "--grid" && i + 4 < argc)
      for (int k = 0; k < 4; ++k) grid[k] = std::atof(argv[++i]);
    else if (!a.empty() && a[0] == '-') files.clear(), files.resize(3);  // unknown option: usage
    else files.push_back(a);
  }
  if (files.size() != 2 || splitCut < 1 || splitInput < 1 || threads < 1) {
    std::fprintf(stderr, "usage: bench_cut_distance INPUT CUT [--split-cut N] [--split-input N] [--threads T]\n");
    return 2;
  }
  try {
    const Mesh input = load(files[0]), cut = load(files[1]);
    {
      // The cut's shape: mean quality (4 sqrt(3) area / sum of squared edges), the share below
      // 0.3, the total edge length and the spread of triangle areas (their coefficient of variation).
      double q = 0, area = 0, area2 = 0, len = 0;
      size_t poor = 0;
      const size_t nt = cut.triangles.size() / 3;
      for (size_t t = 0; t < nt; ++t) {
        const double* p[3];
        for (int c = 0; c < 3; ++c) p[c] = &cut.positions[3 * size_t(cut.triangles[3 * t + c])];
        double l2 = 0, e1[3], e2[3], cr[3];
        for (int c = 0; c < 3; ++c) {
          double d = 0;
          for (int a = 0; a < 3; ++a) d += (p[(c + 1) % 3][a] - p[c][a]) * (p[(c + 1) % 3][a] - p[c][a]);
          l2 += d, len += 0.5 * std::sqrt(d);  // interior edges are seen twice
        }
        for (int a = 0; a < 3; ++a) e1[a] = p[1][a] - p[0][a], e2[a] = p[2][a] - p[0][a];
        cr[0] = e1[1] * e2[2] - e1[2] * e2[1], cr[1] = e1[2] * e2[0] - e1[0] * e2[2], cr[2] = e1[0] * e2[1] - e1[1] * e2[0];
        const double ar = 0.5 * std::sqrt(cr[0] * cr[0] + cr[1] * cr[1] + cr[2] * cr[2]);
        const double qu = l2 > 0 ? 4 * std::sqrt(3.0) * ar / l2 : 0;
        q += qu, poor += qu < 0.3, area += ar, area2 += ar * ar;
      }
      const double mean = area / double(nt);
      std::printf("  shape: quality %.4f, %.2f%% below 0.3, edge length %.1f, area cv %.3f\n", q / double(nt),
                  100.0 * double(poor) / double(nt), len, std::sqrt(std::max(0.0, area2 / double(nt) - mean * mean)) / mean);
    }
    if (grid[3] > 0) {
      // Cut vertices on the grid point of an input vertex (kept, never moved) against the others.
      auto key = [&](const double* p) {
        uint64_t k = 0;
        for (int a = 0; a < 3; ++a) k = k * 2097152 + uint64_t(std::llround((p[a] - grid[a]) / grid[3]) & 2097151);
        return k;
      };
      std::vector<uint64_t> keys;
      for (size_t v = 0; v < input.positions.size() / 3; ++v) keys.push_back(key(&input.positions[3 * v]));
      std::sort(keys.begin(), keys.end());
      TriangleGrid tg(input.positions.data(), input.positions.size() / 3, input.triangles.data(), input.triangles.size() / 3);
      double sum[2] = {0, 0};
      size_t count[2] = {0, 0};
      std::vector<uint8_t> used(cut.positions.size() / 3, 0);
      for (uint32_t v : cut.triangles) used[v] = 1;
      for (size_t v = 0; v < cut.positions.size() / 3; ++v) {
        if (!used[v]) continue;
        const int on = std::binary_search(keys.begin(), keys.end(), key(&cut.positions[3 * v])) ? 1 : 0;
        sum[on] += tg.distance(&cut.positions[3 * v]), ++count[on];
      }
      std::printf("  vertices on an input vertex's grid point: %zu (mean %.6f); elsewhere: %zu (mean %.6f)\n", count[1],
                  sum[1] / double(count[1]), count[0], sum[0] / double(count[0]));
    }
    const Stats c = distances(cut, input, splitCut, threads);
    const Stats i = distances(input, cut, splitInput, threads);
    // MeshLab's Hausdorff filter (bench/hausdorff.sh) takes all vertices, S samples on the edges
    // and S on the faces, and averages over all of them: its mean is about the mean of the edge
    // and face means. Printed: that blend, then the face, edge and vertex means apart.
    auto blend = [&](const Stats& s) {
      const double S = double(meshlabSamples), nv = std::min<double>(double(s.vertices), S);
      return (nv * s.vertexSum / double(s.vertices) + S * s.edgeSum / s.edgeWeight + S * s.weightedSum / s.weight) /
             (nv + 2 * S);
    };
    std::printf("%zu  c->in %.6f %.4f  in->c %.6f %.4f\n", cut.triangles.size() / 3, blend(c), c.max, blend(i), i.max);
    std::printf("  c->in face %.6f edge %.6f vertex %.6f; in->c face %.6f edge %.6f vertex %.6f\n",
                c.weightedSum / c.weight, c.edgeSum / c.edgeWeight, c.vertexSum / double(c.vertices),
                i.weightedSum / i.weight, i.edgeSum / i.edgeWeight, i.vertexSum / double(i.vertices));
    std::printf("  max c->in at (%.4g %.4g %.4g); max in->c at (%.4g %.4g %.4g)\n", c.at[0], c.at[1], c.at[2], i.at[0],
                i.at[1], i.at[2]);
  } catch (const Error& e) {
    std::fprintf(stderr, "cut_distance: %s\n", e.what());
    return 1;
  }
  return 0;
}
