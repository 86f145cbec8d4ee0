// Exit codes by error kind: the one mapping every tool uses, so a script can tell a damaged file
// from a failing disk from a bad option without reading the message (README "Exit codes").
//
//   0    success
//   1    invalid input: the user's options or input file (also a command-line parse error)
//   3    corruption: a file we wrote (MT file, store, checkpoint) is damaged or truncated
//   4    I/O error: the system failed an open, read, write, fsync, rename (disk full included)
//   5    resource: memory, disk space or a limit is too small for the job
//   130  SIGINT, 143 SIGTERM (128 + the signal): stopped at a safe point
//
// 2 is left out on purpose: shells and test harnesses use it for their own usage errors.
#pragma once

#include <exception>

#include "base/error.h"

namespace mt {

constexpr int kExitInvalidInput = 1;
constexpr int kExitCorruption = 3;
constexpr int kExitIo = 4;
constexpr int kExitResource = 5;

// The exit code of an error of this kind; `signal` is used for Interrupted (0: SIGINT).
int exitCodeFor(ErrorKind kind, int signal = 0);
// The kind of any exception: mt::Error's own kind; std::bad_alloc and std::length_error are a
// resource; std::system_error (std::filesystem_error included) an I/O error; anything else invalid
// input.
ErrorKind errorKindOf(const std::exception& e);
// The exit code of any exception (mt::Interrupted gives 128 + its signal).
int exitCodeFor(const std::exception& e);
// Prints one line "TOOL: MESSAGE[ [KIND]]" to stderr (KIND for every kind but invalid input, e.g.
// "mtinfo: x.mt: patch 3: checksum mismatch [corrupt file]") and returns exitCodeFor(e): a tool's
// catch-all ends with `return mt::reportError("tool", e);`.
int reportError(const char* tool, const std::exception& e);
// The word printed before the message for a kind ("corrupt file", "I/O error", "resource limit"),
// empty for invalid input.
const char* errorKindLabel(ErrorKind kind);

}  // namespace mt
