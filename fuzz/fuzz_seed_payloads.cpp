// Not a fuzz target: writes the payloads of an MT file, one file each, as seeds of the patch
// decoders' targets (bench/fuzz.sh --seeds).  Usage: fuzz_seed_payloads IN.mt OUTDIR MAX
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "base/error.h"
#include "mtfile/mt_file.h"

int main(int argc, char** argv) {
  if (argc != 4) {
    std::fprintf(stderr, "usage: fuzz_seed_payloads IN.mt OUTDIR MAX\n");
    return 1;
  }
  try {
    auto reader = mt::MtFileReader::open(argv[1]);
    const size_t n = std::min<size_t>(reader->patches().size(), std::strtoul(argv[3], nullptr, 10));
    for (size_t p = 0; p < n; ++p) {
      std::vector<uint8_t> bytes = reader->readPayload(uint32_t(p));
      const std::string out = std::string(argv[2]) + "/" + std::string(argv[1]).substr(std::string(argv[1]).rfind('/') + 1) +
                              ".patch" + std::to_string(p);
      std::FILE* f = std::fopen(out.c_str(), "wb");
      if (!f || std::fwrite(bytes.data(), 1, bytes.size(), f) != bytes.size()) return 1;
      std::fclose(f);
    }
  } catch (const mt::Error& e) {
    std::fprintf(stderr, "fuzz_seed_payloads: %s\n", e.what());
    return 1;
  }
  return 0;
}
