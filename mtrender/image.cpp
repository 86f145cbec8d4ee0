#include "mtrender/image.h"

#include <png.h>

#include <cstdio>
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
  if (std::rename(tmp.c_str(), path.c_str()) != 0) fail(path, "cannot rename the PNG into place");
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

}  // namespace mt::render
