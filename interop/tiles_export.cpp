// 3D Tiles export (the mapping: tiles_export.h and docs/interop.md).
#include "interop/tiles_export.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <vector>

#include "base/error.h"
#include "base/output_path.h"
#include "interop/gltf_writer.h"
#include "mtfile/mt_cut.h"
#include "mtfile/textured_cut.h"

namespace mt::interop {

namespace {

using nlohmann::json;
namespace fs = std::filesystem;

// One GLB to write: the patches of these arcs, welded.
struct Content {
  std::string uri;
  std::vector<uint32_t> arcs;
  bool empty = false;  // every triangle degenerate after the weld: the tile gets no content
  uint64_t triangles = 0, bytes = 0;
  bool floatPositions = false;
};

struct Tree {
  // Per node: the content index of its fragment (-1 for source and sink), its tree parent.
  std::vector<int64_t> content;
  std::vector<uint32_t> parent;
  // Per node: its tile's children: (node, kind) with kind 0 = its own subtree, 1 = a leaf copy,
  // 2 = a source arc leaf (node = the content index).
  std::vector<std::vector<std::pair<uint64_t, int>>> children;
};

std::string parentOf(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  return slash == std::string::npos ? "." : slash == 0 ? "/" : path.substr(0, slash);
}

// The temporary directory after a failure: its files through the Env, then the two directories.
void removeTemporary(Env* env, const std::string& tmp) {
  for (const std::string& sub : {tmp + "/tiles", tmp}) {
    std::vector<std::string> names;
    try {
      names = env->listDir(sub);
    } catch (const Error&) {
      continue;
    }
    for (const std::string& n : names) {
      try {
        env->removeFile(sub + "/" + n);
      } catch (const Error&) {
      }
    }
  }
  std::error_code ec;
  fs::remove(tmp + "/tiles", ec);  // empty directories: the Env has no removeDir
  fs::remove(tmp, ec);
}

}  // namespace

TilesReport exportTiles(const MtFileReader& r, const std::string& dir, const TilesOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  TilesReport report;
  const auto& nodes = r.nodes();
  const auto& arcs = r.arcs();
  const auto& patches = r.patches();
  const auto& refs = r.patchRefs();
  const uint32_t N = uint32_t(nodes.size());
  if (N < 2) fail(r.path(), "the DAG has no nodes to export");
  const uint32_t source = 0, sink = N - 1;
  Env* env = Env::Default();
  if (env->exists(dir)) fail(dir, "exists: give a directory name that does not exist yet (nothing is overwritten)");

  auto arcTriangles = [&](uint32_t a) {
    uint64_t t = 0;
    for (uint32_t k = 0; k < arcs[a].patchCount; ++k) t += patches[refs[arcs[a].firstPatchRef + k]].triangles;
    return t;
  };

  // The tree: every node under the successor that receives most of its triangles.
  Tree tree;
  tree.content.assign(N, -1);
  tree.parent.assign(N, sink);
  tree.children.resize(N);
  std::vector<Content> contents;
  for (uint32_t n = 1; n + 1 < N; ++n) {
    const auto& node = nodes[n];
    uint64_t best = 0;
    uint32_t parent = UINT32_MAX;
    Content c;
    c.uri = "tiles/n" + std::to_string(n) + ".glb";
    for (uint32_t k = 0; k < node.arcCount; ++k) {
      const uint32_t a = node.firstArc + k;
      const uint64_t t = arcTriangles(a);
      if (parent == UINT32_MAX || t > best || (t == best && arcs[a].to < parent)) best = t, parent = arcs[a].to;
      c.arcs.push_back(a);
    }
    if (parent == UINT32_MAX) fail(r.path(), "node " + std::to_string(n) + " has no successor");
    tree.parent[n] = parent;
    tree.content[n] = int64_t(contents.size());
    contents.push_back(std::move(c));
  }
  for (uint32_t n = 1; n < N; ++n) {
    const auto& node = nodes[n];
    for (uint32_t k = 0; k < node.backArcCount; ++k) {
      const uint32_t a = r.backArcs()[node.firstBackArc + k];
      const uint32_t p = arcs[a].from;
      if (p == source) {
        Content c;
        c.uri = "tiles/s" + std::to_string(a) + ".glb";
        c.arcs.push_back(a);
        tree.children[n].push_back({contents.size(), 2});
        contents.push_back(std::move(c));
      } else {
        tree.children[n].push_back({p, tree.parent[p] == n ? 0 : 1});
      }
    }
  }

  // The frame: the grid's origin (a double the tileset's root transform carries).
  const auto& h = r.header();
  const double* origin = h.gridOrigin;
  // The root transform: tile frame -> the model's coordinates -> (with a CRS) ECEF.
  const std::string crs = options.modelFrame ? std::string() : options.crs.empty() ? r.crs() : options.crs;
  double rootTransform[16] = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, origin[0], origin[1], origin[2], 1};
  if (!crs.empty()) {
    try {
      report.placement = placeOnGlobe(crs, h.boundsMin, h.boundsMax);
    } catch (const Error& e) {
      fail(r.path(), e.what());
    }
    report.placed = true;
    std::copy(report.placement.toEcef, report.placement.toEcef + 12, rootTransform);
    applyPlacement(report.placement, origin, rootTransform + 12);
  }
  const std::string tmp = uniqueTempName(dir);
  try {
    env->createDir(tmp);
    env->createDir(tmp + "/tiles");
    std::atomic<uint64_t> done{0};
    tbb::parallel_for(size_t(0), contents.size(), [&](size_t i) {
      Content& c = contents[i];
      // A textured file's contents carry their patches' atlases (gltf_writer.h): each patch is in
      // one content, so no image is stored twice. Draco does not code them: meshopt stands in.
      TexturedCut tcut;
      TexturedGltfMesh tmesh;
      WeldedMesh plain;
      const bool textured = r.hasTextures();
      if (textured) tcut = assembleTexturedCut(r, c.arcs);
      else plain = assembleCut(r, c.arcs);
      const WeldedMesh& mesh = textured ? tcut.mesh : plain;
      c.triangles = mesh.triangleCount();
      if (c.triangles == 0) {
        c.empty = true;
        return;
      }
      if (textured) texturedGltfMeshOf(tcut, origin, h.gridStep, tmesh);
      const GltfMeshView view = textured ? tmesh.view : gltfMeshViewOf(mesh, origin, h.gridStep);
      GltfOptions go;
      go.meshopt = options.meshopt || (textured && options.draco);
      go.draco = options.draco;
      go.quantize = options.quantize;
      go.zUpToYUp = true;
      for (int a = 0; a < 3; ++a) go.frame[a] = origin[a];
      go.generator = "batched-mt mtexport";
      GltfBytes g = buildGltf(view, go);
      c.floatPositions = options.quantize && !g.info.quantized;
      std::vector<uint8_t> glb = encodeGlb(g);
      c.bytes = glb.size();
      auto f = env->newWritableFile(tmp + "/" + c.uri);
      f->append(glb.data(), glb.size());
      f->sync();
      f->close();
      const uint64_t k = ++done;
      if (options.progress && k % 2000 == 0)
        std::fprintf(stderr, "mtexport: %llu of %zu contents\n", (unsigned long long)k, contents.size());
    });

    // tileset.json: spheres relative to the frame. A node's sphere contains its predecessors'
    // (mt_format.h) up to float rounding of the radii; the exported radius is grown to contain
    // every child's exported sphere exactly (computed bottom-up), and by a grid step.
    auto sphereOf = [&](uint32_t n) {
      const auto& node = nodes[n];
      return std::array<double, 4>{node.center[0] - origin[0], node.center[1] - origin[1], node.center[2] - origin[2],
                                   double(node.radius) * (1 + 1e-6) + h.gridStep};
    };
    auto enclose = [](std::array<double, 4>& s, const json& child) {
      const json& c = child["boundingVolume"]["sphere"];
      const double d = std::hypot(c[0].get<double>() - s[0], c[1].get<double>() - s[1], c[2].get<double>() - s[2]);
      const double need = d + c[3].get<double>();
      if (need > s[3]) s[3] = std::nextafter(need * (1 + 1e-12), INFINITY);
    };
    auto volume = [](const std::array<double, 4>& s) { return json{{"sphere", {s[0], s[1], s[2], s[3]}}}; };
    uint32_t depth = 0;
    // Recursion depth is the DAG's level count (tens): a plain recursive walk.
    std::function<json(uint32_t, uint32_t)> tile = [&](uint32_t n, uint32_t d) -> json {
      depth = std::max(depth, d);
      ++report.tiles;
      json kids = json::array();
      for (auto [id, kind] : tree.children[n]) {
        if (kind == 0) {
          kids.push_back(tile(uint32_t(id), d + 1));
          continue;
        }
        depth = std::max(depth, d + 1);
        ++report.tiles;
        if (kind == 1) {
          // A leaf copy of a node whose subtree hangs elsewhere: the same GLB, no children.
          ++report.copies;
          json leaf = {{"boundingVolume", volume(sphereOf(uint32_t(id)))}, {"geometricError", double(nodes[id].error)}};
          const Content& c = contents[size_t(tree.content[id])];
          if (!c.empty) leaf["content"] = {{"uri", c.uri}};
          kids.push_back(leaf);
        } else {
          // The source's piece in n's floor: full resolution, inside n's sphere.
          json leaf = {{"boundingVolume", volume(sphereOf(n))}, {"geometricError", 0.0}};
          const Content& c = contents[id];
          if (!c.empty) leaf["content"] = {{"uri", c.uri}};
          kids.push_back(leaf);
        }
      }
      std::array<double, 4> s = sphereOf(n);
      for (const json& k : kids) enclose(s, k);
      json t = {{"boundingVolume", volume(s)}};
      if (n == sink) {
        t["geometricError"] = 2.0 * s[3];
        t["refine"] = "REPLACE";
        t["transform"] = json(std::vector<double>(rootTransform, rootTransform + 16));
      } else {
        t["geometricError"] = double(nodes[n].error);
        const Content& c = contents[size_t(tree.content[n])];
        if (!c.empty) t["content"] = {{"uri", c.uri}};
      }
      if (!kids.empty()) t["children"] = kids;
      return t;
    };
    json root = tile(sink, 0);
    json ts;
    ts["asset"] = {{"version", "1.1"}, {"generator", "batched-mt mtexport"}};
    if (!crs.empty()) {
      const GeoPlacement& g = report.placement;
      ts["asset"]["extras"] = {{"crs", crs},
                               {"placement", {{"method", "local affine map fitted to PROJ over the model's box (EPSG:4978)"},
                                              {"longitude", g.longitude}, {"latitude", g.latitude}, {"height", g.height},
                                              {"maxErrorMetres", g.maxError}}}};
    } else if (!r.crs().empty()) {
      ts["asset"]["extras"] = {{"crs", r.crs()}, {"placement", "model frame (not placed on the globe)"}};
    }
    ts["geometricError"] = root["geometricError"];
    ts["root"] = root;
    const std::string text = ts.dump();
    auto f = env->newWritableFile(tmp + "/tileset.json");
    f->append(text.data(), text.size());
    f->sync();
    f->close();
    report.tilesetBytes = text.size();
    report.depth = depth;
    for (const Content& c : contents) {
      if (c.empty) continue;
      ++report.contents;
      report.glbBytes += c.bytes;
      report.triangles += c.triangles;
      report.floatTiles += c.floatPositions;
    }
    // Durable before it is published: the files were synced, now their directories' entries;
    // after the rename, the parent's.
    env->syncDir(tmp + "/tiles");
    env->syncDir(tmp);
    env->renameFile(tmp, dir);
  } catch (...) {
    removeTemporary(env, tmp);
    throw;
  }
  env->syncDir(parentOf(dir));
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return report;
}

}  // namespace mt::interop
