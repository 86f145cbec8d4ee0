// The patch store's fuzz targets: a small committed store (fuzz/store/, made by mtstore ingest) is
// copied to scratch once; each input replaces one of its files (the manifest or the segment), and
// the store is opened and every patch read, as a reader process would. mt::Error is the expected
// answer to a damaged store.
#pragma once

#include <filesystem>
#include <fstream>
#include <string>

#include "fuzz/fuzz_util.h"
#include "patchstore/patch_store.h"

namespace mt::fuzz {

// The store's copy in scratch, and the path of its file named by `pick` ("MANIFEST" for the live
// manifest, "SEG" for the first segment).
inline std::string storeFile(const std::string& pick) {
  namespace fs = std::filesystem;
  static const std::string dir = [] {
    const std::string d = scratchDir() + "/store";
    fs::copy(MT_FUZZ_STORE_TEMPLATE, d, fs::copy_options::recursive | fs::copy_options::overwrite_existing);
    return d;
  }();
  if (pick == "MANIFEST") {
    std::ifstream current(dir + "/CURRENT");
    std::string name;
    std::getline(current, name);
    return dir + "/" + name;
  }
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().filename().string().rfind("SEG-", 0) == 0) return e.path().string();
  std::abort();
}

inline void openAndReadStore(const std::string& file, const uint8_t* data, size_t size) {
  writeFile(file, data, size);
  try {
    auto store = PatchStore::open(std::filesystem::path(file).parent_path().string());
    (void)store->info();
    size_t n = 0;
    for (PatchId id : store->patchIds()) {
      if (++n > 64) break;
      try {
        Patch p = store->patch(id);
        for (uint32_t i : p.triangles)
          if (i >= p.positions.size() / 3) std::abort();
      } catch (const mt::Error&) {
      }
    }
  } catch (const mt::Error&) {
  }
}

}  // namespace mt::fuzz
