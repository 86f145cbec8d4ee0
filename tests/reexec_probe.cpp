// A probe for test_memory_plan's re-execution test: calls reexecWithMallocHugePages as the
// tools' main does, then prints what the process it ended in sees (the environment the
// re-execution set, and the arguments it was given again).
#include <cstdio>
#include <cstdlib>

#include "base/process.h"

int main(int argc, char** argv) {
  mt::reexecWithMallocHugePages(argv);
  const char* tunables = std::getenv("GLIBC_TUNABLES");
  const char* reexec = std::getenv("MT_HUGEPAGES_REEXEC");
  std::printf("tunables=%s\nreexec=%s\nargs=", tunables ? tunables : "(unset)", reexec ? reexec : "(unset)");
  for (int i = 1; i < argc; ++i) std::printf("%s%s", i > 1 ? " " : "", argv[i]);
  std::printf("\n");
  return 0;
}
