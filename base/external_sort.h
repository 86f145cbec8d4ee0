// External sorts of plain-old-data records within a memory budget, for ingest's out-of-core passes.
// Records are collected in a buffer of at most the budget, each full buffer is sorted and written
// as a run, and the runs are merged when read back; when everything fits, nothing touches the disk.
//
//   ExternalSorter<R, Less>    any comparator; runs sorted with tbb::parallel_sort. Equal records
//                              keep no particular order, so callers make keys total.
//   StableKeySorter<R, KeyFn>  by a 64-bit key, stable: equal keys keep the order they were
//                              added in. Runs are radix sorted (no comparisons), which is what
//                              makes the Morton sort of ingest cheap (ties: face order for free).
//   KeyGroupSorter<R, Less>    records grouped by a 64-bit key, read back one whole group at a
//                              time (a patch); within a group, in Less order. Runs are counting
//                              sorted by key, and the merge moves whole groups, not records.
// Merges go through a loser tree: log2(runs) comparisons per record, no copies inside the tree.
#pragma once

#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>
#include <tbb/task_arena.h>
#include <tbb/task_group.h>

#include <algorithm>
#include <cstdint>
#include <functional>
#include <memory>
#include <queue>
#include <string>
#include <vector>

#include "base/process.h"
#include "base/temp_file.h"

namespace mt {

// Sequential stable LSD radix sort on bits [0, bits) of key(record), between a and tmp; returns
// the one holding the result. Digits of up to 11 bits, as few passes as that allows (the data is
// meant to be in cache, where a pass costs more than a 2048-entry histogram); one read counts
// every digit; a digit that is the same for every record is skipped.
template <class T, class KeyFn>
T* lsdRadixSort(T* a, T* tmp, size_t n, const KeyFn& key, unsigned bits) {
  constexpr unsigned kMaxDigit = 11, kMaxPasses = 6;
  if (n < 2 || bits == 0) return a;
  bits = std::min(bits, 64u);
  const unsigned passes = (bits + kMaxDigit - 1) / kMaxDigit;
  const unsigned digit = (bits + passes - 1) / passes;
  const size_t buckets = size_t(1) << digit;
  const uint64_t mask = buckets - 1;
  uint32_t hist[kMaxPasses][size_t(1) << kMaxDigit];
  for (unsigned p = 0; p < passes; ++p) std::fill(hist[p], hist[p] + buckets, 0);
  for (size_t i = 0; i < n; ++i) {
    const uint64_t k = key(a[i]);
    for (unsigned p = 0; p < passes; ++p) ++hist[p][(k >> (p * digit)) & mask];
  }
  for (unsigned p = 0; p < passes; ++p) {
    uint32_t* h = hist[p];
    bool trivial = false;
    uint32_t run = 0;
    for (size_t d = 0; d < buckets; ++d) {
      trivial |= h[d] == n;
      uint32_t c = h[d];
      h[d] = run;
      run += c;
    }
    if (trivial) continue;
    const unsigned shift = p * digit;
    for (size_t i = 0; i < n; ++i) tmp[h[(key(a[i]) >> shift) & mask]++] = a[i];
    std::swap(a, tmp);
  }
  return a;
}

// Stable radix sort of n records by key(record) (a uint64_t; only its low keyBits bits are looked
// at). Sorts between a and tmp (both n records) and returns the one holding the result. Small
// inputs go through lsdRadixSort. Large ones are split first on the 11 highest bits in which keys
// differ (most significant digit first, in parallel slices that scatter into their own offsets,
// which keeps it stable), and each of the 2048 buckets, small enough to stay in cache, is then
// LSD-sorted on the bits below, in parallel over buckets: every record crosses main memory about
// twice instead of once per digit.
template <class T, class KeyFn>
T* radixSort(T* a, T* tmp, size_t n, const KeyFn& key, unsigned keyBits = 64) {
  if (n < 2 || keyBits == 0) return a;
  if (n >= (size_t(1) << 32)) {  // lsdRadixSort counts in 32 bits
    std::stable_sort(a, a + n, [&](const T& x, const T& y) { return key(x) < key(y); });
    return a;
  }
  const uint64_t keyMask = keyBits >= 64 ? ~uint64_t(0) : (uint64_t(1) << keyBits) - 1;
  if (n < (size_t(1) << 16)) return lsdRadixSort(a, tmp, n, [&](const T& r) { return key(r) & keyMask; }, keyBits);
  constexpr unsigned kTop = 11;
  constexpr size_t kBuckets = size_t(1) << kTop;
  const size_t slices = size_t(std::clamp(tbb::this_task_arena::max_concurrency(), 1, 16));
  const size_t per = (n + slices - 1) / slices;
  auto range = [&](size_t s) { return std::pair<size_t, size_t>(std::min(n, s * per), std::min(n, (s + 1) * per)); };
  // The highest bit in which any two keys differ.
  const uint64_t first = key(a[0]) & keyMask;
  std::vector<uint64_t> diff(slices, 0);
  tbb::parallel_for(size_t(0), slices, [&](size_t s) {
    auto [lo, hi] = range(s);
    uint64_t d = 0;
    for (size_t i = lo; i < hi; ++i) d |= (key(a[i]) & keyMask) ^ first;
    diff[s] = d;
  });
  uint64_t anyDiff = 0;
  for (uint64_t d : diff) anyDiff |= d;
  if (anyDiff == 0) return a;
  unsigned high = 63;
  while (!(anyDiff >> high & 1)) --high;
  const unsigned low = high + 1 > kTop ? high + 1 - kTop : 0;  // the split digit is bits [low, high]
  std::vector<size_t> hist(slices * kBuckets, 0);
  tbb::parallel_for(size_t(0), slices, [&](size_t s) {
    auto [lo, hi] = range(s);
    size_t* h = &hist[s * kBuckets];
    for (size_t i = lo; i < hi; ++i) ++h[((key(a[i]) & keyMask) >> low) & (kBuckets - 1)];
  });
  std::vector<size_t> start(kBuckets + 1, 0);
  {
    size_t run = 0;
    for (size_t d = 0; d < kBuckets; ++d) {
      start[d] = run;
      for (size_t s = 0; s < slices; ++s) {
        size_t c = hist[s * kBuckets + d];
        hist[s * kBuckets + d] = run;
        run += c;
      }
    }
    start[kBuckets] = run;
  }
  tbb::parallel_for(size_t(0), slices, [&](size_t s) {
    auto [lo, hi] = range(s);
    size_t* off = &hist[s * kBuckets];
    for (size_t i = lo; i < hi; ++i) tmp[off[((key(a[i]) & keyMask) >> low) & (kBuckets - 1)]++] = a[i];
  });
  if (low > 0) {
    const uint64_t lowMask = (uint64_t(1) << low) - 1;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, kBuckets, 16), [&](const tbb::blocked_range<size_t>& r) {
      for (size_t d = r.begin(); d < r.end(); ++d) {
        const size_t b = start[d], m = start[d + 1] - b;
        if (m < 2) continue;
        T* sorted = lsdRadixSort(tmp + b, a + b, m, [&](const T& x) { return key(x) & lowMask; }, low);
        if (sorted != tmp + b) std::copy(sorted, sorted + m, tmp + b);
      }
    });
  }
  return tmp;
}

// A loser tree over k sources: better(i, j) says whether source i's head goes before source j's
// (a strict total order, exhausted sources last). top() is the winner; after the caller advances
// it, replay() restores the tree in log2(k) comparisons.
template <class Better>
class LoserTree {
 public:
  LoserTree() = default;
  void init(size_t k, Better better) {
    k_ = k;
    better_ = better;
    tree_.assign(std::max<size_t>(1, k), 0);
    if (k <= 1) return;
    std::vector<size_t> win(2 * k);
    for (size_t i = 0; i < k; ++i) win[k + i] = i;
    for (size_t p = k - 1; p >= 1; --p) {
      size_t a = win[2 * p], b = win[2 * p + 1];
      if (better_(a, b)) {
        win[p] = a;
        tree_[p] = b;
      } else {
        win[p] = b;
        tree_[p] = a;
      }
    }
    tree_[0] = win[1];
  }
  size_t top() const { return tree_[0]; }
  void replay() {
    if (k_ <= 1) return;
    size_t w = tree_[0];
    for (size_t p = (w + k_) / 2; p >= 1; p /= 2)
      if (better_(tree_[p], w)) std::swap(tree_[p], w);
    tree_[0] = w;
  }

 private:
  size_t k_ = 0;
  Better better_{};
  std::vector<size_t> tree_;
};

// Heads of k sorted runs on disk, merged in Less order (ties: lower run first, so a sorter whose
// runs are in input order is stable).
template <class Record, class Less>
class RunMerger {
 public:
  // Merges records [begin[i], end[i]) of each run i (whole runs when begin is empty).
  void open(const std::vector<std::string>& runs, size_t bufferBytes, Less less, const std::vector<uint64_t>& begin = {},
            const std::vector<uint64_t>& end = {}) {
    less_ = less;
    readers_.clear();
    heads_.assign(runs.size(), Record{});
    done_.assign(runs.size(), 0);
    for (size_t i = 0; i < runs.size(); ++i) {
      if (begin.empty())
        readers_.push_back(std::make_unique<TempReader>(runs[i], bufferBytes));
      else
        readers_.push_back(std::make_unique<TempReader>(runs[i], bufferBytes, begin[i] * sizeof(Record),
                                                        (end[i] - begin[i]) * sizeof(Record)));
      readers_[i]->consumeAsRead();  // one pass: the disk is given back as the merge goes
      done_[i] = !readers_[i]->get(heads_[i]);
    }
    tree_.init(runs.size(), Better{this});
  }
  bool next(Record& out) {
    if (readers_.empty()) return false;
    const size_t w = tree_.top();
    if (done_[w]) return false;
    out = heads_[w];
    done_[w] = !readers_[w]->get(heads_[w]);
    tree_.replay();
    return true;
  }
  void close() {
    readers_.clear();
    heads_.clear();
    done_.clear();
  }

 private:
  struct Better {
    RunMerger* m = nullptr;
    bool operator()(size_t i, size_t j) const {
      if (m->done_[i] != m->done_[j]) return !m->done_[i];
      if (m->done_[i]) return i < j;
      if (m->less_(m->heads_[i], m->heads_[j])) return true;
      if (m->less_(m->heads_[j], m->heads_[i])) return false;
      return i < j;
    }
  };
  Less less_{};
  std::vector<std::unique_ptr<TempReader>> readers_;
  std::vector<Record> heads_;
  std::vector<uint8_t> done_;
  LoserTree<Better> tree_;
};

// ---- Bounded fan-in
// A merge reads every run at once, each through a read buffer of at least kMinReadBuffer and one
// or two file descriptors (the reader's, and the one that gives the read part back): with the runs
// a small budget makes of a large input it passed both the budget and the process's descriptor
// limit (a billion triangles at --memory 256M: ~8600 pair runs of 8 MiB, "Too many open files").
// So a sorter with more runs than its fan-in first merges consecutive runs into longer ones, until
// few enough are left (reduceRuns): the same order (ties go to the lower run, and a merged run
// takes the place of the consecutive runs it holds), at the cost of rewriting the runs merged.
// The fan-in is at most maxMergeFanIn(): 128 when the process may hold only ~1024 descriptors,
// up to 1024 when it may hold more (openFileLimit(): eight per run left for two sorters merging at
// once, each run's two descriptors, and everything else). The billion-triangle ingest's Morton sort
// makes 268 runs: at 128 its finish() and mergeInParts rewrote them (and the assign stage its
// groups'), merged at once they are read once: that ingest took 422.6 s against 467.6 s
// (docs/patchstore.md).
inline size_t maxMergeFanIn() {
  const uint64_t limit = openFileLimit();
  return std::clamp<size_t>(size_t(limit > 256 ? (limit - 256) / 8 : 0), 128, 1024);
}
// The fan-in `bufferBytes` of read buffers allow: each run's reader and the merged run's writer
// get bufferBytes / (fanIn + 1), at least kMinReadBuffer (the writer at least 64 KiB, which
// matters only for budgets of a few hundred KiB).
inline size_t mergeFanIn(uint64_t bufferBytes) {
  const uint64_t buffers = bufferBytes / kMinReadBuffer;
  return std::clamp<size_t>(size_t(buffers > 1 ? buffers - 1 : 0), 2, maxMergeFanIn());
}

// Merges runs[first, last) into one new run at `path` (readers and writer sharing bufferBytes),
// calling seen(record, indexInNewRun) for each record, and removes the merged files.
template <class Record, class Less, class Seen>
void mergeRunsInto(const std::vector<std::string>& runs, size_t first, size_t last, const std::string& path,
                   uint64_t bufferBytes, Less less, Seen&& seen) {
  const std::vector<std::string> group(runs.begin() + first, runs.begin() + last);
  const size_t share = std::max<size_t>(kMinReadBuffer, size_t(bufferBytes / (group.size() + 1)));
  RunMerger<Record, Less> merger;
  merger.open(group, share, less);
  TempWriter writer(path, share);
  Record r;
  uint64_t n = 0;
  while (merger.next(r)) {
    seen(r, n++);
    writer.put(r);
  }
  writer.close();
  merger.close();
  for (const std::string& old : group) std::remove(old.c_str());
}

// Merges consecutive runs until at most `fanIn` are left, rewriting as few as it can: while more
// than fanIn^2 are left, every run (in groups of fanIn); then only the first groups, just enough
// of them (a last smaller one) to bring the count to fanIn, the later runs kept as they are (at
// fanIn + 1 runs, two are merged, not all). merge(first, last, path, outRun) writes
// runs[first, last) as one run at `path`; keptRun(outRun, oldRun) is called for each run carried
// over. The new runs are named prefix.mergeN (`made` counts them). If a merge fails, `runs` still
// names every file left, so the caller's release() removes them. onPass() runs after each pass.
template <class Merge, class KeptRun, class OnPass>
void reduceRuns(std::vector<std::string>& runs, size_t fanIn, const std::string& prefix, size_t& made, Merge&& merge,
                KeptRun&& keptRun, OnPass&& onPass) {
  fanIn = std::max<size_t>(fanIn, 2);
  while (runs.size() > fanIn) {
    const size_t n = runs.size();
    // Groups of fanIn from the start: all of them, or the fewest that remove n - fanIn runs (each
    // group of g runs removes g - 1), the last one cut to what is still to remove.
    size_t mergeRuns = n;
    if (n <= fanIn * fanIn) {
      const size_t remove = n - fanIn, groups = (remove + fanIn - 2) / (fanIn - 1);
      mergeRuns = remove + groups;
    }
    std::vector<std::string> next;
    try {
      for (size_t first = 0; first < n;) {
        const size_t out = next.size();
        const size_t last = first < mergeRuns ? std::min(mergeRuns, first + fanIn) : first + 1;
        if (last - first == 1) {
          keptRun(out, first);
          next.push_back(runs[first]);
        } else {
          next.push_back(prefix + ".merge" + std::to_string(made++));
          merge(first, last, next.back(), out);
        }
        first = last;
      }
    } catch (...) {
      runs.insert(runs.end(), next.begin(), next.end());
      throw;
    }
    runs.swap(next);
    onPass();
  }
}

// The input side of a sorter that writes every full buffer as a run (ExternalSorter,
// StableKeySorter): records are buffered up to `capacity`; a full buffer goes to the sorter's
// writeRun (which must clear it) in the caller's thread or, with `background`, in a TBB task
// while the next buffer fills, one spill at a time (the budget then holds two buffers), so a
// producer running in a pipeline is not held up for the length of a spill.
template <class Record>
class RunBuffer {
 public:
  using WriteRun = std::function<void(std::vector<Record>&)>;
  RunBuffer(size_t capacity, bool background, WriteRun writeRun)
      : capacity_(capacity), background_(background), writeRun_(std::move(writeRun)) {}
  ~RunBuffer() { release(); }
  RunBuffer(const RunBuffer&) = delete;
  RunBuffer& operator=(const RunBuffer&) = delete;

  void add(const Record& r) {
    // Reserve the whole buffer at once: untouched pages cost no RSS, while growth by doubling
    // would briefly hold 1.5x the budget.
    if (buffer_.capacity() < capacity_) buffer_.reserve(capacity_);
    if (buffer_.size() == capacity_) spill();
    buffer_.push_back(r);
    ++count_;
  }
  void addBatch(const Record* r, size_t n) {
    if (buffer_.capacity() < capacity_) buffer_.reserve(capacity_);
    while (n > 0) {
      if (buffer_.size() == capacity_) spill();
      size_t take = std::min(n, capacity_ - buffer_.size());
      buffer_.insert(buffer_.end(), r, r + take);
      r += take;
      n -= take;
      count_ += take;
    }
  }
  uint64_t count() const { return count_; }
  size_t capacity() const { return capacity_; }
  // The records not spilled: all of them when spilled() is false (call wait() first).
  std::vector<Record>& records() { return buffer_; }
  // Waits for the spill in flight; rethrows its error.
  void wait() { task_.wait(); }
  // Ends input of a sorter that has spilled: the rest becomes the last run; buffers freed.
  void spillRest() {
    if (!buffer_.empty()) spill();
    task_.wait();
    std::vector<Record>().swap(buffer_);
    std::vector<Record>().swap(spilling_);
  }
  void release() {
    try {
      task_.wait();
    } catch (...) {  // already reported by wait() or spillRest(), or the sorter is being abandoned
    }
    std::vector<Record>().swap(buffer_);
    std::vector<Record>().swap(spilling_);
  }

 private:
  void spill() {
    if (!background_) {
      writeRun_(buffer_);
      return;
    }
    task_.wait();  // one spill at a time (rethrows its error)
    std::swap(buffer_, spilling_);
    buffer_.clear();
    if (buffer_.capacity() < capacity_) buffer_.reserve(capacity_);
    task_.run([this] { writeRun_(spilling_); });
  }

  size_t capacity_;
  bool background_;
  WriteRun writeRun_;
  std::vector<Record> buffer_, spilling_;
  uint64_t count_ = 0;
  tbb::task_group task_;
};

template <class Record, class Less>
class ExternalSorter {
 public:
  // background: see RunBuffer (measured on the chunked ingest path, ingest.cpp).
  ExternalSorter(std::string tempPrefix, uint64_t budgetBytes, Less less = Less(), bool background = false)
      : prefix_(std::move(tempPrefix)), less_(less),
        budgetBytes_(budgetBytes),
        input_(std::max<size_t>(1024, size_t(budgetBytes / ((background ? 2 : 1) * sizeof(Record)))), background,
               [this](std::vector<Record>& records) { writeRun(records); }) {}
  ~ExternalSorter() { release(); }
  ExternalSorter(const ExternalSorter&) = delete;
  ExternalSorter& operator=(const ExternalSorter&) = delete;

  void release() {
    input_.release();
    merger_.close();
    for (auto& path : runs_) std::remove(path.c_str());
    runs_.clear();
    memoryPos_ = 0;
  }

  void add(const Record& r) { input_.add(r); }
  uint64_t count() const { return input_.count(); }

  // Ends input; afterwards next() yields records in order. Equal records keep no particular
  // order, so callers make keys total when the result must be deterministic.
  void finish() {
    input_.wait();
    if (runs_.empty()) {
      tbb::parallel_sort(input_.records().begin(), input_.records().end(), less_);
      memoryPos_ = 0;
      return;
    }
    input_.spillRest();
    reduceRuns(
        runs_, mergeFanIn(budgetBytes_), prefix_, merged_,
        [&](size_t first, size_t last, const std::string& path, size_t) {
          mergeRunsInto<Record>(runs_, first, last, path, budgetBytes_, less_, [](const Record&, uint64_t) {});
        },
        [](size_t, size_t) {}, [] {});
    // Each run gets an equal share of the budget as its read buffer.
    size_t perRun = std::max<size_t>(kMinReadBuffer, budgetBytes_ / (runs_.size() + 1));
    merger_.open(runs_, perRun, less_);
  }

  // Once it returns false the sorter has released its memory and run files, so the next pass
  // gets the budget (and the disk) back before the sorter object goes out of scope.
  bool next(Record& out) {
    if (runs_.empty()) {
      if (memoryPos_ >= input_.records().size()) {
        release();
        return false;
      }
      out = input_.records()[memoryPos_++];
      return true;
    }
    if (!merger_.next(out)) {
      release();
      return false;
    }
    return true;
  }

 private:
  // Sorts `records` and writes them as the next run (clears it).
  void writeRun(std::vector<Record>& records) {
    tbb::parallel_sort(records.begin(), records.end(), less_);
    std::string path = prefix_ + ".run" + std::to_string(runs_.size());
    TempWriter writer(path, 4 << 20);
    writer.write(records.data(), records.size() * sizeof(Record));
    writer.close();
    runs_.push_back(path);
    records.clear();
  }

  std::string prefix_;
  Less less_;
  uint64_t budgetBytes_;
  std::vector<std::string> runs_;
  size_t merged_ = 0;  // runs made by reduceRuns
  size_t memoryPos_ = 0;
  RunMerger<Record, Less> merger_;
  RunBuffer<Record> input_;  // last: its spill task uses the members above
};

// Stable external sort by a 64-bit key (see the top of the file). The budget holds the buffer
// and the radix sort's second array.
template <class Record, class KeyFn>
class StableKeySorter {
 public:
  // background: see RunBuffer (the budget then holds two buffers and the sort's second array).
  StableKeySorter(std::string tempPrefix, uint64_t budgetBytes, KeyFn key = KeyFn(), unsigned keyBits = 64,
                  bool background = false)
      : prefix_(std::move(tempPrefix)), key_(key), keyBits_(keyBits),
        capacity_(std::max<size_t>(1024, size_t(budgetBytes / ((background ? 3 : 2) * sizeof(Record))))),
        input_(capacity_, background, [this](std::vector<Record>& records) { writeRun(records); }) {}
  ~StableKeySorter() { release(); }
  StableKeySorter(const StableKeySorter&) = delete;
  StableKeySorter& operator=(const StableKeySorter&) = delete;

  void release() {
    input_.release();
    merger_.close();
    for (auto& path : runs_) std::remove(path.c_str());
    runs_.clear();
    runLength_.clear();
    samples_.clear();
    std::vector<Record>().swap(tmp_);
    sorted_ = nullptr;
    memoryPos_ = memoryEnd_ = 0;
  }

  void add(const Record& r) { input_.add(r); }
  void addBatch(const Record* r, size_t n) { input_.addBatch(r, n); }
  uint64_t count() const { return input_.count(); }

  void finish() {
    input_.wait();
    if (runs_.empty()) {
      sorted_ = sortBuffer();
      memoryPos_ = 0;
      memoryEnd_ = input_.records().size();
      return;
    }
    input_.spillRest();
    std::vector<Record>().swap(tmp_);
    // Reduced and opened now, while the sorter's budget is its own (the caller may open other
    // readers before its first next()); mergeInParts() reduces further if its parts need it.
    reduce(mergeFanIn(capacity_ * 2 * sizeof(Record)));
    size_t perRun = std::max<size_t>(kMinReadBuffer, capacity_ * 2 * sizeof(Record) / (runs_.size() + 1));
    merger_.open(runs_, std::min<size_t>(perRun, 4 << 20), Less{key_});
  }

  bool next(Record& out) {
    if (runs_.empty()) {
      if (memoryPos_ >= memoryEnd_) {
        release();
        return false;
      }
      out = sorted_[memoryPos_++];
      return true;
    }
    if (!merger_.next(out)) {
      release();
      return false;
    }
    return true;
  }

  // Instead of next(): the merged order cut into `parts` consecutive pieces at key boundaries
  // (quantiles of keys kept from every run), merged on parallel threads. fn(part, firstRank,
  // nextRecord) is called once per piece; firstRank is the position of the piece's first record
  // in the whole order and nextRecord(Record&) yields the piece's records. Releases the sorter.
  template <class Fn>
  void mergeInParts(size_t parts, const Fn& fn) {
    parts = std::max<size_t>(1, parts);
    if (runs_.empty()) {
      const size_t n = memoryEnd_;
      tbb::parallel_for(size_t(0), parts, [&](size_t p) {
        size_t at = n * p / parts, end = n * (p + 1) / parts;
        fn(p, uint64_t(at), [&](Record& r) {
          if (at >= end) return false;
          r = sorted_[at++];
          return true;
        });
      });
      release();
      return;
    }
    // Every part's merge reads every run: the runs reduced so that all parts together stay within
    // the fan-in (descriptors and read buffers). finish()'s merger has read only the runs' heads.
    merger_.close();
    reduce(std::max<size_t>(2, mergeFanIn(capacity_ * 2 * sizeof(Record)) / parts));
    // Splitters: quantiles of the kept keys; a piece holds keys in [split[p-1], split[p]).
    std::vector<uint64_t> kept;
    for (auto& s : samples_) kept.insert(kept.end(), s.begin(), s.end());
    std::sort(kept.begin(), kept.end());
    std::vector<uint64_t> split;
    for (size_t p = 1; p < parts && !kept.empty(); ++p) split.push_back(kept[kept.size() * p / parts]);
    split.erase(std::unique(split.begin(), split.end()), split.end());
    parts = split.size() + 1;
    // Per run and splitter, the first record with key >= splitter (binary search on disk).
    std::vector<std::vector<uint64_t>> cut(runs_.size());
    for (size_t r = 0; r < runs_.size(); ++r) {
      cut[r].push_back(0);
      for (uint64_t s : split) {
        uint64_t lo = cut[r].back(), hi = runLength_[r];
        while (lo < hi) {
          uint64_t mid = lo + (hi - lo) / 2;
          if (key_(TempReader::recordAt<Record>(runs_[r], mid * sizeof(Record))) < s)
            lo = mid + 1;
          else
            hi = mid;
        }
        cut[r].push_back(lo);
      }
      cut[r].push_back(runLength_[r]);
    }
    size_t perRun = std::clamp<size_t>(capacity_ * 2 * sizeof(Record) / ((runs_.size() + 1) * parts), kMinReadBuffer, 4 << 20);
    tbb::parallel_for(size_t(0), parts, [&](size_t p) {
      std::vector<uint64_t> begin(runs_.size()), end(runs_.size());
      uint64_t first = 0;
      for (size_t r = 0; r < runs_.size(); ++r) {
        begin[r] = cut[r][p];
        end[r] = cut[r][p + 1];
        first += begin[r];
      }
      RunMerger<Record, Less> merger;
      merger.open(runs_, perRun, Less{key_}, begin, end);
      fn(p, first, [&](Record& r) { return merger.next(r); });
    });
    release();
  }

 private:
  struct Less {
    KeyFn key;
    bool operator()(const Record& a, const Record& b) const { return key(a) < key(b); }
  };
  const Record* sortBuffer() {
    std::vector<Record>& records = input_.records();
    tmp_.resize(records.size());
    return radixSort(records.data(), tmp_.data(), records.size(), key_, keyBits_);
  }
  // The bounded fan-in (reduceRuns) down to `fanIn` runs, each merged run's length and kept keys
  // taken as it is written.
  void reduce(size_t fanIn) {
    const uint64_t bufferBytes = capacity_ * 2 * sizeof(Record);
    std::vector<uint64_t> lengths;
    std::vector<std::vector<uint64_t>> samples;
    auto slot = [&](size_t out) {
      if (lengths.size() <= out) lengths.resize(out + 1, 0), samples.resize(out + 1);
    };
    reduceRuns(
        runs_, fanIn, prefix_, merged_,
        [&](size_t first, size_t last, const std::string& path, size_t out) {
          slot(out);
          mergeRunsInto<Record>(runs_, first, last, path, bufferBytes, Less{key_}, [&](const Record& r, uint64_t i) {
            if (i % 4096 == 0) samples[out].push_back(key_(r));
            lengths[out] = i + 1;
          });
        },
        [&](size_t out, size_t old) {
          slot(out);
          lengths[out] = runLength_[old];
          samples[out] = std::move(samples_[old]);
        },
        [&] {
          lengths.resize(runs_.size(), 0);
          samples.resize(runs_.size());
          runLength_.swap(lengths);
          samples_.swap(samples);
          lengths.clear();
          samples.clear();
        });
  }
  // Sorts `records` and writes them as the next run (clears it).
  void writeRun(std::vector<Record>& records) {
    tmp_.resize(records.size());
    const Record* sorted = radixSort(records.data(), tmp_.data(), records.size(), key_, keyBits_);
    std::string path = prefix_ + ".run" + std::to_string(runs_.size());
    TempWriter writer(path, 4 << 20);
    writer.write(sorted, records.size() * sizeof(Record));
    writer.close();
    runs_.push_back(path);
    runLength_.push_back(records.size());
    samples_.emplace_back();
    for (size_t i = 0; i < records.size(); i += 4096) samples_.back().push_back(key_(sorted[i]));
    records.clear();
  }

  std::string prefix_;
  KeyFn key_;
  unsigned keyBits_;
  size_t capacity_;
  std::vector<Record> tmp_;
  const Record* sorted_ = nullptr;
  size_t memoryPos_ = 0, memoryEnd_ = 0;
  std::vector<std::string> runs_;
  size_t merged_ = 0;                          // runs made by reduce()
  std::vector<uint64_t> runLength_;            // records per run
  std::vector<std::vector<uint64_t>> samples_;  // every 4096th key of each run
  RunMerger<Record, Less> merger_;
  RunBuffer<Record> input_;  // last: its spill task uses the members above
};

// Records grouped by a 64-bit key (see the top of the file). A run is written as, per key in
// ascending order, a GroupHeader and the group's records in Less order. nextGroup() gathers a
// key's records from every run (lower runs first; re-sorted only when the concatenation is not
// already in Less order, which it is when records were added in Less order). rewind() starts
// another pass over the same groups. The budget covers the keys, the records and the counting
// sort's output.
template <class Record, class Less>
class KeyGroupSorter {
 public:
  // background: as StableKeySorter's (the budget then also holds the buffer being filled).
  KeyGroupSorter(std::string tempPrefix, uint64_t budgetBytes, Less less = Less(), bool background = false)
      : prefix_(std::move(tempPrefix)), less_(less), background_(background) {
    capacity_ = std::max<size_t>(1024, size_t(budgetBytes / (8 + 4 + 2 * sizeof(Record) + (background ? 8 + sizeof(Record) : 0))));
  }
  ~KeyGroupSorter() { release(); }
  KeyGroupSorter(const KeyGroupSorter&) = delete;
  KeyGroupSorter& operator=(const KeyGroupSorter&) = delete;

  void release() {
    try {
      spillTask_.wait();
    } catch (...) {  // already reported by finish(), or the sorter is being abandoned
    }
    readers_.clear();
    for (auto& path : runs_) std::remove(path.c_str());
    runs_.clear();
    std::vector<uint64_t>().swap(keys_);
    std::vector<Record>().swap(recs_);
    std::vector<uint64_t>().swap(spillKeys_);
    std::vector<Record>().swap(spillRecs_);
    std::vector<Record>().swap(grouped_);
    std::vector<uint32_t>().swap(slot_);
    groups_.clear();
  }

  void addBatch(const uint64_t* keys, const Record* recs, size_t n) {
    if (keys_.capacity() < capacity_) {
      keys_.reserve(capacity_);
      recs_.reserve(capacity_);
    }
    while (n > 0) {
      if (keys_.size() == capacity_) spill();
      size_t take = std::min(n, capacity_ - keys_.size());
      keys_.insert(keys_.end(), keys, keys + take);
      recs_.insert(recs_.end(), recs, recs + take);
      keys += take;
      recs += take;
      n -= take;
      count_ += take;
    }
  }
  uint64_t count() const { return count_; }

  void finish() {
    spillTask_.wait();
    if (runs_.empty()) {
      formGroups(keys_, recs_);
      std::vector<uint64_t>().swap(keys_);
      std::vector<Record>().swap(recs_);
      std::vector<uint32_t>().swap(slot_);
    } else {
      if (!keys_.empty()) spill();
      spillTask_.wait();
      std::vector<uint64_t>().swap(spillKeys_);
      std::vector<Record>().swap(spillRecs_);
      std::vector<uint64_t>().swap(keys_);
      std::vector<Record>().swap(recs_);
      std::vector<Record>().swap(grouped_);
      std::vector<uint32_t>().swap(slot_);
      groups_.clear();
      reduce();
    }
    rewind();
  }

  // Starts a pass over the groups (finish() starts the first). lastPass: no pass follows, so the
  // runs' disk space is given back as they are read (TempReader::consumeAsRead).
  void rewind(bool lastPass = false) {
    nextGroup_ = 0;
    if (runs_.empty()) return;
    if (readers_.empty()) {
      // Reads are sequential and the file is usually in the page cache: 512 KiB a run is plenty,
      // and a pass over the groups may be sharing the cap with resident data.
      size_t perRun = std::clamp<size_t>(capacity_ * (8 + 4 + 2 * sizeof(Record)) / (runs_.size() + 1), kMinReadBuffer, 512 << 10);
      for (auto& path : runs_) readers_.push_back(std::make_unique<TempReader>(path, perRun));
    } else {
      for (auto& r : readers_) r->rewind();
    }
    if (lastPass)
      for (auto& r : readers_) r->consumeAsRead();
    heads_.assign(runs_.size(), Header{});
    heap_ = {};
    for (size_t i = 0; i < runs_.size(); ++i)
      if (readers_[i]->get(heads_[i])) heap_.push({heads_[i].key, i});
  }

  // The next key and all its records (appended to out after clearing it); false at the end.
  bool nextGroup(uint64_t& key, std::vector<Record>& out) {
    out.clear();
    if (runs_.empty()) {
      if (nextGroup_ >= groups_.size()) return false;
      const Group& g = groups_[nextGroup_++];
      key = g.key;
      out.assign(grouped_.begin() + g.begin, grouped_.begin() + g.begin + g.count);
      return true;
    }
    if (heap_.empty()) return false;
    key = gatherGroup(readers_, heads_, heap_, 0, out);
    return true;
  }

 private:
  struct Header {
    uint64_t key;
    uint64_t count;
  };
  struct Group {
    uint64_t key;
    size_t begin, count;
  };
  struct HeapEntry {
    uint64_t key;
    size_t run;
    bool operator<(const HeapEntry& o) const { return key != o.key ? key > o.key : run > o.run; }  // min-heap
  };

  // The bounded fan-in (reduceRuns) for runs of groups: consecutive runs merged into one, a key's
  // records from several runs gathered as nextGroup() gathers them (lower runs first, then put in
  // Less order), so the groups read back are the same.
  void reduce() {
    const uint64_t bufferBytes = capacity_ * (8 + 4 + 2 * sizeof(Record));
    reduceRuns(
        runs_, mergeFanIn(bufferBytes), prefix_, merged_,
        [&](size_t first, size_t last, const std::string& path, size_t) { mergeGroupsInto(first, last, path, bufferBytes); },
        [](size_t, size_t) {}, [] {});
  }
  // The smallest key's records from every run that has it (runs[first + i] read by readers[i]),
  // appended to out: lower runs first, then put in Less order. Returns the key; heap non-empty.
  uint64_t gatherGroup(std::vector<std::unique_ptr<TempReader>>& readers, std::vector<Header>& heads,
                       std::priority_queue<HeapEntry>& heap, size_t first, std::vector<Record>& out) const {
    const uint64_t key = heap.top().key;
    const size_t from = out.size();
    size_t sources = 0;
    while (!heap.empty() && heap.top().key == key) {
      const size_t i = heap.top().run;
      heap.pop();
      const size_t at = out.size();
      out.resize(at + heads[i].count);
      if (readers[i]->read(out.data() + at, heads[i].count * sizeof(Record)) != heads[i].count * sizeof(Record))
        fail(runs_[first + i], "scratch run ends inside a group");
      if (readers[i]->get(heads[i])) heap.push({heads[i].key, i});
      ++sources;
    }
    if (sources > 1) sortTail(out.begin() + from, out.end());
    return key;
  }
  void mergeGroupsInto(size_t first, size_t last, const std::string& path, uint64_t bufferBytes) {
    const size_t n = last - first;
    const size_t share = std::max<size_t>(kMinReadBuffer, size_t(bufferBytes / (n + 1)));
    std::vector<std::unique_ptr<TempReader>> readers;
    std::vector<Header> heads(n);
    std::priority_queue<HeapEntry> heap;
    for (size_t i = 0; i < n; ++i) {
      readers.push_back(std::make_unique<TempReader>(runs_[first + i], share));
      readers.back()->consumeAsRead();
      if (readers.back()->get(heads[i])) heap.push({heads[i].key, i});
    }
    TempWriter writer(path, share);
    std::vector<Record> group;
    while (!heap.empty()) {
      group.clear();
      const uint64_t key = gatherGroup(readers, heads, heap, first, group);
      writer.put(Header{key, group.size()});
      writer.write(group.data(), group.size() * sizeof(Record));
    }
    writer.close();
    readers.clear();
    for (size_t i = first; i < last; ++i) std::remove(runs_[i].c_str());
  }

  // Counting sort of (keys, recs) by key into grouped_ (stable), groups_ in ascending key order.
  void formGroups(const std::vector<uint64_t>& keys, const std::vector<Record>& recs) {
    const size_t n = keys.size();
    // Distinct keys through an open-addressing table (first-seen slots); consecutive records
    // of a coherent stream usually share a key, so the last one is checked first.
    size_t cap = 1024;
    std::vector<std::pair<uint64_t, uint32_t>> table(cap, {0, UINT32_MAX});
    std::vector<uint64_t> distinct;
    slot_.resize(n);
    auto hashOf = [](uint64_t k) { return (k * 0x9E3779B97F4A7C15ull) >> 20; };
    auto insert = [&](uint64_t k) -> uint32_t {
      size_t h = hashOf(k) & (cap - 1);
      while (table[h].second != UINT32_MAX) {
        if (table[h].first == k) return table[h].second;
        h = (h + 1) & (cap - 1);
      }
      table[h] = {k, uint32_t(distinct.size())};
      distinct.push_back(k);
      if (distinct.size() * 2 > cap) {
        cap *= 2;
        std::vector<std::pair<uint64_t, uint32_t>> grown(cap, {0, UINT32_MAX});
        for (auto& e : table)
          if (e.second != UINT32_MAX) {
            size_t g = hashOf(e.first) & (cap - 1);
            while (grown[g].second != UINT32_MAX) g = (g + 1) & (cap - 1);
            grown[g] = e;
          }
        table.swap(grown);
      }
      return uint32_t(distinct.size() - 1);
    };
    uint64_t lastKey = 0;
    uint32_t lastSlot = UINT32_MAX;
    for (size_t i = 0; i < n; ++i) {
      if (lastSlot == UINT32_MAX || keys[i] != lastKey) {
        lastKey = keys[i];
        lastSlot = insert(lastKey);
      }
      slot_[i] = lastSlot;
    }
    std::vector<uint32_t> order(distinct.size());
    for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
    std::sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return distinct[a] < distinct[b]; });
    std::vector<uint32_t> rank(distinct.size());
    for (uint32_t r = 0; r < order.size(); ++r) rank[order[r]] = r;
    std::vector<size_t> start(distinct.size() + 1, 0);
    for (size_t i = 0; i < n; ++i) ++start[rank[slot_[i]] + 1];
    for (size_t r = 0; r < distinct.size(); ++r) start[r + 1] += start[r];
    groups_.clear();
    for (uint32_t r = 0; r < order.size(); ++r) groups_.push_back({distinct[order[r]], start[r], start[r + 1] - start[r]});
    grouped_.resize(n);
    for (size_t i = 0; i < n; ++i) grouped_[start[rank[slot_[i]]]++] = recs[i];
    tbb::parallel_for(size_t(0), groups_.size(), [&](size_t g) {
      auto b = grouped_.begin() + groups_[g].begin, e = b + groups_[g].count;
      sortTail(b, e);
    });
  }
  // Sorts [b, e) in Less order, which is cheap when it is sorted up to a small unsorted tail (a
  // group added mostly in order, its stragglers last): the tail is sorted and merged in.
  template <class It>
  void sortTail(It b, It e) const {
    It mid = std::is_sorted_until(b, e, less_);
    if (mid == e) return;
    std::sort(mid, e, less_);
    std::inplace_merge(b, mid, e, less_);
  }

  void spill() {
    if (!background_) {
      writeRun(keys_, recs_);
      return;
    }
    spillTask_.wait();  // one spill at a time (rethrows its error)
    std::swap(keys_, spillKeys_);
    std::swap(recs_, spillRecs_);
    keys_.clear();
    recs_.clear();
    if (keys_.capacity() < capacity_) {
      keys_.reserve(capacity_);
      recs_.reserve(capacity_);
    }
    spillTask_.run([this] { writeRun(spillKeys_, spillRecs_); });
  }
  // Groups (keys, recs) and writes them as the next run (clears them).
  void writeRun(std::vector<uint64_t>& keys, std::vector<Record>& recs) {
    formGroups(keys, recs);
    std::string path = prefix_ + ".run" + std::to_string(runs_.size());
    TempWriter writer(path, 4 << 20);
    // A header and the records' span per group, handed to the writer 512 groups at a time (no copy
    // into its buffer through the page cache).
    constexpr size_t kGroups = 512;
    Header headers[kGroups];
    struct iovec pieces[2 * kGroups];
    for (size_t g0 = 0; g0 < groups_.size(); g0 += kGroups) {
      const size_t n = std::min(kGroups, groups_.size() - g0);
      for (size_t i = 0; i < n; ++i) {
        const Group& g = groups_[g0 + i];
        headers[i] = Header{g.key, g.count};
        pieces[2 * i] = {&headers[i], sizeof(Header)};
        pieces[2 * i + 1] = {grouped_.data() + g.begin, g.count * sizeof(Record)};
      }
      writer.writeGather(pieces, 2 * n);
    }
    writer.close();
    runs_.push_back(path);
    keys.clear();
    recs.clear();
    groups_.clear();
  }

  std::string prefix_;
  Less less_;
  bool background_;
  size_t capacity_;
  std::vector<uint64_t> keys_, spillKeys_;
  std::vector<Record> recs_, spillRecs_, grouped_;
  tbb::task_group spillTask_;
  std::vector<uint32_t> slot_;
  std::vector<Group> groups_;
  size_t nextGroup_ = 0;
  uint64_t count_ = 0;
  std::vector<std::string> runs_;
  size_t merged_ = 0;  // runs made by reduce()
  std::vector<std::unique_ptr<TempReader>> readers_;
  std::vector<Header> heads_;
  std::priority_queue<HeapEntry> heap_;
};

}  // namespace mt
