// node still_loads.mjs FILE.mt VIEWS TOLERANCE WIDTH HEIGHT: a still view asks for its loads at
// once. For each view: the cut converged with every patch resident (as cut_nodes.mjs) gives the
// nodes the tolerance refines; then, from the coarsest cut with nothing else resident, ONE update of
// a still view (budgetScale > 1, as MTObject sets it once the camera stops) must ask for the patches
// of every one of those nodes, however many levels below the coarsest cut they lie (the cut itself
// can refine only one level per round of loads). One update of a moving view asks for fewer (the
// next level and its prefetch) in some view, or the views test nothing. And a moving update's
// look-ahead (ExtractRender.loadAheadOf): after a frame within its gate, with no look-ahead batch in
// flight, it adds at most aheadBatch requests at Urgency.Ahead, after all others, each a patch the
// tolerance needs (in some view at least one); after a slow frame, or with a batch in flight, none.
// Prints one line a view; exits 1 when a still update misses a patch the tolerance needs or the
// look-ahead breaks one of those rules.
import fs from 'node:fs';
import { FileSource } from '../src/source.js';
import { openMtFile } from '../src/mtfile.js';
import { makeView } from '../src/camera.js';
import { ExtractRender, Urgency } from '../src/extract.js';
import { PatchCache } from '../src/cache.js';

const [file, viewsPath, tol, w, h] = process.argv.slice(2);
if (!h) {
  console.error('usage: node still_loads.mjs FILE.mt VIEWS TOLERANCE WIDTH HEIGHT');
  process.exit(2);
}
// A PatchServer that loads nothing and keeps the last request list.
class RecordingServer {
  constructor() { this.last = []; this.aheadInFlight = 0; }
  submit(list) { this.last = list; }
  meanLoadMs() { return 0; }
}
const options = { pixelTolerance: Number(tol), fixedTriangles: 2 ** 40, extractMs: 1e9 };
let failed = 0, deeper = 0, aheadSeen = 0;
try {
  const scene = await openMtFile(new FileSource(file, fs));
  const { center: c, radius: r, nodes, arcs, inArcs, arcPatches } = scene;
  const lines = fs.readFileSync(viewsPath, 'utf8').split('\n').map((l) => l.trim()).filter((l) => l.length);
  lines.forEach((line, k) => {
    const v = line.split(/\s+/).map(Number);
    const pose = { eye: [c[0] + r * v[0], c[1] + r * v[1], c[2] + r * v[2]], target: [c[0] + r * v[3], c[1] + r * v[4], c[2] + r * v[5]], up: [0, 0, 1], fovDeg: 45 };
    const view = makeView(pose, Number(w), Number(h), c, r);
    // The converged cut with everything resident: the nodes it refined (out of S).
    const all = new ExtractRender(scene, null, null, Object.assign({ prefetch: false }, options));
    all.start();
    for (let frame = 1; frame < 100000; ++frame) {
      const st = all.update(frame, view, null);
      if (st.refinements === 0 && st.coarsenings === 0) break;
    }
    const needed = new Set();
    for (let n = 0; n < nodes.count; ++n) {
      if (nodes.sink[n] || all.inS[n]) continue;
      for (let q = 0; q < nodes.inArcCount[n]; ++q) {
        const a = inArcs[nodes.firstInArc[n] + q];
        for (let p = 0; p < arcs.patchCount[a]; ++p) needed.add(arcPatches[arcs.firstPatch[a] + p]);
      }
    }
    // One update from the coarsest cut, its patches resident and nothing else.
    // ahead: {frameMs, inFlight}: a moving update after a frame of frameMs, with that many look-ahead
    // batches in flight (the still image's triangles as MTObject would allow); returns the list.
    const ask = (still, ahead) => {
      const server = new RecordingServer();
      const cache = new PatchCache(2 ** 40, () => {});
      const er = new ExtractRender(scene, cache, server, Object.assign({}, options, { aheadBatch: 16 }));
      er.start();
      for (const id of er.startPatches) cache.reserve(id, 1), cache.commit(id, {}, 1);
      er.pinStart();
      if (still) er.budgetScale = 128;
      if (ahead) {
        er.aheadTriangles = 2 ** 40;
        er.frameDone(1, ahead.frameMs);
        server.aheadInFlight = ahead.inFlight;
      }
      er.update(1, view, null);
      return server.last;
    };
    const asked = (still) => new Set(ask(still, null).map((x) => x.id));
    const still = asked(true), moving = asked(false);
    // The look-ahead: with slack, after every other request, at most 16, each needed.
    const withAhead = ask(false, { frameMs: 10, inFlight: 0 });
    const aheadIds = withAhead.filter((x) => x.urgency === Urgency.Ahead).map((x) => x.id);
    const firstAhead = withAhead.findIndex((x) => x.urgency === Urgency.Ahead);
    const problems = [];
    if (aheadIds.length > 16) problems.push(`${aheadIds.length} look-ahead requests, more than the batch of 16`);
    if (firstAhead >= 0 && withAhead.slice(firstAhead).some((x) => x.urgency !== Urgency.Ahead)) problems.push('a request after the look-ahead ones');
    const unneeded = aheadIds.filter((id) => !needed.has(id));
    if (unneeded.length) problems.push(`look-ahead patches the tolerance does not need: ${unneeded.slice(0, 5).join(', ')}`);
    const slow = ask(false, { frameMs: 45, inFlight: 0 }).filter((x) => x.urgency === Urgency.Ahead).length;
    const busy = ask(false, { frameMs: 10, inFlight: 1 }).filter((x) => x.urgency === Urgency.Ahead).length;
    if (slow) problems.push(`${slow} look-ahead requests after a 45 ms frame (gate 0.6 of 50 ms)`);
    if (busy) problems.push(`${busy} look-ahead requests with a look-ahead batch in flight`);
    if (aheadIds.length) ++aheadSeen;
    console.log(`view ${k}: look-ahead asks for ${aheadIds.length} (none after a slow frame: ${!slow}, none while one is in flight: ${!busy})`);
    for (const pr of problems) console.error(`still_loads: view ${k}: ${pr}`), (failed = 1);
    let missing = 0;
    for (const id of needed) if (!still.has(id)) ++missing;
    if (needed.size > 0 && moving.size < still.size) ++deeper;
    console.log(`view ${k}: the tolerance refines ${needed.size} patches; one still update asks for ${still.size} (missing ${missing}), one moving update ${moving.size}`);
    if (missing > 0) {
      console.error(`still_loads: view ${k}: a still update left ${missing} of ${needed.size} needed patches unasked`);
      failed = 1;
    }
  });
  if (aheadSeen === 0) {
    console.error('still_loads: in no view did a moving update ask for look-ahead loads: the views test nothing');
    failed = 1;
  }
  if (deeper === 0) {
    console.error('still_loads: in no view did a moving update ask for fewer patches than a still one: the views test nothing');
    failed = 1;
  }
} catch (e) {
  console.error(`still_loads: ${e.message}`);
  process.exit(1);
}
process.exit(failed);
