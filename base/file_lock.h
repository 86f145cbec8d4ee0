// An advisory, exclusive lock on a path (flock on a small lock file, after LevelDB's LOCK):
// held by one process at a time, released by the kernel when the holder dies, so a lock file
// left behind by a killed process is never mistaken for a live holder. The lock file holds the
// holder's PID, so a refusal can name it.
#pragma once

#include <string>

namespace mt {

class FileLock {
 public:
  // Takes the lock on `lockPath` (created if missing) or throws mt::Error
  // "WHAT: in use by process PID (lock LOCKPATH)". `what` names the thing being locked (a store,
  // a work directory, an output) in the message.
  FileLock(const std::string& lockPath, const std::string& what);
  ~FileLock();  // removes the lock file, then releases the lock
  FileLock(const FileLock&) = delete;
  FileLock& operator=(const FileLock&) = delete;

  const std::string& path() const { return path_; }
  // Leaves the lock file in place on destruction (for a lock inside a directory that is being
  // removed anyway, or one that must outlive a rename).
  void keepFile() { removeOnRelease_ = false; }

  // The PID written in the lock file at `lockPath` if some live process holds it, else 0.
  static long holder(const std::string& lockPath);

 private:
  std::string path_;
  int fd_ = -1;
  bool removeOnRelease_ = true;
};

}  // namespace mt
