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
  try {
    const uint8_t background[3] = {uint8_t(bg[0]), uint8_t(bg[1]), uint8_t(bg[2])};
    const mt::render::Image a = mt::render::boxDownsample(mt::render::readPng(argv[1]), k, background),
                            b = mt::render::boxDownsample(mt::render::readPng(argv[2]), k, background);
    if (a.width != b.width || a.height != b.height) {
      std::fprintf(stderr, "bench_psnr: %s is %dx%d, %s is %dx%d\n", argv[1], a.width, a.height, argv[2], b.width, b.height);
      return 1;
    }
    const mt::render::Psnr p = mt::render::psnr(a, b, background);
    if (!diffPath.empty()) {  // |A - B| per channel, x4, to see where they differ
      mt::render::Image d = a;
      for (size_t i = 0; i < d.rgba.size(); ++i)
        d.rgba[i] = i % 4 == 3 ? 255 : uint8_t(std::min(255, 4 * std::abs(int(a.rgba[i]) - int(b.rgba[i]))));
      mt::render::writePng(diffPath, d);
    }
    std::printf("psnr_all %.2f psnr_covered %.2f covered_pixels %zu\n", p.all, p.covered, p.coveredPixels);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_psnr: %s\n", e.what());
    return 1;
  }
  return 0;
}
