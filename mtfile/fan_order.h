// A triangle order for the patch codec, in linear time: fans around vertices, in rotational order,
// each next fan centred at the open end of the last one.
//
// meshopt_encodeIndexBuffer codes a triangle in a few bits when it shares an edge with one of the
// last few coded triangles (an edge FIFO) and its third vertex is the next new vertex or a recent
// one (a vertex FIFO). meshopt_optimizeVertexCacheStrip orders any mesh that way, but it re-scores
// every cached vertex's triangles for each triangle it emits (~1,200 instructions per triangle):
// measured at ~8% of the level loop's instructions, for the simplified patches whose own order is
// not coherent any more. This is the vertex-centred walk of Sander, Nehab and Barczak, "Fast
// triangle reordering for vertex locality and reduced overdraw" (SIGGRAPH 2007, "Tipsify"),
// changed for the codec rather than for a vertex cache:
//   * the triangles around the current vertex are emitted in rotational order, so each shares an
//     edge with the one before it (the edge FIFO hits);
//   * the next fan is centred at the last triangle's far vertex (where the fan ended), so its
//     first triangle shares an edge with the last one emitted; when that vertex has nothing left,
//     the fan's other end, then the most recent vertex with triangles left, then Tipsify's
//     dead-end stack, then the next triangle in input order.
// Measured on the simplified patches of a 2M-triangle scan (raw index code, bytes per triangle):
// input order 1.91, this order 1.20, meshopt_optimizeVertexCacheStrip 1.16, at 0.29x its time.
// Deterministic; keeps every triangle's winding (corners are rotated, never reflected).
#pragma once

#include <cstddef>
#include <cstdint>

namespace mt {

// destination: indexCount indices, the same triangles reordered. indices: indexCount (a multiple
// of 3), each < vertexCount.
void fanOrderTriangles(uint32_t* destination, const uint32_t* indices, size_t indexCount, size_t vertexCount);

}  // namespace mt
