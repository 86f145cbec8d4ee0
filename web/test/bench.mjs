// node test/bench.mjs BIN_DIR FILE.mt [--frames 600] [--budget 33] [--tol 1] [--cache 256] [--shots DIR]
//                    [--dump FRAMES.json] (the per-frame records of window.mtViewer.frames)
//                    [--fixed N] (a fixed render budget of N triangles instead of the time model: raw draw cost)
//                    [--query K=V&...] (more viewer.html parameters, e.g. side=front)
//                    [--first-only] (stop at the first image: its time and steps)
//                    [--web DIR] (serve this copy of web/ instead, e.g. main's, for interleaved comparisons;
//                     it must have node_modules/)
//                    [--threads] (each browser thread's CPU from the stop to the cut at the tolerance
//                     with nothing loading, and from there to its image on screen; /proc sampled every
//                     50 ms, which costs the machine a little CPU itself)
// The web viewer's figures on one MT file served by mtserve, in headless Chromium at 1280x720
// (bench/web.sh runs it): time to the first image after page load, the share of frames within the
// page's budget over a 600-frame orbit path, the cache against its cap, bytes fetched per frame and
// in total against the file size, and the time the screen error takes to reach the tolerance once
// the camera stops (the path's last 15% is still).
import fs from 'node:fs';
import path from 'node:path';
import os from 'node:os';
import { spawn } from 'node:child_process';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const here = path.dirname(fileURLToPath(import.meta.url));
const args = process.argv.slice(2);
const opt = (name, def) => {
  const i = args.indexOf(name);
  return i >= 0 ? args[i + 1] : def;
};
const [binDir, file] = args;
const frames = Number(opt('--frames', 600)), budget = Number(opt('--budget', 50)), tol = Number(opt('--tol', 1));
const cacheMiB = Number(opt('--cache', 256)), shots = opt('--shots', ''), dump = opt('--dump', '');
const fixed = Number(opt('--fixed', 0));
const firstOnly = args.includes('--first-only');  // the first image's lines only (no path)
const threads = args.includes('--threads');
const root = fs.mkdtempSync(path.join(os.tmpdir(), 'mtbench-'));
fs.symlinkSync(path.resolve(opt('--web', path.resolve(here, '..'))), path.join(root, 'web'));
fs.symlinkSync(path.resolve(file), path.join(root, 'model.mt'));
const srv = await new Promise((resolve, reject) => {
  const p = spawn(path.join(binDir, 'mtserve'), [root, '--port', '0', '-q'], { stdio: ['ignore', 'pipe', 'inherit'] });
  p.stdout.on('data', (d) => {
    const m = /:(\d+)\//.exec(String(d));
    if (m) resolve({ proc: p, base: `http://127.0.0.1:${m[1]}` });
  });
  p.on('exit', (c) => reject(new Error(`mtserve exited ${c}`)));
});
let browser = null;
let threadWindows = null;  // --threads: prints the still stretch's CPU by thread
// The browser, mtserve and the served directory go on every way out (an error, a time-out, ^C).
async function cleanup() {
  if (browser) await browser.close().catch(() => {});
  browser = null;
  srv.proc.kill();
  fs.rmSync(root, { recursive: true, force: true });
}
process.on('SIGINT', () => cleanup().then(() => process.exit(130)));
try {
browser = await chromium.launch({
  executablePath: '/usr/bin/chromium', headless: true,
  args: ['--no-sandbox', '--disable-gpu', '--disable-background-networking', '--disable-component-update', '--disable-sync',
    '--no-first-run', '--use-angle=swiftshader', '--enable-unsafe-swiftshader'],
});
// CPU time (user + system, ms) of this process's descendants but mtserve: the browser's processes
// (renderer, GPU process with SwiftShader, ...). Over the path, against its wall time, it tells the
// browser's own cost of a frame from time spent waiting for a core on a loaded machine.
const tick = 1000 / 100;  // USER_HZ
// Every process's parent and CPU (ms), read once from /proc; descendants(procs) lists this
// process's descendants but mtserve.
function processes() {
  const procs = new Map();
  for (const d of fs.readdirSync('/proc')) {
    if (!/^\d+$/.test(d)) continue;
    try {
      const st = fs.readFileSync(`/proc/${d}/stat`, 'utf8');
      const f = st.slice(st.lastIndexOf(')') + 2).split(' ');
      procs.set(Number(d), { ppid: Number(f[1]), cpu: (Number(f[11]) + Number(f[12])) * tick });
    } catch { /* gone */ }
  }
  return procs;
}
function descendants(procs) {
  const out = [];
  for (const [pid, k] of procs) {
    if (pid === srv.proc.pid) continue;
    for (let p = k.ppid, n = 0; p > 1 && n < 64; p = procs.get(p)?.ppid ?? 0, ++n)
      if (p === process.pid) {
        out.push(pid);
        break;
      }
  }
  return out;
}
function browserCpuMs() {
  const procs = processes();
  return descendants(procs).reduce((sum, pid) => sum + procs.get(pid).cpu, 0);
}
const loadavg = () => fs.readFileSync('/proc/loadavg', 'utf8').split(' ').slice(0, 3).join(' ');
// --threads: every 50 ms, the CPU (ms) of each thread of this process's descendants but mtserve,
// keyed "process type:thread name" (Chromium's --type, thread names with their numbers dropped).
const samples = [];
function sampleThreads() {
  const m = new Map();
  for (const d of descendants(processes())) {
    let cmd, tasks;
    try {
      cmd = fs.readFileSync(`/proc/${d}/cmdline`, 'utf8');
      tasks = fs.readdirSync(`/proc/${d}/task`);
    } catch { continue; }
    const type = (/--type=([\w-]+)/.exec(cmd) || [, 'browser'])[1];
    for (const t of tasks) {
      try {
        const st = fs.readFileSync(`/proc/${d}/task/${t}/stat`, 'utf8');
        const name = st.slice(st.indexOf('(') + 1, st.lastIndexOf(')')).replace(/\d+$/, '');
        const f = st.slice(st.lastIndexOf(')') + 2).split(' ');
        const key = `${type}:${name}`;
        m.set(key, (m.get(key) || 0) + (Number(f[11]) + Number(f[12])) * tick);
      } catch { /* gone */ }
    }
  }
  samples.push({ t: Date.now(), m });
}
// The threads' CPU between two wall-clock times (ms since the epoch), largest first.
function threadWindow(a, b, label) {
  const at = (t) => samples.reduce((x, s) => (Math.abs(s.t - t) < Math.abs(x.t - t) ? s : x));
  const A = at(a), B = at(b), d = [];
  for (const [k, v] of B.m) if (v - (A.m.get(k) || 0) > 0) d.push([k, v - (A.m.get(k) || 0)]);
  d.sort((x, y) => y[1] - x[1]);
  const sum = d.reduce((acc, x) => acc + x[1], 0);
  console.log(`threads, ${label.padEnd(16)} ${B.t - A.t} ms wall, ${sum.toFixed(0)} ms CPU (${(sum / Math.max(B.t - A.t, 1)).toFixed(2)} cores): ` +
    d.slice(0, 8).map(([k, v]) => `${k} ${v.toFixed(0)}`).join(', '));
}
const page = await browser.newPage({ viewport: { width: 1280, height: 720 } });
page.on('pageerror', (e) => console.error('pageerror:', e.message));
const sampler = threads ? setInterval(sampleThreads, 50) : null;
const q = `file=/model.mt&tol=${tol}&budget=${budget}&cache=${cacheMiB}&path=orbit&frames=${frames}` + (fixed ? `&fixed=${fixed}` : '') + (opt('--query', '') ? `&${opt('--query', '')}` : '');
await page.goto(`${srv.base}/web/viewer.html?${q}`);
await page.waitForFunction(() => window.mtViewer.firstImageMs !== null || window.mtViewer.error, null, { timeout: 60000 });
const loadMs = await page.evaluate(() => performance.timing.loadEventEnd - performance.timing.navigationStart);
if (shots) {
  await page.waitForTimeout(1500);
  await page.screenshot({ path: path.join(shots, 'web-viewer-moving.png') });
}
if (firstOnly) {
  const s = await page.evaluate(() => ({ first: window.mtViewer.firstImageMs, fileSize: window.mtViewer.fileSize, decoder: window.mtViewer.decoder, openBytes: window.mtViewer.openBytes,
    openTimes: window.mtViewer.openTimes, openReads: window.mtViewer.openReads, error: window.mtViewer.error,
    fileRequests: performance.getEntriesByType('resource').filter((r) => r.name.endsWith('/model.mt') && r.startTime < window.mtViewer.firstImageMs).map((r) => [r.startTime, r.responseEnd]) }));
  await cleanup();
  reportFirst(s, loadMs);
  process.exit(s.error ? 1 : 0);
}
const cpu0 = browserCpuMs(), wall0 = performance.now(), frame0 = await page.evaluate(() => window.mtViewer.frames.length);
const load0 = loadavg();
await page.waitForFunction(() => window.mtViewer.done || window.mtViewer.error, null, { timeout: 600000, polling: 250 });
const cpu1 = browserCpuMs(), wall1 = performance.now(), frame1 = await page.evaluate(() => window.mtViewer.frames.length);
const load1 = loadavg();
// Hold still until the screen error reaches the tolerance and nothing loads (or 20 s).
const stillFrom = await page.evaluate(() => window.mtViewer.frames.find((f) => f.still).t);
await page.waitForFunction((tol) => {
  const f = window.mtViewer.frames.at(-1);
  return f.err <= tol && f.pending === 0;
}, tol, { timeout: 20000, polling: 50 }).catch(() => {});
if (sampler) {
  clearInterval(sampler);
  sampleThreads();
  const w = await page.evaluate((tol) => {
    const f = window.mtViewer.frames, s = f.find((x) => x.still);
    if (!s) return { origin: 0, still: 0, loaded: null, shown: null };
    const loaded = f.find((x) => x.t >= s.t && x.cutErr <= tol && x.pending === 0), shown = f.find((x) => x.t >= s.t && x.err <= tol);
    return { origin: performance.timeOrigin, still: s.t, loaded: loaded ? loaded.t : null, shown: shown ? shown.t : null };
  }, tol);
  threadWindows = () => {
    if (w.loaded !== null) threadWindow(w.origin + w.still, w.origin + w.loaded, 'stop to loaded');
    if (w.loaded !== null && w.shown !== null) threadWindow(w.origin + w.loaded, w.origin + w.shown, 'loaded to shown');
  };
}
if (shots) await page.screenshot({ path: path.join(shots, 'web-viewer-still.png') });
// The final cut drawn whole, three times, each waited for: SwiftShader's raw rate on it.
const raw = await page.evaluate(() => window.mtViewer.drawRate(3));
const s = await page.evaluate(() => ({ frames: window.mtViewer.frames, first: window.mtViewer.firstImageMs, fileSize: window.mtViewer.fileSize, decoder: window.mtViewer.decoder,
  openBytes: window.mtViewer.openBytes, resources: performance.getEntriesByType('resource').map((r) => [r.name.replace(location.origin, ''), r.startTime, r.responseEnd, r.transferSize]).filter((r) => r[1] < window.mtViewer.firstImageMs),
  nav: (({ responseEnd, domInteractive, domContentLoadedEventEnd }) => ({ responseEnd, domInteractive, domContentLoadedEventEnd }))(performance.getEntriesByType('navigation')[0]), openTimes: window.mtViewer.openTimes, openReads: window.mtViewer.openReads, error: window.mtViewer.error, warnings: window.mtViewer.warnings.length,
  fileRequests: performance.getEntriesByType('resource').filter((r) => r.name.endsWith('/model.mt') && r.startTime < window.mtViewer.firstImageMs).map((r) => [r.startTime, r.responseEnd]) }));
await cleanup();
report(s, raw, stillFrom, loadMs, { cpu0, cpu1, wall0, wall1, frame0, frame1, load0, load1 });
} catch (e) {
  await cleanup();
  console.error(`bench: ${e.message}`);
  process.exit(1);
}

function report(s, raw, stillFrom, loadMs, { cpu0, cpu1, wall0, wall1, frame0, frame1, load0, load1 }) {
if (s.error) {
  console.error(`bench: ${s.error}`);
  process.exit(1);
}
const f = s.frames;
if (dump) fs.writeFileSync(dump, JSON.stringify(f));
const pathFrames = f.slice(1, frames);
const ms = pathFrames.map((x) => x.frameMs).sort((a, b) => a - b);
const within = ms.filter((x) => x <= budget).length / ms.length;
const cap = f[0].cacheCap, maxCache = Math.max(...f.map((x) => x.cacheBytes));
const reach = f.find((x) => x.t >= stillFrom && x.err <= tol);
const bytesPath = f[frames - 1].bytesRead;
const mib = (b) => (b / 2 ** 20).toFixed(2);
reportFirst(s, loadMs);
console.log(`frames within ${budget} ms     ${(100 * within).toFixed(1)}% of ${ms.length} path frames (median ${ms[ms.length >> 1].toFixed(1)} ms, p95 ${ms[Math.floor(0.95 * ms.length)].toFixed(1)} ms, max ${ms.at(-1).toFixed(1)} ms)`);
const med = (k) => pathFrames.map((x) => x[k]).sort((a, b) => a - b)[pathFrames.length >> 1];
console.log(`browser CPU               ${((cpu1 - cpu0) / (frame1 - frame0)).toFixed(1)} ms a frame (all its processes, user + system) against ${((wall1 - wall0) / (frame1 - frame0)).toFixed(1)} ms of wall time a frame, over ${frame1 - frame0} frames; load average ${load0} before, ${load1} after (${os.cpus().length} cores)`);
console.log(`page's own work         median cut update ${med('updateMs').toFixed(1)} ms, render calls ${med('renderMs').toFixed(1)} ms a frame (the rest of a frame is the browser's: SwiftShader, compositing)`);
console.log(`triangles drawn           median ${pathFrames.map((x) => x.drawn).sort((a, b) => a - b)[pathFrames.length >> 1]}, max ${Math.max(...f.map((x) => x.drawn))}`);
console.log(`cache                     max ${mib(maxCache)} MiB of a ${mib(cap)} MiB cap (${maxCache <= cap ? 'never above' : 'ABOVE'} the cap)`);
console.log(`bytes fetched             ${mib(bytesPath)} MiB over the path (${(bytesPath / frames / 1024).toFixed(1)} KiB/frame), ${mib(f.at(-1).bytesRead)} MiB in all = ${(100 * f.at(-1).bytesRead / s.fileSize).toFixed(1)}% of the file`);
console.log(`screen error after stop   ${reach ? `reached ${tol} px ${(reach.t - stillFrom).toFixed(0)} ms after the camera stopped` : `not at ${tol} px within 20 s (last ${f.at(-1).err.toFixed(2)} px, ${f.at(-1).drawn} triangles)`}`);
// The still stretch: how fast SwiftShader drew (triangles drawn / wall time from the stop to the
// tolerance, or to the end) and how many triangles the cut at the tolerance holds: the floor of
// the time to the tolerance is that cut drawn once at that rate.
{
  const end = reach || f.at(-1);
  const st = f.filter((x) => x.t >= stillFrom && x.t <= end.t);
  const drawn = st.reduce((a, x) => a + x.drawn, 0), wall = end.t - stillFrom;
  const rate = drawn / Math.max(wall, 1) / 1000;  // M triangles/s
  console.log(`still stretch             ${st.length} frames, ${(drawn / 1e6).toFixed(2)} M triangles drawn in ${(wall / 1000).toFixed(1)} s = ${rate.toFixed(2)} M triangles/s; ` +
    `cut ${reach ? 'at the tolerance' : 'at the end'} ${(end.triangles / 1e6).toFixed(2)} M triangles: drawn once at that rate ${(end.triangles / rate / 1e6).toFixed(1)} s`);
}
{
  // The still stretch's milestones: the update's cut at the tolerance (its patches resident, since
  // a cut only holds resident patches), nothing left loading, and that cut's image on screen.
  const st = f.filter((x) => x.t >= stillFrom);
  const at = (pred) => { const x = st.find(pred); return x ? `${((x.t - stillFrom) / 1000).toFixed(2)} s` : 'never'; };
  const rawMs = [...raw.ms].sort((a, b) => a - b);
  console.log(`still milestones          cut chosen at ${tol} px ${at((x) => x.cutErr <= tol)}, and nothing loading ${at((x) => x.cutErr <= tol && x.pending === 0)}, on screen ${at((x) => x.err <= tol)}; ` +
    `images shown ${st.filter((x, i) => i > 0 && x.err !== st[i - 1].err).length}, triangles drawn ${(st.filter((x) => !reach || x.t <= reach.t).reduce((a, x) => a + x.drawn, 0) / 1e6).toFixed(2)} M until then` +
    (reach ? `; its image left out ${(reach.hidden / 1e6).toFixed(2)} M of the cut's ${(reach.triangles / 1e6).toFixed(2)} M triangles as hidden (occlusion tests)` : ''));
  console.log(`raw draw of the last cut  ${(raw.triangles / 1e6).toFixed(2)} M triangles in ${rawMs.map((x) => x.toFixed(0)).join(' / ')} ms = ${(raw.triangles / rawMs[1] / 1000).toFixed(2)} M triangles/s (median; one full draw, synchronised)`);
}
{
  // Where the still stretch's time goes, from the stop to the cut at the tolerance with nothing
  // loading (or the end): the loads (range requests, bytes, the reads' wall time summed over the
  // requests in flight, the workers' decoding time), and the page's own work (cut updates; render
  // calls: geometry upload and the drawing of each chunk, waited for).
  const st = f.filter((x) => x.t >= stillFrom);
  const end = st.find((x) => x.cutErr <= tol && x.pending === 0) || st.at(-1), a = st[0];
  const upto = st.filter((x) => x.t <= end.t);
  const sum = (k) => upto.reduce((acc, x) => acc + x[k], 0);
  const secs = (ms) => (ms / 1000).toFixed(2);
  console.log(`still profile             to loaded ${secs(end.t - a.t)} s: ${end.loads - a.loads} patches in ${end.requests - a.requests} requests, ${mib(end.bytesRead - a.bytesRead)} MiB; ` +
    `reads ${secs(end.fetchMs - a.fetchMs)} s (summed over requests in flight), workers decoding ${secs(end.decodeMs - a.decodeMs)} s; ` +
    `page: cut updates ${secs(sum('updateMs'))} s, render calls ${secs(sum('renderMs'))} s over ${upto.length} frames`);
}
console.log(`damaged patches skipped   ${s.warnings}`);
if (threadWindows) threadWindows();
}

// The first image's lines: its time after navigation start, its steps, the opening's reads.
function reportFirst(s, loadMs) {
if (s.error) {
  console.error(`bench: ${s.error}`);
  return;
}
const mib = (b) => (b / 2 ** 20).toFixed(2);
console.log(`file                      ${file} (${mib(s.fileSize)} MiB); patches decoded in ${s.decoder}`);
console.log(`page load                 ${loadMs} ms (load event)`);
console.log(`first image               ${s.first.toFixed(0)} ms after navigation start, ${(s.first - loadMs).toFixed(0)} ms after the load event (${mib(s.openBytes)} MiB read to it: header, DAG, index, coarsest cut)` +
  (s.openReads ? `; ${s.openReads.requests} range requests to it, ${s.openReads.kept} reads answered from the file's tail` : ''));
if (s.openTimes) {
  const o = s.openTimes, d = (a, b) => (o[b] - o[a]).toFixed(0);
  console.log(`first image's steps       page script ${o.start.toFixed(0)} ms, header+DAG+index ${d('start', 'index')} ms, workers ready ${d('index', 'workers')} ms, ` +
    `coarsest cut loaded ${d('workers', 'coarsest')} ms, shaders ${o.compiled ? d('coarsest', 'compiled') : '-'} ms, closed-surface test ${d(o.compiled ? 'compiled' : 'coarsest', 'surface')} ms, to the first frame ${d('surface', 'frame')} ms, ` +
    `update ${d('frame', 'update')} ms, render calls ${d('update', 'render')} ms, drawing waited for ${d('render', 'drawn')} ms`);
  if (process.env.BENCH_RESOURCES && s.resources) {
    console.log('  navigation', JSON.stringify(s.nav));
    for (const r of s.resources) console.log(`  ${r[1].toFixed(0)}-${r[2].toFixed(0)} ms ${r[0]} (${r[3]} B)`);
  }
  if (s.fileRequests) console.log(`  the file's requests      ${s.fileRequests.map((r) => `${r[0].toFixed(0)}-${r[1].toFixed(0)}`).join(', ')} ms (sent-answered, page time)`);
  if (o.worker) console.log(`  a decoding worker        module running ${o.worker.started.toFixed(0)} ms, decoders in ${o.worker.libs.toFixed(0)} ms, ready ${o.worker.ready.toFixed(0)} ms (page time)`);
  if (o.file) {
    const f = o.file, e = (a, b) => (f[b] - f[a]).toFixed(0);
    console.log(`  the file's opening       begun ${f.begin.toFixed(0)} ms: tail and header ${e('begin', 'tail')} ms, header checked ${e('tail', 'header')} ms, DAG+index read ${e('header', 'read')} ms, ` +
      `checksum ${e('read', 'hashed')} ms, records ${e('hashed', 'parsed')} ms, checks + DAG ${e('parsed', 'built')} ms`);
  }
}
}
