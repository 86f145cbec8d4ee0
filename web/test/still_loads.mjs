// node still_loads.mjs FILE.mt VIEWS TOLERANCE WIDTH HEIGHT: a still view asks for its loads at
// once, and only for the cut it ends with. For each view: the cut converged with every patch
// resident (as cut_nodes.mjs) is the target; its arcs that are not in the coarsest cut are the
// patches the view needs. Then, from the coarsest cut with nothing else resident:
// - ONE update of a still view (budgetScale > 1, as MTObject sets it once the camera stops) must ask
//   for every one of those patches and for no other (the levels between are refined through,
//   never loaded); one update of a moving view asks for fewer in some view, or the views test
//   nothing;
// - still updates whose requests are loaded between them (all, or only every other one of each
//   list) must reach the target's node set, having loaded only its patches, with exactly the cut's
//   patches pinned once (and the coarsest cut's once more, for the whole run); with one of those
//   patches damaged, they must stop with it out of the cut;
//   settled, an update repeats the last (ExtractRender.stillRepeats) and keeps its figures, one
//   after an arrival does not; while loads are pending, one after an arrival within
//   stillLoadingMs of the last that ran repeats too, one after that time or with nothing pending
//   does not;
// - moving on from the settled still view with a budget and no load arriving, the cut coarsens
//   through the levels never loaded (ExtractRender.coarsenThrough) to within the budget in at most
//   3 updates, with exactly its patches pinned (and the coarsest cut's);
// - a moving update's look-ahead (ExtractRender.loadAheadOf): after a frame within its gate, with
//   no look-ahead batch in flight, it adds at most aheadBatch requests at Urgency.Ahead, after all
//   others, each a patch the view needs (in some view at least one); after a slow frame, or with a
//   batch in flight, none.
// Prints a few lines a view; exits 1 when any of this fails.
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
// A PatchServer that loads nothing and keeps the last request list; `busy` says loads are pending
// (the tests load the requests between updates: idle unless a test says otherwise).
class RecordingServer {
  constructor() { this.last = []; this.aheadInFlight = 0; this.busy = false; }
  submit(list) { this.last = list; }
  meanLoadMs() { return 0; }
  idle() { return !this.busy; }
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
    const patchesOf = (arcList) => {
      const out = new Set();
      for (const a of arcList) for (let p = 0; p < arcs.patchCount[a]; ++p) out.add(arcPatches[arcs.firstPatch[a] + p]);
      return out;
    };
    const startPatches = new Set(all.startPatches);
    // The pins: one for each patch of the cut, and one more, held for the whole run, for each patch
    // of the coarsest cut (ExtractRender.pinStart); nothing else pinned.
    const pinsWrong = (cache, cut) => {
      const ids = new Set([...cut, ...startPatches, ...[...cache.entries].filter(([, e]) => e.pins > 0).map(([id]) => id)]);
      const wrong = [...ids].filter((id) => (cache.entries.get(id)?.pins ?? 0) !== (cut.has(id) ? 1 : 0) + (startPatches.has(id) ? 1 : 0));
      return wrong.length ? `${wrong.length} patches pinned otherwise than once for the cut (${cut.size} patches) and once for the coarsest cut (${startPatches.size}): ${wrong.slice(0, 4).map((id) => `${id}: ${cache.entries.get(id)?.pins ?? 0}`).join(', ')}` : '';
    };
    const finalCut = patchesOf(all.cutArcs);
    const needed = new Set([...finalCut].filter((id) => !startPatches.has(id)));
    const target = all.nodeSet().join(' ');
    // One update from the coarsest cut, its patches resident and nothing else.
    // ahead: {frameMs, inFlight}: a moving update after a frame of frameMs, with that many look-ahead
    // batches in flight (the still image's triangles as MTObject would allow); returns the list.
    const fresh = () => {
      const server = new RecordingServer();
      const cache = new PatchCache(2 ** 40, () => {});
      const er = new ExtractRender(scene, cache, server, Object.assign({}, options, { aheadBatch: 16 }));
      er.start();
      for (const id of er.startPatches) cache.reserve(id, 1), cache.commit(id, {}, 1);
      er.pinStart();
      return { server, cache, er };
    };
    const ask = (still, ahead) => {
      const { server, er } = fresh();
      if (still) er.budgetScale = 128;
      if (ahead) {
        er.aheadTriangles = 2 ** 40;
        er.frameDone(1, ahead.frameMs);
        server.aheadInFlight = ahead.inFlight;
      }
      er.update(1, view, null);
      return Object.assign(server.last, { wanted: er.wanted });
    };
    // What one update wants (its requests are these, at most its load budget of them).
    const asked = (still) => new Set([...ask(still, null).wanted.keys()].filter((id) => !startPatches.has(id)));
    const still = asked(true), moving = asked(false);
    // Still updates with the loads they ask for arriving between them: `keep(i)` says which of a
    // request list's items arrive; `damaged` is loaded as bad.
    const settle = (keep, damaged) => {
      const { server, cache, er } = fresh();
      er.budgetScale = 128;
      const loaded = new Set();
      let rounds = 0;
      for (; rounds < 500; ++rounds) {
        const st = er.update(rounds + 1, view, null);
        const list = server.last.filter((x) => cache.state(x.id) === 'absent');
        if (list.length === 0 && st.refinements + st.coarsenings === 0) break;
        list.forEach((x, i) => {
          if (!keep(i)) return;
          loaded.add(x.id);
          cache.reserve(x.id, 1);
          if (x.id === damaged) cache.markBad(x.id);
          else cache.commit(x.id, {}, 1);
        });
      }
      // Settled, an update repeats the last (ExtractRender.stillRepeats) with its figures, whatever
      // the caller did to those it was given (MTObject sets maxScreenError); one after an arrival
      // does not repeat.
      er.stillKey = null;
      const again = er.update(rounds + 2, view, null), againErr = again.maxScreenError;
      again.maxScreenError = -1;
      const arrival = er.update(rounds + 3, view, null);
      let other = scene.patches.count - 1;
      while (other >= 0 && cache.state(other) !== 'absent') --other;
      if (other >= 0) cache.reserve(other, 1), cache.commit(other, {}, 1);
      const after = er.update(rounds + 4, view, null);
      // Loads pending: an arrival within stillLoadingMs of the last update that ran is not looked
      // at (the update repeats); after that time, or once nothing is pending, it is.
      const arrive = () => {
        while (other >= 0 && cache.state(other) !== 'absent') --other;
        if (other >= 0) cache.reserve(other, 1), cache.commit(other, {}, 1);
      };
      server.busy = true;
      arrive();
      const pendingSoon = er.update(rounds + 5, view, null);
      er.stillAt -= er.options.stillLoadingMs;
      const pendingLater = er.update(rounds + 6, view, null);
      arrive();
      const pendingSoon2 = er.update(rounds + 7, view, null);
      server.busy = false;
      const idleSoon = er.update(rounds + 8, view, null);
      const throttled = other < 0 || (pendingSoon.repeated && !pendingLater.repeated && pendingSoon2.repeated && !idleSoon.repeated);
      const throttleFigures = `${pendingSoon.repeated} ${pendingLater.repeated} ${pendingSoon2.repeated} ${idleSoon.repeated}`;
      const cut = patchesOf(er.cutArcs);
      const problems = [];
      // Nothing loaded that neither the target's cut nor the cut settled on holds (the levels
      // between are refined through).
      const extra = [...loaded].filter((id) => !needed.has(id) && !cut.has(id));
      if (extra.length) problems.push(`loaded ${extra.length} patches no final cut holds (${extra.slice(0, 4).join(', ')})`);
      if (rounds >= 500) problems.push('did not settle in 500 updates');
      if (again.repeated || !arrival.repeated || arrival.maxScreenError !== againErr) problems.push('a settled still update was not skipped, or gave another error');
      if (after.repeated && other >= 0) problems.push('a still update after a patch arrived was skipped');
      if (!throttled) problems.push(`loads pending: a still update within stillLoadingMs of the last that ran was not skipped, or one after it or with nothing pending was (repeated: ${throttleFigures})`);
      const wrongPins = pinsWrong(cache, cut);
      if (wrongPins) problems.push(wrongPins);
      for (const id of cut) if (cache.state(id) !== 'ready') problems.push(`the cut holds patch ${id}, ${cache.state(id)}`);
      return { er, cache, loaded, rounds, problems };
    };
    const problems = [];
    for (const [name, keep] of [['all loads', () => true], ['every other load', (i) => i % 2 === 0]]) {
      const r = settle(keep, -1);
      if (r.er.nodeSet().join(' ') !== target) r.problems.push('the cut it settles on is not the target');
      if (r.loaded.size !== needed.size) r.problems.push(`loaded ${r.loaded.size} of the ${needed.size} patches needed`);
      console.log(`view ${k}: still updates, ${name}: ${r.rounds} updates, ${r.loaded.size} patches loaded, ${r.problems.length ? 'FAILED' : 'target reached'}`);
      for (const pr of r.problems) problems.push(`${name}: ${pr}`);
    }
    {
      // The camera moves on: a moving update over its budget coarsens through the levels the
      // still view never loaded (ExtractRender.coarsenThrough), with no load arriving.
      const r = settle(() => true, -1), er = r.er;
      const budget = Math.max(20000, 2 * all.startPatches.reduce((t, id) => t + scene.patches.triangles[id], 0));
      er.budgetScale = 1;
      er.options.fixedTriangles = budget;
      let updates = 0, st = null;
      const before = er.visibleTriangles;
      for (; updates < 3; ++updates) {
        st = er.update(1000 + updates, view, null);
        if (er.visibleTriangles <= budget) break;
      }
      const cut = patchesOf(er.cutArcs);
      console.log(`view ${k}: moving on with a budget of ${budget}: ${before} -> ${er.visibleTriangles} visible triangles in ${updates + 1} update(s), ${st.coarsenings} coarsenings`);
      if (er.visibleTriangles > budget) problems.push(`moving on: ${er.visibleTriangles} visible triangles after 3 updates with no loads, over the budget of ${budget}`);
      const wrongPins = pinsWrong(r.cache, cut);
      if (wrongPins) problems.push(`moving on: ${wrongPins}`);
      for (const id of cut) if (r.cache.state(id) !== 'ready') problems.push(`moving on: the cut holds patch ${id}, ${r.cache.state(id)}`);
    }
    if (needed.size) {
      // The last patch the view needs, in id order, is damaged: the cut settles without it.
      const damaged = Math.max(...needed);
      const r = settle(() => true, damaged);
      const badNodes = r.er.badNode.reduce((s, b) => s + (b ? 1 : 0), 0);
      console.log(`view ${k}: still updates, patch ${damaged} damaged: ${r.rounds} updates, ${badNodes} node(s) marked bad`);
      if (!badNodes) r.problems.push('no node marked bad');
      for (const pr of r.problems) problems.push(`patch ${damaged} damaged: ${pr}`);
    }
    // The look-ahead: with slack, after every other request, at most 16, each needed.
    const withAhead = ask(false, { frameMs: 10, inFlight: 0 });
    const aheadIds = withAhead.filter((x) => x.urgency === Urgency.Ahead).map((x) => x.id);
    const firstAhead = withAhead.findIndex((x) => x.urgency === Urgency.Ahead);
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
    const missing = [...needed].filter((id) => !still.has(id)).length;
    const unwanted = [...still].filter((id) => !needed.has(id)).length;
    if (needed.size > 0 && moving.size < still.size) ++deeper;
    console.log(`view ${k}: the target's cut holds ${needed.size} patches not in the coarsest; one still update asks for ${still.size} (missing ${missing}, others ${unwanted}), one moving update ${moving.size}`);
    if (missing > 0) problems.push(`a still update left ${missing} of ${needed.size} needed patches unasked`);
    if (unwanted > 0) problems.push(`a still update asked for ${unwanted} patches the target's cut does not hold`);
    for (const pr of problems) console.error(`still_loads: view ${k}: ${pr}`), (failed = 1);
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
