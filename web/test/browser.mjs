// The web viewer in a real browser: Debian's chromium, headless, driven by playwright-core, WebGL
// on SwiftShader, the MT files served by mtserve.
//   node test/browser.mjs BIN_DIR DATA_DIR [--update-golden]
// DATA_DIR holds t.mt, t-draco.mt, c.mt, h.mt, o.mt (tests/web_browser.sh builds them). Tests:
//   golden        a fixed view at a fixed tolerance, converged, against test/golden/torus.png
//                 (at most 2% of the pixels differ by more than 48 in RGB), its patches decoded by
//                 the WebAssembly decoder (web/dist/mt_decode.wasm);
//   cracks        several views and tolerances, converged: no background pixel enclosed by the
//                 surface in a component under 400 pixels (the torus' own hole is far larger);
//   draco         the same surface coded with Draco: decoded by Draco's wasm decoder, no crack;
//   path          a recorded camera path (orbit, 240 frames) under a 2 MiB cache: the cache never
//                 above its cap, the cut never above the frame's render budget, loads evicted and
//                 redone; the frame times are printed (the timed figures are bench/web.sh's);
//   corrupted     a copy of the file with damaged payloads: warnings naming the patches, the page
//                 keeps drawing frames;
//   no-ranges     mtserve --no-ranges (200 instead of 206): the page shows the clear message;
//   still-share   a still frame's chunk sized for stillShareLoading of the budget while loads are
//                 pending, stillShare otherwise (synthetic chunk times);
//   open-requests the opening by HTTP (HttpSource, tails of several sizes) gives FileSource's scene
//                 with no byte read twice; the page's early requests (viewer.html) are the only
//                 ones to its first image;
//   colours       a coloured scan (c.mt) converged: on a grid of pixels the colour on screen is the
//                 stored per-vertex colour interpolated at the surface point a ray through the
//                 pixel hits, unlit (as mtrender --color vertex draws it): >= 90% within 8 levels;
//   back-faces    the open scans (c.mt coloured, h.mt lit; 10 holes each): where an oracle drawing
//                 (both sides, one pass, white where the nearest surface is a back face) sees the
//                 inside through a hole, the viewer's image is neither background (its back pass
//                 draws them) nor black (the lit back pass has its light); with side=front
//                 the same check fails (the check can fail). The closed torus (t.mt) seen from
//                 outside is drawn single-sided (no back pass) and shows no back face.
//   occlusion     still images drawn in chunks of 2000 triangles (o.mt, h.mt's scan in small
//                 patches, one of its views in two passes; the textured x.mt): the patches the
//                 occlusion tests leave out are hidden, so the image is the same pixel for pixel as
//                 the one drawn with every patch (occlusion off); some are left out.
//   textured      a textured scan (x.mt, version 6: mtgen --texture charts) at a fixed view,
//                 converged: every patch drawn with its atlas, the image within 35 dB PSNR (over
//                 the pixels the model covers) of mtrender's headless image of the same view and
//                 tolerance (--color texture), and against test/golden/textured.png as the torus;
//   textured-draco  the same scan Draco-coded (x-draco.mt): the same image (the golden);
//   texture-cache x.mt on an orbit under a 4 MiB cache: every frame's cache bytes under the cap;
//                 at the end the cache recounted from what it holds (arrays + RGBA8 atlases) is
//                 what it says it holds, entry by entry, and every entry within the bound its load
//                 reserved (which the cut's byte budget counts, atlases included);
//   texture-corrupted  a copy of x.mt with damaged texture payloads: a warning for each, the
//                 patches drawn untextured (their geometry shown), the page keeps drawing.
// Prints one line per test and "N passed, M failed"; exits 1 on any failure.
import fs from 'node:fs';
import path from 'node:path';
import os from 'node:os';
import { spawn, spawnSync } from 'node:child_process';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';
import { FileSource, HttpSource } from '../src/source.js';
import { openMtFile } from '../src/mtfile.js';

const here = path.dirname(fileURLToPath(import.meta.url));
const webDir = path.resolve(here, '..');
const [binDir, dataDir] = process.argv.slice(2);
const update = process.argv.includes('--update-golden');
if (!dataDir) {
  console.error('usage: node test/browser.mjs BIN_DIR DATA_DIR [--update-golden]');
  process.exit(2);
}
export const chromiumArgs = ['--no-sandbox', '--disable-gpu', '--disable-background-networking', '--disable-component-update',
  '--disable-sync', '--no-first-run', '--use-angle=swiftshader', '--enable-unsafe-swiftshader'];

// A served directory: web/ and the data, linked (mtserve follows links placed inside its DIR).
const root = fs.mkdtempSync(path.join(os.tmpdir(), 'mtweb-'));
fs.symlinkSync(webDir, path.join(root, 'web'));
fs.symlinkSync(path.resolve(dataDir), path.join(root, 'data'));

function serve(extra) {
  return new Promise((resolve, reject) => {
    const p = spawn(path.join(binDir, 'mtserve'), [root, '--port', '0', '-q', ...extra], { stdio: ['ignore', 'pipe', 'inherit'] });
    p.stdout.on('data', (d) => {
      const m = /http:\/\/[\d.]+:(\d+)\//.exec(String(d));
      if (m) resolve({ proc: p, base: `http://127.0.0.1:${m[1]}` });
    });
    p.on('error', reject);
    p.on('exit', (code) => reject(new Error(`mtserve exited with ${code}`)));
  });
}

const results = [];
const only = process.env.ONLY ? process.env.ONLY.split(',') : null;  // run only these tests
async function test(name, fn) {
  if (only && !only.includes(name)) return;
  const t0 = Date.now();
  try {
    const note = await fn();
    results.push(true);
    console.log(`PASS ${name} (${((Date.now() - t0) / 1000).toFixed(1)} s)${note ? ': ' + note : ''}`);
  } catch (e) {
    results.push(false);
    console.log(`FAIL ${name} (${((Date.now() - t0) / 1000).toFixed(1)} s): ${e.message}`);
  }
}
const check = (cond, msg) => { if (!cond) throw new Error(msg); };

const srv = await serve([]);
const noRange = await serve(['--no-ranges']);
const browser = await chromium.launch({ executablePath: '/usr/bin/chromium', headless: true, args: chromiumArgs });
const W = 640, H = 360;

async function open(query, base = srv.base) {
  const page = await browser.newPage({ viewport: { width: W, height: H } });
  const log = [];
  page.on('console', (m) => log.push(m.text()));
  page.on('pageerror', (e) => log.push('pageerror: ' + e.message));
  await page.goto(`${base}/web/viewer.html?capture&${query}`);
  await page.waitForFunction(() => window.mtViewer && (window.mtViewer.ready || window.mtViewer.error), null, { timeout: 60000 });
  return { page, log };
}
// Waits until the cut has stopped moving and nothing is loading for 8 frames.
async function converge(page, timeout = 60000) {
  await page.waitForFunction(() => {
    const f = window.mtViewer.frames;
    if (f.length < 10) return false;
    return f.slice(-8).every((x) => x.moves === 0 && x.pending === 0);
  }, null, { timeout, polling: 100 });
}

await test('golden', async () => {
  const { page } = await open('file=/data/t.mt&tol=2&fixed=3000000&view=0.4,-1.6,0.9,0,0,0');
  await converge(page);
  await page.waitForTimeout(200);
  const golden = path.join(here, 'golden', 'torus.png');
  if (update || !fs.existsSync(golden)) {
    const url = await page.evaluate(() => window.mtViewer.png());
    fs.mkdirSync(path.dirname(golden), { recursive: true });
    fs.writeFileSync(golden, Buffer.from(url.split(',')[1], 'base64'));
    await page.close();
    if (!update) throw new Error(`no golden image: wrote ${golden}; check it and commit it`);
    return `wrote ${golden}`;
  }
  const r = await page.evaluate(() => window.mtViewer.compare('/web/test/golden/torus.png'));
  // The patches were decoded by the WebAssembly decoder (web/dist/mt_decode.wasm, built by CMake).
  const decoder = await page.evaluate(() => window.mtViewer.decoder);
  await page.close();
  check(!r.error, r.error);
  check(decoder === 'wasm', `the patches were decoded in ${decoder}, not by web/dist/mt_decode.wasm`);
  check(r.differing <= 0.02, `${(100 * r.differing).toFixed(2)}% of the pixels differ from the golden image (mean ${r.mean.toFixed(2)})`);
  return `${(100 * r.differing).toFixed(3)}% pixels differ, mean difference ${r.mean.toFixed(2)}, decoded in ${decoder}`;
});

await test('cracks', async () => {
  const notes = [];
  // Each view's tolerance is low enough that its cut mixes several nodes (the far view at 8 px drew
  // one whole-model root node of 12,492 triangles, which has no border that could crack).
  for (const [view, tol] of [['0.4,-1.6,0.9,0,0,0', 1], ['0.2,-0.9,0.35,0,0,0', 3], ['1.4,0.3,0.2,0,0,0', 4], ['0,-0.7,0.15,0.6,0.6,0', 2]]) {
    const { page } = await open(`file=/data/t.mt&tol=${tol}&fixed=3000000&bg=ff00ff&view=${view}`);
    await converge(page);
    const r = await page.evaluate(() => window.mtViewer.cracks('ff00ff'));
    const f = await page.evaluate(() => window.mtViewer.frames.at(-1));
    // The detector finds a 20-pixel slit painted into the middle of the same image.
    const slit = await page.evaluate(() => window.mtViewer.cracks('ff00ff', 400, true));
    await page.close();
    check(slit.crackPixels >= 20, `view ${view}: the detector missed a painted 20-pixel slit (${slit.crackPixels})`);
    check(r.surfacePixels > 1000, `view ${view}: the surface covers only ${r.surfacePixels} pixels`);
    check(r.crackPixels === 0, `view ${view} tolerance ${tol}: ${r.crackPixels} background pixels in ${r.components} holes inside the silhouette`);
    check(f.triangles > 20000, `view ${view}: the cut has only ${f.triangles} triangles`);
    notes.push(`${f.triangles} triangles`);
  }
  return `4 cuts, no crack (${notes.join(', ')})`;
});

await test('draco', async () => {
  const { page, log } = await open('file=/data/t-draco.mt&tol=1&fixed=3000000&bg=ff00ff&view=0.4,-1.6,0.9,0,0,0');
  await converge(page);
  const r = await page.evaluate(() => window.mtViewer.cracks('ff00ff'));
  const st = await page.evaluate(() => ({ f: window.mtViewer.frames.at(-1), w: window.mtViewer.warnings }));
  await page.close();
  check(st.w.length === 0, `warnings: ${st.w[0]}`);
  check(!log.some((m) => m.startsWith('pageerror')), `page error: ${log.find((m) => m.startsWith('pageerror'))}`);
  check(st.f.triangles > 20000 && r.surfacePixels > 1000, `the Draco file's cut has ${st.f.triangles} triangles, ${r.surfacePixels} pixels`);
  check(r.crackPixels === 0, `${r.crackPixels} background pixels enclosed by the surface`);
  return `${st.f.triangles} triangles decoded by Draco's decoder, no crack`;
});

await test('path', async () => {
  const cap = 2 * 2 ** 20;
  const { page } = await open(`file=/data/t.mt&tol=1&budget=50&cache=2&path=orbit&frames=240`);
  await page.waitForFunction(() => window.mtViewer.done, null, { timeout: 240000, polling: 200 });
  const f = await page.evaluate(() => window.mtViewer.frames);
  await page.close();
  const over = f.filter((x) => x.cacheBytes > cap);
  check(over.length === 0, `cache above its cap of ${cap} bytes in ${over.length} frames (max ${Math.max(...f.map((x) => x.cacheBytes))})`);
  const overBudget = f.filter((x) => x.drawn > Math.max(x.budget, f[0].drawn) * 1.001);
  check(overBudget.length === 0, `the drawn cut exceeded the render budget in ${overBudget.length} frames (${overBudget
    .slice(0, 4).map((x) => `frame ${f.indexOf(x)}: ${x.drawn} drawn, budget ${Math.round(x.budget)}, ${x.patches} patches`).join('; ')}; the first frame drew ${f[0].drawn})`);
  const ms = f.slice(1).map((x) => x.frameMs).sort((a, b) => a - b);
  const within = ms.filter((x) => x <= 50).length / ms.length;
  const maxCache = Math.max(...f.map((x) => x.cacheBytes));
  check(f.at(-1).evictions > 0, `nothing was evicted (cache max ${Math.max(...f.map((x) => x.cacheBytes))}, ${f.at(-1).loads} loads, given up ${f.at(-1).givenUp}): the test tests nothing`);
  return `${f.length} frames, cache max ${(maxCache / 2 ** 20).toFixed(2)} MiB of 2, ${f.at(-1).evictions} evictions, frame ms median ${ms[ms.length >> 1].toFixed(1)} p95 ${ms[Math.floor(ms.length * 0.95)].toFixed(1)}, ${(100 * within).toFixed(1)}% within 50 ms, fetched ${(f.at(-1).bytesRead / 2 ** 20).toFixed(2)} MiB`;
});

await test('corrupted', async () => {
  // Damage one byte in the middle of every 3rd payload of the finest two levels.
  const src = path.join(dataDir, 't.mt'), dst = path.join(dataDir, 't-bad.mt');
  fs.copyFileSync(src, dst);
  const s = await openMtFile(new FileSource(src, fs));
  const fd = fs.openSync(dst, 'r+');
  let damaged = 0;
  for (let i = 0; i < s.patches.count; i += 3) {
    const arc = s.patches.arc[i];
    if (s.nodes.level[s.arcs.from[arc]] > 1) continue;
    const at = s.patches.offset[i] + Math.floor(s.patches.size[i] / 2);
    const b = Buffer.alloc(1);
    fs.readSync(fd, b, 0, 1, at);
    b[0] ^= 0x5a;
    fs.writeSync(fd, b, 0, 1, at);
    ++damaged;
  }
  fs.closeSync(fd);
  const { page, log } = await open('file=/data/t-bad.mt&tol=0.5&fixed=3000000&view=0.2,-0.9,0.35,0,0,0');
  await page.waitForFunction(() => window.mtViewer.warnings.length > 0, null, { timeout: 60000 });
  const n0 = await page.evaluate(() => window.mtViewer.frames.length);
  await page.waitForTimeout(1500);
  const st = await page.evaluate(() => ({ n: window.mtViewer.frames.length, w: window.mtViewer.warnings, err: window.mtViewer.error, drawn: window.mtViewer.frames.at(-1).drawn }));
  await page.close();
  fs.unlinkSync(dst);
  check(!st.err, `the page stopped: ${st.err}`);
  check(st.n > n0 + 3, `the page stopped drawing frames after the warning (${n0} -> ${st.n})`);
  check(st.w.every((m) => /patch \d+ is damaged: checksum mismatch/.test(m)), `unexpected warning: ${st.w[0]}`);
  check(log.some((m) => /damaged/.test(m)), 'no warning on the console');
  check(!log.some((m) => m.startsWith('pageerror')), `page error: ${log.find((m) => m.startsWith('pageerror'))}`);
  return `${damaged} payloads damaged, ${st.w.length} skipped with a warning ("${st.w[0].replace(/^.*?: /, '').slice(0, 70)}..."), still drawing`;
});

await test('no-ranges', async () => {
  const { page } = await open('file=/data/t.mt', noRange.base);
  const st = await page.evaluate(() => ({ err: window.mtViewer.error, shown: getComputedStyle(document.getElementById('error')).display }));
  await page.close();
  check(st.err && /instead of 206/.test(st.err) && /Range/.test(st.err), `no clear message: ${st.err}`);
  check(st.shown === 'block', 'the message is not shown on the page');
  return `"${st.err.slice(0, 90)}..."`;
});

await test('open-requests', async () => {
  // The opening's reads by HTTP (HttpSource, in node against mtserve) give the scene FileSource
  // gives, with no byte asked for twice, whatever the tail read's size: a tail shorter than the
  // index section (the rest asked for once), one cutting it, one holding the whole file; payload
  // reads inside the kept tail are its bytes and need no request.
  const file = path.join(dataDir, 't.mt');
  const want = await openMtFile(new FileSource(file, fs));
  const size = fs.statSync(file).size, index = size - want.header.metaOffset;
  const arrays = (sc) => JSON.stringify(['nodes', 'arcs', 'patches'].map((k) => Object.entries(sc[k]).map(([n, a]) => [n, ArrayBuffer.isView(a) ? Array.from(a) : a])));
  const notes = [];
  for (const [tailBytes, requests, bytes, kept] of [[32, 3, 32 + 256 + index - 32, 0], [Math.floor(index / 2), 3, 256 + index, 1], [2 * size, 2, 256 + size, 1]]) {
    const src = new HttpSource(`${srv.base}/data/t.mt`, { tailBytes });
    const sc = await openMtFile(src);
    check(arrays(sc) === arrays(want), `tail ${tailBytes}: the scene differs from FileSource's`);
    check(src.requests === requests && src.bytesFetched === bytes && src.keptReads === kept,
      `tail ${tailBytes}: ${src.requests} requests, ${src.bytesFetched} bytes, ${src.keptReads} reads from the tail (want ${requests}, ${bytes}, ${kept})`);
    notes.push(`tail ${tailBytes}: ${src.requests} requests, ${src.bytesFetched} bytes`);
    // A payload in the tail, one straddling its start (when the tail begins inside the payloads).
    const k = src.kept.begin, ids = [want.patches.count - 1];
    for (let i = 0; i < want.patches.count; ++i) if (want.patches.offset[i] < k && want.patches.offset[i] + want.patches.size[i] > k) ids.push(i);
    for (const i of ids) {
      const a = want.patches.offset[i], b = a + want.patches.size[i];
      const got = Buffer.from(await src.read(a, b)), ref = Buffer.alloc(b - a);
      const fd = fs.openSync(file, 'r');
      fs.readSync(fd, ref, 0, b - a, a);
      fs.closeSync(fd);
      check(got.equals(ref), `tail ${tailBytes}: payload ${i}'s bytes differ`);
    }
  }
  // The page: the header and tail requests started by viewer.html's inline script, before the
  // modules, are the opening's only requests up to the coarsest cut loaded (the 287 KiB file lies
  // in the tail: index and coarsest cut); with noearly the module makes the same two itself.
  for (const q of ['', '&noearly']) {
    const { page, log } = await open(`file=/data/t.mt&tol=2${q}`);
    await page.waitForFunction(() => window.mtViewer.firstImageMs !== null, null, { timeout: 60000 });
    await page.waitForTimeout(300);  // an unused early request's answer settles
    const errors = log.filter((m) => m.startsWith('pageerror') || /Uncaught|Unhandled/.test(m));
    check(errors.length === 0, `page${q}: ${errors[0]}`);
    const st = await page.evaluate(() => ({ reads: window.mtViewer.openReads, early: !!window.mtEarly,
      files: performance.getEntriesByType('resource').filter((r) => r.name.endsWith('/data/t.mt') && r.startTime < window.mtViewer.openTimes.coarsest).length }));
    await page.close();
    check(st.early === !q, `window.mtEarly ${st.early ? 'set' : 'not set'} with "${q}"`);
    check(st.reads && st.reads.requests === 2 && st.reads.kept > 0 && st.files === 2,
      `page${q}: ${JSON.stringify(st.reads)} before the first image, ${st.files} requests for the file`);
    notes.push(`page${q}: 2 requests, ${st.reads.kept} reads from the tail`);
  }
  return notes.join('; ');
});

await test('still-share', async () => {
  // A still frame's chunk while loads are pending is sized for stillShareLoading of the budget,
  // otherwise for stillShare; the still cut's size (stillFullChunk) always for stillShare. Chunks
  // of 10,000 triangles drawn in 10 ms (1000 a ms) under a 50 ms budget: 1000 x (0.35 x 50 - 2)
  // = 15,500 while loading, 1000 x (0.9 x 50 - 2) = 43,000 (after doubling from 20,000) once idle.
  const { page } = await open('file=/data/t.mt&tol=2&budget=50');
  const r = await page.evaluate(() => {
    const mt = window.mtViewer.mt, out = [];
    let pending = true;
    mt.server.idle = () => !pending;
    mt.stillRate = { triangles: 0, ms: 0 };
    mt.stillChunk = mt.stillFullChunk = 0;
    for (const p of [true, true, true, false, false]) {
      pending = p;
      mt._measureChunk(10000, 10);
      out.push([Math.round(mt.stillChunk), Math.round(mt.stillFullChunk)]);
    }
    return out;
  });
  await page.close();
  const want = [[15500, 20000], [15500, 40000], [15500, 43000], [31000, 43000], [43000, 43000]];
  check(JSON.stringify(r) === JSON.stringify(want), `chunks ${JSON.stringify(r)}, want ${JSON.stringify(want)}`);
  return `chunk while loading 15,500, idle 43,000 triangles (at 1000 a ms)`;
});

await test('colours', async () => {
  const notes = [];
  for (const view of ['0.4,-1.6,0.9,0,0,0', '-1.3,0.8,0.5,0,0,0']) {
    const { page } = await open(`file=/data/c.mt&tol=1&fixed=3000000&view=${view}`);
    await converge(page);
    await page.waitForTimeout(200);
    const r = await page.evaluate(() => window.mtViewer.colours(32, 8));
    await page.close();
    check(r.hits > 200, `view ${view}: only ${r.hits} sample pixels hit the surface`);
    check(r.within >= 0.9 * r.hits, `view ${view}: ${r.within} of ${r.hits} pixels within 8 levels of the stored colour (median difference ${r.median.toFixed(1)})`);
    notes.push(`${r.within}/${r.hits} within 8 levels, median ${r.median.toFixed(1)}`);
  }
  return notes.join('; ');
});

await test('back-faces', async () => {
  const notes = [];
  let seen = 0;
  // Both ways of drawing the back faces: one pass (twopass=0) and a second pass (twopass=1: up to
  // a triangle a pixel, so this cut takes two passes); c.mt's by the default rule.
  for (const [file, view, passes] of [['c', '0.4,-1.6,0.9,0,0,0', ''], ['h', '-1.3,0.8,0.5,0,0,0', '0'], ['h', '0.4,-1.6,0.9,0,0,0', '1']]) {
    for (const side of ['', 'front']) {
      const { page } = await open(`file=/data/${file}.mt&tol=1&fixed=3000000&bg=ff00ff&view=${view}${side ? '&side=' + side : ''}${passes ? '&twopass=' + passes : ''}`);
      await converge(page);
      await page.waitForTimeout(200);
      const r = await page.evaluate(() => window.mtViewer.backFaces('ff00ff'));
      await page.close();
      if (!side) {
        check(r.backFaces, `view ${view}: the open scan is drawn without its back faces`);
        if (passes) check(r.twoPass === (passes === '1'), `${file}.mt twopass=${passes}: drawn in ${r.twoPass ? 'two passes' : 'one pass'}`);
        check(r.backBg <= 0.02 * r.back, `${file}.mt view ${view}: ${r.backBg} of ${r.back} pixels showing the inside through a hole are background`);
        check(r.backDark <= 0.02 * r.back, `${file}.mt view ${view}: ${r.backDark} of ${r.back} pixels showing the inside through a hole are black`);
        seen += r.back;
        notes.push(`${file}.mt ${r.twoPass ? 'two passes' : 'one pass'}: ${r.back} px inside, ${r.backBg} background, ${r.backDark} black`);
      } else if (r.back >= 100) {
        check(r.backBg >= 0.5 * r.back, `view ${view}, side=front: only ${r.backBg} of ${r.back} back-face pixels are background: the check cannot fail`);
        notes.push(`side=front ${r.backBg}/${r.back} background`);
      }
    }
  }
  check(seen >= 300, `the views see only ${seen} pixels of the inside: the test tests nothing`);
  const { page } = await open('file=/data/t.mt&tol=1&fixed=3000000&bg=ff00ff&view=0.4,-1.6,0.9,0,0,0');
  await converge(page);
  const r = await page.evaluate(() => window.mtViewer.backFaces('ff00ff'));
  await page.close();
  check(!r.backFaces, 'the closed torus seen from outside is drawn with its back faces');
  check(r.back <= 0.001 * W * H, `the closed torus seen from outside shows ${r.back} back-face pixels`);
  return `${notes.join('; ')}; closed torus: one pass, ${r.back} back-face px`;
});

// ---- version 6: textures ----
const texView = '0.5,-1.5,0.8,0,0,0', texTol = 1, texBg = '141414';

await test('occlusion', async () => {
  const notes = [];
  // twopass=1: up to a triangle a pixel in two passes, so the back pass's meshes are tested too.
  for (const [file, view, extra] of [['o', '0.4,-1.6,0.9,0,0,0', ''], ['o', '-1.3,0.8,0.5,0,0,0', ''], ['o', '-1.3,0.8,0.5,0,0,0', '&twopass=1'], ['x', texView, '']]) {
    const { page } = await open(`file=/data/${file}.mt&tol=1&fixed=3000000&chunk=2000&view=${view}${extra}`);
    await converge(page);
    const r = await page.evaluate(async () => {
      const v = window.mtViewer, mt = v.mt;
      // A new still image of the converged cut, drawn to the end: its pixels and what it left out.
      const image = async () => {
        mt.accum = null;
        mt.cutChanged = true;
        const t0 = performance.now(), f0 = v.frames.length;
        await new Promise((res, rej) => {
          const poll = () => (mt.imageAt > t0 ? res() : performance.now() - t0 > 30000 ? rej(new Error('no image within 30 s')) : setTimeout(poll, 10));
          poll();
        });
        const chunks = v.frames.slice(f0).filter((f) => f.drawn > 0).length;
        return { px: v.pixels().data, hidden: mt.accum.hiddenTriangles, triangles: mt.accum.triangles, chunks, backs: mt.backMeshes.size };
      };
      const a = await image();
      const occlusion = mt.occlusion;
      mt.occlusion = null;
      const b = await image();
      mt.occlusion = occlusion;
      let differ = 0, model = 0;
      for (let i = 0; i < a.px.length; i += 4) {
        if (a.px[i] !== b.px[i] || a.px[i + 1] !== b.px[i + 1] || a.px[i + 2] !== b.px[i + 2]) ++differ;
        if (b.px[i] !== a.px[0] || b.px[i + 1] !== a.px[1] || b.px[i + 2] !== a.px[2]) ++model;
      }
      return { differ, model, hidden: a.hidden, triangles: a.triangles, chunks: a.chunks, backs: a.backs };
    });
    await page.close();
    check(r.chunks >= 4, `${file}.mt view ${view}: the image took ${r.chunks} chunks: the test tests nothing`);
    check(r.model > 1000, `${file}.mt view ${view}: the image shows only ${r.model} pixels of the model`);
    if (extra) check(r.backs > 0, `${file}.mt view ${view}${extra}: no back pass`);
    check(r.hidden > 0, `${file}.mt view ${view}${extra}: no patch of the ${r.triangles}-triangle cut was found hidden`);
    check(r.differ === 0, `${file}.mt view ${view}${extra}: ${r.differ} pixels differ from the image with every patch drawn`);
    notes.push(`${file}.mt${extra} ${r.hidden} of ${r.triangles} triangles left out, same image`);
  }
  return notes.join('; ');
});
await test('textured', async () => {
  // mtrender's image of the same view: headless, --color texture, the same size, tolerance and
  // background, converged (the camera still for 120 frames).
  const tmp = fs.mkdtempSync(path.join(os.tmpdir(), 'mtref-'));
  fs.writeFileSync(path.join(tmp, 'view'), `space unit\nfov 45\n${texView.split(',').join(' ')}\n`);
  const frames = 120;
  const r = spawnSync(path.join(binDir, 'mtrender'), [path.join(dataDir, 'x.mt'), '--headless', '--quiet', '--camera-path', path.join(tmp, 'view'),
    '--frames', String(frames), '--width', String(W), '--height', String(H), '--tolerance', String(texTol), '--fixed-triangles', '3000000',
    '--color', 'texture', '--background', '20', '20', '20', '--screenshots', tmp, '--screenshot-every', '100000'], { encoding: 'utf8' });
  check(r.status === 0, `mtrender failed: ${r.stderr || r.stdout}`);
  const ref = path.join(dataDir, 'x-mtrender.png');
  fs.copyFileSync(path.join(tmp, `frame_${String(frames - 1).padStart(5, '0')}.png`), ref);
  fs.rmSync(tmp, { recursive: true, force: true });
  const { page, log } = await open(`file=/data/x.mt&tol=${texTol}&fixed=3000000&bg=${texBg}&view=${texView}`);
  await converge(page);
  await page.waitForTimeout(200);
  const st = await page.evaluate(() => {
    const v = window.mtViewer, fr = v.frames;
    let k = fr.length - 1;  // the first frame of the final still, loaded stretch
    while (k > 0 && fr[k - 1].moves === 0 && fr[k - 1].pending === 0) --k;
    // (performance.now() counts from the page's navigation)
    return { f: fr.at(-1), w: v.warnings, first: v.firstImageMs, start: 0, conv: fr[k].t };
  });
  const p = await page.evaluate((bg) => window.mtViewer.psnr('/data/x-mtrender.png', bg), texBg);
  const golden = path.join(here, 'golden', 'textured.png');
  let g = null;
  if (update || !fs.existsSync(golden)) {
    const url = await page.evaluate(() => window.mtViewer.png());
    fs.writeFileSync(golden, Buffer.from(url.split(',')[1], 'base64'));
  } else {
    g = await page.evaluate(() => window.mtViewer.compare('/web/test/golden/textured.png'));
  }
  await page.close();
  check(!p.error, p.error);
  check(st.w.length === 0, `warnings: ${st.w[0]}`);
  check(!log.some((m) => m.startsWith('pageerror')), `page error: ${log.find((m) => m.startsWith('pageerror'))}`);
  check(st.f.patches > 10 && st.f.texturedPatches === st.f.patches, `${st.f.texturedPatches} of ${st.f.patches} patches drawn textured`);
  check(p.coveredPixels > 0.1 * W * H, `the model covers only ${p.coveredPixels} pixels`);
  check(p.covered >= 35, `PSNR against mtrender's image ${p.covered.toFixed(2)} dB over ${p.coveredPixels} covered pixels (< 35)`);
  if (!g) throw new Error(`no golden image: wrote ${golden}; check it and commit it`);
  check(!g.error, g.error);
  check(g.differing <= 0.02, `${(100 * g.differing).toFixed(2)}% of the pixels differ from the golden image (mean ${g.mean.toFixed(2)})`);
  const f = st.f;
  return `${f.patches} patches textured, ${f.triangles} triangles; PSNR against mtrender --color texture ${p.covered.toFixed(2)} dB ` +
    `over ${p.coveredPixels} covered pixels (${p.all.toFixed(2)} dB over all); golden: ${(100 * g.differing).toFixed(3)}% pixels differ; ` +
    `${f.loads} loads, ${(f.bytesRead / 2 ** 20).toFixed(2)} MiB fetched in ${f.requests} requests, worker ${(f.decodeMs / f.loads).toFixed(2)} ms a patch ` +
    `of which waiting for images ${(f.textureMs / f.loads).toFixed(2)} ms, first image ${(st.first - st.start).toFixed(0)} ms, converged at ${(st.conv - st.start).toFixed(0)} ms`;
});

await test('textured-draco', async () => {
  // The same textured scan Draco-coded: the texture coordinates follow the order Draco's decoder
  // gives the triangles; the image is the meshopt file's (test/golden/textured.png).
  const { page, log } = await open(`file=/data/x-draco.mt&tol=${texTol}&fixed=3000000&bg=${texBg}&view=${texView}`);
  await converge(page);
  await page.waitForTimeout(200);
  const st = await page.evaluate(() => ({ f: window.mtViewer.frames.at(-1), w: window.mtViewer.warnings }));
  const g = await page.evaluate(() => window.mtViewer.compare('/web/test/golden/textured.png'));
  await page.close();
  check(st.w.length === 0, `warnings: ${st.w[0]}`);
  check(!log.some((m) => m.startsWith('pageerror')), `page error: ${log.find((m) => m.startsWith('pageerror'))}`);
  check(st.f.patches > 10 && st.f.texturedPatches === st.f.patches, `${st.f.texturedPatches} of ${st.f.patches} patches drawn textured`);
  check(!g.error, g.error);
  check(g.differing <= 0.02, `${(100 * g.differing).toFixed(2)}% of the pixels differ from the golden image (mean ${g.mean.toFixed(2)})`);
  return `${st.f.patches} patches textured; golden: ${(100 * g.differing).toFixed(3)}% pixels differ, mean difference ${g.mean.toFixed(2)}`;
});

await test('texture-cache', async () => {
  const capMiB = 4, cap = capMiB * 2 ** 20;
  const { page } = await open(`file=/data/x.mt&tol=1&budget=50&cache=${capMiB}&path=orbit&frames=240`);
  await page.waitForFunction(() => window.mtViewer.done, null, { timeout: 240000, polling: 200 });
  const f = await page.evaluate(() => window.mtViewer.frames);
  const a = await page.evaluate(() => window.mtViewer.cacheAudit());
  await page.close();
  const over = f.filter((x) => x.cacheBytes > cap);
  check(over.length === 0, `cache above its cap of ${cap} bytes in ${over.length} frames (max ${Math.max(...f.map((x) => x.cacheBytes))})`);
  check(a.mismatched === 0, `${a.mismatched} entries hold other bytes than their arrays and atlas take`);
  check(a.ready + a.loading === a.usedBytes, `the cache says ${a.usedBytes} bytes, its entries take ${a.ready} + ${a.loading} loading`);
  check(a.overBound === 0 && a.atlasOutsideBound === 0, `${a.overBound} entries over their reserved bound, ${a.atlasOutsideBound} atlases outside it`);
  check(a.textures === a.textureBytes, `the cache counts ${a.textureBytes} atlas bytes, its atlases take ${a.textures}`);
  check(a.texturedPatches > 0 && a.textures > 0, 'no textured patch in the cache: the test tests nothing');
  check(f.at(-1).evictions > 0, 'nothing was evicted: the test tests nothing');
  const maxTex = Math.max(...f.map((x) => x.cacheTextureBytes));
  return `cache max ${(Math.max(...f.map((x) => x.cacheBytes)) / 2 ** 20).toFixed(2)} of ${capMiB} MiB, textures up to ${(maxTex / 2 ** 20).toFixed(2)} MiB; ` +
    `at the end ${a.usedBytes} bytes = ${a.ready} in ${a.texturedPatches} textured patches (atlases ${a.textures}) + ${a.loading} loading; ` +
    `${f.at(-1).evictions} evictions, ${(a.textureBytesDecoded / 2 ** 20).toFixed(2)} MiB of atlases decoded`;
});

await test('texture-corrupted', async () => {
  // One byte changed in the image of every 4th texture payload: their checksums fail.
  const src = path.join(dataDir, 'x.mt'), dst = path.join(dataDir, 'x-bad.mt');
  fs.copyFileSync(src, dst);
  const s = await openMtFile(new FileSource(src, fs));
  const fd = fs.openSync(dst, 'r+');
  const damaged = new Set();
  for (let i = 0; i < s.patches.count; i += 4) {
    const t = s.textures;
    if (!t.size[i]) continue;
    const at = t.offset[i] + t.size[i] - (t.imageBytes[i] >> 1);
    const b = Buffer.alloc(1);
    fs.readSync(fd, b, 0, 1, at);
    b[0] ^= 0x5a;
    fs.writeSync(fd, b, 0, 1, at);
    damaged.add(i);
  }
  fs.closeSync(fd);
  const { page, log } = await open(`file=/data/x-bad.mt&tol=${texTol}&fixed=3000000&bg=${texBg}&view=${texView}`);
  await converge(page);
  const n0 = await page.evaluate(() => window.mtViewer.frames.length);
  await page.waitForTimeout(1500);
  const st = await page.evaluate(() => {
    const v = window.mtViewer, mt = v.mt;
    const drawn = [...mt.meshes.entries()].map(([id, m]) => ({ id, textured: !!m.geometry.userData.mtTexture, triangles: m.geometry.index.count / 3 }));
    return { n: v.frames.length, w: v.warnings, err: v.error, f: v.frames.at(-1), drawn };
  });
  await page.close();
  fs.unlinkSync(dst);
  check(!st.err, `the page stopped: ${st.err}`);
  check(st.n > n0 + 3, `the page stopped drawing frames after the warnings (${n0} -> ${st.n})`);
  check(!log.some((m) => m.startsWith('pageerror')), `page error: ${log.find((m) => m.startsWith('pageerror'))}`);
  check(st.w.length > 0, 'no warning');
  check(st.w.every((m) => /texture of patch (\d+) is damaged: checksum mismatch in payload at byte offset \d+ .*drawn untextured/.test(m) && damaged.has(Number(/texture of patch (\d+)/.exec(m)[1]))),
    `unexpected warning: ${st.w.find((m) => !/texture of patch/.test(m))}`);
  const untextured = st.drawn.filter((d) => !d.textured);
  check(untextured.length > 0 && untextured.every((d) => damaged.has(d.id) && d.triangles > 0), `drawn untextured: ${untextured.map((d) => d.id).join(',')}`);
  check(st.drawn.some((d) => d.textured), 'no patch drawn textured');
  check(log.some((m) => /drawn untextured/.test(m)), 'no warning on the console');
  return `${damaged.size} texture payloads damaged, ${st.w.length} warnings ("${st.w[0].replace(/^.*?: /, '').slice(0, 80)}..."), ` +
    `${untextured.length} of ${st.drawn.length} patches drawn untextured, still drawing`;
});

await browser.close();
srv.proc.kill();
noRange.proc.kill();
fs.rmSync(root, { recursive: true, force: true });
const passed = results.filter((x) => x).length;
console.log(`${passed} passed, ${results.length - passed} failed`);
process.exit(passed === results.length ? 0 : 1);
