// The option set mtbuild and mtcluster share (mtcluster takes every mtbuild option): one
// definition, so both say the same in --help and refuse the same values, each refusal naming the
// option and its accepted range.
#pragma once

#include <CLI/CLI.hpp>
#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>

#include "base/error.h"
#include "base/memory_plan.h"
#include "base/output_path.h"
#include "base/size.h"
#include "mtbuild/build.h"
#include "patchstore/patch_store.h"

namespace mt::tools {

// --threads: at most this many (beyond it TBB only adds overhead on any machine we know of).
constexpr int64_t kMaxBuildThreads = 1024;

inline uint64_t physicalRamBytes() {
  long pages = ::sysconf(_SC_PHYS_PAGES), size = ::sysconf(_SC_PAGESIZE);
  return pages > 0 && size > 0 ? uint64_t(pages) * uint64_t(size) : uint64_t(1) << 40;
}

inline std::string sizeText(uint64_t bytes) {
  char buf[32];
  if (bytes >= (uint64_t(1) << 30)) std::snprintf(buf, sizeof buf, "%.1fG", double(bytes) / double(1 << 30));
  else std::snprintf(buf, sizeof buf, "%.0fM", double(bytes) / double(1 << 20));
  return buf;
}

// --memory: from the least the build honours (kMinBuildMemory) to the machine's physical RAM (a
// cap above it is no cap, and sizes the buffers beyond what can be allocated).
inline uint64_t parseBuildMemory(const std::string& text) {
  const uint64_t ram = physicalRamBytes();
  const std::string range = " (accepted " + sizeText(kMinBuildMemory) + " to " + sizeText(ram) + ", this machine's RAM)";
  size_t pos = 0;
  double value = 0;
  try {
    value = std::stod(text, &pos);
  } catch (...) {
    throw Error("--memory '" + text + "': not a size such as 512M or 4G" + range);
  }
  uint64_t unit = 0;
  try {
    unit = parseSize("1" + text.substr(pos));
  } catch (const Error&) {
    throw Error("--memory '" + text + "': unknown unit (use K, M, G or T)" + range);
  }
  const double bytes = value * double(unit);
  if (!std::isfinite(bytes) || bytes < double(kMinBuildMemory) || bytes > double(ram))
    throw Error("--memory " + text + ": out of range" + range);
  return uint64_t(bytes);
}

inline std::string weightText(double w) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", w);
  return b;
}

struct BuildCli {
  std::string input, output, crs, memory = "1G", partition = "irregular", codec = "meshopt", indexOrder = "list", simplifier = "auto", statsJson, workDir, taskTimes;
  double colorWeight = kDefaultColorWeight;
  int64_t threads = 0, patchTriangles = 0, levelRatio = 0;  // signed, so that -1 is refused with the range, not wrapped
  int64_t textureQuality = 90;
  bool normals = false, noNormals = false, resume = false, quiet = false;
  CLI::Option *threadsOption = nullptr, *patchTrianglesOption = nullptr,
              *levelRatioOption = nullptr;  // given explicitly: --patch-triangles 0 and --level-ratio 0 are refused

  // `tool`: "mtbuild" or "mtcluster"; `cluster` adds what differs in the help.
  void add(CLI::App& app, bool cluster) {
    app.add_option("input", input,
                   cluster ? "Input mesh (PLY with faces or triangle strips, OBJ, OFF, STL, glTF/GLB) or a patch store made by `mtstore ingest`, read by rank 0"
                           : "Input mesh (PLY with faces or triangle strips, OBJ, OFF, STL, glTF/GLB) or a patch store made by `mtstore ingest`")
        ->required();
    app.add_option("-o,--output", output,
                   std::string("Output MT file, ending in .mt") + (cluster ? ", written by rank 0" : "") +
                       " (written as OUT.tmp.PID.RANDOM, renamed over OUT only when\n"
                       "complete; OUT may not be the input; OUT.lock is held meanwhile, so a second build of OUT is refused)")
        ->required();
    app.add_option("--memory", memory,
                   std::string(cluster ? "Memory cap of rank 0's ingest and store" : "Memory cap for the whole build") +
                       ", e.g. 512M, 4G (default 1G; accepted " + sizeText(kMinBuildMemory) + " to this machine's RAM, " +
                       sizeText(physicalRamBytes()) + ")" +
                       (cluster ? "" : ".\nIt bounds the stages' buffers; what stays resident beside them grows with the input "
                                       "(a billion triangles peak at ~390 MiB at 256M, ~430 at 512M),\nand a peak above the cap is "
                                       "reported at the end"));
    threadsOption = app.add_option("--threads", threads,
                   std::string(cluster ? "Threads of a one-rank run" : "Worker threads") + " (default 0: all cores; 0 to " +
                       std::to_string(kMaxBuildThreads) + "); the output does not depend on it");
    app.add_option("--partition", partition, "V-partition: irregular (default; BMT 4.2.2) or regular (4.2.1)");
    patchTrianglesOption = app.add_option("--patch-triangles", patchTriangles,
                   "Target triangles per patch (default " + std::to_string(kDefaultMtPatchTriangles) +
                       ": smallest file at no extra build time, see docs/mt-format.md;\naccepted " +
                       std::to_string(kMinPatchTriangles) + " to " + std::to_string(kMaxPatchTriangles) +
                       ": below, the per-patch record outweighs the geometry; above, a region no longer fits\na small "
                       "memory cap and a level has too few regions to share out; ignored for a store input, which keeps "
                       "its own)");
    levelRatioOption = app.add_option("--level-ratio", levelRatio,
                   "Each level keeps 1/K of the triangles of the level below (default 2: BMT's halving; accepted " +
                       std::to_string(kMinLevelRatio) + " to " + std::to_string(kMaxLevelRatio) +
                       ",\nirregular partition only). 4 builds in ~0.7x the time, and writes a file of ~0.55x the size, whose\n"
                       "cuts lie 5-30% farther from the input at equal triangles: a node refines 4x its triangles at once, and\n"
                       "a region holds ~2x the triangles (docs/mtbuild.md). A store input keeps the ratio `mtstore ingest` gave it");
    app.add_option("--codec", codec, "Patch coding: meshopt (default, fast decode) or draco (smallest files)");
    app.add_option("--index-order", indexOrder,
                   "Meshopt triangle coding: list (default: the triangle list, in its own order when coherent, else in\n"
                   "fans) or strip (tri-strips, BMT 6; larger files, see docs/mt-format.md)");
    app.add_option("--simplifier", simplifier,
                   "Region simplifier: auto (default: quadric when the input has per-vertex colours, else meshopt),\n"
                   "meshopt (half-edge collapse, every vertex an input vertex; ignores colours: they are carried, not\n"
                   "kept) or quadric (edge collapse with optimal placement: closer to the input at equal size, ~1.7x the\n"
                   "build CPU, docs/mtbuild.md; with colours, colour enters the collapse cost so colour edges survive,\n"
                   "docs/appearance.md)");
    app.add_option("--color-weight", colorWeight,
                   "With colours and the quadric simplifier: a full-range colour difference costs as much as moving the\n"
                   "surface by this many mean edge lengths of the region (default " + weightText(kDefaultColorWeight) +
                       "; 0: colours are carried but do not\nsteer the simplification; accepted 0 to 100)");
    app.add_flag("--normals", normals, "Store per-vertex normals (2x8 bit) instead of letting the renderer compute them");
    app.add_flag("--no-normals", noNormals, "Store no normals (the default; kept for scripts that say so explicitly)");
    app.add_flag("--resume", resume,
                 "Continue a stopped build (killed, or interrupted with Ctrl-C) from the checkpoint in its work directory:\n"
                 "the last finished level; the same bytes as an uninterrupted build" +
                     std::string(cluster ? ", with any number of ranks" : "") +
                     ". Refused (with the reason) when the input\n"
                     "(size, time, a hash of every byte) or an option that changes the output differs (--threads and "
                     "--memory may\nchange). Without --resume the work of an earlier build is removed and the build starts over");
    app.add_option("--stats-json", statsJson,
                   cluster ? "Write build figures and per-rank busy time, bytes, efficiency as JSON"
                           : "Write build figures (per level, throughput, CPU user/sys per level and of the ingest, peak RSS,\nsizes) as JSON");
    app.add_option("--task-times", taskTimes,
                   "Write one CSV line per region (level, region, triangles, load/simplify/commit seconds, bytes a\n"
                   "cluster would move): the input of the scaling model in docs/cluster.md");
    app.add_option("--work-dir", workDir,
                   std::string(cluster ? "Rank 0's scratch" : "Scratch") +
                       " directory for the patch store (default OUT.work; about the input's size). Created\n"
                       "and marked (" + kWorkMarker +
                       ") by the build, removed when it completes. An existing directory the build did not\n"
                       "make (\".\", the input's folder) is never emptied: the build works in DIR/OUT.work inside it");
    app.add_option("--crs", crs,
                   "Coordinate reference system of the input's positions (e.g. EPSG:32633, or a WKT string; 1 to 65536 bytes,\n"
                   "no NUL), stored in the MT file and printed by mtinfo; not interpreted (positions are kept as given)");
    app.add_option("--texture-quality", textureQuality,
                   "Textured inputs (OBJ map_Kd, PLY TextureFile): JPEG quality 1-100 of the atlases in the file (default 90).\n"
                   "Every patch gets its own atlas: the finest keep the input's texels, coarser ones are re-baked\n"
                   "(docs/appearance.md)");
    app.add_flag("-q,--quiet", quiet, "No progress lines on stderr");
  }

  // The validated options; throws mt::Error naming the option and its accepted range.
  BuildOptions options(const std::string& tool) const {
    if (normals && noNormals) throw Error("--normals and --no-normals contradict each other");
    BuildOptions o;
    if (crs.size() > 65536 || crs.find('\0') != std::string::npos)
      throw Error("--crs: 1 to 65536 bytes without NUL (got " + std::to_string(crs.size()) + " bytes)");
    o.crs = crs;
    if (textureQuality < 1 || textureQuality > 100)
      throw Error("--texture-quality " + std::to_string(textureQuality) + ": out of range (accepted 1 to 100; default 90)");
    o.textureQuality = int(textureQuality);
    o.memoryBytes = parseBuildMemory(memory);
    o.levelLoopBytes = planMemory(o.memoryBytes, 1).levelLoop;  // the plan's share for the regions in flight
    const bool threadsGiven = threadsOption && threadsOption->count() > 0;
    const bool patchGiven = patchTrianglesOption && patchTrianglesOption->count() > 0;
    // 0 is "all cores", as the default and as mtgen's --threads 0.
    if (threadsGiven && (threads < 0 || threads > kMaxBuildThreads))
      throw Error("--threads " + std::to_string(threads) + ": out of range (accepted 0 to " + std::to_string(kMaxBuildThreads) +
                  "; 0, the default, is all cores)");
    o.threads = uint32_t(threads);
    if ((patchGiven || patchTriangles != 0) && (patchTriangles < kMinPatchTriangles || patchTriangles > kMaxPatchTriangles))
      throw Error("--patch-triangles " + std::to_string(patchTriangles) + ": out of range (accepted " +
                  std::to_string(kMinPatchTriangles) + " to " + std::to_string(kMaxPatchTriangles) + "; default " +
                  std::to_string(kDefaultMtPatchTriangles) + ")");
    o.patchTriangles = uint32_t(patchTriangles);
    const bool ratioGiven = levelRatioOption && levelRatioOption->count() > 0;
    o.partition = parsePartitionKind(partition);
    if (ratioGiven || levelRatio != 0) checkLevelRatio(levelRatio, o.partition);
    o.levelRatio = uint32_t(levelRatio);
    if (codec == "meshopt") o.codec = format::Codec::Meshopt;
    else if (codec == "draco") o.codec = format::Codec::Draco;
    else throw Error("unknown --codec '" + codec + "' (expected meshopt or draco)");
    if (indexOrder != "list" && indexOrder != "strip")
      throw Error("unknown --index-order '" + indexOrder + "' (expected list or strip)");
    if (indexOrder == "strip" && o.codec != format::Codec::Meshopt)
      throw Error("--index-order strip needs --codec meshopt (Draco's edgebreaker chooses its own order)");
    o.strips = indexOrder == "strip";
    if (simplifier == "quadric") o.simplifier = RegionSimplifier::Quadric;
    else if (simplifier == "meshopt") o.simplifier = RegionSimplifier::Meshopt;
    else if (simplifier == "auto") o.simplifierByInput = true;
    else throw Error("unknown --simplifier '" + simplifier + "' (expected auto, quadric or meshopt)");
    if (!(colorWeight >= 0 && colorWeight <= 100))
      throw Error("--color-weight " + weightText(colorWeight) + ": out of range (accepted 0 to 100; default " +
                  weightText(kDefaultColorWeight) + ")");
    o.colorWeight = colorWeight;
    // The output may not be the input (by inode, whatever the spelling): said first, as it matters
    // most. The MT tools know a file by its contents, but a build's output named .ply or .glb
    // would be taken for one by everything else.
    checkOutputPath(output, {input});
    if (output.size() < 4 || output.compare(output.size() - 3, 3, ".mt") != 0 || output.back() == '/')
      throw Error("-o " + output + ": an MT file name must end in .mt");
    o.normals = normals;
    o.resume = resume;
    o.progress = !quiet;
    o.workDir = workDir;
    o.taskTimesPath = taskTimes;
    o.toolName = tool;
    return o;
  }
};

}  // namespace mt::tools
