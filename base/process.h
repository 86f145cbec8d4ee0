// What a process knows about its own memory: resident set sizes for the tools' reports and the
// memory-cap tests, and the allocator settings the streaming passes run with.
#pragma once

#include <cstdint>

namespace mt {

// Peak resident set size of this process so far (VmHWM), in bytes.
uint64_t peakRssBytes();
// glibc malloc settings for long streaming passes under a memory cap (ingest, mtbuild's level
// loop): buffers of 1 MiB or more get their own mapping, so what a pass frees leaves the process
// at once (glibc's dynamic threshold would keep them in the heap, resident behind live blocks);
// and up to 8 MiB free at a heap's top is kept, so the per-patch and per-region buffers freed and
// allocated all the time are not returned and faulted in again. Process-wide; call before a pass.
void useStreamingAllocator();
// Resident set size now (statm), in bytes.
uint64_t currentRssBytes();

}  // namespace mt
