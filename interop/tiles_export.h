// 3D Tiles 1.1 export of an MT file: tileset.json and one GLB per tile content, REPLACE
// refinement, geometricError in the model's units, bounding spheres that contain their children.
// The mapping of the MT's DAG onto the 3D Tiles tree is written down in docs/interop.md:
//
//  - one tile per DAG node n (neither source nor sink) whose content is n's fragment (the patches
//    on n's out-arcs), geometricError = n's error, bounding sphere = n's sphere;
//  - the tree: each node hangs under ONE successor (the one its largest out-arc goes to); under
//    every other successor it appears as a leaf copy that points at the same GLB (no bytes are
//    duplicated, only a tileset.json entry), so refining any tile shows its whole floor: no holes;
//  - the source (full resolution) is split by its out-arcs: arc 0 -> m is a leaf under m's tile,
//    geometricError 0, exactly the floor of m;
//  - the root has no content, its children are the sink's predecessors; its geometricError is the
//    model's diameter (the whole model missing is an error of its size);
//  - the tiles' frame is the model's, relative to the MT grid's origin (a double), so every GLB
//    stays small; the root transform places that frame: with a CRS (the MT file's, or the
//    options'), on the WGS84 globe in ECEF by PROJ's local affine fit over the model's box
//    (georeference.h); without one, a translation to the grid's origin (the model's coordinates
//    are then taken as Cesium's world frame).
#pragma once

#include <cstdint>
#include <string>

#include "interop/georeference.h"
#include "mtfile/mt_file.h"

namespace mt::interop {

struct TilesOptions {
  // The contents' compression (docs/interop.md, sizes measured): KHR_draco_mesh_compression (the
  // default, needs quantize), else EXT_meshopt_compression when meshopt, else plain buffers.
  bool draco = true;
  bool meshopt = false;
  bool quantize = true;   // KHR_mesh_quantization (grid coordinates as uint16; float where a tile is wider)
  bool progress = false;  // a line on stderr every few seconds
  // The CRS of the model's coordinates; empty: the MT file's (mtbuild --crs), if any.
  std::string crs;
  // Ignore any CRS: the root transform is the translation to the grid's origin (model frame).
  bool modelFrame = false;
};

struct TilesReport {
  uint64_t tiles = 0;         // entries of tileset.json (root and copies included)
  uint64_t contents = 0;      // GLB files written
  uint64_t copies = 0;        // leaf copies (a second parent's entry for a node)
  uint32_t depth = 0;         // levels of the tree below the root (the root alone: 0)
  uint64_t glbBytes = 0;      // sum of the GLB files
  uint64_t tilesetBytes = 0;  // tileset.json
  uint64_t triangles = 0;     // sum over the contents (every stored triangle once)
  uint64_t floatTiles = 0;    // contents written with float positions though quantize was asked
  double seconds = 0;
  bool placed = false;        // the root transform puts the model on the globe (a CRS was given)
  GeoPlacement placement;     // when placed: where, and the affine map's error over the box
};

// Writes DIR (which must not exist): everything is made in a temporary directory beside it and
// renamed to DIR when complete, so on any error nothing is left under DIR. Throws mt::Error.
TilesReport exportTiles(const MtFileReader& reader, const std::string& dir, const TilesOptions& options);

}  // namespace mt::interop
