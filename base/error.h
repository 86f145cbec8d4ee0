// Error type shared by every layer. A message is one line and names the file and the element,
// byte offset or line where the problem is, so the CLIs can print it as is (base/exit_code.h gives
// the exit code of its kind: 1 invalid input, 3 corruption, 4 I/O, 5 resource). Its kind
// says what went wrong, for callers that act on it (retry an I/O error, report damage, ask for
// more memory) and for tests: bad input from the user, a file of ours that is damaged, the system
// failing a read or write, a resource that is short, or a stop asked for by a signal.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>

namespace mt {

enum class ErrorKind {
  InvalidInput,  // the user's input or options (the default)
  Corruption,    // a file we wrote (store block, MT file, checkpoint) is damaged or truncated
  Io,            // the system failed an open, read, write, fsync, rename or remove
  Resource,      // memory, disk or a limit is too small for the job
  Interrupted,   // SIGINT/SIGTERM: stopped at a safe point (base/interrupt.h)
};

inline const char* errorKindName(ErrorKind kind) {
  switch (kind) {
    case ErrorKind::InvalidInput: return "invalid input";
    case ErrorKind::Corruption: return "corruption";
    case ErrorKind::Io: return "I/O error";
    case ErrorKind::Resource: return "resource";
    case ErrorKind::Interrupted: return "interrupted";
  }
  return "error";
}

class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message, ErrorKind kind = ErrorKind::InvalidInput)
      : std::runtime_error(message), kind_(kind) {}
  ErrorKind kind() const { return kind_; }

 private:
  ErrorKind kind_;
};

// "FILE: MESSAGE"; helpers so every message has the same shape.
[[noreturn]] inline void fail(const std::string& file, const std::string& message,
                              ErrorKind kind = ErrorKind::InvalidInput) {
  throw Error(file + ": " + message, kind);
}
[[noreturn]] inline void failCorrupt(const std::string& file, const std::string& message) {
  fail(file, message, ErrorKind::Corruption);
}
[[noreturn]] inline void failIo(const std::string& file, const std::string& message) {
  fail(file, message, ErrorKind::Io);
}

}  // namespace mt
