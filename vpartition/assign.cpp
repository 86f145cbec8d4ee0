// Triangle -> cell assignment and the crossing V*i = Vi x V(i+1) (BMT section 4: "a rule that
// uniquely assigns a triangle t to a region of space, e.g. the one where the barycenter of t
// falls"), plus the sequence's serialized form and the ingest CellAssigner.
//
// Serialized form (little endian), kept by the store as blob "assigner":
//   "MTVPSEQ1" | u32 version | u8 kind | [version 2: u8 levelRatio] | u32 levelCount | levels |
//   u64 XXH64(all before)
// Version 1 is a sequence of level ratio 2 (every sequence before the ratio existed); a sequence
// of ratio 2 is still written as version 1, so stores of the default partition keep their bytes.
//   level: u8 type | f64 scale | u64 target | f64 origin[3] | u32 n[3] | u8 axis0 | u8 axis1 |
//          u32 seedCount | f32 seeds[3*seedCount]
// The seeds are stored bit-exactly, so a deserialized sequence assigns exactly like the original.
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cassert>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <sstream>
#include <unordered_map>

#include <xxhash.h>

#include "base/error.h"
#include "vpartition/level.h"
#include "vpartition/vpartition.h"

namespace mt {

namespace vp {

uint32_t PartitionLevel::cellCount() const {
  return type == Seeds ? uint32_t(seeds.size() / 3) : regularCellCount(*this);
}

uint32_t PartitionLevel::cellOf(const float c[3]) const {
  if (type != Seeds) return regularCellOf(*this, c);
  if (!(std::isfinite(c[0]) && std::isfinite(c[1]) && std::isfinite(c[2]))) return 0;
  return index.nearestCached(c);
}

void PartitionLevel::seedOf(uint32_t cell, float out[3]) const {
  if (type != Seeds) return regularSeedOf(*this, cell, out);
  assert(cell < seeds.size() / 3);
  std::memcpy(out, &seeds[3 * size_t(cell)], 12);
}

}  // namespace vp

PartitionKind parsePartitionKind(const std::string& text) {
  if (text == "irregular") return PartitionKind::Irregular;
  if (text == "regular") return PartitionKind::Regular;
  if (text == "regular2d") return PartitionKind::Regular2D;
  throw Error("--partition: expected irregular, regular or regular2d, got '" + text + "'");
}

const char* partitionKindName(PartitionKind kind) {
  switch (kind) {
    case PartitionKind::Irregular: return "irregular";
    case PartitionKind::Regular: return "regular";
    case PartitionKind::Regular2D: return "regular2d";
  }
  return "?";
}

uint32_t parsePatchTriangles(const std::string& text) {
  char* end = nullptr;
  errno = 0;
  unsigned long long v = text.empty() ? 0 : std::strtoull(text.c_str(), &end, 10);
  if (text.empty() || *end != '\0' || errno || text[0] == '-' || v < 16 || v > (1u << 24))
    throw Error("--patch-triangles: expected an integer in [16, 16777216], got '" + text + "'");
  return uint32_t(v);
}

PartitionSequence::PartitionSequence() = default;
PartitionSequence::~PartitionSequence() = default;
PartitionSequence::PartitionSequence(PartitionSequence&&) noexcept = default;
PartitionSequence& PartitionSequence::operator=(PartitionSequence&&) noexcept = default;

void checkLevelRatio(int64_t ratio, PartitionKind kind) {
  if (ratio < kMinLevelRatio || ratio > kMaxLevelRatio)
    throw Error("--level-ratio " + std::to_string(ratio) + ": out of range (accepted " + std::to_string(kMinLevelRatio) + " to " +
                std::to_string(kMaxLevelRatio) + "; default " + std::to_string(kDefaultLevelRatio) + ")");
  // The regular sequences' cell counts change by their geometry's ratios (8/3, 1, 3 in 3D).
  if (ratio != kDefaultLevelRatio && kind != PartitionKind::Irregular)
    throw Error("--level-ratio " + std::to_string(ratio) + ": the " + partitionKindName(kind) +
                " V-partition has its own level ratios; another ratio than 2 needs the irregular one");
}

PartitionSequence PartitionSequence::build(const CentroidSource& centroids,
                                           const VPartitionOptions& options) {
  checkLevelRatio(options.levelRatio, options.kind);  // before any pass over the input
  return options.kind == PartitionKind::Irregular ? buildIrregularSequence(centroids, options)
                                                  : buildRegularSequence(centroids, options);
}

void PartitionSequence::addLevel(std::unique_ptr<PartitionLevel> level) {
  assert(level);
  if (level->type == PartitionLevel::Seeds) level->finishSeeds();
  levels_.push_back(std::move(level));
}

uint32_t PartitionSequence::cellCount(uint32_t level) const {
  assert(level < levels_.size());
  return levels_[level]->cellCount();
}

uint32_t PartitionSequence::cellOf(uint32_t level, const float c[3]) const {
  assert(level < levels_.size());
  uint32_t id = levels_[level]->cellOf(c);
  assert(id < levels_[level]->cellCount());
  return id;
}

uint64_t PartitionSequence::crossKey(uint32_t level, const float c[3]) const {
  uint64_t hi = cellOf(level, c);
  // Past the coarsest level the next partition is the single root cell 0.
  uint64_t lo = level + 1 < levels_.size() ? cellOf(level + 1, c) : 0;
  return (hi << 32) | lo;
}

void PartitionSequence::seedOf(uint32_t level, uint32_t cell, float out[3]) const {
  assert(level < levels_.size());
  levels_[level]->seedOf(cell, out);
}

const std::vector<float>& PartitionSequence::seeds(uint32_t level) const {
  assert(level < levels_.size());
  return levels_[level]->seeds;
}

double PartitionSequence::levelScale(uint32_t level) const {
  assert(level < levels_.size());
  return levels_[level]->scale;
}

uint64_t PartitionSequence::memoryBytes() const {
  uint64_t bytes = 0;
  for (const auto& L : levels_) bytes += L->seeds.capacity() * sizeof(float) + L->index.bytes();
  return bytes;
}

void PartitionSequence::setLevelRatio(uint32_t ratio) {
  checkLevelRatio(ratio, kind_);
  levelRatio_ = ratio;
}

uint64_t PartitionSequence::levelTarget(uint32_t level) const {
  assert(level < levels_.size());
  return levels_[level]->target;
}

std::string PartitionSequence::describe() const {
  std::ostringstream s;
  s << partitionKindName(kind_) << " V-partition, " << levels_.size() << " levels";
  if (levelRatio_ != kDefaultLevelRatio) s << " (ratio " << levelRatio_ << ")";
  if (kind_ == PartitionKind::Irregular) {
    s << ", seeds";
    for (size_t l = 0; l < levels_.size(); ++l) s << (l ? "/" : " ") << levels_[l]->cellCount();
  } else if (!levels_.empty()) {
    s << ", finest spacing " << levels_[0]->scale;
  }
  return s.str();
}

namespace {

const char kMagic[8] = {'M', 'T', 'V', 'P', 'S', 'E', 'Q', '1'};
constexpr uint32_t kVersion = 1;              // level ratio 2
constexpr uint32_t kVersionWithRatio = 2;     // any other level ratio

template <class T> void put(std::string& out, const T& v) {
  out.append(reinterpret_cast<const char*>(&v), sizeof(T));
}

struct Reader {
  const std::string& in;
  size_t pos = 0;
  template <class T> T get() {
    T v;
    need(sizeof(T));
    std::memcpy(&v, in.data() + pos, sizeof(T));
    pos += sizeof(T);
    return v;
  }
  void need(size_t n) {
    if (in.size() - pos < n)
      throw Error("V-partition blob: truncated at byte " + std::to_string(pos));
  }
};

}  // namespace

std::string PartitionSequence::serialize() const {
  std::string out(kMagic, 8);
  const bool ratio = levelRatio_ != kDefaultLevelRatio;
  put(out, ratio ? kVersionWithRatio : kVersion);
  put(out, uint8_t(kind_));
  if (ratio) put(out, uint8_t(levelRatio_));
  put(out, uint32_t(levels_.size()));
  for (const auto& L : levels_) {
    put(out, uint8_t(L->type));
    put(out, L->scale);
    put(out, L->target);
    for (int a = 0; a < 3; ++a) put(out, L->origin[a]);
    for (int a = 0; a < 3; ++a) put(out, L->n[a]);
    put(out, L->axis0);
    put(out, L->axis1);
    put(out, uint32_t(L->seeds.size() / 3));
    out.append(reinterpret_cast<const char*>(L->seeds.data()), L->seeds.size() * sizeof(float));
  }
  put(out, uint64_t(XXH64(out.data(), out.size(), 0)));
  return out;
}

PartitionSequence PartitionSequence::deserialize(const std::string& bytes) {
  if (bytes.size() < 8 + 4 + 1 + 4 + 8 || std::memcmp(bytes.data(), kMagic, 8) != 0)
    throw Error("V-partition blob: bad magic (not a serialized PartitionSequence)");
  uint64_t stored;
  std::memcpy(&stored, bytes.data() + bytes.size() - 8, 8);
  if (XXH64(bytes.data(), bytes.size() - 8, 0) != stored)
    throw Error("V-partition blob: checksum mismatch (corrupt)");
  std::string body = bytes.substr(0, bytes.size() - 8);
  Reader r{body, 8};
  uint32_t version = r.get<uint32_t>();
  if (version != kVersion && version != kVersionWithRatio)
    throw Error("V-partition blob: unsupported version " + std::to_string(version));
  uint8_t kind = r.get<uint8_t>();
  if (kind > 2) throw Error("V-partition blob: bad kind " + std::to_string(kind));
  PartitionSequence seq;
  seq.kind_ = PartitionKind(kind);
  if (version == kVersionWithRatio) {
    uint8_t ratio = r.get<uint8_t>();
    // Written only for another ratio than 2, and only for irregular sequences.
    if (ratio == kDefaultLevelRatio || ratio < kMinLevelRatio || ratio > kMaxLevelRatio || seq.kind_ != PartitionKind::Irregular)
      throw Error("V-partition blob: bad level ratio " + std::to_string(ratio) + " for a " + partitionKindName(seq.kind_) +
                  " sequence");
    seq.levelRatio_ = ratio;
  }
  uint32_t levels = r.get<uint32_t>();
  for (uint32_t l = 0; l < levels; ++l) {
    auto L = std::make_unique<PartitionLevel>();
    uint8_t type = r.get<uint8_t>();
    if (type > PartitionLevel::Diamond)
      throw Error("V-partition blob: level " + std::to_string(l) + ": bad type");
    L->type = PartitionLevel::Type(type);
    L->scale = r.get<double>();
    L->target = r.get<uint64_t>();
    for (int a = 0; a < 3; ++a) L->origin[a] = r.get<double>();
    for (int a = 0; a < 3; ++a) L->n[a] = r.get<uint32_t>();
    L->axis0 = r.get<uint8_t>();
    L->axis1 = r.get<uint8_t>();
    uint32_t count = r.get<uint32_t>();
    if (!(L->scale > 0) || L->axis0 > 2 || L->axis1 > 2 || L->n[0] == 0 || L->n[1] == 0 ||
        L->n[2] == 0 || (L->type == PartitionLevel::Seeds) != (count > 0))
      throw Error("V-partition blob: level " + std::to_string(l) + ": bad header");
    r.need(size_t(count) * 12);
    L->seeds.resize(size_t(count) * 3);
    if (count) std::memcpy(L->seeds.data(), body.data() + r.pos, size_t(count) * 12);  // no null memcpy
    r.pos += size_t(count) * 12;
    seq.addLevel(std::move(L));
  }
  if (r.pos != body.size()) throw Error("V-partition blob: trailing bytes");
  return seq;
}

void VPartitionAssigner::prepare(const CentroidSource& centroids, uint64_t memoryBytes) {
  // A prepared-again assigner describes its new partition, not one it released.
  released_ = false;
  serialized_.clear();
  described_.clear();
  // One pass over the input: a stride sample (vp::sampleCentroids) that the irregular builder
  // and the patch balancing below run on in memory. Its size depends on the input only.
  const uint32_t P = options_.patchTriangles ? options_.patchTriangles : kDefaultPatchTriangles;
  const uint64_t sampleCount = std::min<uint64_t>(centroids.count(), vp::sampleLimit(centroids.count(), P));
  // Sizes to a hundredth of a MiB: whole MiB printed "8 MiB, more than the 8 MiB allowed".
  auto mib = [](uint64_t bytes) {
    char b[32];
    std::snprintf(b, sizeof b, "%.2f MiB", double(bytes) / double(1 << 20));
    return std::string(b);
  };
  auto tooBig = [&](uint64_t bytes, const char* what) {
    if (memoryBytes && bytes > memoryBytes)
      throw Error(std::string("V-partition: ") + what + " need " + mib(bytes) + ", more than the " + mib(memoryBytes) +
                      " allowed; raise --memory or --patch-triangles",
                  ErrorKind::Resource);
  };
  tooBig(sampleCount * 16, "the centroid sample would");
  vp::CentroidSample sample = vp::sampleCentroids(centroids, P);
  // The candidate tables only speed the lookups up (the same cells with or without them), so
  // their budget may follow the cap: a quarter of this share, since the partition stays resident
  // through the assignment pass beside that pass's own buffers (a billion triangles' tables want
  // ~190 MiB; at 512M with 160 MiB of tables the build's resident set reached 606 MiB).
  VPartitionOptions o = options_;
  if (memoryBytes) o.lookupTableBytes = std::min(o.lookupTableBytes, memoryBytes / 4);
  sequence_ = o.kind == PartitionKind::Irregular ? buildIrregularFromSample(sample, o) : PartitionSequence::build(centroids, o);
  mergeSlivers(sample);
  // The seeds must stay in core (BMT 4.2.2: "about one seed per thousand triangles"); refuse
  // rather than silently exceed the caller's share of --memory.
  tooBig(sequence_.stats().seedBytes + sample.bytes(), "seeds, grids and the centroid sample");
  buildKeyTable();
}

namespace {
inline uint64_t mixKey(uint64_t key) {
  key ^= key >> 31;
  key *= 0x9E3779B97F4A7C15ull;
  return key ^ (key >> 29);
}
}  // namespace

void VPartitionAssigner::buildKeyTable() {
  keyTable_.clear();
  slabList_.clear();
  std::unordered_map<uint64_t, int32_t> slabIndex;
  for (const auto& [key, s] : slabs_) {
    slabIndex[key] = int32_t(slabList_.size());
    slabList_.push_back(s);
  }
  std::sort(sampleKeys_.begin(), sampleKeys_.end());
  sampleKeys_.erase(std::unique(sampleKeys_.begin(), sampleKeys_.end()), sampleKeys_.end());
  if (sampleKeys_.empty()) return;
  uint64_t cap = 16;
  while (cap < 2 * sampleKeys_.size()) cap <<= 1;
  keyTable_.assign(cap, KeyEntry{});
  keyMask_ = cap - 1;
  for (uint64_t raw : sampleKeys_) {
    KeyEntry e;
    e.raw = raw;
    e.final = joinedKey(raw);
    auto it = slabIndex.find(e.final);
    e.slabs = it == slabIndex.end() ? -1 : it->second;
    e.used = 1;
    uint64_t h = mixKey(raw) & keyMask_;
    while (keyTable_[h].used) h = (h + 1) & keyMask_;
    keyTable_[h] = e;
  }
  std::vector<uint64_t>().swap(sampleKeys_);
}

// Balancing the patches (the V*0 cells). Crossing V0 with V1 gives uneven pieces: where a V1
// border runs close to a V0 border it leaves slivers of a handful of triangles, and a V0 cell no
// V1 border crosses stays whole (~kCrossPerCell patches' worth). The level loop reads only the V1
// half of a patch's key (its region), so the V0 half may be refined freely:
//   * a piece with fewer than a quarter of the target joins the largest piece of its V0 cell
//     (its V1 half changes: the V1 region border follows the V0 border there); a V0 cell that is
//     tiny as a whole joins the piece of its V1 region with the nearest V0 seed;
//   * a piece with more than 1.6x the target is cut into k = round(n / target) slabs along the
//     longest axis of its bounding box, at quantiles (slab index in the key's top 8 bits).
// Two passes over the centroid sample (piece counts and boxes; histograms of the pieces to cut),
// not over the input; memory is per piece, not per triangle.
namespace {
constexpr int kSlabShift = 56;  // V0 cell ids stay below 2^24 (checked); slab index above them
constexpr int kBins = 256;      // histogram bins along a piece's cut axis

// A V*0 piece as the sample sees it: sampled triangles and the box of their centroids.
struct Piece {
  uint32_t count = 0;
  float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
};
using PieceList = std::vector<std::pair<uint64_t, Piece>>;  // ascending key
using KeyMap = std::unordered_map<uint64_t, uint64_t>;

PieceList countPieces(const vp::CentroidSample& sample, const std::vector<uint64_t>& crossKeys) {
  std::unordered_map<uint64_t, Piece> pieces;
  for (size_t i = 0; i < crossKeys.size(); ++i) {
    const float* c = &sample.xyza[4 * i];
    Piece& p = pieces[crossKeys[i]];
    ++p.count;
    for (int a = 0; a < 3; ++a) {
      p.lo[a] = std::min(p.lo[a], c[a]);
      p.hi[a] = std::max(p.hi[a], c[a]);
    }
  }
  PieceList sorted(pieces.begin(), pieces.end());
  std::sort(sorted.begin(), sorted.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  return sorted;
}

// Piece `from` joins piece `into` (which is not itself joined: joins are one step).
void joinPiece(PieceList& sorted, size_t from, size_t into, KeyMap& remap) {
  assert(from != into && !remap.count(sorted[into].first));
  remap[sorted[from].first] = sorted[into].first;
  Piece& big = sorted[into].second;
  big.count += sorted[from].second.count;
  for (int a = 0; a < 3; ++a) {
    big.lo[a] = std::min(big.lo[a], sorted[from].second.lo[a]);
    big.hi[a] = std::max(big.hi[a], sorted[from].second.hi[a]);
  }
}

// Step 1: slivers join the largest piece of their V0 cell. Returns the small pieces that are
// their V0 cell's largest; `largest` (sampled inputs only) gets each V0 cell's largest piece.
std::vector<size_t> joinSlivers(PieceList& sorted, double small, KeyMap& remap,
                                std::unordered_map<uint32_t, uint64_t>* largestOf) {
  std::vector<size_t> lonely;
  for (size_t i = 0; i < sorted.size();) {  // grouped by V0 cell (the high half)
    const uint32_t cell = PartitionSequence::crossHigh(sorted[i].first);
    size_t j = i, largest = i;
    while (j < sorted.size() && PartitionSequence::crossHigh(sorted[j].first) == cell) {
      if (sorted[j].second.count > sorted[largest].second.count) largest = j;
      ++j;
    }
    for (size_t k = i; k < j; ++k)
      if (k != largest && sorted[k].second.count < small) joinPiece(sorted, k, largest, remap);
    if (sorted[largest].second.count < small) lonely.push_back(largest);
    if (largestOf) (*largestOf)[cell] = sorted[largest].first;
    i = j;
  }
  return lonely;
}

// Step 2: a whole V0 cell that is still tiny (debris, a thin strip) joins the piece of the same
// V1 region whose V0 seed is nearest, so the region is unchanged.
void joinLonelyCells(PieceList& sorted, const std::vector<size_t>& lonely, double small,
                     const PartitionSequence& sequence, KeyMap& remap) {
  std::unordered_map<uint32_t, std::vector<size_t>> byRegion;
  for (size_t k = 0; k < sorted.size(); ++k)
    if (!remap.count(sorted[k].first)) byRegion[PartitionSequence::crossLow(sorted[k].first)].push_back(k);
  for (size_t k : lonely) {
    float a[3], b[3];
    sequence.seedOf(0, PartitionSequence::crossHigh(sorted[k].first), a);
    size_t best = k;
    double bestD = INFINITY;
    for (size_t o : byRegion[PartitionSequence::crossLow(sorted[k].first)]) {
      if (o == k || remap.count(sorted[o].first) || sorted[o].second.count < small) continue;
      sequence.seedOf(0, PartitionSequence::crossHigh(sorted[o].first), b);
      double d = double(a[0] - b[0]) * (a[0] - b[0]) + double(a[1] - b[1]) * (a[1] - b[1]) + double(a[2] - b[2]) * (a[2] - b[2]);
      if (d < bestD) bestD = d, best = o;
    }
    if (best != k) joinPiece(sorted, k, best, remap);
  }
}

// A piece to cut: its longest axis and the histogram of its centroids along it.
// A piece to cut, and the histogram bin of each of its sampled centroids (one byte each, not a
// histogram: at a billion triangles nearly every piece is cut, from ~26 samples each, and 235 k
// histograms of kBins counters took 240 MiB, over the ingest's memory cap).
struct Cut {
  int axis;
  float lo, width;
  std::vector<uint8_t> bins;
};
static_assert(kBins <= 256, "a bin index must fit Cut::bins' byte");

// Step 3's candidates: the unjoined pieces above the slab limit, with an empty histogram.
std::unordered_map<uint64_t, Cut> oversizedPieces(const PieceList& sorted, const KeyMap& remap, uint32_t target,
                                                  double w, bool sampled) {
  std::unordered_map<uint64_t, Cut> cuts;
  for (const auto& [key, p] : sorted) {
    // A sampled count is off by ~1/sqrt(count): cut earlier, so that no piece ends up above
    // 2x the target (measured on the 53 M scan: max 2.14x without this margin).
    const double limit = sampled ? target * 1.6 / (1 + 3 / std::sqrt(std::max(1.0, double(p.count)))) : target * 8 / 5;
    if (remap.count(key) || p.count * w <= limit) continue;
    int axis = 0;
    for (int a = 1; a < 3; ++a)
      if (p.hi[a] - p.lo[a] > p.hi[axis] - p.lo[axis]) axis = a;
    if (!(p.hi[axis] > p.lo[axis])) continue;
    cuts[key] = {axis, p.lo[axis], (p.hi[axis] - p.lo[axis]) / kBins, {}};
  }
  return cuts;
}

// The second pass over the sample: each cut piece's bins (joined keys count as their piece).
void fillHistograms(std::unordered_map<uint64_t, Cut>& cuts, const vp::CentroidSample& sample,
                    const std::vector<uint64_t>& crossKeys, const KeyMap& remap) {
  for (size_t i = 0; i < crossKeys.size(); ++i) {
    const float* c = &sample.xyza[4 * i];
    uint64_t key = crossKeys[i];
    auto r = remap.find(key);
    if (r != remap.end()) key = r->second;
    auto it = cuts.find(key);
    if (it == cuts.end()) continue;
    Cut& cut = it->second;
    int bin = int(std::clamp((c[cut.axis] - cut.lo) / cut.width, 0.0f, float(kBins - 1)));
    cut.bins.push_back(uint8_t(bin));
  }
}

// The slab walls of a cut into `slabs` pieces, at quantiles of its histogram (ascending, at
// most slabs - 1 of them).
std::vector<float> slabBounds(const Cut& cut, uint32_t slabs, uint64_t total) {
  uint32_t histogram[kBins] = {};
  for (uint8_t b : cut.bins) ++histogram[b];
  std::vector<float> bounds;
  uint64_t run = 0;
  for (int b = 0; b < kBins && bounds.size() + 1 < slabs; ++b) {
    run += histogram[b];
    if (run * slabs >= total * (bounds.size() + 1)) bounds.push_back(cut.lo + cut.width * float(b + 1));
  }
  assert(bounds.size() < slabs);
  return bounds;
}

}  // namespace

void VPartitionAssigner::mergeSlivers(const vp::CentroidSample& sample) {
  // Counts below are of sampled triangles; thresholds in input triangles are divided by w.
  const double w = sample.weight();
  remap_.clear();
  slabs_.clear();
  seen_.clear();
  largest_.clear();
  sampleKeys_.clear();
  sampled_ = sample.stride > 1;
  if (sequence_.levels() < 2 || sequence_.cellCount(0) >= (1u << 24)) return;
  // The V*0 key of every sampled centroid, once (the lookups are independent: in parallel); both
  // passes below read them in sample order.
  const size_t ns = size_t(sample.count());
  std::vector<uint64_t> crossKeys(ns);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, ns, 4096), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i < r.end(); ++i) crossKeys[i] = sequence_.crossKey(0, &sample.xyza[4 * i]);
  });
  PieceList sorted = countPieces(sample, crossKeys);
  for (const auto& [key, piece] : sorted) sampleKeys_.push_back(key);
  const uint32_t target = options_.patchTriangles ? options_.patchTriangles : kDefaultPatchTriangles;
  const double small = std::max(1.0, target / 4.0 / w);
  std::vector<size_t> lonely = joinSlivers(sorted, small, remap_, sampled_ ? &largest_ : nullptr);
  joinLonelyCells(sorted, lonely, small, sequence_, remap_);
  if (sampled_) {
    // Final keys (joins are one step: a piece joins a piece that is not itself joined).
    auto final = [&](uint64_t key) {
      auto r = remap_.find(key);
      return r == remap_.end() ? key : r->second;
    };
    for (auto& [cell, key] : largest_) key = final(key);
    for (const auto& [key, piece] : sorted) seen_[key] = final(key);
  }
  // 3. Oversized pieces are cut into slabs of about `target` triangles along their longest axis,
  //    at quantiles of a histogram gathered in one more pass.
  std::unordered_map<uint64_t, Cut> cuts = oversizedPieces(sorted, remap_, target, w, sampled_);
  if (cuts.empty()) return;
  fillHistograms(cuts, sample, crossKeys, remap_);
  for (auto& [key, cut] : cuts) {
    const uint64_t total = cut.bins.size();
    uint32_t slabs = uint32_t(std::clamp<double>(std::floor((double(total) * w + target / 2) / target), 1, 255));
    if (sampled_) slabs = std::max<uint32_t>(slabs, 2);
    if (slabs < 2) continue;
    Slabs s;
    s.axis = cut.axis;
    s.bounds = slabBounds(cut, slabs, total);
    slabs_[key] = std::move(s);
  }
}

uint64_t VPartitionAssigner::joinedKey(uint64_t key) const {
  if (sampled_) {
    auto seen = seen_.find(key);
    if (seen != seen_.end()) {
      key = seen->second;
    } else if (auto big = largest_.find(PartitionSequence::crossHigh(key)); big != largest_.end()) {
      key = big->second;  // a sliver the sample missed
    }
  } else if (auto it = remap_.find(key); it != remap_.end()) {
    key = it->second;
  }
  return key;
}

uint64_t VPartitionAssigner::cellKey(const float c[3]) const {
  assert(!released_);
  const uint64_t raw = sequence_.crossKey(0, c);
  uint64_t key = raw;
  const Slabs* slabs = nullptr;
  const KeyEntry* entry = nullptr;
  if (!keyTable_.empty()) {
    for (uint64_t h = mixKey(raw) & keyMask_; keyTable_[h].used; h = (h + 1) & keyMask_)
      if (keyTable_[h].raw == raw) {
        entry = &keyTable_[h];
        break;
      }
  }
  if (entry) {
    key = entry->final;
    if (entry->slabs >= 0) slabs = &slabList_[size_t(entry->slabs)];
  } else {
    key = joinedKey(raw);
    auto s = slabs_.find(key);
    if (s != slabs_.end()) slabs = &s->second;
  }
  if (!slabs) return key;
  const std::vector<float>& bounds = slabs->bounds;
  uint64_t slab = uint64_t(std::upper_bound(bounds.begin(), bounds.end(), c[slabs->axis]) - bounds.begin());
  return key | slab << kSlabShift;
}

std::string VPartitionAssigner::describe() const {
  if (released_) return described_;
  return sequence_.describe() + "; patches balanced: " + std::to_string(remap_.size()) + " V*0 slivers merged, " +
         std::to_string(slabs_.size()) + " large cells cut into slabs";
}

void VPartitionAssigner::releaseLookups() {
  if (released_) return;
  serialized_ = sequence_.serialize();
  described_ = describe();
  released_ = true;
  // Swapped with empty containers: clear() would keep the buckets and capacities.
  sequence_ = PartitionSequence();
  std::unordered_map<uint64_t, uint64_t>().swap(remap_);
  std::unordered_map<uint64_t, Slabs>().swap(slabs_);
  std::unordered_map<uint64_t, uint64_t>().swap(seen_);
  std::unordered_map<uint32_t, uint64_t>().swap(largest_);
  std::vector<uint64_t>().swap(sampleKeys_);
  std::vector<KeyEntry>().swap(keyTable_);
  std::vector<Slabs>().swap(slabList_);
  keyMask_ = 0;
}

std::unique_ptr<CellAssigner> makeVPartitionAssigner(const VPartitionOptions& options) {
  return std::make_unique<VPartitionAssigner>(options);
}

}  // namespace mt
