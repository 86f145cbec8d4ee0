// mtverify: check the invariants an MT file promises (BRIEF "Invariants").
//   mtverify OUT.mt [--cuts K] [--seed S] [--memory SIZE] [--quiet]
// 1. every payload's checksum and decode (each damaged patch reported, and checking goes on);
// 2. DAG shape: source has no predecessors, sink no successors, acyclic, every inner node on arcs;
// 3. monotone errors (BMT 4.1, 5.1): a node's error >= each predecessor's, the sink's is +inf;
// 4. nested spheres: each node's sphere contains its predecessors' spheres and the vertices of its
//    fragment (patches on its out-arcs) and of its floor (patches on its in-arcs, up to the node's
//    error), with a relative tolerance for the float radius plus the quantization error. The
//    source is left out: it is in every cut, never refined past, so its sphere means nothing
//    (the builder writes radius 0); what a node must hold of it is its floor;
// 5. crack-free cuts: the finest and coarsest cuts and K random valid cuts, each welded by exact
//    grid position, are conforming by the rule in mtfile/mt_cut.h (no boundary / non-manifold
//    edge away from the input's own). The cuts are never assembled: their edges are counted in
//    parts that fit --memory (mt_cut.h "Conformity in bounded memory"), so any file size can be
//    checked; the payload pass of 1 gathers the patches' grid boxes the parts are planned from.
// One line per problem on stderr, a summary on stdout; exit 0 only if everything holds. Files of
// a million input triangles or more also get a progress line per step on stderr ("mtverify: ...")
// unless --quiet.
#include <CLI/CLI.hpp>
#include <malloc.h>

#include <chrono>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "base/error.h"
#include "base/exit_code.h"
#include "base/output_path.h"
#include "base/process.h"
#include "base/size.h"
#include "mtfile/mt_cut.h"
#include "mtfile/mt_file.h"
#include "base/cli_checks.h"

namespace {

using mt::format::NodeRecord;

// Problem lines, capped per kind so a badly broken file does not flood the terminal.
class Problems {
 public:
  explicit Problems(std::string path) : path_(std::move(path)) {}
  void add(const std::string& kind, const std::string& line) {
    std::lock_guard<std::mutex> g(lock_);
    ++total_;
    uint64_t& n = perKind_[kind];
    if (++n <= kCap) std::fprintf(stderr, "%s\n", line.c_str());
  }
  void flushCaps() {
    for (const auto& [kind, n] : perKind_)
      if (n > kCap) std::fprintf(stderr, "%s: ... and %" PRIu64 " more %s problems\n", path_.c_str(), n - kCap, kind.c_str());
  }
  uint64_t total() const { return total_; }
  uint64_t count(const std::string& kind) const {
    auto it = perKind_.find(kind);
    return it == perKind_.end() ? 0 : it->second;
  }

 private:
  static constexpr uint64_t kCap = 50;
  std::string path_;
  std::mutex lock_;
  std::map<std::string, uint64_t> perKind_;
  uint64_t total_ = 0;
};

double distance(const double a[3], const double b[3]) {
  double s = 0;
  for (int i = 0; i < 3; ++i) s += (a[i] - b[i]) * (a[i] - b[i]);
  return std::sqrt(s);
}

std::string nodeName(const mt::MtFileReader& r, uint32_t v) {
  return "node " + std::to_string(v) + " (level " + std::to_string(r.nodes()[v].level) + ")";
}

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Each random cut is welded and counted in full: a million is days on a large file, more a typo.
constexpr uint32_t kMaxCuts = 1'000'000;

// Radii are floats: allow their rounding (2^-24 relative, with margin) plus one quantization
// step, since a builder may bound the input's positions rather than the quantized ones.
double sphereSlack(double radius, double quantizationError) { return 1e-6 * std::abs(radius) + quantizationError; }

// 2. DAG shape: the source has no predecessors, the sink no successors, every other node an
// outgoing arc, and no cycle (topologicalOrder throws on one: nothing else can be checked then).
void checkDagShape(const mt::MtFileReader& r, const std::string& path, Problems& problems) {
  const auto& nodes = r.nodes();
  const uint32_t sink = uint32_t(nodes.size() - 1);
  if (nodes[0].backArcCount) problems.add("dag", path + ": the source (node 0) has predecessors");
  if (nodes[sink].arcCount) problems.add("dag", path + ": the sink (node " + std::to_string(sink) + ") has successors");
  for (uint32_t v = 0; v < sink; ++v)
    if (!nodes[v].arcCount) problems.add("dag", path + ": " + nodeName(r, v) + " has no outgoing arc (not connected to the sink)");
  mt::topologicalOrder(r);
}

// 3. Monotone errors: a node's error >= each predecessor's, the sink's +inf; the same for the
// colour error (mt_format.h NodeRecord::colorError).
void checkMonotoneErrors(const mt::MtFileReader& r, const std::string& path, Problems& problems) {
  const auto& nodes = r.nodes();
  const uint32_t sink = uint32_t(nodes.size() - 1);
  if (!std::isinf(nodes[sink].error) || nodes[sink].error < 0)
    problems.add("error", path + ": the sink's error is " + std::to_string(nodes[sink].error) + ", not +inf");
  for (uint32_t v = 0; v < nodes.size(); ++v) {
    if (std::isnan(nodes[v].error) || nodes[v].error < 0)
      problems.add("error", path + ": " + nodeName(r, v) + " has error " + std::to_string(nodes[v].error));
    if (std::isnan(nodes[v].colorError) || nodes[v].colorError < 0)
      problems.add("error", path + ": " + nodeName(r, v) + " has colour error " + std::to_string(nodes[v].colorError));
    const NodeRecord& n = nodes[v];
    for (uint32_t k = 0; k < n.backArcCount; ++k) {
      uint32_t u = r.arcs()[r.backArcs()[n.firstBackArc + k]].from;
      if (!(n.error >= nodes[u].error)) {
        char buf[256];
        std::snprintf(buf, sizeof buf, "%s: error not monotone: %s has error %.9g < its predecessor node %u's %.9g",
                      path.c_str(), nodeName(r, v).c_str(), double(n.error), u, double(nodes[u].error));
        problems.add("error", buf);
      }
      if (!(n.colorError >= nodes[u].colorError)) {
        char buf[256];
        std::snprintf(buf, sizeof buf, "%s: colour error not monotone: %s has colour error %.9g < its predecessor node %u's %.9g",
                      path.c_str(), nodeName(r, v).c_str(), double(n.colorError), u, double(nodes[u].colorError));
        problems.add("error", buf);
      }
    }
  }
  // The colour error (file version 5 on): 0 at the source; with colours, +inf at the sink; without, 0 everywhere.
  if (r.header().version >= mt::format::kFirstColorErrorVersion) {
    const bool colors = r.header().vertexFlags & mt::format::kHasColors;
    if (nodes[0].colorError != 0) problems.add("error", path + ": the source's colour error is " + std::to_string(nodes[0].colorError) + ", not 0");
    if (colors && !std::isinf(nodes[sink].colorError))
      problems.add("error", path + ": the sink's colour error is " + std::to_string(nodes[sink].colorError) + ", not +inf");
    if (!colors)
      for (uint32_t v = 0; v < nodes.size(); ++v)
        if (nodes[v].colorError != 0) {
          problems.add("error", path + ": " + nodeName(r, v) + " has colour error " + std::to_string(nodes[v].colorError) +
                                    " in a file without colours");
          break;
        }
  }
}

// 4a. Spheres nested. The source is left out as a predecessor: it is never refined past and its
// sphere means nothing; what a node must contain of it is its floor, the patches on the arc
// source -> node (checked with the payloads). The sink's sphere means nothing either.
void checkNestedSpheres(const mt::MtFileReader& r, const std::string& path, Problems& problems) {
  const auto& nodes = r.nodes();
  const uint32_t sink = uint32_t(nodes.size() - 1);
  const double qErr = r.header().quantizationError;
  for (uint32_t v = 1; v < sink; ++v) {
    const NodeRecord& n = nodes[v];
    for (uint32_t k = 0; k < n.backArcCount; ++k) {
      uint32_t u = r.arcs()[r.backArcs()[n.firstBackArc + k]].from;
      if (u == 0) continue;
      double reach = distance(n.center, nodes[u].center) + double(nodes[u].radius);
      if (reach > double(n.radius) + sphereSlack(n.radius, qErr)) {
        char buf[256];
        std::snprintf(buf, sizeof buf, "%s: sphere of %s (radius %.9g) does not contain predecessor node %u's (reaches %.9g)",
                      path.c_str(), nodeName(r, v).c_str(), double(n.radius), u, reach);
        problems.add("sphere", buf);
      }
    }
  }
}

// What the payload pass gathers.
struct PayloadScan {
  std::vector<mt::GridBox> patchBoxes;  // for planning the crack check's parts
  std::vector<mt::PatchDamage> damage;
  std::vector<uint8_t> isDamaged;       // per patch
  // Triangles with two corners at one grid point, per patch: a cut drops them when it welds, so
  // a build must have removed them (the grid weld) and counted them in the header.
  std::vector<uint32_t> degenerate;
  std::vector<double> worstOutside;     // per node: max distance of its patches beyond its sphere
};

// 1 + 4b. Every payload: checksum, decode, and its vertices inside the sphere of the node whose
// fragment it is (arc.from) and of the node whose floor it is (arc.to); source and sink skipped.
// A damaged patch keeps the box `everything` (cuts holding one are skipped anyway).
PayloadScan scanPayloads(const mt::MtFileReader& r) {
  const auto& nodes = r.nodes();
  const uint32_t sink = uint32_t(nodes.size() - 1);
  const double qErr = r.header().quantizationError;
  const mt::QuantizationGrid grid = r.grid();
  PayloadScan scan;
  scan.patchBoxes.assign(r.patches().size(), mt::GridBox::everything());
  scan.degenerate.assign(r.patches().size(), 0);
  scan.worstOutside.assign(nodes.size(), 0.0);
  std::mutex worstLock;
  std::vector<mt::PatchDamage> damaged = mt::checkAllPatches(r, [&](uint32_t p, const mt::DecodedPatch& d) {
    scan.patchBoxes[p] = mt::patchBox(d);
    for (uint32_t t = 0; t < d.triangleCount(); ++t) {
      const uint32_t* q[3] = {&d.q[3 * d.triangles[3 * t]], &d.q[3 * d.triangles[3 * t + 1]], &d.q[3 * d.triangles[3 * t + 2]]};
      auto same = [](const uint32_t* a, const uint32_t* b) { return a[0] == b[0] && a[1] == b[1] && a[2] == b[2]; };
      scan.degenerate[p] += same(q[0], q[1]) || same(q[1], q[2]) || same(q[0], q[2]);
    }
    const mt::format::ArcRecord& arc = r.arcs()[r.patches()[p].arc];
    for (uint32_t v : {arc.from, arc.to}) {
      if (v == 0 || v == sink) continue;
      const NodeRecord& n = nodes[v];
      // The floor may stick out of a sphere fitted to the fragment by up to the node's error
      // (the fragment is within that of its floor).
      const double allowed = double(n.radius) + sphereSlack(n.radius, qErr) + (v == arc.to ? double(n.error) : 0.0);
      double worst = 0;
      for (uint32_t i = 0; i < d.vertexCount(); ++i) {
        double pos[3];
        for (int a = 0; a < 3; ++a) pos[a] = grid.dequantize(a, d.q[3 * i + a]);
        worst = std::max(worst, distance(pos, n.center) - allowed);
      }
      if (worst > 0) {
        std::lock_guard<std::mutex> g(worstLock);
        scan.worstOutside[v] = std::max(scan.worstOutside[v], worst);
      }
    }
  });
  scan.damage = std::move(damaged);
  return scan;
}

// The damaged payloads, one problem each, named with the node whose fragment they are.
void reportDamage(const mt::MtFileReader& r, PayloadScan& scan, Problems& problems) {
  scan.isDamaged.assign(r.patches().size(), 0);
  for (const auto& d : scan.damage) {
    scan.isDamaged[d.patch] = 1;
    uint32_t v = r.arcs()[r.patches()[d.patch].arc].from;
    problems.add("checksum", d.message + " [" + nodeName(r, v) + "]");
  }
}

// The finest cut holds every input triangle but those the build recorded as welded away; then
// the nodes whose patches reach outside their spheres.
void checkInputKeptAndReach(const mt::MtFileReader& r, const std::string& path, const PayloadScan& scan,
                            Problems& problems) {
  const mt::format::FileHeader& h = r.header();
  uint64_t finest = 0, finestDegenerate = 0, anyDegenerate = 0;
  for (uint32_t p = 0; p < r.patches().size(); ++p) {
    anyDegenerate += scan.degenerate[p];
    if (r.arcs()[r.patches()[p].arc].from == 0)
      finest += r.patches()[p].triangles - scan.degenerate[p], finestDegenerate += scan.degenerate[p];
  }
  if (finest + h.weldedTriangles != h.inputTriangles)
    problems.add("lost", path + ": the finest cut has " + std::to_string(finest) + " triangles (" +
                             std::to_string(finestDegenerate) + " degenerate ones dropped); the input had " +
                             std::to_string(h.inputTriangles) + " and the build recorded " +
                             std::to_string(h.weldedTriangles) + " as welded away");
  else if (anyDegenerate)
    problems.add("lost", path + ": " + std::to_string(anyDegenerate) +
                             " stored triangles have two corners at one grid point (cuts drop them)");
  for (uint32_t v = 0; v < r.nodes().size(); ++v)
    if (scan.worstOutside[v] > 0) {
      char buf[256];
      std::snprintf(buf, sizeof buf, "%s: %s has vertices of its fragment or floor up to %.9g outside its sphere", path.c_str(),
                    nodeName(r, v).c_str(), scan.worstOutside[v]);
      problems.add("sphere", buf);
    }
}

struct CutCheck {
  uint32_t checked = 0, conforming = 0;
  size_t cuts = 0;
  bool haveReference = false;
  mt::ConformityReference reference;
};

// Whether a cut's arcs hold a damaged patch.
bool touchesDamage(const mt::MtFileReader& r, const std::vector<uint32_t>& arcs, const std::vector<uint8_t>& isDamaged) {
  bool touches = false;
  for (uint32_t a : arcs)
    for (uint32_t k = 0; k < r.arcs()[a].patchCount; ++k) touches |= isDamaged[r.patchRefs()[r.arcs()[a].firstPatchRef + k]] != 0;
  return touches;
}

// What --memory leaves the crack-free check's edge table and reference lists. --memory bounds the
// whole process: the file's DAG and index, the payload scan's per-patch arrays (boxes, degenerate
// counts, damage flags) and the process itself stay resident through the check, measured here
// with the heap trimmed; each cut adds its node set, its arcs and, while it is counted, its
// patches' ids, part members and plan items (kCutBytesPerPatch); the threads' decode scratch
// gets kScratchBytes. Given the whole of --memory instead, the edge table made a billion-triangle
// file's check peak at 1190 MiB under --memory 1G.
constexpr uint64_t kCutBytesPerPatch = 32, kScratchBytes = 8ull << 20, kLeastEdgeBudget = 1ull << 20;
uint64_t edgeCountBudget(const mt::MtFileReader& r, uint64_t memoryBytes, size_t cuts, bool progress) {
  malloc_trim(0);
  const uint64_t resident = mt::currentRssBytes();
  const uint64_t perCut = uint64_t(cuts) * r.nodes().size() + 4 * uint64_t(r.arcs().size()) + kCutBytesPerPatch * r.patches().size();
  const uint64_t beside = resident + perCut + kScratchBytes;
  // Below what stays resident, the tables get kLeastEdgeBudget (or all of a smaller --memory, as
  // tests use to force many parts): the process then exceeds --memory by the resident part.
  const uint64_t least = std::min(memoryBytes, kLeastEdgeBudget);
  const uint64_t budget = memoryBytes > beside + least ? memoryBytes - beside : least;
  if (progress)
    std::fprintf(stderr, "mtverify: --memory %.0f MiB: %.0f MiB resident (DAG, index, per-patch arrays, the process), %.0f MiB for the cuts' arrays and scratch, %.0f MiB for the edge tables%s\n",
                 double(memoryBytes) / double(1 << 20), double(resident) / double(1 << 20), double(perCut + kScratchBytes) / double(1 << 20),
                 double(budget) / double(1 << 20), memoryBytes < beside + least ? " (less than the file needs: the check exceeds --memory)" : "");
  return budget;
}

// 5. Crack-free cuts: the finest (the reference), the coarsest and `randomCuts` random ones.
// Cuts touching a damaged patch cannot be assembled: reported and skipped.
CutCheck checkCuts(const mt::MtFileReader& r, const std::string& path, uint32_t randomCuts, uint64_t seed,
                   uint64_t memoryBytes, bool progress, const PayloadScan& scan, Problems& problems) {
  std::vector<std::pair<std::string, mt::Cut>> cuts;
  cuts.push_back({"finest cut", mt::finestCut(r)});
  cuts.push_back({"coarsest cut", mt::coarsestCut(r)});
  std::mt19937_64 rng(seed);
  for (uint32_t k = 0; k < randomCuts; ++k) cuts.push_back({"random cut " + std::to_string(k), mt::randomCut(r, rng)});
  mt::EdgeCountOptions countOptions;
  countOptions.memoryBytes = edgeCountBudget(r, memoryBytes, cuts.size(), progress);
  countOptions.patchBoxes = &scan.patchBoxes;
  CutCheck c;
  c.cuts = cuts.size();
  for (size_t i = 0; i < cuts.size(); ++i) {
    const auto& [name, cut] = cuts[i];
    std::string why;
    if (!mt::isValidCut(r, cut.inSet, &why)) {
      problems.add("cut", path + ": " + name + " is not a valid cut: " + why);  // a bug in mt_cut, not in the file
      continue;
    }
    mt::CutStats stats = mt::cutStats(r, cut.inSet);
    const std::vector<uint32_t> arcs = mt::cutArcs(r, cut.inSet);
    if (touchesDamage(r, arcs, scan.isDamaged)) {
      // The damaged payloads are reported above, each once.
      if (i == 0) problems.add("cut", path + ": crack-free check skipped: the finest cut (the reference) has a damaged patch");
      continue;
    }
    if (i > 0 && !c.haveReference) continue;  // nothing to compare with
    mt::EdgeCountStats counted;
    mt::ConformityReport rep;
    if (i == 0) {
      // The finest cut against the reference made from it conforms by construction (every edge
      // the rule looks at is one the reference was made from): one pass instead of two.
      c.reference = mt::makeConformityReference(r, arcs, countOptions, &counted);
      c.haveReference = true;
      rep.edges = c.reference.edges;
    } else {
      rep = mt::checkConforming(r, arcs, c.reference, countOptions, &counted);
    }
    if (progress)
      std::fprintf(stderr, "mtverify: %s: %" PRIu64 " triangles, %u parts%s, %.2f patch reads per patch, %.1f s\n",
                   name.c_str(), counted.triangles, counted.parts,
                   counted.splitParts ? (" (" + std::to_string(counted.splitParts) + " split)").c_str() : "",
                   counted.patches ? double(counted.patchReads) / double(counted.patches) : 0.0, counted.seconds);
    ++c.checked;
    if (rep.conforming()) {
      ++c.conforming;
    } else {
      problems.add("crack", path + ": crack in " + name + " (" + std::to_string(stats.nodes) + " nodes, " +
                                std::to_string(stats.triangles) + " triangles): " + std::to_string(rep.newBoundaryEdges) +
                                " boundary and " + std::to_string(rep.newNonManifoldEdges) +
                                " non-manifold edges the input does not have; first: " + rep.firstProblem);
    }
  }
  return c;
}

void printSummary(const mt::MtFileReader& r, const std::string& path, const Problems& problems, size_t damaged,
                  const CutCheck& c, uint32_t randomCuts, uint64_t seed) {
  std::printf("%s: %zu nodes, %zu arcs, %zu patches\n", path.c_str(), r.nodes().size(), r.arcs().size(), r.patches().size());
  std::printf("  payloads         %zu checked, %zu damaged\n", r.patches().size(), damaged);
  std::printf("  input kept       %s (%" PRIu64 " triangles, %" PRIu64 " welded away by the build)\n",
              problems.count("lost") ? "PROBLEMS" : "ok", r.header().inputTriangles, r.header().weldedTriangles);
  std::printf("  DAG shape        %s\n", problems.count("dag") ? "PROBLEMS" : "ok");
  std::printf("  monotone errors  %s\n", problems.count("error") ? "PROBLEMS" : "ok");
  std::printf("  nested spheres   %s\n", problems.count("sphere") ? "PROBLEMS" : "ok");
  std::printf("  crack-free cuts  %u of %u conforming (finest, coarsest, %u random; seed %" PRIu64 ")", c.conforming,
              c.checked, randomCuts, seed);
  if (c.checked < c.cuts) std::printf(", %zu not checked (damaged patches)", c.cuts - c.checked);
  if (c.haveReference)
    std::printf(", input has %" PRIu64 " boundary and %" PRIu64 " non-manifold edges", c.reference.edges.boundaryEdges,
                c.reference.edges.nonManifoldEdges);
  std::printf("\n%s\n", problems.total() ? "FAILED" : "OK");
}

int run(const std::string& path, uint32_t randomCuts, uint64_t seed, uint64_t memoryBytes, bool quiet) {
  const auto started = std::chrono::steady_clock::now();
  mt::requireRegularFile(path, "an MT file");  // a FIFO would block the reader, a device mislead it
  auto reader = mt::MtFileReader::open(path);
  const mt::MtFileReader& r = *reader;
  Problems problems(path);
  if (r.nodes().size() < 2) mt::fail(path, "the DAG has fewer than 2 nodes (no source and sink)");
  checkDagShape(r, path, problems);
  checkMonotoneErrors(r, path, problems);
  checkNestedSpheres(r, path, problems);
  const bool progress = !quiet && r.header().inputTriangles >= 1000000;
  PayloadScan scan = scanPayloads(r);
  if (progress)
    std::fprintf(stderr, "mtverify: payloads: %zu patches read and checked, %.1f s\n", r.patches().size(), secondsSince(started));
  reportDamage(r, scan, problems);
  checkInputKeptAndReach(r, path, scan, problems);
  const CutCheck cuts = checkCuts(r, path, randomCuts, seed, memoryBytes, progress, scan, problems);
  problems.flushCaps();
  std::fflush(stderr);
  printSummary(r, path, problems, scan.damage.size(), cuts, randomCuts, seed);
  return problems.total() ? mt::kExitCorruption : 0;  // a file of ours that breaks its promises
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"mtverify: check that a batched Multi-Triangulation file (.mt) keeps its promises: every payload's\n"
               "checksum; the DAG's shape; errors monotone towards the sink (sink +inf); bounding spheres nested\n"
               "and containing their patches; and crack-free cuts: the finest, the coarsest and K random valid\n"
               "cuts, each welded by exact grid position, may have no boundary or non-manifold edge away from the\n"
               "input's own (rule in mtfile/mt_cut.h). One line per problem on stderr; exit 0 only if all hold, 3 if not.\n"
               "Memory: --memory bounds the whole process: the file's DAG and index and the check's own per-patch\n"
               "arrays (about 120 bytes per patch in all, ~0.15 byte per input triangle) are measured and the rest\n"
               "goes to the edge tables. Cuts are never assembled: their edges are counted in parts that fit what\n"
               "is left (32-byte table slots, 3/4 full at most), each part reading only the patches near it, so\n"
               "less memory means more parts but hardly more reading.\n"
               "The input's boundary and non-manifold vertices (12 bytes each) are kept throughout and must fit a\n"
               "quarter of --memory."};
  std::string path, memory = "1G";
  uint32_t cuts = 8;
  uint64_t seed = 1;
  bool quiet = false;
  app.add_option("file", path, "The MT file to verify")->required();
  app.add_option("--cuts", cuts, "Random valid cuts to check besides the finest and coarsest")
      ->check(mt::cli::countIn(0, kMaxCuts))
      ->capture_default_str();
  app.add_option("--seed", seed, "Seed of the random cuts (the same seed checks the same cuts)")
      ->check(mt::cli::countIn(0, UINT64_MAX))
      ->capture_default_str();
  app.add_option("--memory", memory,
                 "Memory for the crack-free check, from 64K to 1024T, e.g. 512M, 4G (K, M, G, T are powers of 1024); "
                 "results do not depend on it")
      ->capture_default_str();
  app.add_flag("-q,--quiet", quiet, "No progress lines on stderr (printed for files of 1M input triangles or more)");
  app.footer(
      "Huge pages: with --memory 256M or more (the default 1G), mtverify restarts itself once with\n"
      "GLIBC_TUNABLES=glibc.malloc.hugetlb=1 (appended to any GLIBC_TUNABLES), so that glibc's malloc asks for\n"
      "transparent huge pages: less time filling large arrays, the same results. Not when MT_NO_HUGEPAGES=1, when\n"
      "GLIBC_TUNABLES already sets glibc.malloc.hugetlb, or when the kernel's transparent huge pages are never.");
  if (int code = mt::cli::parse(app, argc, argv, "mtverify"); code >= 0) return code;
  try {
    // Below 64K the edge table is its 4096-slot minimum anyway and the reference lists get a few
    // KiB: no file worth checking fits.
    const uint64_t memoryBytes = mt::cli::sizeOption(memory, "--memory", uint64_t(64) << 10, uint64_t(1) << 50, "64K", "1024T");
    // glibc's malloc on transparent huge pages (base/process.h), as mtbuild: the index, the
    // per-patch arrays and the edge tables are filled once each; on 4 KiB pages their first
    // touches cost ~10 us a page here (docs/mtbuild.md, "Checking cuts in bounded memory").
    if (memoryBytes >= mt::kMallocHugePagesFromMemory) mt::reexecWithMallocHugePages(argv);
    return run(path, cuts, seed, memoryBytes, quiet);
  } catch (const std::exception& e) {
    return mt::reportError("mtverify", e);
  }
}
