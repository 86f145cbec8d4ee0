// A cut of a textured MT file as one welded mesh with its textures: the plain data a writer of
// textured formats needs (mtextract's OBJ + MTL + PNG; a glTF writer): every triangle's corner
// coordinates over the atlas of the patch it came from, and those atlases as stored (JPEG or
// PNG bytes, decoded by the caller with texture/).
#pragma once

#include <cstdint>
#include <vector>

#include "mtfile/mt_cut.h"
#include "mtfile/mt_file.h"

namespace mt {

struct CutTexture {
  uint32_t patch = 0;
  uint16_t width = 0, height = 0;
  uint8_t imageFormat = 0;      // format::kImageJpeg / kImagePng
  std::vector<uint8_t> image;
};

struct TexturedCut {
  WeldedMesh mesh;                       // assembleCut's
  std::vector<float> cornerUV;           // 6 per triangle of mesh, over textures[triangleTexture[t]]
  std::vector<uint32_t> triangleTexture; // 1 per triangle; UINT32_MAX: its patch has no texture
  std::vector<CutTexture> textures;      // one per textured patch, in the mesh's patch order
  uint64_t textureBytes() const;
};

// assembleCut, then each patch's texture (read and decoded again per patch, in the same order).
// A damaged patch or texture throws its reader's error.
TexturedCut assembleTexturedCut(const MtFileReader& reader, const std::vector<uint32_t>& arcs);

}  // namespace mt
