// The bytes that travel between mtcluster ranks (no shared filesystem needed): the build context
// once per worker, a region's task (its assembled floor: vertices, triangles, locks, per-patch
// vertex maps) out, and the region's result (encoded floor payloads + simplified, split mesh)
// back. Native byte order: every rank runs the same binary on the same kind of machine.
// Decoding throws mt::Error naming the message and the byte offset when bytes are short.
#pragma once

#include <string>

#include "mtbuild/build.h"

namespace mt::cluster {

// The context a worker needs; owns the partition sequence RegionContext points at.
struct WorkerContext {
  PartitionSequence sequence;
  RegionContext context;
};

std::string encodeContext(const RegionContext& context, const std::string& sequenceBytes);
void decodeContext(const std::string& bytes, WorkerContext& out);

// `index`: the region's position in its level (the commit order).
std::string encodeTask(uint64_t index, const RegionTask& task);
RegionTask decodeTask(const std::string& bytes, uint64_t& index);

std::string encodeResult(uint64_t index, const RegionResult& result);
RegionResult decodeResult(const std::string& bytes, uint64_t& index);

}  // namespace mt::cluster
