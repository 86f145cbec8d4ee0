// mtcluster: the batched MT build distributed over MPI ranks (issue 6), same bytes as mtbuild.
//   mpirun -np N mtcluster IN -o OUT.mt [every mtbuild option]
#include <CLI/CLI.hpp>
#include <mpi.h>

#include <cinttypes>
#include <cstdio>
#include <cstdlib>
#include <fstream>

#include "cluster/cluster_build.h"
#include "patchstore/patch_store.h"

int main(int argc, char** argv) {
  CLI::App app{
      "mtcluster: mtbuild on an MPI cluster. Rank 0 ingests and plans, hands each level's regions to the\n"
      "ranks as they become idle (patches travel as MPI messages: no shared filesystem needed), commits\n"
      "the results in region order and writes the file: the same bytes as mtbuild, for any number of\n"
      "ranks. Run it as: mpirun -np N mtcluster IN -o OUT.mt [options]. One rank is the ordinary build.\n"
      "If a rank dies, mpirun stops the job; rank 0 says which level and regions were in flight, and\n"
      "--resume continues from the last finished level (the checkpoint format of mtbuild --resume)."};
  std::string input, output, memory = "1G", partition = "irregular", codec = "meshopt", statsJson, workDir, taskTimes;
  uint32_t threads = 0, patchTriangles = 0;
  bool normals = false, noNormals = false, resume = false, quiet = false;
  app.add_option("input", input, "Input mesh (PLY, OBJ, OFF, STL) or a patch store made by `mtstore ingest`, read by rank 0")
      ->required();
  app.add_option("-o,--output", output, "Output MT file, written by rank 0 (as OUT.tmp, renamed when complete)")->required();
  app.add_option("--memory", memory, "Memory cap of rank 0's ingest and store, e.g. 512M, 4G (default 1G)");
  app.add_option("--threads", threads, "Threads of a one-rank run (default: all cores); the output does not depend on it");
  app.add_option("--partition", partition, "V-partition: irregular (default; BMT 4.2.2) or regular (4.2.1)");
  app.add_option("--patch-triangles", patchTriangles, "Target triangles per patch (default 2000, as mtbuild; see docs/mt-format.md)");
  app.add_option("--codec", codec, "Patch coding: meshopt (default, fast decode) or draco (smallest files)");
  app.add_flag("--normals", normals, "Store per-vertex normals (2x8 bit) instead of letting the renderer compute them");
  app.add_flag("--no-normals", noNormals, "Store no normals (the default)");
  app.add_flag("--resume", resume,
               "Continue a stopped build from the checkpoint in OUT.work (its last finished level); any number of\n"
               "ranks, same bytes. Refused with the reason when the input or a byte-changing option differs");
  app.add_option("--stats-json", statsJson, "Write build figures and per-rank busy time, bytes, efficiency as JSON");
  app.add_option("--task-times", taskTimes, "Write one CSV line per region (times, triangles, bytes moved); see docs/cluster.md");
  app.add_option("--work-dir", workDir, "Rank 0's scratch directory for the patch store (default OUT.work)");
  app.add_flag("-q,--quiet", quiet, "No progress lines on stderr");
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
    if (normals && noNormals) throw mt::Error("--normals and --no-normals contradict each other");
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
    o.toolName = "mtcluster";
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
      if (!statsJson.empty()) {
        std::ofstream f(statsJson);
        f << report.build.toJson();
        if (!f) throw mt::Error(statsJson + ": cannot write");
      }
    }
  } catch (const mt::cluster::StoppedCleanly& e) {
    std::fprintf(stderr, "mtcluster: %s\n", e.what());
    MPI_Finalize();
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mtcluster: %s\n", e.what());
    std::fflush(stderr);
    // Other ranks may be mid-region or waiting for rank 0: stop them all (the work directory and
    // OUT.mt.tmp stay for --resume when a level was checkpointed).
    MPI_Abort(MPI_COMM_WORLD, 1);
    return 1;
  }
  MPI_Finalize();
  return 0;
}
