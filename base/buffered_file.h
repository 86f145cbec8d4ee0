// A WritableFile that gathers appends into large sequential writes: the patch store's segments
// and the MT file's payloads are appended a block at a time (a few hundred bytes to a few KiB
// each), and one write(2) per block made the level loop's I/O hundreds of thousands of small
// system calls. Appends are copied into a buffer and written when it is full, on flush(), sync()
// and close(). Not thread-safe: a reader of the same file in the process must have the writer
// flush (under the writer's lock) before reading bytes past what was written.
#pragma once

#include <cstring>
#include <memory>
#include <vector>

#include "base/env.h"

namespace mt {

class BufferedWritableFile : public WritableFile {
 public:
  static constexpr size_t kDefaultBytes = 4 << 20;
  explicit BufferedWritableFile(std::unique_ptr<WritableFile> file, size_t bufferBytes = kDefaultBytes)
      : file_(std::move(file)), capacity_(bufferBytes) {}
  // Unflushed bytes are dropped (as an unsynced write may be after a crash): callers close() or
  // sync() what they mean to keep.
  ~BufferedWritableFile() override = default;

  void append(const void* data, size_t size) override {
    if (buffer_.size() + size > capacity_) flush();
    if (size >= capacity_) {
      file_->append(data, size);
      return;
    }
    if (buffer_.capacity() < capacity_) buffer_.reserve(capacity_);
    const char* p = static_cast<const char*>(data);
    buffer_.insert(buffer_.end(), p, p + size);
  }
  void sync() override {
    flush();
    file_->sync();
  }
  void close() override {
    flush();
    file_->close();
  }
  uint64_t size() const override { return file_->size() + buffer_.size(); }
  // Bytes written to the file so far (the rest is buffered).
  uint64_t flushedSize() const { return file_->size(); }
  void writeAt(uint64_t offset, const void* data, size_t size) override {
    if (offset + size > file_->size()) flush();
    file_->writeAt(offset, data, size);
  }
  // Writes the buffer. On an error the buffer is dropped (the file holds what the system took).
  void flush() {
    if (buffer_.empty()) return;
    std::vector<char> pending;
    pending.swap(buffer_);
    file_->append(pending.data(), pending.size());
    pending.clear();
    pending.swap(buffer_);  // keep the allocation
  }

 private:
  std::unique_ptr<WritableFile> file_;
  size_t capacity_;
  std::vector<char> buffer_;
};

}  // namespace mt
