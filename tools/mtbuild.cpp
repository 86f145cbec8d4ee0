// mtbuild: build a batched Multi-Triangulation file from a scan (or a V-partitioned patch store).
#include <CLI/CLI.hpp>

#include <cinttypes>
#include <cstdio>
#include <fstream>

#include "mtbuild/build.h"
#include "patchstore/patch_store.h"

int main(int argc, char** argv) {
  CLI::App app{
      "mtbuild: batch-build a multiresolution MT file (a DAG of simplified, compressed patches) from a\n"
      "scan far larger than RAM, with memory capped. Same input and options give the same bytes,\n"
      "whatever --threads or --memory."};
  std::string input, output, memory = "1G", partition = "irregular", codec = "meshopt", statsJson, workDir, taskTimes;
  uint32_t threads = 0, patchTriangles = 0;
  bool normals = false, noNormals = false, resume = false, quiet = false;
  app.add_option("input", input, "Input mesh (PLY, OBJ, OFF, STL) or a patch store made by `mtstore ingest`")->required();
  app.add_option("-o,--output", output, "Output MT file (written as OUT.tmp, renamed when complete)")->required();
  app.add_option("--memory", memory, "Memory cap for the whole build, e.g. 512M, 4G (default 1G)");
  app.add_option("--threads", threads, "Worker threads (default: all cores); the output does not depend on it");
  app.add_option("--partition", partition, "V-partition: irregular (default; BMT 4.2.2) or regular (4.2.1)");
  app.add_option("--patch-triangles", patchTriangles, "Target triangles per patch (default 2000: smallest file at no extra build time, see docs/mt-format.md; ignored for a store input, which keeps its own)");
  app.add_option("--codec", codec, "Patch coding: meshopt (default, fast decode) or draco (smallest files)");
  app.add_flag("--normals", normals, "Store per-vertex normals (2x8 bit) instead of letting the renderer compute them");
  app.add_flag("--no-normals", noNormals, "Store no normals (the default; kept for scripts that say so explicitly)");
  app.add_flag("--resume", resume,
               "Continue a killed build from the checkpoint in its work directory (OUT.work): the last finished\n"
               "level; the same bytes as an uninterrupted build. Refused (with the reason) when the input or an\n"
               "option that changes the output differs (--threads and --memory may change). Without --resume an\n"
               "existing OUT.work is removed and the build starts over");
  app.add_option("--stats-json", statsJson, "Write build figures (per level, throughput, peak RSS, sizes) as JSON");
  app.add_option("--task-times", taskTimes,
                 "Write one CSV line per region (level, region, triangles, load/simplify/commit seconds, bytes a\n"
                 "cluster would move): the input of the scaling model in docs/cluster.md");
  app.add_option("--work-dir", workDir, "Scratch directory for the patch store (default OUT.work; up to ~3x the input)");
  app.add_flag("-q,--quiet", quiet, "No progress lines on stderr");
  CLI11_PARSE(app, argc, argv);
  try {
    if (normals && noNormals) throw mt::Error("--normals and --no-normals contradict each other");
    mt::BuildOptions o;
    o.memoryBytes = mt::parseSize(memory);
    o.threads = threads;
    o.partition = mt::parsePartitionKind(partition);
    o.patchTriangles = patchTriangles;
    if (codec == "meshopt") o.codec = mt::format::Codec::Meshopt;
    else if (codec == "draco") o.codec = mt::format::Codec::Draco;
    else throw mt::Error("unknown --codec '" + codec + "' (expected meshopt or draco)");
    o.normals = normals;
    o.resume = resume;
    o.progress = !quiet;
    o.workDir = workDir;
    o.taskTimesPath = taskTimes;
    mt::BuildReport r = mt::buildMt(input, output, o);
    std::fprintf(stderr,
                 "mtbuild: %" PRIu64 " input triangles -> %s: %" PRIu64 " nodes, %" PRIu64 " patches, %" PRIu64
                 " stored triangles, %.2f bytes/input triangle, %.1f s (%.2f M input triangles/s), peak RSS %.0f MiB, "
                 "peak temp disk %.0f MiB\n",
                 r.inputTriangles, output.c_str(), r.nodes, r.patches, r.storedTriangles,
                 double(r.fileBytes) / double(r.inputTriangles), r.totalSeconds,
                 double(r.inputTriangles) / r.totalSeconds / 1e6, double(r.peakRssBytes) / (1 << 20),
                 double(r.peakTempBytes) / (1 << 20));
    if (!statsJson.empty()) {
      std::ofstream f(statsJson);
      f << r.toJson();
      if (!f) throw mt::Error(statsJson + ": cannot write");
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mtbuild: %s\n", e.what());
    return 1;
  }
  return 0;
}
