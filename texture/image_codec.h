// JPEG and PNG images: row-by-row decoding in bounded memory (libjpeg-turbo, libpng), optionally
// scaled down by 2^shift, and whole-image encoding for atlases. Every file is read through Env in
// chunks; every error is one line "NAME: what [at byte offset N]" (InvalidInput for the user's
// images, the caller rethrows it as Corruption for files of ours).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "base/env.h"

namespace mt::tex {

enum class ImageFormat : uint8_t { Unknown = 0, Jpeg = 1, Png = 2, Raw = 3 };
const char* imageFormatName(ImageFormat f);
// By the magic bytes (JPEG FF D8 FF, PNG's 8-byte signature).
ImageFormat sniffImage(const uint8_t* data, size_t size);

// An RGB8 image in memory, top row first.
struct RgbImage {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;  // 3 per pixel
  RgbImage() = default;
  RgbImage(int w, int h) : width(w), height(h), rgb(size_t(w) * size_t(h) * 3, 0) {}
  uint8_t* pixel(int x, int y) { return &rgb[(size_t(y) * size_t(width) + size_t(x)) * 3]; }
  const uint8_t* pixel(int x, int y) const { return &rgb[(size_t(y) * size_t(width) + size_t(x)) * 3]; }
};

// The largest side an image may have (libjpeg's own limit is 65500).
constexpr int kMaxImageSide = 65500;

// Decodes rows top to bottom. Memory: the decoder's state and a few rows (an interlaced PNG needs
// its whole image: it is refused when larger than `wholeImageLimit` bytes).
class ImageDecoder {
 public:
  virtual ~ImageDecoder() = default;
  // `shift` (0..3): each output pixel is the mean of a 2^shift square (JPEG: libjpeg's scaled
  // IDCT; PNG: a box filter), sides rounded up.
  static std::unique_ptr<ImageDecoder> openFile(const std::string& path, int shift = 0, Env* env = Env::Default(),
                                                uint64_t wholeImageLimit = 256ull << 20);
  static std::unique_ptr<ImageDecoder> openMemory(const uint8_t* data, size_t size, const std::string& name,
                                                  int shift = 0, uint64_t wholeImageLimit = 256ull << 20);
  ImageFormat format() const { return format_; }
  int width() const { return width_; }  // after scaling
  int height() const { return height_; }
  int fullWidth() const { return fullWidth_; }
  int fullHeight() const { return fullHeight_; }
  // The next row: width() * 3 bytes of RGB. Throws mt::Error naming the image and the byte offset
  // reached when the data is damaged or ends early.
  virtual void readRow(uint8_t* rgb) = 0;

 protected:
  ImageFormat format_ = ImageFormat::Unknown;
  int width_ = 0, height_ = 0, fullWidth_ = 0, fullHeight_ = 0;
};

// Just the format and full size (reads the header only).
struct ImageInfo {
  ImageFormat format = ImageFormat::Unknown;
  int width = 0, height = 0;
};
ImageInfo readImageInfo(const std::string& path, Env* env = Env::Default());

// The whole image (small images: atlases, tests).
RgbImage decodeImage(const uint8_t* data, size_t size, const std::string& name);
RgbImage readImageFile(const std::string& path, Env* env = Env::Default());

// Baseline JPEG, 4:2:0 below quality 90 and 4:4:4 from 90 (the chroma of sharp texture edges),
// integer DCT (the same bytes on every machine). quality 1..100.
std::vector<uint8_t> encodeJpeg(const RgbImage& image, int quality);
std::vector<uint8_t> encodePng(const RgbImage& image);
// Lossless and fast, for images that are decoded again by us (the patch store's atlases): the
// magic "RGBZ", uint16 width, height, then one zstd frame (level 1) of the RGB rows.
std::vector<uint8_t> encodeRaw(const RgbImage& image);
// Any of the three formats (by the magic bytes).
RgbImage decodeAnyImage(const uint8_t* data, size_t size, const std::string& name);
// A JPEG written row by row (images larger than memory: generated textures), through Env under
// PATH.tmp.PID.RANDOM, renamed by finish(); the destructor removes an unfinished file.
class JpegRowWriter {
 public:
  JpegRowWriter(const std::string& path, int width, int height, int quality, Env* env = Env::Default());
  ~JpegRowWriter();
  JpegRowWriter(const JpegRowWriter&) = delete;
  JpegRowWriter& operator=(const JpegRowWriter&) = delete;
  void writeRow(const uint8_t* rgb);  // width * 3 bytes, top row first
  void finish();
  struct State;

 private:
  std::unique_ptr<State> s_;
};

// Written under PATH.tmp.PID.RANDOM through Env and renamed.
void writeFileAtomically(const std::string& path, const std::vector<uint8_t>& bytes, Env* env = Env::Default());

}  // namespace mt::tex
