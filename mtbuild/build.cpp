// mtbuild's level loop on threads (BMT section 4, "the i-th simplification step"): LevelBuilder
// (level_builder.cpp) plans each level and commits its regions in order; here the regions are
// loaded and processed on threads. See build.h.
#include "mtbuild/build.h"

#include <tbb/global_control.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

#include <memory>
#include <sstream>

#include "base/interrupt.h"
#include "mtbuild/level_state.h"

namespace mt {

std::string BuildReport::toJson() const {
  std::ostringstream s;
  s.precision(10);
  s << "{\n  \"input_triangles\": " << inputTriangles << ",\n  \"stored_triangles\": " << storedTriangles
    << ",\n  \"nodes\": " << nodes << ",\n  \"arcs\": " << arcs << ",\n  \"patches\": " << patches
    << ",\n  \"file_bytes\": " << fileBytes << ",\n  \"bytes_per_input_triangle\": "
    << (inputTriangles ? double(fileBytes) / double(inputTriangles) : 0) << ",\n  \"grid_step\": " << gridStep
    << ",\n  \"welded_vertices\": " << weldedVertices << ",\n  \"welded_triangles\": " << weldedTriangles
    << ",\n  \"ingest_seconds\": " << ingestSeconds << ",\n  \"build_seconds\": " << buildSeconds
    << ",\n  \"total_seconds\": " << totalSeconds << ",\n  \"input_triangles_per_second\": "
    << (totalSeconds > 0 ? double(inputTriangles) / totalSeconds : 0) << ",\n  \"peak_rss_bytes\": " << peakRssBytes
    << ",\n  \"resumed_at_level\": " << resumedAtLevel << ",\n  \"peak_temp_bytes\": " << peakTempBytes
    << ",\n  \"checkpoint_bytes\": " << checkpointBytes
    << extraJson << ",\n  \"levels\": [";
  for (size_t i = 0; i < levels.size(); ++i) {
    const LevelReport& l = levels[i];
    s << (i ? "," : "") << "\n    {\"level\": " << l.level << ", \"regions\": " << l.regions << ", \"triangles_in\": "
      << l.trianglesIn << ", \"triangles_out\": " << l.trianglesOut << ", \"max_error\": " << l.maxError
      << ", \"seconds\": " << l.seconds << "}";
  }
  s << "\n  ]\n}\n";
  return s.str();
}

// ---- mtbuild: the regions on threads ----------------------------------------------------------

// The level loop on threads; checks for SIGINT/SIGTERM between region commits and levels.
static BuildReport buildLevels(LevelBuilder& builder, const BuildOptions& options);

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

BuildReport buildLevels(LevelBuilder& builder, const BuildOptions& options) {
  const RegionContext& ctx = builder.context();
  checkInterrupt(options.toolName);
  struct Job {
    size_t index = 0;
    RegionTask task;
    RegionResult result;
  };
  while (builder.beginLevel()) {
    const size_t regions = builder.regionCount();
    std::vector<Job> jobs(regions);
    size_t next = 0;
    const size_t tokens = 2 * size_t(options.threads ? options.threads : tbb::this_task_arena::max_concurrency());
    tbb::parallel_pipeline(
        tokens,
        tbb::make_filter<void, Job*>(tbb::filter_mode::serial_in_order,
                                     [&](tbb::flow_control& fc) -> Job* {
                                       // A signal: start no more regions (the level is redone
                                       // from its checkpoint on --resume).
                                       if (next == regions || interruptRequested()) {
                                         fc.stop();
                                         return nullptr;
                                       }
                                       jobs[next].index = next;
                                       return &jobs[next++];
                                     }) &
            tbb::make_filter<Job*, Job*>(tbb::filter_mode::parallel,
                                         [&](Job* job) {
                                           job->task = builder.loadRegion(job->index);
                                           job->result = processRegion(job->task, ctx);
                                           return job;
                                         }) &
            tbb::make_filter<Job*, void>(tbb::filter_mode::serial_in_order, [&](Job* job) {
              checkInterrupt(options.toolName);  // a safe point: between region commits
              builder.commitRegion(job->index, std::move(job->task), std::move(job->result));
              *job = Job();  // free the region's memory now
            }));
    checkInterrupt(options.toolName);
    builder.endLevel();
    checkInterrupt(options.toolName);  // after the level's checkpoint
  }
  return builder.finish();
}

}  // namespace mt
