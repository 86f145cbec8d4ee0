// mtrender/image.h: RGBA8 images and PNG files (libpng), for screenshots and the golden tests.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace mt::render {

struct Image {
  int width = 0, height = 0;
  std::vector<uint8_t> rgba;  // top row first
  const uint8_t* pixel(int x, int y) const { return &rgba[(size_t(y) * width + x) * 4]; }
};

// Written under a temporary name beside PATH (uniqueTempName) and renamed; throws mt::Error, and
// then nothing is left under either name.
void writePng(const std::string& path, const Image& image);
Image readPng(const std::string& path);

// Image comparisons for the golden tests and bench_psnr. `background` is the clear colour
// (RGB); a pixel is background when it is exactly that colour.
//
// Box filter by k x k: a rendering made at k times the size, so that a reference whose triangles
// and texels are far below a pixel is compared antialiased, not point-sampled. A pixel is
// background when all its samples are. k = 1 returns a copy.
Image boxDownsample(const Image& in, int k, const uint8_t background[3]);

// PSNR over every pixel, and over the pixels the model covers in either image (the stricter
// figure: the background, equal in both, would raise it); infinity when equal. Same sizes.
struct Psnr {
  double all = 0, covered = 0;
  size_t coveredPixels = 0;
};
Psnr psnr(const Image& a, const Image& b, const uint8_t background[3]);

}  // namespace mt::render
