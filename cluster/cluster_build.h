// mtcluster's ranks: rank 0 runs mtbuild's LevelBuilder (ingest or resume, plan, commit
// in region order, checkpoints, the file); the regions of each level go out dynamically to the
// other ranks as messages (region_messages.h) and their results come back, so the file has the
// same bytes as mtbuild's whatever the number of ranks. One rank: the ordinary mtbuild build.
#pragma once

#include <string>

#include "base/error.h"
#include "mtbuild/build.h"

namespace mt::cluster {

struct RankStats {
  int rank = 0;
  uint64_t tasks = 0;
  double busySeconds = 0;     // processing regions (rank 0: + loading, sending, committing)
  double processSeconds = 0;  // inside processRegion
  uint64_t bytesSent = 0, bytesReceived = 0;
};

struct ClusterReport {
  BuildReport build;
  std::vector<RankStats> ranks;
  double loopSeconds = 0;           // the level loop's wall time (what the ranks share)
  double parallelEfficiency = 0;    // sum of busy time / (ranks x loopSeconds)
  double masterLoadSeconds = 0, masterCommitSeconds = 0;
};

// Thrown by runCluster on rank 0 when the build failed before any region was handed out: every
// rank has been stopped, so the caller can finalize MPI instead of aborting the job.
struct StoppedCleanly : mt::Error {
  using mt::Error::Error;
};

// Runs this rank's part; MPI must be initialized. Rank 0 returns the report; other ranks return
// an empty one when rank 0 stops them. Throws mt::Error on rank 0 for build errors and for a
// worker's failure (naming the rank, level and region).
ClusterReport runCluster(const std::string& input, const std::string& output, const BuildOptions& options);

// Writes the report (per-rank table, efficiency) to stderr and its JSON members to extraJson.
void describe(ClusterReport& report, bool print);

}  // namespace mt::cluster
