// The level loop's state (LevelBuilder::State), shared by the files that implement LevelBuilder:
// level_builder.cpp (the levels, the commits, the file), checkpoint.cpp (the checkpoints and the
// resume fingerprint). Internal to mtbuild/.
#pragma once

#include <chrono>
#include <csignal>
#include <cstdio>
#include <map>
#include <memory>
#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "base/file_lock.h"
#include "base/process.h"
#include "base/progress.h"
#include "mtbuild/build.h"
#include "mtbuild/dag_node.h"
#include "mtbuild/region_texture.h"
#include "mtfile/mt_file.h"

namespace mt {

using Clock = std::chrono::steady_clock;

inline const char* signalName(int sig) { return sig == SIGINT ? "SIGINT" : sig == SIGTERM ? "SIGTERM" : "a signal"; }

inline double secondsSince(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

// The checkpoint: a blob of the work store, committed with each level's write-backs.
constexpr char kCheckpointBlob[] = "mtbuild.checkpoint";
constexpr uint64_t kCheckpointMagic = 0x31544b43544d4dull;  // "MMTCKT1"
constexpr uint32_t kCheckpointVersion = 6;  // 3: the input hash covers the whole file; 4: texture records; 5: CPU seconds; 6: simplifier runs

// "key=value" lines: the input's identity and every option that changes the bytes (not --threads,
// --memory or levelLoopBytes, which do not). Compared line by line so that a refused resume can
// say what changed.
std::string fingerprint(const std::string& input, const BuildOptions& options, bool storeInput);
// The first line that differs, as "key was A for the killed build, is B now".
std::string fingerprintDifference(const std::string& saved, const std::string& now);

struct LevelBuilder::State {
  // First, so released last: after the temporary file is renamed or removed.
  std::unique_ptr<FileLock> outputLock, workLock;
  BuildOptions options;
  std::string input, output, work, storeDir;
  std::string tempPath;     // the MT file being written, beside the output
  bool workCreated = false;  // the work directory was made by this run
  bool noted = false;        // stopNote() said what was kept
  Clock::time_point t0, buildStart;
  CpuSeconds cpu0, levelCpu0;  // the process's CPU at t0 and at levelStart
  std::unique_ptr<PatchStore> store;
  PartitionSequence sequence;
  std::string sequenceBytes;
  RegionContext ctx;
  std::unique_ptr<TextureContext> texture;  // textured stores (ctx.texture points here)
  std::string fingerprint;
  std::unique_ptr<MtFileWriter> writer;
  format::FileHeader header{};
  // The DAG so far (BMT 3.1). Node 0 is the source: the full-resolution fragment.
  std::vector<format::NodeRecord> nodes;
  std::vector<Sphere> spheres;
  std::map<std::pair<uint32_t, uint32_t>, std::vector<uint32_t>> arcPatches;  // (from, to) -> MT patch ids
  std::unordered_map<PatchId, uint32_t> producer;  // live store patch -> the node whose fragment holds it
  BuildReport report;
  uint64_t liveTriangles = 0;
  uint32_t builtLevels = 0;
  bool finished = false;   // no more levels to build
  bool completed = false;  // the file is written
  // The level in progress.
  std::vector<uint32_t> regionIds;
  std::vector<std::vector<PatchId>> floors;
  std::vector<uint64_t> floorTriangles, floorVertices;
  std::vector<float> floorErrors;  // per region: the largest error of its floor's producers
  bool root = false;
  bool levelDropped = false;  // commitRegion refused this root level (no gain): the loop ends
  size_t nextCommit = 0;
  LevelReport lr;
  Clock::time_point levelStart;
  std::unique_ptr<Progress> progress;
  uint64_t doneTriangles = 0, outTriangles = 0;
  // Test hooks (SIGKILL at a chosen point, a pause after each region so that a test can signal a
  // running build) and the task-time log.
  long killAfterLevel = -1, killAfterRegions = -1, committedRegions = 0, regionPauseMs = 0;
  FILE* taskTimes = nullptr;

  // Checkpoint side file (see checkpointBytes): its committed length and chained hash, and how
  // many patch records / nodes it holds.
  uint64_t sideLength = 0, sideHash = 0;
  size_t ckPatches = 0, ckNodes = 0;
  std::string checkpointBytes() const;
  void appendSideChunk();
  std::vector<format::PatchRecord> readSideFile(uint64_t length, uint64_t hash, std::vector<format::TextureRecord>& textures);
  void appendPatchOf(const EncodedPatch& e, uint32_t& mtPatch);  // payload, then texture
  void restore(const std::string& bytes);
  void writeCheckpoint();
  // A fresh start: the level-0 store (ingestLevelZero), the grid weld, the file's header and the
  // DAG's source node, and checkpoint 0.
  void startFresh(bool storeInput);
  void ingestLevelZero(bool storeInput);
  bool weldToGrid(const QuantizationGrid& grid);
  void startFile(const StoreInfo& info, const QuantizationGrid& grid);
  bool tryResume();
  uint32_t addNode(const RegionTask& task, const RegionResult& result);
  void say(const std::string& what) const {
    if (options.progress) std::fprintf(stderr, "%s: %s\n", options.toolName.c_str(), what.c_str());
  }
};

}  // namespace mt
