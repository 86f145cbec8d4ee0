// mtbuild's level loop on threads (BMT section 4, "the i-th simplification step"): LevelBuilder
// (level_builder.cpp) plans each level and commits its regions in order; here the regions are
// loaded and processed on threads, as many in flight as RegionWindow admits. See build.h.
#include "mtbuild/build.h"

#include <malloc.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cassert>
#include <condition_variable>
#include <exception>
#include <memory>
#include <mutex>
#include <sstream>
#include <thread>
#include <vector>

#include "base/interrupt.h"
#include "base/memory_plan.h"
#include "base/process.h"
#include "mtbuild/level_state.h"
#include "mtbuild/region_window.h"

namespace mt {

std::string BuildReport::toJson() const {
  std::ostringstream s;
  s.precision(10);
  s << "{\n  \"input_triangles\": " << inputTriangles << ",\n  \"stored_triangles\": " << storedTriangles
    << ",\n  \"nodes\": " << nodes << ",\n  \"arcs\": " << arcs << ",\n  \"patches\": " << patches
    << ",\n  \"file_bytes\": " << fileBytes << ",\n  \"bytes_per_input_triangle\": "
    << (inputTriangles ? double(fileBytes) / double(inputTriangles) : 0) << ",\n  \"grid_step\": " << gridStep << ",\n  \"level_ratio\": " << levelRatio
    << ",\n  \"welded_vertices\": " << weldedVertices << ",\n  \"welded_triangles\": " << weldedTriangles
    << ",\n  \"ingest_seconds\": " << ingestSeconds << ",\n  \"build_seconds\": " << buildSeconds
    << ",\n  \"total_seconds\": " << totalSeconds << ",\n  \"ingest_user_seconds\": " << ingestUserSeconds
    << ",\n  \"ingest_sys_seconds\": " << ingestSysSeconds << ",\n  \"cpu_user_seconds\": " << cpuUserSeconds
    << ",\n  \"cpu_sys_seconds\": " << cpuSysSeconds << ",\n  \"input_triangles_per_second\": "
    << (totalSeconds > 0 ? double(inputTriangles) / totalSeconds : 0) << ",\n  \"peak_rss_bytes\": " << peakRssBytes
    << ",\n  \"ingest_peak_rss_bytes\": " << ingestPeakRssBytes
    << ",\n  \"resumed_at_level\": " << resumedAtLevel << ",\n  \"peak_temp_bytes\": " << peakTempBytes
    << ",\n  \"checkpoint_bytes\": " << checkpointBytes << ",\n  \"level_loop_bytes\": " << levelLoopBytes
    << ",\n  \"level_loop_peak_bytes\": " << levelLoopPeakBytes << ",\n  \"level_loop_peak_regions\": " << levelLoopPeakRegions
    << ",\n  \"level_loop_largest_region_bytes\": " << levelLoopLargestRegionBytes;
  if (textureBytes)
    s << ",\n  \"texture_bytes\": " << textureBytes << ",\n  \"texture_image_bytes\": " << textureImageBytes
      << ",\n  \"texture_bytes_per_input_triangle\": " << (inputTriangles ? double(textureBytes) / double(inputTriangles) : 0);
  s << extraJson << ",\n  \"levels\": [";
  for (size_t i = 0; i < levels.size(); ++i) {
    const LevelReport& l = levels[i];
    s << (i ? "," : "") << "\n    {\"level\": " << l.level << ", \"regions\": " << l.regions << ", \"triangles_in\": "
      << l.trianglesIn << ", \"triangles_out\": " << l.trianglesOut << ", \"max_error\": " << l.maxError
      << ", \"seconds\": " << l.seconds << ", \"user_seconds\": " << l.userSeconds << ", \"sys_seconds\": " << l.sysSeconds
      << ", \"simplifier_runs\": " << l.simplifierRuns << "}";
  }
  s << "\n  ]\n}\n";
  return s.str();
}

// ---- mtbuild: the regions on threads ----------------------------------------------------------

namespace {

// One level's regions on `threads` threads (the caller's among them). Each thread commits the
// oldest processed region when no one else is committing (commits run in region order, one at a
// time, beside loads and processing: LevelBuilder allows that), else starts the next region when
// the window admits it, else waits. A signal starts no more regions; the next commit then throws
// Interrupted (the level is redone from its checkpoint on --resume). The first exception of any
// thread stops the others and is rethrown by run().
class ThreadedLevel {
 public:
  ThreadedLevel(LevelBuilder& builder, const BuildOptions& options, RegionWindow& window)
      : builder_(builder), options_(options), window_(window), regions_(builder.regionCount()),
        jobs_(regions_), ready_(regions_, 0) {
    for (size_t i = 0; i < regions_; ++i)
      bytes_.push_back(estimateRegionBytes(builder.regionTriangles(i), builder.regionVertices(i), builder.hasColors()));
  }

  void run(unsigned threads) {
    std::vector<std::thread> helpers;
    for (unsigned t = 1; t < threads; ++t) helpers.emplace_back([this] { work(); });
    work();
    for (std::thread& t : helpers) t.join();
    if (error_) std::rethrow_exception(error_);
    assert(window_.regions() == 0 && "every started region was committed");
  }

 private:
  struct Job {
    RegionTask task;
    RegionResult result;
  };

  void work() {
    std::unique_lock<std::mutex> lock(mutex_);
    while (!error_ && nextCommit_ < regions_) {
      if (!committing_ && ready_[nextCommit_]) {
        commitNext(lock);
      } else if (nextStart_ < regions_ && !stopping_ && window_.admits(bytes_[nextStart_].working)) {
        if (interruptRequested()) {
          stopping_ = true;
          continue;
        }
        startNext(lock);
      } else if (nextStart_ == nextCommit_ && (stopping_ || nextStart_ == regions_)) {
        break;  // nothing in flight and nothing more to start
      } else {
        changed_.wait(lock);
      }
    }
    changed_.notify_all();
  }

  // Called and returns with the lock held; runs the region unlocked.
  void startNext(std::unique_lock<std::mutex>& lock) {
    const size_t i = nextStart_++;
    window_.start(bytes_[i]);
    lock.unlock();
    Job job;
    std::exception_ptr error;
    try {
      job.task = builder_.loadRegion(i);
      job.result = processRegion(job.task, builder_.context());
    } catch (...) {
      error = std::current_exception();
    }
    lock.lock();
    if (error) return fail(error);
    jobs_[i] = std::move(job);
    ready_[i] = 1;
    window_.processed(bytes_[i]);
    changed_.notify_all();
  }

  void commitNext(std::unique_lock<std::mutex>& lock) {
    const size_t i = nextCommit_;
    committing_ = true;
    Job job = std::move(jobs_[i]);
    lock.unlock();
    std::exception_ptr error;
    try {
      checkInterrupt(options_.toolName);  // a safe point: between region commits
      builder_.commitRegion(i, std::move(job.task), std::move(job.result));
    } catch (...) {
      error = std::current_exception();
    }
    job = Job();  // free the region's memory before it leaves the window
    lock.lock();
    committing_ = false;
    if (error) return fail(error);
    window_.committed(bytes_[i]);
    ++nextCommit_;
    changed_.notify_all();
  }

  void fail(std::exception_ptr error) {
    if (!error_) error_ = error;
    changed_.notify_all();
  }

  LevelBuilder& builder_;
  const BuildOptions& options_;
  RegionWindow& window_;
  const size_t regions_;
  std::vector<RegionBytes> bytes_;
  std::mutex mutex_;
  std::condition_variable changed_;
  std::vector<Job> jobs_;
  std::vector<uint8_t> ready_;
  size_t nextStart_ = 0, nextCommit_ = 0;
  bool committing_ = false, stopping_ = false;
  std::exception_ptr error_;
};

// The level loop on threads; checks for SIGINT/SIGTERM between region commits and levels.
BuildReport buildLevels(LevelBuilder& builder, const BuildOptions& options) {
  checkInterrupt(options.toolName);
  const unsigned threads = options.threads ? options.threads : unsigned(tbb::this_task_arena::max_concurrency());
  uint64_t peakBytes = 0, largest = 0;
  size_t peakRegions = 0;
  while (builder.beginLevel()) {
    // 2 x threads regions at most: one processed, one loaded or waiting for its commit per thread.
    // Their bytes: the level loop's share, or less when what stays resident through the loop (the
    // store's patch records, the V-partition, the DAG and the file's index, the process) leaves
    // less (MemoryPlan::besides, measured at the start of each level with the heap trimmed).
    uint64_t windowBytes = options.levelLoopBytes;
    if (windowBytes && options.memoryBytes) {
      malloc_trim(0);
      windowBytes = std::min(windowBytes, planMemory(options.memoryBytes, threads).besides(currentRssBytes()).levelLoop);
    }
    RegionWindow window(windowBytes, 2 * size_t(threads));
    ThreadedLevel(builder, options, window).run(threads);
    peakBytes = std::max(peakBytes, window.peakBytes());
    peakRegions = std::max(peakRegions, window.peakRegions());
    largest = std::max(largest, window.largestRegion());
    checkInterrupt(options.toolName);
    builder.endLevel();
    checkInterrupt(options.toolName);  // after the level's checkpoint
  }
  BuildReport report = builder.finish();
  report.levelLoopBytes = options.levelLoopBytes;
  report.levelLoopPeakBytes = peakBytes;
  report.levelLoopPeakRegions = uint32_t(peakRegions);
  report.levelLoopLargestRegionBytes = largest;
  return report;
}

}  // namespace

BuildReport buildMt(const std::string& input, const std::string& output, const BuildOptions& options) {
  std::unique_ptr<tbb::global_control> threadLimit;
  if (options.threads > 0)
    threadLimit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, options.threads);
  std::unique_ptr<LevelBuilder> owned = std::make_unique<LevelBuilder>(input, output, options);
  try {
    return buildLevels(*owned, options);
  } catch (const Interrupted& e) {
    // Say what was kept while the builder still knows, then let it close the files.
    std::string note = std::string("interrupted by ") + signalName(e.signal()) + " " + owned->stopNote();
    owned.reset();
    throw BuildInterrupted(note, e.signal());
  }
}

}  // namespace mt
