// The render tests' in-process set-up (tests/test_mtrender.cpp, tests/test_render_policies.cpp):
// a Scene of MT files with its RAM patch cache and PatchServer, as mtrender's Engine makes them,
// without GL, so a test drives ExtractRender frame by frame; and the comparison of two images.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "mtrender/camera.h"
#include "mtrender/image.h"
#include "mtrender/patch_cache.h"
#include "mtrender/patch_server.h"
#include "mtrender/scene.h"

namespace mt::test {

struct RenderRig {
  render::Scene scene;
  std::unique_ptr<render::PatchCache> cache;
  std::unique_ptr<render::PatchServer> server;
  glm::dvec3 center{0};
  double radius = 1;
  // The cache's place holders come in size classes with the per-class floor of Scene::forEachMoveGroup
  // (as in Engine) unless `classFloor` is false (the two-argument cache constructor).
  explicit RenderRig(const std::vector<std::string>& files, uint64_t cacheBytes = 16ull << 20,
                     render::PatchServer::Options serverOptions = {}, bool classFloor = true)
      : scene(files) {
    std::vector<uint64_t> bounds(scene.patchCount());
    for (uint32_t p = 0; p < bounds.size(); ++p) bounds[p] = scene.decodedBytesBound(p);
    cache = classFloor ? std::make_unique<render::PatchCache>(cacheBytes, bounds,
                                                              [this](const auto& group) { scene.forEachMoveGroup(group); })
                       : std::make_unique<render::PatchCache>(cacheBytes, bounds);
    server = std::make_unique<render::PatchServer>(scene, *cache, serverOptions);
    double c[3];
    scene.boundingSphere(c, radius);
    center = {c[0], c[1], c[2]};
  }
  render::View view(const render::CameraPose& p, int width = 256, int height = 256) const {
    return render::makeView(p, width, height, center, radius);
  }
};

// Pixels differing by more than 40/255 in some channel, and the mean of the largest channel
// difference per pixel.
inline std::pair<size_t, double> imageDiff(const render::Image& a, const render::Image& b) {
  size_t differ = 0;
  double sum = 0;
  for (int y = 0; y < a.height; ++y)
    for (int x = 0; x < a.width; ++x) {
      int d = 0;
      for (int k = 0; k < 3; ++k) d = std::max(d, std::abs(int(a.pixel(x, y)[k]) - int(b.pixel(x, y)[k])));
      differ += d > 40;
      sum += d;
    }
  return {differ, sum / (double(a.width) * a.height)};
}

// mtrender's background colour (the headless screenshots), as mtrender/image.h's comparisons take it.
inline constexpr uint8_t kBackground[3] = {20, 23, 28};
inline bool isBackground(const uint8_t* p) { return p[0] == kBackground[0] && p[1] == kBackground[1] && p[2] == kBackground[2]; }

// Box filter by k x k (as bench_psnr --downsample): render::boxDownsample on the background.
inline render::Image boxDownsample(const render::Image& in, int k) { return render::boxDownsample(in, k, kBackground); }

// PSNR over the pixels the model covers in either image (render::psnr).
inline double coveredPsnr(const render::Image& a, const render::Image& b) { return render::psnr(a, b, kBackground).covered; }

}  // namespace mt::test
