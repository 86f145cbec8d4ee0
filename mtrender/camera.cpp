#include "mtrender/camera.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <glm/gtc/matrix_transform.hpp>
#include <sstream>

#include "base/error.h"

namespace mt::render {

View makeView(const CameraPose& pose, int width, int height, const glm::dvec3& c, double r) {
  View v;
  v.width = width;
  v.height = height;
  v.eye = pose.eye;
  glm::dvec3 dir = pose.target - pose.eye;
  if (glm::length(dir) < 1e-12) dir = {0, 1, 0};
  v.forward = glm::normalize(dir);
  glm::dvec3 up = pose.up;
  if (glm::length(glm::cross(v.forward, up)) < 1e-6) up = std::abs(v.forward.z) < 0.9 ? glm::dvec3(0, 0, 1) : glm::dvec3(0, 1, 0);
  const double dist = glm::length(c - pose.eye);
  // The depth range hugs the scene's sphere; inside it, a near plane of r/2000 keeps 24-bit depth
  // precise enough for the closest views a path makes.
  v.farPlane = dist + r * 1.01;
  v.nearPlane = std::max(r * 5e-4, (dist - r) * 0.9);
  if (v.nearPlane >= v.farPlane) v.nearPlane = v.farPlane * 1e-3;
  const double fovy = glm::radians(pose.fovDeg);
  v.pixelsPerUnit = double(height) / (2.0 * std::tan(fovy / 2));
  glm::dmat4 view = glm::lookAt(pose.eye, pose.eye + v.forward, up);
  glm::dmat4 proj = glm::perspective(fovy, double(width) / double(height), v.nearPlane, v.farPlane);
  v.viewMatrix = glm::mat4(view);
  v.projMatrix = glm::mat4(proj);
  v.viewD = view;
  v.projD = proj;
  // Gribb-Hartmann plane extraction from the combined matrix.
  glm::dmat4 m = glm::transpose(proj * view);
  glm::dvec4 rows[4] = {m[0], m[1], m[2], m[3]};
  v.planes[0] = rows[3] + rows[0];
  v.planes[1] = rows[3] - rows[0];
  v.planes[2] = rows[3] + rows[1];
  v.planes[3] = rows[3] - rows[1];
  v.planes[4] = rows[3] + rows[2];
  v.planes[5] = rows[3] - rows[2];
  for (auto& p : v.planes) p /= glm::length(glm::dvec3(p));
  return v;
}

CameraPose extrapolate(const CameraPose& prev, const CameraPose& cur, int frames) {
  CameraPose p = cur;
  p.eye = cur.eye + double(frames) * (cur.eye - prev.eye);
  // Extrapolate the viewing direction (not the target point) so turns carry on turning.
  glm::dvec3 d0 = glm::normalize(prev.target - prev.eye), d1 = glm::normalize(cur.target - cur.eye);
  glm::dvec3 d = d1 + double(frames) * (d1 - d0);
  if (glm::length(d) < 1e-9) d = d1;
  p.target = p.eye + glm::normalize(d) * glm::length(cur.target - cur.eye);
  return p;
}

CameraPose defaultPose(const glm::dvec3& c, double r) {
  CameraPose p;
  p.target = c;
  p.eye = c + r * glm::dvec3(0, -2.2, 1.1);
  return p;
}

CameraPath loadCameraPath(const std::string& path, const glm::dvec3& c, double r) {
  std::ifstream in(path);
  if (!in) fail(path, "cannot open the camera path");
  CameraPath out;
  bool unit = true;
  double fov = 45;
  std::string line;
  int lineNo = 0;
  while (std::getline(in, line)) {
    ++lineNo;
    std::istringstream ss(line);
    std::string first;
    if (!(ss >> first) || first[0] == '#') continue;
    if (first == "mtrender-camera-path") continue;
    if (first == "space") {
      std::string s;
      ss >> s;
      if (s != "unit" && s != "object") fail(path, "line " + std::to_string(lineNo) + ": space must be unit or object");
      unit = s == "unit";
      continue;
    }
    if (first == "fov") {
      if (!(ss >> fov) || fov <= 0 || fov >= 180) fail(path, "line " + std::to_string(lineNo) + ": bad fov");
      continue;
    }
    std::istringstream all(line);
    double v[9];
    int n = 0;
    while (n < 9 && all >> v[n]) ++n;
    std::string rest;
    all.clear();  // a word after the numbers stopped the loop with failbit: still read it
    if ((n != 6 && n != 9) || (all >> rest))
      fail(path, "line " + std::to_string(lineNo) + ": expected 6 or 9 numbers (eye, target, [up])");
    CameraPose p;
    p.fovDeg = fov;
    p.eye = {v[0], v[1], v[2]};
    p.target = {v[3], v[4], v[5]};
    if (n == 9) p.up = {v[6], v[7], v[8]};
    if (unit) {
      p.eye = c + r * p.eye;
      p.target = c + r * p.target;
    }
    // A view needs finite points (1e308 in unit space overflows once scaled) and a direction.
    for (int i = 0; i < 3; ++i)
      if (!std::isfinite(p.eye[i]) || !std::isfinite(p.target[i]) || !std::isfinite(p.up[i]))
        fail(path, "line " + std::to_string(lineNo) + ": a coordinate is out of range");
    if (p.eye == p.target) fail(path, "line " + std::to_string(lineNo) + ": eye and target are the same point");
    out.poses.push_back(p);
  }
  if (out.poses.empty()) fail(path, "the camera path has no pose");
  return out;
}

void saveCameraPath(const std::string& path, const CameraPath& cp) {
  const std::string tmp = path + ".tmp";
  {
    std::ofstream out(tmp);
    if (!out) fail(path, "cannot write the camera path");
    out.precision(17);
    out << "mtrender-camera-path 1\nspace object\n";
    double fov = -1;
    for (const auto& p : cp.poses) {
      if (p.fovDeg != fov) out << "fov " << (fov = p.fovDeg) << "\n";
      out << p.eye.x << ' ' << p.eye.y << ' ' << p.eye.z << "  " << p.target.x << ' ' << p.target.y << ' '
          << p.target.z << "  " << p.up.x << ' ' << p.up.y << ' ' << p.up.z << "\n";
    }
    if (!out) fail(path, "write failed");
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) fail(path, "cannot rename the camera path into place");
}

namespace {
double smooth(double t) { return t * t * (3 - 2 * t); }
}  // namespace

bool builtinCameraPath(const std::string& name, int frames, const glm::dvec3& c, double r, CameraPath& out) {
  out.poses.clear();
  if (frames < 1) frames = 1;
  const int moving = std::max(1, int(frames * 0.85));
  const double pi = 3.14159265358979323846;
  for (int f = 0; f < frames; ++f) {
    const double t = double(std::min(f, moving - 1)) / double(std::max(1, moving - 1));  // 0..1, then held
    CameraPose p;
    if (name == "fixed") {
      p = defaultPose(c, r);
    } else if (name == "orbit") {
      double az = -pi / 2 + 2 * pi * t;
      double el = 0.35 + 0.3 * std::sin(4 * pi * t);
      double dist = 2.4 + 1.1 * std::cos(6 * pi * t);  // zooms between 1.3 and 3.5 radii
      p.eye = c + r * dist * glm::dvec3(std::cos(az) * std::cos(el), std::sin(az) * std::cos(el), std::sin(el));
      p.target = c;
    } else if (name == "flythrough") {
      // Key poses in unit space (eye, look-at), visited with smoothstep easing; consecutive keys
      // that differ by a large turn are only a few frames apart: fast turns.
      struct Key { double time; glm::dvec3 eye, target; };
      static const Key keys[] = {
          {0.00, {0, -3.0, 1.2}, {0, 0, 0}},          // overview
          {0.12, {0.1, -1.0, 0.45}, {0.1, 0, 0}},     // dive in
          {0.22, {0.45, -0.55, 0.3}, {0.45, 0.3, 0}}, // sweep along the surface
          {0.25, {0.45, -0.55, 0.3}, {1.2, -0.5, 0}}, // whip right (3% of the path)
          {0.34, {0.9, -0.1, 0.25}, {0.2, 0.4, 0}},   // close, looking back across
          {0.37, {0.9, -0.1, 0.25}, {-0.4, -0.6, 0}}, // whip around
          {0.48, {0.2, -1.6, 1.4}, {0, 0, 0}},        // pull out
          {0.60, {-0.8, -0.6, 0.3}, {-0.4, 0.2, 0}},  // zoom in on the left
          {0.63, {-0.8, -0.6, 0.3}, {0.4, -0.9, 0}},  // whip
          {0.75, {-0.3, 0.9, 0.5}, {0, 0, 0}},        // round the back
          {0.85, {0.0, 2.6, 2.0}, {0, 0, 0}},         // far away
          {1.00, {0.3, -1.3, 0.7}, {0.05, 0.1, 0}},   // final view (held: the camera stops)
      };
      const int nk = int(sizeof(keys) / sizeof(keys[0]));
      int k = 0;
      while (k + 2 < nk && t > keys[k + 1].time) ++k;
      const Key &a = keys[k], &b = keys[k + 1];
      double u = smooth(std::clamp((t - a.time) / (b.time - a.time), 0.0, 1.0));
      p.eye = c + r * glm::mix(a.eye, b.eye, u);
      p.target = c + r * glm::mix(a.target, b.target, u);
    } else {
      return false;
    }
    out.poses.push_back(p);
  }
  return true;
}

}  // namespace mt::render
