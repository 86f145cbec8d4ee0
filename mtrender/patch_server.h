// mtrender/patch_server.h: the PatchServer thread (BMT section 5): loads and decodes the patches
// ExtractRender asks for into the PatchCache, so the frame never waits for the disk.
//
// Each frame the render thread hands over its whole request list, already in priority order
// (urgent first, then the patches requested in the most consecutive frames, so no region starves
// - Derzapf et al., "Parallel out-of-core progressive meshes" section 4.1 - then by screen error;
// prefetches last, 4.3). The list replaces the previous one: requests nobody wants any more are
// dropped instead of piling up. A damaged patch (bad checksum or payload) is reported once on
// stderr, marked bad in the cache and never asked for again.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "mtrender/patch_cache.h"
#include "mtrender/scene.h"

namespace mt::render {

struct LoadRequest {
  uint32_t id = 0;
  Urgency urgency = Urgency::Prefetch;
};

// Decodes patch `id` of the scene into `out` (RenderPatch layout: vertices, then indices), the
// positions relative to Scene::patchOrigin(id), computed in double from the exact grid
// coordinates (camera-relative drawing: a georeferenced model keeps its centimetres); computes
// area-weighted normals when the file stores none, and the patch's bound when `bound` is given.
// Returns {vertexCount, indexCount}. Throws mt::Error (damaged payload, or larger than `capacity`).
std::pair<uint32_t, uint32_t> decodeInto(const Scene& scene, uint32_t id, const DecodedPatch& patch, uint8_t* out,
                                         uint64_t capacity, PatchBound* bound = nullptr);

// A textured patch (mt_format.h "Textures"): writes its corner coordinates (unorm16) and its atlas
// decoded to RGB8 (row by row, straight into the place holder, bottom row first) after the
// geometry decodeInto wrote for `vertexCount` vertices and `triangleCount` triangles (the layout
// of patch_cache.h). Returns the atlas size. Throws mt::Error (damaged image, or larger than
// `capacity`).
std::pair<uint16_t, uint16_t> decodeTextureInto(const TexturePayload& texture, uint32_t vertexCount, uint32_t triangleCount,
                                                uint8_t* out, uint64_t capacity);

class PatchServer {
 public:
  struct Options {
    double readDelayMs = 0;  // test hook: latency added to every read (a slow disk)
    bool quiet = false;      // no warnings on stderr (still counted)
  };
  PatchServer(const Scene& scene, PatchCache& cache, Options options);
  ~PatchServer();

  // Replaces the pending requests (already in priority order). `frame` is the render frame.
  void submit(std::vector<LoadRequest> requests, uint64_t frame);
  // Blocks until the queue is empty and nothing is loading, or the timeout passes.
  bool waitIdle(double timeoutMs);

  uint64_t loads() const { return loads_.load(); }
  uint64_t bytesRead() const { return bytesRead_.load(); }
  uint64_t trianglesLoaded() const { return trianglesLoaded_.load(); }
  uint64_t badPatches() const { return bad_.load(); }
  double meanLoadMs() const;  // measured read + decode time per patch (0 before the first)
  std::vector<std::string> warnings() const;

 private:
  void run();
  const Scene& scene_;
  PatchCache& cache_;
  Options options_;
  mutable std::mutex mu_;
  std::condition_variable cv_, idleCv_;
  std::deque<LoadRequest> queue_;
  uint64_t frame_ = 0;
  bool busy_ = false, stop_ = false;
  std::atomic<uint64_t> loads_{0}, bytesRead_{0}, bad_{0}, trianglesLoaded_{0};
  double loadMsSum_ = 0;
  std::vector<std::string> warnings_;
  std::thread thread_;
};

}  // namespace mt::render
