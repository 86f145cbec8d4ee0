// The store's materials and their texture images (textured inputs). Ingest keeps each material
// (name, diffuse colour) in the blob "materials" and converts its image, whatever its size, into
// a tiled file DIR/TEX-<k>.tiles (texture/tiled_image.h) within the memory cap, so that the store
// holds everything a build needs (the input's images may be moved or removed afterwards) and
// the builder reads any texel without decoding a whole image. Triangles name materials by index
// (Patch::triangleMaterial).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "patchstore/io/mesh_reader.h"
#include "patchstore/patch_store.h"
#include "texture/tiled_image.h"

namespace mt {

constexpr char kMaterialsBlob[] = "materials";

struct StoreMaterial {
  std::string name;
  uint8_t diffuse[3] = {255, 255, 255};
  std::string file;     // the tiled image in the store directory ("" when the material has none)
  std::string source;   // the input image it was made from
  int width = 0, height = 0;  // of the tiled image
  int shift = 0;              // scaled by 1/2^shift at ingest to fit the memory cap
  uint64_t bytes = 0;         // of the tiled file
};

std::string encodeMaterials(const std::vector<StoreMaterial>& materials);
std::vector<StoreMaterial> decodeMaterials(const std::string& bytes, const std::string& source);
// The store's materials (none for an untextured store).
std::vector<StoreMaterial> storeMaterials(const PatchStore& store);

// Ingest: each material's image tiled into `dir` (TEX-<k>.tiles), in bounded memory. An image
// that cannot be read is an error naming it (and the line that named it).
std::vector<StoreMaterial> tileTextures(const std::vector<InputMaterial>& materials, const std::string& dir,
                                        uint64_t memoryBytes, bool progress, Env* env = Env::Default());

// A cache over the store's tiled images (material k = image k; a material without an image has
// an empty slot: the cache is not asked for it). `capBytes` bounds the decoded tiles held.
std::shared_ptr<tex::TileCache> openTextureCache(const PatchStore& store, const std::vector<StoreMaterial>& materials,
                                                 uint64_t capBytes);

// Every tiled image's tiles checked (mtstore check); problems as lines.
std::vector<std::string> checkTextures(const PatchStore& store);

}  // namespace mt
