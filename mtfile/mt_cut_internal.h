// Pieces shared by the cut code's files (mt_cut.cpp, mt_weld.cpp, mt_conformity.cpp,
// mt_edge_count.cpp) and by nothing else: not part of the mtfile library's interface.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "mtfile/mt_file.h"

namespace mt::cut_internal {

__extension__ typedef unsigned __int128 Wide;  // for the multiply-high that maps a hash to a slot

// Mixes all bits of a hash into the high ones, which the multiply-high uses. (The edge table's
// slot index must also not come from the bits that chose the part, a hash range.)
inline uint64_t remix(uint64_t h) {
  h ^= h >> 33;
  h *= 0xff51afd7ed558ccdull;
  h ^= h >> 33;
  h *= 0xc4ceb9fe1a85ec53ull;
  return h ^ (h >> 33);
}

// hash -> [0, slots) by a multiply-high (any size, no modulo).
inline size_t slotOf(uint64_t hash, size_t slots) { return size_t((Wide(remix(hash)) * slots) >> 64); }

// The patches on the arcs, in arc order then patchRefs order (a patch on two of the arcs twice):
// the order assembleCut welds in and the edge counter names patches by.
inline std::vector<uint32_t> cutPatchIds(const MtFileReader& r, const std::vector<uint32_t>& arcs) {
  // Sized exactly first: the bounded-memory checks count 4 bytes per patch for this list, and a
  // list grown by doubling holds up to twice that (three times while it moves).
  size_t count = 0;
  for (uint32_t a : arcs) count += r.arcs().at(a).patchCount;
  std::vector<uint32_t> patchIds;
  patchIds.reserve(count);
  for (uint32_t a : arcs) {
    const format::ArcRecord& arc = r.arcs().at(a);
    for (uint32_t k = 0; k < arc.patchCount; ++k) patchIds.push_back(r.patchRefs()[arc.firstPatchRef + k]);
  }
  return patchIds;
}

}  // namespace mt::cut_internal
