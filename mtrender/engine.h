// mtrender/engine.h: one frame of the renderer, shared by the headless runner and the viewer:
// the scene, the RAM patch cache + PatchServer thread, ExtractRender, and drawing the cut with
// the GL backend.
//
// Progressive refinement of a still view: while the camera moves, every frame draws a cut within
// one frame's render budget. Once it stops, nothing on screen has to change any more, so the
// frames that follow are spent on a finer image instead: the cut may grow to `stillFrames` frames'
// worth of the budget, and it is drawn over that many frames at most (each frame draws at most one
// frame's budget of it into an accumulation target, so every frame still keeps --budget-ms), then
// shown; meanwhile the screen keeps the last complete image. Each completed image starts the next
// (the cut is updated between images: loads that arrived refine it further). The first moving
// frame drops this at once and coarsens the cut back to one frame's budget. This is what lets the
// screen error of a still view reach the tolerance on a renderer (llvmpipe) that cannot draw that
// many triangles in one frame. Time-critical rendering in the sense of BMT section 5: the frame
// rate is guaranteed, the refinement uses the frames the view does not need. The baseline mode (--baseline-mmap) maps the files and renders the same kind of
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
#include "mtrender/occlusion.h"
#include "mtrender/patch_cache.h"
#include "mtrender/patch_server.h"
#include "mtrender/scene.h"

namespace mt::render {

// How occlusion culling finds what is hidden (Derzapf et al. 4.2): a max-depth pyramid of the
// frame's depth read back and tested on the CPU, or hardware occlusion queries of the spheres'
// boxes. docs/mtrender.md has the measurement that chose the default.
enum class OcclusionTest { Pyramid, Queries };

struct EngineOptions {
  std::vector<std::string> files;
  uint64_t cacheBytes = 256ull << 20;  // RAM patch cache cap
  uint64_t gpuCacheBytes = 0;          // GPU buffer cache cap; 0 = same as cacheBytes
  ExtractOptions extract;
  bool baseline = false;
  double readDelayMs = 0;              // test hook: a slow disk
  bool quiet = false;
  // Progressive refinement of a still view (above): a still image may take up to this many
  // frames; 1 turns it off (every frame draws the whole cut).
  uint32_t stillFrames = 16;
  OcclusionTest occlusionTest = OcclusionTest::Pyramid;
  // Load textured files' atlases (Scene::setLoadTextures): off when nothing is drawn textured.
  bool textures = true;
  // The occlusion tests run on every this-many-th frame of a moving (or non-progressive) view;
  // 0 = adaptive (k in 1..16 keeping their measured cost near 5% of the budget, Engine::frame).
  // A fixed cadence makes what is loaded independent of the machine's speed (tests, benches).
  uint32_t occlusionEvery = 0;
};

struct FrameRecord : FrameStats {
  double frameMs = 0;
  uint32_t occludedArcs = 0;  // cut arcs in the frustum not drawn: hidden in this frame's depth
  uint32_t conedPatches = 0;  // finest patches not drawn: back-facing by their own normal cones
  double occlusionMs = 0;     // occlusion tests: depth read-back + pyramid + tests, or the queries
  uint32_t occlusionTests = 0;  // spheres tested for occlusion
  bool occlusionFrame = false;  // the frame tested its own depth (read back, or queried) and culled by it
  uint32_t loads = 0;        // patches loaded (server) or decoded in the frame (baseline)
  uint64_t loadedTriangles = 0;  // their triangles (server loads only)
  uint64_t cacheBytes = 0;   // RAM cache in use (place holders holding a patch)
  uint64_t gpuBytes = 0;
  bool moving = false;
  bool accumulating = false;  // the frame drew part of a still image (maxScreenError: the image shown)
  uint32_t imageFrames = 0;   // a still image was completed and shown: the frames it took
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
  // Triangles drawn so far from each file (all frames). A loaded file with none drawn (out of
  // view all along, or a model whose triangles collapsed) is worth a warning: see
  // warnUndrawnFiles.
  const std::vector<uint64_t>& drawnPerFile() const { return drawnPerFile_; }
  // Prints "mtrender: warning: FILE: nothing of it was drawn in N frames ..." for each such file;
  // returns how many.
  size_t warnUndrawnFiles() const;

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
  uint64_t frame_ = 0, lastLoads_ = 0, lastLoadedTriangles_ = 0;
  std::vector<uint64_t> drawnPerFile_;
  std::vector<std::pair<double, uint32_t>> drawOrder_;  // (distance, cut arc), reused every frame
  // Sorts the cut arcs visible in `view` front to back into drawOrder_.
  void orderVisibleArcs(const View& view);
  // Draws drawOrder_[from, to) and adds to rec's drawn counts (the patches of arcs leaving a
  // source are culled by their own normal cones against `view`).
  void drawArcs(size_t from, size_t to, GlRenderer& gl, FrameRecord& rec, const View& view);
  // Occlusion culling (Derzapf et al. 4.2, with a depth pyramid): draws the arcs whose node was
  // not hidden last frame, reads the depth back, draws those of the rest that this frame's depth
  // does not hide, and marks the front nodes the depth hides for the next cut update.
  void drawWithOcclusion(const View& view, GlRenderer& gl, FrameRecord& rec);
  // Marks the front of the cut hidden (occluded_, for the cut update) and the cut arcs whose
  // patches are all hidden (arcHidden_, deferred by the next test's drawing): against pyramid_, or
  // by queries against the depth the output holds (of the presented image when `presented`).
  void markOccluded(GlRenderer* gl, FrameRecord& rec, bool presented = false);
  // The nodes markOccluded tests, each once: the coarsenings, the refinements and two levels past
  // them (what prefetching and the requests ahead of a still image look at).
  void collectFront(std::vector<uint32_t>& out);
  // The spheres that bound what a move on node n would change on screen, appended to `out`:
  // for a refinement, the patches of its fragment (in the cut), each patch's own sphere grown by
  // the node's error (the finer patches that replace them lie within it); for a coarsening, the
  // patches it would replace, grown the same way; otherwise (or when a patch's bound is unknown)
  // the node's sphere from the file, which nests every finer sphere and is far looser.
  void moveSpheres(uint32_t n, std::vector<GlRenderer::QuerySphere>& out) const;
  // Appends patch id's own sphere (world space) grown by `grow`; false when its bound is unknown.
  bool patchSphere(uint32_t id, double grow, std::vector<GlRenderer::QuerySphere>& out) const;
  // Which of `spheres` are hidden (by the frame's method); adds the time and tests to rec.
  void testHidden(const std::vector<GlRenderer::QuerySphere>& spheres, std::vector<uint8_t>& hidden, GlRenderer* gl,
                  FrameRecord& rec, bool presented);
  bool occlusionOn() const { return options_.extract.cull && options_.extract.occlusion; }
  DepthPyramid pyramid_;
  uint64_t nextOcclusionFrame_ = 0;
  double occlusionMs_ = 0;  // the drawing with occlusion (read-back and tests included), averaged
  std::vector<float> depth_;
  std::vector<uint8_t> occluded_;       // per node, for ExtractRender::setOccluded
  std::vector<uint32_t> occludedList_;  // the nodes set in occluded_
  std::vector<std::pair<double, uint32_t>> deferred_;
  std::vector<uint32_t> frontStamp_, testNodes_, sphereOwner_;
  uint32_t frontVisit_ = 0;
  std::vector<uint8_t> hiddenScratch_, arcHidden_;
  std::vector<uint32_t> hiddenArcs_;  // the arcs set in arcHidden_
  std::vector<GlRenderer::QuerySphere> spheres_;
  // Progressive refinement of a still view.
  struct Still {
    bool active = false;       // the camera has stopped; the screen shows `presented`
    bool drawing = false;      // an image is being accumulated from drawOrder_
    size_t next = 0;           // next arc of drawOrder_ to draw
    uint32_t frames = 0;       // frames spent on the image so far
    double imageError = 0;     // screen error of the cut being accumulated
    double presentedError = 0; // screen error of the image on screen
    bool presentedIsCut = false;  // the image on screen shows the current cut (nothing to redraw)
  } still_;
  double lastScreenError_ = 0;
  int lastWidth_ = 0, lastHeight_ = 0;
  DrawSettings lastSettings_;
  // baseline
  std::vector<const uint8_t*> maps_;
  std::vector<uint64_t> mapSizes_;
  std::vector<uint8_t> scratch_;
  std::unordered_set<uint32_t> baselineBad_;
  uint32_t baselineLoads_ = 0;
};

}  // namespace mt::render
