// The --partition choice shared by mtstore and mtbuild: which CellAssigner ingest uses, and the
// partition metrics `mtstore info` prints.
#pragma once

#include <memory>
#include <string>

#include "base/error.h"
#include "patchstore/cell_assigner.h"
#include "patchstore/patch_store.h"
#include "vpartition/vpartition.h"

namespace mt::tools {

inline const char* kDefaultPartition = "irregular";

inline std::string partitionHelp() {
  return "Cell assignment of level-0 patches: irregular (default; V-partition, BMT 4.2.2), regular "
         "(3D cube/octahedron V-partition, 4.2.1), regular2d (terrains), or grid (a plain uniform grid, "
         "no multiresolution sequence)";
}

// levelRatio: --level-ratio (irregular partitions only; throws mt::Error naming the range or the kind).
inline std::unique_ptr<CellAssigner> makeAssigner(const std::string& kind, uint32_t patchTriangles,
                                                  int64_t levelRatio = kDefaultLevelRatio) {
  if (kind == "grid") {
    checkLevelRatio(levelRatio, PartitionKind::Irregular);
    if (levelRatio != kDefaultLevelRatio)
      throw Error("--level-ratio " + std::to_string(levelRatio) + ": the grid partition has no levels; another ratio than 2 needs "
                  "the irregular one");
    return makeGridAssigner(patchTriangles ? patchTriangles : kDefaultPatchTriangles);
  }
  VPartitionOptions o;
  o.kind = parsePartitionKind(kind);
  checkLevelRatio(levelRatio, o.kind);  // on the int64 the option was read into, before it narrows
  o.patchTriangles = patchTriangles;
  o.levelRatio = uint32_t(levelRatio);
  return makeVPartitionAssigner(o);
}

// Per-level shape metrics of the store's partition (text, or a JSON value), or "" if none. The
// connected-component share reads every patch about twice per level: optional on huge stores.
inline std::string partitionMetrics(const PatchStore& store, bool json, bool components) {
  return storePartitionMetrics(store, json, components);
}

}  // namespace mt::tools
