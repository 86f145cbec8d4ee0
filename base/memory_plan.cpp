// The memory plan: the rule is written at the top of memory_plan.h; this file is its only
// arithmetic.
#include "base/memory_plan.h"

#include <algorithm>
#include <sstream>

namespace mt {

namespace {

constexpr uint64_t kMiB = 1ull << 20;
constexpr uint64_t kSorterFloor = 1 * kMiB;    // an external sorter below this spends its time on runs
constexpr uint64_t kRoomFloor = 8 * kMiB;      // the resident passes' least room, and the level loop's
constexpr uint64_t kReserveFloor = 128 * kMiB; // measured at 53M/512M: ~165 MiB above the records
constexpr uint64_t kGridWeldFloor = 32 * kMiB; // its sorter's 16 MiB: a 200k scan needs 6 MiB

uint64_t share(uint64_t total, uint64_t numerator, uint64_t denominator, uint64_t floor = kSorterFloor) {
  return std::max(floor, total / denominator * numerator + total % denominator * numerator / denominator);
}

// What the cap leaves a resident pass once `inUse` bytes are resident and `margin` bytes are
// spoken for by the pass's other buffers.
uint64_t residentRoom(uint64_t total, uint64_t inUse, uint64_t margin) {
  return std::max(kRoomFloor, total > inUse + margin ? total - inUse - margin : 0);
}

}  // namespace

MemoryPlan planMemory(uint64_t totalBytes, unsigned threads) {
  MemoryPlan p;
  p.total = totalBytes;
  p.threads = std::max(1u, threads);
  p.levelLoop = share(totalBytes, 1, 2, kRoomFloor);
  p.healSorter = share(totalBytes, 1, 2);
  p.gridWeld = share(totalBytes, 1, 2, kGridWeldFloor);
  p.assigner = share(totalBytes, 1, 2);
  p.soupWeldSorter = share(totalBytes, 3, 10);
  p.boundarySorter = share(totalBytes, 1, 8);
  p.chunkedPositions = share(totalBytes, 2, 5);
  p.chunkedSorter = share(totalBytes, 1, 4);
  p.chunkedBuckets = share(totalBytes, 1, 16);
  p.chunkedSharedSorter = share(totalBytes, 1, 8);
  p.chunkedEdgeSorter = share(totalBytes, 1, 16);
  p.residentReserve = std::max(kReserveFloor, totalBytes / 4);
  return p;
}

MemoryPlan MemoryPlan::besides(uint64_t resident) const {
  const uint64_t left = total > resident ? total - resident : 0;
  return planMemory(std::max(left, kMinPlanBytes / 2), threads);
}

uint64_t MemoryPlan::boundarySorterBesides(uint64_t inUse) const {
  const uint64_t left = total > inUse ? total - inUse : 0;
  return std::max(kSorterFloor, std::min(boundarySorter, left / 2));
}

uint64_t MemoryPlan::residentRecordLimit(uint64_t recordBytes) const {
  if (total <= residentReserve || recordBytes == 0) return 0;
  // Per vertex: its record, a state byte, and a bit per thread (at least two).
  const double perVertex = double(recordBytes) + 1 + std::max(2u, threads) / 8.0;
  return uint64_t(double(total - residentReserve) * double(recordBytes) / perVertex);
}

uint64_t MemoryPlan::residentSorter(uint64_t inUse, uint64_t margin) const {
  return residentRoom(total, inUse, margin) * 4 / 5;
}

uint64_t MemoryPlan::residentSharedSorter(uint64_t inUse) const { return residentRoom(total, inUse, 48 * kMiB) / 3; }

uint64_t MemoryPlan::residentEdgeSorter(uint64_t inUse) const { return residentRoom(total, inUse, 48 * kMiB) / 6; }

std::vector<std::pair<std::string, uint64_t>> MemoryPlan::phases() const {
  // The resident path at its largest: 12-byte records at the limit, with their state bytes and
  // thread bits, all resident.
  const uint64_t records = residentRecordLimit(12);
  const uint64_t residentSet = records ? uint64_t(double(records) / 12 * (13 + std::max(2u, threads) / 8.0)) : 0;
  return {
      {"ingest_partition", assigner},
      {"ingest_soup_weld", 2 * soupWeldSorter},
      {"ingest_chunked_join", chunkedPositions + chunkedSorter + chunkedBuckets},
      {"ingest_chunked_patches", 2 * chunkedSorter + chunkedSharedSorter + chunkedEdgeSorter},
      {"ingest_resident_pass", residentSet + residentSorter(residentSet, 48 * kMiB)},
      {"ingest_resident_patches", residentSet + residentSharedSorter(residentSet) + residentEdgeSorter(residentSet)},
      {"ingest_boundary", std::max(chunkedSharedSorter, residentSharedSorter(0)) + boundarySorter},
      {"grid_weld", planMemory(gridWeld, threads).healSorter},
      {"level_loop", levelLoop},
      {"heal_pass", healSorter},
  };
}

std::string describe(const MemoryPlan& p) {
  std::ostringstream s;
  auto mib = [](uint64_t b) { return double(b) / double(kMiB); };
  s.precision(1);
  s << std::fixed << "memory plan for " << mib(p.total) << " MiB, " << p.threads << " threads:\n"
    << "  level loop (regions in flight) " << mib(p.levelLoop) << " MiB\n"
    << "  heal pass sorter " << mib(p.healSorter) << " MiB; grid weld heal cap " << mib(p.gridWeld) << " MiB\n"
    << "  ingest: assigner " << mib(p.assigner) << " MiB, soup weld sorters 2 x " << mib(p.soupWeldSorter)
    << " MiB, boundary sorter " << mib(p.boundarySorter) << " MiB\n"
    << "  ingest, chunked: positions " << mib(p.chunkedPositions) << " MiB, sorters " << mib(p.chunkedSorter)
    << " MiB, buckets " << mib(p.chunkedBuckets) << " MiB, shared " << mib(p.chunkedSharedSorter) << " MiB, edges " << mib(p.chunkedEdgeSorter) << " MiB\n"
    << "  ingest, resident: reserve " << mib(p.residentReserve) << " MiB, records up to "
    << mib(p.residentRecordLimit(12)) << " MiB (12-byte records)\n";
  return s.str();
}

std::string toJson(const MemoryPlan& p) {
  std::ostringstream s;
  s << "{\"total\": " << p.total << ", \"threads\": " << p.threads << ", \"level_loop\": " << p.levelLoop
    << ", \"heal_sorter\": " << p.healSorter << ", \"grid_weld\": " << p.gridWeld << ", \"assigner\": " << p.assigner
    << ", \"soup_weld_sorter\": " << p.soupWeldSorter << ", \"boundary_sorter\": " << p.boundarySorter
    << ", \"chunked_positions\": " << p.chunkedPositions << ", \"chunked_sorter\": " << p.chunkedSorter
    << ", \"chunked_buckets\": " << p.chunkedBuckets << ", \"chunked_shared_sorter\": " << p.chunkedSharedSorter << ", \"chunked_edge_sorter\": " << p.chunkedEdgeSorter
    << ", \"resident_reserve\": " << p.residentReserve << ", \"resident_record_limit\": " << p.residentRecordLimit(12)
    << ", \"phases\": {";
  bool first = true;
  for (const auto& [name, bytes] : p.phases()) {
    s << (first ? "" : ", ") << "\"" << name << "\": " << bytes;
    first = false;
  }
  s << "}}";
  return s.str();
}

}  // namespace mt
