// Checks every tool makes on the files it is given, so that nothing of the user's is read as
// something it is not, or overwritten: inputs must be regular files (a FIFO, a device or a
// directory would block or mislead), an output may not be an input or a directory, and outputs
// are written under a name unique to the process and renamed over the final name only when
// complete.
#pragma once

#include <string>
#include <vector>

namespace mt {

class Env;

// Throws mt::Error "PATH: no such file" / "is a directory, not a mesh file" / "is a FIFO, not a
// regular file" ... unless `path` is a regular file (after following links). `expected` names
// what the tool wanted ("a mesh file", "an MT file").
void requireRegularFile(const std::string& path, const std::string& expected);

// Throws unless `output` can be written as a new file: it may not be an existing directory or
// non-regular file, its folder must exist, and it may not be any of `inputs` (the same file by
// device and inode, whatever the spelling of the path).
void checkOutputPath(const std::string& output, const std::vector<std::string>& inputs);

// True when both paths exist and name the same file (device and inode).
bool sameFile(const std::string& a, const std::string& b);

// "FINAL.tmp.PID.RANDOM": a temporary name beside `finalPath` that no other process uses.
std::string uniqueTempName(const std::string& finalPath);

// A small file (a report, a stats JSON) written whole under uniqueTempName(path) through `env`
// (nullptr: Env::Default()), synced, renamed over `path` and its folder synced: on any error
// (mt::Error naming the file or its folder, kind Io) nothing is left under either name.
void writeWholeFile(const std::string& path, const std::string& bytes, Env* env = nullptr);
void writeWholeFile(const std::string& path, const void* data, size_t size, Env* env = nullptr);

}  // namespace mt
