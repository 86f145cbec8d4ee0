// mtstore: build, inspect, export and check an out-of-core patch store.
//   mtstore ingest IN -o STORE [--memory SIZE] [--patch-triangles N] [--partition KIND]
//   mtstore info STORE [--json]
//   mtstore export STORE -o OUT.ply
//   mtstore check STORE
//   mtstore heal STORE [--weld EPS] [--remove-degenerate] ... [--memory SIZE]  (passes in order given)
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cinttypes>
#include <filesystem>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <iostream>
#include <sstream>

#include "base/env.h"
#include "base/exit_code.h"
#include "base/interrupt.h"
#include "base/output_path.h"
#include "base/process.h"
#include "base/size.h"
#include "patchstore/heal/heal.h"
#include "patchstore/patch_store.h"
#include "patchstore/store_textures.h"
#include "tools/partition_choice.h"

namespace {

std::string ingestField(const std::string& report, const std::string& key) {
  std::istringstream s(report);
  std::string line;
  while (std::getline(s, line))
    if (line.rfind(key + "=", 0) == 0) return line.substr(key.size() + 1);
  return "";
}

std::string jsonEscape(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    if (static_cast<unsigned char>(c) < 0x20) continue;
    out += c;
  }
  return out;
}

int runInfo(const std::string& dir, bool json, bool components) {
  auto store = mt::PatchStore::open(dir);
  mt::StoreInfo s = store->info();
  std::string ingest = store->blob("ingest");
  const char* keys[] = {"input", "format", "inputTriangles", "inputVertices", "polygons", "degenerateTriangles",
                        "duplicateTriangles", "unreferencedVertices", "nonManifoldEdges", "assigner", "seconds"};
  std::string metrics = mt::tools::partitionMetrics(*store, json, components);
  if (json) {
    std::printf("{\n  \"store\": \"%s\",\n  \"patches\": %" PRIu64 ",\n  \"triangles\": %" PRIu64 ",\n  \"vertices\": %" PRIu64
                ",\n  \"triangles_per_patch\": {\"min\": %u, \"mean\": %.1f, \"max\": %u},\n  \"boundary_entries\": %" PRIu64
                ",\n  \"bytes_on_disk\": %" PRIu64 ",\n  \"layout\": {\"double\": %s, \"normals\": %s, \"colors\": %s, \"texcoords\": %s},\n",
                jsonEscape(dir).c_str(), s.patches, s.triangles, s.vertices, s.minPatchTriangles, s.meanPatchTriangles,
                s.maxPatchTriangles, s.boundaryEntries, s.bytesOnDisk, s.layout.doublePrecision ? "true" : "false",
                s.layout.normals ? "true" : "false", s.layout.colors ? "true" : "false", s.layout.texcoords ? "true" : "false");
    if (s.layout.texcoords) {
      std::printf("  \"materials\": [");
      const auto materials = mt::storeMaterials(*store);
      for (size_t k = 0; k < materials.size(); ++k)
        std::printf("%s{\"name\": \"%s\", \"image\": \"%s\", \"width\": %d, \"height\": %d, \"scaled_by\": %d, \"tiled_bytes\": %" PRIu64 "}",
                    k ? ", " : "", jsonEscape(materials[k].name).c_str(), jsonEscape(materials[k].source).c_str(), materials[k].width,
                    materials[k].height, 1 << materials[k].shift, materials[k].bytes);
      std::printf("],\n");
    }
    std::printf("  \"ingest\": {");
    bool first = true;
    for (const char* k : keys) {
      std::string v = ingestField(ingest, k);
      bool numeric = !v.empty() && v.find_first_not_of("0123456789.e+-") == std::string::npos;
      std::printf("%s\"%s\": %s%s%s", first ? "" : ", ", k, numeric ? "" : "\"", jsonEscape(v).c_str(), numeric ? "" : "\"");
      first = false;
    }
    std::printf("}%s\n", metrics.empty() ? "" : ",");
    if (!metrics.empty()) std::printf("  \"partition\": %s\n", metrics.c_str());
    std::printf("}\n");
  } else {
    std::printf("store            %s\n", dir.c_str());
    std::printf("patches          %" PRIu64 "\n", s.patches);
    std::printf("triangles        %" PRIu64 "\n", s.triangles);
    std::printf("vertices         %" PRIu64 "\n", s.vertices);
    std::printf("tris/patch       min %u  mean %.1f  max %u\n", s.minPatchTriangles, s.meanPatchTriangles, s.maxPatchTriangles);
    std::printf("boundary entries %" PRIu64 "\n", s.boundaryEntries);
    std::printf("bytes on disk    %" PRIu64 " (%.2f bytes/triangle)\n", s.bytesOnDisk,
                s.triangles ? double(s.bytesOnDisk) / double(s.triangles) : 0.0);
    std::printf("vertex layout    %s%s%s%s\n", s.layout.doublePrecision ? "double" : "float",
                s.layout.normals ? " +normals" : "", s.layout.colors ? " +colours" : "",
                s.layout.texcoords ? " +texture coordinates (per corner)" : "");
    if (s.layout.texcoords)
      for (const mt::StoreMaterial& m : mt::storeMaterials(*store))
        std::printf("material         %s: %s\n", m.name.c_str(),
                    m.file.empty() ? "no image"
                                   : (m.source + " (" + std::to_string(m.width) + " x " + std::to_string(m.height) +
                                      (m.shift ? ", scaled by 1/" + std::to_string(1 << m.shift) : std::string()) + ", " +
                                      std::to_string(m.bytes) + " bytes tiled)").c_str());
    if (!ingest.empty()) {
      std::printf("ingested from    %s (%s), %s triangles, %s vertices, in %s s\n", ingestField(ingest, "input").c_str(),
                  ingestField(ingest, "format").c_str(), ingestField(ingest, "inputTriangles").c_str(),
                  ingestField(ingest, "inputVertices").c_str(), ingestField(ingest, "seconds").c_str());
      std::printf("input defects    %s degenerate, %s duplicate faces, %s unreferenced vertices, %s non-manifold edges\n",
                  ingestField(ingest, "degenerateTriangles").c_str(), ingestField(ingest, "duplicateTriangles").c_str(),
                  ingestField(ingest, "unreferencedVertices").c_str(), ingestField(ingest, "nonManifoldEdges").c_str());
      std::printf("cell assignment  %s\n", ingestField(ingest, "assigner").c_str());
    }
    if (!metrics.empty()) std::printf("%s", metrics.c_str());
  }
  return 0;
}

// export: the PLY is written under a name of its own and renamed over OUT only when complete, so
// an error or a signal leaves OUT as it was.
void runExport(const std::string& dir, const std::string& output, bool quiet) {
  auto store = mt::PatchStore::open(dir);
  std::vector<std::string> inputs;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(dir, ec)) inputs.push_back(e.path().string());
  mt::checkOutputPath(output, inputs);
  const std::string tmp = mt::uniqueTempName(output);
  try {
    store->exportPly(tmp, !quiet);
    mt::checkInterrupt("export");
    mt::Env::Default()->renameFile(tmp, output);  // names the file (I/O error)
  } catch (...) {
    std::filesystem::remove(tmp, ec);
    throw;
  }
}

// The command line, as parsed (one subcommand runs: the store and output names are shared).
struct Args {
  std::string input, output, dir, memory = "256M", partition = mt::tools::kDefaultPartition;
  uint32_t patchTriangles = 0;
  int64_t levelRatio = mt::kDefaultLevelRatio;
  bool json = false, quiet = false, noComponents = false;
  // heal
  double weldEps = 0;
  uint64_t minComponent = 0;
  uint32_t maxHoleEdges = 0, smoothIterations = 0;
  std::string healMemory = "256M";
  bool flagDegenerate = false, flagDuplicate = false, flagUnreferenced = false, flagNonManifold = false;
  bool force = false;
};

// The heal passes' options; the passes run in the order they appear on the command line.
struct HealPasses {
  CLI::Option *weld = nullptr, *degenerate = nullptr, *duplicate = nullptr, *unreferenced = nullptr,
              *components = nullptr, *nonManifold = nullptr, *holes = nullptr, *smooth = nullptr;
  bool isPass(const CLI::Option* o) const {
    return o == weld || o == degenerate || o == duplicate || o == unreferenced || o == components ||
           o == nonManifold || o == holes || o == smooth;
  }
};

struct Commands {
  CLI::App *ingest = nullptr, *info = nullptr, *exportCmd = nullptr, *check = nullptr, *heal = nullptr;
  HealPasses passes;
};

void addIngest(CLI::App& app, Args& a, Commands& c) {
  c.ingest = app.add_subcommand("ingest", "Build a patch store from a mesh file (PLY with faces or triangle strips, OBJ, OFF, STL, glTF/GLB)");
  c.ingest->add_option("input", a.input, "Input mesh file")->required();
  c.ingest->add_option("-o,--output", a.output,
                       "Store directory to create (must not exist: an existing folder, even empty, is refused)")->required();
  c.ingest->add_option("--memory", a.memory, "Memory cap for the whole ingest, e.g. 256M, 4G (default 256M)");
  c.ingest->add_option("--patch-triangles", a.patchTriangles,
                       "Target triangles per patch (default: the partition's own, see docs/vpartition.md)");
  c.ingest->add_option("--partition", a.partition, mt::tools::partitionHelp());
  c.ingest->add_option("--level-ratio", a.levelRatio,
                       "Irregular partition: each level aims at 1/K of the cells of the one below, and mtbuild simplifies each\n"
                       "region to 1/K (default " + std::to_string(mt::kDefaultLevelRatio) + "; accepted " +
                           std::to_string(mt::kMinLevelRatio) + " to " + std::to_string(mt::kMaxLevelRatio) +
                           "; mtbuild --level-ratio, docs/mtbuild.md)");
  c.ingest->add_flag("-q,--quiet", a.quiet, "No progress lines on stderr");
}

void addInfoExportCheck(CLI::App& app, Args& a, Commands& c) {
  c.info = app.add_subcommand("info", "Print a store's statistics");
  c.info->add_option("store", a.dir, "Store directory")->required();
  c.info->add_flag("--json", a.json, "Machine-readable output");
  c.info->add_flag("--no-components", a.noComponents,
                   "Skip the per-level share of cells with several connected components (it reads every patch "
                   "about twice per level: minutes on stores of hundreds of millions of triangles)");

  c.exportCmd = app.add_subcommand("export", "Write the whole surface as one binary PLY");
  c.exportCmd->add_option("store", a.dir, "Store directory")->required();
  c.exportCmd->add_option("-o,--output", a.output, "Output PLY file")->required();
  c.exportCmd->add_flag("-q,--quiet", a.quiet, "No progress lines on stderr");

  c.check = app.add_subcommand("check", "Verify checksums and that every boundary entry is mirrored");
  c.check->add_option("store", a.dir, "Store directory")->required();
}

// heal: passes run in the order they appear on the command line (CLI11's parse order).
void addHeal(CLI::App& app, Args& a, Commands& c) {
  CLI::App* heal = c.heal = app.add_subcommand("heal", "Run healing passes on a store, out of core, in the order given");
  HealPasses& p = c.passes;
  heal->add_option("store", a.dir, "Store directory (changed in place)")->required();
  char weldHelp[256];
  std::snprintf(weldHelp, sizeof weldHelp,
                "Merge vertices closer than EPS into one, across patches too (0: exactly equal positions); EPS from 0 "
                "to %g%% of the bounding-box diagonal (more only with --force)",
                mt::heal::kMaxWeldFraction * 100);
  p.weld = heal->add_option("--weld", a.weldEps, weldHelp);
  p.degenerate = heal->add_flag("--remove-degenerate", a.flagDegenerate, "Remove triangles with a repeated vertex");
  p.duplicate = heal->add_flag("--remove-duplicate-faces", a.flagDuplicate,
                               "Remove triangles with the same three vertices as an earlier one");
  p.unreferenced = heal->add_flag("--remove-unreferenced", a.flagUnreferenced, "Remove vertices no triangle uses");
  p.components = heal->add_option(
      "--remove-small-components", a.minComponent,
      "Remove connected components with fewer than N triangles (even across patches); N >= 1; refused when it would "
      "remove every component, unless --force");
  p.nonManifold = heal->add_flag(
      "--fix-nonmanifold", a.flagNonManifold, "Split non-manifold edges (more than two triangles) and vertices (several fans) into manifold ones");
  p.holes = heal->add_option(
      "--fill-holes", a.maxHoleEdges,
      "Fill holes whose border has at most MAXEDGES edges: triangulate, refine and fair (CGAL), across patch borders "
      "too; MAXEDGES from 3 to 1000000");
  p.smooth = heal->add_option(
      "--smooth", a.smoothIterations,
      "Taubin smoothing (lambda 0.5, mu -0.53), ITER iterations from 1 to 1000000, borders included; old blocks are "
      "reclaimed as it goes (the store stays within about twice its live data)");
  heal->add_option("--memory", a.healMemory, "Memory cap for sorts and tables, e.g. 512M, 4G (default 256M)");
  heal->add_flag("--force", a.force,
                 "Run parameters refused as nonsense for the model: a --weld EPS above the diagonal fraction, a "
                 "--remove-small-components N that removes every component");
  heal->add_flag("-q,--quiet", a.quiet, "No progress lines on stderr");
}

int runIngest(const Args& a) {
  mt::IngestOptions options;
  options.memoryBytes = mt::parseSize(a.memory);
  options.patchTriangles = a.patchTriangles;
  options.progress = !a.quiet;
  auto assigner = mt::tools::makeAssigner(a.partition, a.patchTriangles, a.levelRatio);
  mt::IngestReport r;
  try {
    r = mt::PatchStore::ingest(a.input, a.output, *assigner, options);
  } catch (const mt::Interrupted& e) {
    std::fprintf(stderr, "mtstore: %s; nothing was written (no store %s, scratch removed)\n", e.what(), a.output.c_str());
    return 128 + e.signal();
  }
  std::fprintf(stderr, "ingested %" PRIu64 " triangles in %.2f s (%.2f M triangles/s), peak RSS %.1f MiB -> %s\n",
               r.inputTriangles, r.seconds, double(r.inputTriangles) / r.seconds / 1e6,
               double(r.peakBytes) / (1 << 20), a.output.c_str());
  if (r.degenerateTriangles || r.duplicateTriangles || r.unreferencedVertices || r.nonManifoldEdges)
    std::fprintf(stderr, "input defects: %" PRIu64 " degenerate triangles, %" PRIu64 " duplicate triangles, %" PRIu64
                 " unreferenced vertices, %" PRIu64 " non-manifold edges\n",
                 r.degenerateTriangles, r.duplicateTriangles, r.unreferencedVertices, r.nonManifoldEdges);
  return 0;
}

int runCheck(const std::string& dir) {
  auto store = mt::PatchStore::open(dir);
  mt::CheckReport r = store->check();
  for (const std::string& p : r.problems) std::fprintf(stderr, "%s\n", p.c_str());
  std::printf("%s: %" PRIu64 " patches, %" PRIu64 " boundary entries checked: %s\n", dir.c_str(), r.patchesChecked,
              r.entriesChecked, r.ok ? "OK" : "PROBLEMS FOUND");
  return r.ok ? 0 : mt::kExitCorruption;
}

// The heal command line's checks, before anything is opened: a pass is given and every range
// holds. Returns the exit code of a refusal, or -1.
int refuseHeal(const Args& a, const CLI::App& heal, const HealPasses& p) {
  const auto& order = heal.parse_order();
  if (order.empty() || std::none_of(order.begin(), order.end(), [&](const CLI::Option* o) { return p.isPass(o); })) {
    std::fprintf(stderr, "mtstore heal: no pass given (see mtstore heal --help)\n");
    return 1;
  }
  auto refuse = [](const std::string& what) {
    std::fprintf(stderr, "mtstore heal: %s\n", what.c_str());
    return 1;
  };
  if (*p.weld && (!std::isfinite(a.weldEps) || a.weldEps < 0))
    return refuse("--weld " + p.weld->as<std::string>() + ": EPS must be a finite number >= 0");
  if (*p.components && a.minComponent < 1) return refuse("--remove-small-components 0: N must be at least 1");
  if (*p.holes && (a.maxHoleEdges < mt::heal::kMinHoleEdges || a.maxHoleEdges > mt::heal::kMaxHoleEdges))
    return refuse("--fill-holes " + std::to_string(a.maxHoleEdges) + ": MAXEDGES must be from 3 to 1000000");
  if (*p.smooth && (a.smoothIterations < 1 || a.smoothIterations > mt::heal::kMaxSmoothIterations))
    return refuse("--smooth " + std::to_string(a.smoothIterations) + ": ITER must be from 1 to 1000000");
  return -1;
}

// Runs the pass of option o; false when o is not a pass (--memory, --quiet, --force, the store).
bool runPass(const CLI::Option* o, const HealPasses& p, const Args& a, mt::PatchStore& store,
             const mt::heal::HealOptions& options, mt::heal::PassReport& r) {
  if (o == p.weld) r = mt::heal::weld(store, a.weldEps, options);
  else if (o == p.degenerate) r = mt::heal::removeDegenerate(store, options);
  else if (o == p.duplicate) r = mt::heal::removeDuplicateFaces(store, options);
  else if (o == p.unreferenced) r = mt::heal::removeUnreferenced(store, options);
  else if (o == p.components) r = mt::heal::removeSmallComponents(store, a.minComponent, options);
  else if (o == p.nonManifold) r = mt::heal::fixNonManifold(store, options);
  else if (o == p.holes) r = mt::heal::fillHoles(store, a.maxHoleEdges, options);
  else if (o == p.smooth) r = mt::heal::smooth(store, a.smoothIterations, options);
  else return false;
  return true;
}

// What a signal leaves: the passes that finished are committed; smoothing keeps its whole
// iterations (the message says how many); the rest did not run.
int healStopped(const mt::Interrupted& e, bool inPass, const std::string& dir, const std::vector<std::string>& names,
                size_t done) {
  auto list = [&](size_t from, size_t to) {
    std::string out;
    for (size_t i = from; i < to && i < names.size(); ++i) out += (out.empty() ? "" : ", ") + names[i];
    return out.empty() ? std::string("none") : out;
  };
  const size_t k = done;
  std::fprintf(stderr, "mtstore heal: %s; the store is at its last committed version: passes finished: %s%s%s; not run: %s\n",
               e.what(), list(0, k).c_str(), inPass ? "; stopped in: " : "", inPass ? list(k, k + 1).c_str() : "",
               list(k + (inPass ? 1 : 0), names.size()).c_str());
  std::error_code ec;
  std::filesystem::remove_all(dir + "/tmp", ec);
  return 128 + e.signal();
}

int runHeal(const Args& a, const CLI::App& heal, const HealPasses& p) {
  mt::heal::HealOptions options;
  options.memoryBytes = mt::parseSize(a.healMemory);
  options.progress = !a.quiet;
  if (int code = refuseHeal(a, heal, p); code >= 0) return code;
  options.force = a.force;
  const std::string& dir = a.dir;
  auto store = mt::PatchStore::open(dir);
  // One writer at a time: a second heal is refused here, before it reads or writes anything.
  store->lockForWriting();
  std::error_code tmpEc;
  if (std::filesystem::exists(dir + "/tmp", tmpEc)) {
    // Under the lock, nobody uses the store's scratch: it is what a killed heal left.
    std::filesystem::remove_all(dir + "/tmp", tmpEc);
    std::fprintf(stderr, "heal: removed %s/tmp, scratch left by an earlier heal that was stopped\n", dir.c_str());
  }
  std::vector<std::string> names;
  for (const CLI::Option* o : heal.parse_order())
    if (p.isPass(o)) names.push_back(o->get_name(false, true));
  size_t done = 0;
  for (const CLI::Option* o : heal.parse_order()) {
    mt::heal::PassReport r;
    try {
      if (!runPass(o, p, a, *store, options, r)) continue;
    } catch (const mt::Interrupted& e) {
      return healStopped(e, true, dir, names, done);
    } catch (...) {
      std::error_code ec;
      std::filesystem::remove_all(dir + "/tmp", ec);
      throw;
    }
    std::printf("%s\n", r.line().c_str());
    std::fflush(stdout);
    ++done;
    // Between passes is a safe point: every pass ends with a commit.
    if (int sig = mt::interruptRequested(); sig && done < names.size())
      return healStopped(mt::Interrupted("heal: after " + names[done - 1], sig), false, dir, names, done);
  }
  store->sync();
  std::error_code ec;
  std::filesystem::remove_all(dir + "/tmp", ec);
  std::fprintf(stderr, "heal: peak RSS %.1f MiB\n", double(mt::peakRssBytes()) / (1 << 20));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  mt::installInterruptHandlers();
  CLI::App app{"mtstore: the out-of-core patch store (ingest a scan, inspect, export, check)"};
  app.require_subcommand(1);
  app.set_help_all_flag("--help-all", "Print the help of every subcommand");
  Args a;
  Commands c;
  addIngest(app, a, c);
  addInfoExportCheck(app, a, c);
  addHeal(app, a, c);
  CLI11_PARSE(app, argc, argv);
  try {
    if (*c.ingest) return runIngest(a);
    if (*c.info) return runInfo(a.dir, a.json, !a.noComponents);
    if (*c.exportCmd) {
      runExport(a.dir, a.output, a.quiet);
      return 0;
    }
    if (*c.heal) return runHeal(a, *c.heal, c.passes);
    if (*c.check) return runCheck(a.dir);
  } catch (const std::exception& e) {
    return mt::reportError("mtstore", e);
  }
  return 0;
}
