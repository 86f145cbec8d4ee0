// mtbuild: build a batched Multi-Triangulation file from a scan (or a V-partitioned patch store).
#include <CLI/CLI.hpp>

#include <cinttypes>
#include <cstdio>

#include "base/exit_code.h"
#include "base/interrupt.h"
#include "base/output_path.h"
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
  CLI11_PARSE(app, argc, argv);
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
