// Sequential scratch files for the out-of-core passes: buffered record writers and readers of
// plain-old-data records. Scratch files need no crash safety (a failed ingest deletes them), so
// they use the system calls directly rather than the store's Env.
//
// Scratch I/O goes through the page cache by default; MT_SCRATCH_DIRECT=1 bypasses it (O_DIRECT)
// where the file system allows it. On the virtual machines this project is measured on, a page the
// guest has not touched lately costs a host fault, so a first buffered write of 1 GiB took 2.9-3.0 s
// of system time and a cold buffered read 1.75 s, against 0.09 s and 0.03 s with O_DIRECT (dd,
// 4 MiB blocks; the device does 1.2-1.6 GB/s either way), and arm13M at --memory 48M took 2.8 s of
// system time direct against 4.5 s buffered (44.4 / 45.5 s CPU, same bytes). But a direct read is
// synchronous and has no readahead: the billion-triangle build's Morton merge (269 runs, a
// 164 KiB buffer each) read 55 MB/s direct at a third of a core, so the page cache stays the
// default until the merges read ahead themselves. Direct buffers are aligned to kDirectAlign and
// the file is read and written in whole aligned blocks; the last partial block of a file is
// written through the page cache (O_DIRECT cleared), which a later direct read sees (the kernel
// writes a range back before reading it directly). Where O_DIRECT is refused (tmpfs, some network
// file systems) the same code runs buffered.
#pragma once

#include <fcntl.h>
#include <limits.h>
#include <sys/uio.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

#include "base/error.h"

namespace mt {

constexpr size_t kDirectAlign = 4096;
// The least read buffer of a TempReader. A merge of many runs gives each run's reader its share
// of the sorter's budget down to this (the kernel's readahead keeps the sequential reads large):
// with a 64 KiB floor a 100 M-triangle ingest at --memory 96M held 463 group runs' readers,
// 29 MiB against the sorter's 14 MiB.
constexpr size_t kMinReadBuffer = 16 << 10;

// A buffer aligned for O_DIRECT, its capacity a multiple of kDirectAlign.
class AlignedBuffer {
 public:
  explicit AlignedBuffer(size_t bytes = 0) { reset(bytes); }
  void reset(size_t bytes) {
    capacity_ = (std::max<size_t>(bytes, kDirectAlign) + kDirectAlign - 1) / kDirectAlign * kDirectAlign;
    data_.reset(static_cast<char*>(std::aligned_alloc(kDirectAlign, capacity_)));
    if (!data_) throw std::bad_alloc();
  }
  char* data() const { return data_.get(); }
  size_t capacity() const { return capacity_; }

 private:
  struct Free {
    void operator()(char* p) const { std::free(p); }
  };
  std::unique_ptr<char, Free> data_;
  size_t capacity_ = 0;
};

// Opens `path` with `flags`, and O_DIRECT when MT_SCRATCH_DIRECT=1 asks for it and the file system
// allows it.
inline int openScratch(const std::string& path, int flags, bool& direct) {
  static const bool wantDirect = [] {
    const char* e = std::getenv("MT_SCRATCH_DIRECT");
    return e && *e == '1';
  }();
  if (!wantDirect) {
    direct = false;
    return ::open(path.c_str(), flags | O_CLOEXEC, 0644);
  }
  int fd = ::open(path.c_str(), flags | O_DIRECT | O_CLOEXEC, 0644);
  direct = fd >= 0;
  if (fd < 0 && errno == EINVAL) fd = ::open(path.c_str(), flags | O_CLOEXEC, 0644);
  return fd;
}

// Writes all of [data, data + size) at `offset` (pwrite, retried on EINTR and short writes).
inline void writeAllAt(int fd, const char* data, size_t size, uint64_t offset, const std::string& path) {
  while (size > 0) {
    const ssize_t n = ::pwrite(fd, data, size, off_t(offset));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) fail(path, std::string("cannot write scratch file (disk full?): ") + std::strerror(n < 0 ? errno : ENOSPC));
    data += n;
    size -= size_t(n);
    offset += uint64_t(n);
  }
}

class TempWriter {
 public:
  explicit TempWriter(std::string path, size_t bufferBytes = 1 << 20)
      : path_(std::move(path)), buffer_(std::max<size_t>(bufferBytes, 64 << 10)) {
    fd_ = openScratch(path_, O_WRONLY | O_CREAT | O_TRUNC, direct_);
    if (fd_ < 0) fail(path_, std::string("cannot create scratch file: ") + std::strerror(errno));
  }
  ~TempWriter() {
    if (fd_ >= 0) ::close(fd_);
  }
  TempWriter(const TempWriter&) = delete;
  TempWriter& operator=(const TempWriter&) = delete;

  void write(const void* data, size_t size) {
    const char* p = static_cast<const char*>(data);
    bytes_ += size;
    // Through the page cache a write needs no alignment: one of at least a buffer goes to the file
    // from the caller's memory (a sorted run, whole: one copy fewer, and no buffer pages touched:
    // the copy and its page faults were a third of the chunked ingest's vertex stage).
    if (!direct_ && size >= buffer_.capacity()) {
      flushBuffer();
      writeAllAt(fd_, p, size, fileBytes_, path_);
      fileBytes_ += size;
      return;
    }
    while (size > 0) {
      const size_t take = std::min(size, buffer_.capacity() - used_);
      std::memcpy(buffer_.data() + used_, p, take);
      used_ += take;
      p += take;
      size -= take;
      if (used_ == buffer_.capacity()) flushBlocks();
    }
  }
  // Writes the pieces in order. Through the page cache they go to the file from the caller's
  // memory (pwritev, up to IOV_MAX pieces a call: a run's group headers and record spans without
  // the copy into the buffer, a tenth of the chunked ingest's assign stage); with O_DIRECT,
  // through the buffer as write() does.
  void writeGather(const struct iovec* v, size_t n) {
    if (direct_) {
      for (size_t i = 0; i < n; ++i) write(v[i].iov_base, v[i].iov_len);
      return;
    }
    flushBuffer();
    while (n > 0) {
      if (v->iov_len == 0) {  // nothing to write (pwritev of empty pieces alone returns 0)
        --n, ++v;
        continue;
      }
      const ssize_t got = ::pwritev(fd_, v, int(std::min<size_t>(n, IOV_MAX)), off_t(fileBytes_));
      if (got < 0 && errno == EINTR) continue;
      if (got <= 0) fail(path_, std::string("cannot write scratch file (disk full?): ") + std::strerror(got < 0 ? errno : ENOSPC));
      size_t left = size_t(got);
      bytes_ += left;
      fileBytes_ += left;
      for (; n > 0 && left >= v->iov_len; --n, ++v) left -= v->iov_len;
      if (left > 0) {  // a short write ended inside this piece: its rest, then on
        const size_t rest = v->iov_len - left;
        writeAllAt(fd_, static_cast<const char*>(v->iov_base) + left, rest, fileBytes_, path_);
        bytes_ += rest;
        fileBytes_ += rest;
        --n, ++v;
      }
    }
  }
  template <class T>
  void put(const T& record) {
    static_assert(std::is_trivially_copyable_v<T>);
    write(&record, sizeof(T));
  }
  // Writes what is buffered and closes the file (its last partial block through the page cache).
  void close() {
    if (fd_ < 0) return;
    flushBlocks();
    if (used_ > 0 && direct_) ::fcntl(fd_, F_SETFL, ::fcntl(fd_, F_GETFL) & ~O_DIRECT);
    flushBuffer();
    const int fd = fd_;
    fd_ = -1;
    if (::close(fd) != 0) fail(path_, std::string("cannot write scratch file: ") + std::strerror(errno));
  }
  uint64_t bytes() const { return bytes_; }
  const std::string& path() const { return path_; }

 private:
  // Writes everything buffered (through the page cache: no alignment needed).
  void flushBuffer() {
    if (used_ == 0) return;
    writeAllAt(fd_, buffer_.data(), used_, fileBytes_, path_);
    fileBytes_ += used_;
    used_ = 0;
  }
  // Writes the buffer's whole aligned blocks; the rest moves to the front.
  void flushBlocks() {
    const size_t whole = used_ / kDirectAlign * kDirectAlign;
    if (whole == 0) return;
    writeAllAt(fd_, buffer_.data(), whole, fileBytes_, path_);
    fileBytes_ += whole;
    std::memmove(buffer_.data(), buffer_.data() + whole, used_ - whole);
    used_ -= whole;
  }
  std::string path_;
  int fd_ = -1;
  bool direct_ = false;
  AlignedBuffer buffer_;
  size_t used_ = 0;        // bytes in the buffer, not yet in the file
  uint64_t fileBytes_ = 0;  // bytes in the file (with O_DIRECT a multiple of kDirectAlign until close)
  uint64_t bytes_ = 0;      // bytes written through this writer
};

class TempReader {
 public:
  // Reads the file from byte `offset`, at most `length` bytes (a slice of a sorted run).
  explicit TempReader(std::string path, size_t bufferBytes = 1 << 20, uint64_t offset = 0, uint64_t length = UINT64_MAX)
      : path_(std::move(path)), offset_(offset), length_(length), buffer_(std::max<size_t>(bufferBytes, kMinReadBuffer)) {
    fd_ = openScratch(path_, O_RDONLY, direct_);
    if (fd_ < 0) fail(path_, std::string("cannot open scratch file: ") + std::strerror(errno));
    if (!direct_) ::posix_fadvise(fd_, 0, 0, POSIX_FADV_SEQUENTIAL);
    rewind();
  }
  // The record at byte offset `at` of a file, read directly (binary searches over a run).
  template <class T>
  static T recordAt(const std::string& path, uint64_t at) {
    static_assert(std::is_trivially_copyable_v<T>);
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) fail(path, std::string("cannot open scratch file: ") + std::strerror(errno));
    T r;
    const bool ok = ::pread(fd, &r, sizeof r, off_t(at)) == ssize_t(sizeof r);
    ::close(fd);
    if (!ok) fail(path, "cannot read scratch file at byte offset " + std::to_string(at));
    return r;
  }
  ~TempReader() {
    if (fd_ >= 0) ::close(fd_);
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
      if (pos_ == end_ && !refill()) break;
      const size_t n = std::min(size - done, end_ - pos_);
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
    next_ = offset_ / kDirectAlign * kDirectAlign;
    skip_ = size_t(offset_ - next_);
    bufferStart_ = next_;
    pos_ = end_ = 0;
    eof_ = false;
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
  uint64_t sliceEnd() const { return length_ > UINT64_MAX - offset_ ? UINT64_MAX : offset_ + length_; }
  // The next aligned block range of the file into the buffer; false at the end of the slice.
  bool refill() {
    if (punch_) punchConsumed(bufferStart_ + end_);
    const uint64_t limit = sliceEnd();
    if (eof_ || next_ >= limit) {
      eof_ = true;
      return false;
    }
    size_t want = buffer_.capacity();
    if (limit - next_ < want) want = size_t((limit - next_ + kDirectAlign - 1) / kDirectAlign * kDirectAlign);
    ssize_t got;
    do got = ::pread(fd_, buffer_.data(), want, off_t(next_));
    while (got < 0 && errno == EINTR);
    if (got < 0) fail(path_, std::string("cannot read scratch file: ") + std::strerror(errno));
    eof_ = size_t(got) < want;  // a short read ends the file (what it read is still returned)
    bufferStart_ = next_;
    next_ += uint64_t(got);
    end_ = size_t(std::min<uint64_t>(uint64_t(got), limit - bufferStart_));
    pos_ = std::min(skip_, end_);
    skip_ = 0;
    return pos_ < end_ || refill();
  }
  // Every byte of the slice before `consumed` has been read: punch whole steps of it (all of it
  // once the slice is read to its end). Never a byte outside the slice (slices of one file are
  // read by parallel merges).
  void punchConsumed(uint64_t consumed) {
    consumed = std::min(consumed, sliceEnd());
    uint64_t to = consumed / kPunchStep * kPunchStep;
    if (eof_ || consumed == sliceEnd()) to = consumed;
    const uint64_t from = std::max(punched_, (offset_ + kPunchStep - 1) / kPunchStep * kPunchStep);
    if (to > from && fallocate(punchFd_, FALLOC_FL_PUNCH_HOLE | FALLOC_FL_KEEP_SIZE, off_t(from), off_t(to - from)) != 0)
      punch_ = false;  // not supported here: the blocks go when the file is removed
    punched_ = std::max(punched_, to);
  }
  std::string path_;
  int fd_ = -1;
  bool direct_ = false;
  uint64_t offset_, length_;  // the slice
  AlignedBuffer buffer_;
  uint64_t next_ = 0;         // file offset of the next block to read (aligned)
  uint64_t bufferStart_ = 0;  // file offset of buffer_[0]
  size_t pos_ = 0, end_ = 0;  // unread bytes are buffer_[pos_, end_)
  size_t skip_ = 0;           // bytes of the first block before the slice
  bool eof_ = false;
  bool punch_ = false;
  int punchFd_ = -1;  // the file opened for writing, to punch holes in
  uint64_t punched_ = 0;
};

}  // namespace mt
