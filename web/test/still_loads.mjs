// node still_loads.mjs FILE.mt VIEWS TOLERANCE WIDTH HEIGHT: a still view asks for its loads at
// once. For each view: the cut converged with every patch resident (as cut_nodes.mjs) gives the
// nodes the tolerance refines; then, from the coarsest cut with nothing else resident, ONE update of
// a still view (budgetScale > 1, as MTObject sets it once the camera stops) must ask for the patches
// of every one of those nodes, however many levels below the coarsest cut they lie (the cut itself
// can refine only one level per round of loads). One update of a moving view asks for fewer (the
// next level and its prefetch) in some view, or the views test nothing. Prints one line a view;
// exits 1 when a still update misses a patch the tolerance needs.
import fs from 'node:fs';
import { FileSource } from '../src/source.js';
import { openMtFile } from '../src/mtfile.js';
import { makeView } from '../src/camera.js';
import { ExtractRender } from '../src/extract.js';
import { PatchCache } from '../src/cache.js';

const [file, viewsPath, tol, w, h] = process.argv.slice(2);
if (!h) {
  console.error('usage: node still_loads.mjs FILE.mt VIEWS TOLERANCE WIDTH HEIGHT');
  process.exit(2);
}
// A PatchServer that loads nothing and keeps the last request list.
class RecordingServer {
  constructor() { this.last = []; }
  submit(list) { this.last = list; }
  meanLoadMs() { return 0; }
}
const options = { pixelTolerance: Number(tol), fixedTriangles: 2 ** 40, extractMs: 1e9 };
let failed = 0, deeper = 0;
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
    const asked = (still) => {
      const server = new RecordingServer();
      const cache = new PatchCache(2 ** 40, () => {});
      const er = new ExtractRender(scene, cache, server, options);
      er.start();
      for (const id of er.startPatches) cache.reserve(id, 1), cache.commit(id, {}, 1);
      er.pinStart();
      if (still) er.budgetScale = 128;
      er.update(1, view, null);
      return new Set(server.last.map((x) => x.id));
    };
    const still = asked(true), moving = asked(false);
    let missing = 0;
    for (const id of needed) if (!still.has(id)) ++missing;
    if (needed.size > 0 && moving.size < still.size) ++deeper;
    console.log(`view ${k}: the tolerance refines ${needed.size} patches; one still update asks for ${still.size} (missing ${missing}), one moving update ${moving.size}`);
    if (missing > 0) {
      console.error(`still_loads: view ${k}: a still update left ${missing} of ${needed.size} needed patches unasked`);
      failed = 1;
    }
  });
  if (deeper === 0) {
    console.error('still_loads: in no view did a moving update ask for fewer patches than a still one: the views test nothing');
    failed = 1;
  }
} catch (e) {
  console.error(`still_loads: ${e.message}`);
  process.exit(1);
}
process.exit(failed);
