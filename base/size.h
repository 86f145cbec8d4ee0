// Sizes as people write them on a command line ("512M", "4G"), for every tool's memory and
// cache options: one parser, so every tool accepts and refuses the same text.
#pragma once

#include <cstdint>
#include <string>

namespace mt {

// "256M", "4G", "512MiB", "1000000" -> bytes (units are powers of 1024). Throws mt::Error, with
// the accepted form and range, on garbage, NaN, infinity, a sign, zero, less than one byte or
// more than 1 PiB; the message starts with "OPTION: " when `option` is given.
uint64_t parseSize(const std::string& text, const std::string& option = {});

}  // namespace mt
