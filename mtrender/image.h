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

// Written under PATH.tmp and renamed. Throws mt::Error.
void writePng(const std::string& path, const Image& image);
Image readPng(const std::string& path);

}  // namespace mt::render
