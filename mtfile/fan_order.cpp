// Fan order for the patch codec (see fan_order.h).
#include "mtfile/fan_order.h"

#include <cassert>
#include <utility>
#include <vector>

namespace mt {

void fanOrderTriangles(uint32_t* destination, const uint32_t* indices, size_t indexCount, size_t vertexCount) {
  assert(indexCount % 3 == 0);
  const size_t triangleCount = indexCount / 3;
  if (triangleCount == 0) return;
  // Vertex -> the triangles that use it (CSR by counting sort), and how many are not emitted yet.
  std::vector<uint32_t> start(vertexCount + 1, 0), uses(indexCount), live(vertexCount);
  for (size_t i = 0; i < indexCount; ++i) {
    assert(indices[i] < vertexCount);
    ++start[indices[i] + 1];
  }
  for (size_t v = 0; v < vertexCount; ++v) {
    live[v] = start[v + 1];
    start[v + 1] += start[v];
  }
  {
    std::vector<uint32_t> fill(start.begin(), start.end() - 1);
    for (size_t i = 0; i < indexCount; ++i) uses[fill[indices[i]]++] = uint32_t(i / 3);
  }
  std::vector<uint8_t> emitted(triangleCount, 0);
  std::vector<uint32_t> deadEnd, fanTris;
  size_t written = 0, cursor = 0;
  uint32_t fan = indices[0];
  // The corners after and before `centre` in t's winding.
  auto nextOf = [&](uint32_t t, uint32_t centre) {
    const uint32_t* f = indices + 3 * size_t(t);
    return f[0] == centre ? f[1] : f[1] == centre ? f[2] : f[0];
  };
  auto prevOf = [&](uint32_t t, uint32_t centre) {
    const uint32_t* f = indices + 3 * size_t(t);
    return f[0] == centre ? f[2] : f[1] == centre ? f[0] : f[1];
  };
  while (written < indexCount) {
    fanTris.clear();
    // (A degenerate triangle lists `fan` twice: its entries are adjacent, take it once.)
    for (uint32_t i = start[fan]; i < start[fan + 1]; ++i)
      if (!emitted[uses[i]] && (fanTris.empty() || fanTris.back() != uses[i])) fanTris.push_back(uses[i]);
    const size_t k = fanTris.size();
    // Rotational order: start where the fan is open (no triangle before it), then each next
    // triangle is the one whose edge (fan, prev) is the last one's edge (fan, next).
    for (size_t a = 0; a < k; ++a) {
      bool hasPredecessor = false;
      for (size_t b = 0; b < k && !hasPredecessor; ++b)
        hasPredecessor = b != a && nextOf(fanTris[b], fan) == prevOf(fanTris[a], fan);
      if (!hasPredecessor) {
        std::swap(fanTris[0], fanTris[a]);
        break;
      }
    }
    for (size_t a = 1; a < k; ++a) {
      const uint32_t joint = nextOf(fanTris[a - 1], fan);
      for (size_t b = a; b < k; ++b)
        if (prevOf(fanTris[b], fan) == joint) {
          std::swap(fanTris[a], fanTris[b]);
          break;
        }
    }
    for (uint32_t t : fanTris) {
      emitted[t] = 1;
      for (int c = 0; c < 3; ++c) {
        const uint32_t v = indices[3 * size_t(t) + c];
        destination[written++] = v;
        --live[v];
        deadEnd.push_back(v);
      }
    }
    // The next fan: where this one ended, else its other end, else the most recent vertex with
    // triangles left (the dead-end stack), else the next triangle in input order.
    uint32_t next = ~0u;
    if (k > 0) {
      const uint32_t end = nextOf(fanTris.back(), fan), other = prevOf(fanTris.front(), fan);
      if (live[end]) next = end;
      else if (live[other]) next = other;
    }
    if (next == ~0u) {
      while (!deadEnd.empty() && !live[deadEnd.back()]) deadEnd.pop_back();
      if (!deadEnd.empty()) {
        next = deadEnd.back();
      } else {
        while (cursor < triangleCount && emitted[cursor]) ++cursor;
        if (cursor == triangleCount) break;
        next = indices[3 * cursor];
      }
    }
    fan = next;
  }
  assert(written == indexCount);
}

}  // namespace mt
