// mtrender/engine.h: one frame of the renderer, shared by the headless runner and the viewer:
// the scene, the RAM patch cache + PatchServer thread, ExtractRender, and drawing the cut with
// the GL backend. The baseline mode (--baseline-mmap) maps the files and renders the same kind of
// cut with no RAM cache, no server thread and no prefetch: a patch the cut needs is decoded from
// the mapping inside the frame (the GPU buffer cache, under the same cap, is all it keeps).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <unordered_set>
#include <utility>
#include <vector>

#include "mtrender/camera.h"
#include "mtrender/extract.h"
#include "mtrender/gl_renderer.h"
#include "mtrender/patch_cache.h"
#include "mtrender/patch_server.h"
#include "mtrender/scene.h"

namespace mt::render {

struct EngineOptions {
  std::vector<std::string> files;
  uint64_t cacheBytes = 256ull << 20;  // RAM patch cache cap
  uint64_t gpuCacheBytes = 0;          // GPU buffer cache cap; 0 = same as cacheBytes
  ExtractOptions extract;
  bool baseline = false;
  double readDelayMs = 0;              // test hook: a slow disk
  bool quiet = false;
};

struct FrameRecord : FrameStats {
  double frameMs = 0;
  uint32_t loads = 0;        // patches loaded (server) or decoded in the frame (baseline)
  uint64_t cacheBytes = 0;   // RAM cache in use (place holders holding a patch)
  uint64_t gpuBytes = 0;
  bool moving = false;
};

class Engine {
 public:
  explicit Engine(EngineOptions options);
  ~Engine();

  const Scene& scene() const { return *scene_; }
  ExtractRender& extract() { return *extract_; }
  PatchCache* cache() { return cache_.get(); }
  PatchServer* server() { return server_.get(); }
  const EngineOptions& options() const { return options_; }
  glm::dvec3 center() const { return center_; }
  double radius() const { return radius_; }
  uint64_t badPatches() const;

  // The coarsest cut, loaded (blocking up to timeoutMs).
  void start(double timeoutMs = 30000);
  // One frame: update the cut for `pose` (prev: the previous frame's pose, for extrapolation),
  // draw it into the current framebuffer and wait for the GPU. A GL context must be current.
  FrameRecord frame(const CameraPose& pose, const CameraPose& prev, GlRenderer& gl, const DrawSettings& settings,
                    int width, int height);

 private:
  PatchView baselineFetch(uint32_t id);
  EngineOptions options_;
  std::unique_ptr<Scene> scene_;
  std::unique_ptr<PatchCache> cache_;
  std::unique_ptr<PatchServer> server_;
  std::unique_ptr<ExtractRender> extract_;
  glm::dvec3 center_{0};
  double radius_ = 1;
  uint64_t frame_ = 0, lastLoads_ = 0;
  std::vector<std::pair<double, uint32_t>> drawOrder_;  // (distance, cut arc), reused every frame
  // baseline
  std::vector<const uint8_t*> maps_;
  std::vector<uint64_t> mapSizes_;
  std::vector<uint8_t> scratch_;
  std::unordered_set<uint32_t> baselineBad_;
  uint32_t baselineLoads_ = 0;
};

// "256M", "1G", "64MiB", "1048576" -> bytes. Throws mt::Error.
uint64_t parseSize(const std::string& text);

}  // namespace mt::render
