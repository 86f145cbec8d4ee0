#include "mtrender/patch_cache.h"

#include <algorithm>
#include <cmath>

#include "base/error.h"

namespace mt::render {

uint32_t packNormal(const float n[3]) {
  auto q = [](float v) -> uint32_t {
    int i = int(std::lround(std::clamp(v, -1.0f, 1.0f) * 511.0f));
    return uint32_t(i) & 0x3ffu;
  };
  return q(n[0]) | (q(n[1]) << 10) | (q(n[2]) << 20);
}

PatchCache::PatchCache(uint64_t capBytes, const std::vector<uint64_t>& patchBytes)
    : PatchCache(capBytes, patchBytes, MoveGroups()) {}

PatchCache::PatchCache(uint64_t capBytes, const std::vector<uint64_t>& patchBytes,
                       const MoveGroups& moves)
    : capBytes_(capBytes) {
  uint64_t largest = 64;
  for (uint64_t b : patchBytes) largest = std::max(largest, b);
  // Size classes: largest / 2^k (rounded up to 64 bytes), down to ~4 KiB, at most 6.
  for (int k = 0; k < 6; ++k) {
    uint64_t s = ((largest >> k) + 63) & ~uint64_t(63);
    if (k > 0 && s < 4096) break;
    classBytes_.push_back(s);
  }
  const size_t nc = classBytes_.size();
  std::vector<uint64_t> count(nc, 0);
  patchClass_.resize(patchBytes.size());
  // A patch's class: the smallest place holder that holds it. The sizes fall with k, so that is
  // the number of classes after the first whose size is at least the patch's: counted without a
  // branch per class (1.2 M patches of a billion-triangle file are classed at open).
  for (size_t i = 0; i < patchBytes.size(); ++i) {
    size_t k = 0;
    for (size_t j = 1; j < nc; ++j) k += classBytes_[j] >= patchBytes[i];
    patchClass_[i] = uint8_t(k);
  }
  for (uint8_t k : patchClass_) ++count[k];
  // The cap is shared in proportion to each class's demand (all its patches resident); a class
  // never gets more place holders than it has patches.
  uint64_t demand = 0;
  for (size_t k = 0; k < nc; ++k) demand += count[k] * classBytes_[k];
  std::vector<uint64_t> n(nc, 0);
  for (size_t k = 0; k < nc; ++k) {
    if (!count[k]) continue;
    n[k] = demand <= capBytes_ ? count[k]
                               : uint64_t(double(capBytes_) * double(count[k] * classBytes_[k]) / double(demand)) / classBytes_[k];
    n[k] = std::max<uint64_t>(n[k], std::min<uint64_t>(count[k], 3));
  }
  // The floor: the largest move's patches of each class, plus 3 (see the header).
  std::vector<uint64_t> floor(nc, 0), inMove(nc, 0);
  if (moves)
    moves([&](const uint32_t* ids, size_t count) {
      std::fill(inMove.begin(), inMove.end(), 0);
      for (size_t i = 0; i < count; ++i)
        if (ids[i] < patchClass_.size()) ++inMove[patchClass_[ids[i]]];
      for (size_t k = 0; k < nc; ++k) floor[k] = std::max(floor[k], inMove[k]);
    });
  std::vector<uint64_t> least(nc);
  for (size_t k = 0; k < nc; ++k) {
    least[k] = std::min<uint64_t>(count[k], std::max<uint64_t>(3, floor[k] ? floor[k] + 3 : 0));
    n[k] = std::max(n[k], least[k]);
  }
  // Over the cap once the floors are in: take place holders back from the classes with the most
  // bytes above their floor, one at a time (a few thousand steps at most).
  auto arena = [&] {
    uint64_t b = 0;
    for (size_t k = 0; k < nc; ++k) b += n[k] * classBytes_[k];
    return b;
  };
  for (uint64_t b = arena(); b > capBytes_;) {
    size_t best = nc;
    for (size_t k = 0; k < nc; ++k)
      if (n[k] > least[k] && (best == nc || (n[k] - least[k]) * classBytes_[k] > (n[best] - least[best]) * classBytes_[best])) best = k;
    if (best == nc) break;  // the floors alone pass the cap: refused below
    --n[best];
    b -= classBytes_[best];
  }
  for (size_t k = 0; k < nc; ++k) arenaBytes_ += n[k] * classBytes_[k];
  if (arenaBytes_ > capBytes_ || arenaBytes_ == 0)
    throw Error("mtrender: a cache of " + std::to_string(capBytes_) + " bytes cannot hold the place holders one cut move needs in every size class (" +
                std::to_string(arenaBytes_) + " bytes; the largest patch decodes to " + std::to_string(largest) + " bytes); give a larger --cache");
  // Uninitialized on purpose: pages are committed only when a place holder is first written, so
  // the resident size grows with use and never passes the cap.
  arena_.reset(new uint8_t[arenaBytes_]);
  free_.resize(nc);
  urgentScan_.assign(nc, 0);
  classFirst_.assign(nc, 0);
  classCount_.assign(nc, 0);
  uint64_t offset = 0;
  for (size_t k = 0; k < nc; ++k) {
    classFirst_[k] = uint32_t(slots_.size());
    classCount_[k] = uint32_t(n[k]);
    for (uint64_t i = 0; i < n[k]; ++i) {
      Slot s;
      s.cls = uint8_t(k);
      s.offset = offset;
      offset += classBytes_[k];
      slots_.push_back(s);
    }
  }
  for (uint32_t i = 0; i < slots_.size(); ++i) putOnFree(i);
}

PatchCache::~PatchCache() = default;

void PatchCache::takeOffFree(Slot& s) {
  if (!s.onFree) return;
  free_[s.cls].erase(s.freeIt);
  s.onFree = false;
}

void PatchCache::putOnFree(uint32_t slot) {
  Slot& s = slots_[slot];
  if (s.onFree) return;
  s.freeIt = free_[s.cls].insert(free_[s.cls].end(), slot);
  s.onFree = true;
}

void PatchCache::evictContent(uint32_t slot) {
  Slot& s = slots_[slot];
  if (s.id == UINT32_MAX) return;
  hash_.erase(s.id);
  s.id = UINT32_MAX;
  s.state = State::Absent;
  s.usage = 0;
  --physical_;
  usedBytes_ -= classBytes_[s.cls];
  ++evictions_;
}

PatchCache::State PatchCache::state(uint32_t id) const {
  std::lock_guard<std::mutex> lock(mu_);
  if (bad_.count(id)) return State::Bad;
  auto it = hash_.find(id);
  return it == hash_.end() ? State::Absent : slots_[it->second].state;
}

bool PatchCache::isBad(uint32_t id) const {
  std::lock_guard<std::mutex> lock(mu_);
  return bad_.count(id) != 0;
}

bool PatchCache::allReady(const uint32_t* ids, size_t n) const {
  std::lock_guard<std::mutex> lock(mu_);
  for (size_t i = 0; i < n; ++i) {
    auto it = hash_.find(ids[i]);
    if (it == hash_.end() || slots_[it->second].state != State::Ready) return false;
  }
  return true;
}

bool PatchCache::pinAll(const uint32_t* ids, size_t n) {
  std::lock_guard<std::mutex> lock(mu_);
  for (size_t i = 0; i < n; ++i) {
    auto it = hash_.find(ids[i]);
    if (it == hash_.end() || slots_[it->second].state != State::Ready) return false;
  }
  for (size_t i = 0; i < n; ++i) {
    Slot& s = slots_[hash_.find(ids[i])->second];
    if (s.onFree) {
      takeOffFree(s);
      ++secondChance_;
    }
    if (s.usage++ == 0) ++pinned_;
  }
  return true;
}

void PatchCache::unpinAll(const uint32_t* ids, size_t n) {
  std::lock_guard<std::mutex> lock(mu_);
  for (size_t i = 0; i < n; ++i) {
    auto it = hash_.find(ids[i]);
    if (it == hash_.end()) continue;
    Slot& s = slots_[it->second];
    if (s.usage > 0 && --s.usage == 0) --pinned_;
  }
}

void PatchCache::touch(const uint32_t* ids, size_t n, uint64_t frame) {
  std::lock_guard<std::mutex> lock(mu_);
  for (size_t i = 0; i < n; ++i) {
    auto it = hash_.find(ids[i]);
    if (it == hash_.end()) continue;
    Slot& s = slots_[it->second];
    s.touched = std::max(s.touched, frame);
    if (s.onFree && s.state == State::Ready) {
      takeOffFree(s);
      ++secondChance_;
    }
  }
}

void PatchCache::endFrame(uint64_t frame) {
  std::lock_guard<std::mutex> lock(mu_);
  for (uint32_t i = 0; i < slots_.size(); ++i) {
    Slot& s = slots_[i];
    if (s.state == State::Ready && s.usage == 0 && !s.onFree && s.touched < frame) putOnFree(i);
  }
}

PatchView PatchCache::view(uint32_t id) const {
  std::lock_guard<std::mutex> lock(mu_);
  PatchView v;
  auto it = hash_.find(id);
  if (it == hash_.end() || slots_[it->second].state != State::Ready) return v;
  const Slot& s = slots_[it->second];
  const uint8_t* base = arena_.get() + s.offset;
  v.vertices = reinterpret_cast<const RenderVertex*>(base);
  v.vertexCount = s.vertexCount;
  v.indices = reinterpret_cast<const uint32_t*>(base + uint64_t(s.vertexCount) * sizeof(RenderVertex));
  v.indexCount = s.indexCount;
  v.bound = s.bound;
  if (s.texWidth && s.texHeight) {
    v.cornerUV = reinterpret_cast<const uint16_t*>(base + textureOffset(s.vertexCount, s.indexCount / 3));
    v.texels = base + texelOffset(s.vertexCount, s.indexCount / 3);
    v.texWidth = s.texWidth;
    v.texHeight = s.texHeight;
  }
  return v;
}

uint32_t PatchCache::unpinnedSlots() const {
  std::lock_guard<std::mutex> lock(mu_);
  return uint32_t(slots_.size()) - pinned_;
}

CacheStats PatchCache::stats() const {
  std::lock_guard<std::mutex> lock(mu_);
  CacheStats st;
  st.capBytes = capBytes_;
  st.slotBytes = classBytes_[0];
  st.classes = uint32_t(classBytes_.size());
  st.slots = uint32_t(slots_.size());
  st.arenaBytes = arenaBytes_;
  st.physical = physical_;
  uint32_t freeWithContent = 0;
  for (const auto& list : free_)
    for (uint32_t i : list)
      if (slots_[i].id != UINT32_MAX) ++freeWithContent;
  st.real = physical_ - freeWithContent;
  st.pinned = pinned_;
  st.usedBytes = usedBytes_;
  st.secondChance = secondChance_;
  st.evictions = evictions_;
  st.urgentEvictions = urgentEvictions_;
  st.givenUp = givenUp_;
  return st;
}

int PatchCache::reserve(uint32_t id, Urgency urgency, uint64_t frame) {
  std::lock_guard<std::mutex> lock(mu_);
  if (hash_.count(id) || bad_.count(id) || id >= patchClass_.size()) return -1;
  const uint8_t k = patchClass_[id];
  auto& freeList = free_[k];
  int chosen = -1;
  if (!freeList.empty()) {
    chosen = int(freeList.front());
    takeOffFree(slots_[chosen]);
    evictContent(uint32_t(chosen));
  } else if (urgency == Urgency::UrgentUp || urgency == Urgency::UrgentDown) {
    // 3.3.2: flush the first found place holder that is only prefetched (not used by the cut).
    // A switch down may do so only while >= 3 of them remain, so memory never fills with
    // patches that are all in use.
    // The paper's one pool needs 3 such place holders before a switch down may flush one; a size
    // class has its own few place holders (3 in a small class), where that rule can never hold
    // once one of them is in use: a refinement then waited for ever while prefetched patches,
    // asked for again every frame, kept the others (the cut stuck at the coarsest, seen on a
    // flythrough). So the threshold scales with the class: 3, or half the class when smaller,
    // at least 1.
    const uint32_t n = classCount_[k], base = classFirst_[k];
    const uint32_t need = std::min<uint32_t>(3, std::max<uint32_t>(1, (n - 1) / 2));
    uint32_t prefetchedOnly = 0;
    int first = -1;
    for (uint32_t j = 0; j < n; ++j) {
      uint32_t i = base + (urgentScan_[k] + j) % n;
      const Slot& s = slots_[i];
      if (s.state == State::Ready && s.usage == 0) {
        ++prefetchedOnly;
        if (first < 0) first = int(i);
        if (urgency == Urgency::UrgentUp || prefetchedOnly >= need) break;
      }
    }
    if (first >= 0 && (urgency == Urgency::UrgentUp || prefetchedOnly >= need)) {
      chosen = first;
      urgentScan_[k] = (uint32_t(first) - base + 1) % n;
      evictContent(uint32_t(chosen));
      ++urgentEvictions_;
    }
  }
  if (chosen < 0) {
    ++givenUp_;
    return -1;
  }
  Slot& s = slots_[chosen];
  s.id = id;
  s.state = State::Loading;
  s.usage = 0;
  s.touched = frame;
  s.vertexCount = s.indexCount = 0;
  s.texWidth = s.texHeight = 0;
  hash_[id] = uint32_t(chosen);
  ++physical_;
  usedBytes_ += classBytes_[s.cls];
  return chosen;
}

void PatchCache::commit(int slot, uint32_t vertexCount, uint32_t indexCount, const PatchBound& bound, uint16_t texWidth,
                        uint16_t texHeight) {
  std::lock_guard<std::mutex> lock(mu_);
  Slot& s = slots_[slot];
  s.texWidth = texWidth;
  s.texHeight = texHeight;
  s.bound = bound;
  s.vertexCount = vertexCount;
  s.indexCount = indexCount;
  s.state = State::Ready;
}

void PatchCache::abort(int slot, bool bad) {
  std::lock_guard<std::mutex> lock(mu_);
  Slot& s = slots_[slot];
  if (bad && s.id != UINT32_MAX) bad_[s.id] = true;
  if (s.id != UINT32_MAX) {
    hash_.erase(s.id);
    --physical_;
    usedBytes_ -= classBytes_[s.cls];
  }
  s.id = UINT32_MAX;
  s.state = State::Absent;
  s.usage = 0;
  // An empty place holder goes to the FRONT: reuse it before flushing any second-chance content.
  s.freeIt = free_[s.cls].insert(free_[s.cls].begin(), uint32_t(slot));
  s.onFree = true;
}

}  // namespace mt::render
