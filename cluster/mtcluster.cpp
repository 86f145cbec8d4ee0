// mtcluster: the batched MT build distributed over MPI ranks, same bytes as mtbuild.
//   mpirun -np N mtcluster IN -o OUT.mt [every mtbuild option]
#include <CLI/CLI.hpp>
#include <mpi.h>

#include <cinttypes>
#include <cstdio>
#include <cstdlib>

#include "base/exit_code.h"
#include "base/interrupt.h"
#include "base/output_path.h"
#include "cluster/cluster_build.h"
#include "patchstore/patch_store.h"
#include "tools/build_cli.h"

int main(int argc, char** argv) {
  CLI::App app{
      "mtcluster: mtbuild on an MPI cluster. Rank 0 ingests and plans, hands each level's regions to the\n"
      "ranks as they become idle (patches travel as MPI messages: no shared filesystem needed), commits\n"
      "the results in region order and writes the file: the same bytes as mtbuild, for any number of\n"
      "ranks. Run it as: mpirun -np N mtcluster IN -o OUT.mt [options]. One rank is the ordinary build.\n"
      "If a rank dies, mpirun stops the job; rank 0 says which level and regions were in flight, and\n"
      "--resume continues from the last finished level (the checkpoint format of mtbuild --resume)."};
  mt::tools::BuildCli cli;
  cli.add(app, true);
  const std::string& input = cli.input;
  const std::string& output = cli.output;
  const bool& quiet = cli.quiet;  // read after parsing
  const char* rankEnv = std::getenv("OMPI_COMM_WORLD_RANK");
  const bool rankZero = !rankEnv || std::atoi(rankEnv) == 0;
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (!rankZero) return e.get_exit_code();
    return app.exit(e);
  }
  mt::BuildOptions o;
  try {
    o = cli.options("mtcluster");
  } catch (const std::exception& e) {
    if (rankZero) std::fprintf(stderr, "mtcluster: %s\n", e.what());
    return 1;
  }
  // Rank 0 commits on a second thread; only the main thread calls MPI.
  int provided = 0;
  MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided);
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  try {
    mt::cluster::ClusterReport report = mt::cluster::runCluster(input, output, o);
    if (rank == 0) {
      const mt::BuildReport& r = report.build;
      mt::cluster::describe(report, !quiet);
      std::fprintf(stderr,
                   "mtcluster: %" PRIu64 " input triangles -> %s: %" PRIu64 " nodes, %" PRIu64 " patches, %.2f bytes/input "
                   "triangle, %.1f s (%.2f M input triangles/s), rank 0 peak RSS %.0f MiB\n",
                   r.inputTriangles, output.c_str(), r.nodes, r.patches, double(r.fileBytes) / double(r.inputTriangles),
                   r.totalSeconds, double(r.inputTriangles) / r.totalSeconds / 1e6, double(r.peakRssBytes) / (1 << 20));
      if (!cli.statsJson.empty()) {
        mt::writeWholeFile(cli.statsJson, report.build.toJson());
      }
    }
  } catch (const mt::BuildInterrupted& e) {
    // Workers may be mid-region: stop the job; the work and the temporary file stay for --resume.
    std::fprintf(stderr, "mtcluster: %s\n", e.what());
    std::fflush(stderr);
    MPI_Abort(MPI_COMM_WORLD, 128 + e.signal());
    return 128 + e.signal();
  } catch (const mt::cluster::StoppedCleanly& e) {
    std::fprintf(stderr, "mtcluster: %s\n", e.what());
    MPI_Finalize();
    return 1;
  } catch (const std::exception& e) {
    const int code = mt::reportError("mtcluster", e);
    std::fflush(stderr);
    // Other ranks may be mid-region or waiting for rank 0: stop them all (the work directory and
    // temporary MT file stay for --resume when a level was checkpointed).
    MPI_Abort(MPI_COMM_WORLD, code);
    return code;
  }
  MPI_Finalize();
  return 0;
}
