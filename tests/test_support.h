// Small helpers shared by the tests: scratch directories, running the CLI tools, reading files.
#pragma once

#include <cstdint>
#include <string>

namespace mt::test {

// A fresh directory under $TMPDIR (or /tmp), removed with its contents on destruction.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  const std::string& path() const { return path_; }
  std::string file(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

struct CommandResult {
  int exitCode = -1;   // -1 when killed by a signal
  std::string output;  // stdout and stderr together
};

// Runs `tool args` where tool is an executable in build/bin (MT_BIN_DIR).
CommandResult runTool(const std::string& tool, const std::string& args);
// Runs a shell command line (stderr joined to stdout).
CommandResult runShell(const std::string& command);
std::string binDir();

std::string readFile(const std::string& path);
void writeFile(const std::string& path, const std::string& bytes);
bool fileExists(const std::string& path);

// An ascii PLY (dir/nonmanifold.ply, returned) of two wavy 60 x 60 grids crossing along a shared
// row of vertices: the edges of that row are used by four triangles (non-manifold in the input,
// which cuts must keep, not crack). 14400 triangles.
std::string writeNonManifoldPly(const TempDir& dir);

}  // namespace mt::test
