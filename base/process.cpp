#include "base/process.h"

#include <malloc.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>

namespace mt {

uint64_t peakRssBytes() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line))
    if (line.rfind("VmHWM:", 0) == 0) return std::stoull(line.substr(6)) * 1024;
  return 0;
}

void useStreamingAllocator() {
  mallopt(M_MMAP_THRESHOLD, 1 << 20);
  mallopt(M_TRIM_THRESHOLD, 8 << 20);
}

uint64_t currentRssBytes() {
  FILE* f = std::fopen("/proc/self/statm", "r");
  if (!f) return 0;
  unsigned long long size = 0, resident = 0;
  int n = std::fscanf(f, "%llu %llu", &size, &resident);
  std::fclose(f);
  return n == 2 ? uint64_t(resident) * uint64_t(sysconf(_SC_PAGESIZE)) : 0;
}

uint64_t openFileLimit() {
  static const uint64_t limit = [] {
    rlimit r{};
    if (getrlimit(RLIMIT_NOFILE, &r) != 0) return uint64_t(1024);
    const rlim_t want = r.rlim_max == RLIM_INFINITY ? rlim_t(65536) : std::min<rlim_t>(r.rlim_max, 65536);
    if (r.rlim_cur != RLIM_INFINITY && r.rlim_cur < want) {
      rlimit raised = r;
      raised.rlim_cur = want;
      if (setrlimit(RLIMIT_NOFILE, &raised) == 0) r = raised;
    }
    return r.rlim_cur == RLIM_INFINITY ? uint64_t(65536) : uint64_t(r.rlim_cur);
  }();
  return limit;
}

CpuSeconds processCpuSeconds() {
  rusage u{};
  if (getrusage(RUSAGE_SELF, &u) != 0) return {};
  CpuSeconds c;
  c.user = double(u.ru_utime.tv_sec) + double(u.ru_utime.tv_usec) * 1e-6;
  c.sys = double(u.ru_stime.tv_sec) + double(u.ru_stime.tv_usec) * 1e-6;
  return c;
}

namespace {

// MT_NO_HUGEPAGES=1: the user turned huge pages off.
bool hugePagesRefused() {
  const char* no = std::getenv("MT_NO_HUGEPAGES");
  return no && std::strcmp(no, "1") == 0;
}

// The kernel's transparent huge pages are on ("always [madvise] never": the bracketed word is the
// mode in force); off when the mode is never or cannot be read.
bool kernelHasHugePages() {
  std::ifstream thp("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string modes;
  return std::getline(thp, modes) && modes.find("[never]") == std::string::npos;
}

}  // namespace

void reexecWithMallocHugePages(char** argv) {
  if (hugePagesRefused()) return;
  // Once per run, whatever glibc makes of GLIBC_TUNABLES (2.36 rewrites the string in place).
  if (std::getenv("MT_HUGEPAGES_REEXEC")) return;
  const char* given = std::getenv("GLIBC_TUNABLES");
  if (given && std::strstr(given, "glibc.malloc.hugetlb")) return;
  const bool had = given != nullptr;
  const std::string tunables = had ? given : "";  // setenv may free what getenv returned
  if (!kernelHasHugePages()) return;
  std::string value = tunables.empty() ? std::string() : tunables + ":";
  value += "glibc.malloc.hugetlb=1";
  if (setenv("GLIBC_TUNABLES", value.c_str(), 1) != 0 || setenv("MT_HUGEPAGES_REEXEC", "1", 1) != 0) return;
  // The executable by its own path, so the process keeps its name ("exe" after an exec of
  // /proc/self/exe: ps, top and pgrep -x lost it); /proc/self/exe when the link cannot be read
  // or names a file no longer there.
  char self[4096];
  const ssize_t length = readlink("/proc/self/exe", self, sizeof self - 1);
  if (length > 0) {
    self[length] = 0;
    execv(self, argv);
  }
  execv("/proc/self/exe", argv);
  unsetenv("MT_HUGEPAGES_REEXEC");
  // The exec failed: run on without the tunable (and leave the variable as it was).
  if (had) setenv("GLIBC_TUNABLES", tunables.c_str(), 1);
  else unsetenv("GLIBC_TUNABLES");
}

void adviseHugePages(void* data, uint64_t bytes) {
#ifdef MADV_HUGEPAGE
  constexpr uintptr_t kHuge = uintptr_t(2) << 20;
  if (bytes < 2 * kHuge || !data) return;
  static const bool enabled = !hugePagesRefused() && kernelHasHugePages();  // read once
  if (!enabled) return;
  const uintptr_t begin = (reinterpret_cast<uintptr_t>(data) + kHuge - 1) & ~uintptr_t(kHuge - 1);
  const uintptr_t end = (reinterpret_cast<uintptr_t>(data) + uintptr_t(bytes)) & ~uintptr_t(kHuge - 1);
  if (end > begin) madvise(reinterpret_cast<void*>(begin), end - begin, MADV_HUGEPAGE);  // advice: failure is harmless
#else
  (void)data, (void)bytes;
#endif
}

}  // namespace mt
