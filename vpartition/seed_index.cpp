// Nearest-seed lookup for irregular V-partitions (BMT 4.2: "QT_i is the patch composed by the
// faces that are nearest to the seed point v_i").
//
// Ingest asks for ~50 M triangles and mtbuild asks again for every simplified triangle, so the
// lookup must be cheap. A kd-tree costs ~0.3-0.5 us per query; instead, a query point falls into
// a small cubic query cell (half the seed radius) and we keep, per thread, a cache of the exact
// candidate set of that cell: every seed that can be nearest to some point of the cell. Scans
// stream triangles in spatially coherent order, so most queries hit the cache and cost a few
// distance evaluations. The builder also hands over the query cells the mesh touches, whose lists
// go into a shared read-only table (a few per seed), so random-order queries (a shuffled PLY) do
// not depend on the cache either. The answer is always the exact nearest seed with ties to the lower index,
// whatever the cache state, so results do not depend on thread count or query order.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <limits>
#include <memory>

#include "vpartition/level.h"

namespace mt::vp {

namespace {

std::atomic<uint64_t> gNextUid{1};

inline uint64_t hashKey(uint64_t key) {
  key ^= key >> 31;
  key *= 0x9E3779B97F4A7C15ull;
  return key ^ (key >> 29);
}

// Candidate lists longer than this fall back to the ring search (rare: very uneven seeds).
constexpr uint32_t kMaxCandidates = 14;
constexpr uint32_t kCacheEntries = 4096;  // per thread, ~256 KB

struct CacheEntry {
  uint64_t uid;
  uint64_t key;
  uint32_t count;  // 0: too many candidates, use the ring search
  uint32_t cand[kMaxCandidates];
};

CacheEntry* threadCache() {
  thread_local std::unique_ptr<CacheEntry[]> cache;
  if (!cache) {
    cache.reset(new CacheEntry[kCacheEntries]);
    std::memset(static_cast<void*>(cache.get()), 0, sizeof(CacheEntry) * kCacheEntries);
  }
  return cache.get();
}

}  // namespace

void SeedIndex::build(const float* seeds, uint32_t count, double cellSize, const double* origin) {
  assert(cellSize > 0);
  seeds_ = seeds;
  count_ = count;
  size_ = cellSize;
  inv_ = 1.0 / cellSize;
  uid_ = gNextUid.fetch_add(1);
  table_.clear();
  order_.clear();
  shared_.clear();
  sharedCand_.clear();
  if (count == 0) return;
  for (int a = 0; a < 3; ++a) {
    if (origin) { origin_[a] = origin[a]; continue; }
    // Origin at the seeds' minimum so cell coordinates stay small and non-negative.
    float m = seeds[a];
    for (uint32_t i = 1; i < count; ++i) m = std::min(m, seeds[3 * i + a]);
    origin_[a] = double(m) - 0.5 * cellSize;
  }
  std::vector<std::pair<uint64_t, uint32_t>> keyed(count);
  for (int a = 0; a < 3; ++a) { lo_[a] = std::numeric_limits<int64_t>::max(); hi_[a] = 0; }
  for (uint32_t i = 0; i < count; ++i) {
    int64_t c[3];
    for (int a = 0; a < 3; ++a) {
      c[a] = coord(seeds[3 * i + a], a);
      lo_[a] = std::min(lo_[a], c[a]);
      hi_[a] = std::max(hi_[a], c[a]);
    }
    keyed[i] = {packCell(c[0], c[1], c[2]), i};
  }
  std::sort(keyed.begin(), keyed.end());  // by cell, then ascending seed index
  uint64_t cap = 16;
  while (cap < 2ull * count) cap <<= 1;
  table_.assign(cap, Slot{~0ull, 0, 0});
  mask_ = cap - 1;
  order_.resize(count);
  for (uint32_t i = 0; i < count;) {
    uint32_t j = i;
    while (j < count && keyed[j].first == keyed[i].first) { order_[j] = keyed[j].second; ++j; }
    uint64_t h = hashKey(keyed[i].first) & mask_;
    while (table_[h].key != ~0ull) h = (h + 1) & mask_;
    table_[h] = Slot{keyed[i].first, i, j};
    i = j;
  }
}

const SeedIndex::Slot* SeedIndex::find(uint64_t key) const {
  uint64_t h = hashKey(key) & mask_;
  for (;;) {
    const Slot& s = table_[h];
    if (s.key == key) return &s;
    if (s.key == ~0ull) return nullptr;
    h = (h + 1) & mask_;
  }
}

uint32_t SeedIndex::nearest(const float p[3]) const {
  if (count_ == 0) return UINT32_MAX;
  int64_t c[3];
  for (int a = 0; a < 3; ++a) c[a] = coord(p[a], a);
  uint32_t best = UINT32_MAX;
  float bestD = std::numeric_limits<float>::infinity();
  bool farAway = false;
  for (int a = 0; a < 3; ++a) farAway |= (c[a] < lo_[a] - 4 || c[a] > hi_[a] + 4);
  if (farAway) {
    // Far outside the seeds (never for a mesh's own triangles): a linear scan beats many rings.
    for (uint32_t i = 0; i < count_; ++i) {
      float d = dist2(p, seeds_ + 3 * size_t(i));
      if (d < bestD) { bestD = d; best = i; }
    }
    return best;
  }
  auto visit = [&](int64_t x, int64_t y, int64_t z) {
    if (x < lo_[0] || y < lo_[1] || z < lo_[2] || x > hi_[0] || y > hi_[1] || z > hi_[2]) return;
    const Slot* s = find(packCell(x, y, z));
    if (!s) return;
    for (uint32_t k = s->begin; k < s->end; ++k) {
      uint32_t i = order_[k];
      float d = dist2(p, seeds_ + 3 * size_t(i));
      if (d < bestD || (d == bestD && i < best)) { bestD = d; best = i; }
    }
  };
  for (int64_t k = 0;; ++k) {
    // Shell at Chebyshev distance k around the query's cell.
    for (int64_t dz = -k; dz <= k; ++dz)
      for (int64_t dy = -k; dy <= k; ++dy) {
        bool inner = std::max(std::abs(dz), std::abs(dy)) < k;
        if (inner) {
          visit(c[0] - k, c[1] + dy, c[2] + dz);
          visit(c[0] + k, c[1] + dy, c[2] + dz);
        } else {
          for (int64_t dx = -k; dx <= k; ++dx) visit(c[0] + dx, c[1] + dy, c[2] + dz);
        }
      }
    // Everything outside the (2k+1)^3 block is at least k cells away from p. Compare with a
    // margin so float rounding can never stop the search one ring early.
    double reach = double(k) * size_;
    if (best != UINT32_MAX && double(bestD) * (1 + 1e-5) < reach * reach) break;
    bool coversAll = true;
    for (int a = 0; a < 3; ++a) coversAll &= (c[a] - k <= lo_[a] && c[a] + k >= hi_[a]);
    if (coversAll) break;
  }
  assert(best != UINT32_MAX);
  return best;
}

void SeedIndex::within(const double p[3], double radius, std::vector<uint32_t>& out) const {
  size_t first = out.size();
  int64_t lo[3], hi[3];
  for (int a = 0; a < 3; ++a) {
    lo[a] = std::max(lo_[a], coord(p[a] - radius, a));
    hi[a] = std::min(hi_[a], coord(p[a] + radius, a));
  }
  double r2 = radius * radius;
  for (int64_t z = lo[2]; z <= hi[2]; ++z)
    for (int64_t y = lo[1]; y <= hi[1]; ++y)
      for (int64_t x = lo[0]; x <= hi[0]; ++x) {
        const Slot* s = find(packCell(x, y, z));
        if (!s) continue;
        for (uint32_t k = s->begin; k < s->end; ++k) {
          const float* q = seeds_ + 3 * size_t(order_[k]);
          double dx = q[0] - p[0], dy = q[1] - p[1], dz = q[2] - p[2];
          if (dx * dx + dy * dy + dz * dz <= r2) out.push_back(order_[k]);
        }
      }
  std::sort(out.begin() + first, out.end());
}

uint64_t SeedIndex::queryCell(const float p[3]) const {
  const double qinv = 2.0 * inv_;
  return packCell(int64_t(std::floor((p[0] - origin_[0]) * qinv)),
                  int64_t(std::floor((p[1] - origin_[1]) * qinv)),
                  int64_t(std::floor((p[2] - origin_[2]) * qinv)));
}

void SeedIndex::candidates(uint64_t key, std::vector<uint32_t>& out) const {
  // Candidate set of a query cell: with s0 the seed nearest to the cell centre m at distance d0,
  // any point x of the cell has its nearest seed within d0 + |x-m| <= d0 + diag/2 of x, hence
  // within d0 + diag of m. The margin absorbs float rounding of the later comparisons.
  constexpr int64_t kBias = int64_t(1) << 20;
  constexpr uint64_t kMask = (1u << 21) - 1;
  const int64_t c[3] = {int64_t(key & kMask) - kBias, int64_t((key >> 21) & kMask) - kBias,
                        int64_t(key >> 42) - kBias};
  const double q = 0.5 * size_;
  double m[3];
  float mf[3];
  for (int a = 0; a < 3; ++a) { m[a] = origin_[a] + (double(c[a]) + 0.5) * q; mf[a] = float(m[a]); }
  uint32_t s0 = nearest(mf);
  const float* s = seeds_ + 3 * size_t(s0);
  double d0 = std::sqrt((s[0] - m[0]) * (s[0] - m[0]) + (s[1] - m[1]) * (s[1] - m[1]) +
                        (s[2] - m[2]) * (s[2] - m[2]));
  double radius = (d0 + q * std::sqrt(3.0)) * (1 + 1e-4) + 1e-6 * size_;
  size_t first = out.size();
  within(m, radius, out);
  if (out.size() - first > kMaxCandidates) out.resize(first);
}

void SeedIndex::precompute(const std::vector<uint64_t>& queryCells) {
  uint64_t cap = 16;
  while (cap < 2ull * queryCells.size()) cap <<= 1;
  shared_.assign(cap, Slot{~0ull, 0, 0});
  sharedMask_ = cap - 1;
  sharedCand_.clear();
  // The lists are independent (a ring search each): computed in parallel, then put in the table
  // in the given order, so the table is the same whatever the thread count.
  std::vector<std::vector<uint32_t>> lists(queryCells.size());
  tbb::parallel_for(tbb::blocked_range<size_t>(0, queryCells.size(), 256), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i < r.end(); ++i) candidates(queryCells[i], lists[i]);
  });
  for (size_t i = 0; i < queryCells.size(); ++i) {
    const uint64_t key = queryCells[i];
    uint64_t h = hashKey(key) & sharedMask_;
    while (shared_[h].key != ~0ull && shared_[h].key != key) h = (h + 1) & sharedMask_;
    if (shared_[h].key == key) continue;
    // An empty range means "too many candidates": use the ring search.
    shared_[h] = Slot{key, uint32_t(sharedCand_.size()), uint32_t(sharedCand_.size() + lists[i].size())};
    sharedCand_.insert(sharedCand_.end(), lists[i].begin(), lists[i].end());
    std::vector<uint32_t>().swap(lists[i]);
  }
  sharedCand_.shrink_to_fit();
}

const SeedIndex::Slot* SeedIndex::findShared(uint64_t key) const {
  if (shared_.empty()) return nullptr;
  uint64_t h = hashKey(key) & sharedMask_;
  for (;;) {
    const Slot& s = shared_[h];
    if (s.key == key) return &s;
    if (s.key == ~0ull) return nullptr;
    h = (h + 1) & sharedMask_;
  }
}

// floor() to an integer without the libm call (not inlined at -O2 without SSE4.1): exact for
// every double in int64 range, which the range checks below keep.
static inline int64_t floorToInt(double x) {
  int64_t t = int64_t(x);
  return t - int64_t(double(t) > x);
}

uint32_t SeedIndex::nearestCached(const float p[3]) const {
  if (count_ <= 1) return count_ == 0 ? UINT32_MAX : 0;
  // Spatially coherent streams (a scan's faces, Morton-ordered samples, a region's triangles in
  // mtbuild) ask about nearby points many times in a row. Per thread and index (uid mod 8, since
  // crossKey alternates between two levels' indexes) we keep the last query cell's candidate list
  // (a copy: cache entries may be refilled by other indexes) and an anchor: a point a whose nearest
  // seed s beats every other seed by a known gap. By the triangle inequality any p with
  // |p - a| < (d2 - d1) / 2 has the same nearest seed, with the rest of the gap (slack below) to
  // spare for float rounding, so the answer is still exactly nearest()'s.
  struct Last {
    const SeedIndex* index;
    uint64_t uid, key;
    uint32_t count;
    uint32_t cand[kMaxCandidates];
    bool anchored;
    uint32_t anchorSeed;
    double anchor[3], reach2;
  };
  thread_local Last lastSlots[8] = {};
  Last& last = lastSlots[uid_ & 7];
  const bool mine = last.index == this && last.uid == uid_;
  if (mine && last.anchored) {
    const double dx = double(p[0]) - last.anchor[0], dy = double(p[1]) - last.anchor[1], dz = double(p[2]) - last.anchor[2];
    if (dx * dx + dy * dy + dz * dz < last.reach2) return last.anchorSeed;
  }
  // Query cells are half a seed radius: a candidate list then holds ~5-10 seeds on a surface.
  const double qinv = 2.0 * inv_;
  int64_t q[3];
  for (int a = 0; a < 3; ++a) {
    const double x = (p[a] - origin_[a]) * qinv;
    // Outside the seeds' range (or beyond int64): no cache. Same test as on floor(x) itself.
    if (!(x >= double(2 * lo_[a] - 8)) || !(x < double(2 * hi_[a] + 9))) return nearest(p);
    q[a] = floorToInt(x);
  }
  const uint64_t key = packCell(q[0], q[1], q[2]);
  const uint32_t* cand;
  uint32_t count;
  if (mine && last.key == key) {
    cand = last.cand;
    count = last.count;
  } else {
    if (const Slot* s = findShared(key)) {
      cand = sharedCand_.data() + s->begin;
      count = s->end - s->begin;
    } else {
      CacheEntry& e =
          threadCache()[hashKey(key ^ (uid_ * 0xD6E8FEB86659FD93ull)) & (kCacheEntries - 1)];
      if (e.uid != uid_ || e.key != key) {
        thread_local std::vector<uint32_t> list;
        list.clear();
        candidates(key, list);
        e.uid = uid_;
        e.key = key;
        e.count = uint32_t(list.size());
        std::copy(list.begin(), list.end(), e.cand);
      }
      cand = e.cand;
      count = e.count;
    }
    if (!mine) last.anchored = false;
    last.index = this;
    last.uid = uid_;
    last.key = key;
    last.count = std::min(count, kMaxCandidates);
    std::copy(cand, cand + last.count, last.cand);
  }
  if (count == 0) return nearest(p);
  // Candidates ascend by index, so strict < keeps the lower index on ties.
  uint32_t best = cand[0];
  float bestD = dist2(p, seeds_ + 3 * size_t(best));
  float secondD = std::numeric_limits<float>::infinity();
  for (uint32_t k = 1; k < count; ++k) {
    float d = dist2(p, seeds_ + 3 * size_t(cand[k]));
    if (d < bestD) {
      secondD = bestD;
      bestD = d;
      best = cand[k];
    } else if (d < secondD) {
      secondD = d;
    }
  }
  // The new anchor. A seed that is not a candidate of the cell lies farther than
  // d0 + q sqrt(3) from the cell centre m (candidates()), where d0 >= d1 - |p - m|, hence farther
  // than d1 + q sqrt(3) - 2 |p - m| from p: that bounds the second distance too.
  const double cellEdge = 0.5 * size_;
  double pm2 = 0;
  for (int a = 0; a < 3; ++a) {
    const double m = origin_[a] + (double(q[a]) + 0.5) * cellEdge;
    pm2 += (double(p[a]) - m) * (double(p[a]) - m);
  }
  const double d1 = std::sqrt(double(bestD));
  const double d2 = std::min(std::sqrt(double(secondD)), d1 + cellEdge * std::sqrt(3.0) - 2 * std::sqrt(pm2));
  const double reach = 0.5 * (d2 - d1) - (1e-3 * d2 + 1e-6 * size_);
  last.anchored = reach > 0;
  if (last.anchored) {
    for (int a = 0; a < 3; ++a) last.anchor[a] = p[a];
    last.reach2 = reach * reach;
    last.anchorSeed = best;
  }
  return best;
}

}  // namespace mt::vp
