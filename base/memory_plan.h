// The memory plan: the --memory cap divided, in this one place, into the share of every stage
// that buffers data (ingest's two paths and their sorters, the grid weld and the other heal
// passes, the level loop). No other code divides the cap; it asks the plan.
//
// The rule. A build's stages run one after another (ingest, grid weld, level loop, pack), and the
// process frees a stage's buffers before the next starts, so each stage plans against the whole
// cap: within a stage, the shares of the buffers alive at the same time add up to at most the
// cap, and what they leave covers the stage's other allocations (the process itself, the store's
// manifest, tables that are not sort buffers). phases() lists, for every stage, the shares alive
// together; the plan's test checks each sum against the cap.
//   ingest, both paths  the assigner (the V-partition's sample and seed tables) total/2; an STL
//                       soup's weld two sorters of total*3/10 (alive together: one merges while
//                       the other fills); the boundary entries' sorter total/8
//   ingest, chunked     the two joins (centroids, then cell keys): float positions total*2/5,
//                       the Morton or the group sorter total/4 and the bucket files' buffers
//                       total/16; then one sorter of total/4 at a time (pairs, patches) besides
//                       the groups' readers, the last one merging while the shared-vertex
//                       (total/8) and edge (total/16) sorters fill
//   ingest, resident    the vertex records stay in RAM when they, a state byte a vertex and a bit
//                       a vertex and thread fit below the cap less a reserve of
//                       max(128 MiB, total/4) (residentRecordLimit); each pass's sorter then gets
//                       4/5 of what the resident set leaves under the cap less a margin for the
//                       pass's other buffers (residentSorter), the shared-vertex and edge sorters
//                       1/3 and 1/6 of it. This path plans against the resident set measured at
//                       the start of each pass, since the records, the assigner's tables and the
//                       process's own pages are all in it.
//   grid weld           the build runs it as a heal pass with a heal cap of max(total/2, 32 MiB)
//   heal pass           one external sorter of half its heal cap (the pass's tables the rest)
//   level loop          the regions in flight (all threads): total/2; the store, the MT writer,
//                       the DAG and the process keep the other half
// Beside a stage's buffers some data stays resident from one stage to the next: once the chunked
// path has made the V-partition, its seeds and candidate tables (up to the assigner's share, a
// quarter of the cap and more at a billion triangles) stay through the assign stage (then the
// assigner keeps only its serialized bytes: CellAssigner::releaseLookups), and the store's patch
// records (one std::map node per patch, kPatchRecordBytes) grow with the patches.
// The stages that run beside them (the chunked path's assign, group, join and patch stages, and
// the boundary stage) take their shares from besides(resident): the same rule applied to what the
// cap leaves. Counted in the whole-cap rule instead, they took the billion-triangle build to
// 582 MiB at --memory 512M.
// Every share has a floor (1 MiB for a sorter, 8 MiB for the level loop and the resident
// sorters) so that a small cap still runs; from kMinPlanBytes up the floors fit in the rule.
// No share changes the output: every sort is total or stable over a fixed input order.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace mt {

// The least cap for which every phase's shares fit in it (mtbuild's kMinBuildMemory).
constexpr uint64_t kMinPlanBytes = 16ull << 20;
// What one patch record of a store being ingested keeps resident: a std::map node (the key, the
// 128-byte record, the tree's links) and malloc's header, rounded up.
constexpr uint64_t kPatchRecordBytes = 192;

struct MemoryPlan {
  uint64_t total = 0;          // the --memory cap
  unsigned threads = 1;        // the threads the stages run on
  uint64_t levelLoop = 0;      // bytes of regions in flight in the level loop (all threads)
  uint64_t healSorter = 0;     // one heal pass's external sorter, when `total` is the heal's cap
  uint64_t gridWeld = 0;       // the heal cap the build gives its grid weld (its sorter: half)

  // ---- ingest, both paths
  uint64_t assigner = 0;       // the V-partition's budget (CellAssigner::prepare)
  uint64_t soupWeldSorter = 0; // each of an STL soup weld's two sorters
  uint64_t boundarySorter = 0; // stage 7: (patch, local) boundary entries

  // ---- ingest, chunked path
  uint64_t chunkedPositions = 0;    // the centroid pass's chunk of float vertex positions
  uint64_t chunkedSorter = 0;       // each of the Morton, group, pair and patch sorters
  uint64_t chunkedBuckets = 0;      // the joins' bucket files' write buffers, all together
  uint64_t chunkedSharedSorter = 0; // (vertex, patch) of shared vertices
  uint64_t chunkedEdgeSorter = 0;   // uses of edges between shared vertices

  // ---- ingest, resident path
  uint64_t residentReserve = 0;     // what the records must leave for the passes and the assigner
  // The most bytes of vertex records (recordBytes each) kept in RAM; 0: the chunked path.
  uint64_t residentRecordLimit(uint64_t recordBytes) const;
  // A resident pass's sorter when `inUse` bytes are resident and the pass allocates `margin`
  // bytes besides its sorter; at least 8 MiB * 4/5.
  uint64_t residentSorter(uint64_t inUse, uint64_t margin) const;
  // The shared-vertex and edge sorters of the resident patch stage (which fill together).
  uint64_t residentSharedSorter(uint64_t inUse) const;
  uint64_t residentEdgeSorter(uint64_t inUse) const;

  // The plan for stages that run beside `resident` bytes that stay resident (the process, the
  // V-partition, the store's patch records): the rule applied to total - resident (at least
  // kMinPlanBytes / 2, so a stage still runs when the resident part nears the cap; it is then
  // over the cap by what its floors need).
  MemoryPlan besides(uint64_t resident) const;
  // The boundary stage's entry sorter once `inUse` bytes are resident (the V-partition, the patch
  // records and the shared-vertex sorter's merge included): boundarySorter, or half of what the
  // cap leaves when that is less (the stage's lists and payloads the other half); at least 1 MiB.
  uint64_t boundarySorterBesides(uint64_t inUse) const;

  // For every stage, the sum of the shares alive at the same time (the resident path's with the
  // largest records the plan admits, measured as in use).
  std::vector<std::pair<std::string, uint64_t>> phases() const;
};

MemoryPlan planMemory(uint64_t totalBytes, unsigned threads);
// One line per share, for logs.
std::string describe(const MemoryPlan& plan);
// A JSON object of the shares and phases (mtbuild's stats JSON prints it as "memory_plan").
std::string toJson(const MemoryPlan& plan);

}  // namespace mt
