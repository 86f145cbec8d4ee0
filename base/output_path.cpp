#include "base/output_path.h"

#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <random>

#include "base/env.h"
#include "base/error.h"

namespace mt {

namespace {

const char* kindOf(mode_t m) {
  if (S_ISDIR(m)) return "a directory";
  if (S_ISFIFO(m)) return "a FIFO";
  if (S_ISCHR(m)) return "a character device";
  if (S_ISBLK(m)) return "a block device";
  if (S_ISSOCK(m)) return "a socket";
  return "not a regular file";
}

}  // namespace

void requireRegularFile(const std::string& path, const std::string& expected) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) {
    if (errno == ENOENT || errno == ENOTDIR) fail(path, "no such file");
    fail(path, std::string("cannot open: ") + std::strerror(errno));
  }
  if (!S_ISREG(st.st_mode)) fail(path, std::string("is ") + kindOf(st.st_mode) + ", not " + expected);
}

bool sameFile(const std::string& a, const std::string& b) {
  struct stat sa {}, sb {};
  return ::stat(a.c_str(), &sa) == 0 && ::stat(b.c_str(), &sb) == 0 && sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
}

void checkOutputPath(const std::string& output, const std::vector<std::string>& inputs) {
  if (output.empty()) throw Error("the output name is empty");
  struct stat st {};
  if (::stat(output.c_str(), &st) == 0) {
    if (!S_ISREG(st.st_mode)) fail(output, std::string("is ") + kindOf(st.st_mode) + "; the output must be a file name");
    for (const std::string& in : inputs)
      if (sameFile(output, in)) fail(output, "is the input " + in + "; choose another output name (the input is never overwritten)");
  }
  std::filesystem::path parent = std::filesystem::path(output).parent_path();
  if (!parent.empty()) {
    std::error_code ec;
    if (!std::filesystem::is_directory(parent, ec)) fail(output, "the folder " + parent.string() + " does not exist");
  }
}

std::string uniqueTempName(const std::string& finalPath) {
  static thread_local std::mt19937_64 rng{std::random_device{}() ^ uint64_t(::getpid()) << 32};
  char buf[64];
  std::snprintf(buf, sizeof buf, ".tmp.%ld.%08llx", long(::getpid()), static_cast<unsigned long long>(rng() & 0xffffffffu));
  return finalPath + buf;
}

void writeWholeFile(const std::string& path, const std::string& bytes, Env* env) {
  writeWholeFile(path, bytes.data(), bytes.size(), env);
}

void writeWholeFile(const std::string& path, const void* data, size_t size, Env* env) {
  if (!env) env = Env::Default();
  const std::string tmp = uniqueTempName(path);
  try {
    auto f = env->newWritableFile(tmp);
    f->append(data, size);
    f->sync();
    f->close();
    env->renameFile(tmp, path);
  } catch (...) {
    try {
      env->removeFile(tmp);
    } catch (const Error&) {
    }
    throw;
  }
  // The rename is durable once the folder's entry is: without this fsync a crash can leave the
  // old file (or none) under `path` after the call returned. If it fails, the new name's
  // durability is unknown and the caller reports an error: nothing is left under it.
  const std::string parent = std::filesystem::path(path).parent_path().string();
  try {
    env->syncDir(parent.empty() ? "." : parent);
  } catch (...) {
    try {
      env->removeFile(path);
    } catch (const Error&) {
    }
    throw;
  }
}

}  // namespace mt
