#define GL_GLEXT_PROTOTYPES 1
#include "mtrender/viewer.h"

#include <GL/glcorearb.h>
#include <GLFW/glfw3.h>
#if MT_HAVE_IMGUI
#include <imgui.h>
#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_opengl3.h>
#endif

#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>

#include "base/error.h"
#include "base/output_path.h"

namespace mt::render {

namespace {

struct OrbitCamera {
  glm::dvec3 target{0};
  double distance = 3, yaw = -1.5707963, pitch = 0.45, fov = 45;
  CameraPose pose() const {
    CameraPose p;
    p.target = target;
    p.eye = target + distance * glm::dvec3(std::cos(pitch) * std::cos(yaw), std::cos(pitch) * std::sin(yaw), std::sin(pitch));
    p.fovDeg = fov;
    return p;
  }
};

struct ViewerState {
  OrbitCamera cam;
  double lastX = 0, lastY = 0;
  bool hud = true, frozen = false, recording = false, replaying = false;
  size_t replayFrame = 0;
  int screenshots = 0;
  bool wantScreenshot = false;
  DrawSettings draw;
  double scrollAccum = 0;
  CameraPath replay, recorded;
  bool prevKeys[512] = {};
  double fps = 0;
  uint32_t lastImageFrames = 0;  // frames the last still image took (progressive refinement)
};

bool hudWantsMouse() {
#if MT_HAVE_IMGUI
  return ImGui::GetIO().WantCaptureMouse;
#else
  return false;
#endif
}

bool hudWantsKeyboard() {
#if MT_HAVE_IMGUI
  return ImGui::GetIO().WantCaptureKeyboard;
#else
  return false;
#endif
}

void onScroll(GLFWwindow* w, double, double dy) {
  auto* s = static_cast<ViewerState*>(glfwGetWindowUserPointer(w));
  if (hudWantsMouse()) return;
  s->scrollAccum += dy;
}

// A GLFW window with an OpenGL 4.5 core context (and the HUD's ImGui context).
GLFWwindow* openWindow(int width, int height) {
  if (!glfwInit()) throw Error("mtrender: cannot open a window (no X display? use --headless)");
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 4);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 5);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  GLFWwindow* window = glfwCreateWindow(width, height, "mtrender", nullptr, nullptr);
  if (!window) {
    glfwTerminate();
    throw Error("mtrender: cannot create an OpenGL 4.5 core window");
  }
  glfwMakeContextCurrent(window);
  glfwSwapInterval(0);  // the frame budget, not the display, paces the loop
#if MT_HAVE_IMGUI
  IMGUI_CHECKVERSION();
  ImGui::CreateContext();
  ImGui::GetIO().IniFilename = nullptr;
  ImGui_ImplGlfw_InitForOpenGL(window, true);
  ImGui_ImplOpenGL3_Init("#version 450");
#endif
  return window;
}

void closeWindow(GLFWwindow* window) {
#if MT_HAVE_IMGUI
  ImGui_ImplOpenGL3_Shutdown();
  ImGui_ImplGlfw_Shutdown();
  ImGui::DestroyContext();
#endif
  glfwDestroyWindow(window);
  glfwTerminate();
}

// A key pressed since the last frame (and not taken by the HUD).
bool pressed(GLFWwindow* window, ViewerState& st, int key) {
  bool down = glfwGetKey(window, key) == GLFW_PRESS;
  bool edge = down && !st.prevKeys[key];
  st.prevKeys[key] = down;
  return edge && !hudWantsKeyboard();
}

void handleKeys(GLFWwindow* window, ViewerState& st, Engine& engine, const ViewerOptions& options) {
  if (pressed(window, st, GLFW_KEY_ESCAPE)) glfwSetWindowShouldClose(window, 1);
  if (pressed(window, st, GLFW_KEY_X)) st.draw.wireframe = !st.draw.wireframe;
  if (pressed(window, st, GLFW_KEY_C)) st.draw.mode = nextColorMode(st.draw.mode, options.colors);
  if (pressed(window, st, GLFW_KEY_F)) engine.extract().setFrozen(st.frozen = !st.frozen);
  if (pressed(window, st, GLFW_KEY_H)) st.hud = !st.hud;
  if (pressed(window, st, GLFW_KEY_P)) st.wantScreenshot = true;
  if (pressed(window, st, GLFW_KEY_R)) {
    st.recording = !st.recording;
    if (st.recording) st.recorded.poses.clear();
    else if (!st.recorded.poses.empty()) saveCameraPath(options.recordPath, st.recorded);
  }
  if (pressed(window, st, GLFW_KEY_L)) {
    if (!st.recorded.poses.empty()) st.replay = st.recorded;
    if (!st.replay.poses.empty()) st.replaying = true, st.replayFrame = 0;
  }
}

// Mouse (left drag orbit, right drag pan, wheel zoom) and W/S/A/D/Q/E flying; any of them stops
// a replay.
void navigate(GLFWwindow* window, ViewerState& st) {
  const bool mouseFree = !hudWantsMouse(), keysFree = !hudWantsKeyboard();
  double x, y;
  glfwGetCursorPos(window, &x, &y);
  const double dx = x - st.lastX, dy = y - st.lastY;
  st.lastX = x, st.lastY = y;
  if (mouseFree) {
    if (glfwGetMouseButton(window, GLFW_MOUSE_BUTTON_LEFT) == GLFW_PRESS) {  // orbit
      st.cam.yaw -= dx * 0.005;
      st.cam.pitch = std::clamp(st.cam.pitch + dy * 0.005, -1.55, 1.55);
      st.replaying = false;
    }
    if (glfwGetMouseButton(window, GLFW_MOUSE_BUTTON_RIGHT) == GLFW_PRESS) {  // pan
      CameraPose p = st.cam.pose();
      glm::dvec3 f = glm::normalize(p.target - p.eye), r = glm::normalize(glm::cross(f, glm::dvec3(0, 0, 1)));
      glm::dvec3 u = glm::cross(r, f);
      double k = st.cam.distance * 0.0015;
      st.cam.target += -dx * k * r + dy * k * u;
      st.replaying = false;
    }
  }
  if (st.scrollAccum != 0) {  // zoom
    st.cam.distance *= std::pow(0.9, st.scrollAccum);
    st.scrollAccum = 0;
    st.replaying = false;
  }
  // fly: W/S forward/back, A/D sideways, Q/E down/up
  CameraPose p = st.cam.pose();
  glm::dvec3 f = glm::normalize(p.target - p.eye), r = glm::normalize(glm::cross(f, glm::dvec3(0, 0, 1)));
  double step = 0.01 * st.cam.distance;
  glm::dvec3 m(0);
  if (keysFree) {
    if (glfwGetKey(window, GLFW_KEY_W) == GLFW_PRESS) m += f;
    if (glfwGetKey(window, GLFW_KEY_S) == GLFW_PRESS) m -= f;
    if (glfwGetKey(window, GLFW_KEY_D) == GLFW_PRESS) m += r;
    if (glfwGetKey(window, GLFW_KEY_A) == GLFW_PRESS) m -= r;
    if (glfwGetKey(window, GLFW_KEY_E) == GLFW_PRESS) m += glm::dvec3(0, 0, 1);
    if (glfwGetKey(window, GLFW_KEY_Q) == GLFW_PRESS) m -= glm::dvec3(0, 0, 1);
  }
  if (m != glm::dvec3(0)) {
    st.cam.target += step * m;
    st.replaying = false;
  }
}

// The frame's camera: the replayed path's next pose (the orbit camera follows it), else the
// orbit camera's; recorded when recording.
CameraPose nextPose(ViewerState& st, const ViewerOptions& options) {
  CameraPose pose = st.cam.pose();
  if (st.replaying) {
    pose = st.replay.at(st.replayFrame++);
    if (st.replayFrame >= st.replay.poses.size() && options.maxFrames <= 0) st.replaying = false;
    st.cam.target = pose.target;
    glm::dvec3 d = pose.eye - pose.target;
    st.cam.distance = glm::length(d);
    if (st.cam.distance > 0) {
      st.cam.pitch = std::asin(std::clamp(d.z / st.cam.distance, -1.0, 1.0));
      st.cam.yaw = std::atan2(d.y, d.x);
    }
  }
  if (st.recording) st.recorded.poses.push_back(pose);
  return pose;
}

// The HUD (Dear ImGui), or its figures in the window title every 10th frame without ImGui.
void drawHud(GLFWwindow* window, const ViewerState& st, const FrameRecord& last, const ViewerOptions& options,
             int frame) {
#if MT_HAVE_IMGUI
  (void)window, (void)frame;
  ImGui_ImplOpenGL3_NewFrame();
  ImGui_ImplGlfw_NewFrame();
  ImGui::NewFrame();
  if (st.hud) {
    ImGui::SetNextWindowPos(ImVec2(8, 8), ImGuiCond_Once);
    ImGui::Begin("mtrender", nullptr, ImGuiWindowFlags_AlwaysAutoResize);
    ImGui::Text("%.1f fps   frame %.1f ms (budget %.0f)", st.fps, last.frameMs, options.engine.extract.budgetMs);
    ImGui::Text("extract %.3f ms", last.extractMs);
    ImGui::Text("triangles %llu (drawn %llu, budget %llu)", (unsigned long long)last.triangles,
                (unsigned long long)last.drawnTriangles, (unsigned long long)last.budgetTriangles);
    ImGui::Text("patches %u (drawn %u)", last.patches, last.drawnPatches);
    ImGui::Text("cache %.1f / %.1f MiB   gpu %.1f MiB", double(last.cacheBytes) / 1048576.0,
                double(options.engine.cacheBytes) / 1048576.0, double(last.gpuBytes) / 1048576.0);
    ImGui::Text("loads %u   misses %u", last.loads, last.misses);
    ImGui::Text("screen error %.2f px   LOD scale %.2f", last.maxScreenError, last.lodScale);
    if (last.accumulating) ImGui::Text("still view: refining, images of %u frame(s)", st.lastImageFrames);
    ImGui::Separator();
    ImGui::Text("[C] %s  [X] wireframe %s  [F] cut %s", colorModeName(st.draw.mode), st.draw.wireframe ? "on" : "off",
                st.frozen ? "FROZEN" : "live");
    ImGui::Text("[R] record %s  [L] replay %s  [P] screenshot  [H] HUD", st.recording ? "ON" : "off",
                st.replaying ? "ON" : "off");
    ImGui::Text("mouse: left orbit, right pan, wheel zoom; WASD/QE fly");
    ImGui::End();
  }
  ImGui::Render();
  ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
#else
  (void)options;
  if (st.hud && frame % 10 == 0) {
    char title[256];
    std::snprintf(title, sizeof title, "mtrender  %.1f fps  %.1f ms  %llu tri  %u patches  cache %.1f MiB  misses %u  %.2f px",
                  st.fps, last.frameMs, (unsigned long long)last.triangles, last.patches,
                  double(last.cacheBytes) / 1048576.0, last.misses, last.maxScreenError);
    glfwSetWindowTitle(window, title);
  }
#endif
}

// The viewer's stats CSV (the first columns of the headless one), written under a temporary name
// and renamed when complete, like every output.
void writeStats(const std::string& path, const std::vector<FrameRecord>& recs) {
  const std::string tmp = uniqueTempName(path);
  {
    std::ofstream out(tmp);
    out << "frame,frame_ms,extract_ms,triangles,patches,loads,misses,cache_bytes,max_screen_error\n";
    for (size_t i = 0; i < recs.size(); ++i)
      out << i << ',' << recs[i].frameMs << ',' << recs[i].extractMs << ',' << recs[i].triangles << ','
          << recs[i].patches << ',' << recs[i].loads << ',' << recs[i].misses << ',' << recs[i].cacheBytes << ','
          << recs[i].maxScreenError << '\n';
    if (!out.flush()) {
      std::remove(tmp.c_str());
      fail(path, "cannot write the stats CSV");
    }
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    fail(path, "cannot rename the stats CSV into place");
  }
}

// The window's loop until it is closed (or maxFrames); returns the frames drawn.
int viewLoop(GLFWwindow* window, const ViewerOptions& options, Engine& engine, GlRenderer& gl, ViewerState& st,
             std::vector<FrameRecord>& recs) {
  CameraPose prev = st.cam.pose();
  FrameRecord last;
  auto lastTime = std::chrono::steady_clock::now();
  int frame = 0;
  while (!glfwWindowShouldClose(window)) {
    glfwPollEvents();
    handleKeys(window, st, engine, options);
    navigate(window, st);
    const CameraPose pose = nextPose(st, options);
    int fbw = 0, fbh = 0;
    glfwGetFramebufferSize(window, &fbw, &fbh);
    if (fbw < 1 || fbh < 1) continue;
    last = engine.frame(pose, prev, gl, st.draw, fbw, fbh);
    if (!last.accumulating) st.lastImageFrames = 0;
    else if (last.imageFrames) st.lastImageFrames = last.imageFrames;
    prev = pose;
    if (!options.statsPath.empty()) recs.push_back(last);
    ++frame;
    const bool closing = options.maxFrames > 0 && frame >= options.maxFrames;
    if (st.wantScreenshot) {
      char name[64];
      std::snprintf(name, sizeof name, "mtrender-%04d.png", st.screenshots++);
      writePng(name, gl.readPixels());
      st.wantScreenshot = false;
    }
    if (closing && !options.screenshotPath.empty()) writePng(options.screenshotPath, gl.readPixels());
    auto now = std::chrono::steady_clock::now();
    double dt = std::chrono::duration<double>(now - lastTime).count();
    lastTime = now;
    st.fps = st.fps == 0 ? 1.0 / std::max(dt, 1e-6) : 0.9 * st.fps + 0.1 / std::max(dt, 1e-6);
    drawHud(window, st, last, options, frame);
    glfwSwapBuffers(window);
    if (closing) glfwSetWindowShouldClose(window, 1);
  }
  return frame;
}

}  // namespace

int runViewer(const ViewerOptions& options) {
  GLFWwindow* window = openWindow(options.width, options.height);
  int exitCode = 0;
  {
    Engine engine(options.engine);
    GlRenderer gl(engine.options().gpuCacheBytes);
    ViewerState st;
    st.draw = options.draw;
    st.cam.target = engine.center();
    st.cam.distance = 2.45 * engine.radius();
    glfwSetWindowUserPointer(window, &st);
    glfwSetScrollCallback(window, onScroll);  // ImGui chains to the previous callbacks
    if (!options.cameraPath.empty()) {
      int n = options.maxFrames > 0 ? options.maxFrames : 600;
      if (!builtinCameraPath(options.cameraPath, n, engine.center(), engine.radius(), st.replay))
        st.replay = loadCameraPath(options.cameraPath, engine.center(), engine.radius());
      st.replaying = true;
    }
    engine.start();
    std::vector<FrameRecord> recs;
    const int frame = viewLoop(window, options, engine, gl, st, recs);
    if (st.recording && !st.recorded.poses.empty()) saveCameraPath(options.recordPath, st.recorded);
    if (!options.statsPath.empty()) writeStats(options.statsPath, recs);
    std::printf("frames %d\nbad_patches %llu\n", frame, (unsigned long long)engine.badPatches());
    std::printf("undrawn_files %zu\n", engine.warnUndrawnFiles());
  }
  closeWindow(window);
  return exitCode;
}

}  // namespace mt::render
