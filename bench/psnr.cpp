// bench_psnr A.png B.png [--background R,G,B]: the PSNR of image A against the reference B, over
// all pixels and over the pixels the model covers in either image (those not of the background
// colour, default mtrender's 20,23,28): the second is the stricter figure, since matching
// background pixels inflate the first. RGB, 8 bits, MSE over the three channels.
// Prints "psnr_all DB psnr_covered DB covered_pixels N".
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>

#include "mtrender/image.h"

int main(int argc, char** argv) {
  if (argc != 3 && argc != 5) {
    std::fprintf(stderr, "usage: bench_psnr A.png REFERENCE.png [--background R,G,B]\n");
    return 1;
  }
  int bg[3] = {20, 23, 28};
  if (argc == 5 && std::sscanf(argv[4], "%d,%d,%d", &bg[0], &bg[1], &bg[2]) != 3) {
    std::fprintf(stderr, "bench_psnr: --background wants R,G,B\n");
    return 1;
  }
  try {
    const mt::render::Image a = mt::render::readPng(argv[1]), b = mt::render::readPng(argv[2]);
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
    std::printf("psnr_all %.2f psnr_covered %.2f covered_pixels %zu\n", psnr(all, n), psnr(covered, m), m);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_psnr: %s\n", e.what());
    return 1;
  }
  return 0;
}
