// Sequential scratch files for the out-of-core passes: buffered record writers and readers of
// plain-old-data records. Scratch files need no crash safety (a failed ingest deletes them), so
// they use stdio directly rather than the store's Env.
#pragma once

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <type_traits>
#include <vector>

#include "base/error.h"

namespace mt {

class TempWriter {
 public:
  explicit TempWriter(std::string path, size_t bufferBytes = 1 << 20) : path_(std::move(path)) {
    file_ = std::fopen(path_.c_str(), "wb");
    if (!file_) fail(path_, std::string("cannot create scratch file: ") + std::strerror(errno));
    buffer_.reserve(bufferBytes);
  }
  ~TempWriter() {
    if (file_) std::fclose(file_);
  }
  TempWriter(const TempWriter&) = delete;
  TempWriter& operator=(const TempWriter&) = delete;

  void write(const void* data, size_t size) {
    if (buffer_.size() + size > buffer_.capacity()) flush();
    if (size > buffer_.capacity()) {
      put(data, size);
    } else {
      const char* p = static_cast<const char*>(data);
      buffer_.insert(buffer_.end(), p, p + size);
    }
    bytes_ += size;
  }
  template <class T>
  void put(const T& record) {
    static_assert(std::is_trivially_copyable_v<T>);
    write(&record, sizeof(T));
  }
  void close() {
    flush();
    if (file_ && std::fclose(file_) != 0) {
      file_ = nullptr;
      fail(path_, std::string("cannot write scratch file: ") + std::strerror(errno));
    }
    file_ = nullptr;
  }
  uint64_t bytes() const { return bytes_; }
  const std::string& path() const { return path_; }

 private:
  void flush() {
    if (!buffer_.empty()) put(buffer_.data(), buffer_.size());
    buffer_.clear();
  }
  void put(const void* data, size_t size) {
    if (std::fwrite(data, 1, size, file_) != size)
      fail(path_, std::string("cannot write scratch file (disk full?): ") + std::strerror(errno));
  }
  std::string path_;
  FILE* file_ = nullptr;
  std::vector<char> buffer_;
  uint64_t bytes_ = 0;
};

class TempReader {
 public:
  // Reads the file from byte `offset`, at most `length` bytes (a slice of a sorted run).
  explicit TempReader(std::string path, size_t bufferBytes = 1 << 20, uint64_t offset = 0, uint64_t length = UINT64_MAX)
      : path_(std::move(path)), offset_(offset), length_(length), left_(length) {
    file_ = std::fopen(path_.c_str(), "rb");
    if (!file_) fail(path_, std::string("cannot open scratch file: ") + std::strerror(errno));
    if (offset > 0 && fseeko(file_, off_t(offset), SEEK_SET) != 0) fail(path_, "cannot seek in scratch file");
    buffer_.resize(bufferBytes);
  }
  // The record at byte offset `at` of a file, read directly (binary searches over a run).
  template <class T>
  static T recordAt(const std::string& path, uint64_t at) {
    static_assert(std::is_trivially_copyable_v<T>);
    FILE* f = std::fopen(path.c_str(), "rb");
    if (!f) fail(path, std::string("cannot open scratch file: ") + std::strerror(errno));
    T r;
    bool ok = fseeko(f, off_t(at), SEEK_SET) == 0 && std::fread(&r, sizeof r, 1, f) == 1;
    std::fclose(f);
    if (!ok) fail(path, "cannot read scratch file at byte offset " + std::to_string(at));
    return r;
  }
  ~TempReader() {
    if (file_) std::fclose(file_);
    if (punchFd_ >= 0) ::close(punchFd_);
  }
  TempReader(const TempReader&) = delete;
  TempReader& operator=(const TempReader&) = delete;

  // A file read once, start to end: what has been read is given back to the file system as the
  // reading goes on (holes punched behind the reader, in steps of kPunchStep), so a pass that
  // consumes scratch files while it writes others holds about the unread part of its input on
  // disk, not all of it. No rewind() afterwards. Where the file system cannot punch holes the
  // file simply keeps its blocks until it is removed.
  void consumeAsRead() {
    if (punchFd_ < 0) punchFd_ = ::open(path_.c_str(), O_WRONLY | O_CLOEXEC);
    punch_ = punchFd_ >= 0;
  }

  // Reads up to `size` bytes; returns the count (0 at end of file).
  size_t read(void* out, size_t size) {
    char* p = static_cast<char*>(out);
    size_t done = 0;
    while (done < size) {
      if (pos_ == end_) {
        if (punch_) punchConsumed();
        end_ = left_ == 0 ? 0 : std::fread(buffer_.data(), 1, size_t(std::min<uint64_t>(buffer_.size(), left_)), file_);
        left_ -= end_;
        pos_ = 0;
        if (end_ == 0) {
          if (std::ferror(file_)) fail(path_, "cannot read scratch file");
          break;
        }
      }
      size_t n = std::min(size - done, end_ - pos_);
      std::memcpy(p + done, buffer_.data() + pos_, n);
      pos_ += n;
      done += n;
    }
    return done;
  }
  template <class T>
  bool get(T& record) {
    static_assert(std::is_trivially_copyable_v<T>);
    size_t n = read(&record, sizeof(T));
    if (n == 0) return false;
    if (n != sizeof(T)) fail(path_, "scratch file ends inside a record");
    return true;
  }
  // Back to the start of the slice (a second pass over the same bytes; not after consumeAsRead).
  void rewind() {
    if (fseeko(file_, off_t(offset_), SEEK_SET) != 0) fail(path_, "cannot rewind scratch file");
    pos_ = end_ = 0;
    left_ = length_;
  }
  // Reads up to maxCount records into out (resized); returns false at end.
  template <class T>
  bool getBatch(std::vector<T>& out, size_t maxCount) {
    out.resize(maxCount);
    size_t n = read(out.data(), maxCount * sizeof(T));
    if (n % sizeof(T) != 0) fail(path_, "scratch file ends inside a record");
    out.resize(n / sizeof(T));
    return !out.empty();
  }

 private:
  static constexpr uint64_t kPunchStep = 64 << 10;
  // Every byte before the next read is consumed: punch whole steps of it (and the tail once the
  // slice is read to its end).
  void punchConsumed() {
    const uint64_t consumed = offset_ + (length_ - left_);
    uint64_t to = consumed / kPunchStep * kPunchStep;
    if (left_ == 0 || std::feof(file_)) to = consumed;
    if (to <= punched_) return;
    const uint64_t from = std::max(punched_, offset_ / kPunchStep * kPunchStep + (offset_ % kPunchStep ? kPunchStep : 0));
    if (to > from && fallocate(punchFd_, FALLOC_FL_PUNCH_HOLE | FALLOC_FL_KEEP_SIZE, off_t(from), off_t(to - from)) != 0)
      punch_ = false;  // not supported here: the blocks go when the file is removed
    punched_ = to;
  }
  std::string path_;
  FILE* file_ = nullptr;
  std::vector<char> buffer_;
  size_t pos_ = 0, end_ = 0;
  uint64_t offset_, length_, left_;  // the slice, and what of it is not read yet
  bool punch_ = false;
  int punchFd_ = -1;  // the file opened for writing, to punch holes in
  uint64_t punched_ = 0;  // bytes before this offset are punched (or were not ours to punch)
};

}  // namespace mt
