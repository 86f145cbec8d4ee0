// Writing a cut welded by exact grid position in bounded memory: the same mesh as assembleCut
// (mt_cut.h), vertex for vertex and triangle for triangle, streamed to a sink through external
// sorts instead of being held in RAM, so a cut of any size (the finest cut of a billion-triangle
// file) is written within a memory budget. mtextract uses it for cuts whose assembled mesh would
// not fit its --memory.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "mtfile/mt_file.h"

namespace mt {

// What the sink learns before the first vertex (the PLY header's choices need it).
struct WeldedCutInfo {
  uint64_t vertices = 0;             // distinct grid points
  uint64_t triangles = 0;            // written (degenerate ones dropped)
  uint64_t degenerateTriangles = 0;  // dropped: two corners at one grid point
  uint64_t patches = 0;              // decoded (a patch on two arcs counts twice)
  double maxAbsCoordinate = 0;       // max |coordinate| over the vertices
  bool normals = false, colors = false;  // as assembleCut: the header's flags, none for an empty cut
};

class WeldedCutSink {
 public:
  virtual ~WeldedCutSink() = default;
  virtual void begin(const WeldedCutInfo& info) = 0;
  // Vertices in assembleCut's order (first use in arc order then patchRefs order), then triangles.
  virtual void vertex(const double p[3], const float* normal, const uint8_t* color) = 0;
  virtual void triangle(uint32_t a, uint32_t b, uint32_t c) = 0;
};

struct WeldedCutOptions {
  uint64_t memoryBytes = uint64_t(1) << 30;  // for the sorts and the decoded patches
  std::string scratchDir;                    // an existing folder for the sorts' run files
  std::function<void()> poll;                // called between batches (signals), may throw
};

// Streams the cut of `arcs` welded to `sink`, in exactly the order and with exactly the values
// assembleCut gives (positions, mean normals, first colours, triangles). Memory: the budget plus
// the file's DAG and index (already in the reader). Disk: about 40 bytes per patch vertex and
// 16 + 16 per vertex in the scratch folder, in runs of the budget's size, removed as read.
// Throws readPatch's error on a damaged patch, mt::Error on a scratch-file failure.
WeldedCutInfo writeWeldedCut(const MtFileReader& reader, const std::vector<uint32_t>& arcs, const WeldedCutOptions& options,
                             WeldedCutSink& sink);

// About how many bytes assembleCut takes for these arcs (the welded mesh, its weld index and a
// batch of decoded patches), from the patch index: mtextract assembles in RAM below its --memory.
uint64_t assembledCutBytes(const MtFileReader& reader, const std::vector<uint32_t>& arcs);

}  // namespace mt
