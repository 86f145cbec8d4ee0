// The texture work of the level loop: see region_texture.h.
#include "mtbuild/region_texture.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>

#include "mtfile/texture_payload.h"
#include "texture/atlas_crop.h"
#include "texture/bake.h"

namespace mt {

namespace {

// The store's materials as a texel source (texture/atlas_crop.h): tiled images, or flat colours.
class StoreTexels final : public tex::TexelSource {
 public:
  explicit StoreTexels(const TextureContext& c) : c_(c) {}
  int width(uint32_t m) const override { return known(m) && !c_.materials[m].file.empty() ? c_.materials[m].width : 0; }
  int height(uint32_t m) const override { return known(m) && !c_.materials[m].file.empty() ? c_.materials[m].height : 0; }
  void flatColor(uint32_t m, uint8_t rgb[3]) const override {
    // A material without an image shows its diffuse colour; an untextured triangle a light grey.
    static const uint8_t kGrey[3] = {180, 180, 180};
    std::copy_n(known(m) ? c_.materials[m].diffuse : kGrey, 3, rgb);
  }
  void copyRect(uint32_t m, int x0, int y0, int w, int h, uint8_t* out) const override {
    c_.tiles->copyRect(m, x0, y0, w, h, out);
  }

 private:
  bool known(uint32_t m) const { return m < c_.materials.size(); }
  const TextureContext& c_;
};

}  // namespace

double texelSizeFor(double nodeError, double floorTexel) {
  // Finer than the floor would only copy its texels (more bytes, no detail); more than twice as
  // wide, the 2 x 2 mean of bakeAtlas would no longer cover each floor texel under it.
  if (!(floorTexel > 0)) return kTexelPerError * nodeError;
  return std::clamp(kTexelPerError * nodeError, floorTexel, 2 * floorTexel);
}

double textureErrorOf(double texelSize) { return texelSize / kTexelPerError; }

FloorAtlases floorAtlases(const std::vector<Patch>& floor, const TextureContext& context) {
  FloorAtlases out;
  StoreTexels texels(context);
  for (const Patch& p : floor) {
    if (!p.atlas.empty()) {
      // A coarser patch: its atlas was baked when it was made (every triangle kAtlasMaterial).
      out.images.push_back(tex::decodeAnyImage(reinterpret_cast<const uint8_t*>(p.atlas.data()), p.atlas.size(),
                                               "patch " + std::to_string(p.id) + " atlas"));
      out.cornerUV.push_back(p.cornerUV);
      continue;
    }
    // A finest patch: the input's texels it covers.
    tex::CropResult crop = tex::cropAtlas(p.triangles.data(), p.triangleCount(), p.vertexCount(), p.cornerUV.data(),
                                          p.triangleMaterial.data(), texels, context.maxSide);
    out.images.push_back(std::move(crop.image));
    out.cornerUV.push_back(std::move(crop.cornerUV));
  }
  return out;
}

void encodeTextures(const std::vector<Patch>& floor, const FloorAtlases& atlases, const QuantizationGrid& grid,
                    const TextureContext& context, format::Codec codec, std::vector<EncodedPatch>& encoded) {
  for (size_t k = 0; k < floor.size(); ++k) {
    const Patch& p = floor[k];
    EncodedPatch& e = encoded[k];
    // The corners in the order the payload decodes them (the codec reorders and turns triangles).
    DecodedPatch d = decodePatch(e.payload.data(), e.payload.size(), codec, grid);
    PatchInput in;
    in.positions = p.positions.data();
    in.vertexCount = p.vertexCount();
    in.triangles = p.triangles.data();
    in.triangleCount = p.triangleCount();
    const std::vector<uint32_t> match = matchDecodedTriangles(d, in, grid);
    const std::vector<float>& uv = atlases.cornerUV[k];
    std::vector<float> ordered(6 * match.size());
    for (size_t t = 0; t < match.size(); ++t) {
      const uint32_t src = match[t] / 3, r = match[t] % 3;
      for (uint32_t c = 0; c < 3; ++c) {
        ordered[6 * t + 2 * c] = uv[6 * size_t(src) + 2 * ((c + r) % 3)];
        ordered[6 * t + 2 * c + 1] = uv[6 * size_t(src) + 2 * ((c + r) % 3) + 1];
      }
    }
    const tex::RgbImage& image = atlases.images[k];
    const std::vector<uint8_t> jpeg = tex::encodeJpeg(image, context.quality);
    e.texture = encodeTexturePayload(d.triangles.data(), d.triangleCount(), d.vertexCount(), ordered.data(), jpeg.data(),
                                     jpeg.size(), uint16_t(image.width), uint16_t(image.height), format::kImageJpeg);
    e.textureWidth = uint16_t(image.width);
    e.textureHeight = uint16_t(image.height);
    e.imageBytes = uint32_t(jpeg.size());
  }
}

double bakeRegion(const LoadedMesh& lm, const FloorAtlases& atlases, double deviation, double nodeError,
                  const TextureContext& context, ReplacementMesh& rep) {
  // The floor as a textured surface: triangles are grouped by patch, in lm.patches order.
  tex::TexturedSurface fine;
  fine.positions = lm.positions.data();
  fine.vertexCount = lm.vertexCount();
  fine.triangles = lm.triangles.data();
  fine.triangleCount = lm.triangleCount();
  std::vector<float> uv;
  std::vector<uint32_t> image;
  uv.reserve(6 * size_t(lm.triangleCount()));
  for (size_t k = 0, t = 0; k < lm.patches.size(); ++k) {
    uv.insert(uv.end(), atlases.cornerUV[k].begin(), atlases.cornerUV[k].end());
    const size_t n = atlases.cornerUV[k].size() / 6;
    image.insert(image.end(), n, uint32_t(k));
    for (size_t i = 0; i < n; ++i, ++t)
      if (lm.trianglePatch[t] != lm.patches[k]) fail("region", "floor triangles are not grouped by patch (texture)");
    fine.images.push_back(&atlases.images[k]);
  }
  if (uv.size() != 6 * size_t(lm.triangleCount())) fail("region", "floor atlases do not cover the floor's triangles");
  fine.cornerUV = uv.data();
  fine.image = image.data();
  tex::SurfaceIndex index(fine);
  const double floorTexel = tex::meanTexelSize(fine);
  const double texel = texelSizeFor(nodeError, floorTexel);
  double textureError = 0;
  const size_t nt = rep.triangles.size() / 3;
  rep.cornerUV.assign(6 * nt, 0.0f);
  rep.triangleMaterial.assign(nt, kAtlasMaterial);
  rep.cellAtlas.clear();
  std::map<uint64_t, std::vector<uint32_t>> cells;  // key -> triangles, in order
  for (uint32_t t = 0; t < nt; ++t) cells[rep.triangleCell[t]].push_back(t);
  std::vector<uint32_t> local(rep.positions.size() / 3, UINT32_MAX);
  for (auto& [key, tris] : cells) {
    std::vector<double> pos;
    std::vector<uint32_t> idx, used;
    for (uint32_t t : tris)
      for (int c = 0; c < 3; ++c) {
        const uint32_t v = rep.triangles[3 * size_t(t) + size_t(c)];
        if (local[v] == UINT32_MAX) {
          local[v] = uint32_t(used.size());
          used.push_back(v);
          pos.insert(pos.end(), &rep.positions[3 * size_t(v)], &rep.positions[3 * size_t(v)] + 3);
        }
        idx.push_back(local[v]);
      }
    for (uint32_t v : used) local[v] = UINT32_MAX;
    tex::BakeResult b = tex::bakeAtlas(pos.data(), used.size(), idx.data(), tris.size(), index, texel, deviation,
                                       context.maxSide, 2, floorTexel);
    textureError = std::max(textureError, textureErrorOf(b.texelSize));
    for (size_t i = 0; i < tris.size(); ++i) std::copy_n(&b.cornerUV[6 * i], 6, &rep.cornerUV[6 * size_t(tris[i])]);
    const std::vector<uint8_t> raw = tex::encodeRaw(b.image);
    rep.cellAtlas[key] = std::string(raw.begin(), raw.end());
  }
  return textureError;
}

}  // namespace mt
