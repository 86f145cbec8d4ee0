// glTF 2.0 output of one welded mesh (a cut of an MT file, or a 3D Tiles content): GLB (one file)
// or .gltf (JSON + one .bin beside it), written under temporary names through Env and renamed
// when complete. Plain data in, bytes out: the caller owns the mesh.
//
// Precision (georeferenced scans): positions are stored relative to the node's translation, which
// glTF writes as a JSON number (a double), so UTM-sized coordinates keep their grid: with float
// positions the node translation is a grid point near the mesh's centre and every stored float
// is the small difference; with KHR_mesh_quantization (`quantize`) the positions are the grid
// coordinates themselves (q - qMin as uint16) and the node is translate(origin + step*qMin) *
// scale(step), so the file holds exactly the MT's grid points.
//
// Options: EXT_meshopt_compression (meshoptimizer's vertex and index codecs on every buffer view,
// with a fallback buffer that has no data, so the extension is required), KHR_draco_mesh_compression
// (Draco's mesh coding of the grid coordinates, lossless) and KHR_mesh_quantization (uint16
// positions, int16 normals). Colours (RGBA8, COLOR_0) and normals
// when the mesh has them.
//
// Textures (a cut of a textured MT file, texturedGltfMeshOf): TEXCOORD_0 per vertex (a vertex per
// distinct grid point and texture coordinate), one primitive and one material per texture (the
// patch's atlas, its JPEG or PNG bytes as stored in the MT file, embedded in a buffer view of the
// GLB or of the .gltf's .bin: nothing is re-encoded), pbrMetallicRoughness.baseColorTexture with
// metallicFactor 0. Coordinates as float (the MT's multiples of 1/16 texel, exact to the float). Draco is not used for textured meshes (plain or meshopt layout).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "base/env.h"
#include "mtfile/mt_cut.h"
#include "mtfile/textured_cut.h"

namespace mt::interop {

struct GltfMeshView {
  size_t vertexCount = 0;
  size_t triangleCount = 0;
  const double* positions = nullptr;  // 3 per vertex, model coordinates
  const uint32_t* triangles = nullptr;  // 3 per triangle, < vertexCount
  const float* normals = nullptr;     // 3 per vertex, or null
  const uint8_t* colors = nullptr;    // 4 per vertex (RGBA), or null
  // The MT grid the positions lie on (positions = gridOrigin + gridStep * q), or q null: then
  // quantization is not available and the translation is the bounding box's centre.
  const uint32_t* q = nullptr;        // 3 per vertex
  double gridOrigin[3] = {0, 0, 0};
  double gridStep = 0;
  // Textures: texcoords null for an untextured mesh.
  const float* texcoords = nullptr;          // 2 per vertex, glTF's convention (v = 0 at the top row)
  const uint32_t* triangleImage = nullptr;   // 1 per triangle: index into images, UINT32_MAX untextured
  struct Image {
    const uint8_t* data = nullptr;
    size_t size = 0;
    bool png = false;  // else JPEG
  };
  const Image* images = nullptr;
  size_t imageCount = 0;
};

// A textured cut as a glTF mesh: the welded mesh's vertices split per distinct texture coordinate
// (and texture), with the textures' bytes. The view points into this object.
struct TexturedGltfMesh {
  std::vector<double> positions;
  std::vector<uint32_t> q, triangles, triangleImage;
  std::vector<float> normals, texcoords;
  std::vector<uint8_t> colors;
  std::vector<GltfMeshView::Image> images;
  GltfMeshView view;
};
// `cut` must outlive the result (the images point into it).
void texturedGltfMeshOf(const TexturedCut& cut, const double gridOrigin[3], double gridStep, TexturedGltfMesh& out);

// The view of a welded cut of an MT file (assembleCut) on its grid (header gridOrigin, gridStep).
inline GltfMeshView gltfMeshViewOf(const WeldedMesh& mesh, const double gridOrigin[3], double gridStep) {
  GltfMeshView view;
  view.vertexCount = mesh.vertexCount();
  view.triangleCount = mesh.triangleCount();
  view.positions = mesh.positions.data();
  view.triangles = mesh.triangles.data();
  view.normals = mesh.normals.empty() ? nullptr : mesh.normals.data();
  view.colors = mesh.colors.empty() ? nullptr : mesh.colors.data();
  view.q = mesh.q.data();
  for (int a = 0; a < 3; ++a) view.gridOrigin[a] = gridOrigin[a];
  view.gridStep = gridStep;
  return view;
}

struct GltfOptions {
  bool meshopt = false;   // EXT_meshopt_compression on every buffer view
  bool quantize = false;  // KHR_mesh_quantization: needs the grid and a q range below 2^16 per axis
  // KHR_draco_mesh_compression (needs `quantize`: Draco codes the grid coordinates losslessly;
  // where quantization falls back to float, so does Draco, to the plain layout). Overrides meshopt.
  bool draco = false;
  int dracoSpeed = 3;     // Draco's encoder/decoder speed (0 smallest .. 10 fastest)
  // The frame the node's transform is expressed in: the node translation is (translation - frame),
  // so a 3D Tiles content can be placed relative to its tileset's root transform.
  double frame[3] = {0, 0, 0};
  // 3D Tiles contents: a parent node turns the model's +Z up into glTF's +Y up (exact 0/1 matrix),
  // which the 3D Tiles runtime turns back.
  bool zUpToYUp = false;
  std::string generator = "batched-mt";
  std::string crs;  // written as asset.extras.crs when not empty
};

// What buildGltf made, for the caller's report.
struct GltfInfo {
  bool quantized = false;  // false when quantize was asked but the range did not fit (then float)
  std::string fallbackReason;
  double translation[3] = {0, 0, 0};  // absolute (before subtracting the frame)
};

struct GltfBytes {
  std::string json;
  std::vector<uint8_t> bin;
  GltfInfo info;
};

// The JSON and the binary buffer. binUri empty: the buffer is the GLB's BIN chunk; otherwise the
// buffer's uri.
GltfBytes buildGltf(const GltfMeshView& mesh, const GltfOptions& options, const std::string& binUri = {});
// JSON + BIN into one GLB (header, chunks padded to 4 bytes).
std::vector<uint8_t> encodeGlb(const GltfBytes& gltf);

// Writes PATH by its extension: .glb, or .gltf plus PATH-without-extension.bin. Each file goes
// to a unique temporary name and is renamed when complete; on error nothing is left under the
// final names. Throws mt::Error naming the file.
GltfInfo writeGltfFile(const std::string& path, const GltfMeshView& mesh, const GltfOptions& options,
                       Env* env = Env::Default());

// One file written completely under a unique temporary name beside PATH, synced and renamed.
void writeFileAtomic(const std::string& path, const void* data, size_t size, Env* env = Env::Default());

}  // namespace mt::interop
