// libFuzzer target: the MT file reader (mtfile/mt_file.cpp) on arbitrary bytes: open() (header,
// footer, index and their cross-checks), then every patch read and decoded (at most 256), as
// mtinfo --check does. mt::Error is the expected answer to a damaged file.
#include <algorithm>

#include "fuzz/fuzz_util.h"
#include "mtfile/mt_file.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = mt::fuzz::scratchDir() + "/input.mt";
  mt::fuzz::writeFile(path, data, size);
  try {
    auto reader = mt::MtFileReader::open(path);
    const size_t patches = std::min<size_t>(reader->patches().size(), 256);
    for (size_t p = 0; p < patches; ++p) {
      try {
        mt::DecodedPatch d = reader->readPatch(uint32_t(p));
        for (uint32_t i : d.triangles)
          if (i >= d.vertexCount()) std::abort();
      } catch (const mt::Error&) {
      }
    }
  } catch (const mt::Error&) {
  }
  return 0;
}
