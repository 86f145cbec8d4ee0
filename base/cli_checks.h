// Command-line checks shared by the tools that read MT files and by mtgen: CLI11 validators for
// counts and numbers with their range in the help and in the refusal, a parse that prints a bad
// command line as one "TOOL: ..." line with exit 1, and size options with a tool's own range.
//
// Own validators rather than CLI::Range because CLI::Range lets NaN through (every comparison
// with NaN is false), converts "-1" into a huge unsigned value when given unsigned bounds, and
// prints double bounds as 0.000000 - 1797693134862315708...
#pragma once

#include <CLI/CLI.hpp>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "base/error.h"
#include "base/size.h"

namespace mt::cli {

// "%g" without the exponent noise for the bounds people type (60000, 0.5, 1e+12 stays short).
inline std::string formatBound(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.10g", v);
  return buf;
}

// An integer in [lo, hi] written in decimal digits only: no sign, no fraction, no exponent, so
// "-1" cannot wrap into an unsigned option and "1e3" is not silently truncated.
inline CLI::Validator countIn(uint64_t lo, uint64_t hi) {
  const std::string range = "an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
  return CLI::Validator(
      [lo, hi, range](std::string& input) -> std::string {
        bool digits = !input.empty() && input.size() <= 20 &&
                      std::all_of(input.begin(), input.end(), [](char c) { return c >= '0' && c <= '9'; });
        errno = 0;
        const unsigned long long v = digits ? std::strtoull(input.c_str(), nullptr, 10) : 0;
        if (!digits || errno != 0 || v < lo || v > hi) return "must be " + range + ", got '" + input + "'";
        return std::string();
      },
      range);
}

// A finite number in the interval from lo to hi, each bound included unless `lowOpen` /
// `highOpen` (hi = infinity: no upper bound but finiteness); `unit` follows the interval in the
// messages ("ms", "pixels", "degrees").
struct Interval {
  double lo, hi;
  bool lowOpen = false, highOpen = false;
  std::string unit;
  // "a number in (0, 180) degrees", "a finite number >= 0 (object units)"
  std::string text() const {
    if (std::isinf(hi))
      return std::string("a finite number ") + (lowOpen ? "> " : ">= ") + formatBound(lo) +
             (unit.empty() ? "" : " (" + unit + ")");
    return std::string("a number in ") + (lowOpen ? "(" : "[") + formatBound(lo) + ", " + formatBound(hi) +
           (highOpen ? ")" : "]") + (unit.empty() ? "" : " " + unit);
  }
  bool contains(double v) const {
    return std::isfinite(v) && (lowOpen ? v > lo : v >= lo) && (highOpen ? v < hi : v <= hi);
  }
};

inline CLI::Validator numberIn(const Interval& r) {
  return CLI::Validator(
      [r](std::string& input) -> std::string {
        char* end = nullptr;
        errno = 0;
        const double v = input.empty() ? NAN : std::strtod(input.c_str(), &end);
        if (input.empty() || errno == ERANGE || *end != '\0' || !r.contains(v))
          return "must be " + r.text() + ", got '" + input + "'";
        return std::string();
      },
      r.text());
}

// Parses the command line. Returns -1 when the tool should go on; otherwise the exit code: 0
// after --help, 1 after a bad command line, reported as one line "TOOL: MESSAGE (see --help)".
inline int parse(CLI::App& app, int argc, char** argv, const char* tool) {
  try {
    app.parse(argc, argv);
    return -1;
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::string message = e.what();
    std::replace(message.begin(), message.end(), '\n', ' ');
    std::fprintf(stderr, "%s: %s (see --help)\n", tool, message.c_str());
    return 1;
  }
}

// A size option (parseSize's forms, "256M", "4G") within [minBytes, maxBytes]; the refusal names
// the option and gives the tool's range ("from 64K to 1024T").
inline uint64_t sizeOption(const std::string& text, const std::string& option, uint64_t minBytes, uint64_t maxBytes,
                           const std::string& minText, const std::string& maxText) {
  const std::string accepted = "(from " + minText + " to " + maxText +
                               ": a number with an optional unit K, M, G or T, powers of 1024, e.g. 256M, 4G)";
  uint64_t bytes = 0;
  try {
    bytes = parseSize(text);
  } catch (const Error& e) {
    // parseSize's reason ("invalid size unit in '12Q'"), with this option's range instead of its own.
    const std::string reason = e.what();
    throw Error(option + ": " + reason.substr(0, reason.find(" (")) + " " + accepted);
  }
  if (bytes < minBytes || bytes > maxBytes) throw Error(option + ": size '" + text + "' out of range " + accepted);
  return bytes;
}

}  // namespace mt::cli
