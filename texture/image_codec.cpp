// JPEG (libjpeg-turbo) and PNG (libpng) decoding row by row and encoding: see image_codec.h.
//
// Both libraries report errors through a callback that must not return; C++ exceptions may not
// unwind through their C frames, so the callback longjmps back to the setjmp of the member
// function that called into the library, and that function throws. Those functions create no
// object with a destructor between the setjmp and the library call.
#include "texture/image_codec.h"

#include <csetjmp>
#include <cstdio>
#include <cstring>
#include <algorithm>

#include <jpeglib.h>
#include <png.h>
#include <zstd.h>

#include "base/output_path.h"

namespace mt::tex {

const char* imageFormatName(ImageFormat f) {
  switch (f) {
    case ImageFormat::Jpeg: return "JPEG";
    case ImageFormat::Png: return "PNG";
    case ImageFormat::Raw: return "RGBZ";
    default: return "unknown";
  }
}

ImageFormat sniffImage(const uint8_t* d, size_t n) {
  if (n >= 3 && d[0] == 0xFF && d[1] == 0xD8 && d[2] == 0xFF) return ImageFormat::Jpeg;
  static const uint8_t kPng[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  if (n >= 8 && std::memcmp(d, kPng, 8) == 0) return ImageFormat::Png;
  if (n >= 8 && std::memcmp(d, "RGBZ", 4) == 0) return ImageFormat::Raw;
  return ImageFormat::Unknown;
}

namespace {

// Where the compressed bytes come from: a file read through Env in 64 KiB chunks, or memory.
class ByteSource {
 public:
  ByteSource(std::unique_ptr<RandomAccessFile> file, std::string name)
      : file_(std::move(file)), name_(std::move(name)), size_(file_->size()) {}
  ByteSource(const uint8_t* data, size_t size, std::string name) : mem_(data), name_(std::move(name)), size_(size) {}
  // Up to `max` bytes at the current position; 0 at the end.
  size_t next(const uint8_t*& out, size_t max = 65536) {
    const size_t n = size_t(std::min<uint64_t>(max, size_ - pos_));
    if (mem_) {
      out = mem_ + pos_;
    } else {
      buf_.resize(n);
      if (n) file_->read(pos_, n, buf_.data());
      out = buf_.data();
    }
    pos_ += n;
    return n;
  }
  void peek(uint8_t* out, size_t n) {
    if (mem_) std::memcpy(out, mem_, n);
    else file_->read(0, n, out);
  }
  uint64_t position() const { return pos_; }
  uint64_t size() const { return size_; }
  const std::string& name() const { return name_; }

 private:
  std::unique_ptr<RandomAccessFile> file_;
  const uint8_t* mem_ = nullptr;
  std::string name_;
  uint64_t size_ = 0, pos_ = 0;
  std::vector<uint8_t> buf_;
};

// ---- JPEG -------------------------------------------------------------------------------------

struct JpegError {
  jpeg_error_mgr mgr;
  std::jmp_buf jump;
  char message[JMSG_LENGTH_MAX];
};
void jpegErrorExit(j_common_ptr c) {
  auto* e = reinterpret_cast<JpegError*>(c->err);
  (*c->err->format_message)(c, e->message);
  std::longjmp(e->jump, 1);
}
void jpegSilent(j_common_ptr, int) {}  // warnings (e.g. extraneous bytes) are not errors

struct JpegSource {
  jpeg_source_mgr mgr;
  ByteSource* src;
  bool ended;
};
void jpegInit(j_decompress_ptr) {}
boolean jpegFill(j_decompress_ptr d) {
  auto* s = reinterpret_cast<JpegSource*>(d->src);
  const uint8_t* p = nullptr;
  size_t n = s->src->next(p);
  if (n == 0) {
    // Premature end: an EOI marker, as libjpeg's own sources do, and a note (the decoder then
    // warns; readRow checks `ended` and fails).
    static const JOCTET kEoi[2] = {0xFF, JPEG_EOI};
    s->ended = true;
    s->mgr.next_input_byte = kEoi;
    s->mgr.bytes_in_buffer = 2;
    return TRUE;
  }
  s->mgr.next_input_byte = p;
  s->mgr.bytes_in_buffer = n;
  return TRUE;
}
void jpegSkip(j_decompress_ptr d, long count) {
  auto* s = reinterpret_cast<JpegSource*>(d->src);
  while (count > 0) {
    if (s->mgr.bytes_in_buffer == 0) jpegFill(d);
    size_t k = std::min<size_t>(size_t(count), s->mgr.bytes_in_buffer);
    s->mgr.next_input_byte += k;
    s->mgr.bytes_in_buffer -= k;
    count -= long(k);
    if (s->ended) return;
  }
}
void jpegTerm(j_decompress_ptr) {}

class JpegDecoder final : public ImageDecoder {
 public:
  JpegDecoder(std::unique_ptr<ByteSource> src, int shift) : src_(std::move(src)) {
    format_ = ImageFormat::Jpeg;
    d_.err = jpeg_std_error(&err_.mgr);
    err_.mgr.error_exit = jpegErrorExit;
    err_.mgr.emit_message = jpegSilent;
    source_.src = src_.get();
    source_.ended = false;
    source_.mgr.init_source = jpegInit;
    source_.mgr.fill_input_buffer = jpegFill;
    source_.mgr.skip_input_data = jpegSkip;
    source_.mgr.resync_to_restart = jpeg_resync_to_restart;
    source_.mgr.term_source = jpegTerm;
    source_.mgr.bytes_in_buffer = 0;
    source_.mgr.next_input_byte = nullptr;
    // A constructor that throws runs no destructor: the library's state is released here first.
    if (!start(shift)) {
      const std::string message = std::string("not a readable JPEG image: ") + err_.message + at();
      release();
      fail(src_->name(), message);
    }
    if (fullWidth_ > kMaxImageSide || fullHeight_ > kMaxImageSide) {
      release();
      fail(src_->name(), "JPEG image too large (" + std::to_string(fullWidth_) + " x " + std::to_string(fullHeight_) + ")");
    }
  }
  ~JpegDecoder() override { release(); }
  void readRow(uint8_t* rgb) override {
    if (row_ >= height_) fail(src_->name(), "read past the last row of the JPEG image");
    if (!readOne(rgb)) fail(src_->name(), std::string("damaged JPEG image: ") + err_.message + at());
    if (source_.ended) fail(src_->name(), "JPEG image ends early, at row " + std::to_string(row_) + at());
    ++row_;
  }

 private:
  std::string at() const { return " at byte offset " + std::to_string(src_->position()); }
  void release() {
    if (created_) jpeg_destroy_decompress(&d_);
    created_ = false;
  }
  bool start(int shift) {
    if (setjmp(err_.jump)) return false;
    jpeg_create_decompress(&d_);
    created_ = true;
    d_.src = &source_.mgr;
    jpeg_read_header(&d_, TRUE);
    fullWidth_ = int(d_.image_width);
    fullHeight_ = int(d_.image_height);
    d_.out_color_space = JCS_RGB;
    d_.dct_method = JDCT_ISLOW;
    d_.scale_num = 1;
    d_.scale_denom = 1u << shift;
    jpeg_start_decompress(&d_);
    width_ = int(d_.output_width);
    height_ = int(d_.output_height);
    return d_.output_components == 3;
  }
  bool readOne(uint8_t* rgb) {
    if (setjmp(err_.jump)) return false;
    JSAMPROW rows[1] = {rgb};
    if (jpeg_read_scanlines(&d_, rows, 1) != 1) {
      std::snprintf(err_.message, sizeof err_.message, "no row decoded");
      return false;
    }
    return true;
  }
  std::unique_ptr<ByteSource> src_;
  jpeg_decompress_struct d_{};
  JpegError err_{};
  JpegSource source_{};
  bool created_ = false;
  int row_ = 0;
};

// ---- PNG --------------------------------------------------------------------------------------

struct PngState {
  std::jmp_buf jump;
  char message[256];
  ByteSource* src;
  bool ended;
};
void pngError(png_structp p, png_const_charp msg) {
  auto* s = static_cast<PngState*>(png_get_error_ptr(p));
  std::snprintf(s->message, sizeof s->message, "%s", msg);
  std::longjmp(s->jump, 1);
}
void pngWarning(png_structp, png_const_charp) {}
void pngRead(png_structp p, png_bytep out, png_size_t n) {
  auto* s = static_cast<PngState*>(png_get_io_ptr(p));
  while (n > 0) {
    const uint8_t* d = nullptr;
    size_t k = s->src->next(d, n);
    if (k == 0) {
      s->ended = true;
      png_error(p, "the file ends early");
    }
    std::memcpy(out, d, k);
    out += k;
    n -= k;
  }
}

class PngDecoder final : public ImageDecoder {
 public:
  PngDecoder(std::unique_ptr<ByteSource> src, int shift, uint64_t wholeLimit) : src_(std::move(src)), shift_(shift) {
    format_ = ImageFormat::Png;
    st_.src = src_.get();
    st_.ended = false;
    st_.message[0] = 0;
    if (!start()) fail(src_->name(), std::string("not a readable PNG image: ") + st_.message + at());
    if (fullWidth_ > kMaxImageSide || fullHeight_ > kMaxImageSide)
      fail(src_->name(), "PNG image too large (" + std::to_string(fullWidth_) + " x " + std::to_string(fullHeight_) + ")");
    const int f = 1 << shift_;
    width_ = (fullWidth_ + f - 1) / f;
    height_ = (fullHeight_ + f - 1) / f;
    rowBytes_ = size_t(fullWidth_) * size_t(channels_);
    if (interlaced_) {
      const uint64_t bytes = uint64_t(rowBytes_) * uint64_t(fullHeight_);
      if (bytes > wholeLimit)
        fail(src_->name(), "interlaced PNG of " + std::to_string(fullWidth_) + " x " + std::to_string(fullHeight_) +
                               " needs its whole image in memory (" + std::to_string(bytes >> 20) +
                               " MiB) and that is more than allowed; save it non-interlaced",
             ErrorKind::Resource);
      whole_.resize(size_t(bytes));
      std::vector<png_bytep> rows(static_cast<size_t>(fullHeight_));
      for (int y = 0; y < fullHeight_; ++y) rows[size_t(y)] = whole_.data() + size_t(y) * rowBytes_;
      if (!readWhole(rows.data())) fail(src_->name(), std::string("damaged PNG image: ") + st_.message + at());
    }
    line_.resize(rowBytes_);
    acc_.resize(size_t(width_) * 3);
  }
  ~PngDecoder() override {
    if (png_) png_destroy_read_struct(&png_, info_ ? &info_ : nullptr, nullptr);
  }
  void readRow(uint8_t* rgb) override {
    if (row_ >= height_) fail(src_->name(), "read past the last row of the PNG image");
    const int f = 1 << shift_;
    const int y0 = row_ * f, y1 = std::min(fullHeight_, y0 + f);
    std::fill(acc_.begin(), acc_.end(), 0u);
    for (int y = y0; y < y1; ++y) {
      const uint8_t* src;
      if (interlaced_) {
        src = whole_.data() + size_t(y) * rowBytes_;
      } else {
        if (!readOne(line_.data())) fail(src_->name(), std::string("damaged PNG image: ") + st_.message + " at row " + std::to_string(y) + at());
        src = line_.data();
      }
      for (int x = 0; x < fullWidth_; ++x) {
        const uint8_t* s = src + size_t(x) * size_t(channels_);
        uint32_t* a = &acc_[size_t(x / f) * 3];
        if (channels_ >= 3) a[0] += s[0], a[1] += s[1], a[2] += s[2];
        else a[0] += s[0], a[1] += s[0], a[2] += s[0];
      }
    }
    for (int x = 0; x < width_; ++x) {
      const int n = (std::min(fullWidth_, (x + 1) * f) - x * f) * (y1 - y0);
      for (int c = 0; c < 3; ++c) rgb[size_t(x) * 3 + size_t(c)] = uint8_t((acc_[size_t(x) * 3 + size_t(c)] + uint32_t(n / 2)) / uint32_t(n));
    }
    ++row_;
  }

 private:
  std::string at() const { return " at byte offset " + std::to_string(src_->position()); }
  bool start() {
    if (setjmp(st_.jump)) return false;
    png_ = png_create_read_struct(PNG_LIBPNG_VER_STRING, &st_, pngError, pngWarning);
    if (!png_) return false;
    info_ = png_create_info_struct(png_);
    if (!info_) return false;
    png_set_read_fn(png_, &st_, pngRead);
    png_read_info(png_, info_);
    fullWidth_ = int(png_get_image_width(png_, info_));
    fullHeight_ = int(png_get_image_height(png_, info_));
    const int type = png_get_color_type(png_, info_);
    png_set_expand(png_);     // palette -> RGB, gray < 8 bits -> 8, tRNS -> alpha
    png_set_strip_16(png_);
    png_set_strip_alpha(png_);
    (void)type;
    interlaced_ = png_get_interlace_type(png_, info_) != PNG_INTERLACE_NONE;
    if (interlaced_) png_set_interlace_handling(png_);
    png_read_update_info(png_, info_);
    channels_ = int(png_get_channels(png_, info_));
    return channels_ == 1 || channels_ == 3;
  }
  bool readOne(uint8_t* row) {
    if (setjmp(st_.jump)) return false;
    png_read_row(png_, row, nullptr);
    return true;
  }
  bool readWhole(png_bytep* rows) {
    if (setjmp(st_.jump)) return false;
    png_read_image(png_, rows);
    return true;
  }
  std::unique_ptr<ByteSource> src_;
  int shift_;
  PngState st_{};
  png_structp png_ = nullptr;
  png_infop info_ = nullptr;
  int channels_ = 3;
  bool interlaced_ = false;
  size_t rowBytes_ = 0;
  std::vector<uint8_t> whole_, line_;
  std::vector<uint32_t> acc_;
  int row_ = 0;
};

std::unique_ptr<ImageDecoder> openSource(std::unique_ptr<ByteSource> src, int shift, uint64_t wholeLimit) {
  if (shift < 0 || shift > 3) fail(src->name(), "image scale 1/" + std::to_string(1 << std::max(0, shift)) + " is out of range");
  uint8_t head[8] = {0};
  const size_t n = size_t(std::min<uint64_t>(8, src->size()));
  src->peek(head, n);
  switch (sniffImage(head, n)) {
    case ImageFormat::Jpeg: return std::make_unique<JpegDecoder>(std::move(src), shift);
    case ImageFormat::Png: return std::make_unique<PngDecoder>(std::move(src), shift, wholeLimit);
    default:
      fail(src->name(), src->size() == 0 ? std::string("image file is empty") : "not a JPEG or PNG image (unknown magic bytes at byte offset 0)");
  }
}

// ---- encoding ---------------------------------------------------------------------------------

struct JpegDest {
  jpeg_destination_mgr mgr;
  std::vector<uint8_t>* out;
  std::vector<uint8_t> buf;
};
void jdInit(j_compress_ptr c) {
  auto* d = reinterpret_cast<JpegDest*>(c->dest);
  d->buf.resize(65536);
  d->mgr.next_output_byte = d->buf.data();
  d->mgr.free_in_buffer = d->buf.size();
}
boolean jdEmpty(j_compress_ptr c) {
  auto* d = reinterpret_cast<JpegDest*>(c->dest);
  d->out->insert(d->out->end(), d->buf.begin(), d->buf.end());
  d->mgr.next_output_byte = d->buf.data();
  d->mgr.free_in_buffer = d->buf.size();
  return TRUE;
}
void jdTerm(j_compress_ptr c) {
  auto* d = reinterpret_cast<JpegDest*>(c->dest);
  d->out->insert(d->out->end(), d->buf.begin(), d->buf.begin() + ptrdiff_t(d->buf.size() - d->mgr.free_in_buffer));
}

bool jpegCompress(jpeg_compress_struct& c, JpegError& err, JpegDest& dest, const RgbImage& image, int quality) {
  if (setjmp(err.jump)) return false;
  jpeg_create_compress(&c);  // clears everything but err
  c.dest = &dest.mgr;
  c.image_width = JDIMENSION(image.width);
  c.image_height = JDIMENSION(image.height);
  c.input_components = 3;
  c.in_color_space = JCS_RGB;
  jpeg_set_defaults(&c);
  c.dct_method = JDCT_ISLOW;
  jpeg_set_quality(&c, quality, TRUE);
  if (quality >= 90) {
    c.comp_info[0].h_samp_factor = c.comp_info[0].v_samp_factor = 1;
  }
  c.optimize_coding = TRUE;
  jpeg_start_compress(&c, TRUE);
  while (c.next_scanline < c.image_height) {
    JSAMPROW row[1] = {const_cast<uint8_t*>(image.pixel(0, int(c.next_scanline)))};
    jpeg_write_scanlines(&c, row, 1);
  }
  jpeg_finish_compress(&c);
  return true;
}

struct PngOut {
  std::jmp_buf jump;
  char message[256];
  std::vector<uint8_t>* out;
};
void pngWErr(png_structp p, png_const_charp msg) {
  auto* s = static_cast<PngOut*>(png_get_error_ptr(p));
  std::snprintf(s->message, sizeof s->message, "%s", msg);
  std::longjmp(s->jump, 1);
}
void pngWrite(png_structp p, png_bytep data, png_size_t n) {
  auto* s = static_cast<PngOut*>(png_get_io_ptr(p));
  s->out->insert(s->out->end(), data, data + n);
}
void pngFlush(png_structp) {}
bool pngCompress(png_structp& png, png_infop& info, PngOut& st, const RgbImage& image) {
  if (setjmp(st.jump)) return false;
  png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &st, pngWErr, pngWarning);
  if (!png) return false;
  info = png_create_info_struct(png);
  if (!info) return false;
  png_set_write_fn(png, &st, pngWrite, pngFlush);
  png_set_IHDR(png, info, png_uint_32(image.width), png_uint_32(image.height), 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_write_info(png, info);
  for (int y = 0; y < image.height; ++y) png_write_row(png, image.pixel(0, y));
  png_write_end(png, info);
  return true;
}

}  // namespace

std::unique_ptr<ImageDecoder> ImageDecoder::openFile(const std::string& path, int shift, Env* env, uint64_t wholeLimit) {
  return openSource(std::make_unique<ByteSource>(env->newRandomAccessFile(path), path), shift, wholeLimit);
}

std::unique_ptr<ImageDecoder> ImageDecoder::openMemory(const uint8_t* data, size_t size, const std::string& name, int shift,
                                                       uint64_t wholeLimit) {
  return openSource(std::make_unique<ByteSource>(data, size, name), shift, wholeLimit);
}

ImageInfo readImageInfo(const std::string& path, Env* env) {
  auto d = ImageDecoder::openFile(path, 0, env, ~0ull);
  return {d->format(), d->fullWidth(), d->fullHeight()};
}

RgbImage decodeImage(const uint8_t* data, size_t size, const std::string& name) {
  auto d = ImageDecoder::openMemory(data, size, name);
  RgbImage img(d->width(), d->height());
  for (int y = 0; y < img.height; ++y) d->readRow(img.pixel(0, y));
  return img;
}

RgbImage readImageFile(const std::string& path, Env* env) {
  auto d = ImageDecoder::openFile(path, 0, env);
  RgbImage img(d->width(), d->height());
  for (int y = 0; y < img.height; ++y) d->readRow(img.pixel(0, y));
  return img;
}

std::vector<uint8_t> encodeJpeg(const RgbImage& image, int quality) {
  if (image.width <= 0 || image.height <= 0 || image.width > kMaxImageSide || image.height > kMaxImageSide)
    throw Error("encodeJpeg: image size " + std::to_string(image.width) + " x " + std::to_string(image.height) + " out of range");
  std::vector<uint8_t> out;
  jpeg_compress_struct c{};
  JpegError err{};
  c.err = jpeg_std_error(&err.mgr);
  err.mgr.error_exit = jpegErrorExit;
  err.mgr.emit_message = jpegSilent;
  JpegDest dest{};
  dest.out = &out;
  dest.mgr.init_destination = jdInit;
  dest.mgr.empty_output_buffer = jdEmpty;
  dest.mgr.term_destination = jdTerm;
  const bool ok = jpegCompress(c, err, dest, image, std::clamp(quality, 1, 100));
  jpeg_destroy_compress(&c);
  if (!ok) throw Error(std::string("encodeJpeg: ") + err.message);
  return out;
}

std::vector<uint8_t> encodePng(const RgbImage& image) {
  std::vector<uint8_t> out;
  PngOut st{};
  st.out = &out;
  png_structp png = nullptr;
  png_infop info = nullptr;
  const bool ok = pngCompress(png, info, st, image);
  if (png) png_destroy_write_struct(&png, info ? &info : nullptr);
  if (!ok) throw Error(std::string("encodePng: ") + st.message);
  return out;
}

std::vector<uint8_t> encodeRaw(const RgbImage& image) {
  if (image.width <= 0 || image.height <= 0 || image.width > 65535 || image.height > 65535)
    throw Error("encodeRaw: image size out of range");
  std::vector<uint8_t> out(8 + ZSTD_compressBound(image.rgb.size()));
  std::memcpy(out.data(), "RGBZ", 4);
  const uint16_t wh[2] = {uint16_t(image.width), uint16_t(image.height)};
  std::memcpy(out.data() + 4, wh, 4);
  const size_t n = ZSTD_compress(out.data() + 8, out.size() - 8, image.rgb.data(), image.rgb.size(), 1);
  if (ZSTD_isError(n)) throw Error(std::string("encodeRaw: ") + ZSTD_getErrorName(n));
  out.resize(8 + n);
  return out;
}

RgbImage decodeAnyImage(const uint8_t* data, size_t size, const std::string& name) {
  if (sniffImage(data, size) != ImageFormat::Raw) return decodeImage(data, size, name);
  uint16_t wh[2];
  std::memcpy(wh, data + 4, 4);
  RgbImage img(wh[0], wh[1]);
  const size_t n = ZSTD_decompress(img.rgb.data(), img.rgb.size(), data + 8, size - 8);
  if (ZSTD_isError(n) || n != img.rgb.size()) fail(name, "damaged RGBZ image");
  return img;
}

// ---- JpegRowWriter ----------------------------------------------------------------------------

struct JpegRowWriter::State {
  std::string path, tmp;
  Env* env = nullptr;
  std::unique_ptr<WritableFile> file;
  jpeg_compress_struct c{};
  JpegError err{};
  JpegDest dest{};
  std::vector<uint8_t> out;  // bytes the destination filled, appended to the file in chunks
  bool created = false, done = false;
  int rows = 0;
};

namespace {
bool startRowWriter(JpegRowWriter::State& s, int width, int height, int quality) {
  if (setjmp(s.err.jump)) return false;
  jpeg_create_compress(&s.c);
  s.created = true;
  s.c.dest = &s.dest.mgr;
  s.c.image_width = JDIMENSION(width);
  s.c.image_height = JDIMENSION(height);
  s.c.input_components = 3;
  s.c.in_color_space = JCS_RGB;
  jpeg_set_defaults(&s.c);
  s.c.dct_method = JDCT_ISLOW;
  jpeg_set_quality(&s.c, quality, TRUE);
  if (quality >= 90) s.c.comp_info[0].h_samp_factor = s.c.comp_info[0].v_samp_factor = 1;
  jpeg_start_compress(&s.c, TRUE);
  return true;
}
bool rowToWriter(JpegRowWriter::State& s, const uint8_t* rgb) {
  if (setjmp(s.err.jump)) return false;
  JSAMPROW row[1] = {const_cast<uint8_t*>(rgb)};
  jpeg_write_scanlines(&s.c, row, 1);
  return true;
}
bool finishRowWriter(JpegRowWriter::State& s) {
  if (setjmp(s.err.jump)) return false;
  jpeg_finish_compress(&s.c);
  return true;
}
}  // namespace

JpegRowWriter::JpegRowWriter(const std::string& path, int width, int height, int quality, Env* env) : s_(std::make_unique<State>()) {
  if (width <= 0 || height <= 0 || width > kMaxImageSide || height > kMaxImageSide)
    fail(path, "JPEG size " + std::to_string(width) + " x " + std::to_string(height) + " out of range");
  s_->path = path;
  s_->tmp = uniqueTempName(path);
  s_->env = env;
  s_->file = env->newWritableFile(s_->tmp);
  s_->c.err = jpeg_std_error(&s_->err.mgr);
  s_->err.mgr.error_exit = jpegErrorExit;
  s_->err.mgr.emit_message = jpegSilent;
  s_->dest.out = &s_->out;
  s_->dest.mgr.init_destination = jdInit;
  s_->dest.mgr.empty_output_buffer = jdEmpty;
  s_->dest.mgr.term_destination = jdTerm;
  if (!startRowWriter(*s_, width, height, std::clamp(quality, 1, 100))) {
    // A constructor that throws runs no destructor: release the library's state and the temporary.
    const std::string message = std::string("JPEG: ") + s_->err.message;
    if (s_->created) jpeg_destroy_compress(&s_->c);
    s_->created = false;
    try {
      s_->file->close();
      env->removeFile(s_->tmp);
    } catch (...) {
    }
    fail(path, message);
  }
}

JpegRowWriter::~JpegRowWriter() {
  if (!s_) return;
  if (s_->created) jpeg_destroy_compress(&s_->c);
  if (!s_->done && s_->file) {
    try {
      s_->file->close();
      s_->env->removeFile(s_->tmp);
    } catch (...) {
    }
  }
}

void JpegRowWriter::writeRow(const uint8_t* rgb) {
  if (!rowToWriter(*s_, rgb)) fail(s_->path, std::string("JPEG: ") + s_->err.message);
  ++s_->rows;
  if (s_->out.size() >= (1 << 20)) {
    s_->file->append(s_->out.data(), s_->out.size());
    s_->out.clear();
  }
}

void JpegRowWriter::finish() {
  if (!finishRowWriter(*s_)) fail(s_->path, std::string("JPEG: ") + s_->err.message);
  s_->file->append(s_->out.data(), s_->out.size());
  s_->out.clear();
  s_->file->sync();
  s_->file->close();
  s_->env->renameFile(s_->tmp, s_->path);
  s_->done = true;
}

void writeFileAtomically(const std::string& path, const std::vector<uint8_t>& bytes, Env* env) {
  writeWholeFile(path, bytes.data(), bytes.size(), env);
}

}  // namespace mt::tex
