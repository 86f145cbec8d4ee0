#include "tests/test_support.h"

#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace mt::test {

TempDir::TempDir() {
  const char* base = std::getenv("TMPDIR");
  std::string tmpl = std::string(base && *base ? base : "/tmp") + "/mt-test-XXXXXX";
  if (!mkdtemp(tmpl.data())) throw std::runtime_error("mkdtemp failed");
  path_ = tmpl;
}

TempDir::~TempDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

std::string binDir() { return MT_BIN_DIR; }

CommandResult runTool(const std::string& tool, const std::string& args) {
  return runShell(binDir() + "/" + tool + " " + args);
}

CommandResult runShell(const std::string& command) {
  const std::string cmd = command + " 2>&1";
  CommandResult result;
  FILE* pipe = popen(cmd.c_str(), "r");
  if (!pipe) throw std::runtime_error("popen failed: " + cmd);
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, pipe)) > 0) result.output.append(buf, n);
  int status = pclose(pipe);
  result.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

std::string readFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

void writeFile(const std::string& path, const std::string& bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), std::streamsize(bytes.size()));
}

bool fileExists(const std::string& path) { return std::filesystem::exists(path); }

std::string writeNonManifoldPly(const TempDir& dir) {
  const int n = 60;
  std::vector<std::array<double, 3>> v;
  std::vector<std::array<int, 3>> f;
  for (int sheet = 0; sheet < 2; ++sheet)
    for (int i = 0; i <= n; ++i)
      for (int j = 0; j <= n; ++j) {
        double x = double(i) / n - 0.5, t = double(j) / n - 0.5, w = 0.02 * std::sin(9 * x) * std::cos(7 * t);
        if (j == n / 2) w = 0;
        v.push_back(sheet == 0 ? std::array<double, 3>{x, t, w} : std::array<double, 3>{x, w, t});
      }
  auto id = [&](int sheet, int i, int j) {
    if (sheet == 1 && j == n / 2) return i * (n + 1) + n / 2;  // the shared row: sheet 0's vertices
    return sheet * (n + 1) * (n + 1) + i * (n + 1) + j;
  };
  for (int sheet = 0; sheet < 2; ++sheet)
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) {
        f.push_back({id(sheet, i, j), id(sheet, i + 1, j), id(sheet, i + 1, j + 1)});
        f.push_back({id(sheet, i, j), id(sheet, i + 1, j + 1), id(sheet, i, j + 1)});
      }
  std::string ply = "ply\nformat ascii 1.0\nelement vertex " + std::to_string(v.size()) +
                    "\nproperty double x\nproperty double y\nproperty double z\nelement face " + std::to_string(f.size()) +
                    "\nproperty list uchar int vertex_indices\nend_header\n";
  char buf[128];
  for (auto& p : v) {
    std::snprintf(buf, sizeof buf, "%.17g %.17g %.17g\n", p[0], p[1], p[2]);
    ply += buf;
  }
  for (auto& t : f) ply += "3 " + std::to_string(t[0]) + " " + std::to_string(t[1]) + " " + std::to_string(t[2]) + "\n";
  std::string path = dir.file("nonmanifold.ply");
  writeFile(path, ply);
  return path;
}

void writePly(const std::string& path, const TestMesh& m) {
  std::ofstream out(path, std::ios::binary);
  out << "ply\nformat binary_little_endian 1.0\nelement vertex " << m.vertexCount()
      << "\nproperty double x\nproperty double y\nproperty double z\nelement face " << m.triangleCount()
      << "\nproperty list uchar int vertex_indices\nend_header\n";
  out.write(reinterpret_cast<const char*>(m.positions.data()), std::streamsize(m.positions.size() * sizeof(double)));
  for (size_t t = 0; t < m.triangleCount(); ++t) {
    const uint8_t three = 3;
    out.write(reinterpret_cast<const char*>(&three), 1);
    const int32_t idx[3] = {int32_t(m.triangles[3 * t]), int32_t(m.triangles[3 * t + 1]), int32_t(m.triangles[3 * t + 2])};
    out.write(reinterpret_cast<const char*>(idx), sizeof idx);
  }
}

namespace {
std::string buildFromPly(const TempDir& dir, const std::string& name) {
  const std::string mt = dir.file(name + ".mt");
  const CommandResult b = runTool("mtbuild", dir.file(name + ".ply") + " -o " + mt + " --patch-triangles 300 --threads 2 -q");
  if (b.exitCode != 0) throw std::runtime_error("mtbuild " + name + ": " + b.output);
  return mt;
}
}  // namespace

std::string buildScanMt(const TempDir& dir, const std::string& name, const std::string& triangles) {
  const CommandResult g = runTool("mtgen", "-o " + dir.file(name + ".ply") + " --triangles " + triangles + " --holes 4 --seed 7");
  if (g.exitCode != 0) throw std::runtime_error("mtgen " + name + ": " + g.output);
  return buildFromPly(dir, name);
}

std::string buildMeshMt(const TempDir& dir, const std::string& name, const TestMesh& mesh) {
  writePly(dir.file(name + ".ply"), mesh);
  return buildFromPly(dir, name);
}

size_t Csv::col(const std::string& name) const {
  for (size_t i = 0; i < header.size(); ++i)
    if (header[i] == name) return i;
  throw std::runtime_error("no column " + name);
}

double Csv::sum(const std::string& name) const {
  const size_t c = col(name);
  double s = 0;
  for (const auto& r : rows) s += r[c];
  return s;
}

std::vector<double> Csv::column(const std::string& name) const {
  const size_t c = col(name);
  std::vector<double> v;
  for (const auto& r : rows) v.push_back(r[c]);
  return v;
}

Csv readCsv(const std::string& path) {
  Csv csv;
  std::ifstream in(path);
  std::string line;
  bool first = true;
  while (std::getline(in, line)) {
    std::vector<std::string> cells;
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ',')) cells.push_back(cell);
    if (first) {
      csv.header = cells;
      first = false;
    } else {
      std::vector<double> r;
      for (const auto& c : cells) r.push_back(std::stod(c));
      csv.rows.push_back(r);
    }
  }
  return csv;
}

std::map<std::string, std::string> parseSummary(const std::string& output) {
  std::map<std::string, std::string> m;
  std::stringstream ss(output);
  std::string line;
  while (std::getline(ss, line)) {
    const auto sp = line.find(' ');
    if (sp != std::string::npos) m[line.substr(0, sp)] = line.substr(sp + 1);
  }
  return m;
}

}  // namespace mt::test
