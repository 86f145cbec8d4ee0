#include "base/file_lock.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <string>

#include "base/error.h"

namespace mt {

namespace {

long readPid(int fd) {
  char buf[32] = {};
  ssize_t n = ::pread(fd, buf, sizeof buf - 1, 0);
  return n > 0 ? std::strtol(buf, nullptr, 10) : 0;
}

}  // namespace

FileLock::FileLock(const std::string& lockPath, const std::string& what) : path_(lockPath) {
  // A holder unlinks the lock file before it releases the lock, so a waiter may lock an inode
  // that no longer has the name: lock, then check the name still refers to what was locked.
  for (int attempt = 0; attempt < 100; ++attempt) {
    int fd = ::open(lockPath.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
    if (fd < 0) fail(lockPath, std::string("cannot create the lock file: ") + std::strerror(errno));
    if (::flock(fd, LOCK_EX | LOCK_NB) != 0) {
      int err = errno;
      long pid = readPid(fd);
      ::close(fd);
      if (err == EWOULDBLOCK)
        fail(what, "in use by " + (pid > 0 ? "process " + std::to_string(pid) : std::string("another process")) +
                       " (lock " + lockPath + "); wait for it to finish or stop it");
      fail(lockPath, std::string("cannot lock: ") + std::strerror(err));
    }
    struct stat held {}, named {};
    if (::fstat(fd, &held) == 0 && ::stat(lockPath.c_str(), &named) == 0 && held.st_ino == named.st_ino &&
        held.st_dev == named.st_dev) {
      std::string pid = std::to_string(long(::getpid())) + "\n";
      if (::ftruncate(fd, 0) != 0 || ::pwrite(fd, pid.data(), pid.size(), 0) != ssize_t(pid.size())) {
        ::close(fd);
        fail(lockPath, std::string("cannot write the lock file: ") + std::strerror(errno));
      }
      fd_ = fd;
      return;
    }
    ::close(fd);  // the name was unlinked (and maybe re-created) under us: try again
  }
  fail(lockPath, "cannot lock: the lock file keeps being replaced");
}

FileLock::~FileLock() {
  if (fd_ < 0) return;
  if (removeOnRelease_) ::unlink(path_.c_str());
  ::close(fd_);
}

long FileLock::holder(const std::string& lockPath) {
  int fd = ::open(lockPath.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return 0;
  long pid = 0;
  if (::flock(fd, LOCK_SH | LOCK_NB) != 0 && errno == EWOULDBLOCK) pid = std::max(1L, readPid(fd));
  ::close(fd);
  return pid;
}

}  // namespace mt
