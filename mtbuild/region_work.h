// The per-region work of the level loop (BMT section 4, "the i-th simplification step"), beside
// processRegion() (build.h): encoding floor patches, and the sizes of a region's task and result.
#pragma once

#include <cstdint>
#include <vector>

#include "mtbuild/build.h"

namespace mt {

// Whether the live patches after `level` levels came out of simplification (level 0: the
// ingest's patches, in the scan's own order), which decides their triangle order in the file
// (PatchCodecOptions::simplified).
inline bool isSimplifiedOutput(uint32_t level) { return level >= 1; }

// Each patch encoded for the MT file, in the order given.
std::vector<EncodedPatch> encodePatches(const std::vector<Patch>& patches, const QuantizationGrid& grid,
                                        const PatchCodecOptions& codec);

// Bytes a region's task and result take as messages (the cluster's serializer writes these
// vectors back to back; used for the task-time log of plain mtbuild runs).
uint64_t taskBytes(const LoadedMesh& mesh);
uint64_t resultBytes(const RegionResult& result);

}  // namespace mt
