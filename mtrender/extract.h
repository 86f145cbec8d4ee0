// mtrender/extract.h: ExtractRender's cut update (BMT section 5, figure 9).
//
// The cut is a node set S (mt_format.h "DAG orientation"): refining removes a node from S, so
// its fragment (out-arcs) is replaced by the finer patches on its in-arcs; coarsening adds one.
// Feasible moves on the current cut sit in two heaps keyed by screen-space error (the node's
// object-space error projected through its bounding sphere, BMT 5.1):
//   RefinementHeap: nodes of S with no successor in S (their whole fragment is on screen), the
//                   largest error first;
//   CoarseningHeap: nodes outside S whose predecessors are all in S, the smallest error first.
// The feasible moves are kept as two indexed candidate sets, updated by every move (the paper's
// heaps persist across frames; only their keys depend on the view). Each frame the heaps are
// re-keyed from those sets for the new view: O(front of the cut), never a walk of the whole DAG,
// and inside the update's deadline. Then Extract + Apply (interleaved, so the deadline can stop it anywhere and the cut stays
// conforming): coarsen while over the render budget, refine the worst node while its error is
// above the tolerance and CheckBudget allows (trading the cheapest coarsening for it when the
// budget is spent), coarsen what is far below the tolerance. A move is applied only when all
// its patches are resident (pinned atomically in the cache): a move waiting for the disk is a
// miss, requested from the PatchServer, and the cut simply stays where it is.
// Then Prefetch in the leftover time before the deadline: patches of the moves at the top of both
// heaps, their children, and the refinements wanted in the frustum enlarged to contain the frusta
// of the next 10 frames (Derzapf et al. 4.3), two levels deep.
// CheckBudget: render budget = triangles per frame from a time model fitted online to measured
// frame times; load budget = patches per frame, from the PatchServer's measured load time.
// A global LOD scale multiplies the tolerance while the cache cannot hold what the cut needs, and
// relaxes gradually (Derzapf et al. 4.1).
#pragma once

#include <chrono>
#include <cstdint>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "mtrender/camera.h"
#include "mtrender/patch_cache.h"
#include "mtrender/patch_server.h"
#include "mtrender/scene.h"

namespace mt::render {

// frame ms ~= a + b * triangles, fitted online by least squares over the last 45 frames, so the
// budget follows the machine (llvmpipe shares the CPU with everything else). The slope is only
// re-estimated when the window's triangle counts vary enough to tell it from the fixed cost
// (with a steady cut the fit is ill-posed and would trade one for the other); samples far above
// the current prediction (a stall caused by something else) are clipped.
class TimeModel {
 public:
  void add(double triangles, double ms);
  double predictMs(double triangles) const { return a_ + b_ * triangles; }
  // Triangles that fit in `ms` (0 when even an empty frame does not).
  double trianglesFor(double ms) const;
  double a() const { return a_; }
  double b() const { return b_; }

 private:
  double a_ = 2.0, b_ = 1e-4;  // prior: 2 ms fixed, 10 M triangles/s
  std::vector<std::pair<double, double>> window_;  // (million triangles, ms), ring buffer
  size_t next_ = 0;
};

struct ExtractOptions {
  double pixelTolerance = 1.0;   // target screen-space error (pixels)
  double budgetMs = 50;          // frame-time budget
  uint64_t fixedTriangles = 0;   // > 0: a fixed render budget instead of the time model
  double extractMs = 0;          // deadline for the cut update; 0: min(2, budgetMs / 20)
  uint32_t loadBudget = 0;       // patches requested per frame; 0: from the measured load time
  bool prefetch = true;
  bool cull = true;              // frustum + normal-cone culling (per node for errors, per arc for drawing)
  double memoryFraction = 0.6;   // the cut may pin at most this share of the cache's place holders
                                 // (all of them when the cache holds every patch of the scene)
  // Internal switches, so a test can show each policy matters (all on in production):
  bool deadline = true;          // the extract deadline stops the update (off: it runs to the end)
  bool starvationOrder = true;   // loads: patches requested in the most consecutive frames first
  bool lodScalePolicy = true;    // the global LOD scale grows while the cache is full
  bool occlusion = true;         // nodes the last frame's depth hides get screen error 0 (setOccluded)
  bool patchCones = true;        // the finest patches are culled by their own normal cones (engine.cpp)
};

// One wanted, non-resident patch, as the load order sees it.
struct RequestCandidate {
  uint32_t id;
  Urgency urgency;
  uint32_t consecutive;  // frames in a row it has been requested, this one included
  uint32_t rank;         // order of discovery this frame (the heaps' order: largest error first)
};
// The load order (Derzapf et al. 4.1): urgent first; then, with byConsecutive, the patches
// requested in the most consecutive frames (so a region the heaps keep ranking low is served
// after a few frames: no LOD starvation); then the heaps' order. At most `budget` requests.
std::vector<LoadRequest> orderRequests(std::vector<RequestCandidate> candidates, uint32_t budget, bool byConsecutive);

struct FrameStats {
  double extractMs = 0;
  double extractCpuMs = 0;       // the update's thread CPU time (its own cost, without waits for a core)
  uint64_t triangles = 0;        // in the cut
  uint32_t patches = 0;          // in the cut
  uint32_t drawnPatches = 0;     // after culling
  uint64_t drawnTriangles = 0;
  uint32_t misses = 0;           // patches wanted for a move but not resident
  uint32_t newMisses = 0;        // ... of which were not a miss the frame before: each wait counted once
  uint32_t requests = 0, prefetches = 0;
  uint32_t refinements = 0, coarsenings = 0;
  double maxScreenError = 0;     // pixels, over the visible part of the cut
  uint64_t budgetTriangles = 0;
  double lodScale = 1;
  bool memoryFull = false;
  bool interrupted = false;      // the deadline stopped the update
  uint32_t nodesKeyed = 0;       // screen errors computed (heaps re-keyed, prefetch): O(front), not O(DAG)
  uint32_t occludedNodes = 0;    // front nodes hidden by the last frame's depth (error 0)
  double modelA = 0, modelB = 0; // time model: ms fixed, ms per million triangles
};

class ExtractRender {
 public:
  // cache/server null: everything counts as resident (the baseline mode loads synchronously).
  ExtractRender(const Scene& scene, PatchCache* cache, PatchServer* server, ExtractOptions options);

  // Coarsest cut; with a cache, loads its patches first (blocking, up to timeoutMs).
  void start(double timeoutMs);

  // One frame's cut update for `view`; `predicted` is the view extrapolated 10 frames ahead.
  FrameStats update(uint64_t frame, const View& view, const View& predicted);
  // The same, prefetching for the frustum enlarged to contain all of `ahead` (the views of the
  // next frames, extrapolated; Derzapf et al. 4.3).
  FrameStats update(uint64_t frame, const View& view, const std::vector<View>& ahead);
  // Per node: 1 = hidden behind nearer geometry in the last frame's depth (occlusion culling,
  // Derzapf et al. 4.2: a node occluded gets no detail and its patches are not loaded). Null: none.
  // The vector must outlive the updates that use it.
  void setOccluded(const std::vector<uint8_t>* occluded) { occluded_ = occluded; }
  // The feasible moves of the cut (kept up to date by every move): refinements, coarsenings.
  const std::vector<uint32_t>& refineCandidates() const { return refineSet_; }
  const std::vector<uint32_t>& coarsenCandidates() const { return coarsenSet_; }
  double lodScale() const { return lodScale_; }
  // Place holders the cut may pin (memoryFraction of the cache's, or all when every patch fits).
  double pinLimit() const;
  // For a frame that leaves the cut as it is (it draws part of a still image, engine.h): advances
  // the render budget and asks the PatchServer for what the refinements of the cut beyond it
  // would need, as if they were applied (the best first, two levels deep, within the scaled
  // budget; up to twice it at prefetch priority, for the trades the next update makes), so loads
  // go on while the image is drawn. Returns the requests' figures.
  FrameStats requestAhead(uint64_t frame, const View& view);
  // Feeds the time model with the last frame's measured time.
  void frameDone(uint64_t drawnTriangles, double frameMs);
  void setFrozen(bool f) { frozen_ = f; }
  // The cut may hold `scale` frames' worth of the render budget (progressive refinement of a still
  // view draws it over that many frames, engine.h); 1 = one frame's worth, the default.
  void setBudgetScale(double scale) { budgetScale_ = scale; }
  // Milliseconds the next frame spends besides the update and the drawing (the occlusion tests of
  // engine.h): its render budget gives up that many milliseconds' worth of triangles.
  void setFrameOverheadMs(double ms) { frameOverheadMs_ = ms; }
  // The render budget of one frame (triangles) at the last update, before the scale above.
  double frameBudget() const { return frameBudget_; }
  uint32_t cutPatchCount() const { return cutPatchCount_; }
  bool frozen() const { return frozen_; }
  ExtractOptions& options() { return options_; }
  const TimeModel& timeModel() const { return time_; }

  // The arcs of the cut (unordered) and whether the arc is visible in `view` (culling).
  const std::vector<uint32_t>& cutArcs() const { return cutArcs_; }
  bool arcVisible(uint32_t arc, const View& view) const;
  const std::vector<uint8_t>& inSet() const { return inS_; }
  double screenError(uint32_t node, const View& view) const;
  // Largest screen error of the node over several views (the enlarged frustum of prefetching).
  double screenErrorAhead(uint32_t node, const std::vector<View>& views) const;
  uint64_t cutTriangles() const { return triangles_; }
  // Triangles of the cut that pass culling for the last update's view: what the render budget
  // constrains (the time model is fitted to drawn triangles; culled ones cost nothing).
  uint64_t visibleTriangles() const { return visibleTriangles_; }

 private:
  bool isRefineCandidate(uint32_t n) const;
  bool isCoarsenCandidate(uint32_t n) const;
  void collectIn(uint32_t n, std::vector<uint32_t>& out) const;   // patches on n's in-arcs
  void collectOut(uint32_t n, std::vector<uint32_t>& out) const;  // patches on n's out-arcs
  bool patchesBad(const std::vector<uint32_t>& ids) const;
  // Applies the move if its patches are resident (pins them); false otherwise.
  bool tryRefine(uint32_t n);
  bool tryCoarsen(uint32_t n);
  void addCutArc(uint32_t a);
  void removeCutArc(uint32_t a);
  void want(const std::vector<uint32_t>& ids, Urgency u);
  // The render budget for this frame (triangles, scaled by budgetScale_); sets frameBudget_.
  double nextBudget(double extractMs);
  // Sends wanted_ to the PatchServer (urgent first, then by consecutive frames), within the load budget.
  void submitRequests(uint64_t frame, FrameStats& st);
  // The steps of update(), on the state of one update (extract.cpp).
  struct Pass;
  void fillHeaps(Pass& p) const;
  void pushAround(Pass& p, uint32_t n) const;
  void popStaleCoarse(Pass& p) const;
  void coarsenTop(Pass& p, Urgency u);
  void coarsenOverBudget(Pass& p);
  bool probeAllowed(double after, double budget) const;
  void refineWithinBudget(Pass& p);
  void refineOrRequest(Pass& p, uint32_t node, double err, int64_t dv);
  void coarsenFarBelow(Pass& p);
  void prefetch(Pass& p, const std::vector<View>& ahead);
  void syncCandidate(uint32_t n);  // n's membership of the candidate sets after a move
  void syncAround(uint32_t n);     // n and the nodes a move on n may have made (in)feasible

  const Scene& scene_;
  PatchCache* cache_;
  PatchServer* server_;
  ExtractOptions options_;
  TimeModel time_;
  std::vector<uint8_t> inS_, badNode_;
  std::vector<uint32_t> succIn_, predOut_;   // per node: out-arcs into S; in-arcs from outside S
  std::vector<uint32_t> cutArcs_, cutPos_;   // indexed set of cut arcs
  uint64_t triangles_ = 0, visibleTriangles_ = 0;
  // Visible triangles a move adds (refine: in-arcs minus out-arcs; coarsen: the reverse).
  int64_t visibleDelta(uint32_t n, bool refine, const View& view) const;
  uint32_t cutPatchCount_ = 0;
  double lodScale_ = 1;
  double budgetScale_ = 1, frameBudget_ = 0, frameOverheadMs_ = 0;
  bool frozen_ = false;
  bool lastMemoryFull_ = false;
  uint64_t frame_ = 0;
  std::vector<uint32_t> scratch_, scratch2_;
  struct Want {
    Urgency urgency;
    uint32_t rank;
  };
  std::unordered_map<uint32_t, Want> wanted_;           // this frame
  std::vector<uint32_t> refineSet_, coarsenSet_, refinePos_, coarsenPos_;  // indexed candidate sets
  std::vector<uint32_t> stamp_;                          // per node: last requestAhead/prefetch visit
  uint32_t stampNow_ = 0;
  mutable uint32_t keyed_ = 0;  // screen errors computed since the update began
  const std::vector<uint8_t>* occluded_ = nullptr;
  std::unordered_map<uint32_t, uint32_t> consecutive_;  // frames in a row a patch was requested
  std::unordered_set<uint32_t> missed_;                 // the last frame's misses
  std::vector<uint32_t> touched_;
  double smoothBudget_ = 0;
  uint32_t slackFrames_ = 0;  // frames since the last probe
  double frameMsAvg_ = 0;     // exponential average of measured frame times
  double lastFrameMs_ = 0, lastDrawn_ = 0;
};

}  // namespace mt::render
