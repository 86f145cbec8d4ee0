// node server_jobs.mjs: the PatchServer's decoding jobs (src/server.js), with stand-in workers and a
// stand-in file. One range request of 300 payloads (a still view's loads of a 53 M build come in
// requests like it) must reach the workers as jobs of at most PatchServer.kJobTriangles triangles
// (a larger patch alone), each posted to the ready worker with the fewest triangles waiting
// (replayed in posting order); a worker whose decoders are not in yet (grown) gets nothing until it
// says it is ready, and then the next request's jobs; a request stays in flight (and its time per
// patch untaken) until its last job is answered; a look-ahead request is counted in aheadInFlight
// until then; when every job is answered, nothing is in flight, every patch is in the cache and no
// worker has triangles waiting. Exits 1 naming the first rule broken.
import { PatchServer } from '../src/server.js';
import { PatchCache } from '../src/cache.js';

let failed = 0;
const check = (ok, what) => {
  if (!ok) {
    console.error(`server_jobs: ${what}`);
    failed = 1;
  }
};

// ~300 payloads written one after another: most of 1-3 k triangles, a few of 20-40 k, one of
// 100 k (larger than a job). A payload takes a byte a triangle here; the request reads them at once.
const count = 320;
const triangles = [], offset = [], size = [];
let at = 4096;
for (let i = 0; i < count; ++i) {
  const t = i === 150 ? 100000 : i % 37 === 5 ? 20000 + 500 * (i % 41) : 1000 + ((i * 7919) % 2000);
  triangles.push(t);
  offset.push(at);
  size.push(Math.ceil(t / 4));  // ~300 payloads within the 512 KiB a request may span
  at += size[i];
}
const scene = {
  path: 'stand-in.mt',
  header: { codec: 1, gridBits: 15, gridOrigin: [0, 0, 0], gridStep: 1 },
  center: [0, 0, 0],
  patches: { count, offset, size, triangles, checksumLo: new Array(count).fill(0), checksumHi: new Array(count).fill(0) },
  loadEnd: offset.map((o, i) => o + size[i]),
  decodedBytes: triangles.map((t) => 40 * t),
  textures: null,
  // The file's byte at offset o is o % 251: a job's bytes show where they were cut from.
  source: { read: async (a, b) => Uint8Array.from({ length: b - a }, (_, k) => (a + k) % 251).buffer, bytesFetched: 0 },
};

let posts = 0;  // the order of every post, over all workers
class StandInWorker {
  constructor() { this.posted = []; this.onmessage = null; }
  postMessage(msg, transfer = []) { this.posted.push(Object.assign(msg, { seq: posts++, transfer })); }
  terminate() {}
  jobs() { return this.posted.filter((m) => m.type === 'decode'); }
}
const settle = () => new Promise((resolve) => setTimeout(resolve, 0));

const cache = new PatchCache(2 ** 31, () => {});
const pool = [new StandInWorker(), new StandInWorker()];
const server = new PatchServer(scene, cache, { pool: [...pool], workers: 3, libs: {}, makeGeometry: () => ({}) });
for (const w of pool) w.onmessage({ data: { type: 'ready', startedAt: 0, libsAt: 0, readyAt: 0 } });
await server.ready;
// A third worker grown now: its decoders are not in.
const grown = new StandInWorker();
PatchServer.spawnWorkers = () => [grown];
server.grow();
check(server.workers.length === 3, `grow() made ${server.workers.length} workers, not 3`);

// The first 300 payloads asked for, in one request (neighbours in the file).
server.submit(Array.from({ length: 300 }, (_, id) => ({ id, urgency: 1 })), 1);
await settle();
check(server.requests === 1, `${server.requests} range requests for 300 neighbouring payloads, not 1`);
check(grown.jobs().length === 0, `the worker whose decoders are not in got ${grown.jobs().length} jobs`);
const load = [0, 0];
let jobs = 0, largest = 0;
const seen = new Set();
for (const [wi, w] of pool.entries()) {
  for (const m of w.jobs()) {
    ++jobs;
    const t = m.items.reduce((a, it) => a + it.triangles, 0);
    largest = Math.max(largest, t);
    load[wi] += t;
    check(m.items.length === 1 || t <= PatchServer.kJobTriangles, `a job of ${m.items.length} patches and ${t} triangles (most ${PatchServer.kJobTriangles})`);
    check(m.transfer.length === 1 && m.transfer[0] === m.bytes, 'a job\'s bytes are not transferred to its worker');
    for (const it of m.items) {
      check(!seen.has(it.id), `patch ${it.id} posted twice`);
      seen.add(it.id);
      // Its payload lies in the job's bytes (one copy a job, starting at file offset m.base).
      check(it.offset === offset[it.id] && it.size === size[it.id], `patch ${it.id}: posted at ${it.offset}, ${it.size} bytes; its payload is at ${offset[it.id]}, ${size[it.id]} bytes`);
      check(it.offset >= m.base && it.offset - m.base + it.size <= m.bytes.byteLength, `patch ${it.id}: its payload is outside its job's bytes`);
      const b = new Uint8Array(m.bytes, it.offset - m.base, it.size);
      check(b[0] === it.offset % 251 && b[it.size - 1] === (it.offset + it.size - 1) % 251, `patch ${it.id}: the bytes posted for it are not its payload's`);
    }
  }
}
check(seen.size === 300, `${seen.size} patches posted, not 300`);
check(pool.every((w) => w.jobs().length > 0), `the jobs went to one worker (${pool.map((w) => w.jobs().length).join(' / ')} jobs)`);
check(Math.abs(load[0] - load[1]) <= largest, `the workers' shares ${load[0]} and ${load[1]} triangles differ by more than the largest job (${largest})`);
check(server.workerTriangles[0] === load[0] && server.workerTriangles[1] === load[1], `waiting triangles ${server.workerTriangles} against posted ${load}`);
// Replayed in posting order: each job went to a worker with no more triangles waiting than the other.
{
  const order = pool.flatMap((w, wi) => w.jobs().map((m) => ({ wi, seq: m.seq, t: m.items.reduce((a, it) => a + it.triangles, 0) }))).sort((a, b) => a.seq - b.seq);
  const waiting = [0, 0];
  for (const j of order) {
    check(waiting[j.wi] <= waiting[1 - j.wi], `job ${j.seq} went to worker ${j.wi} with ${waiting[j.wi]} triangles waiting, the other had ${waiting[1 - j.wi]}`);
    waiting[j.wi] += j.t;
  }
}
// The grown worker ready: the next request's first job is its (it has nothing waiting).
grown.onmessage({ data: { type: 'ready' } });
// (The two first workers have the first request's ~460 k triangles each waiting, it has none.)
server.submit(Array.from({ length: 20 }, (_, k) => ({ id: 300 + k, urgency: -1 })), 2);  // look-ahead loads
await settle();
check(grown.jobs().length >= 1 && pool.every((w) => w.jobs().every((m) => m.items.every((it) => it.id < 300))), 'the worker ready with nothing waiting did not get the next request\'s jobs');
check(server.inFlight === 2, `${server.inFlight} requests in flight, not 2`);
check(server.aheadInFlight === 1, `${server.aheadInFlight} look-ahead requests in flight, not 1`);

// Every job of the request answered but its last: still in flight, its time not yet taken.
const first = pool.flatMap((w) => w.jobs().map((m) => ({ w, m }))).sort((a, b) => a.m.seq - b.m.seq);
const answer = ({ w, m }) => w.onmessage({ data: { type: 'decoded', job: m.job, busyMs: 1, results: m.items.map((it) => ({ id: it.id, bytes: 40 * it.triangles })) } });
first.slice(0, -1).forEach(answer);
check(server.inFlight === 2, `${server.inFlight} requests in flight with one job of the first unanswered and the second's waiting, not 2`);
check(server.meanLoadMs() === 0, `the load time was taken before the request's last job (${server.meanLoadMs()} ms a patch)`);

// Every job answered: nothing in flight or waiting, every patch in the cache.
answer(first.at(-1));
check(server.inFlight === 1 && server.meanLoadMs() > 0, `after the first request's last job: ${server.inFlight} in flight (not 1), load time ${server.meanLoadMs()} ms a patch`);
for (const w of [...pool, grown])
  for (const m of w.jobs())
    if (m.seq > first.at(-1).m.seq) answer({ w, m });
check(server.aheadInFlight === 0, `${server.aheadInFlight} look-ahead requests in flight after their jobs were answered`);
check(server.inFlight === 0, `${server.inFlight} requests still in flight after every job was answered`);
check(server.workerTriangles.every((t) => t === 0), `triangles still waiting: ${server.workerTriangles}`);
check(server.loads === 320, `${server.loads} patches loaded, not 320`);
for (let id = 0; id < count; ++id) check(cache.state(id) === 'ready', `patch ${id}: ${cache.state(id)}, not ready`);
console.log(`server_jobs: 320 patches in 2 requests, ${jobs} jobs for the first (${load[0]} / ${load[1]} triangles, largest job ${largest}), ${grown.jobs().length} for the grown worker; ${failed ? 'FAILED' : 'ok'}`);
process.exit(failed);
