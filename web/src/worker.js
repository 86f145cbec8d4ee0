// The decoding worker: checks each payload's XXH64 and decodes it (patch_codec.js) into the
// arrays three.js draws: positions relative to the scene centre (float32), normals (int8,
// normalized; area-weighted from the triangles when the file stores none), colours (RGBA8),
// indices (uint16 when they fit). A damaged payload comes back as an error naming the patch.
// A textured patch (version 6) also has its texture payload checked (XXH64), its corner
// coordinates decoded and its vertices split per coordinate (texture.js), and its atlas decoded by
// createImageBitmap; a damaged texture comes back as `textureError` with the untextured patch.
import { decodePatch } from './patch_codec.js';
import { decodeTexturePayload, splitTexturedVertices } from './texture.js';
import { defaultLibUrls } from './libs.js';
import { loadWasmDecoder } from './codec_wasm.js';

let libs = null, cfg = null, h64Raw = null;

// Two steps, so the decoders load while the page still reads the file's index: 'libs' (the npm
// decoders), then 'init' (the file's codec and grid; Draco's decoder when the file needs it).
let libsPromise = null;
function loadLibs(urls) {
  if (!libsPromise)
    libsPromise = Promise.all([import(urls.zstd), import(urls.meshopt), import(urls.xxhash), loadWasm(urls.decoder)]).then(async ([zstdMod, meshoptMod, xxMod, wasm]) => {
      const meshopt = meshoptMod.MeshoptDecoder;
      await meshopt.ready;
      const xx = await xxMod.default();
      libsAt = performance.timeOrigin + performance.now();
      return { zstdMod, meshopt, xx, wasm };
    });
  return libsPromise;
}

// The WebAssembly decoder (codec_wasm.js), or null: without it (no URL given, or a page served
// without the built web/dist/mt_decode.wasm) the JavaScript port decodes, slower; each worker says
// why in the console once, and the page's PatchServer.decoderNote holds it.
let decoderNote = '';
async function loadWasm(url) {
  try {
    if (!url) throw new Error('no URL given (libs.decoder)');
    return await loadWasmDecoder(url);
  } catch (err) {
    decoderNote = `the WebAssembly decoder did not load (${err.message}): decoding in JavaScript, slower (cmake --build builds web/dist/mt_decode.wasm)`;
    console.warn(decoderNote);
    return null;
  }
}

// A page may start the workers before its modules load (viewer.html: `worker.js?preload`): they
// load the default decoders at once, overlapping the page's own start-up.
const startedAt = performance.timeOrigin + performance.now();  // the bench's profile of the first image
let libsAt = 0;
if (new URL(self.location.href).searchParams.has('preload')) loadLibs(defaultLibUrls()).catch(() => {});

let initPromise = null;
async function init(msg) {
  cfg = msg;
  const { zstdMod, meshopt, xx, wasm } = await loadLibs(msg.libs);
  h64Raw = xx.h64Raw;
  let draco = null;
  if (msg.codec === 2) {
    const text = await (await fetch(msg.libs.dracoWrapper)).text();
    (0, eval)(text);  // defines DracoDecoderModule (an Emscripten wrapper, not an ES module)
    const wasmBinary = await (await fetch(msg.libs.dracoWasm)).arrayBuffer();
    draco = await new Promise((resolve) => {
      self.DracoDecoderModule({ wasmBinary, onModuleLoaded: (m) => resolve(m) });
    });
  }
  libs = { zstd: (b, n) => zstdMod.decompress(b, new Uint8Array(n)), meshopt, draco, wasm };
}

let normalSums = null;
function toRender(d) {
  const n = d.q.length / 3;
  // One array buffer holds the patch's arrays (positions, normals, then indices): a third of the
  // buffers to make here, to transfer, and for the page's collector to sweep once they go.
  const wide = n > 65536, t = d.triangles;
  const buffer = new ArrayBuffer(16 * n + t.length * (wide ? 4 : 2));
  const positions = new Float32Array(buffer, 0, 3 * n);
  const o = cfg.gridOrigin, s = cfg.gridStep, c = cfg.center;
  for (let i = 0; i < n; ++i)
    for (let a = 0; a < 3; ++a) positions[3 * i + a] = o[a] + s * d.q[3 * i + a] - c[a];
  let nf = d.normals;
  if (!nf) {
    // The sums, in an array reused from patch to patch (typed arrays cost Chromium dearly to make).
    if (!normalSums || normalSums.length < n * 3) normalSums = new Float32Array(Math.max(n * 3, 2 * (normalSums ? normalSums.length : 0)));
    nf = normalSums.fill(0, 0, n * 3);
    const p = positions;
    for (let k = 0; k < t.length; k += 3) {
      const a = 3 * t[k], b = 3 * t[k + 1], cc = 3 * t[k + 2];
      const ux = p[b] - p[a], uy = p[b + 1] - p[a + 1], uz = p[b + 2] - p[a + 2];
      const vx = p[cc] - p[a], vy = p[cc + 1] - p[a + 1], vz = p[cc + 2] - p[a + 2];
      const fx = uy * vz - uz * vy, fy = uz * vx - ux * vz, fz = ux * vy - uy * vx;  // area-weighted face normal
      nf[a] += fx, (nf[a + 1] += fy), (nf[a + 2] += fz);
      nf[b] += fx, (nf[b + 1] += fy), (nf[b + 2] += fz);
      nf[cc] += fx, (nf[cc + 1] += fy), (nf[cc + 2] += fz);
    }
  }
  const normals = new Int8Array(buffer, 12 * n, 4 * n);
  for (let i = 0; i < n; ++i) {
    const x = nf[3 * i], y = nf[3 * i + 1], z = nf[3 * i + 2];
    const l = Math.sqrt(x * x + y * y + z * z) || 1;
    normals[4 * i] = Math.round((x / l) * 127);
    normals[4 * i + 1] = Math.round((y / l) * 127);
    normals[4 * i + 2] = Math.round((z / l) * 127);
  }
  const indices = wide ? new Uint32Array(buffer, 16 * n, t.length) : new Uint16Array(buffer, 16 * n, t.length);
  indices.set(t);
  return { positions, normals, colors: d.colors, indices };
}

// The bytes a decoded patch takes in the page (the cache counts these): its arrays and, textured,
// its atlas as RGBA8.
function renderBytes(r) {
  let b = r.positions.byteLength + r.normals.byteLength + r.indices.byteLength;
  if (r.colors) b += r.colors.byteLength;
  if (r.uv) b += r.uv.byteLength;
  if (r.texture) b += 4 * r.texture.width * r.texture.height;
  return b;
}

// The texture payload `data` of item `it` over the decoded patch `d` (render arrays `r`): checksum, corner
// coordinates and the vertices split per coordinate now, then the image decoded (the promise: a
// batch's images are decoded concurrently, createImageBitmap works off this thread). The promise
// rejects on any damage with the message mt_file.cpp's readTexture gives.
function withTexture(it, data, d, r) {
  const t = it.texture;
  if (h64Raw(data, 0n) !== ((BigInt(t.checksumHi) << 32n) | BigInt(t.checksumLo)))
    return Promise.reject(new Error(`texture of patch ${it.id} is damaged: checksum mismatch in payload at byte offset ${t.offset} (${data.length} bytes)`));
  const where = (what) => new Error(`texture of patch ${it.id} at byte offset ${t.offset}: ${what}`);
  const n = d.q.length / 3;
  let p, s;
  try {
    p = decodeTexturePayload(data, d.triangles, n, t, libs.zstd);
    s = splitTexturedVertices(d.triangles, n, p.cornerUV);
  } catch (err) {
    return Promise.reject(where(err.message));
  }
  const m = s.remap.length;
  const positions = new Float32Array(3 * m), normals = new Int8Array(4 * m), colors = r.colors ? new Uint8Array(4 * m) : null;
  for (let i = 0; i < m; ++i) {
    const v = s.remap[i];
    for (let a = 0; a < 3; ++a) positions[3 * i + a] = r.positions[3 * v + a], (normals[4 * i + a] = r.normals[4 * v + a]);
    if (colors) for (let a = 0; a < 4; ++a) colors[4 * i + a] = r.colors[4 * v + a];
  }
  const indices = m <= 65536 ? Uint16Array.from(s.triangles) : s.triangles;
  const blob = new Blob([p.image], { type: p.imageFormat === 1 ? 'image/jpeg' : 'image/png' });
  return createImageBitmap(blob, { premultiplyAlpha: 'none', colorSpaceConversion: 'none' }).then((bitmap) => {
    if (bitmap.width !== p.width || bitmap.height !== p.height) {
      bitmap.close();
      throw where(`the image is ${bitmap.width} x ${bitmap.height}, the payload says ${p.width} x ${p.height}`);
    }
    return { positions, normals, colors, indices, uv: s.uv, texture: { image: bitmap, width: p.width, height: p.height } };
  }, (err) => { throw where(`the image does not decode (${err.message})`); });
}

self.onmessage = async (e) => {
  const msg = e.data;
  if (msg.type === 'libs') {
    loadLibs(msg.libs).catch(() => {});  // errors are reported by 'init'
    return;
  }
  if (msg.type === 'init') {
    try {
      initPromise = init(msg);
      await initPromise;
      self.postMessage({ type: 'ready', startedAt, libsAt, readyAt: performance.timeOrigin + performance.now(),
        decoder: libs.wasm ? 'wasm' : 'javascript', decoderNote });
    } catch (err) {
      self.postMessage({ type: 'ready', error: `decoder set-up failed: ${err.message}` });
    }
    return;
  }
  if (msg.type !== 'decode') return;
  // Payloads may arrive while the decoders still load (the page reads them meanwhile).
  try {
    await initPromise;
  } catch (_) { /* reported by 'init' */ }
  if (!libs) {
    self.postMessage({ type: 'decoded', job: msg.job, results: msg.items.map((it) => ({ id: it.id, error: `patch ${it.id}: no decoder` })), busyMs: 0 });
    return;
  }
  const t0 = performance.now();
  const results = [], transfer = [], textured = [];
  // The job's payloads lie in msg.bytes, which starts at file offset msg.base.
  const at = (x) => new Uint8Array(msg.bytes, x.offset - msg.base, x.size);
  for (const it of msg.items) {
    const data = at(it);
    const sum = h64Raw(data, 0n);
    const want = (BigInt(it.checksumHi) << 32n) | BigInt(it.checksumLo);
    if (sum !== want) {
      results.push({ id: it.id, error: `patch ${it.id} is damaged: checksum mismatch in payload at byte offset ${it.offset} (${data.length} bytes)` });
      continue;
    }
    try {
      const d = decodePatch(data, cfg.codec, { bits: cfg.gridBits }, libs);
      if (d.triangles.length / 3 !== it.triangles)
        throw new Error(`triangle count ${d.triangles.length / 3} differs from the index (${it.triangles})`);
      const r = toRender(d);
      results.push({ id: it.id, ...r, textureError: null });
      if (it.texture) textured.push({ at: results.length - 1, job: withTexture(it, at(it.texture), d, r) });
    } catch (err) {
      results.push({ id: it.id, error: `patch ${it.id} at byte offset ${it.offset}: ${err.message}` });
    }
  }
  // The textured patches: their images decoded together; a damaged texture leaves the patch as it
  // was decoded (untextured) with `textureError`.
  const tt = performance.now();
  const done = await Promise.allSettled(textured.map((x) => x.job));
  const textureMs = performance.now() - tt;  // of busyMs: waiting for the images
  done.forEach((o, k) => {
    const res = results[textured[k].at];
    if (o.status === 'fulfilled') Object.assign(res, o.value);
    else res.textureError = o.reason.message;
  });
  const sent = new Set();
  for (const r of results) {
    if (r.error) continue;
    r.bytes = renderBytes(r);
    // Each buffer once (a patch's arrays may share one: toRender).
    for (const a of [r.positions, r.normals, r.indices, r.colors, r.uv]) if (a && !sent.has(a.buffer)) sent.add(a.buffer), transfer.push(a.buffer);
    if (r.texture) transfer.push(r.texture.image);
  }
  self.postMessage({ type: 'decoded', job: msg.job, results, busyMs: performance.now() - t0, textureMs }, transfer);
};
