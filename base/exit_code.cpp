#include "base/exit_code.h"

#include <csignal>
#include <cstdio>
#include <new>
#include <stdexcept>
#include <string>
#include <system_error>

#include "base/interrupt.h"

namespace mt {

int exitCodeFor(ErrorKind kind, int signal) {
  switch (kind) {
    case ErrorKind::InvalidInput: return kExitInvalidInput;
    case ErrorKind::Corruption: return kExitCorruption;
    case ErrorKind::Io: return kExitIo;
    case ErrorKind::Resource: return kExitResource;
    case ErrorKind::Interrupted: return 128 + (signal > 0 ? signal : SIGINT);
  }
  return kExitInvalidInput;
}

ErrorKind errorKindOf(const std::exception& e) {
  if (auto* error = dynamic_cast<const Error*>(&e)) return error->kind();
  if (dynamic_cast<const std::bad_alloc*>(&e) || dynamic_cast<const std::length_error*>(&e))
    return ErrorKind::Resource;
  if (dynamic_cast<const std::system_error*>(&e)) return ErrorKind::Io;
  return ErrorKind::InvalidInput;
}

int exitCodeFor(const std::exception& e) {
  if (auto* interrupted = dynamic_cast<const Interrupted*>(&e)) return 128 + interrupted->signal();
  return exitCodeFor(errorKindOf(e));
}

const char* errorKindLabel(ErrorKind kind) {
  switch (kind) {
    case ErrorKind::InvalidInput: return "";
    case ErrorKind::Corruption: return "corrupt file";
    case ErrorKind::Io: return "I/O error";
    case ErrorKind::Resource: return "resource limit";
    case ErrorKind::Interrupted: return "";
  }
  return "";
}

int reportError(const char* tool, const std::exception& e) {
  std::fflush(stdout);
  std::string message = e.what();
  const std::string prefix = std::string(tool) + ": ";
  // Some layers already name the tool: do not say it twice.
  if (message.rfind(prefix, 0) == 0) message.erase(0, prefix.size());
  // The kind goes last, so the line still starts "TOOL: FILE: " as every message does.
  const char* label = errorKindLabel(errorKindOf(e));
  std::fprintf(stderr, "%s%s%s%s%s\n", prefix.c_str(), message.c_str(), *label ? " [" : "", label, *label ? "]" : "");
  return exitCodeFor(e);
}

}  // namespace mt
