// mtrender --color (see color_mode.h).
#include "mtrender/color_mode.h"

#include "base/error.h"
#include "mtfile/mt_file.h"

namespace mt::render {

const std::vector<std::string>& colorModeNames() {
  static const std::vector<std::string> names = {"auto", "shaded", "vertex", "texture", "patch", "lod"};
  return names;
}

const char* colorModeName(ColorMode mode) {
  switch (mode) {
    case ColorMode::Shaded: return "shaded";
    case ColorMode::Vertex: return "vertex colours";
    case ColorMode::Texture: return "texture";
    case ColorMode::Patch: return "patch colours";
    case ColorMode::Lod: return "LOD colours";
  }
  return "?";
}

ColorMode resolveColorMode(const std::string& name, const ColorSupport& support, std::string* note) {
  if (note) note->clear();
  if (name == "auto") return support.hasTextures ? ColorMode::Texture : support.hasColors ? ColorMode::Vertex : ColorMode::Shaded;
  if (name == "shaded") return ColorMode::Shaded;
  if (name == "patch") return ColorMode::Patch;
  if (name == "lod") return ColorMode::Lod;
  if (name == "vertex") {
    if (!support.hasColors && note) *note = "no vertex colours in " + support.fileName + ", drawing it white";
    return ColorMode::Vertex;
  }
  if (name == "texture") {
    if (support.hasTextures) return ColorMode::Texture;
    if (note)
      *note = "no texture in " + support.fileName + (support.hasColors ? ", using vertex colours" : ", using shaded");
    return support.hasColors ? ColorMode::Vertex : ColorMode::Shaded;
  }
  throw Error("--color " + name + ": unknown (expected auto, shaded, vertex, texture, patch or lod)");
}

ColorSupport colorSupportOf(const std::vector<std::string>& files) {
  ColorSupport s;
  s.hasColors = s.hasTextures = !files.empty();
  for (const std::string& f : files) {
    const format::FileHeader h = MtFileReader::readHeader(f);
    if (!(h.vertexFlags & format::kHasColors)) s.hasColors = false;
    if (!(h.vertexFlags & format::kHasTextures) || h.patchCount == 0) s.hasTextures = false;
  }
  if (!files.empty()) s.fileName = files.size() == 1 ? files[0] : files[0] + " (and " + std::to_string(files.size() - 1) + " more)";
  return s;
}

ColorMode nextColorMode(ColorMode mode, const ColorSupport& support) {
  static const ColorMode order[] = {ColorMode::Shaded, ColorMode::Vertex, ColorMode::Texture, ColorMode::Patch, ColorMode::Lod};
  constexpr int n = sizeof order / sizeof order[0];
  int i = 0;
  while (i < n && order[i] != mode) ++i;
  for (int k = 1; k <= n; ++k) {
    const ColorMode m = order[(i + k) % n];
    if ((m == ColorMode::Vertex && !support.hasColors) || (m == ColorMode::Texture && !support.hasTextures)) continue;
    return m;
  }
  return mode;
}

}  // namespace mt::render
