#include "mtrender/extract.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <queue>

#include <time.h>

namespace mt::render {

using Clock = std::chrono::steady_clock;

namespace {
// The calling thread's CPU time (ms): the update's own cost, without the time the thread waited
// for a core (on a loaded machine the wall time of a 0.1 ms update reaches 10 ms).
double threadCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) * 1e3 + double(ts.tv_nsec) * 1e-6;
}
}  // namespace

// ---- TimeModel: windowed least squares on (million triangles, ms) ----

void TimeModel::add(double triangles, double ms) {
  const double t = triangles * 1e-6;
  const double predicted = a_ + b_ * 1e6 * t;
  ms = std::min(ms, 2.0 * predicted + 5.0);  // a stall from elsewhere must not wreck the fit
  const size_t kWindow = 45;
  if (window_.size() < kWindow) window_.push_back({t, ms});
  else window_[next_] = {t, ms};
  next_ = (next_ + 1) % kWindow;
  const double n = double(window_.size());
  double mt = 0, mm = 0;
  for (const auto& [x, y] : window_) mt += x, mm += y;
  mt /= n, mm /= n;
  double vt = 0, cov = 0;
  for (const auto& [x, y] : window_) vt += (x - mt) * (x - mt), cov += (x - mt) * (y - mm);
  vt /= n, cov /= n;
  double bm = b_ * 1e6;  // ms per million triangles
  if (window_.size() >= 8 && std::sqrt(vt) > 0.15 * mt && vt > 0)
    bm = std::clamp(cov / vt, 20.0, 1e5);  // between 50 M and 10 k triangles/s (noise can fit ~0)
  b_ = bm * 1e-6;
  a_ = std::max(0.0, mm - bm * mt);
}

double TimeModel::trianglesFor(double ms) const { return std::max(0.0, (ms - a_) / b_); }

// ---- ExtractRender ----

ExtractRender::ExtractRender(const Scene& scene, PatchCache* cache, PatchServer* server, ExtractOptions options)
    : scene_(scene), cache_(cache), server_(server), options_(options) {}

void ExtractRender::collectIn(uint32_t n, std::vector<uint32_t>& out) const {
  out.clear();
  const SceneNode& s = scene_.nodes()[n];
  for (uint32_t k = 0; k < s.inArcCount; ++k) {
    const SceneArc& a = scene_.arcs()[scene_.inArcs()[s.firstInArc + k]];
    for (uint32_t p = 0; p < a.patchCount; ++p) out.push_back(scene_.arcPatches()[a.firstPatch + p]);
  }
}

void ExtractRender::collectOut(uint32_t n, std::vector<uint32_t>& out) const {
  out.clear();
  const SceneNode& s = scene_.nodes()[n];
  for (uint32_t k = 0; k < s.arcCount; ++k) {
    const SceneArc& a = scene_.arcs()[s.firstArc + k];
    for (uint32_t p = 0; p < a.patchCount; ++p) out.push_back(scene_.arcPatches()[a.firstPatch + p]);
  }
}

bool ExtractRender::isRefineCandidate(uint32_t n) const {
  const SceneNode& s = scene_.nodes()[n];
  return inS_[n] && !s.source && succIn_[n] == 0;
}

bool ExtractRender::isCoarsenCandidate(uint32_t n) const {
  const SceneNode& s = scene_.nodes()[n];
  return !inS_[n] && !s.sink && predOut_[n] == 0;
}

void ExtractRender::syncCandidate(uint32_t n) {
  auto sync = [this](std::vector<uint32_t>& set, std::vector<uint32_t>& pos, uint32_t n, bool member) {
    if (member == (pos[n] != UINT32_MAX)) return;
    if (member) {
      pos[n] = uint32_t(set.size());
      set.push_back(n);
      key_[n] = std::numeric_limits<double>::quiet_NaN();  // a new candidate: keyed at its first heap fill
    } else {
      const uint32_t last = set.back();
      set[pos[n]] = last;
      pos[last] = pos[n];
      set.pop_back();
      pos[n] = UINT32_MAX;
    }
  };
  sync(refineSet_, refinePos_, n, isRefineCandidate(n));
  sync(coarsenSet_, coarsenPos_, n, isCoarsenCandidate(n));
}

double ExtractRender::pinLimit() const {
  if (!cache_) return 1e18;
  const double slots = cache_->stats().slots;
  // A cache that holds every patch of the scene needs no room kept for prefetching.
  if (slots >= double(scene_.patchCount())) return slots;
  return options_.memoryFraction * slots;
}

void ExtractRender::addCutArc(uint32_t a) {
  cutPos_[a] = uint32_t(cutArcs_.size());
  cutArcs_.push_back(a);
}

void ExtractRender::removeCutArc(uint32_t a) {
  uint32_t pos = cutPos_[a];
  uint32_t last = cutArcs_.back();
  cutArcs_[pos] = last;
  cutPos_[last] = pos;
  cutArcs_.pop_back();
  cutPos_[a] = UINT32_MAX;
}

bool ExtractRender::patchesBad(const std::vector<uint32_t>& ids) const {
  if (!cache_) return false;
  for (uint32_t id : ids)
    if (cache_->isBad(id)) return true;
  return false;
}

void ExtractRender::start(double timeoutMs) {
  const auto& nodes = scene_.nodes();
  const size_t n = nodes.size();
  inS_.assign(n, 0);
  badNode_.assign(n, 0);
  succIn_.assign(n, 0);
  predOut_.assign(n, 0);
  cutPos_.assign(scene_.arcs().size(), UINT32_MAX);
  cutArcs_.clear();
  triangles_ = 0;
  cutPatchCount_ = 0;
  refineSet_.clear();
  coarsenSet_.clear();
  refinePos_.assign(n, UINT32_MAX);
  coarsenPos_.assign(n, UINT32_MAX);
  key_.assign(n, std::numeric_limits<double>::quiet_NaN());
  rekeyCursor_ = 0;
  stamp_.assign(n, 0);
  stampNow_ = 0;
  // The coarsest cut: every node but the sinks.
  for (size_t i = 0; i < n; ++i) inS_[i] = !nodes[i].sink;
  for (uint32_t a = 0; a < scene_.arcs().size(); ++a) {
    const SceneArc& arc = scene_.arcs()[a];
    if (inS_[arc.to]) ++succIn_[arc.from];
    if (!inS_[arc.from]) ++predOut_[arc.to];
    if (inS_[arc.from] && !inS_[arc.to]) {
      addCutArc(a);
      triangles_ += arc.triangles;
      cutPatchCount_ += arc.patchCount;
    }
  }
  for (uint32_t i = 0; i < n; ++i) syncCandidate(i);
  if (!cache_) return;
  std::vector<LoadRequest> req;
  for (uint32_t a : cutArcs_) {
    const SceneArc& arc = scene_.arcs()[a];
    for (uint32_t p = 0; p < arc.patchCount; ++p) req.push_back({scene_.arcPatches()[arc.firstPatch + p], Urgency::UrgentUp});
  }
  server_->submit(req, 0);
  server_->waitIdle(timeoutMs);
  // Pin what arrived; a damaged patch of the coarsest cut is simply not drawn.
  for (const auto& r : req) cache_->pinAll(&r.id, 1);
}

bool ExtractRender::arcVisible(uint32_t arc, const View& view) const {
  if (!options_.cull) return true;
  const SceneArc& a = scene_.arcs()[arc];
  const SceneNode& s = scene_.nodes()[a.cullNode];
  const glm::dvec3 c(s.center[0], s.center[1], s.center[2]);
  for (const auto& p : view.planes)
    if (glm::dot(glm::dvec3(p), c) + p.w < -double(s.radius)) return false;
  // The cone describes `from`'s own fragment; for a source arc (cullNode = to) it does not bound
  // these patches, so only the sphere test applies.
  if (a.cullNode == a.from && s.coneCutoff > 0.0f && coneOn(s.file, view)) {
    glm::dvec3 v = c - view.eye;
    double d = glm::length(v);
    if (d > s.radius) {
      double ang = std::acos(std::clamp(glm::dot(glm::dvec3(s.coneAxis[0], s.coneAxis[1], s.coneAxis[2]), v / d), -1.0, 1.0));
      double alpha = std::acos(double(s.coneCutoff)), beta = std::asin(double(s.radius) / d);
      if (ang + alpha + beta < 1.5707963267948966) return false;  // every triangle faces away
    }
  }
  return true;
}

double ExtractRender::screenError(uint32_t node, const View& view) const {
  const SceneNode& s = scene_.nodes()[node];
  if (s.sink) return std::numeric_limits<double>::infinity();
  ++keyed_;
  const glm::dvec3 c(s.center[0], s.center[1], s.center[2]);
  // Occlusion (Derzapf et al. 4.2): hidden behind nearer geometry in the last frame's depth; or
  // everything the node replaces (its in-arcs, each bounded by its cull node's sphere) is hidden:
  // then refining it adds nothing visible and coarsening it removes nothing visible, even when the
  // node's own sphere (which also bounds its coarser fragment) pokes out.
  if (options_.cull && options_.occlusion && occluded_) {
    if ((*occluded_)[node]) return 0;
    bool hidden = s.inArcCount > 0;
    for (uint32_t k = 0; k < s.inArcCount && hidden; ++k)
      hidden = (*occluded_)[scene_.arcs()[scene_.inArcs()[s.firstInArc + k]].cullNode] != 0;
    if (hidden) return 0;
  }
  if (options_.cull) {
    // Frustum: a node entirely outside needs no detail (BMT 5.1 projects through the sphere).
    for (const auto& p : view.planes)
      if (glm::dot(glm::dvec3(p), c) + p.w < -double(s.radius)) return 0;
    // Normal cone (back-face) culling of the node's fragment.
    if (s.coneCutoff > 0.0f && coneOn(s.file, view)) {
      glm::dvec3 v = c - view.eye;
      double d = glm::length(v);
      if (d > s.radius) {
        double ang = std::acos(std::clamp(glm::dot(glm::dvec3(s.coneAxis[0], s.coneAxis[1], s.coneAxis[2]), v / d), -1.0, 1.0));
        double alpha = std::acos(double(s.coneCutoff)), beta = std::asin(double(s.radius) / d);
        if (ang + alpha + beta < 1.5707963267948966) return 0;
      }
    }
  }
  // The error projected through the bounding sphere: the closest point of the sphere (BMT 5.1),
  // so the screen error is monotone along the DAG (spheres nest, errors grow towards the sink).
  double d = glm::length(c - view.eye) - double(s.radius);
  d = std::max(d, view.nearPlane);
  return double(s.error) * view.pixelsPerUnit / d;
}

double ExtractRender::screenErrorAhead(uint32_t node, const std::vector<View>& views) const {
  double e = 0;
  // The views ahead share the current eye's cone flags (their eyes are a few frames away; the eye
  // test per view would cost more than prefetching gains).
  coneHeld_ = coneValid_;
  for (const View& v : views) e = std::max(e, screenError(node, v));
  coneHeld_ = false;
  return e;
}

bool ExtractRender::coneOn(uint32_t file, const View& view) const {
  if (options_.cones == ExtractOptions::Cones::Always) return true;
  if (options_.cones == ExtractOptions::Cones::Off) return false;
  const double eye[3] = {view.eye.x, view.eye.y, view.eye.z};
  if (!coneHeld_ && (!coneValid_ || eye[0] != coneEye_[0] || eye[1] != coneEye_[1] || eye[2] != coneEye_[2])) {
    coneFiles_.resize(scene_.fileCount());
    for (uint32_t f = 0; f < scene_.fileCount(); ++f) coneFiles_[f] = scene_.surface(f).eyeOutside(eye);
    for (int a = 0; a < 3; ++a) coneEye_[a] = eye[a];
    coneValid_ = true;
  }
  return coneFiles_[file] != 0;
}

bool ExtractRender::tryRefine(uint32_t n) {
  const SceneNode& s = scene_.nodes()[n];
  collectIn(n, scratch_);
  if (cache_ && !cache_->pinAll(scratch_.data(), scratch_.size())) return false;
  collectOut(n, scratch2_);
  if (cache_) cache_->unpinAll(scratch2_.data(), scratch2_.size());
  inS_[n] = 0;
  for (uint32_t k = 0; k < s.arcCount; ++k) {
    uint32_t a = s.firstArc + k;
    removeCutArc(a);
    ++predOut_[scene_.arcs()[a].to];
  }
  for (uint32_t k = 0; k < s.inArcCount; ++k) {
    uint32_t a = scene_.inArcs()[s.firstInArc + k];
    --succIn_[scene_.arcs()[a].from];
    addCutArc(a);
  }
  triangles_ = triangles_ + s.inTriangles - s.outTriangles;
  cutPatchCount_ = cutPatchCount_ + uint32_t(scratch_.size()) - uint32_t(scratch2_.size());
  syncAround(n);
  return true;
}

// A move on n changes n's membership of S, the successor counts of its in-arcs' `from` nodes and
// the predecessor counts of its out-arcs' `to` nodes: only those can change candidacy.
void ExtractRender::syncAround(uint32_t n) {
  const SceneNode& s = scene_.nodes()[n];
  syncCandidate(n);
  for (uint32_t k = 0; k < s.inArcCount; ++k) syncCandidate(scene_.arcs()[scene_.inArcs()[s.firstInArc + k]].from);
  for (uint32_t k = 0; k < s.arcCount; ++k) syncCandidate(scene_.arcs()[s.firstArc + k].to);
}

bool ExtractRender::tryCoarsen(uint32_t n) {
  const SceneNode& s = scene_.nodes()[n];
  collectOut(n, scratch_);
  if (cache_ && !cache_->pinAll(scratch_.data(), scratch_.size())) return false;
  collectIn(n, scratch2_);
  if (cache_) cache_->unpinAll(scratch2_.data(), scratch2_.size());
  inS_[n] = 1;
  for (uint32_t k = 0; k < s.inArcCount; ++k) {
    uint32_t a = scene_.inArcs()[s.firstInArc + k];
    ++succIn_[scene_.arcs()[a].from];
    removeCutArc(a);
  }
  for (uint32_t k = 0; k < s.arcCount; ++k) {
    uint32_t a = s.firstArc + k;
    --predOut_[scene_.arcs()[a].to];
    addCutArc(a);
  }
  triangles_ = triangles_ + s.outTriangles - s.inTriangles;
  cutPatchCount_ = cutPatchCount_ + uint32_t(scratch_.size()) - uint32_t(scratch2_.size());
  syncAround(n);
  return true;
}

int64_t ExtractRender::visibleDelta(uint32_t n, bool refine, const View& view) const {
  const SceneNode& s = scene_.nodes()[n];
  int64_t in = 0, out = 0;
  for (uint32_t k = 0; k < s.inArcCount; ++k) {
    uint32_t a = scene_.inArcs()[s.firstInArc + k];
    if (arcVisible(a, view)) in += scene_.arcs()[a].triangles;
  }
  for (uint32_t k = 0; k < s.arcCount; ++k) {
    uint32_t a = s.firstArc + k;
    if (arcVisible(a, view)) out += scene_.arcs()[a].triangles;
  }
  return refine ? in - out : out - in;
}

void ExtractRender::want(const std::vector<uint32_t>& ids, Urgency u) {
  for (uint32_t id : ids) {
    auto [it, fresh] = wanted_.emplace(id, Want{u, uint32_t(wanted_.size())});
    if (!fresh && uint8_t(u) > uint8_t(it->second.urgency)) it->second.urgency = u;
  }
}

void ExtractRender::frameDone(uint64_t drawnTriangles, double frameMs) {
  time_.add(double(drawnTriangles), frameMs);
  frameMsAvg_ = frameMsAvg_ == 0 ? frameMs : 0.9 * frameMsAvg_ + 0.1 * frameMs;
  lastFrameMs_ = frameMs;
  lastDrawn_ = double(drawnTriangles);
  ++slackFrames_;
}

double ExtractRender::nextBudget(double extractMs) {
  // CheckBudget's render budget: the triangles the time model says fit in the frame budget, with
  // a margin for the model's error; it falls at once and rises gradually.
  // The frames aim at 70% of the budget: on this 2-core machine the same cut at the same view
  // takes up to 1.3x its median (p99, llvmpipe's threads sharing the cores with the PatchServer
  // and the host), and the fit adds its own error in views it has not seen.
  constexpr double kAim = 0.7;
  double budget;
  if (options_.fixedTriangles) {
    budget = double(options_.fixedTriangles);
  } else {
    const double aimMs = kAim * options_.budgetMs;
    double target = time_.trianglesFor(aimMs - extractMs);
    // Falls fast (at most 30% a frame, so one odd frame cannot empty the screen), rises gradually.
    // Start low (a first guess of the machine is no measurement) and let the fit raise it.
    if (smoothBudget_ == 0) smoothBudget_ = std::min(target, 20000.0);
    else if (target < smoothBudget_) smoothBudget_ = std::max(target, 0.7 * smoothBudget_);
    else if (budgetScale_ == 1) smoothBudget_ = std::min(smoothBudget_ + 0.25 * (target - smoothBudget_), 1.25 * smoothBudget_);
    // A still view (progressive refinement, budgetScale_ > 1) has nothing to keep steady on screen:
    // follow the model twice as fast, so its images grow to what the machine can draw.
    else smoothBudget_ = std::min(smoothBudget_ + 0.5 * (target - smoothBudget_), 1.5 * smoothBudget_);
    // Feedback whatever the model says: the last frame's triangles scaled by the aim over its
    // time cap the budget (the secant from the origin, which overestimates the per-triangle cost:
    // it counts the fixed cost in). Applied when the frame was over the aim (the machine may have
    // slowed down faster than the fit can follow), and when it drew half its budget or more, so
    // the budget rises only as far as a real frame has shown there is room: the fitted model
    // alone let it rise into views dearer per triangle (fill, overdraw) than those it was fitted
    // on, the flythrough's over-budget frames.
    if (lastDrawn_ > 0 && lastFrameMs_ > 0 && (lastFrameMs_ > aimMs || lastDrawn_ >= 0.5 * frameBudget_))
      smoothBudget_ = std::min(smoothBudget_, lastDrawn_ * aimMs / lastFrameMs_);
    budget = std::max(smoothBudget_, 1000.0);
    // What else this frame costs (occlusion tests): taken off this frame's triangles only.
    if (frameOverheadMs_ > 0) budget = std::max(1000.0, budget - frameOverheadMs_ / time_.b());
  }
  frameBudget_ = budget;
  return budget * budgetScale_;
}

std::vector<LoadRequest> orderRequests(std::vector<RequestCandidate> c, uint32_t budget, bool byConsecutive) {
  std::sort(c.begin(), c.end(), [byConsecutive](const RequestCandidate& a, const RequestCandidate& b) {
    if (a.urgency != b.urgency) return uint8_t(a.urgency) > uint8_t(b.urgency);
    if (byConsecutive && a.consecutive != b.consecutive) return a.consecutive > b.consecutive;
    return a.rank < b.rank;
  });
  std::vector<LoadRequest> out;
  for (size_t i = 0; i < c.size() && out.size() < budget; ++i) out.push_back({c[i].id, c[i].urgency});
  return out;
}

void ExtractRender::submitRequests(uint64_t frame, FrameStats& st) {
  // Requests for the PatchServer: urgent first, then the patches wanted in the most consecutive
  // frames (Derzapf 4.1: no region starves), within the load budget.
  if (!cache_) return;
  std::vector<RequestCandidate> reqs;
  std::unordered_map<uint32_t, uint32_t> nextConsecutive;
  std::unordered_set<uint32_t> missed;
  touched_.clear();
  for (const auto& [id, w] : wanted_) {
    PatchCache::State s = cache_->state(id);
    if (s == PatchCache::State::Ready) {
      touched_.push_back(id);
      continue;
    }
    if (s == PatchCache::State::Bad) continue;
    if (w.urgency != Urgency::Prefetch) {
      ++st.misses;
      missed.insert(id);
      st.newMisses += missed_.count(id) == 0;
    }
    auto it = consecutive_.find(id);
    const uint32_t c = (it == consecutive_.end() ? 0 : it->second) + 1;
    nextConsecutive[id] = c;
    if (s == PatchCache::State::Loading) continue;
    reqs.push_back({id, w.urgency, c, w.rank});
  }
  consecutive_.swap(nextConsecutive);
  missed_.swap(missed);
  cache_->touch(touched_.data(), touched_.size(), frame);
  uint32_t loadBudget = options_.loadBudget;
  if (!loadBudget) {
    double ms = server_->meanLoadMs();
    loadBudget = uint32_t(std::clamp(ms > 0 ? options_.budgetMs / ms : 64.0, 8.0, 512.0));
  }
  std::vector<LoadRequest> out = orderRequests(std::move(reqs), loadBudget, options_.starvationOrder);
  for (const LoadRequest& r : out) {
    if (r.urgency == Urgency::Prefetch) ++st.prefetches;
    else ++st.requests;
  }
  server_->submit(std::move(out), frame);
  cache_->endFrame(frame);
}

FrameStats ExtractRender::requestAhead(uint64_t frame, const View& view) {
  const auto t0 = Clock::now();
  const double cpu0 = threadCpuMs();
  FrameStats st;
  frame_ = frame;
  wanted_.clear();
  const double extractMs = options_.extractMs > 0 ? options_.extractMs : std::min(2.0, options_.budgetMs / 20);
  const double budget = nextBudget(extractMs);
  const double tau = options_.pixelTolerance * lodScale_;
  const auto& nodes = scene_.nodes();
  // The refinements of the cut, the largest error first; a refinement whose patches are resident
  // is taken as done and its predecessors (the next refinements there) join the heap one level on.
  struct Entry {
    double err;
    uint32_t node, depth;
    bool operator<(const Entry& o) const { return err < o.err; }
  };
  std::priority_queue<Entry> heap;
  keyed_ = 0;
  // Bounded as the update's heaps are (fillHeaps): fresh keys within half the deadline, the last
  // keys after it (the view is still: they were made for it or for a view a few frames before);
  // the walk below stops at the deadline.
  const auto deadline = t0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double, std::milli>(extractMs));
  const auto half = t0 + (deadline - t0) / 2;
  const bool bounded = options_.deadline && options_.boundedRekey;
  bool fresh = true;
  for (size_t i = 0; i < refineSet_.size(); ++i) {
    const uint32_t n = refineSet_[i];
    if (badNode_[n]) continue;
    if (fresh && bounded && (i & 63) == 63 && Clock::now() >= half) fresh = false;
    if (fresh || std::isnan(key_[n])) key_[n] = screenError(n, view);
    else ++st.staleKeys;
    heap.push({key_[n], n, 0});
  }
  double triangles = double(visibleTriangles_);
  const uint32_t visit = ++stampNow_;
  for (uint32_t ops = 0; !heap.empty(); ++ops) {
    if (bounded && (ops & 15) == 15 && Clock::now() >= deadline) break;
    Entry e = heap.top();
    heap.pop();
    if (e.err <= tau || stamp_[e.node] == visit) continue;
    stamp_[e.node] = visit;
    triangles += double(visibleDelta(e.node, true, view));
    // Beyond the budget the next update trades coarsenings for the best refinements: ask for
    // those too, at prefetch priority, up to twice the budget.
    if (triangles > 2 * budget) break;
    collectIn(e.node, scratch_);
    want(scratch_, e.depth == 0 && triangles <= budget ? Urgency::Needed : Urgency::Prefetch);
    if (e.depth >= 1) continue;
    const SceneNode& s = nodes[e.node];
    for (uint32_t k = 0; k < s.inArcCount; ++k) {
      const uint32_t p = scene_.arcs()[scene_.inArcs()[s.firstInArc + k]].from;
      if (!nodes[p].source && !badNode_[p]) heap.push({screenError(p, view), p, e.depth + 1});
    }
  }
  submitRequests(frame, st);
  st.budgetTriangles = uint64_t(budget);
  st.triangles = triangles_;
  st.patches = cutPatchCount_;
  st.lodScale = lodScale_;
  st.modelA = time_.a();
  st.modelB = time_.b() * 1e6;
  st.nodesKeyed = keyed_;
  st.extractMs = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
  st.extractCpuMs = threadCpuMs() - cpu0;
  return st;
}

// ---- The cut update (Extract + Apply, then Prefetch) ----

// The state of one cut update: the view, the heaps of feasible moves (BMT 5, figure 8), the
// deadline, the render budget and the frame's figures.
struct ExtractRender::Pass {
  struct Entry {
    double err;
    uint32_t node;
  };
  struct LargestFirst {
    bool operator()(const Entry& a, const Entry& b) const { return a.err < b.err; }
  };
  struct SmallestFirst {
    bool operator()(const Entry& a, const Entry& b) const { return a.err > b.err; }
  };

  const View& view;
  FrameStats& st;
  Clock::time_point t0, deadline;
  double tau = 0;       // the tolerance times the LOD scale (pixels)
  double budget = 0;    // the render budget (triangles); a probe may raise it
  double pinLimit = 0;  // place holders the cut may pin
  std::priority_queue<Entry, std::vector<Entry>, LargestFirst> refine;
  std::priority_queue<Entry, std::vector<Entry>, SmallestFirst> coarse;
  double maxErr = 0;         // the largest screen error left on the visible cut
  uint32_t ops = 0;
  uint32_t urgentLeft = 4;   // the first misses at the top of the heap are urgent (3.3.2)
  double blockedErr = 0;     // the refinement memory stopped: what the LOD scale must reach at most
  bool memoryFull = false;   // the cut would crowd the cache: the global LOD scale grows

  Pass(const View& v, FrameStats& s) : view(v), st(s) {}
  // The deadline, looked at every 8th move; once passed, the update stops where it is.
  bool useDeadline = true;
  bool timeUp() {
    if ((++ops & 7) != 0 || !useDeadline) return false;
    if (Clock::now() < deadline) return false;
    st.interrupted = true;
    return true;
  }
};

// Re-keys the heaps for the new view from the candidate sets (kept by every move): the work is
// the front of the cut, not the DAG.
void ExtractRender::fillHeaps(Pass& p) const {
  // The keys depend on the view, so every candidate is re-keyed for the new one: O(front of the
  // cut). On a DAG of small patches the front holds thousands of nodes, so the re-keying is
  // bounded: it runs within the first half of the deadline, from a cursor that rotates over the
  // candidates, and the candidates it does not reach keep the key of the last frame that reached
  // them (BMT 5: the heaps persist between frames; consecutive views differ little, and every key
  // is fresh again within a few frames). Candidates never keyed are always keyed. Without the
  // deadline, or with time enough, every key is fresh (the cut is the same as unbounded).
  const size_t nr = refineSet_.size(), total = nr + coarsenSet_.size();
  const auto half = p.t0 + (p.deadline - p.t0) / 2;
  size_t fresh = 0;
  for (size_t start = total ? rekeyCursor_ % total : 0; fresh < total; ++fresh) {
    if (p.useDeadline && options_.boundedRekey && (fresh & 63) == 63 && Clock::now() >= half) break;
    const size_t j = (start + fresh) % total;
    const uint32_t n = j < nr ? refineSet_[j] : coarsenSet_[j - nr];
    key_[n] = screenError(n, p.view);
  }
  rekeyCursor_ = total ? (rekeyCursor_ % total + fresh) % total : 0;
  size_t late = 0;  // candidates past the bound keyed anyway (never keyed before)
  auto keyOf = [&](uint32_t n) {
    if (std::isnan(key_[n])) key_[n] = screenError(n, p.view), ++late;
    return key_[n];
  };
  std::vector<Pass::Entry> r, c;
  r.reserve(refineSet_.size());
  c.reserve(coarsenSet_.size());
  for (uint32_t n : refineSet_) r.push_back({keyOf(n), n});
  for (uint32_t n : coarsenSet_) c.push_back({keyOf(n), n});
  p.st.staleKeys = uint32_t(total - fresh - late);
  p.refine = decltype(p.refine)(Pass::LargestFirst(), std::move(r));
  p.coarse = decltype(p.coarse)(Pass::SmallestFirst(), std::move(c));
  for (uint32_t n : scene_.sources())
    if (succIn_[n] == 0) p.maxErr = std::max(p.maxErr, screenError(n, p.view));
}

// After a move on n, n and its neighbours may have become feasible moves (BMT 5, figure 8).
void ExtractRender::pushAround(Pass& p, uint32_t n) const {
  const SceneNode& s = scene_.nodes()[n];
  if (isRefineCandidate(n)) p.refine.push({screenError(n, p.view), n});
  if (isCoarsenCandidate(n)) p.coarse.push({screenError(n, p.view), n});
  for (uint32_t k = 0; k < s.inArcCount; ++k) {
    uint32_t m = scene_.arcs()[scene_.inArcs()[s.firstInArc + k]].from;
    if (isRefineCandidate(m)) p.refine.push({screenError(m, p.view), m});
  }
  for (uint32_t k = 0; k < s.arcCount; ++k) {
    uint32_t m = scene_.arcs()[s.firstArc + k].to;
    if (isCoarsenCandidate(m)) p.coarse.push({screenError(m, p.view), m});
  }
}

// Drops heap entries that are no longer feasible coarsenings or lead into a damaged patch.
void ExtractRender::popStaleCoarse(Pass& p) const {
  while (!p.coarse.empty() && (!isCoarsenCandidate(p.coarse.top().node) || (badNode_[p.coarse.top().node] & 2)))
    p.coarse.pop();
}

// Takes the cheapest coarsening off the heap and applies it when its patches are resident;
// otherwise asks for them with urgency `u` (or marks the node when one of them is damaged).
void ExtractRender::coarsenTop(Pass& p, Urgency u) {
  const Pass::Entry c = p.coarse.top();
  p.coarse.pop();
  const int64_t dc = visibleDelta(c.node, false, p.view);
  if (tryCoarsen(c.node)) {
    visibleTriangles_ = uint64_t(int64_t(visibleTriangles_) + dc);
    ++p.st.coarsenings;
    pushAround(p, c.node);
    return;
  }
  collectOut(c.node, scratch_);
  if (patchesBad(scratch_)) badNode_[c.node] |= 2;
  else want(scratch_, u);
}

// Step 1. Over the render budget: coarsen, the smallest error first (a "switch up", always urgent).
void ExtractRender::coarsenOverBudget(Pass& p) {
  while (double(visibleTriangles_) > p.budget && !p.st.interrupted) {
    popStaleCoarse(p);
    if (p.coarse.empty() || p.timeUp()) break;
    coarsenTop(p, Urgency::UrgentUp);
  }
}

// Probe: with a steady cut the time model cannot tell the per-triangle cost from the fixed cost
// and may stay pessimistic for ever. When frames have averaged under 60% of the budget and 30
// frames passed since the last probe, one refinement beyond the model's budget is taken (if it
// fits in twice the budget); the measurement corrects the model, and step 1 undoes it next frame
// if it was too much. Not right after a slow frame (the budget has just been cut for a reason).
bool ExtractRender::probeAllowed(double after, double budget) const {
  return after > budget && !options_.fixedTriangles && budgetScale_ == 1 && slackFrames_ >= 30 &&
         frameMsAvg_ < 0.6 * options_.budgetMs && lastFrameMs_ < 0.6 * options_.budgetMs && after <= 2 * budget;
}

// Step 2. Refine the largest screen error while CheckBudget allows; beyond the budget, trade the
// cheapest coarsening for it when that drops detail where it matters much less.
void ExtractRender::refineWithinBudget(Pass& p) {
  while (!p.refine.empty() && !p.st.interrupted) {
    const Pass::Entry e = p.refine.top();
    if (!isRefineCandidate(e.node) || (badNode_[e.node] & 1)) {
      p.refine.pop();
      continue;
    }
    if (e.err <= p.tau || p.timeUp()) break;
    const int64_t dv = visibleDelta(e.node, true, p.view);
    const double after = double(visibleTriangles_) + double(dv);
    if (probeAllowed(after, p.budget)) {  // the frame's budget is the probe's
      slackFrames_ = 0;
      p.budget = after;
      p.st.budgetTriangles = uint64_t(p.budget);
    }
    if (after > p.budget) {
      // Trade: drop detail where it matters much less, to spend it where it matters most.
      popStaleCoarse(p);
      const bool trade = !p.coarse.empty() && p.coarse.top().err * 2 < e.err;
      if (!trade) break;  // the budget is spent
      coarsenTop(p, Urgency::Needed);
      continue;
    }
    collectIn(e.node, scratch_);
    if (double(cutPatchCount_) + double(scratch_.size()) > p.pinLimit) {
      p.memoryFull = true;
      p.blockedErr = e.err;
      break;
    }
    p.refine.pop();
    refineOrRequest(p, e.node, e.err, dv);
  }
}

// Applies the refinement of `node` (screen error `err`) when its patches are resident; otherwise asks for them (the first few
// misses urgently) and counts its error as left on screen, or marks a damaged node.
void ExtractRender::refineOrRequest(Pass& p, uint32_t node, double err, int64_t dv) {
  if (tryRefine(node)) {
    visibleTriangles_ = uint64_t(int64_t(visibleTriangles_) + dv);
    ++p.st.refinements;
    pushAround(p, node);
    return;
  }
  collectIn(node, scratch_);
  if (patchesBad(scratch_)) {
    badNode_[node] |= 1;  // never refine into a damaged patch
    return;
  }
  want(scratch_, p.urgentLeft > 0 ? Urgency::UrgentDown : Urgency::Needed);
  if (p.urgentLeft > 0) --p.urgentLeft;
  p.maxErr = std::max(p.maxErr, err);
}

// Step 3. Coarsen detail far below the tolerance (frees triangles and memory; hysteresis 2x).
void ExtractRender::coarsenFarBelow(Pass& p) {
  while (!p.st.interrupted) {
    popStaleCoarse(p);
    if (p.coarse.empty() || p.coarse.top().err >= p.tau * 0.5 || p.timeUp()) break;
    coarsenTop(p, Urgency::Needed);
  }
}

// Step 4. Prefetch (BMT 5: "the operations in the heaps"; Derzapf 4.3: the children, and the
// frustum enlarged to contain the frusta of the next frames), at low priority so it only uses
// spare load capacity, and only in the time left before the deadline.
void ExtractRender::prefetch(Pass& p, const std::vector<View>& ahead) {
  const auto& nodes = scene_.nodes();
  auto timeLeft = [&] { return p.useDeadline ? Clock::now() < p.deadline : true; };
  for (int k = 0; !p.refine.empty() && k < 24;) {
    const Pass::Entry e = p.refine.top();
    p.refine.pop();
    if (!isRefineCandidate(e.node) || badNode_[e.node] || e.err <= p.tau * 0.5) continue;
    collectIn(e.node, scratch_);
    want(scratch_, Urgency::Prefetch);
    // Children: the next refinements after this one.
    const SceneNode& s = nodes[e.node];
    for (uint32_t j = 0; j < s.inArcCount && k < 8; ++j) {
      uint32_t m = scene_.arcs()[scene_.inArcs()[s.firstInArc + j]].from;
      if (!nodes[m].source && screenError(m, p.view) > p.tau) {
        collectIn(m, scratch_);
        want(scratch_, Urgency::Prefetch);
      }
    }
    ++k;
  }
  for (int k = 0; !p.coarse.empty() && k < 16;) {
    const Pass::Entry c = p.coarse.top();
    p.coarse.pop();
    if (!isCoarsenCandidate(c.node) || badNode_[c.node]) continue;
    collectOut(c.node, scratch_);
    want(scratch_, Urgency::Prefetch);
    ++k;
  }
  if (ahead.empty() || !timeLeft()) return;
  // The enlarged frustum: the refinements the next frames' views will want, the largest error
  // first, two levels deep (as if applied), within twice the render budget's worth of triangles.
  struct Entry {
    double err;
    uint32_t node, depth;
    bool operator<(const Entry& o) const { return err < o.err; }
  };
  std::vector<Entry> start;
  start.reserve(refineSet_.size());
  // The whole front keyed for the views ahead is O(front x views): it stops at the deadline too
  // (what it reached is prefetched; the next frame starts over).
  for (size_t i = 0; i < refineSet_.size(); ++i) {
    if ((i & 63) == 63 && !timeLeft()) break;
    const uint32_t n = refineSet_[i];
    if (!badNode_[n]) {
      const double e = screenErrorAhead(n, ahead);
      if (e > p.tau) start.push_back({e, n, 0});
    }
  }
  std::priority_queue<Entry> heap(std::less<Entry>(), std::move(start));
  const uint32_t visit = ++stampNow_;
  double triangles = 0;
  for (uint32_t ops = 0; !heap.empty(); ++ops) {
    if ((ops & 15) == 15 && !timeLeft()) break;
    const Entry e = heap.top();
    heap.pop();
    if (stamp_[e.node] == visit) continue;
    stamp_[e.node] = visit;
    triangles += double(nodes[e.node].inTriangles);
    if (triangles > 2 * p.budget) break;
    collectIn(e.node, scratch_);
    want(scratch_, Urgency::Prefetch);
    if (e.depth >= 1) continue;
    const SceneNode& s = nodes[e.node];
    for (uint32_t k = 0; k < s.inArcCount; ++k) {
      const uint32_t m = scene_.arcs()[scene_.inArcs()[s.firstInArc + k]].from;
      if (nodes[m].source || badNode_[m]) continue;
      const double em = screenErrorAhead(m, ahead);
      if (em > p.tau) heap.push({em, m, e.depth + 1});
    }
  }
}

FrameStats ExtractRender::update(uint64_t frame, const View& view, const View& predicted) {
  return update(frame, view, std::vector<View>{predicted});
}

FrameStats ExtractRender::update(uint64_t frame, const View& view, const std::vector<View>& ahead) {
  FrameStats st;
  Pass p(view, st);
  p.t0 = Clock::now();
  const double cpu0 = threadCpuMs();
  p.useDeadline = options_.deadline;
  keyed_ = 0;
  frame_ = frame;
  wanted_.clear();
  const double extractMs = options_.extractMs > 0 ? options_.extractMs : std::min(2.0, options_.budgetMs / 20);
  p.deadline = p.t0 + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double, std::milli>(extractMs));
  p.tau = options_.pixelTolerance * lodScale_;
  p.budget = nextBudget(extractMs);
  st.budgetTriangles = uint64_t(p.budget);
  st.modelA = time_.a();
  st.modelB = time_.b() * 1e6;
  visibleTriangles_ = 0;
  for (uint32_t a : cutArcs_)
    if (arcVisible(a, view)) visibleTriangles_ += scene_.arcs()[a].triangles;
  p.pinLimit = pinLimit();
  fillHeaps(p);
  if (occluded_ && options_.occlusion)
    for (uint32_t n : refineSet_) st.occludedNodes += (*occluded_)[n];

  if (!frozen_) {
    // A still view's image is drawn over as many frames as it takes, each within one frame's
    // budget (engine.h), so its cut need not shrink when the budget does: a still view only gets
    // finer. (Under a fluctuating load the budget swung by 2-4x and the still image with it, coarser
    // and finer again while nothing moved.)
    if (budgetScale_ == 1) coarsenOverBudget(p);
    refineWithinBudget(p);
    coarsenFarBelow(p);
  }
  // The cut's largest visible screen error: the worst refinement left undone.
  while (!p.refine.empty() && !isRefineCandidate(p.refine.top().node)) p.refine.pop();
  if (!p.refine.empty()) p.maxErr = std::max(p.maxErr, p.refine.top().err);
  st.maxScreenError = p.maxErr;
  if (cache_ && options_.prefetch && !frozen_ && (!p.useDeadline || Clock::now() < p.deadline)) prefetch(p, ahead);

  submitRequests(frame, st);

  // Global LOD scale (Derzapf 4.1): while the cut cannot refine for lack of place holders, the
  // tolerance of every model grows (x1.1 a frame), but never past the error of the refinement
  // memory stopped (beyond that it buys nothing: a scale that ran away during close views left a
  // later far view at the coarsest cut). It relaxes once the cut is back under 80% of the limit:
  // quickly (x0.85) under half of it, gradually (x0.97) above; between 80% and 100% it holds, so
  // raising and relaxing cannot alternate.
  const double cut = double(cutPatchCount_);
  if (p.memoryFull && options_.lodScalePolicy) {
    const double cap = std::max(lodScale_, p.blockedErr / options_.pixelTolerance);
    lodScale_ = std::min({lodScale_ * 1.1, cap, 64.0});
  } else if (lodScale_ > 1 && cut < 0.8 * p.pinLimit) {
    lodScale_ = std::max(1.0, lodScale_ * (cut < 0.5 * p.pinLimit ? 0.85 : 0.97));
  }
  st.memoryFull = p.memoryFull;
  st.lodScale = lodScale_;
  st.triangles = triangles_;
  st.patches = cutPatchCount_;
  st.nodesKeyed = keyed_;
  st.extractMs = std::chrono::duration<double, std::milli>(Clock::now() - p.t0).count();
  st.extractCpuMs = threadCpuMs() - cpu0;
  return st;
}

}  // namespace mt::render
