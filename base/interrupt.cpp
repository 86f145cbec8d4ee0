#include "base/interrupt.h"

#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <cstring>

namespace mt {

namespace {

std::atomic<int> g_signal{0};

extern "C" void onInterrupt(int sig) {
  if (g_signal.exchange(sig) != 0) {
    // Second signal: the user insists. Restore the default action and re-raise.
    ::signal(sig, SIG_DFL);
    ::raise(sig);
    return;
  }
  const char msg[] = "\nstopping at the next safe point (signal again to stop at once)...\n";
  ssize_t ignored = ::write(2, msg, sizeof msg - 1);
  (void)ignored;
}

}  // namespace

Interrupted::Interrupted(const std::string& where, int signal)
    : Error(where + ": interrupted by " + (signal == SIGTERM ? "SIGTERM" : signal == SIGINT ? "SIGINT" : "a signal"),
            ErrorKind::Interrupted),
      signal_(signal) {}

void installInterruptHandlers() {
  struct sigaction sa {};
  sa.sa_handler = onInterrupt;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = SA_RESTART;  // reads and writes carry on; the work stops at its next safe point
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
}

int interruptRequested() { return g_signal.load(std::memory_order_relaxed); }

void checkInterrupt(const std::string& where) {
  if (int sig = interruptRequested()) throw Interrupted(where, sig);
}

void clearInterrupt() { g_signal.store(0); }

}  // namespace mt
