// Tiled texture images on disk: see tiled_image.h.
#include "texture/tiled_image.h"

#include <xxhash.h>
#include <zstd.h>

#include <algorithm>
#include <cstring>

#include "base/output_path.h"

namespace mt::tex {

TiledInfo writeTiledImage(const std::string& source, const std::string& path, uint64_t memoryBytes, Env* env,
                          uint32_t tileSize) {
  auto probe = ImageDecoder::openFile(source, 0, env, memoryBytes);
  const uint64_t fullBand = uint64_t(probe->fullWidth()) * tileSize * 3;
  int shift = 0;
  // The band of rows the tiles are cut from, plus the decoder's own rows, must fit the memory.
  while (shift < 3 && (fullBand >> shift) * 2 > memoryBytes) ++shift;
  probe.reset();
  auto dec = ImageDecoder::openFile(source, shift, env, memoryBytes);
  TiledHeader h{};
  std::memcpy(h.magic, kTiledMagic, 8);
  h.version = kTiledVersion;
  h.width = uint32_t(dec->width());
  h.height = uint32_t(dec->height());
  h.tileSize = tileSize;
  h.tilesX = (h.width + tileSize - 1) / tileSize;
  h.tilesY = (h.height + tileSize - 1) / tileSize;
  h.shift = uint32_t(shift);
  h.sourceWidth = uint32_t(dec->fullWidth());
  h.sourceHeight = uint32_t(dec->fullHeight());
  const std::string tmp = uniqueTempName(path);
  TiledInfo info;
  try {
    auto f = env->newWritableFile(tmp);
    f->append(&h, sizeof h);
    uint64_t offset = sizeof h;
    std::vector<TileEntry> entries(size_t(h.tilesX) * h.tilesY);
    std::vector<uint8_t> band(size_t(h.width) * tileSize * 3), tile(size_t(tileSize) * tileSize * 3);
    std::vector<uint8_t> frame(ZSTD_compressBound(tile.size()));
    for (uint32_t ty = 0; ty < h.tilesY; ++ty) {
      const uint32_t rows = std::min(tileSize, h.height - ty * tileSize);
      for (uint32_t y = 0; y < rows; ++y) dec->readRow(&band[size_t(y) * h.width * 3]);
      for (uint32_t tx = 0; tx < h.tilesX; ++tx) {
        const uint32_t cols = std::min(tileSize, h.width - tx * tileSize);
        for (uint32_t y = 0; y < rows; ++y)
          std::memcpy(&tile[size_t(y) * cols * 3], &band[(size_t(y) * h.width + size_t(tx) * tileSize) * 3], size_t(cols) * 3);
        const size_t raw = size_t(rows) * cols * 3;
        const size_t n = ZSTD_compress(frame.data(), frame.size(), tile.data(), raw, 1);
        if (ZSTD_isError(n)) fail(path, std::string("cannot compress a tile: ") + ZSTD_getErrorName(n));
        f->append(frame.data(), n);
        entries[size_t(ty) * h.tilesX + tx] = {offset, uint32_t(n), 0, XXH64(frame.data(), n, 0)};
        offset += n;
      }
    }
    h.indexOffset = offset;
    h.indexChecksum = XXH64(entries.data(), entries.size() * sizeof(TileEntry), 0);
    f->append(entries.data(), entries.size() * sizeof(TileEntry));
    f->writeAt(0, &h, sizeof h);
    f->sync();
    f->close();
    info.bytes = offset + entries.size() * sizeof(TileEntry);
    env->renameFile(tmp, path);
  } catch (...) {
    try {
      env->removeFile(tmp);
    } catch (...) {
    }
    throw;
  }
  info.width = int(h.width);
  info.height = int(h.height);
  info.shift = shift;
  info.sourceWidth = int(h.sourceWidth);
  info.sourceHeight = int(h.sourceHeight);
  return info;
}

std::unique_ptr<TiledImage> TiledImage::open(const std::string& path, Env* env) {
  auto t = std::unique_ptr<TiledImage>(new TiledImage);
  t->path_ = path;
  t->file_ = env->newRandomAccessFile(path);
  const uint64_t size = t->file_->size();
  if (size < sizeof(TiledHeader)) failCorrupt(path, "tiled texture is shorter than its header");
  t->file_->read(0, sizeof(TiledHeader), &t->h_);
  const TiledHeader& h = t->h_;
  if (std::memcmp(h.magic, kTiledMagic, 8) != 0) failCorrupt(path, "not a tiled texture (bad magic at byte offset 0)");
  if (h.version != kTiledVersion) failCorrupt(path, "tiled texture version " + std::to_string(h.version) + " is not known");
  if (h.tileSize == 0 || h.width == 0 || h.height == 0 || h.width > uint32_t(kMaxImageSide) ||
      h.height > uint32_t(kMaxImageSide) || h.tilesX != (h.width + h.tileSize - 1) / h.tileSize ||
      h.tilesY != (h.height + h.tileSize - 1) / h.tileSize)
    failCorrupt(path, "tiled texture header is damaged (sizes)");
  const uint64_t n = uint64_t(h.tilesX) * h.tilesY;
  if (h.indexOffset < sizeof(TiledHeader) || h.indexOffset > size || (size - h.indexOffset) != n * sizeof(TileEntry))
    failCorrupt(path, "tiled texture index does not end the file (index at byte offset " + std::to_string(h.indexOffset) + ")");
  t->entries_.resize(size_t(n));
  t->file_->read(h.indexOffset, size_t(n) * sizeof(TileEntry), t->entries_.data());
  if (XXH64(t->entries_.data(), size_t(n) * sizeof(TileEntry), 0) != h.indexChecksum)
    failCorrupt(path, "tiled texture index is damaged (checksum) at byte offset " + std::to_string(h.indexOffset));
  for (const TileEntry& e : t->entries_)
    if (e.offset < sizeof(TiledHeader) || e.offset + e.size > h.indexOffset)
      failCorrupt(path, "tiled texture index names bytes outside the tiles");
  return t;
}

std::vector<uint8_t> TiledImage::readTile(int tx, int ty) const {
  if (tx < 0 || ty < 0 || uint32_t(tx) >= h_.tilesX || uint32_t(ty) >= h_.tilesY)
    throw Error(path_ + ": tile (" + std::to_string(tx) + ", " + std::to_string(ty) + ") out of range");
  const TileEntry& e = entries_[size_t(ty) * h_.tilesX + size_t(tx)];
  std::vector<uint8_t> frame(e.size);
  file_->read(e.offset, e.size, frame.data());
  const std::string where = "tile (" + std::to_string(tx) + ", " + std::to_string(ty) + ") at byte offset " + std::to_string(e.offset);
  if (XXH64(frame.data(), frame.size(), 0) != e.checksum) failCorrupt(path_, where + " is damaged (checksum)");
  const size_t raw = size_t(tileWidth(tx)) * size_t(tileHeight(ty)) * 3;
  std::vector<uint8_t> out(raw);
  const size_t n = ZSTD_decompress(out.data(), raw, frame.data(), frame.size());
  if (ZSTD_isError(n) || n != raw) failCorrupt(path_, where + " is damaged (frame)");
  return out;
}

void TiledImage::verify() const {
  for (uint32_t ty = 0; ty < h_.tilesY; ++ty)
    for (uint32_t tx = 0; tx < h_.tilesX; ++tx) readTile(int(tx), int(ty));
}

TileCache::TileCache(std::vector<std::shared_ptr<const TiledImage>> images, uint64_t capBytes)
    : images_(std::move(images)), cap_(capBytes) {}

TileCache::Tile TileCache::tile(size_t k, int tx, int ty) const {
  const uint64_t key = uint64_t(k) << 40 | uint64_t(uint32_t(ty)) << 20 | uint32_t(tx);
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = map_.find(key);
    if (it != map_.end()) {
      lru_.splice(lru_.begin(), lru_, it->second.it);
      return it->second.tile;
    }
  }
  // Read outside the lock (two threads may read one tile at once: both results are equal).
  auto t = std::make_shared<const std::vector<uint8_t>>(images_[k]->readTile(tx, ty));
  std::lock_guard<std::mutex> lock(mu_);
  auto it = map_.find(key);
  if (it != map_.end()) return it->second.tile;
  lru_.push_front(key);
  map_[key] = {t, lru_.begin()};
  bytes_ += t->size();
  peak_ = std::max(peak_, bytes_);
  while (bytes_ > cap_ && lru_.size() > 1) {
    auto last = map_.find(lru_.back());
    bytes_ -= last->second.tile->size();
    map_.erase(last);
    lru_.pop_back();
  }
  return t;
}

void TileCache::copyRect(size_t k, int x0, int y0, int w, int h, uint8_t* out) const {
  const TiledImage& img = *images_[k];
  const int ts = img.tileSize();
  for (int y = 0; y < h;) {
    const int sy = std::clamp(y0 + y, 0, img.height() - 1);
    const int ty = sy / ts;
    // The rows of this output band that read tile row ty (rows clamped below/above repeat it); the
    // last tile row and column stop at the image's edge, not at a whole tile.
    int rows = 1;
    if (y0 + y >= 0 && y0 + y < img.height()) rows = std::min(h - y, std::min((ty + 1) * ts, img.height()) - sy);
    for (int x = 0; x < w;) {
      const int sx = std::clamp(x0 + x, 0, img.width() - 1);
      const int tx = sx / ts;
      int cols = 1;
      if (x0 + x >= 0 && x0 + x < img.width()) cols = std::min(w - x, std::min((tx + 1) * ts, img.width()) - sx);
      Tile t = tile(k, tx, ty);
      const int tw = img.tileWidth(tx);
      for (int r = 0; r < rows; ++r) {
        const int ry = std::clamp(y0 + y + r, 0, img.height() - 1) - ty * ts;
        std::memcpy(out + (size_t(y + r) * size_t(w) + size_t(x)) * 3, t->data() + (size_t(ry) * size_t(tw) + size_t(sx - tx * ts)) * 3,
                    size_t(cols) * 3);
      }
      x += cols;
    }
    y += rows;
  }
}

void TileCache::texel(size_t k, int x, int y, uint8_t out[3]) const {
  const TiledImage& img = *images_[k];
  x = std::clamp(x, 0, img.width() - 1);
  y = std::clamp(y, 0, img.height() - 1);
  const int ts = img.tileSize();
  Tile t = tile(k, x / ts, y / ts);
  std::memcpy(out, t->data() + (size_t(y % ts) * size_t(img.tileWidth(x / ts)) + size_t(x % ts)) * 3, 3);
}

uint64_t TileCache::peakBytes() const {
  std::lock_guard<std::mutex> lock(mu_);
  return peak_;
}

}  // namespace mt::tex
