#define GL_GLEXT_PROTOTYPES 1
#include "mtrender/gl_renderer.h"

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GL/glcorearb.h>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstring>
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/type_ptr.hpp>
#include <string>

#include "base/error.h"

namespace mt::render {

EglContext::EglContext() {
  auto getPlatformDisplay = reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
  if (!getPlatformDisplay) throw Error("mtrender: EGL has no eglGetPlatformDisplayEXT");
  EGLDisplay d = getPlatformDisplay(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
  EGLint major = 0, minor = 0;
  if (d == EGL_NO_DISPLAY || !eglInitialize(d, &major, &minor))
    throw Error("mtrender: cannot open a surfaceless EGL display (EGL_MESA_platform_surfaceless)");
  if (!eglBindAPI(EGL_OPENGL_API)) throw Error("mtrender: EGL cannot bind the OpenGL API");
  const EGLint attribs[] = {EGL_CONTEXT_MAJOR_VERSION, 4, EGL_CONTEXT_MINOR_VERSION, 5, EGL_CONTEXT_OPENGL_PROFILE_MASK,
                            EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, EGL_NONE};
  EGLContext c = eglCreateContext(d, EGL_NO_CONFIG_KHR, EGL_NO_CONTEXT, attribs);
  if (c == EGL_NO_CONTEXT) throw Error("mtrender: cannot create an OpenGL 4.5 core context on EGL");
  if (!eglMakeCurrent(d, EGL_NO_SURFACE, EGL_NO_SURFACE, c)) throw Error("mtrender: eglMakeCurrent failed");
  display_ = d;
  context_ = c;
}

EglContext::~EglContext() {
  eglMakeCurrent(display_, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
  eglDestroyContext(display_, context_);
  eglTerminate(display_);
}

namespace {

// A headlight, lit on both sides (scans are open surfaces: their back shows through holes).
// Lit per vertex (Gouraud): at the triangle sizes of a budgeted cut (a few pixels each) it looks
// the same as per-pixel lighting, and llvmpipe shades ~10x more fragments than vertices.
const char* kVertexShader = R"(#version 450 core
layout(location = 0) in vec3 position;
layout(location = 1) in vec4 normal;
layout(location = 2) in vec4 color;
layout(location = 3) in vec2 uv;
uniform mat4 mvp;
uniform mat4 mv;
uniform vec3 tint;
uniform int mode;
out vec4 vColor;
out vec2 vUv;
void main() {
  vUv = uv;
  gl_Position = mvp * vec4(position, 1.0);
  vec3 n = normalize(mat3(mv) * normal.xyz);
  vec3 p = (mv * vec4(position, 1.0)).xyz;
  float d = abs(dot(n, normalize(-p)));
  // mode 0: shaded (stone, geometry only); 1: the tint (patch or LOD colours), both lit; 2: vertex
  // colours as they are, unlit (a scan's colours were captured under real light and carry its
  // shading already; lighting them again darkens every hollow twice: mtrender/color_mode.h)
  vec3 base = mode == 0 ? vec3(0.85, 0.82, 0.75) : tint;
  vColor = mode == 2 ? vec4(color.rgb, 1.0) : vec4(base * (0.2 + 0.8 * d), 1.0);
}
)";

// A textured patch in texture mode: its atlas, unlit like the vertex colours (a photographic
// texture carries the light it was captured under), trilinear from the mips.
const char* kFragmentShader = R"(#version 450 core
in vec4 vColor;
in vec2 vUv;
uniform int useTexture;
uniform sampler2D atlas;
out vec4 fragColor;
void main() { fragColor = useTexture != 0 ? vec4(texture(atlas, vUv).rgb, 1.0) : vColor; }
)";

// Occlusion query boxes: position only, no colour written.
const char* kBoxVertexShader = R"(#version 450 core
layout(location = 0) in vec3 position;
uniform mat4 mvp;
void main() { gl_Position = mvp * vec4(position, 1.0); }
)";

const char* kBoxFragmentShader = R"(#version 450 core
void main() {}
)";

uint32_t compile(GLenum type, const char* src) {
  GLuint s = glCreateShader(type);
  glShaderSource(s, 1, &src, nullptr);
  glCompileShader(s);
  GLint ok = 0;
  glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
  if (!ok) {
    char log[2048];
    glGetShaderInfoLog(s, sizeof log, nullptr, log);
    throw Error(std::string("mtrender: shader compile error: ") + log);
  }
  return s;
}

glm::vec3 hashColor(uint32_t id) {
  uint32_t h = id * 2654435761u;
  h ^= h >> 15;
  h *= 2246822519u;
  h ^= h >> 13;
  return {0.3f + 0.7f * float(h & 255) / 255.0f, 0.3f + 0.7f * float((h >> 8) & 255) / 255.0f,
          0.3f + 0.7f * float((h >> 16) & 255) / 255.0f};
}

glm::vec3 levelColor(uint32_t level) {
  static const glm::vec3 palette[] = {{0.9f, 0.2f, 0.2f}, {0.95f, 0.55f, 0.1f}, {0.95f, 0.9f, 0.2f}, {0.4f, 0.85f, 0.3f},
                                      {0.2f, 0.8f, 0.8f},  {0.25f, 0.45f, 0.95f}, {0.6f, 0.3f, 0.9f},  {0.9f, 0.4f, 0.8f}};
  return palette[level % 8];
}

}  // namespace

void splitTexturedVertices(const PatchView& v, std::vector<TexturedVertex>& vertices, std::vector<uint32_t>& indices) {
  vertices.clear();
  indices.resize(v.indexCount);
  std::vector<uint32_t> first(v.vertexCount, UINT32_MAX), next;
  next.reserve(v.vertexCount + v.vertexCount / 4);
  vertices.reserve(v.vertexCount + v.vertexCount / 4);
  for (uint32_t i = 0; i < v.indexCount; ++i) {
    const uint32_t p = v.indices[i];
    assert(p < v.vertexCount);
    const uint16_t u = v.cornerUV[2 * i], w = v.cornerUV[2 * i + 1];
    uint32_t k = first[p];
    while (k != UINT32_MAX && (vertices[k].uv[0] != u || vertices[k].uv[1] != w)) k = next[k];
    if (k == UINT32_MAX) {
      k = uint32_t(vertices.size());
      vertices.push_back({v.vertices[p], {u, w}});
      next.push_back(first[p]);
      first[p] = k;
    }
    indices[i] = k;
  }
}

uint64_t mippedTextureBytes(uint32_t width, uint32_t height) {
  uint64_t bytes = 0;
  for (;;) {
    bytes += uint64_t(width) * height * 4;
    if (width == 1 && height == 1) return bytes;
    width = std::max(1u, width / 2);
    height = std::max(1u, height / 2);
  }
}

GlRenderer::GlRenderer(uint64_t gpuCapBytes) : cap_(gpuCapBytes) {
  GLuint vs = compile(GL_VERTEX_SHADER, kVertexShader), fs = compile(GL_FRAGMENT_SHADER, kFragmentShader);
  program_ = glCreateProgram();
  glAttachShader(program_, vs);
  glAttachShader(program_, fs);
  glLinkProgram(program_);
  GLint ok = 0;
  glGetProgramiv(program_, GL_LINK_STATUS, &ok);
  if (!ok) throw Error("mtrender: shader link error");
  glDeleteShader(vs);
  glDeleteShader(fs);
  locMvp_ = glGetUniformLocation(program_, "mvp");
  locMv_ = glGetUniformLocation(program_, "mv");
  locTint_ = glGetUniformLocation(program_, "tint");
  locMode_ = glGetUniformLocation(program_, "mode");
  locUseTexture_ = glGetUniformLocation(program_, "useTexture");
  locAtlas_ = glGetUniformLocation(program_, "atlas");
  glProgramUniform1i(program_, locAtlas_, 0);
  glProgramUniform1i(program_, locUseTexture_, 0);
  glCreateVertexArrays(1, &vao_);
  glEnableVertexArrayAttrib(vao_, 0);
  glEnableVertexArrayAttrib(vao_, 1);
  glEnableVertexArrayAttrib(vao_, 2);
  glVertexArrayAttribFormat(vao_, 0, 3, GL_FLOAT, GL_FALSE, 0);
  glVertexArrayAttribFormat(vao_, 1, 4, GL_INT_2_10_10_10_REV, GL_TRUE, 12);
  glVertexArrayAttribFormat(vao_, 2, 4, GL_UNSIGNED_BYTE, GL_TRUE, 16);
  for (int a = 0; a < 3; ++a) glVertexArrayAttribBinding(vao_, a, 0);
  // Textured patches in texture mode: the same attributes plus the coordinate (TexturedVertex).
  glCreateVertexArrays(1, &vaoTex_);
  for (int a = 0; a < 4; ++a) glEnableVertexArrayAttrib(vaoTex_, a);
  glVertexArrayAttribFormat(vaoTex_, 0, 3, GL_FLOAT, GL_FALSE, 0);
  glVertexArrayAttribFormat(vaoTex_, 1, 4, GL_INT_2_10_10_10_REV, GL_TRUE, 12);
  glVertexArrayAttribFormat(vaoTex_, 2, 4, GL_UNSIGNED_BYTE, GL_TRUE, 16);
  glVertexArrayAttribFormat(vaoTex_, 3, 2, GL_UNSIGNED_SHORT, GL_TRUE, 20);
  for (int a = 0; a < 4; ++a) glVertexArrayAttribBinding(vaoTex_, a, 0);
}

void GlRenderer::release(Buffer& b) {
  glDeleteBuffers(1, &b.buffer);
  if (b.texture) {
    glDeleteTextures(1, &b.texture);
    const uint64_t t = mippedTextureBytes(b.textureWidth, b.textureHeight);
    gpuTextureBytes_ -= t;
  }
  gpuBytes_ -= b.bytes;
  b = Buffer();
}

GlRenderer::~GlRenderer() {
  for (auto& [id, b] : buffers_) release(b);
  if (!queries_.empty()) glDeleteQueries(GLsizei(queries_.size()), queries_.data());
  if (boxProgram_) {
    glDeleteProgram(boxProgram_);
    glDeleteVertexArrays(1, &boxVao_);
    glDeleteBuffers(1, &boxBuffer_);
  }
  deleteTarget(accumulation_);
  deleteTarget(presented_);
  if (fbo_) {
    glDeleteFramebuffers(1, &fbo_);
    glDeleteRenderbuffers(1, &colorRb_);
    glDeleteRenderbuffers(1, &depthRb_);
  }
  glDeleteVertexArrays(1, &vao_);
  glDeleteVertexArrays(1, &vaoTex_);
  glDeleteProgram(program_);
}

void GlRenderer::useOffscreen(int width, int height) {
  width_ = width;
  height_ = height;
  glCreateFramebuffers(1, &fbo_);
  glCreateRenderbuffers(1, &colorRb_);
  glCreateRenderbuffers(1, &depthRb_);
  glNamedRenderbufferStorage(colorRb_, GL_RGBA8, width, height);
  glNamedRenderbufferStorage(depthRb_, GL_DEPTH_COMPONENT24, width, height);
  glNamedFramebufferRenderbuffer(fbo_, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, colorRb_);
  glNamedFramebufferRenderbuffer(fbo_, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depthRb_);
  if (glCheckNamedFramebufferStatus(fbo_, GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
    throw Error("mtrender: the offscreen framebuffer is incomplete");
}

void GlRenderer::makeTarget(Target& t, int width, int height) {
  if (t.fbo && t.width == width && t.height == height) return;
  deleteTarget(t);
  glCreateFramebuffers(1, &t.fbo);
  glCreateRenderbuffers(1, &t.color);
  glCreateRenderbuffers(1, &t.depth);
  glNamedRenderbufferStorage(t.color, GL_RGBA8, width, height);
  glNamedRenderbufferStorage(t.depth, GL_DEPTH_COMPONENT24, width, height);
  glNamedFramebufferRenderbuffer(t.fbo, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, t.color);
  glNamedFramebufferRenderbuffer(t.fbo, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, t.depth);
  if (glCheckNamedFramebufferStatus(t.fbo, GL_FRAMEBUFFER) != GL_FRAMEBUFFER_COMPLETE)
    throw Error("mtrender: an accumulation framebuffer is incomplete");
  t.width = width;
  t.height = height;
}

void GlRenderer::deleteTarget(Target& t) {
  if (!t.fbo) return;
  glDeleteFramebuffers(1, &t.fbo);
  glDeleteRenderbuffers(1, &t.color);
  glDeleteRenderbuffers(1, &t.depth);
  t = Target();
}

void GlRenderer::keepOutputAsPresented(int width, int height) {
  makeTarget(presented_, width, height);
  glBlitNamedFramebuffer(fbo_, presented_.fbo, 0, 0, width, height, 0, 0, width, height, GL_COLOR_BUFFER_BIT, GL_NEAREST);
}

void GlRenderer::beginAccumulation(const View& view, const DrawSettings& s, bool clear) {
  ++frame_;
  width_ = view.width;
  height_ = view.height;
  makeTarget(accumulation_, view.width, view.height);
  glBindFramebuffer(GL_FRAMEBUFFER, accumulation_.fbo);
  glViewport(0, 0, view.width, view.height);
  glClearColor(s.background.r, s.background.g, s.background.b, 1.0f);
  glClearDepth(1.0);
  if (clear) glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  setFrameState(view, s);
}

void GlRenderer::presentAccumulation() { std::swap(accumulation_, presented_); }

void GlRenderer::showPresented() {
  if (!presented_.fbo) return;
  glBlitNamedFramebuffer(presented_.fbo, fbo_, 0, 0, presented_.width, presented_.height, 0, 0, presented_.width,
                         presented_.height, GL_COLOR_BUFFER_BIT, GL_NEAREST);
}

void GlRenderer::beginFrame(const View& view, const DrawSettings& s) {
  ++frame_;
  width_ = view.width;
  height_ = view.height;
  glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
  glViewport(0, 0, view.width, view.height);
  glClearColor(s.background.r, s.background.g, s.background.b, 1.0f);
  glClearDepth(1.0);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  setFrameState(view, s);
}

void GlRenderer::setFrameState(const View& view, const DrawSettings& s) {
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glDisable(GL_CULL_FACE);
  glPolygonMode(GL_FRONT_AND_BACK, s.wireframe ? GL_LINE : GL_FILL);
  wireframe_ = s.wireframe;
  glUseProgram(program_);
  viewD_ = view.viewD;
  projD_ = view.projD;
  nearPlane_ = view.nearPlane;
  glm::mat4 mvp = view.projMatrix * view.viewMatrix;
  glUniformMatrix4fv(locMvp_, 1, GL_FALSE, glm::value_ptr(mvp));
  glUniformMatrix4fv(locMv_, 1, GL_FALSE, glm::value_ptr(view.viewMatrix));
  glUniform1i(locMode_, s.mode == ColorMode::Shaded ? 0 : s.mode == ColorMode::Vertex || s.mode == ColorMode::Texture ? 2 : 1);
  glUniform3f(locTint_, 1, 1, 1);
  mode_ = s.mode;
  glBindVertexArray(vao_);
}

void GlRenderer::warmUp(const DrawSettings& settings) {
  View v;
  v.width = std::max(width_, 1);
  v.height = std::max(height_, 1);
  beginFrame(v, settings);
  // A small visible triangle (identity matrices: clip space), so the draw reaches rasterization.
  RenderVertex tri[3] = {};
  const float xy[3][2] = {{-0.05f, -0.05f}, {0.05f, -0.05f}, {0.0f, 0.05f}};
  const float up[3] = {0, 0, 1};
  for (int k = 0; k < 3; ++k) {
    tri[k].position[0] = xy[k][0];
    tri[k].position[1] = xy[k][1];
    tri[k].normal = packNormal(up);
  }
  const uint32_t idx[3] = {0, 1, 2};
  GLuint b = 0;
  glCreateBuffers(1, &b);
  glNamedBufferStorage(b, sizeof tri + sizeof idx, nullptr, GL_DYNAMIC_STORAGE_BIT);
  glNamedBufferSubData(b, 0, sizeof tri, tri);
  glNamedBufferSubData(b, sizeof tri, sizeof idx, idx);
  glVertexArrayVertexBuffer(vao_, 0, b, 0, sizeof(RenderVertex));
  glVertexArrayElementBuffer(vao_, b);
  glDrawElements(GL_TRIANGLES, 3, GL_UNSIGNED_INT, reinterpret_cast<const void*>(sizeof tri));
  glFinish();
  glDeleteBuffers(1, &b);
  --frame_;  // not a frame of the cut
}

void GlRenderer::evictFor(uint64_t bytes) {
  if (gpuBytes_ + bytes <= cap_) return;
  // Least recently drawn first. In the hard cap that may include buffers drawn earlier in this
  // frame: their draws are already submitted, and GL keeps a deleted buffer alive until the draws
  // that use it are done, so the image is unaffected (a cut larger than the GPU cache is simply
  // re-uploaded every frame). The soft cap (test switch) keeps this frame's buffers.
  std::vector<std::pair<uint64_t, uint32_t>> old;
  for (const auto& [id, b] : buffers_)
    if (hardCap_ || b.lastFrame < frame_) old.push_back({b.lastUse, id});
  std::sort(old.begin(), old.end());
  for (const auto& [f, id] : old) {
    if (gpuBytes_ + bytes <= cap_) break;
    auto it = buffers_.find(id);
    release(it->second);
    buffers_.erase(it);
  }
}

uint32_t GlRenderer::drawPatch(uint32_t id, uint32_t level, const double origin[3], const std::function<PatchView()>& fetch) {
  auto it = buffers_.find(id);
  // Uploaded without its atlas (another mode): uploaded again with it.
  if (it != buffers_.end() && mode_ == ColorMode::Texture && it->second.hasTexture && !it->second.texture) {
    release(it->second);
    buffers_.erase(it);
    it = buffers_.end();
  }
  if (it == buffers_.end()) {
    PatchView v = fetch();
    if (v.vertexCount == 0 || v.indexCount == 0) return 0;
    Buffer b;
    b.hasTexture = v.textured();
    const bool withTexture = mode_ == ColorMode::Texture && b.hasTexture;
    std::vector<TexturedVertex> split;
    std::vector<uint32_t> splitIndices;
    const void* vdata = v.vertices;
    const uint32_t* idata = v.indices;
    uint64_t vbytes = uint64_t(v.vertexCount) * sizeof(RenderVertex);
    uint64_t tbytes = 0;
    if (withTexture) {
      splitTexturedVertices(v, split, splitIndices);
      vdata = split.data();
      idata = splitIndices.data();
      vbytes = uint64_t(split.size()) * sizeof(TexturedVertex);
      b.stride = sizeof(TexturedVertex);
      tbytes = mippedTextureBytes(v.texWidth, v.texHeight);
    }
    b.indexOffset = vbytes;
    b.indexCount = v.indexCount;
    b.bytes = vbytes + uint64_t(v.indexCount) * 4 + tbytes;
    if (hardCap_) {
      evictFor(b.bytes);
      if (gpuBytes_ + b.bytes > cap_) return 0;  // one patch larger than the whole cap
    }
    glCreateBuffers(1, &b.buffer);
    glNamedBufferStorage(b.buffer, GLsizeiptr(vbytes + uint64_t(v.indexCount) * 4), nullptr, GL_DYNAMIC_STORAGE_BIT);
    glNamedBufferSubData(b.buffer, 0, GLsizeiptr(vbytes), vdata);
    glNamedBufferSubData(b.buffer, GLintptr(vbytes), GLsizeiptr(uint64_t(v.indexCount) * 4), idata);
    if (withTexture) {
      // The atlas with its full mip chain: a coarse patch seen from far samples a mip, not an
      // aliased texel of the full image.
      const int levels = 1 + int(std::floor(std::log2(double(std::max(v.texWidth, v.texHeight)))));
      glCreateTextures(GL_TEXTURE_2D, 1, &b.texture);
      glTextureStorage2D(b.texture, levels, GL_RGBA8, v.texWidth, v.texHeight);
      glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
      glTextureSubImage2D(b.texture, 0, 0, 0, v.texWidth, v.texHeight, GL_RGB, GL_UNSIGNED_BYTE, v.texels);
      glGenerateTextureMipmap(b.texture);
      glTextureParameteri(b.texture, GL_TEXTURE_MIN_FILTER, GL_LINEAR_MIPMAP_LINEAR);
      glTextureParameteri(b.texture, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
      glTextureParameteri(b.texture, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
      glTextureParameteri(b.texture, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
      b.textureWidth = v.texWidth;
      b.textureHeight = v.texHeight;
      gpuTextureBytes_ += tbytes;
    }
    gpuBytes_ += b.bytes;
    gpuPeak_ = std::max(gpuPeak_, gpuBytes_);
    ++uploads_;
    it = buffers_.emplace(id, b).first;
  }
  Buffer& b = it->second;
  b.lastFrame = frame_;
  b.lastUse = ++uses_;
  if (mode_ == ColorMode::Patch) {
    glm::vec3 c = hashColor(id);
    glUniform3f(locTint_, c.r, c.g, c.b);
  } else if (mode_ == ColorMode::Lod) {
    glm::vec3 c = levelColor(level);
    glUniform3f(locTint_, c.r, c.g, c.b);
  }
  // Camera-relative: the translation to the patch's origin is composed with the view in double;
  // the float matrix holds only the small offset from the eye.
  const glm::dmat4 mvD = glm::translate(viewD_, glm::dvec3(origin[0], origin[1], origin[2]));
  const glm::mat4 mv(mvD), mvp(projD_ * mvD);
  glUniformMatrix4fv(locMvp_, 1, GL_FALSE, glm::value_ptr(mvp));
  glUniformMatrix4fv(locMv_, 1, GL_FALSE, glm::value_ptr(mv));
  const bool textured = mode_ == ColorMode::Texture && b.texture != 0;
  const GLuint vao = textured ? vaoTex_ : vao_;
  if (textured) {
    glBindTextureUnit(0, b.texture);
    ++texturedDraws_;
  }
  glUniform1i(locUseTexture_, textured ? 1 : 0);
  glBindVertexArray(vao);
  glVertexArrayVertexBuffer(vao, 0, b.buffer, 0, GLsizei(b.stride));
  glVertexArrayElementBuffer(vao, b.buffer);
  glDrawElements(GL_TRIANGLES, GLsizei(b.indexCount), GL_UNSIGNED_INT, reinterpret_cast<const void*>(b.indexOffset));
  return b.indexCount / 3;
}

void GlRenderer::endFrame() {
  glPolygonMode(GL_FRONT_AND_BACK, GL_FILL);
  // The soft cap of the test switch: trimmed after the frame.
  if (!hardCap_) evictFor(0);
}

void GlRenderer::readDepth(std::vector<float>& out, bool presented) const {
  const Target* t = presented ? &presented_ : nullptr;
  const int w = t ? t->width : width_, h = t ? t->height : height_;
  out.resize(size_t(w) * h);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, t ? t->fbo : fbo_);
  glPixelStorei(GL_PACK_ALIGNMENT, 4);
  glReadPixels(0, 0, w, h, GL_DEPTH_COMPONENT, GL_FLOAT, out.data());
}

void GlRenderer::queryHidden(const std::vector<QuerySphere>& spheres, std::vector<uint8_t>& hidden, bool presented) {
  hidden.assign(spheres.size(), 0);
  if (spheres.empty()) return;
  if (!boxProgram_) {
    GLuint vs = compile(GL_VERTEX_SHADER, kBoxVertexShader), fs = compile(GL_FRAGMENT_SHADER, kBoxFragmentShader);
    boxProgram_ = glCreateProgram();
    glAttachShader(boxProgram_, vs);
    glAttachShader(boxProgram_, fs);
    glLinkProgram(boxProgram_);
    GLint ok = 0;
    glGetProgramiv(boxProgram_, GL_LINK_STATUS, &ok);
    if (!ok) throw Error("mtrender: box shader link error");
    glDeleteShader(vs);
    glDeleteShader(fs);
    locBoxMvp_ = glGetUniformLocation(boxProgram_, "mvp");
    // The unit cube [-1, 1]^3: 8 corners, 12 triangles.
    const float corners[8][3] = {{-1, -1, -1}, {1, -1, -1}, {-1, 1, -1}, {1, 1, -1},
                                 {-1, -1, 1},  {1, -1, 1},  {-1, 1, 1},  {1, 1, 1}};
    const uint32_t idx[36] = {0, 1, 3, 0, 3, 2, 4, 6, 7, 4, 7, 5, 0, 4, 5, 0, 5, 1,
                              2, 3, 7, 2, 7, 6, 0, 2, 6, 0, 6, 4, 1, 5, 7, 1, 7, 3};
    glCreateBuffers(1, &boxBuffer_);
    glNamedBufferStorage(boxBuffer_, sizeof corners + sizeof idx, nullptr, GL_DYNAMIC_STORAGE_BIT);
    glNamedBufferSubData(boxBuffer_, 0, sizeof corners, corners);
    glNamedBufferSubData(boxBuffer_, sizeof corners, sizeof idx, idx);
    glCreateVertexArrays(1, &boxVao_);
    glEnableVertexArrayAttrib(boxVao_, 0);
    glVertexArrayAttribFormat(boxVao_, 0, 3, GL_FLOAT, GL_FALSE, 0);
    glVertexArrayAttribBinding(boxVao_, 0, 0);
    glVertexArrayVertexBuffer(boxVao_, 0, boxBuffer_, 0, 3 * sizeof(float));
    glVertexArrayElementBuffer(boxVao_, boxBuffer_);
  }
  if (queries_.size() < spheres.size()) {
    const size_t old = queries_.size();
    queries_.resize(spheres.size());
    glCreateQueries(GL_ANY_SAMPLES_PASSED_CONSERVATIVE, GLsizei(spheres.size() - old), queries_.data() + old);
  }
  if (presented && presented_.fbo) glBindFramebuffer(GL_FRAMEBUFFER, presented_.fbo);
  glPolygonMode(GL_FRONT_AND_BACK, GL_FILL);
  glColorMask(GL_FALSE, GL_FALSE, GL_FALSE, GL_FALSE);
  glDepthMask(GL_FALSE);
  glEnable(GL_DEPTH_TEST);
  glDepthFunc(GL_LESS);
  glUseProgram(boxProgram_);
  glBindVertexArray(boxVao_);
  std::vector<uint8_t> asked(spheres.size(), 0);
  for (size_t i = 0; i < spheres.size(); ++i) {
    const QuerySphere& q = spheres[i];
    // In eye space, in double (camera-relative: a georeferenced centre is millions of units out);
    // the box's near face is in front of the sphere's nearest point, so the test is conservative.
    const glm::dvec4 c = viewD_ * glm::dvec4(q.center[0], q.center[1], q.center[2], 1.0);
    if (-c.z - q.radius <= nearPlane_) continue;  // reaches the near plane: visible
    glm::dmat4 m(q.radius);
    m[3] = glm::dvec4(c.x, c.y, c.z, 1.0);
    const glm::mat4 mvp(projD_ * m);
    glUniformMatrix4fv(locBoxMvp_, 1, GL_FALSE, glm::value_ptr(mvp));
    glBeginQuery(GL_ANY_SAMPLES_PASSED_CONSERVATIVE, queries_[i]);
    glDrawElements(GL_TRIANGLES, 36, GL_UNSIGNED_INT, reinterpret_cast<const void*>(8 * 3 * sizeof(float)));
    glEndQuery(GL_ANY_SAMPLES_PASSED_CONSERVATIVE);
    asked[i] = 1;
  }
  for (size_t i = 0; i < spheres.size(); ++i) {
    if (!asked[i]) continue;
    GLuint any = 1;
    glGetQueryObjectuiv(queries_[i], GL_QUERY_RESULT, &any);
    hidden[i] = any == 0;
  }
  glColorMask(GL_TRUE, GL_TRUE, GL_TRUE, GL_TRUE);
  glDepthMask(GL_TRUE);
  glPolygonMode(GL_FRONT_AND_BACK, wireframe_ ? GL_LINE : GL_FILL);
  glUseProgram(program_);
  glBindVertexArray(vao_);
  if (presented && presented_.fbo) glBindFramebuffer(GL_FRAMEBUFFER, fbo_);
}

void GlRenderer::finish() { glFinish(); }

Image GlRenderer::readPixels() const {
  Image img;
  img.width = width_;
  img.height = height_;
  img.rgba.resize(size_t(width_) * height_ * 4);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo_);
  if (!fbo_) glReadBuffer(GL_BACK);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  std::vector<uint8_t> tmp(img.rgba.size());
  glReadPixels(0, 0, width_, height_, GL_RGBA, GL_UNSIGNED_BYTE, tmp.data());
  const size_t row = size_t(width_) * 4;
  for (int y = 0; y < height_; ++y) std::memcpy(&img.rgba[size_t(y) * row], &tmp[size_t(height_ - 1 - y) * row], row);
  return img;
}

}  // namespace mt::render
