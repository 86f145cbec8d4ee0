// mtrender/camera.h: camera poses, the view derived from one (matrices, frustum planes, the
// pixels-per-unit factor that projects object-space errors to the screen, BMT 5.1), and camera
// paths: a small text format plus built-in generators, so a benchmark needs no extra file.
//
// Camera path text format (docs/mtrender.md), one pose per frame:
//   # comment                      lines starting with '#' are ignored
//   mtrender-camera-path 1         optional first line
//   space unit|object              unit (default): coordinates are relative to the scene's bounding
//                                  sphere, p = centre + radius * v, so one path fits every model;
//                                  object: coordinates are object space
//   fov DEGREES                    vertical field of view for the following poses (default 45)
//   EX EY EZ  TX TY TZ  [UX UY UZ] one pose: eye, target, optional up (default 0 0 1)
// A run with more frames than poses holds the last pose (the camera has stopped).
#pragma once

#include <glm/glm.hpp>
#include <string>
#include <vector>

namespace mt::render {

struct CameraPose {
  glm::dvec3 eye{0, -3, 1}, target{0, 0, 0}, up{0, 0, 1};
  double fovDeg = 45;
};

struct View {
  glm::mat4 viewMatrix{1}, projMatrix{1};
  // The same in double: the GL backend composes each patch's model-view matrix from these and the
  // patch's double origin (camera-relative drawing), so nothing large ever reaches a float.
  glm::dmat4 viewD{1}, projD{1};
  glm::dvec3 eye{0};
  glm::dvec3 forward{0, 0, -1};
  glm::dvec4 planes[6];   // inside: dot(plane.xyz, p) + plane.w >= 0 (normalized)
  double pixelsPerUnit = 1;  // H / (2 tan(fovy/2)): screen error = error * this / distance
  double nearPlane = 0.01, farPlane = 100;
  int width = 1, height = 1;
};

// Near/far planes are fitted to the scene's bounding sphere (centre c, radius r).
View makeView(const CameraPose& pose, int width, int height, const glm::dvec3& sceneCenter, double sceneRadius);

// The pose `frames` frames ahead, extrapolating the motion from `prev` to `cur` (Derzapf et al.
// 4.3: the frustum extrapolated over the next 10 frames, used for prefetching).
CameraPose extrapolate(const CameraPose& prev, const CameraPose& cur, int frames);

struct CameraPath {
  std::vector<CameraPose> poses;  // object space
  const CameraPose& at(size_t frame) const { return poses[std::min(frame, poses.size() - 1)]; }
};

// Reads a path file (format above). Throws mt::Error "PATH: line N: ...".
CameraPath loadCameraPath(const std::string& path, const glm::dvec3& center, double radius);
// Writes poses in object space ("space object").
void saveCameraPath(const std::string& path, const CameraPath& cameraPath);

// Built-in paths of `frames` poses, in unit space mapped to the scene:
//   orbit       one turn around the model with elevation changes and zooms (1.3 to 3.5 radii);
//               the last 15% of the frames hold still.
//   flythrough  fast turns and zooms: dives from far away to close to the surface, sweeps along it,
//               whips around by 90-180 degrees within a few frames, pulls back out; the last 15%
//               of the frames hold still (the camera stops, for "time to 1 px after stopping").
//   fixed       the default view, every frame.
// Returns false for an unknown name.
bool builtinCameraPath(const std::string& name, int frames, const glm::dvec3& center, double radius, CameraPath& out);

// The default view: from the -y side, slightly above, the whole model in view.
CameraPose defaultPose(const glm::dvec3& center, double radius);

}  // namespace mt::render
