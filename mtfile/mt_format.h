// The MT file format: the one place where it is written down. mtbuild writes it (mt_file.h),
// mtrender reads it and needs nothing else from the build side. docs/mt-format.md is a summary.
//
// A file holds one batched Multi-Triangulation (BMT sections 3.1, 4.1): a DAG whose nodes are
// fragments (one per region of V(i+1) per level, plus a source and a sink) and whose arcs carry
// patches. Every patch payload is coded on its own (BMT section 6: "individually compressed using
// a quick decompression algorithm") so the renderer can load any patch with one read.
//
// Layout (all integers little-endian, all structs below are the exact on-disk bytes):
//
//   offset 0            FileHeader (kHeaderSize bytes)
//   kHeaderSize...      patch payloads, each starting at a multiple of header.payloadAlignment
//   header.metaOffset   NodeRecord[nodeCount]
//                       ArcRecord[arcCount]          sorted by (from, to): a node's forward star
//                       uint32 backArcs[arcCount]    arc ids sorted by (to, from): backward stars
//                       uint32 patchRefs[patchRefCount]  arc -> its patches
//                       PatchRecord[patchCount]      the patch index
//   header.metadataOffset  metadata block (metadataSize bytes; optional, absent when 0)
//   end - kFooterSize   Footer
//
// The section offsets in the header are absolute and must tile [metaOffset, footer) exactly in
// the order above. Footer.checksum = XXH64(header bytes, then bytes [metaOffset, footer), seed 0):
// it covers everything a reader trusts before touching a payload. Each payload has its own
// XXH64 (seed 0) in its PatchRecord, checked when the patch is read, so a damaged payload is
// reported as "patch N" without spoiling the rest of the file. The padding between a payload and
// the next one (or the index after the last) is zero bytes, which no checksum covers: readers
// check the gaps of up to 4 KiB a writer makes, so a flipped byte there is found too. A range-coded
// stream (below) that a decoder reads past the payload's end is damaged, not zero-extended.
//
// DAG orientation (BMT 3.1): node 0 is the source, whose fragment is the full-resolution mesh
// (level 0); the last node is the sink (level = levelCount, error = +inf, no patches). An arc
// from -> to carries the patches of `from`'s fragment that lie in the floor of `to`, i.e. that
// `to` replaces; `to` is the coarser node. A cut is the set of arcs leaving a set of nodes that
// contains the source and is closed under predecessors (for every node in it, all its from-nodes
// are in it); its patches, welded by exact grid position, form a conforming mesh. Refining a cut
// means removing a node from the set (moving towards the source), coarsening means adding one.
//
// Positions: every vertex of every patch is stored as integer coordinates q on ONE global grid,
// p = gridOrigin + gridStep * q (per axis, computed in double). Vertices that neighbouring patches
// share therefore decode to bit-identical positions and cuts cannot crack. The grid step is chosen
// by the builder; quantization moves a vertex by at most quantizationError = gridStep*sqrt(3)/2,
// which is already added to every node's error.
#pragma once

#include <cstddef>
#include <cstdint>

namespace mt::format {

constexpr char kMagic[8] = {'B', 'M', 'T', '-', 'M', 'T', '\r', '\n'};
constexpr char kFooterMagic[8] = {'B', 'M', 'T', '-', 'E', 'N', 'D', '\n'};
// Version 2: meshopt payloads may set kPayloadRangePositions (positions range-coded after the
// zstd frame instead of byte planes inside it). Version 3: meshopt payloads may also set
// kPayloadPositionContexts (another residual model) and kPayloadRangeIndices (the index code
// range-coded ahead of the positions). Version 4: meshopt payloads may also set
// kPayloadConnectivity (the triangles by the connectivity code instead of the meshopt index code);
// version-4 writers no longer set kPayloadRangeIndices. Version 5: NodeRecord::colorError (the
// word was reserved and zero before, so an older file reads as "colour error not measured", 0).
// Readers accept kMinReadableVersion..kVersion; the payload flags say how each payload is coded,
// so one decoder reads all five.
constexpr uint32_t kVersion = 5;
// The first version whose nodes carry NodeRecord::colorError.
constexpr uint32_t kFirstColorErrorVersion = 5;
constexpr uint32_t kMinReadableVersion = 1;
constexpr uint32_t kHeaderSize = 256;
constexpr uint32_t kFooterSize = 32;
// Payload alignment: 16 keeps the padding cost at ~8 bytes per patch (patches are ~1-4 KB)
// while every payload starts on a SIMD/cache-friendly boundary. Readers wanting O_DIRECT read
// the enclosing 4 KiB-aligned range. Stored in the header so a writer may choose another power
// of two.
constexpr uint32_t kDefaultPayloadAlignment = 16;

// How the payloads are coded (patch_codec.h has the payload layouts).
enum class Codec : uint32_t {
  Meshopt = 1,  // meshoptimizer index (+attribute) codecs, parallelogram positions, then zstd
  Draco = 2,    // Draco edgebreaker, positions as lossless integer attribute
};

// FileHeader::vertexFlags
constexpr uint32_t kHasNormals = 1u << 0;  // every patch stores octahedral normals
constexpr uint32_t kHasColors = 1u << 1;   // every patch stores RGBA8 colours

struct FileHeader {
  char magic[8];             // kMagic
  uint32_t version;          // kVersion
  uint32_t headerSize;       // kHeaderSize
  uint32_t codec;            // Codec
  uint32_t vertexFlags;      // kHasNormals | kHasColors
  uint32_t payloadAlignment; // power of two >= 1
  uint32_t levelCount;       // levels 0..levelCount-1 (the sink has level levelCount)
  uint64_t nodeCount;
  uint64_t arcCount;
  uint64_t patchRefCount;
  uint64_t patchCount;
  uint64_t inputTriangles;   // triangles of the input mesh
  uint64_t inputVertices;
  uint64_t storedTriangles;  // sum over all patches
  double boundsMin[3];       // bounding box of the input, object space
  double boundsMax[3];
  double gridOrigin[3];      // p = gridOrigin + gridStep * q
  double gridStep;
  double quantizationError;  // gridStep * sqrt(3) / 2, included in every node error
  uint32_t gridBits;         // every q component is < 2^gridBits (<= 31)
  uint32_t metadataSize;     // bytes of the metadata block (0: none; was reserved, zero, before)
  uint64_t metaOffset;       // start of the DAG + index section (end of payloads)
  uint64_t nodesOffset;
  uint64_t arcsOffset;
  uint64_t backArcsOffset;
  uint64_t patchRefsOffset;
  uint64_t patchesOffset;
  // The grid weld (patchstore/heal/heal.h weldToGrid): input vertices that fell into one grid
  // cell became one vertex, and the triangles that became degenerate were removed, so the finest
  // cut has inputTriangles - weldedTriangles triangles. Zero in files written before the weld.
  uint64_t weldedVertices;
  uint64_t weldedTriangles;
  uint64_t metadataOffset;   // the metadata block's offset (0 when metadataSize is 0; was reserved, zero)
};
static_assert(sizeof(FileHeader) == kHeaderSize, "FileHeader is the first 256 bytes of the file");
static_assert(offsetof(FileHeader, metadataSize) == 180 && offsetof(FileHeader, metadataOffset) == 248, "metadata fields");

// A DAG node: one fragment (BMT 3.1). Invariants (checked by the reader only where cheap, by
// mtverify in full): error >= every predecessor's error (monotone towards the sink), the sphere
// contains every predecessor's sphere.
struct NodeRecord {
  double center[3];      // bounding sphere of the fragment and everything it replaces
  float radius;
  float error;           // object-space error bound of the fragment (incl. quantization); sink: +inf
  float coneAxis[3];     // normal cone: unit axis ...
  float coneCutoff;      // ... and cos(half angle); -1 when the cone is the whole sphere
  uint32_t level;        // 0 = source (full resolution)
  uint32_t region;       // the region's index in V(level) (builder-defined; 0 for source/sink)
  uint32_t firstArc;     // forward star: arcs[firstArc, firstArc + arcCount)
  uint32_t arcCount;
  uint32_t firstBackArc; // backward star: backArcs[firstBackArc, firstBackArc + backArcCount)
  uint32_t backArcCount;
  uint32_t triangles;    // triangles of the node's fragment (sum over its out-arcs' patches)
  // Version 5 (was reserved, zero): the fragment's colour error bound, like `error` a measured,
  // accumulated bound (the max of the predecessors' plus the colour deviation measured against
  // them, mtbuild/color_error.h): the RGBA distance (Euclidean, in 8-bit levels, 0..510) between a
  // point's colour and the colour of the nearest point of the full-resolution surface. 0 for the
  // source and in files without kHasColors; +inf for the sink of a file with kHasColors; monotone
  // towards the sink like `error`. 0 everywhere in files before version 5 (not measured).
  float colorError;
};
static_assert(sizeof(NodeRecord) == 80, "NodeRecord layout");

struct ArcRecord {
  uint32_t from;         // finer node (whose fragment holds the patches)
  uint32_t to;           // coarser node (whose floor the patches are)
  uint32_t firstPatchRef;  // patchRefs[firstPatchRef, firstPatchRef + patchCount)
  uint32_t patchCount;
};
static_assert(sizeof(ArcRecord) == 16, "ArcRecord layout");

struct PatchRecord {
  uint64_t offset;       // absolute file offset of the payload, a multiple of payloadAlignment
  uint32_t size;         // payload bytes
  uint32_t arc;          // the arc that carries it
  uint32_t triangles;
  uint32_t vertices;
  uint64_t checksum;     // XXH64 of the payload bytes, seed 0
};
static_assert(sizeof(PatchRecord) == 32, "PatchRecord layout");

struct Footer {
  uint64_t metaOffset;   // == header.metaOffset (lets a reader find the index from the end)
  uint64_t checksum;     // XXH64(header || bytes[metaOffset, fileSize - kFooterSize))
  uint32_t version;      // kVersion
  uint32_t reserved;     // zero (readers refuse another value: no checksum covers it)
  char magic[8];         // kFooterMagic
};
static_assert(sizeof(Footer) == kFooterSize, "Footer is the last 32 bytes of the file");

// ---- The metadata block (optional) ----
//
// Text facts about the model that no reader needs to decode the geometry: today the coordinate
// reference system of a georeferenced scan ("crs"). The block was added without a version change:
// the two header fields that locate it were reserved and zero before, so every older file reads as
// "no block". Rules:
//  - metadataSize == 0: no block, metadataOffset must be 0, and the index section tiles
//    [metaOffset, footer) exactly as above (every file written without metadata is byte-identical
//    to what writers produced before the block existed).
//  - metadataSize > 0: the block starts right after the patch index (metadataOffset ==
//    patchesOffset + patchCount * sizeof(PatchRecord)) and ends at the footer, so it lies inside
//    the range the footer checksum covers; metadataSize <= kMaxMetadataSize.
//  - The block is a sequence of entries, each uint32 keyLength, key bytes (UTF-8, 1..255 bytes),
//    uint32 valueLength, value bytes (UTF-8); the entries fill the block exactly; keys are unique.
//  - Readers ignore entries whose key they do not know (so later keys need no version change), and
//    refuse a block that breaks the rules above as damage (Corruption).
// Known keys: "crs": the coordinate reference system of the positions, as the user gave it to the
// builder (an EPSG code like "EPSG:32633", a WKT or PROJJSON string); not interpreted here.
constexpr uint32_t kMaxMetadataSize = 1u << 20;
constexpr uint32_t kMaxMetadataKey = 255;
constexpr char kMetadataCrs[] = "crs";

// ---- Patch payloads (the bytes a PatchRecord points at) ----
//
// Every payload starts with this header; the rest depends on the file's codec.
// Its counts agree with the patch's record (triangleCount == PatchRecord::triangles), every vertex
// is used by a triangle (vertexCount <= 3 * triangleCount), and a payload holds at most
// kMaxPayloadTriangles triangles (2^22, 42x the builder's largest patch target): readers refuse
// more before allocating, so a damaged count cannot ask for gigabytes. The payload's size bounds
// nothing: a flat, regular patch codes at hundreds of triangles per byte (Draco: 355 on a
// 256 x 256 grid).
constexpr uint32_t kMaxPayloadTriangles = 1u << 22;
struct PayloadHeader {
  uint32_t vertexCount;
  uint32_t triangleCount;
  uint32_t qMin[3];      // per-axis minimum grid coordinate of the patch; stored q are relative
  uint8_t flags;         // kPayload* below
  uint8_t reserved[3];
};
static_assert(sizeof(PayloadHeader) == 24, "PayloadHeader layout");

constexpr uint8_t kPayloadNormals = 1u << 0;  // octahedral normals present
constexpr uint8_t kPayloadColors = 1u << 1;   // RGBA8 colours present
constexpr uint8_t kPayloadWide = 1u << 2;     // meshopt: position residuals need 32 bits (else 16)
constexpr uint8_t kPayloadStrip = 1u << 3;    // meshopt: indices are a strip (restart ~0u)
constexpr uint8_t kPayloadRangePositions = 1u << 4;  // meshopt: positions range-coded after the zstd frame (v2)
constexpr uint8_t kPayloadRangeIndices = 1u << 5;      // meshopt: index code range-coded ahead of the positions (v3)
constexpr uint8_t kPayloadPositionContexts = 1u << 6;  // meshopt: positions with the version-3 model (v3)
constexpr uint8_t kPayloadConnectivity = 1u << 7;      // meshopt: triangles by the version-4 connectivity code (v4)

// Codec::Meshopt, after the PayloadHeader:
//   uint32 rawSize, uint32 zstdSize, then zstdSize bytes (one zstd frame) that decompress to
//   rawSize bytes (then, with kPayloadRangePositions, the position stream up to the payload's end):
//     uint32 indexBytes, uint32 indexCount, uint32 attributeBytes,
//     indexBytes: meshopt_encodeIndexBuffer of the triangle list (indexCount = 3 * triangles),
//         or with kPayloadStrip meshopt_encodeIndexSequence of a strip with restart index ~0u
//         (decoded with meshopt_unstripify);
//     attributeBytes: meshopt_encodeVertexBuffer of vertexCount records of attributeStride(flags)
//         bytes: uint8[2] octahedral normal if kPayloadNormals, then uint8[4] RGBA if
//         kPayloadColors, zero-padded (absent, 0 bytes, when neither flag is set);
//     positions, without kPayloadRangePositions (version 1 files): 3 axes x P byte planes x
//         vertexCount bytes (P = 4 with kPayloadWide, else 2): plane b of axis x holds byte b of
//         zigzag(r) for every vertex, r = qRel - prediction.
//   With kPayloadRangePositions (version 2 and 3 writers) the frame holds no positions; after
//   it comes one range-coded stream (LZMA's binary range coder: 32-bit low/range, the encoder's
//   always-zero first byte not stored, so the decoder starts with code = the first 4 bytes).
//   Version 2 (kPayloadPositionContexts clear): probabilities of 11 bits starting at 1024 and
//   adapted by 1/32; zigzag(r) for vertex 0..n-1, axis x, y, z: the bit length k of z (0..32) as a
//   6-bit binary tree (MSB first, node index m from 1, probability length[axis][m]), then for
//   k >= 2 the k-1 bits below the leading one, MSB first, probability mantissa[axis][k][bit].
//   Version 3 bits ("counted"): probability p of a 0 in 12 bits starting at 2048 with a count n
//   starting at 0; bound = (range >> 12) * p; after coding bit b, rate = 65536 / (min(n, 30) + 2)
//   (integer division), p += ((4096 - p) * rate) >> 16 if b = 0 else p -= (p * rate) >> 16, then p is
//   clamped to [31, 4065] and n incremented up to 30.
//   kPayloadPositionContexts (version 3): as version 2 but with counted bits, and length
//   probabilities length[kind][axis][m], kind = the prediction case below (0 parallelogram,
//   1 midpoint, 2 one vertex known, 3 none known); mantissa[axis][k][bit].
//   kPayloadRangeIndices (version 3, needs kPayloadRangePositions and kPayloadPositionContexts,
//   never kPayloadStrip): the frame holds only uint32 indexBytes, indexCount, attributeBytes and the
//   attribute code (rawSize = 12 + attributeBytes); zSize 0 means those rawSize bytes are stored as
//   they are instead of a zstd frame. The range-coded stream starts with the meshopt index code
//   (indexBytes >= 1 + triangles + 16 bytes: header byte, one code byte per triangle, data bytes,
//   16-byte table), counted bits, fresh per payload:
//     one bit, probability `standard`: 0 = header 0xe1 and the version-1 table 00 76 87 56 67 78
//       a9 86 65 89 68 98 01 69 00 00; 1 = header then the 16 table bytes follow, each an 8-bit
//       tree over data[0];
//     per triangle t, code byte c = (h << 4) | l: h as a 4-bit tree over hi[ctx], then l as a 4-bit
//       tree over lo[(h << 1) | (ctx & 1)]; ctx = (h' << 1) | (l' == 0) of the previous triangle's
//       code (0 for the first);
//     each data byte as an 8-bit tree over data[top bit of the previous data byte (0 first)];
//   then the positions (kPayloadPositionContexts) in the same stream.
//   "An n-bit tree over P" (above and below): the n bits of a value, most significant first, bit i
//   coded with probability P[m], m starting at 1 and becoming (m << 1) | bit after each bit; the
//   value is m - 2^n at the end. P has 2^n entries (entry 0 unused).
//   kPayloadConnectivity (version 4, needs kPayloadRangePositions and kPayloadPositionContexts,
//   never kPayloadStrip or kPayloadRangeIndices): the frame is as with kPayloadRangeIndices
//   (zSize 0 = stored) with indexBytes = 0 and indexCount = 3 * triangles; the range-coded stream
//   starts with the connectivity code (counted bits, fresh per payload), then the positions
//   (kPayloadPositionContexts) in the same stream, predicted along the triangles as decoded here.
//   Decoder state: next = 0 (the next new vertex); an edge FIFO of 16 directed edges (e0, e1), all
//   empty, pushed at position `offset` (starting at 0, then offset = (offset + 1) & 15), slot i
//   being the entry at (offset - 1 - i) & 15 (slot 0 = the most recent push); per vertex two lists
//   of open half-edges, out[u] (the v of every open u->v) and in[v] (the u), most recently added
//   first; ctx = 15. Probabilities: slot0[16], slot1[16], slotRest[16][16], third[12][4],
//   fresh[3], length[64], mantissa[33][32]. Per triangle t = 0 .. triangles - 1:
//     edge slot s: bit over slot0[ctx]: 0 -> s = 0; else bit over slot1[ctx]: 0 -> s = 1; else
//       s = 2 + a 4-bit tree over slotRest[ctx]; s = 16 means "no edge", s = 17 is an error.
//     s <= 15 (attached): (a, b) = slot s's edge (an error if the slot is empty); then the symbol
//       y as a 2-bit tree over third[min(s, 2) * 4 + (ctx & 3)]:
//         y = 0: c = next, next += 1;
//         y = 1: c = the first entry of out[a] (an error if empty);
//         y = 2: c = the first entry of in[b] (an error if empty);
//         y = 3: c = an explicit vertex (below).
//     s = 16 (free): y = 3; for corner k = 0, 1, 2: a bit over fresh[k]: 0 -> v_k = next,
//       next += 1; 1 -> v_k = an explicit vertex; (a, b, c) = (v_0, v_1, v_2).
//     An explicit vertex: its distance d = next - 1 - v (next as it is at that point) as the bit
//       length k of d (0..32; above 32 an error) by a 6-bit tree over length, then for k >= 2 the
//       k-1 bits below the leading one, most significant first, bit i (i = k-2 .. 0) over
//       mantissa[k][i]; d = k for k <= 1. d >= next is an error.
//     next > vertexCount after the triangle is an error. The triangle is (a, b, c) in this corner
//       order. Then its directed edges a->b, b->c, c->a are added in that order to the open
//       half-edges: if out[v] holds u (the twin v->u is open), adding u->v removes the first entry
//       equal to u from out[v] and the first entry equal to v from in[u]; else it puts v at the
//       front of out[u] and u at the front of in[v]. Then the FIFO: for s = 16 push (b, a); in both cases push (c, b), then (a, c).
//       ctx = (s = 16 ? 3 : min(s, 2)) * 4 + y.
//   After the last triangle next must equal vertexCount (every vertex referenced). Vertices are
//   thus numbered by first use, and the encoder attaches a triangle to the lowest FIFO slot whose
//   edge (e0, e1) equals (v0, v1), (v1, v2) or (v2, v0) of the triangle (tried in that order per
//   slot), and prefers y = 0, then 1, then 2 (the decoder does not depend on these choices).
//   Prediction (parallelogram rule): walk the decoded triangles in order; at the first use of a
//   vertex v in triangle (v, a, b) (rotated so v comes first):
//     a, b known and a visited triangle has directed edge (b, a) or else (a, b) with third vertex
//       c: a + b - c;   a, b known otherwise: (a + b) >> 1 (arithmetic shift);
//     only one of a, b known: that one;   none: the previously visited vertex, or 0 for the first;
//   per component in int64, clamped to [0, 2^31 - 1]. After a triangle is processed its three
//   directed edges (a,b)->c, (b,c)->a, (c,a)->b are recorded (a later record replaces an earlier).
//   zigzag(r) = (r << 1) ^ (r >> 63), kept in 32 bits.
// Codec::Draco, after the PayloadHeader:
//   a Draco mesh buffer (edgebreaker): POSITION as 3 x INT32 (qRel, lossless, no quantization),
//   and when flagged GENERIC 2 x UINT8 (octahedral normal) and COLOR 4 x UINT8. Draco may split
//   non-manifold vertices, so a decoder may see more vertices than vertexCount.
//
// qRel = q - qMin per axis. Octahedral normals (8 bits per component): n = (x, y, z) / (|x| + |y|
// + |z|); if z < 0 the xy pair is folded: (x, y) <- ((1 - |y|) * sign(x), (1 - |x|) * sign(y));
// each of x, y is stored as round((v * 0.5 + 0.5) * 255). Decoding reverses this, renormalizes.
inline uint32_t attributeStride(uint8_t payloadFlags) {
  uint32_t s = 0;
  if (payloadFlags & kPayloadNormals) s += 2;
  if (payloadFlags & kPayloadColors) s += 4;
  return (s + 3) & ~3u;
}

}  // namespace mt::format
