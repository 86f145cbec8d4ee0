// bench_psnr A.png B.png [--downsample K] [--background R,G,B]: the PSNR of image A against the
// reference B (each first box-filtered by K x K when --downsample is given: renderings made at K
// times the resolution, so that both are antialiased and a reference whose triangles are far below
// a pixel is not compared point-sampled), over
// all pixels and over the pixels the model covers in either image (those not of the background
// colour, default mtrender's 20,23,28): the second is the stricter figure, since matching
// background pixels inflate the first. RGB, 8 bits, MSE over the three channels.
// Prints "psnr_all DB psnr_covered DB covered_pixels N".
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>
#include <vector>

#include "mtrender/image.h"

int main(int argc, char** argv) {
  int bg[3] = {20, 23, 28}, k = 1;
  std::string diffPath;
  bool ok = argc >= 3 && argc % 2 == 1;
  for (int i = 3; ok && i + 1 < argc; i += 2) {
    const std::string o = argv[i];
    if (o == "--background") ok = std::sscanf(argv[i + 1], "%d,%d,%d", &bg[0], &bg[1], &bg[2]) == 3;
    else if (o == "--downsample") ok = std::sscanf(argv[i + 1], "%d", &k) == 1 && k >= 1 && k <= 16;
    else if (o == "--diff") diffPath = argv[i + 1];
    else ok = false;
  }
  if (!ok) {
    std::fprintf(stderr, "usage: bench_psnr A.png REFERENCE.png [--downsample K (1-16)] [--background R,G,B] [--diff OUT.png]\n");
    return 1;
  }
  // Box filter by k x k; a pixel is background when all its k x k samples are.
  auto down = [&](const mt::render::Image& in) {
    if (k == 1) return in;
    mt::render::Image out;
    out.width = in.width / k, out.height = in.height / k;
    out.rgba.assign(size_t(out.width) * out.height * 4, 0);
    for (int y = 0; y < out.height; ++y)
      for (int x = 0; x < out.width; ++x) {
        int sum[3] = {0, 0, 0}, background = 0;
        for (int dy = 0; dy < k; ++dy)
          for (int dx = 0; dx < k; ++dx) {
            const uint8_t* p = in.pixel(x * k + dx, y * k + dy);
            for (int c = 0; c < 3; ++c) sum[c] += p[c];
            background += p[0] == bg[0] && p[1] == bg[1] && p[2] == bg[2];
          }
        uint8_t* o = &out.rgba[(size_t(y) * out.width + x) * 4];
        for (int c = 0; c < 3; ++c) o[c] = uint8_t((sum[c] + k * k / 2) / (k * k));
        if (background == k * k)
          for (int c = 0; c < 3; ++c) o[c] = uint8_t(bg[c]);
        o[3] = 255;
      }
    return out;
  };
  try {
    const mt::render::Image a = down(mt::render::readPng(argv[1])), b = down(mt::render::readPng(argv[2]));
    if (a.width != b.width || a.height != b.height) {
      std::fprintf(stderr, "bench_psnr: %s is %dx%d, %s is %dx%d\n", argv[1], a.width, a.height, argv[2], b.width, b.height);
      return 1;
    }
    double all = 0, covered = 0;
    size_t n = 0, m = 0;
    auto isBg = [&](const uint8_t* p) { return p[0] == bg[0] && p[1] == bg[1] && p[2] == bg[2]; };
    for (int y = 0; y < a.height; ++y)
      for (int x = 0; x < a.width; ++x) {
        const uint8_t *p = a.pixel(x, y), *q = b.pixel(x, y);
        double e = 0;
        for (int k = 0; k < 3; ++k) e += (double(p[k]) - q[k]) * (double(p[k]) - q[k]);
        all += e, ++n;
        if (!isBg(p) || !isBg(q)) covered += e, ++m;
      }
    auto psnr = [](double sse, size_t count) {
      const double mse = count ? sse / (3.0 * double(count)) : 0;
      return mse > 0 ? 10 * std::log10(255.0 * 255.0 / mse) : INFINITY;
    };
    if (!diffPath.empty()) {  // |A - B| per channel, x4, to see where they differ
      mt::render::Image d = a;
      for (size_t i = 0; i < d.rgba.size(); ++i)
        d.rgba[i] = i % 4 == 3 ? 255 : uint8_t(std::min(255, 4 * std::abs(int(a.rgba[i]) - int(b.rgba[i]))));
      mt::render::writePng(diffPath, d);
    }
    std::printf("psnr_all %.2f psnr_covered %.2f covered_pixels %zu\n", psnr(all, n), psnr(covered, m), m);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_psnr: %s\n", e.what());
    return 1;
  }
  return 0;
}
