// External merge sort of plain-old-data records within a memory budget: records are collected in
// a buffer of at most budget bytes, each full buffer is sorted (in parallel) and written as a run,
// and the runs are merged with a heap when read back. When everything fits, nothing touches the
// disk. Used by ingest for the (vertex, patch) and face regrouping passes that the issue asks to
// stay out of core ("an external sort of (vertex, patch) pairs").
#pragma once

#include <tbb/parallel_sort.h>

#include <algorithm>
#include <cstdint>
#include <memory>
#include <queue>
#include <string>
#include <vector>

#include "patchstore/temp_file.h"

namespace mt {

template <class Record, class Less>
class ExternalSorter {
 public:
  ExternalSorter(std::string tempPrefix, uint64_t budgetBytes, Less less = Less())
      : prefix_(std::move(tempPrefix)), less_(less) {
    capacity_ = std::max<size_t>(1024, size_t(budgetBytes / sizeof(Record)));
  }
  ~ExternalSorter() { release(); }

  void release() {
    readers_.clear();
    for (auto& path : runs_) std::remove(path.c_str());
    runs_.clear();
    std::vector<Record>().swap(buffer_);
    memoryPos_ = 0;
  }

  void add(const Record& r) {
    // Reserve the whole budget at once: untouched pages cost no RSS, while growth by doubling
    // would briefly hold 1.5x the budget.
    if (buffer_.capacity() < capacity_) buffer_.reserve(capacity_);
    if (buffer_.size() == capacity_) spill();
    buffer_.push_back(r);
    ++count_;
  }
  uint64_t count() const { return count_; }
  size_t runCount() const { return runs_.size(); }

  // Ends input; afterwards next() yields records in order. Equal records keep no particular
  // order, so callers make keys total when the result must be deterministic.
  void finish() {
    if (runs_.empty()) {
      tbb::parallel_sort(buffer_.begin(), buffer_.end(), less_);
      memoryPos_ = 0;
      return;
    }
    if (!buffer_.empty()) spill();
    std::vector<Record>().swap(buffer_);
    // Each run gets an equal share of the budget as its read buffer.
    size_t perRun = std::max<size_t>(64 << 10, capacity_ * sizeof(Record) / (runs_.size() + 1));
    for (size_t i = 0; i < runs_.size(); ++i) {
      readers_.push_back(std::make_unique<TempReader>(runs_[i], perRun));
      Record r;
      if (readers_[i]->get(r)) heap_.push({r, i});
    }
  }

  // Once it returns false the sorter has released its memory and run files, so the next pass
  // gets the budget (and the disk) back before the sorter object goes out of scope.
  bool next(Record& out) {
    if (runs_.empty()) {
      if (memoryPos_ >= buffer_.size()) {
        release();
        return false;
      }
      out = buffer_[memoryPos_++];
      return true;
    }
    if (heap_.empty()) {
      release();
      return false;
    }
    Entry top = heap_.top();
    heap_.pop();
    out = top.record;
    Record r;
    if (readers_[top.run]->get(r)) heap_.push({r, top.run});
    return true;
  }

 private:
  struct Entry {
    Record record;
    size_t run;
  };
  struct EntryGreater {
    Less less;
    bool operator()(const Entry& a, const Entry& b) const {
      if (less(b.record, a.record)) return true;
      if (less(a.record, b.record)) return false;
      return a.run > b.run;
    }
  };

  void spill() {
    tbb::parallel_sort(buffer_.begin(), buffer_.end(), less_);
    std::string path = prefix_ + ".run" + std::to_string(runs_.size());
    TempWriter writer(path, 4 << 20);
    writer.write(buffer_.data(), buffer_.size() * sizeof(Record));
    writer.close();
    runs_.push_back(path);
    buffer_.clear();
  }

  std::string prefix_;
  Less less_;
  size_t capacity_;
  std::vector<Record> buffer_;
  size_t memoryPos_ = 0;
  uint64_t count_ = 0;
  std::vector<std::string> runs_;
  std::vector<std::unique_ptr<TempReader>> readers_;
  std::priority_queue<Entry, std::vector<Entry>, EntryGreater> heap_{EntryGreater{less_}};
};

}  // namespace mt
