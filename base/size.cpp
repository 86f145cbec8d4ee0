#include "base/size.h"

#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstring>

#include "base/error.h"

namespace mt {

uint64_t parseSize(const std::string& text, const std::string& option) {
  // The largest size accepted: far above any memory or cache this machine class has, and far
  // below 2^64, so a typo (99999T) is refused instead of ending in std::bad_alloc or wrapping.
  constexpr double kMaxBytes = double(uint64_t(1) << 50);  // 1 PiB
  const std::string where = option.empty() ? "" : option + ": ";
  const std::string accepted = "(from 1 byte to 1024T = 1 PiB: a number with an optional unit K, M, G or T, powers "
                               "of 1024, e.g. 1000000, 64K, 256M, 4G, 512MiB)";
  // Only plain decimal numbers: strtod alone would also take "nan", "inf", hex and leading blanks.
  size_t digits = 0;
  while (digits < text.size() && std::strchr("0123456789.eE+-", text[digits]) && text[digits] != '\0') ++digits;
  double value = 0;
  size_t pos = 0;
  if (digits > 0 && std::isdigit(static_cast<unsigned char>(text[0])) != 0) {
    const std::string number = text.substr(0, digits);
    char* end = nullptr;
    value = std::strtod(number.c_str(), &end);
    pos = size_t(end - number.c_str());
  }
  if (pos == 0) throw Error(where + "invalid size '" + text + "' " + accepted);
  std::string unit = text.substr(pos);
  for (auto& c : unit) c = char(std::toupper(static_cast<unsigned char>(c)));
  double mult = 1;
  if (unit == "" || unit == "B") mult = 1;
  else if (unit == "K" || unit == "KB" || unit == "KIB") mult = 1024.0;
  else if (unit == "M" || unit == "MB" || unit == "MIB") mult = 1024.0 * 1024;
  else if (unit == "G" || unit == "GB" || unit == "GIB") mult = 1024.0 * 1024 * 1024;
  else if (unit == "T" || unit == "TB" || unit == "TIB") mult = 1024.0 * 1024 * 1024 * 1024;
  else throw Error(where + "invalid size unit in '" + text + "' " + accepted);
  const double bytes = value * mult;
  if (!std::isfinite(bytes) || !(bytes >= 1) || bytes > kMaxBytes)
    throw Error(where + "size '" + text + "' out of range " + accepted);
  return uint64_t(bytes);
}

}  // namespace mt
