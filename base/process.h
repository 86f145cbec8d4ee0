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

// The most descriptors this process may hold open (RLIMIT_NOFILE's soft value; 65536 when it is
// unlimited). The first call raises a soft value below 65536 to the hard one, or to 65536 when
// the hard one is higher (a soft value already above is kept): the external sorts merge their runs
// all at once when the descriptors allow (base/external_sort.h, maxMergeFanIn), and a default soft
// value of 1024 would make them rewrite the runs of a billion-triangle ingest in extra passes.
// Raising it is what the soft value is for; other limits of the process are left as they are.
uint64_t openFileLimit();

// CPU time this process has used so far, all its threads (those that ended included): the
// kernel's own accounting (getrusage RUSAGE_SELF). Differences of two readings say where a stage's
// CPU went; user + sys is exact, the split between them is sampled at the scheduler tick.
struct CpuSeconds {
  double user = 0, sys = 0;
};
CpuSeconds processCpuSeconds();

// glibc malloc on transparent huge pages. The tunable glibc.malloc.hugetlb=1 (glibc 2.35+) makes
// malloc advise the kernel (MADV_HUGEPAGE) to back its heaps and large mappings with 2 MiB pages;
// it is read only when a process starts, so this re-executes the process (its own executable, the
// same argv) with it appended to GLIBC_TUNABLES (and MT_HUGEPAGES_REEXEC=1, so it happens once).
// It returns, doing nothing, in the re-executed process, when GLIBC_TUNABLES already names
// glibc.malloc.hugetlb (the user's own choice), when MT_NO_HUGEPAGES=1, when the kernel's
// transparent huge pages are off ("never": the advice would change nothing), or when the exec
// fails. Call first thing in main, before any thread starts.
void reexecWithMallocHugePages(char** argv);
// The least --memory at which the tools that take one (mtbuild, mtverify, mtextract) re-execute
// with it: below, a 2 MiB page's unused part weighs on the cap.
constexpr uint64_t kMallocHugePagesFromMemory = uint64_t(256) << 20;

// Asks the kernel to back the 2 MiB-aligned pages inside [data, data + bytes) with transparent
// huge pages (MADV_HUGEPAGE), for a large array about to be written for the first time: one fault
// per 2 MiB instead of 512. On this project's VMs a first touch of a 4 KiB page costs ~10 us, so
// a 78 MB index took ~200 ms of faults; with the advice it takes a third of that. Does nothing
// below 4 MiB, when the kernel has no huge pages, or when MT_NO_HUGEPAGES=1. Advice only: the
// contents are unchanged.
void adviseHugePages(void* data, uint64_t bytes);

}  // namespace mt
