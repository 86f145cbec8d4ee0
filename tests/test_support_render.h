// The render tests' in-process set-up (tests/test_mtrender.cpp, tests/test_render_policies.cpp):
// a Scene of MT files with its RAM patch cache and PatchServer, as mtrender's Engine makes them,
// without GL, so a test drives ExtractRender frame by frame; and the comparison of two images.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
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
  // The cache's place holders come in size classes with the per-class floor of Scene::moveGroups
  // (as in Engine) unless `classFloor` is false (the two-argument cache constructor).
  explicit RenderRig(const std::vector<std::string>& files, uint64_t cacheBytes = 16ull << 20,
                     render::PatchServer::Options serverOptions = {}, bool classFloor = true)
      : scene(files) {
    std::vector<uint64_t> bounds(scene.patches().size());
    for (uint32_t p = 0; p < bounds.size(); ++p) bounds[p] = scene.decodedBytesBound(p);
    cache = classFloor ? std::make_unique<render::PatchCache>(cacheBytes, bounds, scene.moveGroups())
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

// mtrender's background colour (the headless screenshots).
inline bool isBackground(const uint8_t* p) { return p[0] == 20 && p[1] == 23 && p[2] == 28; }

// Box filter by k x k (as bench_psnr --downsample): a rendering made at k times the size, so that
// a reference whose triangles and texels are far below a pixel is compared antialiased, not
// point-sampled. A pixel is background when all its samples are.
inline render::Image boxDownsample(const render::Image& in, int k) {
  render::Image out;
  out.width = in.width / k, out.height = in.height / k;
  out.rgba.assign(size_t(out.width) * size_t(out.height) * 4, 255);
  for (int y = 0; y < out.height; ++y)
    for (int x = 0; x < out.width; ++x) {
      int sum[3] = {0, 0, 0}, background = 0;
      for (int dy = 0; dy < k; ++dy)
        for (int dx = 0; dx < k; ++dx) {
          const uint8_t* p = in.pixel(x * k + dx, y * k + dy);
          for (int c = 0; c < 3; ++c) sum[c] += p[c];
          background += isBackground(p);
        }
      uint8_t* o = &out.rgba[(size_t(y) * size_t(out.width) + size_t(x)) * 4];
      const uint8_t bg[3] = {20, 23, 28};
      for (int c = 0; c < 3; ++c) o[c] = background == k * k ? bg[c] : uint8_t((sum[c] + k * k / 2) / (k * k));
    }
  return out;
}

// PSNR over the pixels the model covers in either image (the stricter figure: the background,
// equal in both, would raise it).
inline double coveredPsnr(const render::Image& a, const render::Image& b) {
  double sse = 0;
  size_t n = 0;
  for (int y = 0; y < a.height; ++y)
    for (int x = 0; x < a.width; ++x) {
      const uint8_t *p = a.pixel(x, y), *q = b.pixel(x, y);
      if (isBackground(p) && isBackground(q)) continue;
      ++n;
      for (int k = 0; k < 3; ++k) sse += (double(p[k]) - q[k]) * (double(p[k]) - q[k]);
    }
  const double mse = n ? sse / (3.0 * double(n)) : 0;
  return mse > 0 ? 10 * std::log10(255.0 * 255.0 / mse) : std::numeric_limits<double>::infinity();
}

}  // namespace mt::test
