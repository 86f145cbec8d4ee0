// mtinfo: what an MT file holds.
//   mtinfo OUT.mt [--json] [--check]
// Opening validates the header, the DAG and the patch index (mt_file.h); payloads are only read
// with --check, which decodes every one and names the damaged patches with their node and level.
#include <CLI/CLI.hpp>

#include <algorithm>
#include <charconv>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "base/error.h"
#include "base/exit_code.h"
#include "base/output_path.h"
#include "mtfile/mt_cut.h"
#include "mtfile/mt_file.h"
#include "base/cli_checks.h"

namespace {

using mt::format::NodeRecord;

struct LevelInfo {
  uint64_t nodes = 0, patches = 0, triangles = 0;
  double errorMin = std::numeric_limits<double>::infinity(), errorMax = -std::numeric_limits<double>::infinity();
  double colorErrorMax = 0;  // NodeRecord::colorError (file version 5 on; 8-bit RGBA levels)
};

struct StarInfo {
  double mean = 0;
  uint32_t max = 0;
};

std::string jsonEscape(const std::string& s) {
  std::string out;
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    if (static_cast<unsigned char>(c) < 0x20) continue;
    out += c;
  }
  return out;
}

// A double the header stores (origin, step, bounds) in the fewest digits that read back to the same
// double: at UTM coordinates (4e6 m) "%.9g" would drop the centimetres.
std::string exact(double v) {
  if (!std::isfinite(v)) return "null";
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, r.ptr);
}

// JSON has no inf/nan: print them as null.
std::string num(double v) {
  if (!std::isfinite(v)) return "null";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.9g", v);
  return buf;
}

const char* codecName(mt::format::Codec c) {
  switch (c) {
    case mt::format::Codec::Meshopt: return "meshopt";
    case mt::format::Codec::Draco: return "draco";
  }
  return "unknown";
}

int run(const std::string& path, bool json, bool check) {
  mt::requireRegularFile(path, "an MT file");  // a FIFO would block the reader, a device mislead it
  auto reader = mt::MtFileReader::open(path);
  const auto& h = reader->header();
  const auto& nodes = reader->nodes();
  const uint32_t sink = uint32_t(nodes.size() - 1);

  // Per level (the sink, level == levelCount, is left out: it holds nothing).
  std::vector<LevelInfo> levels(h.levelCount);
  for (uint32_t v = 0; v + 1 < nodes.size(); ++v) {
    const NodeRecord& n = nodes[v];
    if (n.level >= levels.size()) levels.resize(n.level + 1);
    LevelInfo& L = levels[n.level];
    ++L.nodes;
    L.triangles += n.triangles;
    for (uint32_t k = 0; k < n.arcCount; ++k) L.patches += reader->arcs()[n.firstArc + k].patchCount;
    L.errorMin = std::min(L.errorMin, double(n.error));
    L.errorMax = std::max(L.errorMax, double(n.error));
    L.colorErrorMax = std::max(L.colorErrorMax, double(n.colorError));
  }
  // The colour error column: files with colours; written by version 5 on (older files have none).
  const bool colors = h.vertexFlags & mt::format::kHasColors;
  const bool colorErrors = colors && h.version >= mt::format::kFirstColorErrorVersion;

  // DAG shape (BMT 3.2: paths logarithmic, small backward stars). Depth = arcs on the longest
  // source -> sink path. Stars are over the inner nodes: the source's forward star and the
  // sink's backward star span the whole model and say nothing about conditioning.
  std::vector<uint32_t> order = mt::topologicalOrder(*reader);
  std::vector<uint32_t> longest(nodes.size(), 0);
  for (uint32_t v : order) {
    const NodeRecord& n = nodes[v];
    for (uint32_t k = 0; k < n.arcCount; ++k) {
      uint32_t to = reader->arcs()[n.firstArc + k].to;
      longest[to] = std::max(longest[to], longest[v] + 1);
    }
  }
  StarInfo back, forward;
  uint64_t inner = 0;
  for (uint32_t v = 1; v < sink; ++v) {
    ++inner;
    back.mean += nodes[v].backArcCount;
    forward.mean += nodes[v].arcCount;
    back.max = std::max(back.max, nodes[v].backArcCount);
    forward.max = std::max(forward.max, nodes[v].arcCount);
  }
  if (inner) back.mean /= double(inner), forward.mean /= double(inner);

  uint64_t payloadBytes = 0;
  for (const auto& p : reader->patches()) payloadBytes += p.size;
  auto per = [](uint64_t bytes, uint64_t count) { return count ? double(bytes) / double(count) : 0.0; };
  const char* codec = codecName(reader->codec());
  std::string flags = std::string(h.vertexFlags & mt::format::kHasNormals ? "normals" : "") +
                      (h.vertexFlags & mt::format::kHasColors ? (h.vertexFlags & mt::format::kHasNormals ? "+colors" : "colors") : "");

  if (json) {
    std::printf("{\n  \"file\": \"%s\",\n  \"fileBytes\": %" PRIu64 ",\n  \"payloadBytes\": %" PRIu64 ",\n", jsonEscape(path).c_str(),
                reader->fileSize(), payloadBytes);
    std::printf("  \"codec\": \"%s\",\n  \"vertexAttributes\": \"%s\",\n  \"levels\": %u,\n  \"nodes\": %zu,\n  \"arcs\": %zu,\n"
                "  \"patches\": %zu,\n",
                codec, flags.c_str(), h.levelCount, nodes.size(), reader->arcs().size(), reader->patches().size());
    std::printf("  \"inputTriangles\": %" PRIu64 ",\n  \"inputVertices\": %" PRIu64 ",\n  \"storedTriangles\": %" PRIu64 ",\n",
                h.inputTriangles, h.inputVertices, h.storedTriangles);
    std::printf("  \"bytesPerInputTriangle\": %s,\n  \"bytesPerStoredTriangle\": %s,\n",
                num(per(reader->fileSize(), h.inputTriangles)).c_str(), num(per(reader->fileSize(), h.storedTriangles)).c_str());
    // The CRS (mtbuild --crs) and the grid's origin at full double precision (georeferenced scans).
    std::printf("  \"crs\": %s,\n  \"gridOrigin\": [%s, %s, %s],\n",
                reader->crs().empty() ? "null" : ("\"" + jsonEscape(reader->crs()) + "\"").c_str(), exact(h.gridOrigin[0]).c_str(),
                exact(h.gridOrigin[1]).c_str(), exact(h.gridOrigin[2]).c_str());
    std::printf("  \"gridStep\": %s,\n  \"quantizationError\": %s,\n  \"gridBits\": %u,\n", exact(h.gridStep).c_str(),
                exact(h.quantizationError).c_str(), h.gridBits);
    std::printf("  \"boundsMin\": [%s, %s, %s],\n  \"boundsMax\": [%s, %s, %s],\n", exact(h.boundsMin[0]).c_str(),
                exact(h.boundsMin[1]).c_str(), exact(h.boundsMin[2]).c_str(), exact(h.boundsMax[0]).c_str(),
                exact(h.boundsMax[1]).c_str(), exact(h.boundsMax[2]).c_str());
    std::printf("  \"dag\": {\"depth\": %u, \"backwardStarMean\": %s, \"backwardStarMax\": %u, \"forwardStarMean\": %s, "
                "\"forwardStarMax\": %u},\n",
                longest[sink], num(back.mean).c_str(), back.max, num(forward.mean).c_str(), forward.max);
    std::printf("  \"perLevel\": [");
    for (size_t l = 0; l < levels.size(); ++l) {
      const LevelInfo& L = levels[l];
      std::printf("%s\n    {\"level\": %zu, \"nodes\": %" PRIu64 ", \"patches\": %" PRIu64 ", \"triangles\": %" PRIu64
                  ", \"errorMin\": %s, \"errorMax\": %s, \"colorErrorMax\": %s}",
                  l ? "," : "", l, L.nodes, L.patches, L.triangles, num(L.nodes ? L.errorMin : NAN).c_str(),
                  num(L.nodes ? L.errorMax : NAN).c_str(), num(colorErrors && L.nodes ? L.colorErrorMax : NAN).c_str());
    }
    std::printf("\n  ]\n}\n");
  } else {
    std::printf("file              %s\n", path.c_str());
    std::printf("size              %" PRIu64 " bytes (payloads %" PRIu64 ")\n", reader->fileSize(), payloadBytes);
    std::printf("codec             %s%s%s\n", codec, flags.empty() ? "" : ", ", flags.c_str());
    std::printf("input             %" PRIu64 " triangles, %" PRIu64 " vertices\n", h.inputTriangles, h.inputVertices);
    std::printf("stored            %" PRIu64 " triangles in %zu patches\n", h.storedTriangles, reader->patches().size());
    std::printf("bytes/triangle    %.3f per input triangle, %.3f per stored triangle\n", per(reader->fileSize(), h.inputTriangles),
                per(reader->fileSize(), h.storedTriangles));
    std::printf("crs               %s\n", reader->crs().empty() ? "(none)" : reader->crs().c_str());
    std::printf("grid origin       (%s, %s, %s)\n", exact(h.gridOrigin[0]).c_str(), exact(h.gridOrigin[1]).c_str(),
                exact(h.gridOrigin[2]).c_str());
    std::printf("grid              step %s, quantization error %s, %u bits\n", exact(h.gridStep).c_str(),
                exact(h.quantizationError).c_str(), h.gridBits);
    std::printf("bounding box      (%s, %s, %s) - (%s, %s, %s)\n", exact(h.boundsMin[0]).c_str(), exact(h.boundsMin[1]).c_str(),
                exact(h.boundsMin[2]).c_str(), exact(h.boundsMax[0]).c_str(), exact(h.boundsMax[1]).c_str(),
                exact(h.boundsMax[2]).c_str());
    std::printf("DAG               %u levels, %zu nodes, %zu arcs, depth %u\n", h.levelCount, nodes.size(),
                reader->arcs().size(), longest[sink]);
    std::printf("stars (inner)     backward mean %.2f max %u, forward mean %.2f max %u\n", back.mean, back.max, forward.mean,
                forward.max);
    if (colors && !colorErrors)
      std::printf("colour error      not stored (file version %u; version %u on stores it)\n", h.version,
                  mt::format::kFirstColorErrorVersion);
    std::printf("level     nodes    patches      triangles    error min    error max%s\n",
                colorErrors ? "  colour err max" : "");
    for (size_t l = 0; l < levels.size(); ++l) {
      const LevelInfo& L = levels[l];
      std::printf("%5zu %9" PRIu64 " %10" PRIu64 " %14" PRIu64 " %12.6g %12.6g", l, L.nodes, L.patches, L.triangles,
                  L.nodes ? L.errorMin : 0.0, L.nodes ? L.errorMax : 0.0);
      if (colorErrors) std::printf(" %15.6g", L.nodes ? L.colorErrorMax : 0.0);
      std::printf("\n");
    }
  }

  if (!check) return 0;
  std::vector<mt::PatchDamage> damaged = mt::checkAllPatches(*reader);
  for (const auto& d : damaged) {
    uint32_t node = reader->arcs()[reader->patches()[d.patch].arc].from;
    std::fprintf(stderr, "%s [node %u, level %u]\n", d.message.c_str(), node, nodes[node].level);
  }
  std::fprintf(stderr, "%s: checked %zu payloads, %zu damaged\n", path.c_str(), reader->patches().size(), damaged.size());
  return damaged.empty() ? 0 : mt::kExitCorruption;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"mtinfo: describe a batched Multi-Triangulation file (.mt): levels, nodes, arcs, patches, per-level\n"
               "triangles and error, bytes per triangle, quantization, bounding box and DAG shape (depth = arcs on\n"
               "the longest source->sink path; backward/forward star sizes over the inner nodes).\n"
               "A damaged header, DAG or index is reported on one line naming the file and where; exit 3 (README, \"Exit codes\")."};
  std::string path;
  bool json = false, check = false;
  app.add_option("file", path, "The MT file to describe")->required();
  app.add_flag("--json", json, "Print one JSON object instead of the text table (inf/nan errors are null)");
  app.add_flag("--check", check,
               "Also read and decode every patch payload, verifying its checksum; each damaged patch is named "
               "on stderr with its node and level, and the exit code is 3 (corrupt file) if any is damaged");
  if (int code = mt::cli::parse(app, argc, argv, "mtinfo"); code >= 0) return code;
  try {
    return run(path, json, check);
  } catch (const std::exception& e) {
    return mt::reportError("mtinfo", e);
  }
}
