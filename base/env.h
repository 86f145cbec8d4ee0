// The file layer (after LevelDB's Env): every open, write, fsync, rename and remove of the patch
// store, the MT file's writer and reader and the builder's checkpoint files goes through here, so
// tests can inject failures and check that what is left is wholly the old file or wholly the new
// one, and that the error names the file and the byte offset.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <vector>

#include "base/error.h"

namespace mt {

class WritableFile {
 public:
  virtual ~WritableFile() = default;
  virtual void append(const void* data, size_t size) = 0;  // throws mt::Error
  virtual void sync() = 0;                                  // fdatasync; throws mt::Error
  virtual void close() = 0;
  virtual uint64_t size() const = 0;
  // Overwrites bytes already written (offset + size <= size()) without moving the end: a header
  // filled in once the rest is known. Not for files from newAppendableFile (O_APPEND would put
  // the bytes at the end). Throws mt::Error naming the file and offset.
  virtual void writeAt(uint64_t offset, const void* data, size_t size) = 0;
};

class RandomAccessFile {
 public:
  virtual ~RandomAccessFile() = default;
  // Reads exactly size bytes at offset or throws mt::Error naming the file and offset.
  virtual void read(uint64_t offset, size_t size, void* out) const = 0;
  virtual uint64_t size() const = 0;
};

// `bytes` of a file at `offset`, to be read into `to`.
struct FileRange {
  uint64_t offset;
  size_t bytes;
  void* to;
};

// Reads every range. When they add up to `parallelFrom` bytes or more, they are read in 1 MiB
// chunks by up to four threads at once: one read of tens of megabytes from a file not in the page
// cache waits on the disk one readahead window at a time, while several reads in flight keep the
// device's queue full (a billion-triangle MT file's 78 MB index, dropped from the page cache: 250
// ms as one read, 73-138 ms as four, on this project's VM; from the page cache the threads cost
// ~10 ms more). Throws what the file's read throws; with several failures, the one first in file
// order (the same message whatever the threads' timing; chunks after a failed one are not read).
void readRanges(const RandomAccessFile& file, const std::vector<FileRange>& ranges, uint64_t parallelFrom = uint64_t(4) << 20);

class Env {
 public:
  virtual ~Env() = default;
  // The process's Env: the POSIX one, or the one a ScopedDefaultEnv put in its place.
  static Env* Default();

  virtual std::unique_ptr<WritableFile> newWritableFile(const std::string& path) = 0;  // truncates
  virtual std::unique_ptr<WritableFile> newAppendableFile(const std::string& path) = 0;
  // Continues a file at byte `length`, cutting off whatever follows (a file written up to a
  // checkpoint that recorded its length; what came later is discarded). Creates the file when it
  // is missing and `length` is 0; a file shorter than `length` is damaged (Corruption).
  virtual std::unique_ptr<WritableFile> newWritableFileAt(const std::string& path, uint64_t length) = 0;
  virtual std::unique_ptr<RandomAccessFile> newRandomAccessFile(const std::string& path) = 0;
  virtual void renameFile(const std::string& from, const std::string& to) = 0;  // atomic
  virtual void removeFile(const std::string& path) = 0;
  virtual void syncDir(const std::string& dir) = 0;
  virtual void createDir(const std::string& dir) = 0;
  virtual bool exists(const std::string& path) = 0;
  virtual std::vector<std::string> listDir(const std::string& dir) = 0;
  virtual uint64_t fileSize(const std::string& path) = 0;
};

// For tests: makes Env::Default() return `env` while it lives, so code that takes no Env (the
// build, the tools' outputs) runs on a FaultInjectionEnv. Set it before any thread that may call
// Env::Default() starts, and let it go after they end.
class ScopedDefaultEnv {
 public:
  explicit ScopedDefaultEnv(Env* env);
  ~ScopedDefaultEnv();
  ScopedDefaultEnv(const ScopedDefaultEnv&) = delete;
  ScopedDefaultEnv& operator=(const ScopedDefaultEnv&) = delete;

 private:
  Env* previous_;
};

// Wraps another Env and fails the N-th write, fsync, rename, read or directory fsync from now on
// (counting from 1), by throwing mt::Error (Io) as a real failure would. Used by the crash-safety tests.
// failAfter's `errnum` (e.g. ENOSPC) puts the system's text for it in the message, as a real
// failure of that kind would ("...: injected write failure: No space left on device"); with
// `partial`, a failed write first writes half of its bytes (a disk that fills mid-write).
class FaultInjectionEnv : public Env {
 public:
  enum class Op { Write, Sync, Rename, Read, DirSync };
  explicit FaultInjectionEnv(Env* base) : base_(base) {}
  void failAfter(Op op, int64_t count, int errnum = 0, bool partial = false) {
    op_ = op;
    remaining_ = count;
    errnum_ = errnum;
    partial_ = partial;
  }
  bool partialWrites() const { return partial_; }
  void disarm() { remaining_ = -1; }
  bool fired() const { return fired_; }
  // Counts of each operation so far (to enumerate every failure point in a test). Reads may come
  // from several threads at once (the MT reader's): hit() counts under a lock.
  int64_t writes = 0, syncs = 0, renames = 0, reads = 0, dirSyncs = 0;
  // Every path opened for writing or renamed to through this Env (to check that a process wrote
  // nothing behind its back).
  std::set<std::string> written;

  std::unique_ptr<WritableFile> newWritableFile(const std::string& path) override;
  std::unique_ptr<WritableFile> newAppendableFile(const std::string& path) override;
  std::unique_ptr<WritableFile> newWritableFileAt(const std::string& path, uint64_t length) override;
  std::unique_ptr<RandomAccessFile> newRandomAccessFile(const std::string& path) override;
  void renameFile(const std::string& from, const std::string& to) override;
  void removeFile(const std::string& path) override { base_->removeFile(path); }
  void syncDir(const std::string& dir) override;
  void createDir(const std::string& dir) override { base_->createDir(dir); }
  bool exists(const std::string& path) override { return base_->exists(path); }
  std::vector<std::string> listDir(const std::string& dir) override { return base_->listDir(dir); }
  uint64_t fileSize(const std::string& path) override { return base_->fileSize(path); }

  // Called by the wrapped files; throws "PATH: injected OP failure WHERE" when the armed failure
  // is due (`where`: " at byte offset N" for a read).
  void hit(Op op, const std::string& path, const std::string& where = {});

 private:
  Env* base_;
  std::mutex mutex_;
  Op op_ = Op::Write;
  int64_t remaining_ = -1;
  int errnum_ = 0;
  bool partial_ = false;
  bool fired_ = false;
};

}  // namespace mt
