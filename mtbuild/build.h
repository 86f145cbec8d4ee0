// The batched MT builder (BMT sections 4 and 6): from a scan (or a patch store) to one MT file.
//
//   ingest (V-partitioned, patchstore) -> for level i = 0, 1, ...: for each region R of V(i+1):
//   load the V*i patches inside R, simplify to about half with R's border locked, split by
//   V*(i+1), write back -> one DAG node per region; the floor patches become the payloads of the
//   arcs into that node. Regions run in parallel and commit in region order, so the file does not
//   depend on the thread count; every step is deterministic, so it does not depend on the memory
//   cap either.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "mtbuild/mt_format.h"
#include "vpartition/vpartition.h"

namespace mt {

struct BuildOptions {
  uint64_t memoryBytes = 1ull << 30;  // --memory: the cap for the whole build (ingest included)
  uint32_t threads = 0;               // 0: all cores
  PartitionKind partition = PartitionKind::Irregular;
  uint32_t patchTriangles = 0;        // 0: vpartition's default
  format::Codec codec = format::Codec::Meshopt;
  bool normals = false;               // store normals (else the renderer computes them)
  bool resume = false;                // continue a killed build (not yet: restarts from the input)
  bool progress = true;
  std::string workDir;                // default: OUT.work
  // Stop adding levels once the top level has at most this many triangles (0: 2 x patch size),
  // or when a level removes less than 10% of the triangles.
  uint64_t rootTriangles = 0;
};

struct LevelReport {
  uint32_t level = 0;
  uint32_t regions = 0;
  uint64_t trianglesIn = 0, trianglesOut = 0;
  double maxError = 0;
  double seconds = 0;
};

struct BuildReport {
  uint64_t inputTriangles = 0;
  uint64_t storedTriangles = 0;
  uint64_t nodes = 0, arcs = 0, patches = 0;
  uint64_t fileBytes = 0;
  double gridStep = 0;
  double ingestSeconds = 0, buildSeconds = 0, totalSeconds = 0;
  uint64_t peakRssBytes = 0;
  std::vector<LevelReport> levels;
  std::string toJson() const;
};

// input: a mesh file (PLY/OBJ/OFF/STL) or a patch store directory made with a V-partition.
// Writes `output` under a temporary name and renames it when complete. Throws mt::Error.
BuildReport buildMt(const std::string& input, const std::string& output, const BuildOptions& options);

}  // namespace mt
