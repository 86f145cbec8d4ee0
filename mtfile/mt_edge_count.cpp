// Counting a cut's edges in bounded memory (mt_edge_count.h; the plan and its guarantees are in
// mt_cut.h, "Conformity in bounded memory").
#include "mtfile/mt_edge_count.h"

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>
#include <xxhash.h>

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <cstring>
#include <thread>

#include "base/error.h"
#include "mtfile/mt_cut_internal.h"

namespace mt::cut_internal {

namespace {

constexpr double kMaxLoad = 0.75;   // a part with more distinct edges than this overflows
constexpr double kPlanLoad = 0.6;   // what planning aims at: room for the estimate to be low
constexpr size_t kMinSlots = 4096;  // a silly budget still gets a working table
constexpr uint64_t kFlushEvery = 4096;  // new edges a thread counts before adding them to the part's total

constexpr uint32_t kClaimed = UINT32_MAX;  // `uses` of a slot whose key is being written
constexpr uint32_t kMaxUses = UINT32_MAX - 1;

uint64_t edgeHash(const EdgeKey& k) { return XXH3_64bits(k.data(), sizeof k); }

}  // namespace

void EdgeTable::clear() {
  tbb::parallel_for(tbb::blocked_range<size_t>(0, count_, 1 << 16), [&](const tbb::blocked_range<size_t>& b) {
    std::memset(static_cast<void*>(&slots_[b.begin()]), 0, b.size() * sizeof(EdgeSlot));
  });
}

size_t EdgeTable::home(uint64_t hash) const { return slotOf(hash, count_); }

EdgeTable::Add EdgeTable::add(const EdgeKey& key, size_t home, uint32_t patch, uint32_t uses) {
  assert(uses > 0 && home < count_);
  for (size_t probe = 0, i = home; probe < count_; ++probe, i = i + 1 == count_ ? 0 : i + 1) {
    EdgeSlot& s = slots_[i];
    std::atomic_ref<uint32_t> state(s.uses);
    uint32_t u = state.load(std::memory_order_acquire);
    if (u == 0 && state.compare_exchange_strong(u, kClaimed, std::memory_order_acquire)) {
      s.key = key;
      std::atomic_ref<uint32_t>(s.patch).store(patch, std::memory_order_relaxed);
      state.store(std::min(uses, kMaxUses), std::memory_order_release);
      return Add::New;
    }
    while (u == kClaimed) {  // the claiming thread may have been preempted (shared cores)
      std::this_thread::yield();
      u = state.load(std::memory_order_acquire);
    }
    if (s.key != key) continue;
    while (u < kMaxUses && !state.compare_exchange_weak(u, u > kMaxUses - uses ? kMaxUses : u + uses, std::memory_order_relaxed)) {
    }
    std::atomic_ref<uint32_t> first(s.patch);
    uint32_t f = first.load(std::memory_order_relaxed);
    while (patch < f && !first.compare_exchange_weak(f, patch, std::memory_order_relaxed)) {
    }
    return Add::Counted;
  }
  return Add::Full;
}

namespace {

// The edges a pass counts: smaller endpoint inside `box`, hash inside [hashLo, hashHi].
struct EdgePart {
  GridBox box = GridBox::everything();
  uint64_t hashLo = 0, hashHi = UINT64_MAX;
};

bool inside(const GridBox& b, const uint32_t* q) {
  return q[0] >= b.lo[0] && q[0] <= b.hi[0] && q[1] >= b.lo[1] && q[1] <= b.hi[1] && q[2] >= b.lo[2] && q[2] <= b.hi[2];
}
bool meets(const GridBox& a, const GridBox& b) {
  for (int k = 0; k < 3; ++k)
    if (a.lo[k] > b.hi[k] || b.lo[k] > a.hi[k]) return false;
  return true;
}
bool lexLess(const uint32_t* a, const uint32_t* b) {
  return a[0] != b[0] ? a[0] < b[0] : a[1] != b[1] ? a[1] < b[1] : a[2] < b[2];
}
bool sameQ(const uint32_t* a, const uint32_t* b) { return a[0] == b[0] && a[1] == b[1] && a[2] == b[2]; }

// One patch's edges in a part, each with its number of uses in the patch: most edges are used
// twice within their patch, so the shared table sees each once (half the random accesses).
struct PatchEdges {
  struct Edge {
    EdgeKey key;
    uint64_t hash;
    size_t home;
    uint32_t uses;
  };
  std::vector<uint64_t> pairs;  // (smaller local index << 32 | larger), one per use
  std::vector<Edge> edges;

  void collect(const DecodedPatch& d, const EdgePart& part) {
    pairs.clear();
    edges.clear();
    for (uint32_t t = 0; t < d.triangleCount(); ++t) {
      const uint32_t* v = &d.triangles[3 * t];
      const uint32_t* q[3] = {&d.q[3 * v[0]], &d.q[3 * v[1]], &d.q[3 * v[2]]};
      if (sameQ(q[0], q[1]) || sameQ(q[1], q[2]) || sameQ(q[0], q[2])) continue;  // assembleCut drops it
      for (int c = 0; c < 3; ++c) {
        const uint64_t a = v[c], b = v[(c + 1) % 3];
        pairs.push_back(a < b ? a << 32 | b : b << 32 | a);
      }
    }
    std::sort(pairs.begin(), pairs.end());
    // Two local vertices at one q give two entries of one edge here; the table adds them up.
    for (size_t i = 0; i < pairs.size();) {
      size_t j = i + 1;
      while (j < pairs.size() && pairs[j] == pairs[i]) ++j;
      const uint32_t* a = &d.q[3 * (pairs[i] >> 32)];
      const uint32_t* b = &d.q[3 * (pairs[i] & 0xffffffffu)];
      if (lexLess(b, a)) std::swap(a, b);
      if (inside(part.box, a)) {
        Edge e{{a[0], a[1], a[2], b[0], b[1], b[2]}, 0, 0, uint32_t(j - i)};
        e.hash = edgeHash(e.key);
        if (e.hash >= part.hashLo && e.hash <= part.hashHi) edges.push_back(e);
      }
      i = j;
    }
  }
};

// A patch's position in the cut's patch list, where its box centre is, and how many triangles
// (of the index) it brings: what the k-d split weighs.
struct PlanItem {
  std::array<uint32_t, 3> centre;
  uint32_t triangles;  // a patch's, as its record has them
  uint32_t position;
};
// The bounded check's accounting (tools/mtverify.cpp, kCutBytesPerPatch = 32) counts a plan item
// and the patch's id in the cut's list; the part members come after the items are gone.
static_assert(sizeof(PlanItem) + sizeof(uint32_t) <= 32, "a patch's plan item and id fit what the budget counts");

// Splits `box` (holding the items' centres) into `leaves` parts along the longest side of the
// centres' extent, each cut at the weight (triangles) that gives both sides their share of the
// leaves, so the parts come out about equal and no more than needed; parts in k-d order.
void planSpatialParts(const GridBox& box, PlanItem* begin, PlanItem* end, uint64_t leaves, std::vector<EdgePart>& parts) {
  uint64_t weight = 0;
  GridBox extent;
  for (PlanItem* p = begin; p != end; ++p) {
    weight += p->triangles;
    for (int k = 0; k < 3; ++k)
      extent.lo[k] = std::min(extent.lo[k], p->centre[k]), extent.hi[k] = std::max(extent.hi[k], p->centre[k]);
  }
  int axis = 0;
  for (int k = 1; k < 3; ++k)
    if (uint64_t(extent.hi[k]) - extent.lo[k] > uint64_t(extent.hi[axis]) - extent.lo[axis]) axis = k;
  if (leaves <= 1 || end - begin <= 1 || extent.hi[axis] == extent.lo[axis]) {
    parts.push_back({box});  // one part, or all centres at one point: an overflow will split it
    return;
  }
  std::sort(begin, end, [&](const PlanItem& a, const PlanItem& b) {
    return a.centre[axis] != b.centre[axis] ? a.centre[axis] < b.centre[axis] : a.position < b.position;
  });
  const uint64_t leftLeaves = leaves / 2;
  const double leftWeight = double(weight) * double(leftLeaves) / double(leaves);
  PlanItem* at = begin;
  for (uint64_t before = 0; at + 1 < end && double(before + at->triangles) < leftWeight; ++at) before += at->triangles;
  // Centres below `splitAt` go left. At least the smallest centre goes left and the largest right.
  const uint32_t splitAt = std::max(at->centre[axis], begin->centre[axis] + 1);
  PlanItem* split = std::partition_point(begin, end, [&](const PlanItem& p) { return p.centre[axis] < splitAt; });
  assert(split != begin && split != end && leftLeaves >= 1 && "both sides get items and leaves");
  GridBox left = box, right = box;
  left.hi[axis] = splitAt - 1;
  right.lo[axis] = splitAt;
  planSpatialParts(left, begin, split, leftLeaves, parts);
  planSpatialParts(right, split, end, leaves - leftLeaves, parts);
}

// One run of countCutEdges: the cut's patches, their grid boxes (computed once needed), the plan
// (a stack of parts: a split part's halves are counted next, in order) and the table.
class CutEdgeCounter {
 public:
  CutEdgeCounter(const MtFileReader& r, const std::vector<uint32_t>& arcs, const EdgeCountOptions& o, uint64_t tableBytes)
      : r_(r), o_(o), patchIds_(cutPatchIds(r, arcs)), table_(0) {
    st_.patches = patchIds_.size();
    for (uint32_t id : patchIds_) st_.triangles += r.patches()[id].triangles;
    if (o.patchBoxes && o.patchBoxes->size() != r.patches().size())
      throw Error("EdgeCountOptions::patchBoxes has " + std::to_string(o.patchBoxes->size()) + " boxes for " +
                  std::to_string(r.patches().size()) + " patches");
    // The whole budget when the cut needs several parts (fewer parts, fewer patches read twice at
    // their borders); a cut that fits gets a table for its estimate (an overflow splits it).
    estimate_ = o.edgesPerTriangle * double(st_.triangles);
    const uint64_t budgetSlots = tableBytes / kSlotBytes;
    const uint64_t wantedSlots = uint64_t(std::ceil(estimate_ / kPlanLoad)) + 1;
    const size_t slots = size_t(std::max<uint64_t>(kMinSlots, std::min(budgetSlots, wantedSlots)));
    table_ = EdgeTable(slots);
    st_.tableBytes = slots * kSlotBytes;
    limit_ = uint64_t(kMaxLoad * double(slots));
    planEdges_ = kPlanLoad * double(slots);
  }

  EdgeCountStats run(const std::function<void(const EdgeTable&)>& sweep) {
    const auto start = std::chrono::steady_clock::now();
    std::vector<EdgePart> parts = plan();
    bool tableUsed = false;
    while (!parts.empty()) {
      const EdgePart part = parts.back();
      parts.pop_back();
      selectMembers(part);
      if (tableUsed) table_.clear();
      tableUsed = true;
      if (countPart(part)) {
        ++st_.splitParts;
        split(part, parts);
        continue;
      }
      sweep(table_);
      ++st_.parts;
    }
    st_.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return st_;
  }

 private:
  // Grid boxes by position in patchIds: the caller's, or one decode pass.
  void ensureBoxes() {
    if (haveBoxes_ || o_.patchBoxes) return void(haveBoxes_ = true);
    ownBoxes_.resize(patchIds_.size());
    tbb::parallel_for(size_t(0), patchIds_.size(), [&](size_t i) { ownBoxes_[i] = patchBox(r_.readPatch(patchIds_[i])); });
    st_.patchReads += patchIds_.size();
    haveBoxes_ = true;
  }
  const GridBox& boxAt(size_t i) const { return o_.patchBoxes ? (*o_.patchBoxes)[patchIds_[i]] : ownBoxes_[i]; }

  // The parts, as a stack (the first to count last).
  std::vector<EdgePart> plan() {
    std::vector<EdgePart> parts;
    const uint64_t wanted = uint64_t(std::ceil(estimate_ / planEdges_));
    if (estimate_ <= planEdges_) {
      parts.push_back({});
    } else if (o_.spatialParts) {
      ensureBoxes();
      // Reserved exactly, like the member list: the budget counts one item per patch, and growing
      // by doubling held up to three (a billion-triangle file's check passed --memory 1G by 8 MiB).
      std::vector<PlanItem> items;
      items.reserve(patchIds_.size());
      for (uint32_t i = 0; i < patchIds_.size(); ++i) {
        const GridBox& b = boxAt(i);
        if (b.empty()) continue;
        PlanItem p{{}, r_.patches()[patchIds_[i]].triangles, i};
        for (int k = 0; k < 3; ++k) p.centre[k] = uint32_t(b.lo[k] + (uint64_t(b.hi[k]) - b.lo[k]) / 2);
        items.push_back(p);
      }
      planSpatialParts(GridBox::everything(), items.data(), items.data() + items.size(), wanted, parts);
    } else {
      const uint64_t width = UINT64_MAX / wanted;
      for (uint64_t k = 0; k < wanted; ++k)
        parts.push_back({GridBox::everything(), k * width, k + 1 == wanted ? UINT64_MAX : (k + 1) * width - 1});
    }
    std::reverse(parts.begin(), parts.end());
    return parts;
  }

  // members_: positions in patchIds of the patches that can hold the part's edges.
  void selectMembers(const EdgePart& part) {
    members_.clear();
    members_.reserve(patchIds_.size());  // once: never more members than patches
    const bool wholeGrid = part.box.lo == GridBox::everything().lo && part.box.hi == GridBox::everything().hi;
    for (uint32_t i = 0; i < patchIds_.size(); ++i)
      if (!haveBoxes_ || (!boxAt(i).empty() && (wholeGrid || meets(boxAt(i), part.box)))) members_.push_back(i);
  }

  // Counts the part's edges into the (clear) table; true when it overflowed.
  bool countPart(const EdgePart& part) {
    std::atomic<uint64_t> distinct{0}, reads{0};
    std::atomic<bool> overflow{false};
    tbb::parallel_for(tbb::blocked_range<size_t>(0, members_.size()), [&](const tbb::blocked_range<size_t>& range) {
      PatchEdges& local = scratch_.local();
      for (size_t m = range.begin(); m != range.end(); ++m) {
        if (overflow.load(std::memory_order_relaxed)) return;
        const uint32_t id = patchIds_[members_[m]];
        const DecodedPatch d = r_.readPatch(id);
        reads.fetch_add(1, std::memory_order_relaxed);
        local.collect(d, part);
        if (!addPatchEdges(local, id, distinct, overflow)) return;
      }
    });
    st_.patchReads += reads.load();
    // The part overflowed iff it has more than `limit` distinct edges: the flushed partial sums and
    // a full table are both lower bounds, so the decision does not depend on thread timing.
    return overflow.load() || distinct.load() > limit_;
  }

  // Adds one patch's edges to the table, adding the new ones to `distinct` every kFlushEvery
  // and at the end; sets `overflow` (and returns false) once the table is full or `distinct`
  // passes the limit.
  bool addPatchEdges(PatchEdges& local, uint32_t id, std::atomic<uint64_t>& distinct, std::atomic<bool>& overflow) {
    uint64_t added = 0;
    auto flush = [&] {
      if (distinct.fetch_add(added, std::memory_order_relaxed) + added > limit_) overflow.store(true);
      added = 0;
    };
    // Random accesses over the whole table: start fetching a few edges ahead.
    constexpr size_t kAhead = 8;
    const size_t n = local.edges.size();
    for (size_t k = 0; k < std::min(n, kAhead); ++k) table_.prefetch(local.edges[k].home = table_.home(local.edges[k].hash));
    for (size_t k = 0; k < n; ++k) {
      if (k + kAhead < n) table_.prefetch(local.edges[k + kAhead].home = table_.home(local.edges[k + kAhead].hash));
      const PatchEdges::Edge& e = local.edges[k];
      const EdgeTable::Add result = table_.add(e.key, e.home, id, e.uses);
      if (result == EdgeTable::Add::Full) {  // more than `limit` distinct edges: overflow
        overflow.store(true);
        return false;
      }
      if (result == EdgeTable::Add::New && ++added == kFlushEvery) flush();
    }
    flush();
    return true;
  }

  // Splits an overflowed part in two (pushed so the lower half is counted next): its box at the
  // middle of the longest side of its patches' extent inside it, or its hash range when that
  // extent is one grid point.
  void split(const EdgePart& part, std::vector<EdgePart>& parts) {
    GridBox data;  // where the part's patches are, inside the part's box
    if (o_.spatialParts) {
      ensureBoxes();
      for (uint32_t i : members_) {
        const GridBox& b = boxAt(i);
        if (b.empty() || !meets(b, part.box)) continue;
        for (int k = 0; k < 3; ++k)
          data.lo[k] = std::min(data.lo[k], std::max(b.lo[k], part.box.lo[k])),
          data.hi[k] = std::max(data.hi[k], std::min(b.hi[k], part.box.hi[k]));
      }
    }
    EdgePart low = part, high = part;
    int axis = 0;
    for (int k = 1; k < 3; ++k)
      if (uint64_t(data.hi[k]) - data.lo[k] > uint64_t(data.hi[axis]) - data.lo[axis]) axis = k;
    if (!data.empty() && data.hi[axis] > data.lo[axis]) {
      const uint32_t mid = uint32_t(data.lo[axis] + (uint64_t(data.hi[axis]) - data.lo[axis]) / 2);
      low.box.hi[axis] = mid;
      high.box.lo[axis] = mid + 1;
      assert(part.box.lo[axis] <= mid && mid < part.box.hi[axis] && "both halves inside the part's box");
    } else {
      if (part.hashHi == part.hashLo) fail(r_.path(), "more edges share one hash than the edge table holds");
      const uint64_t mid = part.hashLo + (part.hashHi - part.hashLo) / 2;
      low.hashHi = mid;
      high.hashLo = mid + 1;
    }
    parts.push_back(high);
    parts.push_back(low);
  }

  const MtFileReader& r_;
  const EdgeCountOptions& o_;
  const std::vector<uint32_t> patchIds_;
  EdgeCountStats st_;
  double estimate_ = 0, planEdges_ = 0;
  uint64_t limit_ = 0;
  EdgeTable table_;
  std::vector<GridBox> ownBoxes_;
  bool haveBoxes_ = false;
  std::vector<uint32_t> members_;
  tbb::enumerable_thread_specific<PatchEdges> scratch_;
};

}  // namespace

EdgeCountStats countCutEdges(const MtFileReader& r, const std::vector<uint32_t>& arcs, const EdgeCountOptions& o,
                             uint64_t tableBytes, const std::function<void(const EdgeTable&)>& sweep) {
  return CutEdgeCounter(r, arcs, o, tableBytes).run(sweep);
}

}  // namespace mt::cut_internal
