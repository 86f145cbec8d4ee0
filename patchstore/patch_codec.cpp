// The patch store's payloads: a patch's geometry block (header, positions, attributes,
// triangles) and its boundary-list block. Layouts: store_format.h; shared by ingest, the write
// path and the readers, so every block the store holds was written by encodeGeometry and
// encodeBoundary.
#include <meshoptimizer.h>

#include <algorithm>
#include <cassert>
#include <cstring>
#include <limits>
#include <mutex>

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

namespace {

// A packed section: its byte count, then what `encode(destination, capacity)` writes (at most
// `bound` bytes; returns how many).
template <class Encode>
void appendSection(std::string& block, size_t bound, Encode encode) {
  const size_t at = block.size();
  block.resize(at + 4 + bound);
  const uint32_t n = uint32_t(encode(reinterpret_cast<unsigned char*>(&block[at + 4]), bound));
  assert(n > 0);
  std::memcpy(&block[at], &n, 4);
  block.resize(at + 4 + n);
}

}  // namespace

// The index sequence code keeps every index in its place (meshopt_encodeIndexBuffer would rotate
// triangles, and the corners' texture coordinates and the floors' payloads follow the corner
// order). Version 1, as the MT file's payload codec sets it process-wide (setMeshoptVersions):
// the same bytes whichever sets it first.
void appendPackedTriangles(std::string& block, const uint32_t* indices, size_t indexCount, uint32_t vertexCount) {
  assert(indexCount > 0 && indexCount % 3 == 0);
  static std::once_flag once;
  std::call_once(once, [] { meshopt_encodeIndexVersion(1); });
  appendSection(block, meshopt_encodeIndexSequenceBound(indexCount, vertexCount), [&](unsigned char* out, size_t capacity) {
    return meshopt_encodeIndexSequence(out, capacity, indices, indexCount);
  });
}

// Version 0 of the vertex codec, the one meshoptimizer 0.18 has and the MT file's payloads use.
void appendPackedPositions(std::string& block, const void* positions, size_t vertexCount, size_t vertexSize) {
  assert(vertexCount > 0 && vertexSize % 4 == 0);
  static std::once_flag once;
  std::call_once(once, [] { meshopt_encodeVertexVersion(0); });
  appendSection(block, meshopt_encodeVertexBufferBound(vertexCount, vertexSize), [&](unsigned char* out, size_t capacity) {
    return meshopt_encodeVertexBuffer(out, capacity, positions, vertexCount, vertexSize);
  });
}

std::string encodeGeometry(const Patch& p, const VertexLayout& layout) {
  const bool vertexUV = layout.texcoords && !p.texcoords.empty();
  const bool packed = !p.triangles.empty(), packedPositions = p.vertexCount() > 0;
  GeometryHeader h{p.vertexCount(), p.triangleCount(),
                   layoutFlags(layout) | (vertexUV ? kGeomVertexUV : 0) | (packed ? kGeomPackedTriangles : 0) |
                       (packedPositions ? kGeomPackedPositions : 0),
                   0};
  ByteWriter w;
  w.put(h);
  if (packedPositions && layout.doublePrecision) {
    appendPackedPositions(w.bytes(), p.positions.data(), p.vertexCount(), 3 * sizeof(double));
  } else if (packedPositions) {
    const std::vector<float> f(p.positions.begin(), p.positions.end());
    appendPackedPositions(w.bytes(), f.data(), p.vertexCount(), 3 * sizeof(float));
  }
  if (layout.normals) w.putRaw(p.normals.data(), p.normals.size() * sizeof(float));
  if (layout.colors) w.putRaw(p.colors.data(), p.colors.size());
  if (vertexUV) {
    assert(p.texcoords.size() == 2 * size_t(p.vertexCount()) && p.vertexMaterial.size() == p.vertexCount());
    for (uint32_t v = 0; v < p.vertexCount(); ++v) {
      w.putRaw(&p.texcoords[2 * size_t(v)], 2 * sizeof(float));
      w.put<uint32_t>(p.vertexMaterial[v]);
    }
  }
  if (packed) appendPackedTriangles(w.bytes(), p.triangles.data(), p.triangles.size(), p.vertexCount());
  if (layout.texcoords && !vertexUV) {
    if (p.cornerUV.size() != 6 * size_t(p.triangleCount()) || p.triangleMaterial.size() != p.triangleCount())
      fail("patch " + std::to_string(p.id), "texture coordinates missing for a textured store");
    w.putRaw(p.triangleMaterial.data(), p.triangleMaterial.size() * sizeof(uint32_t));
    w.putRaw(p.cornerUV.data(), p.cornerUV.size() * sizeof(float));
    w.put<uint32_t>(uint32_t(p.atlas.size()));
    w.putRaw(p.atlas.data(), p.atlas.size());
  }
  return std::move(w.bytes());
}

void decodeGeometry(const std::string& payload, const VertexLayout& layout, Patch& out,
                    const std::string& source) {
  ByteReader r(payload, source);
  auto h = r.get<GeometryHeader>();
  const bool packed = h.flags & kGeomPackedTriangles, packedPositions = h.flags & kGeomPackedPositions;
  const uint32_t flags = h.flags & ~(kGeomPackedTriangles | kGeomPackedPositions);
  const bool vertexUV = layout.texcoords && flags == (layoutFlags(layout) | kGeomVertexUV);
  if (flags != layoutFlags(layout) && !vertexUV) fail(source, "geometry block has the wrong vertex layout");
  if (packed && h.triangleCount == 0) fail(source, "geometry block packs the triangles of an empty patch");
  if (packedPositions && h.vertexCount == 0) fail(source, "geometry block packs the positions of no vertices");
  const size_t nv = h.vertexCount, nt = h.triangleCount;
  // Every array is found in the block before anything is allocated: a damaged count must not ask
  // for gigabytes the block does not hold (checked in one statement first, for a message with the counts).
  const size_t positionSize = layout.doublePrecision ? 24 : 12;
  const uint64_t perVertex = (packedPositions ? 0 : positionSize) + (layout.normals ? 12 : 0) + (layout.colors ? 4 : 0) +
                             (vertexUV ? 12 : 0);
  // A packed triangle takes at least one byte of its code.
  const uint64_t perTriangle = (packed ? 1 : 12) + (layout.texcoords && !vertexUV ? 28 : 0);
  if (uint64_t(nv) * perVertex + uint64_t(nt) * perTriangle > payload.size() - sizeof h)
    fail(source, "geometry block of " + std::to_string(payload.size()) + " bytes is too short for its " + std::to_string(nv) +
                     " vertices and " + std::to_string(nt) + " triangles");
  const size_t positionBytes = nv * positionSize;
  const uint32_t positionCode = packedPositions ? r.get<uint32_t>() : uint32_t(0);
  // The vertex codec spends at least 4 bytes on each byte of a vertex per block of 256 vertices
  // (its 2-bit group headers), so a count beyond that is refused before anything is allocated.
  if (packedPositions && uint64_t(nv) * positionSize > uint64_t(positionCode) * 64 + 256 * positionSize)
    fail(source, "geometry block's " + std::to_string(positionCode) + " bytes of packed positions cannot hold its " +
                     std::to_string(nv) + " vertices");
  const char* positions = r.getRaw(packedPositions ? positionCode : positionBytes);
  const char* normals = layout.normals ? r.getRaw(nv * 3 * sizeof(float)) : nullptr;
  const char* colors = layout.colors ? r.getRaw(nv * 4) : nullptr;
  const char* vertexUVRaw = vertexUV ? r.getRaw(nv * 12) : nullptr;
  const uint32_t triangleBytes = packed ? r.get<uint32_t>() : uint32_t(nt * 3 * sizeof(uint32_t));
  const char* triangles = r.getRaw(triangleBytes);
  const char* triangleMaterial = nullptr;
  const char* cornerUV = nullptr;
  const char* atlas = nullptr;
  uint32_t atlasBytes = 0;
  if (layout.texcoords && !vertexUV) {
    triangleMaterial = r.getRaw(nt * 4);
    cornerUV = r.getRaw(nt * 24);
    atlasBytes = r.get<uint32_t>();
    atlas = r.getRaw(atlasBytes);
  }
  if (!r.atEnd()) fail(source, "geometry block has trailing bytes");
  std::vector<char> unpacked;
  if (packedPositions) {
    unpacked.resize(positionBytes);
    if (meshopt_decodeVertexBuffer(unpacked.data(), nv, positionSize, reinterpret_cast<const unsigned char*>(positions),
                                   positionCode) != 0)
      fail(source, "geometry block's packed positions (" + std::to_string(positionCode) + " bytes) do not decode to " +
                       std::to_string(nv) + " vertices");
    positions = unpacked.data();
  }
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
  std::vector<float> vertexUV2;
  std::vector<uint32_t> vertexMat;
  if (vertexUV) {
    vertexUV2.resize(nv * 2);
    vertexMat.resize(nv);
    for (size_t v = 0; v < nv; ++v) {
      std::memcpy(&vertexUV2[2 * v], vertexUVRaw + 12 * v, 8);
      std::memcpy(&vertexMat[v], vertexUVRaw + 12 * v + 8, 4);
    }
  }
  out.triangles.resize(nt * 3);
  if (packed) {
    if (meshopt_decodeIndexSequence(out.triangles.data(), nt * 3, sizeof(uint32_t),
                                    reinterpret_cast<const unsigned char*>(triangles), triangleBytes) != 0)
      fail(source, "geometry block's packed triangles (" + std::to_string(triangleBytes) + " bytes) do not decode to " +
                       std::to_string(nt) + " triangles");
  } else if (nt) {
    std::memcpy(out.triangles.data(), triangles, nt * 3 * sizeof(uint32_t));
  }
  out.cornerUV.clear();
  out.triangleMaterial.clear();
  out.atlas.clear();
  out.texcoords.clear();
  out.vertexMaterial.clear();
  if (triangleMaterial) {
    out.triangleMaterial.resize(nt);
    if (nt) std::memcpy(out.triangleMaterial.data(), triangleMaterial, nt * 4);
    out.cornerUV.resize(nt * 6);
    if (nt) std::memcpy(out.cornerUV.data(), cornerUV, nt * 24);
    if (atlasBytes) out.atlas.assign(atlas, atlasBytes);
  }
  for (size_t i = 0; i < out.triangles.size(); ++i)
    if (out.triangles[i] >= nv)
      fail(source, "triangle " + std::to_string(i / 3) + " references vertex " +
                       std::to_string(out.triangles[i]) + " of " + std::to_string(nv));
  if (vertexUV) {
    // Ingest's per-vertex form, as every corner's (store_format.h).
    out.cornerUV.resize(nt * 6);
    out.triangleMaterial.resize(nt);
    for (size_t t = 0; t < nt; ++t) {
      for (int c = 0; c < 3; ++c) {
        const uint32_t v = out.triangles[3 * t + size_t(c)];
        out.cornerUV[6 * t + 2 * size_t(c)] = vertexUV2[2 * size_t(v)];
        out.cornerUV[6 * t + 2 * size_t(c) + 1] = vertexUV2[2 * size_t(v) + 1];
      }
      out.triangleMaterial[t] = vertexMat[out.triangles[3 * t]];
    }
  }
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
