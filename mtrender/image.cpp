#include "mtrender/image.h"

#include <png.h>

#include <cassert>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <limits>
#include <cstring>

#include "base/error.h"
#include "base/output_path.h"

namespace mt::render {

void writePng(const std::string& path, const Image& image) {
  png_image img;
  std::memset(&img, 0, sizeof img);
  img.version = PNG_IMAGE_VERSION;
  img.width = uint32_t(image.width);
  img.height = uint32_t(image.height);
  img.format = PNG_FORMAT_RGBA;
  const std::string tmp = uniqueTempName(path);  // a viewer and a headless run may share a folder
  if (!png_image_write_to_file(&img, tmp.c_str(), 0, image.rgba.data(), 0, nullptr)) {
    std::remove(tmp.c_str());
    fail(path, std::string("cannot write PNG: ") + img.message);
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const int e = errno;
    std::remove(tmp.c_str());  // nothing left under either name
    fail(path, std::string("cannot rename the PNG into place: ") + std::strerror(e));
  }
}

Image readPng(const std::string& path) {
  png_image img;
  std::memset(&img, 0, sizeof img);
  img.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&img, path.c_str())) fail(path, std::string("cannot read PNG: ") + img.message);
  img.format = PNG_FORMAT_RGBA;
  Image out;
  out.width = int(img.width);
  out.height = int(img.height);
  out.rgba.resize(PNG_IMAGE_SIZE(img));
  if (!png_image_finish_read(&img, nullptr, out.rgba.data(), 0, nullptr))
    fail(path, std::string("cannot decode PNG: ") + img.message);
  return out;
}

static bool isBackground(const uint8_t* p, const uint8_t background[3]) {
  return p[0] == background[0] && p[1] == background[1] && p[2] == background[2];
}

Image boxDownsample(const Image& in, int k, const uint8_t background[3]) {
  assert(k >= 1);
  if (k == 1) return in;
  Image out;
  out.width = in.width / k, out.height = in.height / k;
  out.rgba.assign(size_t(out.width) * size_t(out.height) * 4, 255);
  for (int y = 0; y < out.height; ++y)
    for (int x = 0; x < out.width; ++x) {
      int sum[3] = {0, 0, 0}, backgroundSamples = 0;
      for (int dy = 0; dy < k; ++dy)
        for (int dx = 0; dx < k; ++dx) {
          const uint8_t* p = in.pixel(x * k + dx, y * k + dy);
          for (int c = 0; c < 3; ++c) sum[c] += p[c];
          backgroundSamples += isBackground(p, background);
        }
      uint8_t* o = &out.rgba[(size_t(y) * size_t(out.width) + size_t(x)) * 4];
      for (int c = 0; c < 3; ++c)
        o[c] = backgroundSamples == k * k ? background[c] : uint8_t((sum[c] + k * k / 2) / (k * k));
    }
  return out;
}

Psnr psnr(const Image& a, const Image& b, const uint8_t background[3]) {
  assert(a.width == b.width && a.height == b.height);
  double all = 0, covered = 0;
  Psnr out;
  for (int y = 0; y < a.height; ++y)
    for (int x = 0; x < a.width; ++x) {
      const uint8_t *p = a.pixel(x, y), *q = b.pixel(x, y);
      double e = 0;
      for (int c = 0; c < 3; ++c) e += (double(p[c]) - q[c]) * (double(p[c]) - q[c]);
      all += e;
      if (!isBackground(p, background) || !isBackground(q, background)) covered += e, ++out.coveredPixels;
    }
  auto db = [](double sse, size_t count) {
    const double mse = count ? sse / (3.0 * double(count)) : 0;
    return mse > 0 ? 10 * std::log10(255.0 * 255.0 / mse) : std::numeric_limits<double>::infinity();
  };
  out.all = db(all, size_t(a.width) * size_t(a.height));
  out.covered = db(covered, out.coveredPixels);
  return out;
}

}  // namespace mt::render
