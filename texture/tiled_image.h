// A texture image kept on disk in square tiles, for random access in bounded memory: the patch
// store converts every input texture into one at ingest (its images may be far larger than the
// memory cap), and the builder reads the texels of a patch's charts from it.
//
// File layout (little-endian):
//   TiledHeader (64 bytes)
//   tile payloads, row-major over the tile grid: each a zstd frame of the tile's RGB8 rows
//     (tileSize x tileSize, less at the right and bottom edges)
//   TileEntry[tilesX * tilesY] at header.indexOffset
// header.indexChecksum = XXH64 of the entries; each entry has its payload's XXH64. A damaged
// tile is reported as "PATH: tile (x, y) is damaged" (Corruption).
#pragma once

#include <cstdint>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "base/env.h"
#include "texture/image_codec.h"

namespace mt::tex {

constexpr char kTiledMagic[8] = {'M', 'T', 'T', 'I', 'L', 'E', 'S', '1'};
constexpr uint32_t kTiledVersion = 1;

struct TiledHeader {
  char magic[8];
  uint32_t version;
  uint32_t width, height;
  uint32_t tileSize;
  uint32_t tilesX, tilesY;
  uint32_t shift;          // the source image was scaled by 1/2^shift to fit the memory given
  uint32_t sourceWidth, sourceHeight;
  uint32_t reserved;
  uint64_t indexOffset;
  uint64_t indexChecksum;
};
static_assert(sizeof(TiledHeader) == 64, "TiledHeader layout");

struct TileEntry {
  uint64_t offset;
  uint32_t size;
  uint32_t reserved;
  uint64_t checksum;
};
static_assert(sizeof(TileEntry) == 24, "TileEntry layout");

struct TiledInfo {
  int width = 0, height = 0, shift = 0, sourceWidth = 0, sourceHeight = 0;
  uint64_t bytes = 0;
};

// Converts the image at `source` (JPEG or PNG) into a tiled file at `path` (written under a
// temporary name and renamed). Memory: one band of tileSize rows; when that band would exceed
// `memoryBytes`, the image is scaled by 1/2, 1/4 or 1/8 (its texels then cover 2^shift source
// texels: the info says so). Throws mt::Error naming `source` and its byte offset for a bad image.
TiledInfo writeTiledImage(const std::string& source, const std::string& path, uint64_t memoryBytes,
                          Env* env = Env::Default(), uint32_t tileSize = 256);

class TiledImage {
 public:
  static std::unique_ptr<TiledImage> open(const std::string& path, Env* env = Env::Default());
  int width() const { return int(h_.width); }
  int height() const { return int(h_.height); }
  int tileSize() const { return int(h_.tileSize); }
  const TiledHeader& header() const { return h_; }
  // Tile (tx, ty) decoded: RGB8 rows of tileWidth(tx) x tileHeight(ty) texels. Thread-safe.
  std::vector<uint8_t> readTile(int tx, int ty) const;
  int tileWidth(int tx) const { return std::min(int(h_.tileSize), width() - tx * int(h_.tileSize)); }
  int tileHeight(int ty) const { return std::min(int(h_.tileSize), height() - ty * int(h_.tileSize)); }
  // Every tile's checksum and frame (mtstore check).
  void verify() const;
  const std::string& path() const { return path_; }

 private:
  std::string path_;
  std::unique_ptr<RandomAccessFile> file_;
  TiledHeader h_{};
  std::vector<TileEntry> entries_;
};

// Texels of several tiled images through one cache of decoded tiles with a byte cap (least
// recently used out). Thread-safe.
class TileCache {
 public:
  TileCache(std::vector<std::shared_ptr<const TiledImage>> images, uint64_t capBytes);
  size_t imageCount() const { return images_.size(); }
  const TiledImage& image(size_t k) const { return *images_[k]; }
  // Copies the texels [x0, x0 + w) x [y0, y0 + h) of image k into out (RGB8, w * 3 bytes a row);
  // texels outside the image are clamped to its edge.
  void copyRect(size_t k, int x0, int y0, int w, int h, uint8_t* out) const;
  // One texel (clamped to the edge).
  void texel(size_t k, int x, int y, uint8_t out[3]) const;
  uint64_t peakBytes() const;

 private:
  using Tile = std::shared_ptr<const std::vector<uint8_t>>;
  Tile tile(size_t k, int tx, int ty) const;
  std::vector<std::shared_ptr<const TiledImage>> images_;
  uint64_t cap_;
  mutable std::mutex mu_;
  mutable std::list<uint64_t> lru_;  // keys, most recent first
  struct Entry {
    Tile tile;
    std::list<uint64_t>::iterator it;
  };
  mutable std::unordered_map<uint64_t, Entry> map_;
  mutable uint64_t bytes_ = 0, peak_ = 0;
};

}  // namespace mt::tex
