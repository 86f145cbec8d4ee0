// mtrender/viewer.h: the interactive viewer: a GLFW window (OpenGL 4.5 core), orbit / pan / zoom /
// fly navigation, a Dear ImGui HUD, keys for wireframe, patch and LOD colours, freezing the cut,
// screenshots, and recording / replaying camera paths. Needs X (tests run it under xvfb-run).
#pragma once

#include <string>

#include "mtrender/color_mode.h"
#include "mtrender/engine.h"
#include "mtrender/gl_renderer.h"

namespace mt::render {

struct ViewerOptions {
  EngineOptions engine;
  int width = 1280, height = 720;
  std::string cameraPath;      // replayed from the start when given (file or built-in name)
  int maxFrames = 0;           // > 0: close after this many frames
  std::string screenshotPath;  // written from the last frame when closing
  std::string recordPath = "mtrender-path.txt";
  std::string statsPath;       // CSV as in headless mode
  DrawSettings draw;
  ColorSupport colors;         // what the C key cycles through (color_mode.h)
};

// Returns the process exit code. Throws mt::Error (no display, no GL 4.5, bad file).
int runViewer(const ViewerOptions& options);

}  // namespace mt::render
