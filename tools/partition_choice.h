// The --partition choice shared by mtstore and mtbuild: which CellAssigner ingest uses, and the
// partition metrics `mtstore info` prints. Until the V-partitions are wired in, only the grid.
#pragma once

#include <memory>
#include <string>

#include "patchstore/cell_assigner.h"
#include "patchstore/error.h"
#include "patchstore/patch_store.h"

namespace mt::tools {

inline const char* kDefaultPartition = "grid";

inline std::string partitionHelp() { return "Cell assignment for level-0 patches: grid (default)"; }

inline std::unique_ptr<CellAssigner> makeAssigner(const std::string& kind, uint32_t patchTriangles) {
  if (kind == "grid") return makeGridAssigner(patchTriangles);
  throw Error("unknown --partition '" + kind + "' (expected grid)");
}

// Per-level shape metrics of the store's partition (text or a JSON value), or "" if none.
inline std::string partitionMetrics(const PatchStore&, bool) { return ""; }

}  // namespace mt::tools
