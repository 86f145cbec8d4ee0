// The texture work of the level loop (textured stores; docs/appearance.md "Textures"):
//   - every floor patch's atlas: the finest level's cut out of the input images (the store's
//     tiled copies, texture/atlas_crop.h), a coarser patch's the one baked when it was made;
//   - its texture payload for the MT file: the atlas as JPEG and the corner coordinates in the
//     order the patch's geometry payload decodes (mtfile/texture_payload.h);
//   - the simplified region's atlases, one per new patch, baked from the floor (texture/bake.h)
//     at a texel size of sqrt(2) times the floor's (triangles halve per level, so do texels),
//     or half the region's measured deviation when that is coarser, and kept in the store
//     losslessly (RGBZ) for the next level to sample.
#pragma once

#include <memory>
#include <vector>

#include "mtbuild/build.h"
#include "patchstore/store_textures.h"
#include "texture/image_codec.h"

namespace mt {

struct TextureContext {
  std::vector<StoreMaterial> materials;
  std::shared_ptr<tex::TileCache> tiles;  // the store's tiled images (thread-safe)
  int quality = 90;                       // JPEG quality of the file's atlases
  int maxSide = int(format::kMaxAtlasSide);
};

// The atlases of floor patches (in their order) and their corners' coordinates over them.
struct FloorAtlases {
  std::vector<tex::RgbImage> images;
  std::vector<std::vector<float>> cornerUV;  // per patch: 6 per triangle
};
FloorAtlases floorAtlases(const std::vector<Patch>& floor, const TextureContext& context);

// Adds the texture payload to each encoded floor patch (same order as `floor`).
void encodeTextures(const std::vector<Patch>& floor, const FloorAtlases& atlases, const QuantizationGrid& grid,
                    const TextureContext& context, format::Codec codec, std::vector<EncodedPatch>& encoded);

// Gives the simplified region (rep: positions, triangles, triangleCell filled) its atlases: one
// per cell key, corner coordinates and kAtlasMaterial on every triangle.
void bakeRegion(const LoadedMesh& floorMesh, const FloorAtlases& atlases, double deviation, const TextureContext& context,
                ReplacementMesh& rep);

}  // namespace mt
