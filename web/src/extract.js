// ExtractRender's cut update in the browser: a port of mtrender/extract.cpp (BMT section 5, figure
// 9), rule for rule, so that for the same file, view and tolerance both choose the same cut
// (tests/web_cut_compare checks it). Read extract.h's header comment for the design; the names
// here are the C++ ones. What differs: the place-holder count of PatchCache is replaced by bytes
// (the browser's cache is byte-capped, cache.js), so the memory limit of the cut is
// memoryFraction * cap in decoded bytes rather than in place holders. And a still view's loads: it
// asks at once for the patches of the cut it converges to (wantBelowCut) and refines through the
// levels between without loading them (refineThrough); the cut it settles on is the same.

import { Heap } from './heap.js';

export const Urgency = Object.freeze({ Ahead: -1, Prefetch: 0, Needed: 1, UrgentDown: 2, UrgentUp: 3 });
const now = () => (typeof performance !== 'undefined' ? performance.now() : Date.now());

/** frame ms ~= a + b * triangles, fitted online by least squares over the last 45 frames. */
export class TimeModel {
  constructor() {
    this.a = 2.0;
    this.b = 1e-4;
    this.window = [];
    this.next = 0;
  }
  add(triangles, ms) {
    const t = triangles * 1e-6;
    const predicted = this.a + this.b * 1e6 * t;
    ms = Math.min(ms, 2.0 * predicted + 5.0);
    const kWindow = 45;
    if (this.window.length < kWindow) this.window.push([t, ms]);
    else this.window[this.next] = [t, ms];
    this.next = (this.next + 1) % kWindow;
    const n = this.window.length;
    let mt = 0, mm = 0;
    for (const [x, y] of this.window) mt += x, mm += y;
    mt /= n, mm /= n;
    let vt = 0, cov = 0;
    for (const [x, y] of this.window) vt += (x - mt) * (x - mt), cov += (x - mt) * (y - mm);
    vt /= n, cov /= n;
    let bm = this.b * 1e6;
    if (this.window.length >= 8 && Math.sqrt(vt) > 0.15 * mt && vt > 0) bm = Math.min(Math.max(cov / vt, 20.0), 1e5);
    this.b = bm * 1e-6;
    this.a = Math.max(0.0, mm - bm * mt);
  }
  predictMs(triangles) { return this.a + this.b * triangles; }
  trianglesFor(ms) { return Math.max(0, (ms - this.a) / this.b); }
}

export const defaultExtractOptions = () => ({
  pixelTolerance: 1.0,
  budgetMs: 50,
  fixedTriangles: 0,
  extractMs: 0,
  loadBudget: 0,
  // A moving view's spare loading capacity fetches what the view would need still (below).
  loadAhead: true,
  aheadBatch: 32,  // at most this many look-ahead patches asked for at a time
  aheadGate: 0.6,  // only after a frame within this share of the budget
  prefetch: true,
  cull: true,
  // Normal-cone culling within `cull` (mtrender's ExtractOptions::Cones): 'closed' only for a
  // closed surface seen from outside (closed_surface.js; setSurface gives it), 'always', 'off'.
  cones: 'closed',
  memoryFraction: 0.6,
  // While a still view's loads are pending, its update runs at most every this many ms (0: every
  // frame): no image is drawn before they end, and each update walks every node (below).
  stillLoadingMs: 250,
});

export class ExtractRender {
  /**
   * @param {object} scene buildScene()
   * @param {object|null} cache PatchCache (cache.js) or null: everything counts as resident
   * @param {object|null} server PatchServer (server.js) or null
   * @param {object} options see defaultExtractOptions
   */
  constructor(scene, cache, server, options) {
    this.scene = scene;
    this.cache = cache;
    this.server = server;
    this.options = Object.assign(defaultExtractOptions(), options || {});
    this.time = new TimeModel();
    this.lodScale = 1;
    this.budgetScale = 1;
    this.stillTriangles = 0;  // a still view's cut may hold this many triangles (MTObject: K chunks at their measured rate)
    this.aheadTriangles = 0;  // the same for a moving view's look-ahead (loadAheadOf; MTObject sets it)
    this.frameBudget = 0;
    this.frozen = false;
    this.cutVersion = 0;  // counts the cut's changes (an arc added or removed)
    this.smoothBudget = 0;
    this.slackFrames = 0;
    this.frameMsAvg = 0;
    this.lastFrameMs = 0;
    this.lastDrawn = 0;
    this.wanted = new Map();
    this.consecutive = new Map();
    this.surface = null;  // ClosedSurface of the coarsest cut; null: not known yet (no cone culling)
    this.coneEye = null;
    this.coneFlag = false;
    this.coneHeld = false;
    this.stillKey = null;  // stillRepeats: what the last still update ran with
    this.stillStats = null;
    this.stillAt = 0;  // when the last still update ran (not skipped)
  }

  /** The file's coarsest cut as a ClosedSurface (closed_surface.js), once it is decoded. */
  setSurface(surface) {
    this.surface = surface;
    this.coneEye = null;
  }
  /** Whether normal cones cull for this view's eye (memoised for the last eye; held for the views ahead). */
  coneOn(view) {
    if (this.options.cones === 'always') return true;
    if (this.options.cones === 'off') return false;
    return this.outsideClosed(view);
  }
  /**
   * Whether the file is a closed surface and this view's eye is outside the solid it bounds
   * (closed_surface.js): no back face can then be seen. Memoised for the last eye; held for the
   * views ahead.
   */
  outsideClosed(view) {
    if (!this.surface) return false;
    const e = view.eye;
    if (!this.coneHeld && !(this.coneEye && this.coneEye[0] === e[0] && this.coneEye[1] === e[1] && this.coneEye[2] === e[2])) {
      this.coneFlag = this.surface.eyeOutside(e);
      this.coneEye = [e[0], e[1], e[2]];
    }
    return this.coneFlag;
  }

  collectIn(n, out) {
    out.length = 0;
    const { nodes, inArcs } = this.scene;
    for (let k = 0; k < nodes.inArcCount[n]; ++k) this.pushArc(inArcs[nodes.firstInArc[n] + k], out);
    return out;
  }
  collectOut(n, out) {
    out.length = 0;
    const { nodes } = this.scene;
    for (let k = 0; k < nodes.arcCount[n]; ++k) this.pushArc(nodes.firstArc[n] + k, out);
    return out;
  }
  /** Appends arc a's patches to `out` (returned). */
  pushArc(a, out) {
    const { arcs, arcPatches } = this.scene;
    for (let q = 0; q < arcs.patchCount[a]; ++q) out.push(arcPatches[arcs.firstPatch[a] + q]);
    return out;
  }
  /** 'ready' when every patch of arc a is, 'bad' when one is damaged, else 'absent'. */
  arcState(a) {
    const { arcs, arcPatches } = this.scene;
    let ready = true;
    for (let q = 0; q < arcs.patchCount[a]; ++q) {
      const s = this.cache.state(arcPatches[arcs.firstPatch[a] + q]);
      if (s === 'bad') return 'bad';
      if (s !== 'ready') ready = false;
    }
    return ready ? 'ready' : 'absent';
  }
  isRefineCandidate(n) { return this.inS[n] && !this.scene.nodes.source[n] && this.succIn[n] === 0; }
  isCoarsenCandidate(n) { return !this.inS[n] && !this.scene.nodes.sink[n] && this.predOut[n] === 0; }
  addCutArc(a) {
    ++this.cutVersion;
    this.cutPos[a] = this.cutArcs.length;
    this.cutArcs.push(a);
  }
  removeCutArc(a) {
    ++this.cutVersion;
    const pos = this.cutPos[a];
    const last = this.cutArcs[this.cutArcs.length - 1];
    this.cutArcs[pos] = last;
    this.cutPos[last] = pos;
    this.cutArcs.pop();
    this.cutPos[a] = 0xffffffff;
  }
  patchesBad(ids) {
    if (!this.cache) return false;
    for (const id of ids) if (this.cache.isBad(id)) return true;
    return false;
  }
  bytesOf(ids) {
    let b = 0;
    for (const id of ids) b += this.scene.decodedBytes[id];
    return b;
  }

  /** The coarsest cut; with a cache, asks for its patches (urgently). */
  start() {
    const { nodes, arcs } = this.scene;
    const n = nodes.count;
    this.inS = new Uint8Array(n);
    this.badNode = new Uint8Array(n);
    this.succIn = new Uint32Array(n);
    this.predOut = new Uint32Array(n);
    this.cutPos = new Uint32Array(arcs.count).fill(0xffffffff);
    this.cutArcs = [];
    this.triangles = 0;
    this.visibleTriangles = 0;
    this.cutPatchCount = 0;
    this.cutBytes = 0;
    this.scratch = [];
    this.scratch2 = [];
    for (let i = 0; i < n; ++i) this.inS[i] = nodes.sink[i] ? 0 : 1;
    const start = [];
    for (let a = 0; a < arcs.count; ++a) {
      const from = arcs.from[a], to = arcs.to[a];
      if (this.inS[to]) ++this.succIn[from];
      if (!this.inS[from]) ++this.predOut[to];
      if (this.inS[from] && !this.inS[to]) {
        this.addCutArc(a);
        this.triangles += arcs.triangles[a];
        this.cutPatchCount += arcs.patchCount[a];
        this.pushArc(a, start);
      }
    }
    this.cutBytes = this.bytesOf(start);
    this.startPatches = start;
    if (!this.cache) return;
    this.server.submit(start.map((id) => ({ id, urgency: Urgency.UrgentUp })), 0);
  }
  /**
   * Pins the coarsest cut's patches that arrived (call once start()'s loads are done): once as the
   * cut's (released when a refinement leaves them), and once more for the whole run, so that they
   * are never evicted and a frame over its budget can always coarsen to them at once
   * (coarsenThrough ends on them; a few whole-model nodes above the partition's levels hold
   * patches that a 2 MiB cache evicts while the cut is finer, and waiting for them drew cuts of
   * 2-6x the budget for 5-14 frames after a slow one). They are the file's smallest cut.
   */
  pinStart() {
    if (!this.cache) return;
    for (const id of this.startPatches) this.cache.pinAll([id, id]);
  }

  arcVisible(arc, view) {
    if (!this.options.cull) return true;
    const { nodes, arcs } = this.scene;
    const s = arcs.cullNode[arc];
    const c0 = nodes.center[3 * s], c1 = nodes.center[3 * s + 1], c2 = nodes.center[3 * s + 2];
    const radius = nodes.radius[s];
    for (const p of view.planes) if (p[0] * c0 + p[1] * c1 + p[2] * c2 + p[3] < -radius) return false;
    if (s === arcs.from[arc] && nodes.coneCutoff[s] > 0 && this.coneOn(view)) {
      if (this.coneAway(s, c0, c1, c2, radius, view)) return false;
    }
    return true;
  }
  /**
   * Every triangle of the arc's patches faces the eye (its from-node's normal cone, as arcVisible
   * reads it): none shows its back face, whatever the rest of the surface (MTObject's back pass).
   */
  arcFacesEye(arc, view) {
    const { nodes, arcs } = this.scene;
    const s = arcs.cullNode[arc];
    if (s !== arcs.from[arc] || !(nodes.coneCutoff[s] > 0)) return false;
    const c = nodes.center, e = view.eye;
    // The eye mirrored through the sphere's centre: the cone faces the eye when every triangle
    // faces away from the mirrored eye.
    const mirrored = { eye: [2 * c[3 * s] - e[0], 2 * c[3 * s + 1] - e[1], 2 * c[3 * s + 2] - e[2]] };
    return this.coneAway(s, c[3 * s], c[3 * s + 1], c[3 * s + 2], nodes.radius[s], mirrored);
  }
  // Every triangle of the node's fragment faces away from the eye (normal-cone culling).
  coneAway(s, c0, c1, c2, radius, view) {
    const { nodes } = this.scene;
    const v0 = c0 - view.eye[0], v1 = c1 - view.eye[1], v2 = c2 - view.eye[2];
    const d = Math.sqrt(v0 * v0 + v1 * v1 + v2 * v2);
    if (!(d > radius)) return false;
    const ax = nodes.coneAxis;
    const cosA = ax[3 * s] * (v0 / d) + ax[3 * s + 1] * (v1 / d) + ax[3 * s + 2] * (v2 / d);
    const ang = Math.acos(Math.min(Math.max(cosA, -1), 1));
    const alpha = Math.acos(nodes.coneCutoff[s]), beta = Math.asin(radius / d);
    return ang + alpha + beta < 1.5707963267948966;
  }

  screenError(node, view) {
    const { nodes } = this.scene;
    if (nodes.sink[node]) return Number.POSITIVE_INFINITY;
    const c0 = nodes.center[3 * node], c1 = nodes.center[3 * node + 1], c2 = nodes.center[3 * node + 2];
    const radius = nodes.radius[node];
    if (this.options.cull) {
      for (const p of view.planes) if (p[0] * c0 + p[1] * c1 + p[2] * c2 + p[3] < -radius) return 0;
      if (nodes.coneCutoff[node] > 0 && this.coneOn(view) && this.coneAway(node, c0, c1, c2, radius, view)) return 0;
    }
    const v0 = c0 - view.eye[0], v1 = c1 - view.eye[1], v2 = c2 - view.eye[2];
    let d = Math.sqrt(v0 * v0 + v1 * v1 + v2 * v2) - radius;
    d = Math.max(d, view.nearPlane);
    return nodes.error[node] * view.pixelsPerUnit / d;
  }

  tryRefine(n) {
    const inP = this.collectIn(n, this.scratch);
    if (this.cache && !this.cache.pinAll(inP)) return false;
    if (this.cache) this.cache.unpinAll(this.collectOut(n, this.scratch2));
    this.moveDown(n);
    return true;
  }
  // Refines n in the cut's structure and counts (the patches' pins are the caller's).
  moveDown(n) {
    const { nodes, arcs, inArcs } = this.scene;
    const inP = this.collectIn(n, this.scratch), inBytes = this.bytesOf(inP), inCount = inP.length;
    const outP = this.collectOut(n, this.scratch2);
    this.inS[n] = 0;
    for (let k = 0; k < nodes.arcCount[n]; ++k) {
      const a = nodes.firstArc[n] + k;
      this.removeCutArc(a);
      ++this.predOut[arcs.to[a]];
    }
    for (let k = 0; k < nodes.inArcCount[n]; ++k) {
      const a = inArcs[nodes.firstInArc[n] + k];
      --this.succIn[arcs.from[a]];
      this.addCutArc(a);
    }
    this.triangles += nodes.inTriangles[n] - nodes.outTriangles[n];
    this.cutPatchCount += inCount - outP.length;
    this.cutBytes += inBytes - this.bytesOf(outP);
  }
  tryCoarsen(n) {
    const outP = this.collectOut(n, this.scratch);
    if (this.cache && !this.cache.pinAll(outP)) return false;
    if (this.cache) this.cache.unpinAll(this.collectIn(n, this.scratch2));
    this.moveUp(n);
    return true;
  }
  // Coarsens n in the cut's structure and counts (the patches' pins are the caller's).
  moveUp(n) {
    const { nodes, arcs, inArcs } = this.scene;
    const outP = this.collectOut(n, this.scratch), outBytes = this.bytesOf(outP), outCount = outP.length;
    const inP = this.collectIn(n, this.scratch2);
    this.inS[n] = 1;
    for (let k = 0; k < nodes.inArcCount[n]; ++k) {
      const a = inArcs[nodes.firstInArc[n] + k];
      ++this.succIn[arcs.from[a]];
      this.removeCutArc(a);
    }
    for (let k = 0; k < nodes.arcCount[n]; ++k) {
      const a = nodes.firstArc[n] + k;
      --this.predOut[arcs.to[a]];
      this.addCutArc(a);
    }
    this.triangles += nodes.outTriangles[n] - nodes.inTriangles[n];
    this.cutPatchCount += outCount - inP.length;
    this.cutBytes += outBytes - this.bytesOf(inP);
  }
  visibleDelta(n, refine, view) {
    const { nodes, arcs, inArcs } = this.scene;
    let i = 0, o = 0;
    for (let k = 0; k < nodes.inArcCount[n]; ++k) {
      const a = inArcs[nodes.firstInArc[n] + k];
      if (this.arcVisible(a, view)) i += arcs.triangles[a];
    }
    for (let k = 0; k < nodes.arcCount[n]; ++k) {
      const a = nodes.firstArc[n] + k;
      if (this.arcVisible(a, view)) o += arcs.triangles[a];
    }
    return refine ? i - o : o - i;
  }
  want(ids, u) {
    for (const id of ids) {
      const w = this.wanted.get(id);
      if (w === undefined || u > w) this.wanted.set(id, u);
    }
  }
  /**
   * A frame whose time says nothing about drawing (it drew nothing; the browser kept the image):
   * it does not feed the model, and the last drawn frame's time no longer caps the budget (one slow
   * frame before a run of such frames, e.g. the one that made the still image's target, would
   * otherwise pin the budget at its floor for as long as the run lasts).
   */
  frameSkipped() {
    this.lastDrawn = 0;
    this.lastFrameMs = 0;
  }
  frameDone(drawnTriangles, frameMs) {
    this.time.add(drawnTriangles, frameMs);
    this.frameMsAvg = this.frameMsAvg === 0 ? frameMs : 0.9 * this.frameMsAvg + 0.1 * frameMs;
    this.lastFrameMs = frameMs;
    this.lastDrawn = drawnTriangles;
    ++this.slackFrames;
  }
  nextBudget(extractMs) {
    const kAim = 0.7;
    let budget;
    if (this.options.fixedTriangles) {
      budget = this.options.fixedTriangles;
    } else {
      const aimMs = kAim * this.options.budgetMs;
      const target = this.time.trianglesFor(aimMs - extractMs);
      if (this.smoothBudget === 0) this.smoothBudget = Math.min(target, 20000.0);
      else if (target < this.smoothBudget) this.smoothBudget = Math.max(target, 0.7 * this.smoothBudget);
      else if (this.budgetScale === 1) this.smoothBudget = Math.min(this.smoothBudget + 0.25 * (target - this.smoothBudget), 1.25 * this.smoothBudget);
      else this.smoothBudget = Math.min(this.smoothBudget + 0.5 * (target - this.smoothBudget), 1.5 * this.smoothBudget);
      if (this.lastDrawn > 0 && this.lastFrameMs > 0 && (this.lastFrameMs > aimMs || this.lastDrawn >= 0.5 * this.frameBudget))
        this.smoothBudget = Math.min(this.smoothBudget, this.lastDrawn * aimMs / this.lastFrameMs);
      budget = Math.max(this.smoothBudget, 1000.0);
    }
    this.frameBudget = budget;
    if (this.budgetScale > 1 && !this.options.fixedTriangles) return Math.max(budget * this.budgetScale, this.stillTriangles);
    return budget * this.budgetScale;
  }
  submitRequests(frame, st) {
    if (!this.cache) return;
    const reqs = [];
    const nextConsecutive = new Map();
    const touched = [];
    for (const [id, u] of this.wanted) {
      const s = this.cache.state(id);
      if (s === 'ready') { touched.push(id); continue; }
      if (s === 'bad') continue;
      if (u > Urgency.Prefetch) ++st.misses;
      if (s === 'loading') continue;
      const c = (this.consecutive.get(id) || 0) + 1;
      nextConsecutive.set(id, c);
      reqs.push({ id, urgency: u, consecutive: c });
    }
    this.consecutive = nextConsecutive;
    this.cache.touch(touched, frame);
    // Among equal urgency and age, the order of the wants (the sort is stable): the traversals want
    // the largest screen errors first.
    reqs.sort((a, b) => (a.urgency !== b.urgency ? b.urgency - a.urgency : b.consecutive - a.consecutive));
    let loadBudget = this.options.loadBudget;
    if (!loadBudget) {
      const ms = this.server.meanLoadMs();
      loadBudget = Math.floor(Math.min(Math.max(ms > 0 ? this.options.budgetMs / ms : 64, 8), 512));
      // A still view (budgetScale > 1: its image is drawn over many frames): the loads no longer
      // compete with a frame that must show motion, and a longer queue lets the server coalesce
      // neighbouring payloads into fewer range reads. Measured on the 53 M build: docs/web.md.
      if (this.budgetScale > 1) loadBudget = 512;
    }
    const out = [];
    let ahead = 0;
    for (const r of reqs) {
      if (out.length >= loadBudget) break;
      if (r.urgency === Urgency.Ahead && ++ahead > this.options.aheadBatch) break;  // Ahead comes last
      out.push({ id: r.id, urgency: r.urgency });
      if (r.urgency <= Urgency.Prefetch) ++st.prefetches;
      else ++st.requests;
    }
    this.server.submit(out, frame);
  }

  /**
   * For a frame that leaves the cut as it is (it draws part of a still image): advances the render
   * budget and asks for what the refinements of the cut beyond it would need (wantBelowCut).
   */
  requestAhead(frame, view) {
    const t0 = now();
    const st = this.newStats();
    this.wanted.clear();
    const extractMs = this.options.extractMs > 0 ? this.options.extractMs : Math.min(2.0, this.options.budgetMs / 20);
    const budget = this.nextBudget(extractMs);
    if (!this.cache || !this.stillRepeats('ahead', view, budget)) {
      this.wantBelowCut(view, this.options.pixelTolerance * this.lodScale, budget);
      this.submitRequests(frame, st);
      if (this.cache) this.stillRecord('ahead', view, budget, this.options.pixelTolerance * this.lodScale);
    }
    st.budgetTriangles = budget;
    st.modelA = this.time.a;
    st.modelB = this.time.b * 1e6;
    st.triangles = this.triangles;
    st.patches = this.cutPatchCount;
    st.lodScale = this.lodScale;
    st.extractMs = now() - t0;
    return st;
  }

  /**
   * The refinements a still view's cut goes on to, as if every patch were resident:
   * refineWithinBudget's walk replayed without applying it. A node refines once every node it
   * refines into has (the refinement candidate's rule), the largest screen error first, until the
   * errors reach `tau`; the visible triangles count against `budget` and the cut's decoded bytes
   * against `pinLimit`. Returns {order, urgency}: the nodes in the order they refine, Needed while
   * within both limits, then Prefetch on to twice the budget.
   */
  simulateBelowCut(view, tau, budget, pinLimit = Infinity) {
    const { nodes, arcs, inArcs } = this.scene;
    const heap = new Heap(true);
    for (let n = 0; n < nodes.count; ++n)
      if (this.isRefineCandidate(n) && !this.badNode[n]) heap.push(this.screenError(n, view), n);
    // A node's successors still in S once the refinements so far are applied (succIn, simulated).
    const left = new Map();
    let triangles = this.visibleTriangles, bytes = this.cutBytes, needed = true;
    const order = [], urgency = [];
    while (!heap.empty()) {
      const err = heap.topErr(), node = heap.topNode();
      heap.pop();
      if (err <= tau) break;
      triangles += this.visibleDelta(node, true, view);
      if (triangles > 2 * budget) break;
      // The memory rule of refineWithinBudget: the cut's bytes and the node's new patches.
      const inBytes = this.bytesOf(this.collectIn(node, this.scratch));
      needed = needed && triangles <= budget && bytes + inBytes <= pinLimit;
      bytes += inBytes - this.bytesOf(this.collectOut(node, this.scratch));
      order.push(node);
      urgency.push(needed ? Urgency.Needed : Urgency.Prefetch);
      for (let k = 0; k < nodes.inArcCount[node]; ++k) {
        const m = arcs.from[inArcs[nodes.firstInArc[node] + k]];
        if (nodes.source[m] || this.badNode[m]) continue;
        const l = (left.has(m) ? left.get(m) : this.succIn[m]) - 1;
        left.set(m, l);
        if (l === 0) heap.push(this.screenError(m, view), m);
      }
    }
    return { order, urgency };
  }

  /**
   * Asks for the patches a simulated refinement (simulateBelowCut) ends with, and no others: the
   * arcs into its nodes from nodes it leaves in S, each at its node's urgency (or at `urgency`),
   * in the order the nodes refine (submitRequests keeps it among equals: the coarser refinements
   * first). An arc between two Needed nodes is only passed through: refineThrough applies both
   * refinements in one update, so the arc is never drawn and its patches need not be loaded. (An
   * arc between two Prefetch nodes is left out too: those nodes refine only once the budget lets
   * them into the Needed walk, whose final arcs are then asked for.) `absentLimit`: stop after
   * that many patches not in the cache (the look-ahead's batch).
   */
  wantFinal(sim, urgency, absentLimit = Infinity) {
    const { nodes, arcs, inArcs } = this.scene;
    const refinedAt = new Map();
    for (let i = 0; i < sim.order.length; ++i) refinedAt.set(sim.order[i], sim.urgency[i]);
    for (let i = 0; i < sim.order.length; ++i) {
      const n = sim.order[i], u = urgency ?? sim.urgency[i];
      for (let k = 0; k < nodes.inArcCount[n]; ++k) {
        const a = inArcs[nodes.firstInArc[n] + k];
        if (refinedAt.get(arcs.from[a]) === sim.urgency[i]) continue;
        const ids = this.scratch2;
        ids.length = 0;
        this.pushArc(a, ids);
        this.want(ids, u);
        if (absentLimit === Infinity) continue;
        for (const id of ids) if (this.cache.state(id) === 'absent' && this.wanted.get(id) === u) --absentLimit;
        if (absentLimit <= 0) return;
      }
    }
  }

  /**
   * A still view's loads (MTObject sets budgetScale > 1 once the camera stops; its image is drawn
   * over many frames): the patches of the cut the tolerance or the budget stops at, however many
   * levels below the cut it lies, asked for at once (Needed; on to twice the budget at Prefetch).
   * Asked for a level at a time, as the cut refines, a still view waited for as many rounds of
   * requests and decoding as the DAG has levels between the moving cut and the tolerance; and the
   * levels on the way, drawn by no image, were about half of its decoding (docs/web.md).
   */
  wantBelowCut(view, tau, budget, urgency, absentLimit = Infinity) {
    const pinLimit = this.cache ? this.options.memoryFraction * this.cache.capBytes : Infinity;
    const sim = this.simulateBelowCut(view, tau, budget, pinLimit);
    this.wantFinal(sim, urgency, absentLimit);
  }

  /**
   * A still update's refinements through the levels it does not draw (wantBelowCut loads only the
   * arcs the simulated refinement ends with): the largest subset X of the simulation's Needed
   * nodes that can be refined now, applied at once. A node is in X when every successor it has in
   * S is in X (the candidate rule) and every arc into it from a node outside X, which the cut keeps,
   * has its patches ready; dropping a node from X drops its predecessors in X and the successors in
   * X whose arc from it is not ready, until nothing changes. Only the arcs X ends with are pinned;
   * those it passes through are added to the cut and removed again before anything is drawn. A
   * final arc whose patch is damaged marks its node bad, as refineOrRequest does. Returns whether
   * it marked one.
   */
  refineThrough(p, sim) {
    let marked = false;
    const { nodes, arcs, inArcs } = this.scene;
    const inX = new Set();
    for (let i = 0; i < sim.order.length && sim.urgency[i] === Urgency.Needed; ++i) inX.add(sim.order[i]);
    const drop = [];
    for (const n of inX) {
      for (let k = 0; k < nodes.inArcCount[n]; ++k) {
        const a = inArcs[nodes.firstInArc[n] + k];
        if (inX.has(arcs.from[a])) continue;
        const s = this.arcState(a);
        if (s === 'bad' && !(this.badNode[n] & 1)) this.badNode[n] |= 1, marked = true;
        if (s !== 'ready') {
          drop.push(n);
          break;
        }
      }
    }
    while (drop.length) {
      const n = drop.pop();
      if (!inX.delete(n)) continue;
      for (let k = 0; k < nodes.inArcCount[n]; ++k) {
        const m = arcs.from[inArcs[nodes.firstInArc[n] + k]];
        if (inX.has(m)) drop.push(m);  // n stays in S: m is no candidate
      }
      for (let k = 0; k < nodes.arcCount[n]; ++k) {
        const a = nodes.firstArc[n] + k, t = arcs.to[a];
        if (inX.has(t) && this.arcState(a) !== 'ready') drop.push(t);  // the cut keeps n -> t
      }
    }
    if (inX.size === 0) return marked;
    const order = sim.order.filter((n) => inX.has(n));
    let bytes = this.cutBytes;
    const pin = [], unpin = [];
    for (const n of order) {
      for (let k = 0; k < nodes.inArcCount[n]; ++k) {
        const a = inArcs[nodes.firstInArc[n] + k];
        if (!inX.has(arcs.from[a])) this.pushArc(a, pin);
      }
      for (let k = 0; k < nodes.arcCount[n]; ++k) {
        const a = nodes.firstArc[n] + k;
        if (!this.inS[arcs.to[a]]) this.pushArc(a, unpin);
      }
      bytes += this.bytesOf(this.collectIn(n, this.scratch)) - this.bytesOf(this.collectOut(n, this.scratch));
    }
    if (bytes > p.pinLimit) {
      p.memoryFull = true;
      return marked;
    }
    const pinned = this.cache.pinAll(pin);
    console.assert(pinned, 'refineThrough: a final arc is not ready');
    this.cache.unpinAll(unpin);
    for (const n of order) {
      console.assert(this.isRefineCandidate(n), 'refineThrough: a node refined before its successors');
      this.visibleTriangles += this.visibleDelta(n, true, p.view);
      this.moveDown(n);
      ++p.st.refinements;
    }
    for (const n of order) this.pushAround(p, n);
    return marked;
  }

  /**
   * A moving view's look-ahead: the loads a still view here would ask for (wantBelowCut, down to the
   * tolerance, as a still update with `aheadTriangles` for its budget), at Urgency.Ahead, after
   * every other request, one batch of at most `aheadBatch` patches at a time (the walk stops at the
   * first `aheadBatch` that are not resident), only after a frame within `aheadGate` of its budget.
   * The cache's LRU order keeps what the cut and prefetch want over these: they are wanted last.
   * The moving cut stays within the render budget, but when the camera stops, the patches its image
   * needs are mostly in the cache: on a 53 M build a still view waited ~2 s for its ~1300 patches'
   * loads after the stop. Decoding them while moving costs the frames some of the cores on a
   * software renderer, hence one batch at a time and only while the frames have slack
   * (docs/web.md, "Loading ahead").
   */
  loadAheadOf(view, tau) {
    if (!this.options.loadAhead || !this.cache || this.aheadTriangles <= 0) return;
    if (!(this.lastFrameMs > 0 && this.lastFrameMs <= this.options.aheadGate * this.options.budgetMs)) return;
    if (this.server.aheadInFlight > 0) return;
    this.wantBelowCut(view, tau, this.aheadTriangles, Urgency.Ahead, this.options.aheadBatch);
  }

  newStats() {
    return {
      extractMs: 0, triangles: 0, patches: 0, drawnPatches: 0, drawnTriangles: 0, misses: 0, requests: 0,
      prefetches: 0, refinements: 0, coarsenings: 0, maxScreenError: 0, budgetTriangles: 0, lodScale: 1,
      memoryFull: false, interrupted: false, modelA: 0, modelB: 0, repeated: false,
    };
  }

  /**
   * Whether a still update (`kind`: 'update' or 'ahead', requestAhead's) would repeat the last one,
   * which it may then skip: no patch arrived, left the cache, was cancelled or was refused room
   * since, and the view, the cut, the tolerance and the budget (within 1%) are those it ran with.
   * A still view's loads take 50-60 frames, many of which change none of it, and each update walks
   * every node.
   */
  stillRepeats(kind, view, budget, sameCache = true) {
    const k = this.stillKey;
    return k !== null && k.kind === kind && (!sameCache || k.generation === this.cache.generation) && k.cutVersion === this.cutVersion &&
      k.tau === this.options.pixelTolerance * this.lodScale && Math.abs(k.budget - budget) <= 0.01 * k.budget && k.ppu === view.pixelsPerUnit &&
      k.eye[0] === view.eye[0] && k.eye[1] === view.eye[1] && k.eye[2] === view.eye[2] &&
      k.planes.every((x, i) => x === view.planes[i >> 2][i & 3]);
  }
  // `tau`: the tolerance the update ran with (its end may have moved lodScale: the next must run).
  stillRecord(kind, view, budget, tau) {
    this.stillKey = { kind, generation: this.cache.generation, cutVersion: this.cutVersion, tau, budget,
      ppu: view.pixelsPerUnit, eye: view.eye.slice(), planes: view.planes.flat() };
  }

  /**
   * One frame's cut update for `view`; `predicted`: the views of the next frames, extrapolated (an
   * array, or one view), whose frusta prefetching enlarges the current one to.
   */
  update(frame, view, predicted) {
    const st = this.newStats();
    const t0 = now();
    const extractMs = this.options.extractMs > 0 ? this.options.extractMs : Math.min(2.0, this.options.budgetMs / 20);
    const p = {
      view, st, t0, deadline: t0 + extractMs, tau: this.options.pixelTolerance * this.lodScale, budget: 0, pinLimit: 0,
      refine: new Heap(true), coarse: new Heap(false), maxErr: 0, ops: 0, urgentLeft: 4, memoryFull: false,
      // A still view with a cache (budgetScale > 1): its loads come from wantBelowCut, and
      // refineThrough refines through the levels whose patches are not loaded.
      still: this.budgetScale > 1 && this.cache !== null && !this.frozen, unrefined: [],
    };
    p.timeUp = () => {
      if ((++p.ops & 7) !== 0) return false;
      if (now() < p.deadline) return false;
      st.interrupted = true;
      return true;
    };
    p.budget = this.nextBudget(extractMs);
    // A still update is skipped when it would repeat the last one; and while the loads it asked
    // for are pending, also when patches arrived, until stillLoadingMs after the last one ran: its
    // requests stand (the server takes the next as each load ends), no image is drawn before they
    // end (MTObject), and the refinements the arrivals allow can wait for the update after. Each
    // still update walks every node (simulateBelowCut): on the 53 M armadillo's still view, 76
    // updates took 0.36 s of the page's thread while the workers decoded on the same two cores.
    const loading = !!this.server && !this.server.idle() && t0 - this.stillAt < this.options.stillLoadingMs;
    if (p.still && this.stillStats && !this.stillStats.interrupted && this.stillRepeats('update', view, p.budget, !loading))
      return Object.assign({}, this.stillStats, { refinements: 0, coarsenings: 0, requests: 0, prefetches: 0, extractMs: now() - t0, repeated: true });
    if (p.still) this.stillAt = t0;
    this.wanted.clear();
    st.budgetTriangles = p.budget;
    st.modelA = this.time.a;
    st.modelB = this.time.b * 1e6;
    this.visibleTriangles = 0;
    for (const a of this.cutArcs) if (this.arcVisible(a, view)) this.visibleTriangles += this.scene.arcs.triangles[a];
    p.pinLimit = this.cache ? this.options.memoryFraction * this.cache.capBytes : Number.POSITIVE_INFINITY;
    this.fillHeaps(p);
    if (!this.frozen) {
      // A still view only gets finer: its image is drawn over as many frames as it takes, each
      // within one frame's budget, so its cut need not shrink when the budget does (extract.cpp).
      if (this.budgetScale === 1) this.coarsenOverBudget(p);
      this.refineWithinBudget(p);
      if (p.still) {
        // Whatever the deadline: a still frame's image stays on screen meanwhile, and without this
        // walk the still view would ask for nothing. It asks for the final arcs down to the
        // tolerance and nothing finer: the refinements below the tolerance that prefetch() asks
        // for would only delay its image (it waits for the loads) and take the workers' time.
        // A damaged final patch marks its node bad: the walk then stops above it, whose arcs become
        // final (and are loaded); walked again at once, so that this update asks for them.
        let sim = this.simulateBelowCut(view, p.tau, p.budget, p.pinLimit);
        for (let pass = 0; pass < 4 && this.refineThrough(p, sim); ++pass) sim = this.simulateBelowCut(view, p.tau, p.budget, p.pinLimit);
        this.wantFinal(sim);
        for (let i = 0; i < p.unrefined.length; i += 2)
          if (this.isRefineCandidate(p.unrefined[i])) p.maxErr = Math.max(p.maxErr, p.unrefined[i + 1]);
      }
      this.coarsenFarBelow(p);
    }
    while (!p.refine.empty() && !this.isRefineCandidate(p.refine.topNode())) p.refine.pop();
    if (!p.refine.empty()) p.maxErr = Math.max(p.maxErr, p.refine.topErr());
    st.maxScreenError = p.maxErr;
    if (this.cache && this.options.prefetch && !this.frozen && !p.still && now() < p.deadline + (p.deadline - p.t0)) {
      this.prefetch(p, predicted);
      this.loadAheadOf(view, p.tau);
    }
    this.submitRequests(frame, st);
    if (p.memoryFull) this.lodScale = Math.min(this.lodScale * 1.1, 64.0);
    else if (this.lodScale > 1 && this.cutBytes < 0.8 * p.pinLimit) this.lodScale = Math.max(1.0, this.lodScale * 0.97);
    st.memoryFull = p.memoryFull;
    st.lodScale = this.lodScale;
    st.triangles = this.triangles;
    st.patches = this.cutPatchCount;
    st.extractMs = now() - t0;
    // A copy: the caller may change the figures it is given (MTObject sets maxScreenError).
    if (p.still) this.stillRecord('update', view, p.budget, p.tau), (this.stillStats = Object.assign({}, st));
    else this.stillKey = null;
    return st;
  }

  fillHeaps(p) {
    const { nodes } = this.scene;
    for (let n = 0; n < nodes.count; ++n) {
      if (this.isRefineCandidate(n)) p.refine.push(this.screenError(n, p.view), n);
      else if (this.isCoarsenCandidate(n)) p.coarse.push(this.screenError(n, p.view), n);
      else if (nodes.source[n] && this.succIn[n] === 0) p.maxErr = Math.max(p.maxErr, this.screenError(n, p.view));
    }
  }
  pushAround(p, n) {
    const { nodes, arcs, inArcs } = this.scene;
    if (this.isRefineCandidate(n)) p.refine.push(this.screenError(n, p.view), n);
    if (this.isCoarsenCandidate(n)) p.coarse.push(this.screenError(n, p.view), n);
    for (let k = 0; k < nodes.inArcCount[n]; ++k) {
      const m = arcs.from[inArcs[nodes.firstInArc[n] + k]];
      if (this.isRefineCandidate(m)) p.refine.push(this.screenError(m, p.view), m);
    }
    for (let k = 0; k < nodes.arcCount[n]; ++k) {
      const m = arcs.to[nodes.firstArc[n] + k];
      if (this.isCoarsenCandidate(m)) p.coarse.push(this.screenError(m, p.view), m);
    }
  }
  popStaleCoarse(p) {
    while (!p.coarse.empty() && (!this.isCoarsenCandidate(p.coarse.topNode()) || (this.badNode[p.coarse.topNode()] & 2))) p.coarse.pop();
  }
  coarsenTop(p, u) {
    const node = p.coarse.topNode();
    p.coarse.pop();
    const dc = this.visibleDelta(node, false, p.view);
    if (this.tryCoarsen(node)) {
      this.visibleTriangles += dc;
      ++p.st.coarsenings;
      this.pushAround(p, node);
      return;
    }
    // Over the budget: through the levels above whose patches are not loaded, if need be.
    if (u === Urgency.UrgentUp && this.cache && this.coarsenThrough(p, node)) return;
    const ids = this.collectOut(node, this.scratch);
    if (this.patchesBad(ids)) this.badNode[node] |= 2;
    else this.want(ids, u);
  }
  /**
   * Coarsens `node`, whose out-arcs' patches are not ready, together with the nodes above it that
   * it takes to end on arcs whose patches are: refineThrough loads only the cut a still view ends
   * with, so when the camera moves on, the levels it passed through are not in the cache, and a
   * frame over its budget must not wait for them (nor draw the still cut meanwhile). The set Y
   * starts as {node}; a node in Y adds its predecessors not in S (a node joins S after them), and
   * an arc from Y to a node outside it whose patches are not ready adds that node, until every arc
   * Y ends with is ready (the coarsest cut's are: pinned from the start). Y is applied finer nodes
   * first; only the arcs it ends with are pinned. Returns false (nothing done) when it would have
   * to coarsen a sink.
   */
  coarsenThrough(p, node) {
    const { nodes, arcs, inArcs } = this.scene;
    const inY = new Set([node]), work = [node];
    while (work.length) {
      const y = work.pop();
      for (let k = 0; k < nodes.inArcCount[y]; ++k) {
        const m = arcs.from[inArcs[nodes.firstInArc[y] + k]];
        if (!this.inS[m] && !inY.has(m)) inY.add(m), work.push(m);
      }
      for (let k = 0; k < nodes.arcCount[y]; ++k) {
        const a = nodes.firstArc[y] + k, t = arcs.to[a];
        if (inY.has(t) || this.arcState(a) === 'ready') continue;
        if (nodes.sink[t]) return false;
        inY.add(t), work.push(t);
      }
    }
    const pin = [], unpin = [];
    for (const y of inY) {
      for (let k = 0; k < nodes.arcCount[y]; ++k) {
        const a = nodes.firstArc[y] + k;
        if (!inY.has(arcs.to[a])) this.pushArc(a, pin);
      }
      for (let k = 0; k < nodes.inArcCount[y]; ++k) {
        const a = inArcs[nodes.firstInArc[y] + k];
        if (this.inS[arcs.from[a]]) this.pushArc(a, unpin);
      }
    }
    const pinned = this.cache.pinAll(pin);
    console.assert(pinned, 'coarsenThrough: a final arc is not ready');
    this.cache.unpinAll(unpin);
    // Finer nodes first: a node joins S once all its predecessors are in it.
    const order = [...inY].filter((y) => this.predOut[y] === 0);
    for (let i = 0; i < order.length; ++i) {
      const y = order[i];
      this.visibleTriangles += this.visibleDelta(y, false, p.view);
      this.moveUp(y);
      ++p.st.coarsenings;
      for (let k = 0; k < nodes.arcCount[y]; ++k) {
        const t = arcs.to[nodes.firstArc[y] + k];
        if (inY.has(t) && this.predOut[t] === 0 && !this.inS[t]) order.push(t);
      }
    }
    console.assert(order.length === inY.size, 'coarsenThrough: a node of Y was not coarsened');
    for (const y of order) this.pushAround(p, y);
    return true;
  }
  coarsenOverBudget(p) {
    while (this.visibleTriangles > p.budget && !p.st.interrupted) {
      this.popStaleCoarse(p);
      if (p.coarse.empty() || p.timeUp()) break;
      this.coarsenTop(p, Urgency.UrgentUp);
    }
  }
  probeAllowed(after, budget) {
    const b = this.options.budgetMs;
    return after > budget && !this.options.fixedTriangles && this.budgetScale === 1 && this.slackFrames >= 30 &&
      this.frameMsAvg < 0.6 * b && this.lastFrameMs < 0.6 * b && after <= 2 * budget;
  }
  refineWithinBudget(p) {
    while (!p.refine.empty() && !p.st.interrupted) {
      const node = p.refine.topNode(), err = p.refine.topErr();
      if (!this.isRefineCandidate(node) || (this.badNode[node] & 1)) {
        p.refine.pop();
        continue;
      }
      if (err <= p.tau || p.timeUp()) break;
      const dv = this.visibleDelta(node, true, p.view);
      const after = this.visibleTriangles + dv;
      if (this.probeAllowed(after, p.budget)) {
        this.slackFrames = 0;
        p.budget = after;
        p.st.budgetTriangles = p.budget;
      }
      if (after > p.budget) {
        this.popStaleCoarse(p);
        const trade = !p.coarse.empty() && p.coarse.topErr() * 2 < err;
        if (!trade) break;
        this.coarsenTop(p, Urgency.Needed);
        continue;
      }
      const ids = this.collectIn(node, this.scratch);
      if (this.cutBytes + this.bytesOf(ids) > p.pinLimit) {
        p.memoryFull = true;
        break;
      }
      p.refine.pop();
      this.refineOrRequest(p, node, err, dv);
    }
  }
  refineOrRequest(p, node, err, dv) {
    if (this.tryRefine(node)) {
      this.visibleTriangles += dv;
      ++p.st.refinements;
      this.pushAround(p, node);
      return;
    }
    if (p.still) {
      // Its loads are wantBelowCut's, and refineThrough may yet refine it this update.
      p.unrefined.push(node, err);
      return;
    }
    const ids = this.collectIn(node, this.scratch);
    if (this.patchesBad(ids)) {
      this.badNode[node] |= 1;
      return;
    }
    this.want(ids, p.urgentLeft > 0 ? Urgency.UrgentDown : Urgency.Needed);
    if (p.urgentLeft > 0) --p.urgentLeft;
    p.maxErr = Math.max(p.maxErr, err);
  }
  coarsenFarBelow(p) {
    while (!p.st.interrupted) {
      this.popStaleCoarse(p);
      if (p.coarse.empty() || p.coarse.topErr() >= p.tau * 0.5 || p.timeUp()) break;
      this.coarsenTop(p, Urgency.Needed);
    }
  }
  prefetch(p, predicted) {
    const { nodes, arcs, inArcs } = this.scene;
    for (let k = 0; !p.refine.empty() && k < 24;) {
      const node = p.refine.topNode(), err = p.refine.topErr();
      p.refine.pop();
      if (!this.isRefineCandidate(node) || this.badNode[node] || err <= p.tau * 0.5) continue;
      this.want(this.collectIn(node, this.scratch), Urgency.Prefetch);
      for (let j = 0; j < nodes.inArcCount[node] && k < 8; ++j) {
        const m = arcs.from[inArcs[nodes.firstInArc[node] + j]];
        if (!nodes.source[m] && this.screenError(m, p.view) > p.tau) this.want(this.collectIn(m, this.scratch), Urgency.Prefetch);
      }
      ++k;
    }
    for (let k = 0; !p.coarse.empty() && k < 16;) {
      const node = p.coarse.topNode();
      p.coarse.pop();
      if (!this.isCoarsenCandidate(node) || this.badNode[node]) continue;
      this.want(this.collectOut(node, this.scratch), Urgency.Prefetch);
      ++k;
    }
    // The frustum enlarged to contain the frusta of the next 10 frames (Derzapf et al. 4.3): the
    // refinements the extrapolated views want (a node's error is its largest over them), the
    // largest first, two levels deep (as if applied), within twice the render budget's triangles.
    const ahead = !predicted ? [] : Array.isArray(predicted) ? predicted : [predicted];
    if (!ahead.length || now() >= p.deadline + (p.deadline - p.t0)) return;
    const errAhead = (n) => {
      let e = 0;
      // The views ahead share the current eye's cone flag (as screenErrorAhead in extract.cpp).
      this.coneHeld = this.coneEye !== null;
      for (const v of ahead) e = Math.max(e, this.screenError(n, v));
      this.coneHeld = false;
      return e;
    };
    const heap = new Heap(true);
    const depth = new Map();
    for (let n = 0; n < nodes.count; ++n)
      if (this.isRefineCandidate(n) && !this.badNode[n]) {
        const e = errAhead(n);
        if (e > p.tau) heap.push(e, n), depth.set(n, 0);
      }
    const seen = new Uint8Array(nodes.count);
    let triangles = 0;
    while (!heap.empty()) {
      const node = heap.topNode();
      heap.pop();
      if (seen[node]) continue;
      seen[node] = 1;
      triangles += nodes.inTriangles[node];
      if (triangles > 2 * p.budget) break;
      this.want(this.collectIn(node, this.scratch), Urgency.Prefetch);
      const d = depth.get(node) || 0;
      if (d >= 1) continue;
      for (let k = 0; k < nodes.inArcCount[node]; ++k) {
        const m = arcs.from[inArcs[nodes.firstInArc[node] + k]];
        if (nodes.source[m] || this.badNode[m] || seen[m]) continue;
        const e = errAhead(m);
        if (e > p.tau) heap.push(e, m), depth.set(m, d + 1);
      }
    }
  }

  /** Nodes of the cut's set S (sorted): what the cut comparison prints. */
  nodeSet() {
    const out = [];
    for (let n = 0; n < this.inS.length; ++n) if (this.inS[n]) out.push(n);
    return out;
  }
}
