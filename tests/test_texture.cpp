// The texture room (texture/): images decoded row by row and scaled, encoded; bad images refused
// with the file and byte offset.
#include <gtest/gtest.h>

#include <cmath>

#include "base/error.h"
#include "test_support.h"
#include "texture/image_codec.h"

namespace mt {
namespace {

using tex::RgbImage;

// A picture with sharp features: a checkerboard of 8-px cells with a colour ramp.
RgbImage testPicture(int w, int h) {
  RgbImage img(w, h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      uint8_t* p = img.pixel(x, y);
      const bool on = ((x / 8) + (y / 8)) % 2 == 0;
      p[0] = uint8_t(on ? 230 : 20);
      p[1] = uint8_t((x * 255) / std::max(1, w - 1));
      p[2] = uint8_t((y * 255) / std::max(1, h - 1));
    }
  return img;
}

double psnr(const RgbImage& a, const RgbImage& b) {
  EXPECT_EQ(a.width, b.width);
  EXPECT_EQ(a.height, b.height);
  double se = 0;
  for (size_t i = 0; i < a.rgb.size(); ++i) se += double(a.rgb[i] - b.rgb[i]) * double(a.rgb[i] - b.rgb[i]);
  const double mse = se / double(a.rgb.size());
  return mse == 0 ? 99 : 10 * std::log10(255.0 * 255.0 / mse);
}

TEST(TextureImage, PngRoundTripIsExact) {
  RgbImage img = testPicture(37, 21);
  std::vector<uint8_t> png = tex::encodePng(img);
  EXPECT_EQ(tex::sniffImage(png.data(), png.size()), tex::ImageFormat::Png);
  RgbImage back = tex::decodeImage(png.data(), png.size(), "mem.png");
  EXPECT_EQ(back.width, 37);
  EXPECT_EQ(back.height, 21);
  EXPECT_EQ(back.rgb, img.rgb);
}

TEST(TextureImage, JpegRoundTripIsClose) {
  RgbImage img = testPicture(64, 48);
  std::vector<uint8_t> jpg = tex::encodeJpeg(img, 95);
  EXPECT_EQ(tex::sniffImage(jpg.data(), jpg.size()), tex::ImageFormat::Jpeg);
  RgbImage back = tex::decodeImage(jpg.data(), jpg.size(), "mem.jpg");
  EXPECT_GT(psnr(img, back), 30.0);
  // Deterministic bytes.
  EXPECT_EQ(jpg, tex::encodeJpeg(img, 95));
  // Lower quality: smaller and further.
  std::vector<uint8_t> low = tex::encodeJpeg(img, 30);
  EXPECT_LT(low.size(), jpg.size());
  EXPECT_LT(psnr(img, tex::decodeImage(low.data(), low.size(), "x")), psnr(img, back));
}

TEST(TextureImage, ScaledDecodeIsTheBoxMean) {
  RgbImage img = testPicture(33, 17);
  std::vector<uint8_t> png = tex::encodePng(img);
  auto d = tex::ImageDecoder::openMemory(png.data(), png.size(), "mem.png", 1);
  EXPECT_EQ(d->width(), 17);
  EXPECT_EQ(d->height(), 9);
  EXPECT_EQ(d->fullWidth(), 33);
  std::vector<uint8_t> row(size_t(d->width()) * 3);
  d->readRow(row.data());
  // Pixel (0,0) of the half-size image: the mean of the 2x2 block.
  for (int c = 0; c < 3; ++c) {
    int sum = img.pixel(0, 0)[c] + img.pixel(1, 0)[c] + img.pixel(0, 1)[c] + img.pixel(1, 1)[c];
    EXPECT_EQ(row[size_t(c)], uint8_t((sum + 2) / 4));
  }
  // JPEG scaled by libjpeg: the sizes round up the same way.
  std::vector<uint8_t> jpg = tex::encodeJpeg(img, 90);
  auto j = tex::ImageDecoder::openMemory(jpg.data(), jpg.size(), "mem.jpg", 2);
  EXPECT_EQ(j->width(), 9);
  EXPECT_EQ(j->height(), 5);
}

TEST(TextureImage, FilesThroughEnvAndBadImages) {
  test::TempDir dir;
  RgbImage img = testPicture(40, 30);
  tex::writeFileAtomically(dir.file("a.png"), tex::encodePng(img));
  tex::writeFileAtomically(dir.file("a.jpg"), tex::encodeJpeg(img, 90));
  EXPECT_EQ(tex::readImageFile(dir.file("a.png")).rgb, img.rgb);
  tex::ImageInfo info = tex::readImageInfo(dir.file("a.jpg"));
  EXPECT_EQ(info.format, tex::ImageFormat::Jpeg);
  EXPECT_EQ(info.width, 40);
  EXPECT_EQ(info.height, 30);

  auto expectError = [](const std::string& path, const std::string& part) {
    try {
      tex::RgbImage r = tex::readImageFile(path);
      ADD_FAILURE() << path << " was read (" << r.width << " x " << r.height << ")";
    } catch (const Error& e) {
      EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(part), std::string::npos) << e.what();
    }
  };
  // Truncated: the message says where the data ended.
  for (const char* name : {"a.png", "a.jpg"}) {
    std::string bytes = test::readFile(dir.file(name));
    test::writeFile(dir.file(std::string("cut-") + name), bytes.substr(0, bytes.size() / 2));
    expectError(dir.file(std::string("cut-") + name), "byte offset");
  }
  test::writeFile(dir.file("junk.png"), "this is not an image at all");
  expectError(dir.file("junk.png"), "not a JPEG or PNG image");
  test::writeFile(dir.file("empty.jpg"), "");
  expectError(dir.file("empty.jpg"), "empty");
  expectError(dir.file("missing.png"), "missing.png");
  // Damaged PNG data (a flipped byte inside the compressed stream): the CRC catches it.
  std::string png = test::readFile(dir.file("a.png"));
  png[png.size() / 2] ^= 0x5a;
  test::writeFile(dir.file("flip.png"), png);
  expectError(dir.file("flip.png"), "damaged PNG image");
}

}  // namespace
}  // namespace mt
