// The build's work directory: see work_dir.h.
#include "mtbuild/work_dir.h"

#include <sys/stat.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "base/env.h"
#include "base/error.h"
#include "mtbuild/build.h"

namespace mt {

namespace fs = std::filesystem;

namespace {

// Writes `text` as the whole of `path` and syncs it, through the Env.
void writeSmallFile(const std::string& path, const std::string& text) {
  std::unique_ptr<WritableFile> f = Env::Default()->newWritableFile(path);
  f->append(text.data(), text.size());
  f->sync();
  f->close();
}

bool hasWorkMarker(const std::string& dir) {
  std::error_code ec;
  return fs::is_regular_file(fs::path(dir) / kWorkMarker, ec);
}

// Creates `dir` (its parents too) and marks it ours; false when `dir` already exists.
bool createWorkDir(const std::string& dir, const std::string& output) {
  std::error_code ec;
  fs::path parent = fs::path(dir).parent_path();
  if (!parent.empty()) fs::create_directories(parent, ec);
  if (::mkdir(dir.c_str(), 0755) != 0) {
    if (errno == EEXIST) return false;
    fail(dir, std::string("cannot create the work directory: ") + std::strerror(errno));
  }
  // Through the Env like every file of a build (a full disk is an I/O error naming the file). A
  // directory whose marker could not be written is removed again: without its marker it would not
  // be recognised as ours, and --resume would refuse it.
  const std::string marker = (fs::path(dir) / kWorkMarker).string();
  try {
    writeSmallFile(marker, "work directory of an MT build of " + fs::weakly_canonical(output, ec).string() +
                               "; removed by the build when it completes\n");
  } catch (...) {
    fs::remove(marker, ec);
    fs::remove(dir, ec);
    throw;
  }
  return true;
}

}  // namespace

bool isStoreDir(const std::string& path) { return fs::is_directory(path) && fs::exists(path + "/CURRENT"); }

WorkChoice chooseWorkDir(const std::string& output, const std::string& requested) {
  auto oursOrRefuse = [&](const std::string& dir) -> WorkChoice {
    if (createWorkDir(dir, output)) return {dir, true};
    std::error_code ec;
    if (!fs::is_directory(dir, ec)) fail(dir, "exists and is not a directory; move it away or give another --work-dir");
    if (hasWorkMarker(dir)) return {dir, false};
    fail(dir, std::string("exists and was not made by a build (no ") + kWorkMarker +
                  " in it), so it is left alone; move it away or give another --work-dir");
  };
  if (requested.empty()) return oursOrRefuse(output + ".work");
  if (createWorkDir(requested, output)) return {requested, true};
  std::error_code ec;
  if (!fs::is_directory(requested, ec)) fail(requested, "--work-dir: exists and is not a directory");
  if (hasWorkMarker(requested)) return {requested, false};
  // A folder of the user's: work in a subdirectory of it, named after the output.
  return oursOrRefuse((fs::path(requested) / (fs::path(output).filename().string() + ".work")).string());
}

std::string recordedTempPath(const std::string& work, const std::string& output) {
  std::ifstream f(fs::path(work) / kTempNameFile);
  std::string name;
  if (!f || !std::getline(f, name)) return "";
  const std::string prefix = fs::path(output).filename().string() + ".tmp.";
  if (name.size() <= prefix.size() || name.compare(0, prefix.size(), prefix) != 0 || name.find('/') != std::string::npos)
    return "";
  return (fs::path(output).parent_path() / name).string();
}

void recordTempPath(const std::string& work, const std::string& tempPath) {
  writeSmallFile((fs::path(work) / kTempNameFile).string(), fs::path(tempPath).filename().string() + "\n");
}

void clearWorkDir(const std::string& work) {
  std::error_code ec;
  for (auto it = fs::directory_iterator(work, ec); !ec && it != fs::directory_iterator(); it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name == kWorkMarker || name == kWorkLock) continue;
    std::error_code rc;
    fs::remove_all(it->path(), rc);
    if (rc) fail(it->path().string(), "cannot remove (clearing the work directory of an earlier build): " + rc.message());
  }
}

uint64_t treeBytes(const std::string& path) {
  // Blocks allocated, not file sizes: scratch files read once have their read part given back
  // (TempReader::consumeAsRead), which their sizes do not show.
  auto allocated = [](const std::string& file) -> uint64_t {
    struct stat st;
    return ::stat(file.c_str(), &st) == 0 ? uint64_t(st.st_blocks) * 512 : 0;
  };
  std::error_code ec;
  uint64_t n = 0;
  if (fs::is_regular_file(path, ec)) return allocated(path);
  for (auto it = fs::recursive_directory_iterator(path, ec); !ec && it != fs::recursive_directory_iterator(); it.increment(ec))
    if (it->is_regular_file(ec)) n += allocated(it->path().string());
  return n;
}

}  // namespace mt
