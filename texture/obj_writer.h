// A textured mesh as Wavefront OBJ + MTL + PNG (mtextract's textured cuts): the meshes' textures
// (one per patch, small) re-packed into pages of at most pageSide texels (texture/atlas_pack.h),
// one material per page, each page one PNG; "vt" written once per distinct (vertex, coordinate).
// Every file goes under a temporary name and is renamed when complete; the OBJ last, so a reader
// never sees an OBJ without its MTL and images. On error the files written so far are removed.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "base/env.h"
#include "texture/image_codec.h"

namespace mt::tex {

struct TexturedMeshView {
  const double* positions = nullptr;  // 3 per vertex
  size_t vertexCount = 0;
  const uint32_t* triangles = nullptr;  // 3 per triangle
  size_t triangleCount = 0;
  const float* cornerUV = nullptr;         // 6 per triangle, over its texture (v = 0 at the bottom)
  const uint32_t* triangleTexture = nullptr;  // 1 per triangle, UINT32_MAX: untextured
  const std::vector<RgbImage>* textures = nullptr;
};

struct ObjWriteInfo {
  std::vector<std::string> files;  // written: the images, the MTL, the OBJ (last)
  size_t pages = 0;
  uint64_t texels = 0;
};

// `path` ends in .obj; the MTL and pages are PATH-less-.obj + ".mtl" and "_<k>.png" beside it.
ObjWriteInfo writeTexturedObj(const std::string& path, const TexturedMeshView& mesh, int pageSide = 8192,
                              Env* env = Env::Default());

}  // namespace mt::tex
