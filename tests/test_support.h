// Small helpers shared by the tests: scratch directories, running the CLI tools, reading files.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "testing/test_meshes.h"

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

// A binary little-endian PLY of `mesh` with double coordinates (read back exactly).
void writePly(const std::string& path, const TestMesh& mesh);

// The scan-like model of the render suites: `mtgen --triangles TRIANGLES --holes 4 --seed 7` into
// dir/NAME.ply, then `mtbuild --patch-triangles 300 --threads 2` into dir/NAME.mt (40k triangles:
// ~250 patches over 5 levels). Returns the .mt path; throws std::runtime_error with the tools'
// output when either fails.
std::string buildScanMt(const TempDir& dir, const std::string& name, const std::string& triangles = "40k");
// mtbuild --patch-triangles 300 --threads 2 of `mesh` (written as dir/NAME.ply) into dir/NAME.mt.
std::string buildMeshMt(const TempDir& dir, const std::string& name, const TestMesh& mesh);

// A CSV of numbers with a header line (mtrender --stats).
struct Csv {
  std::vector<std::string> header;
  std::vector<std::vector<double>> rows;
  size_t col(const std::string& name) const;  // throws std::runtime_error for an unknown column
  double at(size_t row, const std::string& name) const { return rows[row][col(name)]; }
  double last(const std::string& name) const { return rows.back()[col(name)]; }
  double sum(const std::string& name) const;
  std::vector<double> column(const std::string& name) const;
};
Csv readCsv(const std::string& path);
// "key value" lines (mtrender's summary) as a map from key to the rest of the line.
std::map<std::string, std::string> parseSummary(const std::string& output);

}  // namespace mt::test
