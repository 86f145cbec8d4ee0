// Little-endian serialization of manifest records. ByteReader throws mt::Error naming the source
// and the byte offset when a record is shorter than what it claims.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>

#include "base/error.h"

namespace mt {

class ByteWriter {
 public:
  template <class T>
  void put(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    bytes_.append(reinterpret_cast<const char*>(&v), sizeof(T));
  }
  void putString(const std::string& s) {
    put<uint64_t>(s.size());
    bytes_ += s;
  }
  void putRaw(const void* data, size_t size) { bytes_.append(static_cast<const char*>(data), size); }
  const std::string& bytes() const { return bytes_; }
  std::string& bytes() { return bytes_; }

 private:
  std::string bytes_;
};

class ByteReader {
 public:
  ByteReader(const std::string& bytes, std::string source, uint64_t baseOffset = 0)
      : data_(bytes.data()), size_(bytes.size()), source_(std::move(source)), base_(baseOffset) {}
  ByteReader(const char* data, size_t size, std::string source, uint64_t baseOffset = 0)
      : data_(data), size_(size), source_(std::move(source)), base_(baseOffset) {}

  template <class T>
  T get() {
    static_assert(std::is_trivially_copyable_v<T>);
    need(sizeof(T));
    T v;
    std::memcpy(&v, data_ + pos_, sizeof(T));
    pos_ += sizeof(T);
    return v;
  }
  std::string getString() {
    uint64_t n = get<uint64_t>();
    need(n);
    std::string s(data_ + pos_, size_t(n));
    pos_ += size_t(n);
    return s;
  }
  const char* getRaw(size_t n) {
    need(n);
    const char* p = data_ + pos_;
    pos_ += n;
    return p;
  }
  bool atEnd() const { return pos_ == size_; }
  size_t position() const { return pos_; }

 private:
  void need(uint64_t n) const {
    if (n > size_ - pos_)
      fail(source_, "record truncated at byte offset " + std::to_string(base_ + pos_) + " (needs " +
                        std::to_string(n) + " more bytes, has " + std::to_string(size_ - pos_) + ")");
  }
  const char* data_;
  size_t size_;
  size_t pos_ = 0;
  std::string source_;
  uint64_t base_;
};

}  // namespace mt
