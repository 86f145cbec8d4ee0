// --smooth ITER: Taubin's lambda|mu smoothing (G. Taubin, "A signal processing approach to fair
// surface design", SIGGRAPH 1995): each iteration is a shrinking step x += lambda * L(x) and an
// inflating step x += mu * L(x) (mu < -lambda < 0), L the uniform umbrella operator (mean of the
// 1-ring minus the vertex). Jacobi steps: every new position comes from old positions only.
//
// Out of core, each step is two streaming passes over the patches:
//  A. Shared vertices: each holder emits, per neighbour of the vertex in its own triangles,
//     (vertex key, neighbour key, neighbour position); an external sort groups them by vertex and
//     drops neighbours seen from two patches, giving each shared vertex its whole 1-ring once.
//     The result (sum and count per shared vertex) is a table of O(shared vertices).
//  B. Each patch computes its interior vertices from its own triangles, takes its shared ones from
//     the table (so all copies of a vertex get bit-identical positions), and stages the new
//     geometry block. All blocks of the step become live in one manifest edit (commitStaged), so
//     pass A and B of the step read only old positions, exactly like an in-core Jacobi step.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <tuple>

#include "base/external_sort.h"
#include "base/memory_plan.h"
#include "base/interrupt.h"
#include "base/progress.h"
#include "patchstore/heal/region.h"

namespace mt::heal {

namespace {

struct RingRecord {
  uint64_t vertex, neighbour;
  double p[3];
};
struct RingLess {
  bool operator()(const RingRecord& a, const RingRecord& b) const {
    return std::tie(a.vertex, a.neighbour) < std::tie(b.vertex, b.neighbour);
  }
};
struct RingSum {
  uint64_t vertex;
  double sum[3];
  uint32_t count;
};

// Unique neighbours of every local vertex, from the patch's own triangles (CSR).
void localRings(const Patch& p, std::vector<uint32_t>& offset, std::vector<uint32_t>& ring) {
  std::vector<std::pair<uint32_t, uint32_t>> pairs;
  pairs.reserve(p.triangles.size() * 2);
  for (size_t t = 0; t < p.triangles.size(); t += 3)
    for (int c = 0; c < 3; ++c) {
      uint32_t a = p.triangles[t + c], b = p.triangles[t + (c + 1) % 3];
      if (a == b) continue;
      pairs.push_back({a, b});
      pairs.push_back({b, a});
    }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  offset.assign(p.vertexCount() + 1, 0);
  ring.resize(pairs.size());
  for (auto& pr : pairs) ++offset[pr.first + 1];
  for (uint32_t v = 0; v < p.vertexCount(); ++v) offset[v + 1] += offset[v];
  for (size_t i = 0; i < pairs.size(); ++i) ring[i] = pairs[i].second;  // pairs sorted by first
}

// `interruptible`: stop at a signal before anything of the step is committed (the lambda step:
// once it is committed, the mu step runs to its end, so the store only ever holds whole
// iterations).
void step(PatchStore& store, double factor, const HealOptions& options, const std::vector<PatchId>& ids,
          const std::string& task, bool interruptible) {
  auto poll = [&]() {
    if (interruptible) checkInterrupt(task);
  };
  // A. 1-rings of shared vertices.
  ExternalSorter<RingRecord, RingLess> sorter(scratchPrefix(store, options, "smooth"), planMemory(options.memoryBytes, 1).healSorter);
  std::vector<uint32_t> offset, ring;
  Progress progressA(options.progress, task + " rings", ids.size(), "patches");
  size_t done = 0;
  for (PatchId id : ids) {
    Patch p = store.patch(id);
    std::vector<uint64_t> key = ownerKeys(p);
    localRings(p, offset, ring);
    uint32_t last = kNoVertex;
    for (const BoundaryEntry& e : p.boundary) {
      if (e.local == last) continue;
      last = e.local;
      for (uint32_t i = offset[e.local]; i < offset[e.local + 1]; ++i) {
        uint32_t w = ring[i];
        sorter.add({key[e.local], key[w], {p.positions[3 * w], p.positions[3 * w + 1], p.positions[3 * w + 2]}});
      }
    }
    progressA.update(++done);
    poll();
  }
  sorter.finish();
  std::vector<RingSum> table;
  RingRecord r, prev{};
  bool have = false;
  while (sorter.next(r)) {
    if (!have || r.vertex != prev.vertex) table.push_back({r.vertex, {0, 0, 0}, 0});
    if (!have || r.vertex != prev.vertex || r.neighbour != prev.neighbour) {
      for (int a = 0; a < 3; ++a) table.back().sum[a] += r.p[a];
      ++table.back().count;
    }
    prev = r;
    have = true;
  }
  // B. New positions, staged.
  StagedUpdate staged;
  Progress progressB(options.progress, task + " move", ids.size(), "patches");
  done = 0;
  std::vector<uint8_t> shared;
  for (PatchId id : ids) {
    Patch p = store.patch(id);
    std::vector<uint64_t> key = ownerKeys(p);
    localRings(p, offset, ring);
    shared.assign(p.vertexCount(), 0);
    for (const BoundaryEntry& e : p.boundary) shared[e.local] = 1;
    std::vector<double> next = p.positions;
    for (uint32_t v = 0; v < p.vertexCount(); ++v) {
      double sum[3] = {0, 0, 0};
      uint32_t n = 0;
      if (shared[v]) {
        auto it = std::lower_bound(table.begin(), table.end(), key[v], [](const RingSum& s, uint64_t k) { return s.vertex < k; });
        if (it != table.end() && it->vertex == key[v]) {
          std::copy(it->sum, it->sum + 3, sum);
          n = it->count;
        }
      } else {
        for (uint32_t i = offset[v]; i < offset[v + 1]; ++i)
          for (int a = 0; a < 3; ++a) sum[a] += p.positions[3 * ring[i] + a];
        n = offset[v + 1] - offset[v];
      }
      if (n == 0) continue;  // isolated vertex: no umbrella
      for (int a = 0; a < 3; ++a) next[3 * v + a] = p.positions[3 * v + a] + factor * (sum[a] / n - p.positions[3 * v + a]);
    }
    p.positions.swap(next);
    store.stageGeometry(staged, p);
    progressB.update(++done);
    poll();
  }
  store.commitStaged(staged);
}

}  // namespace

PassReport smooth(PatchStore& store, uint32_t iterations, const HealOptions& options, double lambda, double mu) {
  auto start = std::chrono::steady_clock::now();
  store.sync();
  if (iterations > kMaxSmoothIterations)
    fail(store.dir(), "smooth: " + std::to_string(iterations) + " iterations is out of range (1 to " +
                          std::to_string(kMaxSmoothIterations) + ")");
  std::vector<PatchId> ids = store.patchIds();
  const uint64_t vertices = store.info().vertices;
  const bool tty = isatty(2);
  for (uint32_t i = 0; i < iterations; ++i) {
    auto t0 = std::chrono::steady_clock::now();
    std::string task = "smooth " + std::to_string(i + 1) + "/" + std::to_string(iterations);
    try {
      step(store, lambda, options, ids, task + " lambda", true);
    } catch (const Interrupted& e) {
      throw Interrupted("smooth: " + std::to_string(i) + " of " + std::to_string(iterations) +
                            " iterations done and kept in the store",
                        e.signal());
    }
    step(store, mu, options, ids, task + " mu", false);
    if (options.progress) {
      // One line per iteration: its rate, and the store's size against its live blocks (the
      // compaction bound).
      const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      const double total = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      StoreInfo info = store.info();
      std::fprintf(stderr, tty ? "\r\033[Kheal: %s: %.2f s (%.2f M vertices/s), store %.1f MiB (live %.1f MiB), ETA %.0f s%s"
                             : "heal: %s: %.2f s (%.2f M vertices/s), store %.1f MiB (live %.1f MiB), ETA %.0f s%s",
                   task.c_str(), s, s > 0 ? double(vertices) / s / 1e6 : 0.0, double(info.bytesOnDisk) / (1 << 20),
                   double(info.liveBytes) / (1 << 20), total / double(i + 1) * double(iterations - i - 1),
                   tty && i + 1 < iterations ? "" : "\n");
      std::fflush(stderr);
    }
    if (int sig = interruptRequested())
      throw Interrupted("smooth: " + std::to_string(i + 1) + " of " + std::to_string(iterations) +
                            " iterations done and kept in the store",
                        sig);
  }
  double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return {"smooth", {{"iterations", iterations}, {"patches", uint64_t(ids.size())}}, seconds};
}

}  // namespace mt::heal
