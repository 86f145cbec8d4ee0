// Counting a cut's edges in bounded memory (see mt_cut.h, "Conformity in bounded memory"): the
// edge table the conformity checks sweep, and the part-by-part counter that fills it. Internal
// to the cut code (mt_conformity.cpp sweeps it); not part of the mtfile library's interface.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <vector>

#include "mtfile/mt_cut.h"

namespace mt::cut_internal {

constexpr uint64_t kSlotBytes = 32;

// An undirected edge: the lexicographically smaller endpoint's q, then the larger's.
using EdgeKey = std::array<uint32_t, 6>;

struct alignas(32) EdgeSlot {
  EdgeKey key;
  uint32_t uses;   // 0: empty
  uint32_t patch;  // the lowest patch id using the edge (names it in firstProblem, deterministically)
};
static_assert(sizeof(EdgeSlot) == kSlotBytes, "EdgeSlot layout");

// Insert-only open addressing with linear probing, filled by many threads at once: a slot is
// claimed by a CAS of `uses` 0 -> kClaimed, its key written, then published by storing the count
// (release); a thread meeting a claimed slot waits for it (a few stores) before comparing keys.
// No locks, and no thread ever sees a half-written key. Read (swept) only between passes.
class EdgeTable {
 public:
  enum class Add { New, Counted, Full };
  explicit EdgeTable(size_t slots) : slots_(slots), count_(slots) {}

  size_t capacity() const { return count_; }
  const EdgeSlot& operator[](size_t i) const { return slots_[i]; }

  void clear();
  // Where the probe for an edge of this hash starts (callers prefetch it ahead of add).
  size_t home(uint64_t hash) const;
  void prefetch(size_t slot) const { __builtin_prefetch(&slots_[slot], 1); }
  // Counts `uses` (> 0) more uses of `key` by `patch`; Full when no slot is left for a new edge.
  Add add(const EdgeKey& key, size_t home, uint32_t patch, uint32_t uses);

 private:
  std::vector<EdgeSlot> slots_;
  size_t count_;
};

// Counts the cut's edges part by part in one table of at most tableBytes; after each part has
// been counted, `sweep` reads the table. Returns the statistics. Deterministic: which parts are
// counted, and the table's contents after each, depend only on the file, the arcs and the options.
EdgeCountStats countCutEdges(const MtFileReader& reader, const std::vector<uint32_t>& arcs,
                             const EdgeCountOptions& options, uint64_t tableBytes,
                             const std::function<void(const EdgeTable&)>& sweep);

}  // namespace mt::cut_internal
