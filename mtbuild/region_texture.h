// The texture work of the level loop (textured stores; docs/appearance.md "Textures"):
//   - every floor patch's atlas: the finest level's cut out of the input images (the store's
//     tiled copies, texture/atlas_crop.h), a coarser patch's the one baked when it was made;
//   - its texture payload for the MT file: the atlas as JPEG and the corner coordinates in the
//     order the patch's geometry payload decodes (mtfile/texture_payload.h);
//   - the simplified region's atlases, one per new patch, baked from the floor (texture/bake.h)
//     at a texel size tied to the new node's error (texelSizeFor below), and kept in the store
//     losslessly (RGBZ) for the next level to sample; the node's error is raised to cover the
//     texels when they had to be wider than it (textureErrorOf), so the cut, chosen by the
//     error, refines where the texture needs it.
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

// The texel size (world units) of a new node's atlases: kTexelPerError times the node's error
// (the cut's tolerance is on the error, so a cut at 1 px shows texels of at most 1 px), clamped to
// [1, 2] times the floor's texel size (finer would only copy the floor's texels; wider, each texel
// averages up to 2 x 2 samples of the floor, bake.h).
inline constexpr double kTexelPerError = 1.0;
double texelSizeFor(double nodeError, double floorTexel);
// The node error that a texel size needs (the inverse of the above): the node's error is at least this.
double textureErrorOf(double texelSize);

// Gives the simplified region (rep: positions, triangles, triangleCell filled) its atlases: one
// per cell key, corner coordinates and kAtlasMaterial on every triangle. nodeError: the new node's
// geometric error (floor error + deviation). Returns the node error the atlases' texels need
// (textureErrorOf the widest, which is wider than asked when a chart set had to grow to fit
// maxSide, or when the floor's texels are wider than the error).
double bakeRegion(const LoadedMesh& floorMesh, const FloorAtlases& atlases, double deviation, double nodeError,
                  const TextureContext& context, ReplacementMesh& rep);

}  // namespace mt
