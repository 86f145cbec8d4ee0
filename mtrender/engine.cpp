#include "mtrender/engine.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>

#include "base/error.h"

namespace mt::render {

Engine::Engine(EngineOptions options) : options_(std::move(options)) {
  scene_ = std::make_unique<Scene>(options_.files);
  scene_->setLoadTextures(options_.textures);
  drawnPerFile_.assign(scene_->fileCount(), 0);
  double c[3], r;
  scene_->boundingSphere(c, r);
  center_ = {c[0], c[1], c[2]};
  radius_ = r;
  if (!options_.gpuCacheBytes) options_.gpuCacheBytes = options_.cacheBytes;
  if (options_.baseline) {
    for (size_t f = 0; f < scene_->fileCount(); ++f) {
      const std::string& path = scene_->reader(uint32_t(f)).path();
      int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
      if (fd < 0) fail(path, "cannot open for mapping");
      uint64_t size = scene_->reader(uint32_t(f)).fileSize();
      void* m = ::mmap(nullptr, size, PROT_READ, MAP_SHARED, fd, 0);
      ::close(fd);
      if (m == MAP_FAILED) fail(path, "cannot map the file");
      maps_.push_back(static_cast<const uint8_t*>(m));
      mapSizes_.push_back(size);
    }
    uint64_t largest = 0;
    for (uint64_t b : scene_->decodedBytesBounds()) largest = std::max(largest, b);
    scratch_.resize(largest);
    extract_ = std::make_unique<ExtractRender>(*scene_, nullptr, nullptr, options_.extract);
  } else {
    const std::vector<uint64_t> bounds = scene_->decodedBytesBounds();
    cache_ = std::make_unique<PatchCache>(options_.cacheBytes, bounds, [this](const auto& group) { scene_->forEachMoveGroup(group); });
    PatchServer::Options so;
    so.readDelayMs = options_.readDelayMs;
    so.quiet = options_.quiet;
    server_ = std::make_unique<PatchServer>(*scene_, *cache_, so);
    extract_ = std::make_unique<ExtractRender>(*scene_, cache_.get(), server_.get(), options_.extract);
  }
  occluded_.assign(scene_->nodes().size(), 0);
  extract_->setOccluded(&occluded_);
}

Engine::~Engine() {
  server_.reset();
  for (size_t f = 0; f < maps_.size(); ++f) ::munmap(const_cast<uint8_t*>(maps_[f]), mapSizes_[f]);
}

uint64_t Engine::badPatches() const { return server_ ? server_->badPatches() : baselineBad_.size(); }

size_t Engine::warnUndrawnFiles() const {
  size_t n = 0;
  for (uint32_t f = 0; f < drawnPerFile_.size(); ++f)
    if (drawnPerFile_[f] == 0 && frame_ > 0) {
      std::fprintf(stderr,
                   "mtrender: warning: %s: nothing of it was drawn in %llu frames (out of view all along, or its "
                   "triangles are degenerate: run mtverify)\n",
                   scene_->reader(f).path().c_str(), (unsigned long long)frame_);
      ++n;
    }
  return n;
}

void Engine::start(double timeoutMs) { extract_->start(timeoutMs); }

PatchView Engine::baselineFetch(uint32_t id) {
  PatchView v;
  if (baselineBad_.count(id)) return v;
  const ScenePatch sp = scene_->patch(id);
  const MtFileReader& reader = scene_->reader(sp.file);
  const format::PatchRecord& rec = reader.patches()[sp.local];
  try {
    DecodedPatch d = decodePatch(maps_[sp.file] + rec.offset, rec.size, reader.codec(), reader.grid(), rec.triangles);
    auto counts = decodeInto(*scene_, id, d, scratch_.data(), scratch_.size(), &v.bound);
    v.vertices = reinterpret_cast<const RenderVertex*>(scratch_.data());
    v.vertexCount = counts.first;
    v.indices = reinterpret_cast<const uint32_t*>(scratch_.data() + uint64_t(counts.first) * sizeof(RenderVertex));
    v.indexCount = counts.second;
    if (scene_->loadsTextures(sp.file)) {
      const TexturePayload t = reader.readTexture(sp.local, d);
      const auto atlas = decodeTextureInto(t, counts.first, counts.second / 3, scratch_.data(), scratch_.size());
      if (atlas.first) {
        v.cornerUV = reinterpret_cast<const uint16_t*>(scratch_.data() + textureOffset(counts.first, counts.second / 3));
        v.texels = scratch_.data() + texelOffset(counts.first, counts.second / 3);
        v.texWidth = atlas.first;
        v.texHeight = atlas.second;
      }
    }
    ++baselineLoads_;
  } catch (const std::exception& e) {
    baselineBad_.insert(id);
    if (!options_.quiet)
      std::fprintf(stderr, "warning: %s: patch %u: %s (patch skipped, rendering continues)\n", reader.path().c_str(),
                   sp.local, e.what());
  }
  return v;
}

void Engine::orderVisibleArcs(const View& view) {
  const auto& arcs = scene_->arcs();
  const auto& nodes = scene_->nodes();
  // Front to back (by the distance of the arc's bounding sphere): llvmpipe tests depth before
  // shading, so near surfaces drawn first spare the shading of what they hide.
  drawOrder_.clear();
  for (uint32_t a : extract_->cutArcs()) {
    if (!extract_->arcVisible(a, view)) continue;
    const SceneNode& s = nodes[arcs[a].cullNode];
    const glm::dvec3 c(s.center[0], s.center[1], s.center[2]);
    drawOrder_.push_back({glm::length(c - view.eye) - double(s.radius), a});
  }
  std::sort(drawOrder_.begin(), drawOrder_.end());
}

namespace {

// Back-facing by the patch's own normal cone (the node test of ExtractRender, on the patch's
// sphere): every triangle faces away from the eye.
bool backFacing(const PatchBound& b, const double origin[3], const glm::dvec3& eye) {
  if (b.coneCutoff <= 0.0f) return false;
  const glm::dvec3 c(origin[0] + b.center[0], origin[1] + b.center[1], origin[2] + b.center[2]);
  const glm::dvec3 v = c - eye;
  const double d = glm::length(v);
  if (d <= double(b.radius)) return false;
  const double ang = std::acos(std::clamp(glm::dot(glm::dvec3(b.coneAxis[0], b.coneAxis[1], b.coneAxis[2]), v / d), -1.0, 1.0));
  const double alpha = std::acos(double(b.coneCutoff)), beta = std::asin(double(b.radius) / d);
  return ang + alpha + beta < 1.5707963267948966;
}

}  // namespace

void Engine::drawArcs(size_t from, size_t to, GlRenderer& gl, FrameRecord& rec, const View& view) {
  const auto& arcs = scene_->arcs();
  const auto& nodes = scene_->nodes();
  const bool cull = options_.extract.cull;
  for (size_t i = from; i < to; ++i) {
    const SceneArc& arc = arcs[drawOrder_[i].second];
    const uint32_t level = nodes[arc.from].level;
    // The finest patches have no node cone of their own (the `to` node's cone bounds another
    // fragment): their own cones, measured at decode, cull them.
    const bool ownCone = cull && options_.extract.patchCones && nodes[arc.from].source &&
                         extract_->coneOn(nodes[arc.from].file, view);
    for (uint32_t k = 0; k < arc.patchCount; ++k) {
      const uint32_t id = scene_->arcPatches()[arc.firstPatch + k];
      const double* origin = scene_->patchOrigin(id);
      bool coned = false;
      auto fetch = [&]() -> PatchView {
        PatchView v = cache_ ? cache_->view(id) : baselineFetch(id);
        if (ownCone && v.vertexCount && backFacing(v.bound, origin, view.eye)) {
          coned = true;
          return PatchView();
        }
        return v;
      };
      if (ownCone && cache_) {
        const PatchView v = cache_->view(id);
        if (v.vertexCount && backFacing(v.bound, origin, view.eye)) {
          ++rec.conedPatches;
          continue;
        }
      }
      uint32_t t = gl.drawPatch(id, level, origin, fetch);
      if (coned) ++rec.conedPatches;
      if (t) {
        ++rec.drawnPatches;
        rec.drawnTriangles += t;
        drawnPerFile_[scene_->fileOfPatch(id)] += t;
      }
    }
  }
}

void Engine::collectFront(std::vector<uint32_t>& out) {
  out.clear();
  const auto& nodes = scene_->nodes();
  if (frontStamp_.size() != nodes.size()) frontStamp_.assign(nodes.size(), 0);
  if (++frontVisit_ == 0) {
    std::fill(frontStamp_.begin(), frontStamp_.end(), 0);
    frontVisit_ = 1;
  }
  auto add = [&](uint32_t n) {
    if (nodes[n].sink || nodes[n].source || frontStamp_[n] == frontVisit_) return;
    frontStamp_[n] = frontVisit_;
    out.push_back(n);
  };
  for (uint32_t n : extract_->coarsenCandidates()) add(n);
  const auto& arcs = scene_->arcs();
  const auto& inArcs = scene_->inArcs();
  for (uint32_t n : extract_->refineCandidates()) {
    add(n);
    const SceneNode& s = nodes[n];
    for (uint32_t k = 0; k < s.inArcCount; ++k) {
      const uint32_t m = arcs[inArcs[s.firstInArc + k]].from;
      if (nodes[m].source) continue;
      add(m);
      const SceneNode& sm = nodes[m];
      for (uint32_t j = 0; j < sm.inArcCount; ++j) add(arcs[inArcs[sm.firstInArc + j]].from);
    }
  }
}

bool Engine::patchSphere(uint32_t id, double grow, std::vector<GlRenderer::QuerySphere>& out) const {
  if (!cache_) return false;
  const PatchView v = cache_->view(id);
  if (!v.vertexCount || v.bound.radius <= 0) return false;
  const double* o = scene_->patchOrigin(id);
  out.push_back({{o[0] + v.bound.center[0], o[1] + v.bound.center[1], o[2] + v.bound.center[2]}, double(v.bound.radius) + grow});
  return true;
}

void Engine::moveSpheres(uint32_t n, std::vector<GlRenderer::QuerySphere>& out) const {
  const SceneNode& s = scene_->nodes()[n];
  const auto& arcs = scene_->arcs();
  const auto& inArcs = scene_->inArcs();
  const auto& inS = extract_->inSet();
  const size_t start = out.size();
  bool tight = false;
  // A refinement of n replaces the patches of its out-arcs (its fragment, on screen); a coarsening
  // replaces those of its in-arcs. Either way the other side lies within n's error of them.
  auto patchesOf = [&](const SceneArc& a) {
    for (uint32_t k = 0; k < a.patchCount; ++k)
      if (!patchSphere(scene_->arcPatches()[a.firstPatch + k], double(s.error), out)) return false;
    return true;
  };
  if (inS[n]) {
    tight = s.arcCount > 0;
    for (uint32_t k = 0; k < s.arcCount && tight; ++k) tight = patchesOf(arcs[s.firstArc + k]);
  } else {
    tight = s.inArcCount > 0;
    for (uint32_t k = 0; k < s.inArcCount && tight; ++k) tight = patchesOf(arcs[inArcs[s.firstInArc + k]]);
  }
  if (tight) return;
  out.resize(start);
  out.push_back({{s.center[0], s.center[1], s.center[2]}, double(s.radius)});
}

void Engine::testHidden(const std::vector<GlRenderer::QuerySphere>& spheres, std::vector<uint8_t>& hidden, GlRenderer* gl,
                        FrameRecord& rec, bool presented) {
  const auto t0 = std::chrono::steady_clock::now();
  hidden.assign(spheres.size(), 0);
  if (options_.occlusionTest == OcclusionTest::Queries && gl) {
    gl->queryHidden(spheres, hidden, presented);
  } else if (!pyramid_.empty()) {
    for (size_t i = 0; i < spheres.size(); ++i) hidden[i] = pyramid_.occluded(spheres[i].center, spheres[i].radius);
  }
  rec.occlusionTests += uint32_t(spheres.size());
  rec.occlusionMs += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

void Engine::markOccluded(GlRenderer* gl, FrameRecord& rec, bool presented) {
  for (uint32_t n : occludedList_) occluded_[n] = 0;
  occludedList_.clear();
  if (arcHidden_.size() != scene_->arcs().size()) arcHidden_.assign(scene_->arcs().size(), 0);
  for (uint32_t a : hiddenArcs_) arcHidden_[a] = 0;
  hiddenArcs_.clear();
  // One batch (the queries are issued together and their results read once): each front node's
  // move spheres, then each cut arc's patches; a node or an arc is hidden when all of its are.
  collectFront(testNodes_);
  spheres_.clear();
  sphereOwner_.clear();
  for (uint32_t i = 0; i < testNodes_.size(); ++i) {
    moveSpheres(testNodes_[i], spheres_);
    sphereOwner_.resize(spheres_.size(), i);
  }
  const auto& cut = extract_->cutArcs();
  const uint32_t arcBase = uint32_t(testNodes_.size());
  for (uint32_t i = 0; i < cut.size(); ++i) {
    const SceneArc& a = scene_->arcs()[cut[i]];
    const size_t start = spheres_.size();
    bool tight = true;
    for (uint32_t k = 0; k < a.patchCount && tight; ++k) tight = patchSphere(scene_->arcPatches()[a.firstPatch + k], 0, spheres_);
    if (!tight) {
      spheres_.resize(start);
      const SceneNode& s = scene_->nodes()[a.cullNode];
      spheres_.push_back({{s.center[0], s.center[1], s.center[2]}, double(s.radius)});
    }
    sphereOwner_.resize(spheres_.size(), arcBase + i);
  }
  testHidden(spheres_, hiddenScratch_, gl, rec, presented);
  std::vector<uint8_t> all(testNodes_.size() + cut.size(), 1);
  for (size_t i = 0; i < spheres_.size(); ++i) all[sphereOwner_[i]] &= hiddenScratch_[i];
  for (uint32_t i = 0; i < testNodes_.size(); ++i)
    if (all[i]) {
      occluded_[testNodes_[i]] = 1;
      occludedList_.push_back(testNodes_[i]);
    }
  for (uint32_t i = 0; i < cut.size(); ++i)
    if (all[arcBase + i]) {
      arcHidden_[cut[i]] = 1;
      hiddenArcs_.push_back(cut[i]);
    }
}

void Engine::drawWithOcclusion(const View& view, GlRenderer& gl, FrameRecord& rec) {
  const auto& arcs = scene_->arcs();
  if (arcHidden_.size() != arcs.size()) arcHidden_.assign(arcs.size(), 0);
  // Phase 1: what was not hidden at the last test, front to back.
  std::vector<std::pair<double, uint32_t>> all;
  all.swap(drawOrder_);
  deferred_.clear();
  for (const auto& e : all) (arcHidden_[e.second] ? deferred_ : drawOrder_).push_back(e);
  drawArcs(0, drawOrder_.size(), gl, rec, view);
  // This frame's depth so far: phase 2 draws what it does not hide (so nothing visible is ever
  // skipped), and it marks the front hidden for the next update (the LOD lags one frame, as in
  // Derzapf et al. 4.2). The drawing so far is finished first, so the time measured is the tests'
  // own (the read-back or the queries' results wait for the rasterizer either way).
  gl.finish();
  rec.occlusionFrame = true;
  if (options_.occlusionTest == OcclusionTest::Pyramid) {
    const auto t0 = std::chrono::steady_clock::now();
    gl.readDepth(depth_);
    pyramid_.build(depth_, view.width, view.height, view);
    rec.occlusionMs += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  }
  // Each deferred arc is tested by its patches' own spheres (its node's sphere nests every finer
  // one and hides far less often).
  spheres_.clear();
  sphereOwner_.clear();
  for (uint32_t i = 0; i < deferred_.size(); ++i) {
    const SceneArc& a = arcs[deferred_[i].second];
    const size_t start = spheres_.size();
    bool tight = true;
    for (uint32_t k = 0; k < a.patchCount && tight; ++k) tight = patchSphere(scene_->arcPatches()[a.firstPatch + k], 0, spheres_);
    if (!tight) {
      spheres_.resize(start);
      const SceneNode& s = scene_->nodes()[a.cullNode];
      spheres_.push_back({{s.center[0], s.center[1], s.center[2]}, double(s.radius)});
    }
    sphereOwner_.resize(spheres_.size(), i);
  }
  testHidden(spheres_, hiddenScratch_, &gl, rec, false);
  std::vector<uint8_t> hiddenArc(deferred_.size(), 1);
  for (size_t i = 0; i < spheres_.size(); ++i) hiddenArc[sphereOwner_[i]] &= hiddenScratch_[i];
  drawOrder_.clear();
  for (size_t i = 0; i < deferred_.size(); ++i) {
    if (hiddenArc[i]) ++rec.occludedArcs;
    else drawOrder_.push_back(deferred_[i]);
  }
  drawArcs(0, drawOrder_.size(), gl, rec, view);
  markOccluded(&gl, rec);
  // drawOrder_ back to every visible arc (the still path reuses it).
  drawOrder_.swap(all);
}

FrameRecord Engine::frame(const CameraPose& pose, const CameraPose& prev, GlRenderer& gl, const DrawSettings& settings,
                          int width, int height) {
  using Clock = std::chrono::steady_clock;
  const auto t0 = Clock::now();
  ++frame_;
  View view = makeView(pose, width, height, center_, radius_);
  FrameRecord rec;
  rec.moving = pose.eye != prev.eye || pose.target != prev.target || pose.up != prev.up || pose.fovDeg != prev.fovDeg;
  // Prefetching's enlarged frustum (Derzapf et al. 4.3): the views of the next 10 frames,
  // extrapolated from the motion (every second one: the frusta overlap heavily).
  std::vector<View> ahead;
  if (rec.moving)
    for (int k = 2; k <= 10; k += 2) ahead.push_back(makeView(extrapolate(prev, pose, k), width, height, center_, radius_));
  baselineLoads_ = 0;
  // A new image size or new draw settings (viewer keys) also invalidate the image on screen.
  const bool sameLook = width == lastWidth_ && height == lastHeight_ && settings.mode == lastSettings_.mode &&
                        settings.wireframe == lastSettings_.wireframe && settings.background == lastSettings_.background;
  lastWidth_ = width, lastHeight_ = height, lastSettings_ = settings;
  const bool progressive = options_.stillFrames > 1 && !rec.moving && sameLook && frame_ > 1 && !extract_->frozen();
  if (!progressive) {
    // Moving (or refinement off): the whole cut, within one frame's budget, straight to the output.
    still_ = Still();
    extract_->setBudgetScale(1);
    // The occlusion tests cost several ms on llvmpipe (docs/mtrender.md): they run on every k-th
    // frame, k keeping their measured cost near 5% of the budget (or k = occlusionEvery, fixed);
    // the other frames draw every visible arc and keep the last flags. A frame that runs them
    // draws that much less.
    const bool testFrame = occlusionOn() && frame_ >= nextOcclusionFrame_;
    extract_->setFrameOverheadMs(testFrame ? occlusionMs_ : 0);
    static_cast<FrameStats&>(rec) = extract_->update(frame_, view, ahead);
    extract_->setFrameOverheadMs(0);
    gl.beginFrame(view, settings);
    orderVisibleArcs(view);
    if (testFrame) {
      drawWithOcclusion(view, gl, rec);
      const double ms = rec.occlusionMs;
      occlusionMs_ = occlusionMs_ == 0 ? ms : 0.8 * occlusionMs_ + 0.2 * ms;
      const double share = 0.05 * options_.extract.budgetMs;
      nextOcclusionFrame_ = frame_ + (options_.occlusionEvery
                                          ? options_.occlusionEvery
                                          : std::clamp<uint64_t>(uint64_t(occlusionMs_ / share) + 1, 1, 16));
    } else {
      drawArcs(0, drawOrder_.size(), gl, rec, view);
      // The cut's new front is marked against the last depth read (its own view: a few frames old
      // while moving, exact while still), so no frame refines and loads blindly. (Queries have no
      // depth of their own to keep: the flags of their last frame stay.)
      if (occlusionOn() && options_.occlusionTest == OcclusionTest::Pyramid) markOccluded(nullptr, rec);
    }
    lastScreenError_ = rec.maxScreenError;
  } else {
    if (!still_.active) {  // the camera has just stopped: what is on screen stays until a finer image is ready
      gl.keepOutputAsPresented(width, height);
      still_.active = true;
      still_.presentedError = lastScreenError_;
    }
    bool startImage = !still_.drawing;
    if (startImage) {
      // Between images: move the cut (it may hold stillFrames frames' worth of triangles) and
      // start drawing it, unless the cut did not move and the image on screen is already of it.
      extract_->setBudgetScale(double(options_.stillFrames));
      static_cast<FrameStats&>(rec) = extract_->update(frame_, view, ahead);
      if (rec.refinements || rec.coarsenings || !still_.presentedIsCut) {
        orderVisibleArcs(view);
        still_.drawing = true;
        still_.next = 0;
        still_.frames = 0;
        still_.imageError = rec.maxScreenError;
      } else {
        startImage = false;
      }
    } else {
      // The cut stays as it is while its image is drawn (its patches stay pinned); loads for its
      // next refinements go on.
      static_cast<FrameStats&>(rec) = extract_->requestAhead(frame_, view);
    }
    if (still_.drawing) {
      gl.beginAccumulation(view, settings, startImage);
      // One frame's budget of the image (at least one arc, so every image completes). The frame
      // that moved the cut draws half: it also pays for the update and for uploading the patches
      // that arrived (and the PatchServer is decoding on the other core).
      const auto& arcs = scene_->arcs();
      const double frameBudget = std::max(extract_->frameBudget(), 1000.0) * (startImage ? 0.5 : 1.0);
      size_t end = still_.next;
      uint64_t slice = 0;
      while (end < drawOrder_.size() &&
             (end == still_.next || double(slice + arcs[drawOrder_[end].second].triangles) <= frameBudget))
        slice += arcs[drawOrder_[end++].second].triangles;
      drawArcs(still_.next, end, gl, rec, view);
      still_.next = end;
      ++still_.frames;
      if (still_.next == drawOrder_.size()) {
        gl.presentAccumulation();
        if (occlusionOn()) {
          // The finished image's depth marks the front hidden for the next image's cut (same view).
          rec.occlusionFrame = true;
          if (options_.occlusionTest == OcclusionTest::Pyramid) {
            const auto o0 = std::chrono::steady_clock::now();
            gl.readDepth(depth_, true);
            pyramid_.build(depth_, view.width, view.height, view);
            rec.occlusionMs += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - o0).count();
          }
          markOccluded(&gl, rec, true);
        }
        still_.presentedError = still_.imageError;
        still_.presentedIsCut = true;
        still_.drawing = false;
        rec.imageFrames = still_.frames;
      }
    }
    gl.showPresented();
    rec.accumulating = true;
    rec.maxScreenError = still_.presentedError;
  }
  gl.endFrame();
  gl.finish();
  // A still view whose next detail is waiting for the disk: the frame spends what is left of its
  // budget (up to 80%) waiting for those loads, as a display-bound renderer would wait for the
  // next refresh anyway. Without this, frames that redraw nothing (the image on screen is already
  // of the cut) take ~0.2 ms, and a headless run's whole still stretch passed before one load
  // finished: the run ended at the coarsest cut (1 patch, 21 px) with the camera still.
  if (server_ && !rec.moving && (rec.requests > 0 || rec.misses > 0)) {
    const double left = 0.8 * options_.extract.budgetMs - std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
    if (left > 1) server_->waitIdle(left);
  }
  rec.frameMs = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
  // The first frame pays for shader compilation: not a sample of the draw cost. Nor are the
  // occlusion tests (the time model is of drawing; a test frame's budget gives up their time).
  if (frame_ > 1) extract_->frameDone(rec.drawnTriangles, std::max(0.0, rec.frameMs - rec.occlusionMs));
  if (server_) {
    uint64_t l = server_->loads();
    rec.loads = uint32_t(l - lastLoads_);
    lastLoads_ = l;
    const uint64_t lt = server_->trianglesLoaded();
    rec.loadedTriangles = lt - lastLoadedTriangles_;
    lastLoadedTriangles_ = lt;
    rec.cacheBytes = cache_->stats().usedBytes;
  } else {
    rec.loads = baselineLoads_;
    rec.misses = rec.newMisses = baselineLoads_;  // every patch not on the GPU is a synchronous read
  }
  rec.gpuBytes = gl.gpuBytes();
  return rec;
}

}  // namespace mt::render
