// mtexport: an MT file in formats other tools read.
//   mtexport tiles OUT.mt DIR [--meshopt] [--no-quantize]   a 3D Tiles 1.1 tileset (interop/tiles_export.h)
// DIR must not exist; it is made under a temporary name beside it and renamed when complete.
#include <CLI/CLI.hpp>

#include <cinttypes>
#include <cstdio>
#include <string>

#include "base/cli_checks.h"
#include "base/error.h"
#include "base/output_path.h"
#include "interop/tiles_export.h"
#include "mtfile/mt_file.h"

int main(int argc, char** argv) {
  CLI::App app{"mtexport: write an MT file in a format other tools read.\n"
               "  mtexport tiles OUT.mt DIR   a 3D Tiles 1.1 tileset: DIR/tileset.json and DIR/tiles/*.glb, one tile per\n"
               "                              DAG node (REPLACE refinement, geometricError in model units); see docs/interop.md\n"
               "On any error: one line, exit 1, and nothing under DIR."};
  app.require_subcommand(1);
  auto* tiles = app.add_subcommand("tiles", "Export a 3D Tiles 1.1 tileset");
  std::string input, dir;
  bool meshopt = false, noQuantize = false;
  tiles->add_option("file", input, "The MT file")->required();
  tiles->add_option("dir", dir, "The tileset directory to create (must not exist)")->required();
  tiles->add_flag("--meshopt", meshopt, "Compress every GLB's buffer views with EXT_meshopt_compression");
  tiles->add_flag("--no-quantize", noQuantize,
                  "Float positions instead of KHR_mesh_quantization (the default stores the MT grid's coordinates as uint16,\n"
                  "exactly; a tile wider than 65536 grid steps falls back to float by itself)");
  if (int code = mt::cli::parse(app, argc, argv, "mtexport"); code >= 0) return code;
  try {
    mt::requireRegularFile(input, "an MT file");
    auto reader = mt::MtFileReader::open(input);
    mt::interop::TilesOptions o;
    o.meshopt = meshopt;
    o.quantize = !noQuantize;
    o.progress = true;
    mt::interop::TilesReport r = mt::interop::exportTiles(*reader, dir, o);
    std::fprintf(stderr,
                 "mtexport: %s: %" PRIu64 " tiles (%" PRIu64 " leaf copies), %" PRIu64 " GLB contents, depth %u, %" PRIu64
                 " triangles; GLB %" PRIu64 " bytes + tileset.json %" PRIu64 " bytes = %.3f x the MT file (%" PRIu64
                 " bytes); %.2f s\n",
                 dir.c_str(), r.tiles, r.copies, r.contents, r.depth, r.triangles, r.glbBytes, r.tilesetBytes,
                 double(r.glbBytes + r.tilesetBytes) / double(reader->fileSize()), reader->fileSize(), r.seconds);
    if (r.floatTiles)
      std::fprintf(stderr, "mtexport: %" PRIu64 " tiles wider than 65536 grid steps have float positions\n", r.floatTiles);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mtexport: %s\n", e.what());
    return 1;
  }
  return 0;
}
