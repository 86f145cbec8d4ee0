#include "base/env.h"

#include <dirent.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cassert>
#include <cerrno>
#include <cstring>
#include <exception>
#include <system_error>
#include <thread>

namespace mt {

namespace {

std::string errnoText() { return std::strerror(errno); }

class PosixWritableFile : public WritableFile {
 public:
  PosixWritableFile(std::string path, int fd, uint64_t size, bool appendMode = false)
      : path_(std::move(path)), fd_(fd), size_(size), appendMode_(appendMode) {}
  ~PosixWritableFile() override {
    if (fd_ >= 0) ::close(fd_);
  }
  void append(const void* data, size_t size) override {
    const char* p = static_cast<const char*>(data);
    while (size > 0) {
      ssize_t n = ::write(fd_, p, size);
      if (n < 0) {
        if (errno == EINTR) continue;
        failIo(path_, "write failed at byte offset " + std::to_string(size_) + ": " + errnoText());
      }
      p += n;
      size -= size_t(n);
      size_ += uint64_t(n);
    }
  }
  void sync() override {
    if (::fdatasync(fd_) != 0) failIo(path_, "fsync failed: " + errnoText());
  }
  void close() override {
    if (fd_ >= 0 && ::close(fd_) != 0) {
      fd_ = -1;
      failIo(path_, "close failed: " + errnoText());
    }
    fd_ = -1;
  }
  uint64_t size() const override { return size_; }
  void writeAt(uint64_t offset, const void* data, size_t size) override {
    assert(!appendMode_ && "writeAt on a file opened for append");
    assert(offset <= size_ && size <= size_ - offset && "writeAt past the end");
    const char* p = static_cast<const char*>(data);
    uint64_t at = offset;
    while (size > 0) {
      ssize_t n = ::pwrite(fd_, p, size, off_t(at));
      if (n < 0) {
        if (errno == EINTR) continue;
        failIo(path_, "write failed at byte offset " + std::to_string(at) + ": " + errnoText());
      }
      p += n;
      size -= size_t(n);
      at += uint64_t(n);
    }
  }

 private:
  std::string path_;
  int fd_;
  uint64_t size_;
  [[maybe_unused]] bool appendMode_;  // read only by an assert
};

class PosixRandomAccessFile : public RandomAccessFile {
 public:
  PosixRandomAccessFile(std::string path, int fd, uint64_t size) : path_(std::move(path)), fd_(fd), size_(size) {}
  ~PosixRandomAccessFile() override { ::close(fd_); }
  void read(uint64_t offset, size_t size, void* out) const override {
    char* p = static_cast<char*>(out);
    uint64_t at = offset;
    while (size > 0) {
      ssize_t n = ::pread(fd_, p, size, off_t(at));
      if (n < 0 && errno == EINTR) continue;
      if (n < 0) failIo(path_, "read failed at byte offset " + std::to_string(at) + ": " + errnoText());
      if (n == 0) failIo(path_, "unexpected end of file at byte offset " + std::to_string(at));
      p += n;
      at += uint64_t(n);
      size -= size_t(n);
    }
  }
  uint64_t size() const override { return size_; }

 private:
  std::string path_;
  int fd_;
  uint64_t size_;
};

class PosixEnv : public Env {
 public:
  std::unique_ptr<WritableFile> newWritableFile(const std::string& path) override {
    int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
    if (fd < 0) failIo(path, "cannot create: " + errnoText());
    return std::make_unique<PosixWritableFile>(path, fd, 0);
  }
  std::unique_ptr<WritableFile> newAppendableFile(const std::string& path) override {
    int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
    if (fd < 0) failIo(path, "cannot open for append: " + errnoText());
    struct stat st;
    if (::fstat(fd, &st) != 0) {
      ::close(fd);
      failIo(path, "cannot stat: " + errnoText());
    }
    return std::make_unique<PosixWritableFile>(path, fd, uint64_t(st.st_size), true);
  }
  std::unique_ptr<WritableFile> newWritableFileAt(const std::string& path, uint64_t length) override {
    int fd = ::open(path.c_str(), O_WRONLY | (length == 0 ? O_CREAT : 0) | O_CLOEXEC, 0644);
    if (fd < 0) failIo(path, "cannot open to continue: " + errnoText());
    struct stat st;
    if (::fstat(fd, &st) != 0) {
      std::string why = errnoText();
      ::close(fd);
      failIo(path, "cannot stat: " + why);
    }
    if (uint64_t(st.st_size) < length) {
      ::close(fd);
      failCorrupt(path, "cannot continue at byte offset " + std::to_string(length) + ": the file has only " +
                            std::to_string(st.st_size) + " bytes");
    }
    if (::ftruncate(fd, off_t(length)) != 0 || ::lseek(fd, off_t(length), SEEK_SET) != off_t(length)) {
      std::string why = errnoText();
      ::close(fd);
      failIo(path, "cannot cut back to byte offset " + std::to_string(length) + ": " + why);
    }
    return std::make_unique<PosixWritableFile>(path, fd, length);
  }
  std::unique_ptr<RandomAccessFile> newRandomAccessFile(const std::string& path) override {
    int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) failIo(path, "cannot open: " + errnoText());
    struct stat st;
    if (::fstat(fd, &st) != 0) {
      ::close(fd);
      failIo(path, "cannot stat: " + errnoText());
    }
    return std::make_unique<PosixRandomAccessFile>(path, fd, uint64_t(st.st_size));
  }
  void renameFile(const std::string& from, const std::string& to) override {
    if (::rename(from.c_str(), to.c_str()) != 0) failIo(to, "cannot rename from " + from + ": " + errnoText());
  }
  void removeFile(const std::string& path) override {
    if (::unlink(path.c_str()) != 0 && errno != ENOENT) failIo(path, "cannot remove: " + errnoText());
  }
  void syncDir(const std::string& dir) override {
    int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0) failIo(dir, "cannot open directory: " + errnoText());
    int rc = ::fsync(fd);
    ::close(fd);
    if (rc != 0) failIo(dir, "fsync of directory failed: " + errnoText());
  }
  void createDir(const std::string& dir) override {
    if (::mkdir(dir.c_str(), 0755) != 0 && errno != EEXIST) failIo(dir, "cannot create directory: " + errnoText());
  }
  bool exists(const std::string& path) override {
    struct stat st;
    return ::stat(path.c_str(), &st) == 0;
  }
  std::vector<std::string> listDir(const std::string& dir) override {
    std::vector<std::string> names;
    DIR* d = ::opendir(dir.c_str());
    if (!d) failIo(dir, "cannot list directory: " + errnoText());
    while (dirent* e = ::readdir(d)) {
      std::string name = e->d_name;
      if (name != "." && name != "..") names.push_back(name);
    }
    ::closedir(d);
    return names;
  }
  uint64_t fileSize(const std::string& path) override {
    struct stat st;
    if (::stat(path.c_str(), &st) != 0) failIo(path, "cannot stat: " + errnoText());
    return uint64_t(st.st_size);
  }
};

// Passes writes and syncs through to the real file, consulting the FaultInjectionEnv first.
class FaultyWritableFile : public WritableFile {
 public:
  FaultyWritableFile(FaultInjectionEnv* env, std::string path, std::unique_ptr<WritableFile> base)
      : env_(env), path_(std::move(path)), base_(std::move(base)) {}
  void append(const void* data, size_t size) override {
    try {
      env_->hit(FaultInjectionEnv::Op::Write, path_);
    } catch (const Error&) {
      if (env_->partialWrites() && size > 1) base_->append(data, size / 2);
      throw;
    }
    base_->append(data, size);
  }
  void sync() override {
    env_->hit(FaultInjectionEnv::Op::Sync, path_);
    base_->sync();
  }
  void close() override { base_->close(); }
  uint64_t size() const override { return base_->size(); }
  void writeAt(uint64_t offset, const void* data, size_t size) override {
    env_->hit(FaultInjectionEnv::Op::Write, path_);
    base_->writeAt(offset, data, size);
  }

 private:
  FaultInjectionEnv* env_;
  std::string path_;
  std::unique_ptr<WritableFile> base_;
};

// Passes reads through to the real file, consulting the FaultInjectionEnv first.
class FaultyRandomAccessFile : public RandomAccessFile {
 public:
  FaultyRandomAccessFile(FaultInjectionEnv* env, std::string path, std::unique_ptr<RandomAccessFile> base)
      : env_(env), path_(std::move(path)), base_(std::move(base)) {}
  void read(uint64_t offset, size_t size, void* out) const override {
    env_->hit(FaultInjectionEnv::Op::Read, path_, " at byte offset " + std::to_string(offset));
    base_->read(offset, size, out);
  }
  uint64_t size() const override { return base_->size(); }

 private:
  FaultInjectionEnv* env_;
  std::string path_;
  std::unique_ptr<RandomAccessFile> base_;
};

}  // namespace

void readRanges(const RandomAccessFile& file, const std::vector<FileRange>& ranges, uint64_t parallelFrom) {
  constexpr size_t kChunk = size_t(1) << 20;
  constexpr unsigned kReaders = 4;
  uint64_t total = 0;
  for (const FileRange& r : ranges) total += r.bytes;
  const bool parallel = total >= parallelFrom;
  const size_t chunk = parallel ? kChunk : SIZE_MAX;  // one read a range when not parallel
  std::vector<FileRange> chunks;
  for (const FileRange& r : ranges)
    for (size_t at = 0; at < r.bytes; at += std::min(chunk, r.bytes - at))
      chunks.push_back({r.offset + at, std::min(chunk, r.bytes - at), static_cast<char*>(r.to) + at});
  // In file order, so that the first failure in it is the one thrown on either path.
  std::sort(chunks.begin(), chunks.end(), [](const FileRange& a, const FileRange& b) { return a.offset < b.offset; });
  if (!parallel) {
    for (const FileRange& c : chunks) file.read(c.offset, c.bytes, c.to);
    return;
  }
  std::vector<std::exception_ptr> errors(chunks.size());
  std::atomic<size_t> next{0}, firstFailed{chunks.size()};
  auto work = [&] {
    for (size_t c; (c = next.fetch_add(1)) < chunks.size();) {
      if (c > firstFailed.load()) continue;  // a chunk before it failed: nothing after it is wanted
      try {
        file.read(chunks[c].offset, chunks[c].bytes, chunks[c].to);
      } catch (...) {
        errors[c] = std::current_exception();
        for (size_t f = firstFailed.load(); c < f && !firstFailed.compare_exchange_weak(f, c);) {
        }
      }
    }
  };
  std::vector<std::thread> threads;
  threads.reserve(kReaders - 1);
  const unsigned n = unsigned(std::min<size_t>(kReaders, chunks.size()));
  try {
    for (unsigned t = 1; t < n; ++t) threads.emplace_back(work);
  } catch (...) {
    // No more threads to be had (a thread that failed to start was not made): the ones started
    // and this one read everything.
  }
  work();
  for (auto& t : threads) t.join();
  for (const auto& e : errors)
    if (e) std::rethrow_exception(e);
}

namespace {
std::atomic<Env*> gDefaultOverride{nullptr};
}  // namespace

Env* Env::Default() {
  static PosixEnv env;
  Env* override = gDefaultOverride.load(std::memory_order_acquire);
  return override ? override : &env;
}

ScopedDefaultEnv::ScopedDefaultEnv(Env* env) : previous_(gDefaultOverride.exchange(env)) {}
ScopedDefaultEnv::~ScopedDefaultEnv() { gDefaultOverride.store(previous_); }

std::unique_ptr<WritableFile> FaultInjectionEnv::newWritableFile(const std::string& path) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    written.insert(path);
  }
  return std::make_unique<FaultyWritableFile>(this, path, base_->newWritableFile(path));
}

std::unique_ptr<WritableFile> FaultInjectionEnv::newAppendableFile(const std::string& path) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    written.insert(path);
  }
  return std::make_unique<FaultyWritableFile>(this, path, base_->newAppendableFile(path));
}

std::unique_ptr<WritableFile> FaultInjectionEnv::newWritableFileAt(const std::string& path, uint64_t length) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    written.insert(path);
  }
  return std::make_unique<FaultyWritableFile>(this, path, base_->newWritableFileAt(path, length));
}

std::unique_ptr<RandomAccessFile> FaultInjectionEnv::newRandomAccessFile(const std::string& path) {
  return std::make_unique<FaultyRandomAccessFile>(this, path, base_->newRandomAccessFile(path));
}

void FaultInjectionEnv::renameFile(const std::string& from, const std::string& to) {
  hit(Op::Rename, to);
  base_->renameFile(from, to);
  std::lock_guard<std::mutex> lock(mutex_);
  written.insert(to);
}

void FaultInjectionEnv::syncDir(const std::string& dir) {
  hit(Op::DirSync, dir);
  base_->syncDir(dir);
}

void FaultInjectionEnv::hit(Op op, const std::string& path, const std::string& where) {
  static const char* const kNames[] = {"write", "fsync", "rename", "read", "directory fsync"};
  std::lock_guard<std::mutex> guard(mutex_);
  int64_t& counter = op == Op::Write    ? writes
                     : op == Op::Sync   ? syncs
                     : op == Op::Rename ? renames
                     : op == Op::Read   ? reads
                                        : dirSyncs;
  ++counter;
  if (remaining_ < 0 || op != op_) return;
  if (--remaining_ == 0) {
    remaining_ = -1;
    fired_ = true;
    failIo(path, std::string("injected ") + kNames[int(op)] + " failure" + where +
                     (errnum_ ? std::string(": ") + std::strerror(errnum_) : std::string()));
  }
}

}  // namespace mt
