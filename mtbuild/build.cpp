// The level loop of the batched MT (BMT section 4, "the i-th simplification step"), the DAG it
// defines (sections 3.1, 4.1) and the MT file it streams (section 6). See build.h.
#include "mtbuild/build.h"

#include <tbb/global_control.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_arena.h>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <xxhash.h>

#include <algorithm>
#include <chrono>
#include <cerrno>
#include <cinttypes>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <sstream>
#include <unordered_map>

#include "base/byte_io.h"
#include "base/file_lock.h"
#include "base/interrupt.h"
#include "base/output_path.h"
#include "base/process.h"
#include "base/progress.h"
#include "mtbuild/mt_file.h"
#include "mtbuild/patch_codec.h"
#include "mtbuild/simplify_region.h"
#include "patchstore/heal/heal.h"
#include "patchstore/patch_store.h"

namespace mt {

namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

double secondsSince(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

struct Sphere {
  double c[3] = {0, 0, 0};
  double r = 0;
};

// Smallest-enough sphere around points: the box centre and the farthest point from it.
Sphere sphereOf(const std::vector<double>& positions) {
  Sphere s;
  if (positions.empty()) return s;
  double lo[3] = {positions[0], positions[1], positions[2]}, hi[3] = {lo[0], lo[1], lo[2]};
  for (size_t i = 0; i < positions.size(); i += 3)
    for (int a = 0; a < 3; ++a) {
      lo[a] = std::min(lo[a], positions[i + a]);
      hi[a] = std::max(hi[a], positions[i + a]);
    }
  for (int a = 0; a < 3; ++a) s.c[a] = 0.5 * (lo[a] + hi[a]);
  double r2 = 0;
  for (size_t i = 0; i < positions.size(); i += 3) {
    double d2 = 0;
    for (int a = 0; a < 3; ++a) d2 += (positions[i + a] - s.c[a]) * (positions[i + a] - s.c[a]);
    r2 = std::max(r2, d2);
  }
  s.r = std::sqrt(r2);
  return s;
}

// Grows s (keeping its centre) to contain t: the nesting the renderer relies on (BMT 5.1: "each
// bounding sphere encloses the bounding sphere of all the arcs in the subgraph").
void enclose(Sphere& s, const Sphere& t) {
  double d2 = 0;
  for (int a = 0; a < 3; ++a) d2 += (t.c[a] - s.c[a]) * (t.c[a] - s.c[a]);
  s.r = std::max(s.r, std::sqrt(d2) + t.r);
}

// Normal cone of a fragment's triangles: the mean normal and cos of the widest deviation; -1 when
// the triangles face every way (no back-face culling possible).
void normalCone(const std::vector<double>& p, const std::vector<uint32_t>& t, float axis[3], float& cutoff) {
  std::vector<double> normals;
  double sum[3] = {0, 0, 0};
  for (size_t i = 0; i < t.size(); i += 3) {
    const double *a = &p[3 * t[i]], *b = &p[3 * t[i + 1]], *c = &p[3 * t[i + 2]];
    double e1[3] = {b[0] - a[0], b[1] - a[1], b[2] - a[2]}, e2[3] = {c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
    double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    for (int k = 0; k < 3; ++k) sum[k] += n[k];
    if (len > 0)
      for (int k = 0; k < 3; ++k) normals.push_back(n[k] / len);
  }
  double len = std::sqrt(sum[0] * sum[0] + sum[1] * sum[1] + sum[2] * sum[2]);
  if (len == 0 || normals.empty()) {
    axis[0] = 0, axis[1] = 0, axis[2] = 1;
    cutoff = -1;
    return;
  }
  double minDot = 1;
  for (size_t i = 0; i < normals.size(); i += 3)
    minDot = std::min(minDot, (normals[i] * sum[0] + normals[i + 1] * sum[1] + normals[i + 2] * sum[2]) / len);
  for (int k = 0; k < 3; ++k) axis[k] = float(sum[k] / len);
  // Conservative: widen a little for the float axis; a cone past 90 degrees culls nothing useful.
  cutoff = minDot <= 0.01 ? -1.0f : float(minDot - 1e-4);
}

bool isStoreDir(const std::string& path) { return fs::is_directory(path) && fs::exists(path + "/CURRENT"); }

// ---- The work directory: ours or left alone ---------------------------------------------------
// A build empties or removes a directory only when it carries kWorkMarker, which only a build
// writes, in a directory it has just created itself. So a --work-dir naming a user's folder (".",
// the input's folder) is never emptied: the build works in a subdirectory of it instead.

// Inside the work directory: its lock, and the name of the temporary MT file beside the output
// (the name is unique to the process that started the build; a resumed build continues that file).
constexpr char kWorkLock[] = "LOCK";
constexpr char kTempNameFile[] = "output-temp-name";

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
  std::ofstream marker(fs::path(dir) / kWorkMarker);
  marker << "work directory of an MT build of " << fs::weakly_canonical(output, ec).string()
         << "; removed by the build when it completes\n";
  if (!marker) fail(dir, std::string("cannot write the marker ") + kWorkMarker);
  return true;
}

struct WorkChoice {
  std::string dir;
  bool created = false;  // made by this run (else an earlier build's, ours by its marker)
};

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

// The temporary MT file an earlier build in `work` recorded, or "" (also when the record does not
// name a temporary file of `output`: nothing else is ever opened, reused or removed through it).
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
  const std::string path = (fs::path(work) / kTempNameFile).string();
  std::ofstream f(path);
  f << fs::path(tempPath).filename().string() << "\n";
  f.flush();
  if (!f) fail(path, "cannot write");
}

// Empties a work directory of ours for a fresh start, keeping its marker and lock.
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

const char* signalName(int sig) { return sig == SIGINT ? "SIGINT" : sig == SIGTERM ? "SIGTERM" : "a signal"; }

// The modification time as "2026-12-02 05:27:00.123456789 UTC".
std::string utcTime(const struct timespec& t) {
  struct tm tm {};
  time_t sec = t.tv_sec;
  gmtime_r(&sec, &tm);
  char buf[64], out[96];
  std::strftime(buf, sizeof buf, "%Y-%m-%d %H:%M:%S", &tm);
  std::snprintf(out, sizeof out, "%s.%09ld UTC", buf, long(t.tv_nsec));
  return out;
}

// XXH3-64 of the whole file, streamed through an 8 MiB buffer (a 1 GB PLY: see docs/mtbuild.md).
uint64_t hashFile(const std::string& path) {
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) fail(path, std::string("cannot open: ") + std::strerror(errno));
  ::posix_fadvise(fd, 0, 0, POSIX_FADV_SEQUENTIAL);
  XXH3_state_t* state = XXH3_createState();
  XXH3_64bits_reset(state);
  std::vector<char> buf(8 << 20);
  uint64_t at = 0;
  for (;;) {
    ssize_t n = ::read(fd, buf.data(), buf.size());
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      std::string why = std::strerror(errno);
      XXH3_freeState(state);
      ::close(fd);
      fail(path, "read failed at byte offset " + std::to_string(at) + ": " + why);
    }
    if (n == 0) break;
    XXH3_64bits_update(state, buf.data(), size_t(n));
    at += uint64_t(n);
  }
  uint64_t h = XXH3_64bits_digest(state);
  XXH3_freeState(state);
  ::close(fd);
  return h;
}

// The quantization step: 1/8 of the mean edge length (estimated from a sample of patches): the
// quantization error (step * sqrt(3)/2) stays a fraction of an edge, and /16 measured 0.2 bytes
// per input triangle more (docs/mtbuild.md).
double chooseGridStep(const PatchStore& store) {
  std::vector<PatchId> ids = store.patchIds();
  double sum = 0;
  uint64_t edges = 0;
  size_t stride = std::max<size_t>(1, ids.size() / 64);
  for (size_t i = 0; i < ids.size(); i += stride) {
    Patch p = store.patch(ids[i]);
    for (size_t t = 0; t < p.triangles.size(); t += 3)
      for (int k = 0; k < 3; ++k) {
        const double *a = &p.positions[3 * p.triangles[t + k]], *b = &p.positions[3 * p.triangles[t + (k + 1) % 3]];
        sum += std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) + (a[2] - b[2]) * (a[2] - b[2]));
        ++edges;
      }
  }
  double mean = edges ? sum / double(edges) : 0;
  return mean > 0 ? mean / 8 : 1e-6;
}

std::vector<EncodedPatch> encodePatches(const std::vector<Patch>& patches, const QuantizationGrid& grid,
                                        const PatchCodecOptions& codec) {
  std::vector<EncodedPatch> out;
  for (const Patch& p : patches) {
    PatchInput in;
    in.positions = p.positions.data();
    in.vertexCount = p.vertexCount();
    in.triangles = p.triangles.data();
    in.triangleCount = p.triangleCount();
    in.normals = p.normals.empty() ? nullptr : p.normals.data();
    in.colors = p.colors.empty() ? nullptr : p.colors.data();
    EncodedPatch e;
    e.storeId = p.id;
    e.payload = encodePatch(in, grid, codec);
    e.triangles = p.triangleCount();
    e.vertices = p.vertexCount();
    out.push_back(std::move(e));
  }
  return out;
}

// The floor patches of an assembled region, rebuilt exactly (same local vertex order, same
// triangles) from the assembly: PatchStore::assemble appends each patch's triangles in id order
// and records each patch's local -> unified vertex map in unifiedOf. So a worker that only got the
// assembled mesh (mtcluster ranks have no store) encodes the same payloads as one that read them.
std::vector<Patch> floorPatches(const LoadedMesh& m) {
  if (m.unifiedOf.size() != m.patches.size()) fail("region", "assembled mesh has no per-patch vertex maps");
  std::vector<Patch> out(m.patches.size());
  std::vector<uint32_t> localOf(m.vertexCount(), kNoVertex);
  size_t t = 0;
  for (size_t k = 0; k < m.patches.size(); ++k) {
    Patch& p = out[k];
    p.id = m.patches[k];
    const std::vector<uint32_t>& map = m.unifiedOf[k];
    for (uint32_t v = 0; v < map.size(); ++v) {
      uint32_t u = map[v];
      if (u >= m.vertexCount() || localOf[u] != kNoVertex)
        fail("region", "patch " + std::to_string(p.id) + ": vertex " + std::to_string(v) + " maps to a unified vertex twice");
      localOf[u] = v;
      p.positions.insert(p.positions.end(), &m.positions[3 * size_t(u)], &m.positions[3 * size_t(u)] + 3);
      if (!m.normals.empty()) p.normals.insert(p.normals.end(), &m.normals[3 * size_t(u)], &m.normals[3 * size_t(u)] + 3);
      if (!m.colors.empty()) p.colors.insert(p.colors.end(), &m.colors[4 * size_t(u)], &m.colors[4 * size_t(u)] + 4);
    }
    for (; t < m.trianglePatch.size() && m.trianglePatch[t] == p.id; ++t)
      for (int c = 0; c < 3; ++c) p.triangles.push_back(localOf[m.triangles[3 * t + c]]);
    for (uint32_t u : map) localOf[u] = kNoVertex;
  }
  if (t != m.trianglePatch.size()) fail("region", "assembled triangles are not grouped by patch");
  return out;
}

// Bytes a region's task and result take as messages (the cluster's serializer writes these
// vectors back to back; used for the task-time log of plain mtbuild runs).
uint64_t taskBytes(const LoadedMesh& m) {
  uint64_t n = m.positions.size() * 8 + m.normals.size() * 4 + m.colors.size() + m.triangles.size() * 4 +
               m.trianglePatch.size() * 4 + m.locked.size() + m.patches.size() * 4;
  for (const auto& u : m.unifiedOf) n += u.size() * 4;
  return n;
}
uint64_t resultBytes(const RegionResult& r) {
  uint64_t n = 0;
  for (const EncodedPatch& e : r.encoded) n += e.payload.size() + 16;
  const ReplacementMesh& m = r.replacement;
  return n + m.positions.size() * 8 + m.normals.size() * 4 + m.colors.size() + m.triangles.size() * 4 +
         m.origin.size() * 4 + m.triangleCell.size() * 8;
}

uint64_t treeBytes(const std::string& path) {
  std::error_code ec;
  uint64_t n = 0;
  if (fs::is_regular_file(path, ec)) return fs::file_size(path, ec);
  for (auto it = fs::recursive_directory_iterator(path, ec); !ec && it != fs::recursive_directory_iterator(); it.increment(ec))
    if (it->is_regular_file(ec)) n += it->file_size(ec);
  return n;
}

// ---- Checkpoints ----------------------------------------------------------------------------

constexpr char kCheckpointBlob[] = "mtbuild.checkpoint";
constexpr uint64_t kCheckpointMagic = 0x31544b43544d4dull;  // "MMTCKT1"
constexpr uint32_t kCheckpointVersion = 3;  // 3: the input hash covers the whole file

// "key=value" lines: the input's identity and every option that changes the bytes (not --threads
// or --memory, which do not). Compared line by line so a refused resume can say what changed.
std::string fingerprint(const std::string& input, const BuildOptions& o, bool storeInput) {
  std::ostringstream s;
  std::error_code ec;
  s << "format=" << format::kVersion << "." << kCheckpointVersion << "\n";
  s << "input=" << fs::weakly_canonical(input, ec).string() << "\n";
  if (storeInput) {
    uint64_t h = 0;
    std::vector<std::pair<std::string, uint64_t>> files;
    for (auto it = fs::recursive_directory_iterator(input, ec); !ec && it != fs::recursive_directory_iterator(); it.increment(ec))
      if (it->is_regular_file(ec)) files.push_back({fs::relative(it->path(), input, ec).string(), it->file_size(ec)});
    std::sort(files.begin(), files.end());
    for (auto& [name, size] : files) {
      h = XXH64(name.data(), name.size(), h);
      h = XXH64(&size, sizeof size, h);
    }
    std::string current;
    if (FILE* f = std::fopen((input + "/CURRENT").c_str(), "rb")) {
      char buf[256];
      size_t n = std::fread(buf, 1, sizeof buf, f);
      current.assign(buf, n);
      std::fclose(f);
    }
    s << "input_store_files=" << files.size() << "\ninput_store_hash=" << std::hex << XXH64(current.data(), current.size(), h)
      << std::dec << "\n";
  } else {
    // Size, modification time (readable, for a refused resume's message) and a hash of every
    // byte: an edit anywhere is caught, even one that kept the size and restored the mtime.
    struct stat st {};
    if (::stat(input.c_str(), &st) != 0) fail(input, std::string("cannot stat: ") + std::strerror(errno));
    s << "input_size=" << uint64_t(st.st_size) << "\ninput_mtime=" << utcTime(st.st_mtim) << "\ninput_hash=" << std::hex
      << hashFile(input) << std::dec << "\n";
  }
  s << "partition=" << (o.partition == PartitionKind::Regular ? "regular" : "irregular") << "\n";
  s << "patch_triangles=" << o.patchTriangles << "\n";
  s << "codec=" << (o.codec == format::Codec::Draco ? "draco" : "meshopt") << "\n";
  s << "normals=" << (o.normals ? 1 : 0) << "\n";
  s << "simplifier=" << (o.simplifier == RegionSimplifier::Meshopt ? "meshopt" : "quadric") << "\n";
  s << "root_triangles=" << o.rootTriangles << "\n";
  return s.str();
}

// The first line that differs, as "key: A (checkpoint) vs B (this run)".
std::string fingerprintDifference(const std::string& saved, const std::string& now) {
  std::istringstream a(saved), b(now);
  std::string la, lb;
  while (true) {
    bool ga = bool(std::getline(a, la)), gb = bool(std::getline(b, lb));
    if (!ga && !gb) return "";
    if (la != lb || ga != gb) {
      std::string key = la.substr(0, la.find('='));
      if (key.empty()) key = lb.substr(0, lb.find('='));
      auto value = [](const std::string& l) { return l.find('=') == std::string::npos ? std::string("?") : l.substr(l.find('=') + 1); };
      return key + " was " + value(la) + " for the killed build, is " + value(lb) + " now";
    }
  }
}

struct ProducerEntry {
  PatchId patch;
  uint32_t node;
};

template <class T>
void putVector(ByteWriter& w, const std::vector<T>& v) {
  w.put<uint64_t>(v.size());
  if (!v.empty()) w.putRaw(v.data(), v.size() * sizeof(T));
}
template <class T>
std::vector<T> getVector(ByteReader& r) {
  uint64_t n = r.get<uint64_t>();
  if (n > (uint64_t(1) << 40) / sizeof(T)) fail("checkpoint", "vector of " + std::to_string(n) + " elements");
  std::vector<T> v(n);
  if (n) std::memcpy(v.data(), r.getRaw(n * sizeof(T)), n * sizeof(T));
  return v;
}

}  // namespace

std::string BuildReport::toJson() const {
  std::ostringstream s;
  s.precision(10);
  s << "{\n  \"input_triangles\": " << inputTriangles << ",\n  \"stored_triangles\": " << storedTriangles
    << ",\n  \"nodes\": " << nodes << ",\n  \"arcs\": " << arcs << ",\n  \"patches\": " << patches
    << ",\n  \"file_bytes\": " << fileBytes << ",\n  \"bytes_per_input_triangle\": "
    << (inputTriangles ? double(fileBytes) / double(inputTriangles) : 0) << ",\n  \"grid_step\": " << gridStep
    << ",\n  \"welded_vertices\": " << weldedVertices << ",\n  \"welded_triangles\": " << weldedTriangles
    << ",\n  \"ingest_seconds\": " << ingestSeconds << ",\n  \"build_seconds\": " << buildSeconds
    << ",\n  \"total_seconds\": " << totalSeconds << ",\n  \"input_triangles_per_second\": "
    << (totalSeconds > 0 ? double(inputTriangles) / totalSeconds : 0) << ",\n  \"peak_rss_bytes\": " << peakRssBytes
    << ",\n  \"resumed_at_level\": " << resumedAtLevel << ",\n  \"peak_temp_bytes\": " << peakTempBytes
    << ",\n  \"checkpoint_bytes\": " << checkpointBytes
    << extraJson << ",\n  \"levels\": [";
  for (size_t i = 0; i < levels.size(); ++i) {
    const LevelReport& l = levels[i];
    s << (i ? "," : "") << "\n    {\"level\": " << l.level << ", \"regions\": " << l.regions << ", \"triangles_in\": "
      << l.trianglesIn << ", \"triangles_out\": " << l.trianglesOut << ", \"max_error\": " << l.maxError
      << ", \"seconds\": " << l.seconds << "}";
  }
  s << "\n  ]\n}\n";
  return s.str();
}

// ---- The per-region work ----------------------------------------------------------------------

// Whether the live patches after `level` levels came out of simplification (level 0: the
// ingest's patches, in the scan's own order), which decides their triangle order in the file
// (PatchCodecOptions::simplified).
static bool isSimplifiedOutput(uint32_t level) { return level >= 1; }

RegionResult processRegion(const RegionTask& task, const RegionContext& ctx) {
  auto start = Clock::now();
  RegionResult out;
  const LoadedMesh& lm = task.mesh;
  const uint32_t L = ctx.partitionLevels;
  // The floor patches become the payloads of the arcs into this region's node.
  PatchCodecOptions codec = ctx.codec;
  codec.simplified = isSimplifiedOutput(task.level - 1);
  out.encoded = encodePatches(floorPatches(lm), ctx.grid, codec);
  // Simplify to about half with the region's border locked (BMT 4), split by V*(level).
  SimplifyRegionOptions so;
  so.simplifier = ctx.simplifier;
  so.gridStep = ctx.grid.step;
  for (int a = 0; a < 3; ++a) so.gridOrigin[a] = ctx.grid.origin[a];
  // At least one triangle: a region that had some must keep some, or its node would carry no
  // patch and have no arc to the sink (a one-triangle input built such a file).
  so.targetTriangles = std::max<size_t>(
      1, task.root ? std::min<size_t>(lm.triangleCount() / 2, ctx.rootTriangles / 2) : lm.triangleCount() / 2);
  SimplifiedRegion sr = simplifyRegion(lm, so);
  out.deviation = sr.error;
  ReplacementMesh& rep = out.replacement;
  rep.level = task.level;
  rep.origin = sr.origin;
  rep.triangles = sr.triangles;
  for (uint32_t o : sr.origin) {
    if (!lm.normals.empty()) rep.normals.insert(rep.normals.end(), &lm.normals[3 * o], &lm.normals[3 * o] + 3);
    if (!lm.colors.empty()) rep.colors.insert(rep.colors.end(), &lm.colors[4 * o], &lm.colors[4 * o] + 4);
  }
  rep.triangleCell.resize(sr.triangleCount());
  for (uint32_t t = 0; t < sr.triangleCount(); ++t) {
    uint64_t low = 0;
    if (task.level + 1 < L) {
      float c[3];
      triangleCentroid(&sr.positions[3 * sr.triangles[3 * t]], &sr.positions[3 * sr.triangles[3 * t + 1]],
                       &sr.positions[3 * sr.triangles[3 * t + 2]], c);
      low = ctx.sequence->cellOf(task.level + 1, c);
    }
    // The triangle belongs to region R by construction (BMT 4: "this simplified mesh portion ...
    // corresponds to a blue patch"), whatever its new centroid.
    rep.triangleCell[t] = uint64_t(task.root ? 0 : task.region) << 32 | low;
  }
  Sphere sphere = sphereOf(sr.positions);
  for (int a = 0; a < 3; ++a) out.sphere[a] = sphere.c[a];
  out.sphere[3] = sphere.r;
  normalCone(sr.positions, sr.triangles, out.coneAxis, out.coneCutoff);
  rep.positions = std::move(sr.positions);
  out.seconds = secondsSince(start);
  return out;
}

// ---- The level loop's state ---------------------------------------------------------------------

struct LevelBuilder::State {
  // First, so released last: after the temporary file is renamed or removed.
  std::unique_ptr<FileLock> outputLock, workLock;
  BuildOptions options;
  std::string input, output, work, storeDir;
  std::string tempPath;     // the MT file being written, beside the output
  bool workCreated = false;  // the work directory was made by this run
  bool noted = false;        // stopNote() said what was kept
  Clock::time_point t0, buildStart;
  std::unique_ptr<PatchStore> store;
  PartitionSequence sequence;
  std::string sequenceBytes;
  RegionContext ctx;
  std::string fingerprint;
  std::unique_ptr<MtFileWriter> writer;
  format::FileHeader header{};
  // The DAG so far (BMT 3.1). Node 0 is the source: the full-resolution fragment.
  std::vector<format::NodeRecord> nodes;
  std::vector<Sphere> spheres;
  std::map<std::pair<uint32_t, uint32_t>, std::vector<uint32_t>> arcPatches;  // (from, to) -> MT patch ids
  std::unordered_map<PatchId, uint32_t> producer;  // live store patch -> the node whose fragment holds it
  BuildReport report;
  uint64_t liveTriangles = 0;
  uint32_t builtLevels = 0;
  bool finished = false;   // no more levels to build
  bool completed = false;  // the file is written
  // The level in progress.
  std::vector<uint32_t> regionIds;
  std::vector<std::vector<PatchId>> floors;
  std::vector<uint64_t> floorTriangles;
  bool root = false;
  size_t nextCommit = 0;
  LevelReport lr;
  Clock::time_point levelStart;
  std::unique_ptr<Progress> progress;
  uint64_t doneTriangles = 0, outTriangles = 0;
  // Test hooks (SIGKILL at a chosen point, a pause after each region so that a test can signal a
  // running build) and the task-time log.
  long killAfterLevel = -1, killAfterRegions = -1, committedRegions = 0, regionPauseMs = 0;
  FILE* taskTimes = nullptr;

  // Checkpoint side file (see checkpointBytes): its committed length and chained hash, and how
  // many patch records / nodes it holds.
  uint64_t sideLength = 0, sideHash = 0;
  size_t ckPatches = 0, ckNodes = 0;
  std::string checkpointBytes() const;
  void appendSideChunk();
  std::vector<format::PatchRecord> readSideFile(uint64_t length, uint64_t hash);
  void restore(const std::string& bytes);
  void writeCheckpoint();
  void startFresh(bool storeInput);
  void say(const std::string& what) const {
    if (options.progress) std::fprintf(stderr, "%s: %s\n", options.toolName.c_str(), what.c_str());
  }
};

// The checkpoint is split in two so that it costs little memory and disk at any scale: what only
// grows (patch records, DAG nodes and spheres, arcs) is appended level by level to the side file
// OUT.work/checkpoint.dat, made durable before the store's commit; the store blob (committed with
// the level's write-backs) holds the small state, the producer map of the live patches, and the
// side file's length and chained XXH64 at that level. A resume reads the side file up to that
// length, so a chunk appended by a level that never committed is ignored and cut off.
std::string LevelBuilder::State::checkpointBytes() const {
  ByteWriter w;
  w.put<uint64_t>(kCheckpointMagic);
  w.put<uint32_t>(kCheckpointVersion);
  w.putString(fingerprint);
  w.put<uint32_t>(builtLevels);
  w.put<uint8_t>(finished ? 1 : 0);
  w.put<uint64_t>(liveTriangles);
  w.put(header);
  w.put<uint64_t>(writer->bytesWritten());
  w.put<uint64_t>(writer->patchCount());
  w.put<uint64_t>(nodes.size());
  w.put<uint64_t>(sideLength);
  w.put<uint64_t>(sideHash);
  std::vector<ProducerEntry> prod;
  for (auto& [id, node] : producer) prod.push_back({id, node});
  std::sort(prod.begin(), prod.end(), [](const ProducerEntry& a, const ProducerEntry& b) { return a.patch < b.patch; });
  putVector(w, prod);
  w.put<uint64_t>(report.inputTriangles);
  w.put<double>(report.gridStep);
  w.put<double>(report.ingestSeconds);
  w.put<uint64_t>(report.peakTempBytes);
  putVector(w, report.levels);
  w.put<uint64_t>(XXH64(w.bytes().data(), w.bytes().size(), 0));
  return w.bytes();
}

// Appends what grew since the last checkpoint to the side file and makes it durable.
void LevelBuilder::State::appendSideChunk() {
  ByteWriter w;
  const auto& records = writer->patchRecords();
  std::vector<format::PatchRecord> newRecords(records.begin() + long(ckPatches), records.end());
  putVector(w, newRecords);
  putVector(w, std::vector<format::NodeRecord>(nodes.begin() + long(ckNodes), nodes.end()));
  putVector(w, std::vector<Sphere>(spheres.begin() + long(ckNodes), spheres.end()));
  uint64_t arcs = 0;
  for (auto& [key, ids] : arcPatches) arcs += key.second >= ckNodes;
  w.put<uint64_t>(arcs);
  for (auto& [key, ids] : arcPatches)
    if (key.second >= ckNodes) {
      w.put<uint32_t>(key.first);
      w.put<uint32_t>(key.second);
      putVector(w, ids);
    }
  ByteWriter chunk;
  chunk.put<uint64_t>(w.bytes().size());
  chunk.putRaw(w.bytes().data(), w.bytes().size());
  const std::string path = work + "/checkpoint.dat";
  int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) fail(path, std::string("cannot open: ") + std::strerror(errno));
  // Cut off a chunk of a level that was never committed, then append.
  bool ok = ::ftruncate(fd, off_t(sideLength)) == 0 && ::lseek(fd, off_t(sideLength), SEEK_SET) == off_t(sideLength);
  const char* p = chunk.bytes().data();
  size_t left = chunk.bytes().size();
  while (ok && left > 0) {
    ssize_t n = ::write(fd, p, left);
    if (n < 0 && errno == EINTR) continue;
    ok = n > 0;
    if (ok) p += n, left -= size_t(n);
  }
  ok = ok && ::fdatasync(fd) == 0;
  std::string why = ok ? "" : std::strerror(errno);
  ::close(fd);
  if (!ok) fail(path, "cannot write the checkpoint at byte offset " + std::to_string(sideLength) + ": " + why);
  sideHash = XXH64(chunk.bytes().data(), chunk.bytes().size(), sideHash);
  sideLength += chunk.bytes().size();
  ckPatches = records.size();
  ckNodes = nodes.size();
}

// Reads the side file up to `length`, checking the chained hash; fills records, nodes, spheres, arcs.
std::vector<format::PatchRecord> LevelBuilder::State::readSideFile(uint64_t length, uint64_t hash) {
  const std::string path = work + "/checkpoint.dat";
  std::vector<format::PatchRecord> records;
  FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) fail(path, "cannot --resume: missing (rerun without --resume to start over)");
  uint64_t at = 0, h = 0;
  std::string chunk;
  while (at < length) {
    uint64_t size = 0;
    if (length - at < 8 || std::fread(&size, 8, 1, f) != 1 || size > length - at - 8) {
      std::fclose(f);
      fail(path, "cannot --resume: chunk at byte offset " + std::to_string(at) + " is truncated (rerun without --resume to start over)");
    }
    chunk.resize(size_t(size) + 8);
    std::memcpy(chunk.data(), &size, 8);
    if (size && std::fread(chunk.data() + 8, 1, size_t(size), f) != size) {
      std::fclose(f);
      fail(path, "cannot --resume: chunk at byte offset " + std::to_string(at) + " is truncated");
    }
    h = XXH64(chunk.data(), chunk.size(), h);
    ByteReader r(chunk.data() + 8, size_t(size), path, at + 8);
    for (auto& rec : getVector<format::PatchRecord>(r)) records.push_back(rec);
    for (auto& n : getVector<format::NodeRecord>(r)) nodes.push_back(n);
    for (auto& sp : getVector<Sphere>(r)) spheres.push_back(sp);
    uint64_t arcs = r.get<uint64_t>();
    for (uint64_t i = 0; i < arcs; ++i) {
      uint32_t from = r.get<uint32_t>(), to = r.get<uint32_t>();
      arcPatches[{from, to}] = getVector<uint32_t>(r);
    }
    at += chunk.size();
  }
  std::fclose(f);
  if (h != hash) fail(path, "cannot --resume: checksum mismatch before byte offset " + std::to_string(length) + " (rerun without --resume to start over)");
  sideLength = length;
  sideHash = hash;
  return records;
}

void LevelBuilder::State::restore(const std::string& bytes) {
  const std::string where = storeDir + " (blob " + kCheckpointBlob + ")";
  if (bytes.size() < 8 || XXH64(bytes.data(), bytes.size() - 8, 0) != [&] {
        uint64_t h;
        std::memcpy(&h, bytes.data() + bytes.size() - 8, 8);
        return h;
      }())
    fail(where, "checkpoint checksum mismatch (rerun without --resume to start over)");
  ByteReader r(bytes, where);
  if (r.get<uint64_t>() != kCheckpointMagic) fail(where, "not a checkpoint (bad magic at byte offset 0)");
  if (uint32_t v = r.get<uint32_t>(); v != kCheckpointVersion)
    fail(where, "checkpoint version " + std::to_string(v) + ", this build reads " + std::to_string(kCheckpointVersion));
  std::string saved = r.getString();
  if (saved != fingerprint)
    fail(work, "cannot --resume: the killed build used other input or options (" + fingerprintDifference(saved, fingerprint) +
                   "); rerun without --resume to start over");
  builtLevels = r.get<uint32_t>();
  finished = r.get<uint8_t>() != 0;
  liveTriangles = r.get<uint64_t>();
  header = r.get<format::FileHeader>();
  report.weldedVertices = header.weldedVertices;
  report.weldedTriangles = header.weldedTriangles;
  uint64_t length = r.get<uint64_t>();
  uint64_t patchCount = r.get<uint64_t>(), nodeCount = r.get<uint64_t>();
  uint64_t sideLen = r.get<uint64_t>(), sideH = r.get<uint64_t>();
  for (const ProducerEntry& e : getVector<ProducerEntry>(r)) producer[e.patch] = e.node;
  report.inputTriangles = r.get<uint64_t>();
  report.gridStep = r.get<double>();
  report.ingestSeconds = r.get<double>();
  report.peakTempBytes = r.get<uint64_t>();
  report.levels = getVector<LevelReport>(r);
  std::vector<format::PatchRecord> records = readSideFile(sideLen, sideH);
  if (records.size() != patchCount || nodes.size() != nodeCount || nodes.size() != spheres.size() || nodes.empty())
    fail(where, "checkpoint and " + work + "/checkpoint.dat disagree (rerun without --resume to start over)");
  ckPatches = records.size();
  ckNodes = nodes.size();
  for (PatchId id : store->patchIds())
    if (!producer.count(id)) fail(where, "checkpoint does not know live patch " + std::to_string(id));
  if (producer.size() != store->patchIds().size()) fail(where, "checkpoint names patches the store does not hold");
  writer = std::make_unique<MtFileWriter>(output, header, length, std::move(records), tempPath);
}

void LevelBuilder::State::writeCheckpoint() {
  // Payloads and the side file first: the checkpoint may only name bytes that are on disk. The
  // store then commits the level's write-backs and the checkpoint blob in one manifest edit
  // (store_format.h), so a kill at any point leaves either the previous level's state or this
  // one's, never a mix.
  writer->syncPayloads();
  appendSideChunk();
  std::string bytes = checkpointBytes();
  report.checkpointBytes = std::max<uint64_t>(report.checkpointBytes, bytes.size());
  store->putBlob(kCheckpointBlob, bytes);
  store->sync();
  report.peakTempBytes = std::max(report.peakTempBytes, treeBytes(work) + treeBytes(tempPath));
}

void LevelBuilder::State::startFresh(bool storeInput) {
  std::error_code ec;
  // An earlier build's work (ours by its marker, locked by us now) and its temporary file.
  if (std::string old = recordedTempPath(work, output); !old.empty()) fs::remove(old, ec);
  clearWorkDir(work);
  // 1. The level-0 patch store, partitioned by V*0 (BMT 4: "the mesh partitioned according to V*0").
  // Nothing to resume from yet: a failure (or a signal) here leaves no work directory behind.
  try {
    if (storeInput) {
      // The store's writer lock while its files are copied: the build is refused (with the
      // PID) while a heal writes it, and a heal started during the copy is refused, so no copy is
      // half one version, half another (a heal may compact, replacing segment files).
      FileLock inputLock(input + "/LOCK", input);
      fs::copy(input, storeDir, fs::copy_options::recursive, ec);
      if (ec) fail(input, "cannot copy the store into " + work + ": " + ec.message());
      fs::remove(storeDir + "/LOCK", ec);
    } else {
      VPartitionOptions vp;
      vp.kind = options.partition;
      vp.patchTriangles = options.patchTriangles ? options.patchTriangles : kDefaultMtPatchTriangles;
      VPartitionAssigner assigner(vp);
      IngestOptions io;
      io.memoryBytes = options.memoryBytes;
      io.progress = options.progress;
      PatchStore::ingest(input, storeDir, assigner, io);
    }
    store = PatchStore::open(storeDir);
    store->setAutoCommit(false);
    if (!loadStoreSequence(*store, sequence))
      fail(input, "the patch store was not made with a V-partition (ingest it with --partition irregular or regular)");
    // An empty surface (e.g. a heal removed every component) would give an MT file without
    // patches, which no reader accepts.
    if (store->info().triangles == 0)
      fail(input, storeInput ? "the patch store holds no triangles; nothing to build" : "has no triangles; nothing to build");
  } catch (...) {
    store.reset();
    fs::remove_all(work, ec);
    throw;
  }
  report.ingestSeconds = secondsSince(t0);
  StoreInfo info = store->info();
  report.inputTriangles = info.triangles;
  liveTriangles = info.triangles;

  // 2. The global quantization grid (mt_format.h): shared vertices quantize identically.
  QuantizationGrid grid = QuantizationGrid::fromBounds(info.bounds.lo, info.bounds.hi, chooseGridStep(*store));
  report.gridStep = grid.step;
  {
    heal::GridCells cells;
    for (int a = 0; a < 3; ++a) cells.origin[a] = grid.origin[a];
    cells.step = grid.step;
    heal::HealOptions ho;
    ho.memoryBytes = std::max<uint64_t>(options.memoryBytes / 4, 16ull << 20);
    ho.progress = options.progress;
    heal::PassReport w = heal::weldToGrid(*store, cells, ho);
    report.weldedVertices = w.get("merged");
    report.weldedTriangles = w.get("degenerate");
    if (report.weldedVertices) {
      say("grid weld: " + std::to_string(report.weldedVertices) + " vertices closer than the grid step (" +
          std::to_string(grid.step) + ") merged, " + std::to_string(report.weldedTriangles) +
          " triangles that became degenerate removed");
      info = store->info();
      liveTriangles = info.triangles;
    }
  }
  const double qError = grid.maxError();
  header = format::FileHeader{};
  header.codec = uint32_t(options.codec);
  header.vertexFlags = (options.normals ? format::kHasNormals : 0) | (info.layout.colors ? format::kHasColors : 0);
  header.payloadAlignment = format::kDefaultPayloadAlignment;
  header.inputTriangles = report.inputTriangles;
  header.inputVertices = info.vertices;  // (copies of shared vertices counted once per patch)
  header.weldedVertices = report.weldedVertices;
  header.weldedTriangles = report.weldedTriangles;
  for (int a = 0; a < 3; ++a) {
    header.boundsMin[a] = info.bounds.lo[a];
    header.boundsMax[a] = info.bounds.hi[a];
    header.gridOrigin[a] = grid.origin[a];
  }
  header.gridStep = grid.step;
  header.quantizationError = qError;
  header.gridBits = grid.bits;
  tempPath = uniqueTempName(output);
  recordTempPath(work, tempPath);
  writer = std::make_unique<MtFileWriter>(output, header, tempPath);
  header = writer->header();

  // 3. The DAG. Node 0 is the source: the full-resolution fragment (BMT 3.1).
  nodes.assign(1, format::NodeRecord{});
  spheres.assign(1, Sphere{});
  format::NodeRecord& source = nodes[0];
  for (int a = 0; a < 3; ++a) source.center[a] = 0.5 * (info.bounds.lo[a] + info.bounds.hi[a]);
  source.radius = 0;  // never refined past, so its sphere is not part of the nesting
  source.error = float(qError);
  source.coneCutoff = -1;
  source.coneAxis[2] = 1;
  source.level = 0;
  for (PatchId id : store->patchIds()) producer[id] = 0;
  // Checkpoint 0: a build killed from here on resumes without ingesting again.
  writeCheckpoint();
}

// ---- LevelBuilder -------------------------------------------------------------------------------

LevelBuilder::LevelBuilder(const std::string& input, const std::string& output, const BuildOptions& options)
    : s_(std::make_unique<State>()) {
  State& s = *s_;
  s.t0 = Clock::now();
  s.options = options;
  s.input = input;
  s.output = output;
  if (options.patchTriangles != 0 && (options.patchTriangles < kMinPatchTriangles || options.patchTriangles > kMaxPatchTriangles))
    throw Error("--patch-triangles " + std::to_string(options.patchTriangles) + ": out of range (accepted " +
                std::to_string(kMinPatchTriangles) + " to " + std::to_string(kMaxPatchTriangles) + ")");
  // Nothing is touched before the input and the output are known to be what they should.
  const bool storeInput = isStoreDir(input);
  if (!storeInput) requireRegularFile(input, "a mesh file (PLY, OBJ, OFF, STL) or a patch store");
  checkOutputPath(output, {input});
  // One build per output, one per work directory: a second one is refused (naming the first's
  // PID) before it removes or writes anything.
  s.outputLock = std::make_unique<FileLock>(output + ".lock", output);
  WorkChoice choice = chooseWorkDir(output, options.workDir);
  s.work = choice.dir;
  s.workCreated = choice.created;
  try {
    s.workLock = std::make_unique<FileLock>(s.work + "/" + kWorkLock, "work directory " + s.work);
  } catch (...) {
    std::error_code ec;
    if (s.workCreated) fs::remove_all(s.work, ec);
    throw;
  }
  s.workLock->keepFile();  // the directory goes as a whole, or stays for --resume
  s.storeDir = s.work + "/store";
  s.say("work directory " + s.work + (s.workCreated ? " (new)" : ""));
  // The level loop frees and allocates region buffers all the time; from a patch store (no
  // ingest, which sets the same) glibc's defaults returned and re-faulted them: 10M store, level
  // loop 12.5-14.2 s -> 11.4-12.4 s, sys 1.8 -> 0.7 s.
  useStreamingAllocator();
  if (const char* k = std::getenv("MT_TEST_KILL_AFTER_LEVEL")) s.killAfterLevel = std::atol(k);
  if (const char* k = std::getenv("MT_TEST_KILL_AFTER_REGIONS")) s.killAfterRegions = std::atol(k);
  if (const char* k = std::getenv("MT_TEST_PAUSE_MS_PER_REGION")) s.regionPauseMs = std::atol(k);
  s.fingerprint = fingerprint(input, options, storeInput);

  bool resumed = false;
  if (!s.workCreated) {
    const std::string recorded = recordedTempPath(s.work, output);
    if (!options.resume) {
      s.say("removing the work in " + s.work + " of an earlier build and starting over (--resume continues it)");
    } else if (!fs::exists(s.storeDir + "/CURRENT")) {
      s.say("--resume: " + s.work + " holds no finished ingest; starting from the input");
    } else {
      s.store = PatchStore::open(s.storeDir);
      std::string bytes = s.store->blob(kCheckpointBlob);
      if (bytes.empty()) {
        s.say("--resume: " + s.work + " has no checkpoint yet; starting from the input");
        s.store.reset();
      } else if (recorded.empty() || !fs::exists(recorded)) {
        s.say("--resume: the temporary file " + (recorded.empty() ? output + ".tmp.*" : recorded) +
              " of the stopped build is gone; starting from the input");
        s.store.reset();
      } else {
        s.store->setAutoCommit(false);
        if (!loadStoreSequence(*s.store, s.sequence)) fail(s.storeDir, "work store has no V-partition");
        s.tempPath = recorded;
        s.restore(bytes);
        s.report.resumedAtLevel = s.builtLevels;
        s.say("--resume: continuing after level " + std::to_string(s.builtLevels) + " from " + s.work + " and " + recorded);
        resumed = true;
      }
    }
  } else if (options.resume) {
    s.say("--resume: no work directory " + s.work + "; starting from the input");
  }
  if (!resumed) {
    try {
      s.startFresh(storeInput);
    } catch (const Interrupted& e) {
      throw BuildInterrupted(std::string("interrupted by ") + signalName(e.signal()) + " during the ingest; removed " + s.work +
                                 " (nothing to resume yet)",
                             e.signal());
    }
  }

  s.buildStart = Clock::now();
  s.sequenceBytes = s.sequence.serialize();
  const uint32_t patchTriangles = options.patchTriangles ? options.patchTriangles : kDefaultMtPatchTriangles;
  s.ctx.grid.step = s.header.gridStep;
  s.ctx.grid.bits = s.header.gridBits;
  for (int a = 0; a < 3; ++a) s.ctx.grid.origin[a] = s.header.gridOrigin[a];
  s.ctx.codec.codec = options.codec;
  s.ctx.codec.normals = options.normals;
  s.ctx.sequence = &s.sequence;
  s.ctx.partitionLevels = s.sequence.levels();
  s.ctx.simplifier = options.simplifier;
  s.ctx.rootTriangles = options.rootTriangles ? options.rootTriangles : 2ull * patchTriangles;
  if (!options.taskTimesPath.empty()) {
    s.taskTimes = std::fopen(options.taskTimesPath.c_str(), resumed ? "a" : "w");
    if (!s.taskTimes) fail(options.taskTimesPath, "cannot write");
    if (!resumed)
      std::fprintf(s.taskTimes,
                   "level,region,floor_patches,triangles_in,triangles_out,load_s,process_s,commit_s,task_bytes,result_bytes,moved_bytes\n");
  }
}

LevelBuilder::~LevelBuilder() {
  if (!s_) return;
  if (s_->taskTimes) std::fclose(s_->taskTimes);
  // Stopped by an error after a checkpoint: keep the temporary file beside the work directory so
  // that --resume can continue from the last finished level (the final name is never written).
  if (!s_->completed && s_->writer && s_->store) {
    if (!s_->noted) s_->say("stopped " + stopNote());
  }
}

std::string LevelBuilder::stopNote() {
  State& s = *s_;
  if (s.completed || !s.writer || !s.store) return "; nothing to resume";
  s.writer->detach();
  s.noted = true;
  const bool inLevel = s.progress && s.nextCommit < s.regionIds.size() && s.nextCommit > 0;
  std::string where = s.builtLevels == 0 ? "after the ingest" : "after level " + std::to_string(s.builtLevels);
  if (inLevel) where = "during level " + std::to_string(s.builtLevels + 1) + " (the checkpoint " + where + " is kept)";
  return where + "; kept " + s.work + " and " + s.tempPath + "; run the same command with --resume to continue";
}

const RegionContext& LevelBuilder::context() const { return s_->ctx; }
const std::string& LevelBuilder::sequenceBytes() const { return s_->sequenceBytes; }
const BuildOptions& LevelBuilder::options() const { return s_->options; }
const std::string& LevelBuilder::workDir() const { return s_->work; }
const std::string& LevelBuilder::tempPath() const { return s_->tempPath; }
uint32_t LevelBuilder::level() const { return s_->builtLevels + 1; }
size_t LevelBuilder::regionCount() const { return s_->regionIds.size(); }
uint64_t LevelBuilder::regionTriangles(size_t i) const { return s_->floorTriangles.at(i); }

bool LevelBuilder::beginLevel() {
  State& s = *s_;
  if (s.finished) return false;
  const uint32_t level = s.builtLevels;  // building level + 1 from V*level
  // Regions of V(level+1): patches grouped by the low half of their V*level key.
  std::map<uint32_t, std::vector<PatchId>> regions;
  std::map<uint32_t, uint64_t> triangles;
  for (PatchId id : s.store->patchIds()) {
    PatchMeta m = s.store->meta(id);
    regions[PartitionSequence::crossLow(m.cell)].push_back(id);
    triangles[PartitionSequence::crossLow(m.cell)] += m.triangles;
  }
  s.root = level + 1 >= s.ctx.partitionLevels;
  if (s.liveTriangles <= s.ctx.rootTriangles && level > 0) {
    s.finished = true;
    return false;
  }
  s.regionIds.clear();
  s.floors.clear();
  s.floorTriangles.clear();
  for (auto& [r, ids] : regions) {
    s.regionIds.push_back(r);
    s.floors.push_back(std::move(ids));
    s.floorTriangles.push_back(triangles[r]);
  }
  s.levelStart = Clock::now();
  s.lr = LevelReport{};
  s.lr.level = level + 1;
  s.lr.regions = uint32_t(s.regionIds.size());
  s.lr.trianglesIn = s.liveTriangles;
  s.nextCommit = 0;
  s.doneTriangles = s.outTriangles = 0;
  s.progress = std::make_unique<Progress>(
      s.options.progress, s.options.toolName + ": level " + std::to_string(level + 1) + "/" + std::to_string(s.ctx.partitionLevels),
      s.liveTriangles);
  return true;
}

RegionTask LevelBuilder::loadRegion(size_t i) const {
  const State& s = *s_;
  auto start = Clock::now();
  RegionTask task;
  task.level = s.builtLevels + 1;
  task.region = s.regionIds.at(i);
  task.root = s.root;
  std::vector<Patch> floor;
  for (PatchId id : s.floors[i]) floor.push_back(s.store->patch(id));
  task.mesh = s.store->assemble(floor);
  task.loadSeconds = secondsSince(start);
  return task;
}

void LevelBuilder::commitRegion(size_t i, RegionTask task, RegionResult result, uint64_t moveBytes) {
  State& s = *s_;
  if (i != s.nextCommit) fail(s.output, "region " + std::to_string(i) + " committed out of order");
  auto start = Clock::now();
  // Commit in region order: ids, payload order and node numbers do not depend on which worker
  // finished first.
  const uint32_t node = uint32_t(s.nodes.size());
  format::NodeRecord rec{};
  float predecessorError = 0;
  Sphere sphere;
  for (int a = 0; a < 3; ++a) sphere.c[a] = result.sphere[a];
  sphere.r = result.sphere[3];
  if (result.encoded.size() != task.mesh.patches.size()) fail(s.output, "region result has the wrong number of floor patches");
  for (size_t k = 0; k < result.encoded.size(); ++k) {
    const EncodedPatch& e = result.encoded[k];
    if (e.storeId != task.mesh.patches[k]) fail(s.output, "region result names the wrong floor patch");
    uint32_t from = s.producer.at(e.storeId);
    uint32_t mtPatch = s.writer->appendPatch(e.payload.data(), e.payload.size(), e.triangles, e.vertices);
    s.arcPatches[{from, node}].push_back(mtPatch);
    predecessorError = std::max(predecessorError, s.nodes[from].error);
    if (from != 0) enclose(sphere, s.spheres[from]);
    s.producer.erase(e.storeId);
  }
  // A real, monotone bound: the floor is within predecessorError of the input,
  // the new fragment within `deviation` of the floor.
  rec.error = std::nextafter(float(predecessorError + result.deviation), std::numeric_limits<float>::infinity());
  for (int a = 0; a < 3; ++a) rec.center[a] = sphere.c[a];
  rec.radius = std::nextafter(float(sphere.r), std::numeric_limits<float>::infinity());
  for (int a = 0; a < 3; ++a) rec.coneAxis[a] = result.coneAxis[a];
  rec.coneCutoff = result.coneCutoff;
  rec.level = task.level;
  rec.region = task.region;
  s.nodes.push_back(rec);
  s.spheres.push_back(sphere);
  std::vector<PatchId> created = s.store->writeBack(task.mesh, result.replacement);
  for (PatchId id : created) s.producer[id] = node;
  s.lr.maxError = std::max(s.lr.maxError, double(rec.error));
  const uint64_t in = task.mesh.triangleCount(), out = result.replacement.triangles.size() / 3;
  s.doneTriangles += in;
  s.outTriangles += out;
  s.progress->update(s.doneTriangles);
  ++s.nextCommit;
  if (s.taskTimes)
    std::fprintf(s.taskTimes, "%u,%u,%zu,%" PRIu64 ",%" PRIu64 ",%.6f,%.6f,%.6f,%" PRIu64 ",%" PRIu64 ",%" PRIu64 "\n", task.level,
                 task.region, task.mesh.patches.size(), in, out, task.loadSeconds, result.seconds, secondsSince(start),
                 taskBytes(task.mesh), resultBytes(result), moveBytes);
  // Temporary disk peaks inside a level too (new patches appended before the old ones' space is
  // reclaimed): sample it now and then.
  if (s.nextCommit % 32 == 0)
    s.report.peakTempBytes = std::max(s.report.peakTempBytes, treeBytes(s.work) + treeBytes(s.tempPath));
  if (s.killAfterRegions >= 0 && ++s.committedRegions > s.killAfterRegions) std::raise(SIGKILL);  // test hook
  if (s.regionPauseMs > 0) ::usleep(useconds_t(s.regionPauseMs) * 1000);                            // test hook
}

void LevelBuilder::endLevel() {
  State& s = *s_;
  if (s.nextCommit != s.regionIds.size()) fail(s.output, "level ended before all regions were committed");
  s.progress->finish(s.doneTriangles);
  s.lr.trianglesOut = s.outTriangles;
  s.lr.seconds = secondsSince(s.levelStart);
  s.report.levels.push_back(s.lr);
  s.liveTriangles = s.outTriangles;
  ++s.builtLevels;
  if (s.root || s.outTriangles <= s.ctx.rootTriangles || s.outTriangles * 10 > s.lr.trianglesIn * 9) s.finished = true;
  // The level is durable: the checkpoint a resumed build restarts from.
  s.writeCheckpoint();
  if (s.taskTimes) std::fflush(s.taskTimes);
  if (s.killAfterLevel >= 0 && long(s.builtLevels) >= s.killAfterLevel) std::raise(SIGKILL);  // test hook
}

BuildReport LevelBuilder::finish() {
  State& s = *s_;
  const uint32_t level = s.builtLevels;
  // 4. The sink: every remaining patch is on an arc from its producer to the sink (BMT 3.1: "all
  // the leaf nodes ... are connected through an arc to a dummy sink node").
  const uint32_t sink = uint32_t(s.nodes.size());
  {
    std::vector<PatchId> ids = s.store->patchIds();
    std::vector<Patch> top;
    for (PatchId id : ids) top.push_back(s.store->patch(id));
    PatchCodecOptions codec = s.ctx.codec;
    codec.simplified = isSimplifiedOutput(level);
    std::vector<EncodedPatch> encoded = encodePatches(top, s.ctx.grid, codec);
    for (const EncodedPatch& e : encoded) {
      uint32_t mtPatch = s.writer->appendPatch(e.payload.data(), e.payload.size(), e.triangles, e.vertices);
      s.arcPatches[{s.producer.at(e.storeId), sink}].push_back(mtPatch);
    }
    format::NodeRecord rec{};
    Sphere all;
    for (int a = 0; a < 3; ++a) all.c[a] = 0.5 * (s.header.boundsMin[a] + s.header.boundsMax[a]);
    for (size_t n = 1; n < s.nodes.size(); ++n) enclose(all, s.spheres[n]);
    for (int a = 0; a < 3; ++a) rec.center[a] = all.c[a];
    rec.radius = std::nextafter(float(all.r), std::numeric_limits<float>::infinity());
    rec.error = std::numeric_limits<float>::infinity();
    rec.coneCutoff = -1;
    rec.coneAxis[2] = 1;
    rec.level = level + 1;
    s.nodes.push_back(rec);
  }
  std::vector<DagArc> arcs;
  for (auto& [key, patches] : s.arcPatches) arcs.push_back({key.first, key.second, patches});
  BuildReport& report = s.report;
  s.writer->header().levelCount = level + 1;
  report.nodes = s.nodes.size();
  report.arcs = arcs.size();
  report.patches = s.writer->patchCount();
  report.peakTempBytes = std::max(report.peakTempBytes, treeBytes(s.work) + treeBytes(s.tempPath));
  s.writer->finish(std::move(s.nodes), std::move(arcs));
  report.fileBytes = fs::file_size(s.output);
  s.store.reset();
  // The work directory is ours (created by a build, marked): it goes as a whole.
  std::error_code ec;
  fs::remove_all(s.work, ec);
  report.buildSeconds = secondsSince(s.buildStart);
  report.totalSeconds = secondsSince(s.t0);
  report.peakRssBytes = peakRssBytes();
  auto reader = MtFileReader::open(s.output);
  report.storedTriangles = reader->header().storedTriangles;
  s.completed = true;
  return report;
}

// ---- mtbuild: the regions on threads ----------------------------------------------------------

// The level loop on threads; checks for SIGINT/SIGTERM between region commits and levels.
static BuildReport buildLevels(LevelBuilder& builder, const BuildOptions& options);

BuildReport buildMt(const std::string& input, const std::string& output, const BuildOptions& options) {
  std::unique_ptr<tbb::global_control> threadLimit;
  if (options.threads > 0)
    threadLimit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, options.threads);
  std::unique_ptr<LevelBuilder> owned = std::make_unique<LevelBuilder>(input, output, options);
  try {
    return buildLevels(*owned, options);
  } catch (const Interrupted& e) {
    // Say what was kept while the builder still knows, then let it close the files.
    std::string note = std::string("interrupted by ") + signalName(e.signal()) + " " + owned->stopNote();
    owned.reset();
    throw BuildInterrupted(note, e.signal());
  }
}

BuildReport buildLevels(LevelBuilder& builder, const BuildOptions& options) {
  const RegionContext& ctx = builder.context();
  checkInterrupt(options.toolName);
  struct Job {
    size_t index = 0;
    RegionTask task;
    RegionResult result;
  };
  while (builder.beginLevel()) {
    const size_t regions = builder.regionCount();
    std::vector<Job> jobs(regions);
    size_t next = 0;
    const size_t tokens = 2 * size_t(options.threads ? options.threads : tbb::this_task_arena::max_concurrency());
    tbb::parallel_pipeline(
        tokens,
        tbb::make_filter<void, Job*>(tbb::filter_mode::serial_in_order,
                                     [&](tbb::flow_control& fc) -> Job* {
                                       // A signal: start no more regions (the level is redone
                                       // from its checkpoint on --resume).
                                       if (next == regions || interruptRequested()) {
                                         fc.stop();
                                         return nullptr;
                                       }
                                       jobs[next].index = next;
                                       return &jobs[next++];
                                     }) &
            tbb::make_filter<Job*, Job*>(tbb::filter_mode::parallel,
                                         [&](Job* job) {
                                           job->task = builder.loadRegion(job->index);
                                           job->result = processRegion(job->task, ctx);
                                           return job;
                                         }) &
            tbb::make_filter<Job*, void>(tbb::filter_mode::serial_in_order, [&](Job* job) {
              checkInterrupt(options.toolName);  // a safe point: between region commits
              builder.commitRegion(job->index, std::move(job->task), std::move(job->result));
              *job = Job();  // free the region's memory now
            }));
    checkInterrupt(options.toolName);
    builder.endLevel();
    checkInterrupt(options.toolName);  // after the level's checkpoint
  }
  return builder.finish();
}

}  // namespace mt
