// mtexport: an MT file in formats other tools read.
//   mtexport tiles OUT.mt DIR [--codec draco|meshopt|none] [--no-quantize] [--crs CRS | --model-frame]
//                                                           a 3D Tiles 1.1 tileset (interop/tiles_export.h)
// DIR must not exist; it is made under a temporary name beside it and renamed when complete.
#include <CLI/CLI.hpp>

#include <cinttypes>
#include <cstdio>
#include <string>

#include "base/cli_checks.h"
#include "base/error.h"
#include "base/exit_code.h"
#include "base/output_path.h"
#include "interop/tiles_export.h"
#include "mtfile/mt_file.h"

int main(int argc, char** argv) {
  CLI::App app{"mtexport: write an MT file in a format other tools read.\n"
               "  mtexport tiles OUT.mt DIR   a 3D Tiles 1.1 tileset: DIR/tileset.json and DIR/tiles/*.glb, one tile per\n"
               "                              DAG node (REPLACE refinement, geometricError in model units), placed on the\n"
               "                              WGS84 globe when the model has a CRS; see docs/interop.md\n"
               "On any error: one line, the exit code of its kind (1 invalid input, 3 corrupt file, 4 I/O error,\n"
               "5 resource limit: README, \"Exit codes\"), and nothing under DIR."};
  app.require_subcommand(1);
  auto* tiles = app.add_subcommand("tiles", "Export a 3D Tiles 1.1 tileset");
  std::string input, dir;
  bool noQuantize = false, modelFrame = false, quiet = false;
  std::string codec = "draco";
  std::string crs;
  tiles->add_option("file", input, "The MT file")->required();
  tiles->add_option("dir", dir, "The tileset directory to create (must not exist)")->required();
  tiles->add_option("--codec", codec,
                    "How the GLB contents are compressed (docs/interop.md, measured on a 53M build):\n"
                    "  draco    KHR_draco_mesh_compression (the default): Draco's edgebreaker and parallelogram coding of the\n"
                    "           grid coordinates, lossless; the tileset about the MT file's size\n"
                    "  meshopt  EXT_meshopt_compression: about 3x the MT file, a simpler decoder (byte codecs)\n"
                    "  none     plain buffers (KHR_mesh_quantization only): about 11x the MT file")
      ->check(CLI::IsMember({"draco", "meshopt", "none"}));
  tiles->add_flag("--no-quantize", noQuantize,
                  "Float positions instead of KHR_mesh_quantization (the default stores the MT grid's coordinates as uint16,\n"
                  "exactly; a tile wider than 65536 grid steps falls back to float by itself, and to no Draco)");
  auto* crsOption = tiles->add_option(
      "--crs", crs,
      "The CRS of the model's coordinates (e.g. EPSG:32633, a WKT, a PROJ string), instead of the one the MT file\n"
      "carries (mtbuild --crs). With a CRS the root transform places the model on the WGS84 globe (ECEF, the frame\n"
      "of CesiumJS): PROJ transforms a lattice of the model's box and a local affine map is fitted to it (scale\n"
      "factor, convergence, local up); its largest error over the box is printed. x, y are easting and northing\n"
      "(longitude, latitude), z the height (above the ellipsoid for a 2D CRS; give a compound CRS for geoid heights)");
  tiles->add_flag("--model-frame", modelFrame,
                  "Ignore any CRS: the root transform is a translation to the model's coordinates, taken as ECEF\n"
                  "(the default when the MT file has no CRS)")
      ->excludes(crsOption);
  tiles->add_flag("-q,--quiet", quiet, "No progress lines on stderr");
  if (int code = mt::cli::parse(app, argc, argv, "mtexport"); code >= 0) return code;
  try {
    mt::requireRegularFile(input, "an MT file");
    auto reader = mt::MtFileReader::open(input);
    mt::interop::TilesOptions o;
    o.meshopt = codec == "meshopt";
    o.draco = codec == "draco";
    o.quantize = !noQuantize;
    o.progress = !quiet;
    o.crs = crs;
    o.modelFrame = modelFrame;
    mt::interop::TilesReport r = mt::interop::exportTiles(*reader, dir, o);
    std::fprintf(stderr,
                 "mtexport: %s: %" PRIu64 " tiles (%" PRIu64 " leaf copies), %" PRIu64 " GLB contents, depth %u, %" PRIu64
                 " triangles; GLB %" PRIu64 " bytes + tileset.json %" PRIu64 " bytes = %.3f x the MT file (%" PRIu64
                 " bytes); %.2f s\n",
                 dir.c_str(), r.tiles, r.copies, r.contents, r.depth, r.triangles, r.glbBytes, r.tilesetBytes,
                 double(r.glbBytes + r.tilesetBytes) / double(reader->fileSize()), reader->fileSize(), r.seconds);
    if (r.placed) {
      const mt::interop::GeoPlacement& g = r.placement;
      std::fprintf(stderr,
                   "mtexport: placed on the globe (%s): box centre at longitude %.9f, latitude %.9f, height %.3f m; "
                   "scale %.7f %.7f %.7f, convergence %.6f deg; local affine map within %.3g m of PROJ over the box\n",
                   g.crsName.c_str(), g.longitude, g.latitude, g.height, g.unitScale[0], g.unitScale[1], g.unitScale[2],
                   g.convergenceDegrees, g.maxError);
      if (g.maxError > reader->header().quantizationError)
        std::fprintf(stderr,
                     "mtexport: warning: the affine map's error (%.3g m) exceeds the MT grid's quantization error (%.3g): "
                     "the model is too large for one root transform at this precision\n",
                     g.maxError, reader->header().quantizationError);
    }
    if (r.floatTiles)
      std::fprintf(stderr, "mtexport: %" PRIu64 " tiles wider than 65536 grid steps have float positions\n", r.floatTiles);
  } catch (const std::exception& e) {
    return mt::reportError("mtexport", e);
  }
  return 0;
}
