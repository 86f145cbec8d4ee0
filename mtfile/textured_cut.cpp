// A textured cut: see textured_cut.h.
#include "mtfile/textured_cut.h"

namespace mt {

uint64_t TexturedCut::textureBytes() const {
  uint64_t n = 0;
  for (const CutTexture& t : textures) n += t.image.size();
  return n;
}

TexturedCut assembleTexturedCut(const MtFileReader& r, const std::vector<uint32_t>& arcs) {
  TexturedCut out;
  out.mesh = assembleCut(r, arcs);
  const WeldedMesh& m = out.mesh;
  out.cornerUV.assign(6 * size_t(m.triangleCount()), 0.0f);
  out.triangleTexture.assign(m.triangleCount(), UINT32_MAX);
  // The mesh's triangles come patch by patch, each patch's in decoded order less its degenerate
  // ones (two corners at one grid point): walk them again alongside.
  for (size_t t = 0; t < m.triangleCount();) {
    const uint32_t p = m.trianglePatch[t];
    const DecodedPatch d = r.readPatch(p);
    const TexturePayload tp = r.readTexture(p, d);
    uint32_t texture = UINT32_MAX;
    if (!tp.image.empty()) {
      texture = uint32_t(out.textures.size());
      out.textures.push_back({p, tp.width, tp.height, tp.imageFormat, tp.image});
    }
    auto same = [&](uint32_t a, uint32_t b) {
      return d.q[3 * a] == d.q[3 * b] && d.q[3 * a + 1] == d.q[3 * b + 1] && d.q[3 * a + 2] == d.q[3 * b + 2];
    };
    for (uint32_t k = 0; k < d.triangleCount(); ++k) {
      const uint32_t a = d.triangles[3 * k], b = d.triangles[3 * k + 1], c = d.triangles[3 * k + 2];
      if (same(a, b) || same(b, c) || same(a, c)) continue;
      if (t >= m.triangleCount() || m.trianglePatch[t] != p)
        failCorrupt(r.path(), "patch " + std::to_string(p) + " decodes differently on a second read");
      if (texture != UINT32_MAX) {
        std::copy_n(&tp.cornerUV[6 * size_t(k)], 6, &out.cornerUV[6 * t]);
        out.triangleTexture[t] = texture;
      }
      ++t;
    }
  }
  return out;
}

}  // namespace mt
