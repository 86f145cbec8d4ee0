// The rank-0 scheduler and the worker loop (see cluster_build.h).
//
// Scheduling follows the BMT paper's cluster build (section 7.1: "the computation is dominated by
// the CPU time to perform patch simplification"): rank 0 does the cheap, ordered, stateful steps
// (read and assemble a region's floor, commit the result, write the file); workers do the
// expensive pure step, processRegion(). Regions are handed out one at a time to whichever rank is
// idle (a work queue, so slow and fast regions balance), at most `window` regions ahead of the
// commit point so rank 0 holds a bounded number of regions in memory.
//
// A rank that dies: OpenMPI 4.1's mpirun then aborts the whole job (it prints "mpirun noticed
// that process rank R ... exited on signal S" and sends SIGTERM to the surviving ranks). Without
// ULFM a surviving rank cannot learn of the failure through MPI (measured here: with
// --enable-recovery an MPI_Irecv from the dead rank stays pending, never in error). So rank 0
// keeps a one-line account of the level and of which rank holds which region, and its SIGTERM
// handler prints it; the checkpoint of the last finished level is intact (commits happen only at
// level ends), so `--resume` continues from it with identical bytes.
#include "cluster/cluster_build.h"

#include <mpi.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cinttypes>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <condition_variable>
#include <exception>
#include <map>
#include <memory>
#include <mutex>
#include <thread>
#include <sstream>

#include "base/byte_io.h"
#include "base/error.h"
#include "base/interrupt.h"
#include "cluster/region_messages.h"

namespace mt::cluster {

namespace {

using Clock = std::chrono::steady_clock;
double secondsSince(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

enum Tag : int { kContext = 1, kTask = 2, kResult = 3, kStop = 4, kStats = 5, kError = 6 };

// ---- What rank 0 says if mpirun stops the job (async-signal-safe: a prebuilt buffer) ----------
char gStopNote[1024] = "";
char gWorkNote[256] = "";

void onTerminate(int) {
  // mpirun sends SIGTERM to every rank when it stops the job: on Ctrl-C (it does not forward
  // SIGINT), or because a rank died. Rank 0 cannot reach a safe point before mpirun's SIGKILL, but
  // the checkpoint of the last finished level is intact: say where the build was and what is kept.
  static const char head[] = "\nmtcluster: stopped by SIGTERM from mpirun (Ctrl-C, or a rank died: mpirun names it) ";
  ssize_t ignored = ::write(2, head, sizeof head - 1);
  ignored = ::write(2, gStopNote, std::strlen(gStopNote));
  ignored = ::write(2, gWorkNote, std::strlen(gWorkNote));
  (void)ignored;
  ::_exit(1);
}

void check(int rc, const char* what, int peer) {
  if (rc == MPI_SUCCESS) return;
  char text[MPI_MAX_ERROR_STRING];
  int len = 0;
  MPI_Error_string(rc, text, &len);
  fail("mtcluster", std::string(what) + " with rank " + std::to_string(peer) + " failed: " + std::string(text, size_t(len)));
}

void send(const std::string& bytes, int to, int tag, uint64_t& counter) {
  if (bytes.size() > size_t(INT32_MAX)) fail("mtcluster", "message of " + std::to_string(bytes.size()) + " bytes (> 2 GiB)");
  check(MPI_Send(bytes.data(), int(bytes.size()), MPI_BYTE, to, tag, MPI_COMM_WORLD), "send", to);
  counter += bytes.size();
}

std::string receive(const MPI_Status& probed, uint64_t& counter) {
  int count = 0;
  MPI_Get_count(&probed, MPI_BYTE, &count);
  std::string bytes(size_t(count), '\0');
  check(MPI_Recv(bytes.data(), count, MPI_BYTE, probed.MPI_SOURCE, probed.MPI_TAG, MPI_COMM_WORLD, MPI_STATUS_IGNORE),
        "receive", probed.MPI_SOURCE);
  counter += bytes.size();
  return bytes;
}

// ---- Workers ---------------------------------------------------------------------------------

void runWorker(int rank) {
  WorkerContext ctx;
  bool haveContext = false;
  RankStats stats;
  stats.rank = rank;
  // Test hook: MT_TEST_KILL_RANK=R:L makes rank R SIGKILL itself when its first task of level L
  // arrives. By level, not by a count of tasks: how many regions of a level each rank gets depends
  // on the ranks' speeds, but rank 0 hands every idle worker a region as a level starts (when it
  // has as many), so the level the job dies in does not.
  long killLevel = -1;
  if (const char* k = std::getenv("MT_TEST_KILL_RANK"); k && std::atoi(k) == rank && std::strchr(k, ':'))
    killLevel = std::atol(std::strchr(k, ':') + 1);
  for (;;) {
    MPI_Status st;
    check(MPI_Probe(0, MPI_ANY_TAG, MPI_COMM_WORLD, &st), "probe", 0);
    std::string bytes = receive(st, stats.bytesReceived);
    if (st.MPI_TAG == kStop) {
      ByteWriter w;
      w.put(stats);
      send(w.bytes(), 0, kStats, stats.bytesSent);
      return;
    }
    auto start = Clock::now();
    uint64_t index = 0;
    RegionTask task;
    try {
      if (st.MPI_TAG == kContext) {
        decodeContext(bytes, ctx);
        haveContext = true;
        continue;
      }
      if (st.MPI_TAG != kTask || !haveContext) fail("mtcluster", "unexpected message tag " + std::to_string(st.MPI_TAG));
      task = decodeTask(bytes, index);
      if (killLevel >= 0 && long(task.level) == killLevel) std::raise(SIGKILL);
      RegionResult result = processRegion(task, ctx.context);
      stats.processSeconds += result.seconds;
      std::string reply = encodeResult(index, result);
      stats.busySeconds += secondsSince(start);
      ++stats.tasks;
      send(reply, 0, kResult, stats.bytesSent);
    } catch (const std::exception& e) {
      std::string what = "rank " + std::to_string(rank) + ", level " + std::to_string(task.level) + ", region " +
                         std::to_string(task.region) + ": " + e.what();
      send(what, 0, kError, stats.bytesSent);
    }
  }
}

// ---- Rank 0 ----------------------------------------------------------------------------------

// Sends every worker the stop message and collects its statistics (workers must be idle).
void stopAll(int size, std::vector<RankStats>& stats) {
  for (int r = 1; r < size; ++r) send(std::string(), r, kStop, stats[0].bytesSent);
  for (int r = 1; r < size; ++r) {
    MPI_Status st;
    check(MPI_Probe(r, kStats, MPI_COMM_WORLD, &st), "probe", r);
    std::string bytes = receive(st, stats[0].bytesReceived);
    ByteReader reader(bytes, "stats message");
    stats[size_t(r)] = reader.get<RankStats>();
  }
}

// Rank 0's commits run on their own thread, so that loading and sending the next regions overlaps
// committing the previous ones: per region, rank 0's critical path is max(load + messages,
// commit) instead of their sum (docs/cluster.md). Commits stay in region order; only this thread
// commits; loadRegion() may run concurrently with commitRegion() (disjoint patch sets, as in
// mtbuild's pipeline). MPI is called by the main thread only (MPI_THREAD_FUNNELED).
struct Committer {
  struct Item {
    RegionTask task;
    RegionResult result;
    uint64_t moved = 0;
  };
  LevelBuilder& builder;
  std::mutex m;
  std::condition_variable cv;
  std::map<size_t, Item> ready;
  size_t committed = 0;
  bool stop = false;
  std::exception_ptr error;
  double seconds = 0;
  std::thread thread;

  explicit Committer(LevelBuilder& b) : builder(b) { thread = std::thread([this] { loop(); }); }
  ~Committer() {
    {
      std::lock_guard<std::mutex> lock(m);
      stop = true;
    }
    cv.notify_all();
    thread.join();
  }
  void startLevel() {
    std::lock_guard<std::mutex> lock(m);
    committed = 0;
  }
  void add(size_t index, Item item) {
    {
      std::lock_guard<std::mutex> lock(m);
      ready.emplace(index, std::move(item));
    }
    cv.notify_all();
  }
  // Regions committed so far in this level; rethrows a commit's error.
  size_t done() {
    std::lock_guard<std::mutex> lock(m);
    if (error) std::rethrow_exception(error);
    return committed;
  }
  // Waits until more than `seen` regions are committed, or `timeout` passes.
  void waitPast(size_t seen, std::chrono::milliseconds timeout) {
    std::unique_lock<std::mutex> lock(m);
    cv.wait_for(lock, timeout, [&] { return committed > seen || error; });
  }
  void loop() {
    for (;;) {
      Item item;
      size_t index;
      {
        std::unique_lock<std::mutex> lock(m);
        cv.wait(lock, [&] { return stop || ready.count(committed); });
        if (stop) return;  // the run ended (all committed) or failed: commit nothing more
        index = committed;
        item = std::move(ready.at(index));
        ready.erase(index);
      }
      try {
        auto t0 = Clock::now();
        builder.commitRegion(index, std::move(item.task), std::move(item.result), item.moved);
        seconds += secondsSince(t0);
      } catch (...) {
        std::lock_guard<std::mutex> lock(m);
        error = std::current_exception();
        cv.notify_all();
        return;
      }
      {
        std::lock_guard<std::mutex> lock(m);
        ++committed;
      }
      cv.notify_all();
    }
  }
};

struct Master {
  LevelBuilder& builder;
  int size;
  std::vector<RankStats> stats;
  double loadSeconds = 0, commitSeconds = 0;

  void note(uint32_t level, const std::vector<int64_t>& holding, const std::vector<uint32_t>& regionOf) {
    // The account printed if the job is stopped (see onTerminate): level and regions in flight.
    std::string s = "during level " + std::to_string(level) + " (regions in flight:";
    bool any = false;
    for (int r = 1; r < size; ++r)
      if (holding[size_t(r)] >= 0) {
        s += " rank " + std::to_string(r) + " region " + std::to_string(regionOf[size_t(r)]) + ";";
        any = true;
      }
    if (!any) s += " none;";
    s += " the checkpoint after level " + std::to_string(level - 1) + " is intact: rerun with --resume)\n";
    std::snprintf(gStopNote, sizeof gStopNote, "%s", s.c_str());
  }

  void run() {
    // A rank has no patch store, so no tiled input images to cut the finest atlases from.
    if (builder.context().texture)
      throw Error("mtcluster: textured inputs are not supported on MPI ranks yet; build them with mtbuild");
    const std::string context = encodeContext(builder.context(), builder.sequenceBytes());
    for (int r = 1; r < size; ++r) send(context, r, kContext, stats[0].bytesSent);
    // Rank 0 also processes regions when there are few workers (its own load/commit work is
    // small next to theirs); with many workers it only feeds them, since a region it is busy
    // simplifying would delay handing out the next ones.
    const bool masterWorks = size <= 4;
    const size_t window = size_t(2 * size + 2);
    Committer committer(builder);
    while (builder.beginLevel()) {
      const size_t n = builder.regionCount();
      const uint32_t level = builder.level();
      committer.startLevel();
      std::map<size_t, RegionTask> tasks;  // handed out, result not back yet
      std::map<size_t, uint64_t> moved;
      std::vector<int64_t> holding(size_t(size), -1);
      std::vector<uint32_t> regionOf(size_t(size), 0);
      size_t next = 0;
      note(level, holding, regionOf);
      for (;;) {
        // SIGINT sent to rank 0 itself (mpirun turns Ctrl-C into SIGTERM, handled above): stop
        // handing out regions; the level is redone from its checkpoint on --resume.
        checkInterrupt("mtcluster");
        const size_t committed = committer.done();
        if (committed == n) break;
        bool progressed = false;
        // 1. Hand regions to idle workers (at most `window` ahead of the commits).
        for (int r = 1; r < size && next < n && next < committed + window; ++r) {
          if (holding[size_t(r)] >= 0) continue;
          auto t0 = Clock::now();
          RegionTask task = builder.loadRegion(next);
          loadSeconds += secondsSince(t0);
          std::string bytes = encodeTask(next, task);
          holding[size_t(r)] = int64_t(next);
          regionOf[size_t(r)] = task.region;
          note(level, holding, regionOf);
          send(bytes, r, kTask, stats[0].bytesSent);
          moved[next] = bytes.size();
          tasks.emplace(next, std::move(task));
          ++next;
          progressed = true;
        }
        // 2. Take in every result that has arrived; the committer takes them in order.
        for (;;) {
          int flag = 0;
          MPI_Status st;
          check(MPI_Iprobe(MPI_ANY_SOURCE, MPI_ANY_TAG, MPI_COMM_WORLD, &flag, &st), "probe", -1);
          if (!flag) break;
          size_t index = accept(st, holding, moved, level, committer, tasks);
          (void)index;
          progressed = true;
        }
        if (progressed) continue;
        // 3. Nothing arrived: work on a region here, or wait for a worker or a commit.
        bool anyBusy = std::any_of(holding.begin() + 1, holding.end(), [](int64_t h) { return h >= 0; });
        if ((masterWorks || !anyBusy) && next < n && next < committed + window) {
          auto t0 = Clock::now();
          RegionTask task = builder.loadRegion(next);
          loadSeconds += secondsSince(t0);
          RegionResult result = processRegion(task, builder.context());
          stats[0].processSeconds += result.seconds;
          ++stats[0].tasks;
          committer.add(next, {std::move(task), std::move(result), 0});
          ++next;
          continue;
        }
        // A commit may open the window for an idle worker; a result may arrive: poll both.
        committer.waitPast(committed, std::chrono::milliseconds(anyBusy ? 1 : 50));
      }
      std::snprintf(gStopNote, sizeof gStopNote, "after level %u was checkpointed (rerun with --resume)\n", level);
      builder.endLevel();
      checkInterrupt("mtcluster");
    }
    commitSeconds = committer.seconds;
  }

  size_t accept(const MPI_Status& st, std::vector<int64_t>& holding, std::map<size_t, uint64_t>& moved, uint32_t level,
                Committer& committer, std::map<size_t, RegionTask>& tasks) {
    const int r = st.MPI_SOURCE;
    std::string bytes = receive(st, stats[0].bytesReceived);
    if (st.MPI_TAG == kError) fail("mtcluster", bytes);
    if (st.MPI_TAG != kResult)
      fail("mtcluster", "rank " + std::to_string(r) + " sent unexpected tag " + std::to_string(st.MPI_TAG) + " during level " +
                            std::to_string(level));
    uint64_t index = 0;
    RegionResult result = decodeResult(bytes, index);
    if (holding[size_t(r)] != int64_t(index) || !tasks.count(size_t(index)))
      fail("mtcluster", "rank " + std::to_string(r) + " returned region index " + std::to_string(index) + " it was not given");
    holding[size_t(r)] = -1;
    uint64_t total = moved[index] + bytes.size();
    moved.erase(index);
    committer.add(size_t(index), {std::move(tasks.at(size_t(index))), std::move(result), total});
    tasks.erase(size_t(index));
    return size_t(index);
  }

  void stopWorkers() { stopAll(size, stats); }
};

}  // namespace

ClusterReport runCluster(const std::string& input, const std::string& output, const BuildOptions& options) {
  int rank = 0, size = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
  ClusterReport report;
  if (rank != 0) {
    runWorker(rank);
    return report;
  }
  report.ranks.resize(size_t(size));
  for (int r = 0; r < size; ++r) report.ranks[size_t(r)].rank = r;
  if (size == 1) {
    // One rank: the ordinary mtbuild build (threads and all), stopped by SIGINT/SIGTERM at its
    // safe points (buildMt throws BuildInterrupted saying what was kept).
    installInterruptHandlers();
    auto t0 = Clock::now();
    report.build = buildMt(input, output, options);
    report.loopSeconds = report.build.buildSeconds;
    report.ranks[0].busySeconds = secondsSince(t0) - report.build.ingestSeconds;
    report.parallelEfficiency = 1;
    return report;
  }
  installInterruptHandlers();  // SIGINT; SIGTERM is mpirun's stop, handled at once:
  std::signal(SIGTERM, onTerminate);
  std::snprintf(gStopNote, sizeof gStopNote, "during ingest (nothing to resume yet)\n");
  std::unique_ptr<LevelBuilder> owned;
  try {
    owned = std::make_unique<LevelBuilder>(input, output, options);
    std::snprintf(gWorkNote, sizeof gWorkNote, "mtcluster: kept %s and %s for --resume\n", owned->workDir().c_str(),
                  owned->tempPath().c_str());
  } catch (const std::exception& e) {
    // Bad input or options: no region is out yet, so the workers can be stopped cleanly.
    stopAll(size, report.ranks);
    throw StoppedCleanly(e.what());
  }
  Master master{*owned, size, report.ranks};
  auto loopStart = Clock::now();
  try {
    master.run();
  } catch (const Interrupted& e) {
    std::signal(SIGTERM, SIG_DFL);
    std::string note = std::string("interrupted by ") + (e.signal() == SIGTERM ? "SIGTERM " : "SIGINT ") + owned->stopNote();
    owned.reset();
    throw BuildInterrupted(note, e.signal());
  } catch (...) {
    // Workers may be mid-region: abort the job (the checkpoint stays for --resume).
    std::signal(SIGTERM, SIG_DFL);
    throw;
  }
  report.loopSeconds = secondsSince(loopStart);
  master.stopWorkers();
  report.build = owned->finish();
  report.ranks = master.stats;
  report.ranks[0].busySeconds = master.loadSeconds + master.commitSeconds + report.ranks[0].processSeconds;
  report.masterLoadSeconds = master.loadSeconds;
  report.masterCommitSeconds = master.commitSeconds;
  double busy = 0;
  for (const RankStats& s : report.ranks) busy += s.busySeconds;
  report.parallelEfficiency = report.loopSeconds > 0 ? busy / (double(size) * report.loopSeconds) : 0;
  std::signal(SIGTERM, SIG_DFL);
  return report;
}

void describe(ClusterReport& report, bool print) {
  std::ostringstream j;
  j.precision(6);
  j << ",\n  \"ranks\": " << report.ranks.size() << ",\n  \"level_loop_seconds\": " << report.loopSeconds
    << ",\n  \"parallel_efficiency\": " << report.parallelEfficiency << ",\n  \"rank0_load_seconds\": " << report.masterLoadSeconds
    << ",\n  \"rank0_commit_seconds\": " << report.masterCommitSeconds << ",\n  \"rank_stats\": [";
  for (size_t i = 0; i < report.ranks.size(); ++i) {
    const RankStats& s = report.ranks[i];
    j << (i ? "," : "") << "\n    {\"rank\": " << s.rank << ", \"tasks\": " << s.tasks << ", \"busy_seconds\": " << s.busySeconds
      << ", \"process_seconds\": " << s.processSeconds << ", \"bytes_sent\": " << s.bytesSent
      << ", \"bytes_received\": " << s.bytesReceived << "}";
  }
  j << "\n  ]";
  report.build.extraJson = j.str();
  if (!print) return;
  std::fprintf(stderr, "mtcluster: %zu ranks, level loop %.2f s, parallel efficiency %.0f%%\n", report.ranks.size(),
               report.loopSeconds, 100 * report.parallelEfficiency);
  for (const RankStats& s : report.ranks)
    std::fprintf(stderr, "  rank %d: %" PRIu64 " regions, busy %.2f s (%.0f%%), sent %.1f MiB, received %.1f MiB\n", s.rank,
                 s.tasks, s.busySeconds, report.loopSeconds > 0 ? 100 * s.busySeconds / report.loopSeconds : 0,
                 double(s.bytesSent) / (1 << 20), double(s.bytesReceived) / (1 << 20));
}

}  // namespace mt::cluster
