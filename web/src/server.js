// The PatchServer of the browser (mtrender/patch_server.h's role): takes the cut's request list
// each frame (it replaces the previous one), reads the payloads by HTTP range requests, a few in
// flight, neighbouring payloads of the file coalesced into one request, and has them checked and
// decoded by Web Workers into the cache. A damaged patch is reported once (a warning), marked bad
// and never asked for again. The measured load time per patch sets the load budget (extract.js).

import { NoRangeError } from './source.js';

export class PatchServer {
  // A decoding job's size: ~35 ms of one worker on this machine (1.7-1.9 M triangles/s).
  static kJobTriangles = 65536;
  /**
   * @param {object} scene openMtFile()'s scene
   * @param {import('./cache.js').PatchCache} cache
   * @param {{workers?:number, inFlight?:number, libs:object, makeGeometry:Function,
   *          onWarning?:Function, onFatal?:Function}} opt
   */
  constructor(scene, cache, opt) {
    this.scene = scene;
    this.cache = cache;
    this.opt = opt;
    this.queue = [];
    this.inFlight = 0;
    this.aheadInFlight = 0;  // of inFlight: batches with a look-ahead load (extract.js, Urgency.Ahead)
    this.maxInFlight = opt.inFlight || 12;
    this.loads = 0;
    this.bad = 0;
    this.badTextures = 0;  // patches whose texture payload was damaged (drawn untextured)
    this.textureBytes = 0;  // RGBA8 atlas bytes decoded so far (all loads, evicted ones too)
    this.bytesRead = 0;
    this.requests = 0;
    // Where a load's time goes (the bench's profile of a still view): the range reads' wall time
    // (summed over requests, which overlap), the workers' decoding time (summed over workers), and
    // the decoded results' wait between the worker and the page.
    this.fetchMs = 0;
    this.decodeMs = 0;
    this.textureMs = 0;  // of decodeMs: the workers waiting for their batches' images (createImageBitmap)
    this.geometryMs = 0;
    this.loadMsAvg = 0;
    this.warnings = [];
    this.jobs = new Map();
    this.nextJob = 1;
    // The triangles posted to each worker and not decoded yet, and whether it is ready (its
    // decoders in): a job goes to the ready worker with the fewest (see load()).
    this.workerTriangles = [];
    this.workerReady = [];
    const h = scene.header;
    this.workers = opt.pool || PatchServer.spawnWorkers(opt.libs, opt.workers);
    const init = { type: 'init', libs: opt.libs, codec: h.codec, gridBits: h.gridBits, gridOrigin: h.gridOrigin, gridStep: h.gridStep, center: scene.center };
    this.init = init;
    // grow() takes the pool to this many workers once the first image is up: on two cores, one
    // worker while the page starts (its modules and WebGL context want the other core), two for a
    // still view's loads, while the page itself draws little.
    this.maxWorkers = opt.workers || Math.max(2, this.workers.length);
    this.ready = Promise.all(this.workers.map((w) => {
      this.workerTriangles.push(0);
      this.workerReady.push(true);  // jobs posted before its decoders are in wait in its queue
      return new Promise((resolve, reject) => {
        w.onmessage = (e) => {
          if (e.data.type === 'ready') {
            // When the worker's module ran, its decoders were in, and it was ready (page time, ms).
            const rel = (x) => x - performance.timeOrigin;
            this.workerTimes = { started: rel(e.data.startedAt), libs: rel(e.data.libsAt), ready: rel(e.data.readyAt) };
            this.decoder = e.data.decoder;  // 'wasm', or 'javascript' (decoderNote says why)
            this.decoderNote = e.data.decoderNote;
            if (e.data.error) reject(new Error(e.data.error));
            else resolve();
            w.onmessage = (ev) => this.onDecoded(ev.data);
          }
        };
        w.onerror = (e) => reject(new Error(`decoder worker: ${e.message}`));
        w.postMessage(init);
      });
    }));
  }
  /** Starts the decoding workers and has them load the npm decoders (before the file is open). */
  static spawnWorkers(libs, workers) {
    const count = workers || Math.max(1, Math.min(4, ((typeof navigator !== 'undefined' && navigator.hardwareConcurrency) || 2) - 1));
    return Array.from({ length: count }, () => {
      const w = new Worker(new URL('./worker.js', import.meta.url), { type: 'module' });
      w.postMessage({ type: 'libs', libs });
      return w;
    });
  }
  /** Adds workers up to maxWorkers (their decoders load meanwhile; jobs posted wait for them). */
  grow() {
    const more = this.maxWorkers - this.workers.length;
    if (more <= 0 || this.disposed) return;
    for (const w of PatchServer.spawnWorkers(this.opt.libs, more)) {
      const i = this.workers.length;
      w.onmessage = (ev) => {
        if (ev.data.type === 'decoded') this.onDecoded(ev.data);
        else if (ev.data.error) this.warn(ev.data.error);
        else if (ev.data.type === 'ready') this.workerReady[i] = true;
      };
      w.postMessage(this.init);
      this.workers.push(w);
      this.workerTriangles.push(0);
      this.workerReady.push(false);  // given jobs once its decoders are in
    }
  }
  meanLoadMs() { return this.loadMsAvg; }
  /** Replaces the pending requests ({id, urgency}[], in priority order). */
  submit(requests, frame) {
    this.queue = requests.slice();
    this.frame = frame;
    this.pump();
  }
  idle() { return this.queue.length === 0 && this.inFlight === 0; }
  warn(msg) {
    this.warnings.push(msg);
    if (this.opt.onWarning) this.opt.onWarning(msg);
    else console.warn(msg);
  }
  // Takes the next request and its file neighbours among the queued ones (gaps up to 16 KiB, up to
  // 512 KiB a request): one range read for a run of payloads written together.
  nextBatch() {
    const p = this.scene.patches;
    while (this.queue.length) {
      const head = this.queue.shift();
      if (this.cache.state(head.id) !== 'absent') continue;
      const near = this.queue.filter((r) => this.cache.state(r.id) === 'absent' && Math.abs(p.offset[r.id] - p.offset[head.id]) < 524288);
      near.push(head);
      near.sort((a, b) => p.offset[a.id] - p.offset[b.id]);
      let i = near.indexOf(head), lo = i, hi = i;
      const end = this.scene.loadEnd;  // a patch's payload, then its texture payload if it has one
      const gap = (a, b) => p.offset[near[b].id] - end[near[a].id];
      const span = () => end[near[hi].id] - p.offset[near[lo].id];
      while (hi + 1 < near.length && gap(hi, hi + 1) <= 16384 && span() < 524288) ++hi;
      while (lo > 0 && gap(lo - 1, lo) <= 16384 && span() < 524288) --lo;
      const batch = [];
      let ahead = false;  // any look-ahead request in it makes it the one look-ahead batch in flight
      for (let k = lo; k <= hi; ++k) {
        const id = near[k].id;
        if (this.cache.reserve(id, this.scene.decodedBytes[id])) batch.push(id), (ahead = ahead || near[k].urgency < 0);
        else if (id === head.id) return batch.length ? Object.assign(batch, { ahead }) : null;  // no room: try again next frame
      }
      const taken = new Set(batch);
      this.queue = this.queue.filter((r) => !taken.has(r.id));
      if (batch.length) return Object.assign(batch, { ahead });
    }
    return null;
  }
  pump() {
    while (this.inFlight < this.maxInFlight && this.queue.length) {
      const batch = this.nextBatch();
      if (!batch) break;
      this.load(batch);
    }
  }
  async load(batch) {
    ++this.inFlight;
    const ahead = !!batch.ahead;
    if (ahead) ++this.aheadInFlight;
    const p = this.scene.patches;
    const t0 = performance.now();
    const begin = p.offset[batch[0]];
    const last = batch[batch.length - 1];
    const end = this.scene.loadEnd[last];
    let buf;
    try {
      buf = await this.scene.source.read(begin, end);
    } catch (e) {
      for (const id of batch) this.cache.cancel(id);
      --this.inFlight;
      if (ahead) --this.aheadInFlight;
      if (e instanceof NoRangeError && this.opt.onFatal) this.opt.onFatal(e);
      else this.warn(`${this.scene.path}: reading patches ${batch.join(', ')}: ${e.message}`);
      return;
    }
    this.bytesRead += end - begin;
    ++this.requests;
    this.fetchMs += performance.now() - t0;
    const tx = this.scene.textures;
    // Each item's payload (and texture payload) by its place in the file; a job gets one copy of
    // the bytes its items span (one array buffer a job, not one a patch: ~1000 small copies cost
    // the page's thread ~70 ms of a still view's loads).
    const items = batch.map((id) => {
      const it = {
        id, offset: p.offset[id], size: p.size[id], triangles: p.triangles[id], checksumLo: p.checksumLo[id], checksumHi: p.checksumHi[id],
      };
      // The texture payload read with it (mt_format.h: it follows the patch's payload), checked and
      // decoded by the worker as well.
      if (tx && tx.size[id]) {
        it.texture = {
          offset: tx.offset[id], size: tx.size[id], width: tx.width[id], height: tx.height[id], imageBytes: tx.imageBytes[id],
          checksumLo: tx.checksumLo[id], checksumHi: tx.checksumHi[id],
        };
      }
      return it;
    });
    // The request's payloads go to the workers in jobs of at most kJobTriangles triangles (at least
    // one patch), each to the ready worker with the fewest triangles waiting. A request of up to
    // 512 KiB holds up to ~300 patches of a 53 M build: handed whole to the next worker in turn, a
    // still view's loads kept one worker decoding a large request while the other sat idle (the
    // workers used ~0.75 of the two cores while the loads ran).
    const req = { left: 0, ahead, t0, count: items.length };
    for (let k = 0; k < items.length;) {
      let tris = 0;
      const part = [];
      while (k < items.length && (part.length === 0 || tris + items[k].triangles <= PatchServer.kJobTriangles)) tris += items[k].triangles, part.push(items[k++]);
      let wi = -1;
      for (let i = 0; i < this.workers.length; ++i)
        if (this.workerReady[i] && (wi < 0 || this.workerTriangles[i] < this.workerTriangles[wi])) wi = i;
      const job = this.nextJob++;
      this.jobs.set(job, { req, worker: wi, triangles: tris });
      this.workerTriangles[wi] += tris;
      ++req.left;
      // The job's bytes: from its first payload to its last item's end; `base` is their file offset.
      const base = part[0].offset, jobEnd = Math.max(...part.map((it) => this.scene.loadEnd[it.id]));
      const bytes = buf.slice(base - begin, jobEnd - begin);
      this.workers[wi].postMessage({ type: 'decode', job, items: part, bytes, base }, [bytes]);
    }
  }
  onDecoded(msg) {
    const j = this.jobs.get(msg.job);
    this.jobs.delete(msg.job);
    this.workerTriangles[j.worker] -= j.triangles;
    this.decodeMs += msg.busyMs || 0;
    this.textureMs += msg.textureMs || 0;
    const tg = performance.now();
    for (const r of msg.results) {
      if (r.error) {
        ++this.bad;
        this.cache.markBad(r.id);
        this.warn(`${this.scene.path}: ${r.error}; the patch is skipped`);
        continue;
      }
      // A damaged texture: the patch is drawn untextured, with a warning (its geometry is sound).
      if (r.textureError) {
        ++this.badTextures;
        this.warn(`${this.scene.path}: ${r.textureError}; the patch is drawn untextured`);
      }
      // The cache holds what the patch actually takes (its reservation was a bound).
      const atlas = r.texture ? 4 * r.texture.width * r.texture.height : 0;
      this.cache.commit(r.id, this.opt.makeGeometry(r), r.bytes, atlas);
      this.textureBytes += atlas;
      ++this.loads;
    }
    this.geometryMs += performance.now() - tg;
    // The request is done when its last job is: its time per patch feeds the load budget.
    if (--j.req.left === 0) {
      const ms = (performance.now() - j.req.t0) / Math.max(1, j.req.count);
      this.loadMsAvg = this.loadMsAvg === 0 ? ms : 0.9 * this.loadMsAvg + 0.1 * ms;
      --this.inFlight;
      if (j.req.ahead) --this.aheadInFlight;
    }
    this.pump();
  }
  dispose() {
    this.disposed = true;
    for (const w of this.workers) w.terminate();
  }
}
