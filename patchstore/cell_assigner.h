// The pluggable cell assignment used by ingest (and by mtbuild when it splits a simplified region).
// A triangle goes to a cell by its centroid (BMT section 4: "the rule that uniquely assigns a
// triangle to a region of space, e.g. the one where the barycenter of t falls").
//
// Ingest hands the assigner its centroids in Morton order; an assigner may stream over them as
// many times as it needs before it is asked for cell keys, or take a stride sample only (the
// irregular V-partition), which ingest can give without materializing the stream. Keys need not
// be compact: the store sorts by key and numbers the non-empty cells.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace mt {

struct Box3 {
  double lo[3] = {0, 0, 0};
  double hi[3] = {0, 0, 0};
};

// A sequence of triangle centroids that can be read start to end any number of times with bounded
// memory. Each triangle is 4 floats: centroid x,y,z and the triangle's area. One forEach() is one
// pass: fn gets consecutive batches that cover every triangle exactly once, always in the same
// order (ingest gives Morton order, so that consecutive centroids are close in space).
class CentroidSource {
 public:
  virtual ~CentroidSource() = default;
  virtual uint64_t count() const = 0;
  virtual Box3 bounds() const = 0;  // of the vertices, not only of the centroids
  virtual void forEach(const std::function<void(const float* xyza, size_t count)>& fn) const = 0;
  // The centroids at positions 0, stride, 2 stride, ... of one pass (4 floats each), in pass
  // order: what a sampling assigner reads instead of the whole stream. This default runs a whole
  // pass; a source that can pick them without materializing the stream (ingest) overrides it.
  virtual std::vector<float> sample(uint64_t stride) const {
    std::vector<float> out;
    out.reserve(4 * size_t((count() + stride - 1) / stride));
    uint64_t index = 0;
    forEach([&](const float* xyza, size_t n) {
      size_t t = size_t((stride - index % stride) % stride);
      for (; t < n; t += size_t(stride)) out.insert(out.end(), xyza + 4 * t, xyza + 4 * t + 4);
      index += n;
    });
    return out;
  }
};

class CellAssigner {
 public:
  virtual ~CellAssigner() = default;
  // Called once before any cellKey(); memoryBytes is the share of the --memory cap it may use.
  virtual void prepare(const CentroidSource& centroids, uint64_t memoryBytes) = 0;
  // The cell of a triangle whose centroid is c. Must be deterministic and thread-safe.
  virtual uint64_t cellKey(const float c[3]) const = 0;
  // One line for logs and `mtstore info`, e.g. "grid 32x20x11".
  virtual std::string describe() const = 0;
  // Opaque bytes the assigner wants kept in the store (e.g. the V-partition seeds), or empty.
  virtual std::string serialize() const { return {}; }
  // Called once the last cellKey() has returned: frees what only cellKey() needs (lookup tables,
  // the sample's key maps), so the ingest's later stages plan with that memory. describe() and
  // serialize() answer as before; cellKey() must not be called again.
  virtual void releaseLookups() {}
};

// The default until a V-partition is plugged in: a uniform grid over the bounding box with cubic
// cells sized so that a cell holds about trianglesPerCell triangles if the surface were spread
// evenly over the occupied cells (the grid is refined once by counting occupied cells).
std::unique_ptr<CellAssigner> makeGridAssigner(uint32_t trianglesPerCell);

}  // namespace mt
