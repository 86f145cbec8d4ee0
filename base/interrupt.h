// SIGINT / SIGTERM as a request, not an abort: long-running tools install the handler, the work
// polls interruptRequested() at its safe points (between regions, levels, passes, chunks) and
// unwinds with Interrupted, so temporary files are removed or kept for --resume as on any error,
// and the tool can say what it kept. A second signal while stopping ends the process at once.
#pragma once

#include <string>

#include "base/error.h"

namespace mt {

// Thrown at a safe point after SIGINT/SIGTERM; the tool exits with 128 + signal().
class Interrupted : public Error {
 public:
  Interrupted(const std::string& where, int signal);
  int signal() const { return signal_; }

 private:
  int signal_;
};

// Installs the handlers for SIGINT and SIGTERM (idempotent).
void installInterruptHandlers();
// The signal received (SIGINT or SIGTERM), or 0.
int interruptRequested();
// Throws Interrupted("WHERE: interrupted by SIGxxx") when a signal was received.
void checkInterrupt(const std::string& where);
// For tests: forget a received signal.
void clearInterrupt();

}  // namespace mt
