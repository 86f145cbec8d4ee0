// mtbuild: build a batched Multi-Triangulation file from a scan (or a V-partitioned patch store).
#include <CLI/CLI.hpp>

#include <cinttypes>
#include <cstdio>

#include "base/exit_code.h"
#include "base/interrupt.h"
#include "base/output_path.h"
#include "base/process.h"
#include "mtbuild/build.h"
#include "patchstore/patch_store.h"
#include "tools/build_cli.h"

int main(int argc, char** argv) {
  CLI::App app{
      "mtbuild: batch-build a multiresolution MT file (a DAG of simplified, compressed patches) from a\n"
      "scan far larger than RAM, with memory capped. Same input and options give the same bytes,\n"
      "whatever --threads or --memory."};
  mt::tools::BuildCli cli;
  cli.add(app, false);
  app.footer(
      "Huge pages: with --memory 256M or more, mtbuild restarts itself once with GLIBC_TUNABLES=glibc.malloc.hugetlb=1\n"
      "(appended to any GLIBC_TUNABLES), so that glibc's malloc asks for transparent huge pages when the kernel's\n"
      "/sys/kernel/mm/transparent_hugepage/enabled is madvise or always: less CPU, the same bytes (docs/mtbuild.md).\n"
      "Not when MT_NO_HUGEPAGES=1, when GLIBC_TUNABLES already sets glibc.malloc.hugetlb, or when that mode is never.");
  CLI11_PARSE(app, argc, argv);
  // From --memory 256M up: glibc malloc on transparent huge pages (base/process.h; docs/mtbuild.md,
  // "Where the CPU goes"): fewer page faults and TLB misses over the region buffers, the same
  // bytes. Below 256M a 2 MiB page's unused part weighs on the cap.
  try {
    if (mt::tools::parseBuildMemory(cli.memory) >= mt::kMallocHugePagesFromMemory) mt::reexecWithMallocHugePages(argv);
  } catch (const mt::Error&) {
    // an unusable --memory is refused below, with its range
  }
  const std::string& output = cli.output;
  // Ctrl-C / SIGTERM stop at the next safe point and say what was kept for --resume.
  mt::installInterruptHandlers();
  try {
    mt::BuildOptions o = cli.options("mtbuild");
    mt::BuildReport r = mt::buildMt(cli.input, output, o);
    std::fprintf(stderr,
                 "mtbuild: %" PRIu64 " input triangles -> %s: %" PRIu64 " nodes, %" PRIu64 " patches, %" PRIu64
                 " stored triangles, %.2f bytes/input triangle, %.1f s (%.2f M input triangles/s), peak RSS %.0f MiB, "
                 "peak temp disk %.0f MiB\n",
                 r.inputTriangles, output.c_str(), r.nodes, r.patches, r.storedTriangles,
                 double(r.fileBytes) / double(r.inputTriangles), r.totalSeconds,
                 double(r.inputTriangles) / r.totalSeconds / 1e6, double(r.peakRssBytes) / (1 << 20),
                 double(r.peakTempBytes) / (1 << 20));
    // The cap bounds the stages' buffers (base/memory_plan.h); what stays resident beside them
    // grows with the input and is not capped, so a small cap on a large input can be passed.
    // Said here, with where the peak was, rather than left for the user to find in the figures.
    if (r.peakRssBytes > o.memoryBytes) {
      const bool inIngest = r.ingestPeakRssBytes == r.peakRssBytes;
      std::fprintf(stderr,
                   "mtbuild: note: peak RSS %.0f MiB was above --memory %s (%s). The cap bounds the stages' buffers; "
                   "the process, the store's patch records, the V-partition and the DAG stay resident beside them "
                   "and grow with the input (docs/mtbuild.md, \"Below the cap\")\n",
                   double(r.peakRssBytes) / (1 << 20), cli.memory.c_str(),
                   inIngest ? "in the ingest" : "after the ingest: in the level loop or the file's index");
    }
    if (!cli.statsJson.empty()) {
      mt::writeWholeFile(cli.statsJson, r.toJson());
    }
  } catch (const mt::BuildInterrupted& e) {
    std::fprintf(stderr, "mtbuild: %s\n", e.what());
    return 128 + e.signal();
  } catch (const mt::Interrupted& e) {
    std::fprintf(stderr, "mtbuild: %s\n", e.what());
    return 128 + e.signal();
  } catch (const std::exception& e) {
    return mt::reportError("mtbuild", e);
  }
  return 0;
}
