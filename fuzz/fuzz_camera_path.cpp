// libFuzzer target: mtrender's camera-path parser (mtrender/camera.cpp loadCameraPath) on
// arbitrary text. Every pose it returns must be finite.
#include <cmath>

#include "fuzz/fuzz_util.h"
#include "mtrender/camera.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string path = mt::fuzz::scratchDir() + "/input.path";
  mt::fuzz::writeFile(path, data, size);
  try {
    mt::render::CameraPath p = mt::render::loadCameraPath(path, glm::dvec3(1, 2, 3), 4.0);
    for (const auto& pose : p.poses)
      for (int i = 0; i < 3; ++i)
        if (!std::isfinite(pose.eye[i]) || !std::isfinite(pose.target[i]) || !std::isfinite(pose.fovDeg)) std::abort();
  } catch (const mt::Error&) {
  }
  return 0;
}
