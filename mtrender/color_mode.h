// mtrender --color: the one place that names the colour modes, parses them and decides what a
// file can show (the viewer's C key cycles through the same list).
//   shaded   the surface in one stone colour, lit by the headlight (geometry only);
//   vertex   the per-vertex colours (mt_format.h kHasColors) as they are, unlit: a scan's colours
//            were captured under real light and carry its shading (lighting them again darkens
//            every hollow twice; photogrammetry viewers show them unlit too), and the image then
//            measures the colours alone (docs/appearance.md); white where a file has none;
//   texture  the node textures (mt_format.h "Textures"), unlit like the vertex colours; patches
//            without one show their vertex colours; files without textures fall back to vertex
//            colours (or shaded), saying so;
//   patch    one colour per patch; lod: one colour per level;
//   auto     (the default) texture when every file has textures, else vertex when every file has
//            colours, else shaded.
#pragma once

#include <string>
#include <vector>

#include "mtrender/gl_renderer.h"

namespace mt::render {

// Every name --color accepts, "auto" first.
const std::vector<std::string>& colorModeNames();
const char* colorModeName(ColorMode mode);

// What the files can show. hasColors: every file has per-vertex colours; hasTextures: every file
// has node textures.
struct ColorSupport {
  bool hasColors = false, hasTextures = false;
  std::string fileName;  // named in notes (the first file)
};

// The mode for `name` (one of colorModeNames(); throws mt::Error otherwise). When the files cannot
// show it (texture without textures), the mode drawn instead, with `note` saying so, e.g. "no
// texture in FILE, using vertex colours".
ColorMode resolveColorMode(const std::string& name, const ColorSupport& support, std::string* note);

// What the files can show (reads their headers).
ColorSupport colorSupportOf(const std::vector<std::string>& files);

// The viewer's C key: the next mode after `mode` among those the files can show.
ColorMode nextColorMode(ColorMode mode, const ColorSupport& support);

}  // namespace mt::render
