// The patch store's payloads: a patch's geometry block (header, positions, attributes,
// triangles) and its boundary-list block. Layouts: store_format.h; shared by ingest, the write
// path and the readers, so every block the store holds was written by encodeGeometry and
// encodeBoundary.
#include <algorithm>
#include <cstring>
#include <limits>

#include "base/byte_io.h"
#include "patchstore/store_impl.h"

namespace mt {

using namespace store_format;

Box3 boundsOf(const std::vector<double>& positions) {
  Box3 b;
  for (int a = 0; a < 3; ++a) {
    b.lo[a] = std::numeric_limits<double>::infinity();
    b.hi[a] = -std::numeric_limits<double>::infinity();
  }
  for (size_t i = 0; i < positions.size(); i += 3)
    for (int a = 0; a < 3; ++a) {
      b.lo[a] = std::min(b.lo[a], positions[i + a]);
      b.hi[a] = std::max(b.hi[a], positions[i + a]);
    }
  return b;
}

std::string encodeGeometry(const Patch& p, const VertexLayout& layout) {
  GeometryHeader h{p.vertexCount(), p.triangleCount(), layoutFlags(layout), 0};
  ByteWriter w;
  w.put(h);
  if (layout.doublePrecision) {
    w.putRaw(p.positions.data(), p.positions.size() * sizeof(double));
  } else {
    std::vector<float> f(p.positions.begin(), p.positions.end());
    w.putRaw(f.data(), f.size() * sizeof(float));
  }
  if (layout.normals) w.putRaw(p.normals.data(), p.normals.size() * sizeof(float));
  if (layout.colors) w.putRaw(p.colors.data(), p.colors.size());
  w.putRaw(p.triangles.data(), p.triangles.size() * sizeof(uint32_t));
  return std::move(w.bytes());
}

void decodeGeometry(const std::string& payload, const VertexLayout& layout, Patch& out,
                    const std::string& source) {
  ByteReader r(payload, source);
  auto h = r.get<GeometryHeader>();
  if (h.flags != layoutFlags(layout)) fail(source, "geometry block has the wrong vertex layout");
  const size_t nv = h.vertexCount, nt = h.triangleCount;
  // Every array is found in the block before anything is allocated: a damaged count must not ask
  // for gigabytes the block does not hold.
  const size_t positionBytes = nv * 3 * (layout.doublePrecision ? sizeof(double) : sizeof(float));
  const char* positions = r.getRaw(positionBytes);
  const char* normals = layout.normals ? r.getRaw(nv * 3 * sizeof(float)) : nullptr;
  const char* colors = layout.colors ? r.getRaw(nv * 4) : nullptr;
  const char* triangles = r.getRaw(nt * 3 * sizeof(uint32_t));
  if (!r.atEnd()) fail(source, "geometry block has trailing bytes");
  out.positions.resize(nv * 3);
  if (layout.doublePrecision) {
    if (nv) std::memcpy(out.positions.data(), positions, positionBytes);  // memcpy(null, ..., 0) is UB
  } else {
    for (size_t i = 0; i < nv * 3; ++i) {
      float f;
      std::memcpy(&f, positions + i * sizeof(float), sizeof f);
      out.positions[i] = f;
    }
  }
  out.normals.clear();
  out.colors.clear();
  if (normals) {
    out.normals.resize(nv * 3);
    if (nv) std::memcpy(out.normals.data(), normals, nv * 3 * sizeof(float));
  }
  if (colors) {
    out.colors.resize(nv * 4);
    if (nv) std::memcpy(out.colors.data(), colors, nv * 4);
  }
  out.triangles.resize(nt * 3);
  if (nt) std::memcpy(out.triangles.data(), triangles, nt * 3 * sizeof(uint32_t));
  for (size_t i = 0; i < out.triangles.size(); ++i)
    if (out.triangles[i] >= nv)
      fail(source, "triangle " + std::to_string(i / 3) + " references vertex " +
                       std::to_string(out.triangles[i]) + " of " + std::to_string(nv));
}

std::string encodeBoundary(const std::vector<BoundaryEntry>& entries) {
  ByteWriter w;
  w.put<uint32_t>(uint32_t(entries.size()));
  w.putRaw(entries.data(), entries.size() * sizeof(BoundaryEntry));
  return std::move(w.bytes());
}

std::vector<BoundaryEntry> decodeBoundary(const std::string& payload, const std::string& source) {
  ByteReader r(payload, source);
  uint32_t n = r.get<uint32_t>();
  const void* raw = r.getRaw(size_t(n) * sizeof(BoundaryEntry));  // there before it is allocated
  if (!r.atEnd()) fail(source, "boundary block has trailing bytes");
  std::vector<BoundaryEntry> entries(n);
  if (n) std::memcpy(entries.data(), raw, size_t(n) * sizeof(BoundaryEntry));  // memcpy(null, ..., 0) is UB
  return entries;
}

}  // namespace mt
