// Streaming mesh readers: the contract between the input formats and everything that consumes a
// scan (ingest, the V-partition seed pass, tests). A reader never holds the whole file: it pushes
// vertices and triangles in file order, in batches, to a MeshSink, with bounded memory.
//
// Guarantees a sink can rely on:
//  - every vertex is finite (NaN/Inf is an error naming the vertex index and line/byte offset);
//  - every triangle index is < the number of vertices already delivered, or, for formats that
//    declare their vertex count up front (PLY, OFF), < that count; out-of-range or negative
//    indices are errors naming the face index and line/byte offset;
//  - polygons are fan-triangulated (v0, vi, vi+1) in file order;
//  - errors are mt::Error with a one-line message "PATH: ...";
//  - degenerate triangles (a repeated index) are delivered, and counted in ReadStats;
//  - texture coordinates (header.hasTexcoords) come per vertex, in [0, 1], with the vertex's
//    material (an index into header.materials, or kNoMaterial). Inputs that give them per face
//    corner (OBJ "f v/vt", PLY per-face texcoord lists) are split into one vertex per distinct
//    (vertex, texture coordinate, material) by openMesh (wedge_split.cpp), so seams become
//    vertices with equal positions; the store's grid weld joins them again and keeps the seam in
//    per-corner texture coordinates.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "base/error.h"

namespace mt {

enum class MeshFormat { Unknown, PlyAscii, PlyBinaryLE, PlyBinaryBE, Obj, Off, StlAscii, StlBinary, Gltf, Glb };
const char* formatName(MeshFormat f);

// The material of a textured input: its texture image (the resolved path; empty when it has
// none) and its diffuse colour (what a renderer shows where there is no image).
struct InputMaterial {
  std::string name;
  std::string texture;    // path of the image (OBJ map_Kd, PLY "comment TextureFile"), or ""
  std::string source;     // where it was named, for errors about the image: "FILE (line N)"
  uint8_t diffuse[3] = {255, 255, 255};
};
constexpr uint32_t kNoMaterial = 0xFFFFFFFFu;

// What the file declares before its data (counts are -1 when the format does not declare them).
struct MeshHeader {
  MeshFormat format = MeshFormat::Unknown;
  int64_t declaredVertices = -1;
  int64_t declaredFaces = -1;
  bool hasNormals = false;  // per-vertex nx,ny,nz (PLY, OBJ vn when one normal per vertex)
  bool hasColors = false;   // per-vertex red,green,blue[,alpha] (PLY)
  // True when the input's coordinates need more than float32 to round-trip exactly: binary PLY
  // with double or 32-bit integer coordinates, and every text format (decimal text carries the
  // precision its writer gave it, whatever type it declares; it is parsed to double).
  bool doublePrecision = false;
  // Per-vertex texture coordinates and material (InputVertex::uv, material) and the materials
  // they index. Set only when a material has a texture image.
  bool hasTexcoords = false;
  std::vector<InputMaterial> materials;
  // The reader gives texture coordinates per face corner (MeshSink::cornerTexcoords) instead:
  // only between a reader and openMesh's wedge split; a sink never sees it set.
  bool cornerTexcoords = false;
  // The vertices (and the faces' indices) are the wedge split's, not the file's.
  bool splitAtSeams = false;
};

struct InputVertex {
  double p[3];
  float n[3];          // 0,0,0 when the input has no normals
  uint8_t c[4];        // 255,255,255,255 when the input has no colours
  float uv[2];         // texture coordinates in [0, 1] (0,0 when none), v up (OBJ's convention)
  uint32_t material;   // index into MeshHeader::materials, kNoMaterial when untextured
};

struct ReadStats {
  uint64_t vertices = 0;
  uint64_t triangles = 0;          // after triangulation
  uint64_t polygons = 0;           // faces with more than 3 corners, before triangulation
  uint64_t degenerateTriangles = 0;  // with a repeated vertex index
  uint64_t bytes = 0;              // bytes of input consumed
};

class MeshSink {
 public:
  virtual ~MeshSink() = default;
  // Called once, after the header is parsed and before any data.
  virtual void begin(const MeshHeader& header) { (void)header; }
  // Batches of vertices, in file order; global index of v[0] is `first`.
  virtual void vertices(const InputVertex* v, size_t count, uint64_t first) = 0;
  // Batches of triangles as global vertex indices (3 per triangle), in file order.
  virtual void triangles(const uint32_t* indices, size_t count) = 0;
  // With header.cornerTexcoords only (a reader feeding openMesh's wedge split): right after each
  // triangles() call, the same triangles' corner texture coordinates (6 floats per triangle) and
  // materials (1 per triangle).
  virtual void cornerTexcoords(const float* uv, const uint32_t* materials, size_t count) {
    (void)uv, (void)materials, (void)count;
  }
  virtual void end(const ReadStats& stats) { (void)stats; }
};

class MeshReader {
 public:
  virtual ~MeshReader() = default;
  virtual const MeshHeader& header() const = 0;
  // Streams the whole file to the sink. Throws mt::Error on bad input.
  virtual ReadStats read(MeshSink& sink) = 0;
};

// Picks the format by content (magic bytes, "ply"/"OFF"/"solid" headers, the GLB magic "glTF", STL
// size check) and then
// by extension; unknown formats are an error naming the file. Opens and parses the header only.
std::unique_ptr<MeshReader> openMesh(const std::string& path);

// Where openMesh's wedge split of a per-corner textured input keeps its scratch files (external
// sorts of the corners), and how much memory the split and the readers' texture-coordinate
// tables (OBJ "vt") may take.
struct MeshOpenOptions {
  std::string scratchDir;                 // empty: $TMPDIR (or /tmp)
  uint64_t memoryBytes = 256ull << 20;
};
std::unique_ptr<MeshReader> openMesh(const std::string& path, const MeshOpenOptions& options);

// Vertices above this index count cannot be addressed by the 32-bit indices used throughout.
constexpr uint64_t kMaxVertices = 0xFFFFFFFEull;

}  // namespace mt
