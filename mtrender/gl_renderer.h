// mtrender/gl_renderer.h: the OpenGL 4.5 core backend that draws the cut, with a GPU buffer
// cache under its own byte cap, plus an EGL surfaceless context (EGL_MESA_platform_surfaceless)
// with an FBO for headless runs (no X needed). The viewer uses a GLFW window's context instead.
#pragma once

#include <cstdint>
#include <functional>
#include <glm/glm.hpp>
#include <memory>
#include <unordered_map>
#include <vector>

#include "mtrender/camera.h"
#include "mtrender/image.h"
#include "mtrender/patch_cache.h"

namespace mt::render {

// A surfaceless EGL display + OpenGL 4.5 core context, current on the calling thread.
class EglContext {
 public:
  EglContext();  // throws mt::Error when EGL or GL 4.5 core is unavailable
  ~EglContext();
  EglContext(const EglContext&) = delete;
  EglContext& operator=(const EglContext&) = delete;

 private:
  void* display_ = nullptr;
  void* context_ = nullptr;
};

// A textured patch's vertex on the GPU: the vertex, then its texture coordinate (unorm16). A
// vertex of the patch whose corners have several coordinates (a seam of its atlas) becomes one
// such vertex per distinct coordinate.
struct TexturedVertex {
  RenderVertex vertex;
  uint16_t uv[2];
};
static_assert(sizeof(TexturedVertex) == 24, "TexturedVertex layout");

// Splits a textured patch's vertices per distinct (vertex, corner coordinate) pair, as GL needs
// (one attribute set per vertex); the triangles keep their order. Linear time: each vertex chains
// the copies made of it so far.
void splitTexturedVertices(const PatchView& v, std::vector<TexturedVertex>& vertices, std::vector<uint32_t>& indices);

// GPU bytes of an RGBA8 texture of this size with its full mip chain.
uint64_t mippedTextureBytes(uint32_t width, uint32_t height);

// mtrender --color (mtrender/color_mode.h names, parses and chooses them).
enum class ColorMode { Shaded, Patch, Lod, Vertex, Texture };

struct DrawSettings {
  ColorMode mode = ColorMode::Shaded;
  bool wireframe = false;
  glm::vec3 background{0.08f, 0.09f, 0.11f};
};

class GlRenderer {
 public:
  explicit GlRenderer(uint64_t gpuCapBytes);  // needs a current GL 4.5 context
  ~GlRenderer();

  // Renders into an offscreen FBO of this size (headless) instead of the default framebuffer.
  void useOffscreen(int width, int height);
  // Starts a frame drawn straight into the output (the offscreen FBO, or the default framebuffer).
  void beginFrame(const View& view, const DrawSettings& settings);

  // Progressive refinement of a still view (engine.h): an image of a cut too large for one frame
  // is drawn over several frames into an accumulation target, and shown once it is complete;
  // until then the output shows the last complete image (the "presented" target).
  // Keeps what the output shows now as the presented image (entering the still state).
  void keepOutputAsPresented(int width, int height);
  // Binds the accumulation target for drawing with the frame's state; `clear` starts a new image.
  void beginAccumulation(const View& view, const DrawSettings& settings, bool clear);
  // The accumulated image is complete: it becomes the presented one.
  void presentAccumulation();
  // Copies the presented image to the output.
  void showPresented();
  // Draws one small triangle with the frame's state and waits: llvmpipe compiles its shader
  // variants (LLVM JIT) at the first draw, so doing it while the files open takes it off the
  // first frame.
  void warmUp(const DrawSettings& settings);
  // Draws patch `id`, whose vertices are relative to `origin` (Scene::patchOrigin): its
  // model-view matrix is the view matrix times translate(origin), composed in double, so only
  // small numbers reach the GPU (camera-relative drawing). Uploads the patch first when it is not
  // on the GPU, taking its data from fetch() (a PatchView with vertexCount 0 = unavailable:
  // nothing drawn). In texture mode a textured patch is uploaded with its vertices split per
  // coordinate (splitTexturedVertices) and its atlas as a mipmapped texture, both counted in the
  // GPU bytes; patches without a texture show their vertex colours. The GPU cap is hard: before an upload, the least recently drawn buffers are
  // deleted until it fits (this frame's too, once their draws are submitted: GL keeps them alive
  // until done), so the bytes held never pass the cap. Returns triangles drawn.
  uint32_t drawPatch(uint32_t id, uint32_t level, const double origin[3], const std::function<PatchView()>& fetch);
  void endFrame();
  // Test switch: false = the old soft cap (buffers trimmed after the frame), to show the hard cap matters.
  void setHardCap(bool hard) { hardCap_ = hard; }
  // The largest GPU bytes held at any moment (after every upload), since the start.
  uint64_t gpuPeakBytes() const { return gpuPeak_; }
  // The depth of the output (or of the presented image when `presented`) as window-space depths
  // in [0, 1], rows bottom to top (occlusion culling reads it back; engine.h).
  void readDepth(std::vector<float>& out, bool presented = false) const;
  // Occlusion queries (Derzapf et al. 4.2): for each sphere (world centre, radius), whether no
  // sample of its bounding box (aligned with the eye's axes) passes the depth test against the
  // depth the output holds now (or the presented image's, when `presented`); nothing is written.
  // A sphere that reaches the near plane is never hidden. Waits for the results (on llvmpipe a
  // query's result is there once its box is rasterized). The alternative to DepthPyramid,
  // measured against it: docs/mtrender.md.
  struct QuerySphere {
    double center[3];
    double radius;
  };
  void queryHidden(const std::vector<QuerySphere>& spheres, std::vector<uint8_t>& hidden, bool presented = false);
  void finish();
  Image readPixels() const;
  uint64_t gpuBytes() const { return gpuBytes_; }
  // Of which textures (atlases with their mips).
  uint64_t gpuTextureBytes() const { return gpuTextureBytes_; }
  uint64_t texturedDraws() const { return texturedDraws_; }
  uint64_t uploads() const { return uploads_; }

 private:
  struct Buffer {
    uint32_t buffer = 0;
    uint64_t bytes = 0;
    uint64_t indexOffset = 0;
    uint32_t indexCount = 0;
    uint64_t lastFrame = 0;
    uint64_t lastUse = 0;
    uint32_t stride = sizeof(RenderVertex);
    uint32_t texture = 0;     // the atlas (uploaded in texture mode), 0: none
    uint16_t textureWidth = 0, textureHeight = 0;
    bool hasTexture = false;  // the patch has one (uploaded or not)
  };
  void release(Buffer& b);
  // A colour + depth render target.
  struct Target {
    uint32_t fbo = 0, color = 0, depth = 0;
    int width = 0, height = 0;
  };
  void makeTarget(Target& t, int width, int height);
  void deleteTarget(Target& t);
  void setFrameState(const View& view, const DrawSettings& settings);
  void evictFor(uint64_t bytes);  // evicts buffers not drawn this frame until `bytes` more fit
  uint64_t cap_;
  bool hardCap_ = true;
  uint64_t gpuPeak_ = 0;
  uint64_t uses_ = 0;             // draw counter (least recently drawn order)
  glm::dmat4 viewD_{1}, projD_{1};
  uint32_t program_ = 0, vao_ = 0, vaoTex_ = 0, fbo_ = 0, colorRb_ = 0, depthRb_ = 0;
  Target accumulation_, presented_;
  int width_ = 0, height_ = 0;
  int locMvp_ = -1, locMv_ = -1, locTint_ = -1, locMode_ = -1, locUseTexture_ = -1, locAtlas_ = -1;
  ColorMode mode_ = ColorMode::Shaded;
  std::unordered_map<uint32_t, Buffer> buffers_;
  // Occlusion queries: the box program, a unit cube, a pool of query objects.
  uint32_t boxProgram_ = 0, boxVao_ = 0, boxBuffer_ = 0;
  int locBoxMvp_ = -1;
  std::vector<uint32_t> queries_;
  double nearPlane_ = 0;
  bool wireframe_ = false;
  uint64_t gpuBytes_ = 0, frame_ = 0, uploads_ = 0, gpuTextureBytes_ = 0, texturedDraws_ = 0;
};

}  // namespace mt::render
