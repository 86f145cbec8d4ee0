// The regions in flight of one level of the level loop, bounded by bytes and by count
// (BuildOptions::levelLoopBytes): plain accounting, no threads. Regions start in region order and
// commit in region order; a region counts its `working` bytes from its start until it is
// processed, its `held` bytes from then until its commit (estimateRegionBytes).
//
// Invariant: the bytes in flight never exceed max(byte budget, the largest single region's
// working bytes), because a region starts only when it fits or when nothing else is in flight.
// Progress: the oldest region in flight is always running or committable, so the window empties;
// when it is empty, the next region is admitted whatever its size.
#pragma once

#include <algorithm>
#include <cassert>
#include <cstddef>
#include <cstdint>

#include "mtbuild/build.h"

namespace mt {

class RegionWindow {
 public:
  // byteBudget 0: no byte bound. maxRegions >= 1.
  RegionWindow(uint64_t byteBudget, size_t maxRegions) : budget_(byteBudget), maxRegions_(maxRegions) {
    assert(maxRegions >= 1);
  }

  bool admits(uint64_t working) const {
    if (regions_ == 0) return true;
    if (regions_ >= maxRegions_) return false;
    return budget_ == 0 || bytes_ + working <= budget_;
  }
  void start(const RegionBytes& b) {
    assert(admits(b.working));
    bytes_ += b.working;
    ++regions_;
    peakBytes_ = std::max(peakBytes_, bytes_);
    peakRegions_ = std::max(peakRegions_, regions_);
    largest_ = std::max(largest_, b.working);
  }
  // `held` is at most `working` (estimateRegionBytes), so this never raises the bytes in flight.
  void processed(const RegionBytes& b) {
    assert(b.held <= b.working && bytes_ >= b.working);
    bytes_ -= b.working - b.held;
  }
  void committed(const RegionBytes& b) {
    assert(regions_ > 0 && bytes_ >= b.held);
    bytes_ -= b.held;
    --regions_;
  }

  uint64_t bytes() const { return bytes_; }
  size_t regions() const { return regions_; }
  uint64_t peakBytes() const { return peakBytes_; }
  size_t peakRegions() const { return peakRegions_; }
  uint64_t largestRegion() const { return largest_; }

 private:
  uint64_t budget_;
  size_t maxRegions_;
  uint64_t bytes_ = 0, peakBytes_ = 0, largest_ = 0;
  size_t regions_ = 0, peakRegions_ = 0;
};

}  // namespace mt
