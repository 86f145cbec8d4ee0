// Error type shared by every layer. A message is one line and names the file and the element,
// byte offset or line where the problem is, so the CLIs can print it as is and exit 1.
#pragma once

#include <cstdint>
#include <stdexcept>
#include <string>

namespace mt {

class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message) : std::runtime_error(message) {}
};

// "FILE: MESSAGE"; a helper so every message has the same shape.
[[noreturn]] inline void fail(const std::string& file, const std::string& message) {
  throw Error(file + ": " + message);
}

}  // namespace mt
