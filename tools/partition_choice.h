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

inline std::unique_ptr<CellAssigner> makeAssigner(const std::string& kind, uint32_t patchTriangles) {
  if (kind == "grid") return makeGridAssigner(patchTriangles ? patchTriangles : kDefaultPatchTriangles);
  VPartitionOptions o;
  o.kind = parsePartitionKind(kind);
  o.patchTriangles = patchTriangles;
  return makeVPartitionAssigner(o);
}

// Per-level shape metrics of the store's partition (text, or a JSON value), or "" if none. The
// connected-component share reads every patch about twice per level: optional on huge stores.
inline std::string partitionMetrics(const PatchStore& store, bool json, bool components) {
  return storePartitionMetrics(store, json, components);
}

}  // namespace mt::tools
