// The build's work directory: ours or left alone (see build.h, kWorkMarker). A build empties or
// removes a directory only when it carries kWorkMarker, which only a build writes, in a directory
// it has just created itself. So a --work-dir naming a user's folder (".", the input's folder) is
// never emptied: the build works in a subdirectory of it instead.
#pragma once

#include <cstdint>
#include <string>

namespace mt {

// Inside the work directory: its lock, and the name of the temporary MT file beside the output
// (the name is unique to the process that started the build; a resumed build continues that file).
constexpr char kWorkLock[] = "LOCK";
constexpr char kTempNameFile[] = "output-temp-name";

struct WorkChoice {
  std::string dir;
  bool created = false;  // made by this run (else an earlier build's, ours by its marker)
};

// `requested` empty: OUT.work. A requested directory that exists without the marker: a
// subdirectory of it named after the output. Throws mt::Error when neither is ours to use.
WorkChoice chooseWorkDir(const std::string& output, const std::string& requested);

// The temporary MT file an earlier build in `work` recorded, or "" (also when the record does not
// name a temporary file of `output`: nothing else is ever opened, reused or removed through it).
std::string recordedTempPath(const std::string& work, const std::string& output);
void recordTempPath(const std::string& work, const std::string& tempPath);

// Empties a work directory of ours for a fresh start, keeping its marker and lock.
void clearWorkDir(const std::string& work);

// Bytes on disk (allocated blocks) of a file, or of every regular file under a directory.
uint64_t treeBytes(const std::string& path);

// A patch store directory (it has a CURRENT file).
bool isStoreDir(const std::string& path);

}  // namespace mt
