// node payload_check.mjs SOURCE_DIR [FILE.mt]: the web decoder on payloads of older versions and on
// damaged version-4 payloads.
//  1. The version-2 and version-3 payload fixtures of tests/test_mt_codec.cpp (the byte arrays of
//     Codec.Version2PayloadStillDecodes and Codec.Version3PayloadStillDecodes, read from that file so
//     there is one copy) decode to the triangles of its smallIrregularPatch on its grid.
//  2. With FILE.mt (a meshopt file built by the current mtbuild): every version-4 payload
//     (kPayloadConnectivity) among the first ones, truncated at several lengths or with a byte
//     changed, throws BadPayload or decodes to valid indices; never another exception, never a hang.
//     With --wasm PATH, each variant is decoded by the WebAssembly decoder (codec_wasm.js) too: it
//     must refuse the same variants, each with a message of the C++ decoder (no other trap), and
//     decode the others to the same triangles and coordinates.
import fs from 'node:fs';
import path from 'node:path';
import { decompress } from 'fzstd';
import { MeshoptDecoder } from 'meshoptimizer/decoder';
import { FileSource } from '../src/source.js';
import { openMtFile } from '../src/mtfile.js';
import { decodePatch, BadPayload } from '../src/patch_codec.js';
import { loadWasmDecoder } from '../src/codec_wasm.js';
import { Codec, kPayloadConnectivity, kPayloadRangePositions, kPayloadRangeIndices, kPayloadPositionContexts } from '../src/format.js';

const wasmAt = process.argv.indexOf('--wasm');
const [src, file] = process.argv.slice(2).filter((a, i) => wasmAt < 0 || (i + 2 !== wasmAt && i + 2 !== wasmAt + 1));
if (!src) {
  console.error('usage: node payload_check.mjs SOURCE_DIR [FILE.mt] [--wasm PATH]');
  process.exit(2);
}
await MeshoptDecoder.ready;
const libs = { zstd: (b, n) => decompress(b, new Uint8Array(n)), meshopt: MeshoptDecoder, draco: null };
const wasmLibs = wasmAt > 0 ? { ...libs, wasm: await loadWasmDecoder(fs.readFileSync(process.argv[wasmAt + 1])) } : null;
let failures = 0;
const fail = (what) => { console.error(`payload_check: FAILED: ${what}`); ++failures; };

// ---- 1. the C++ fixtures ----
const cpp = fs.readFileSync(path.join(src, 'tests/test_mt_codec.cpp'), 'utf8');
function fixture(test, name) {
  const at = cpp.indexOf(`TEST(Codec, ${test})`);
  if (at < 0) throw new Error(`tests/test_mt_codec.cpp has no TEST(Codec, ${test})`);
  const m = new RegExp(`std::vector<uint8_t> ${name} = \\{([^}]*)\\}`).exec(cpp.slice(at));
  if (!m) throw new Error(`TEST(Codec, ${test}) has no byte array ${name}`);
  return Uint8Array.from(m[1].split(',').map((x) => x.trim()).filter((x) => x).map((x) => Number(x)));
}

// smallIrregularPatch of tests/test_mt_codec.cpp: a 5x5 grid, uneven heights, triangles out of order.
function smallIrregularPatch() {
  const p = [], t = [];
  for (let y = 0; y < 5; ++y)
    for (let x = 0; x < 5; ++x) p.push(x + 0.1 * ((x * 7 + y * 3) % 5), y, 0.3 * ((x * y) % 3));
  for (let y = 0; y < 4; ++y)
    for (let x = 0; x < 4; ++x) {
      const a = y * 5 + x;
      t.push(a, a + 1, a + 6, a, a + 6, a + 5);
    }
  for (let i = 0; i + 6 < t.length; i += 12)
    for (let k = 0; k < 3; ++k) {
      const j = t.length - 3 - i + k, s = t[i + k];
      t[i + k] = t[j];
      t[j] = s;
    }
  return { p, t };
}

// triangleSet: each triangle as its corners' grid coordinates, rotated to start at the least one.
function triangleSet(q, tris) {
  const out = [];
  for (let t = 0; t < tris.length; t += 3) {
    const c = [0, 1, 2].map((k) => [q[tris[t + k] * 3], q[tris[t + k] * 3 + 1], q[tris[t + k] * 3 + 2]]);
    const less = (a, b) => a[0] !== b[0] ? a[0] < b[0] : a[1] !== b[1] ? a[1] < b[1] : a[2] < b[2];
    let m = 0;
    for (let k = 1; k < 3; ++k) if (less(c[k], c[m])) m = k;
    out.push(JSON.stringify([c[m], c[(m + 1) % 3], c[(m + 2) % 3]]));
  }
  return out.sort().join(' ');
}

{
  // QuantizationGrid::fromBounds({-1,-1,-1}, {10,10,10}, 1/64): 705 cells a side, 10 bits.
  const step = 1 / 64, origin = -1, bits = 10;
  const { p, t } = smallIrregularPatch();
  const q = p.map((v) => Math.floor((v - origin) / step + 0.5));
  const want = triangleSet(q, t);
  const cases = [
    ['Version2PayloadStillDecodes', 'v2', kPayloadRangePositions],
    ['Version3PayloadStillDecodes', 'v3', kPayloadRangePositions | kPayloadRangeIndices | kPayloadPositionContexts],
  ];
  for (const [test, name, flags] of cases) {
    const payload = fixture(test, name);
    if (payload[20] !== flags) fail(`${test}: flags 0x${payload[20].toString(16)}, expected 0x${flags.toString(16)}`);
    const d = decodePatch(payload, Codec.Meshopt, { bits }, libs);
    if (triangleSet(d.q, d.triangles) !== want) fail(`${test}: the ${name} payload decodes to other triangles`);
    else console.log(`${test}: ${payload.length}-byte ${name} payload decodes to the ${t.length / 3} triangles of the patch`);
  }
}

// ---- 2. damaged version-4 payloads ----
if (file) {
  const scene = await openMtFile(new FileSource(file, fs));
  if (scene.header.codec !== Codec.Meshopt) throw new Error(`${file}: not a meshopt file`);
  const grid = { bits: scene.header.gridBits };
  const pr = scene.patches;
  let payloads = 0, trials = 0, threw = 0, wasmAgreed = 0;
  const t0 = performance.now();
  for (let i = 0; i < pr.count && payloads < 6; ++i) {
    const data = new Uint8Array(await scene.source.read(pr.offset[i], pr.offset[i] + pr.size[i]));
    if (!(data[20] & kPayloadConnectivity) || pr.triangles[i] < 50) continue;
    ++payloads;
    const n = data.length;
    const variants = [];
    for (const cut of [24, 32, 40, 48, Math.floor(n / 3), Math.floor(n / 2), n - 1]) variants.push(data.slice(0, cut));
    const stride = Math.max(1, Math.floor(n / 150));
    for (let k = 0; k < n; k += stride)
      for (const x of [0x01, 0x80, 0xff]) {
        const v = data.slice();
        v[k] ^= x;
        variants.push(v);
      }
    for (const v of variants) {
      ++trials;
      let d = null;
      try {
        d = decodePatch(v, Codec.Meshopt, grid, libs);
        const nv = d.q.length / 3;
        for (const idx of d.triangles) if (!(idx < nv)) { fail(`patch ${i}: a damaged payload decoded to index ${idx} of ${nv}`); break; }
      } catch (e) {
        if (e instanceof BadPayload) ++threw;
        else fail(`patch ${i}: a damaged payload threw ${e.name}: ${e.message}`);
      }
      if (!wasmLibs) continue;
      let w = null;
      try {
        w = decodePatch(v, Codec.Meshopt, grid, wasmLibs);
      } catch (e) {
        if (!(e instanceof BadPayload)) fail(`patch ${i}: the wasm decoder threw ${e.name}: ${e.message}`);
        // A trap that is not bad()'s (an access out of bounds) is a fault of the decoder.
        else if (e.message.includes('the decoder trapped')) fail(`patch ${i}: ${e.message}`);
      }
      const same = (a, b) => a.length === b.length && a.every((x, k) => x === b[k]);
      if (!d !== !w) fail(`patch ${i}: a damaged payload ${d ? 'decodes in JavaScript, is refused' : 'is refused in JavaScript, decodes'} in wasm`);
      else if (d && !(same(d.triangles, w.triangles) && same(d.q, w.q))) fail(`patch ${i}: a damaged payload decodes to other triangles in wasm`);
      else ++wasmAgreed;
    }
  }
  if (payloads === 0) fail(`${file}: no version-4 payload with 50 triangles or more`);
  console.log(`damaged version-4 payloads: ${payloads} payloads, ${trials} variants, ${threw} refused as BadPayload, ` +
    `the rest decoded to valid indices (${(performance.now() - t0).toFixed(0)} ms)`);
  if (threw === 0) fail('no damaged variant was refused: the checks test nothing');
  if (wasmLibs) {
    // The variants that decode went through the module (not the JavaScript port).
    const decoded = trials - threw;
    if (wasmLibs.wasm.decodes < decoded) fail(`the wasm decoder decoded ${wasmLibs.wasm.decodes} streams, ${decoded} variants decode`);
    console.log(`the wasm decoder agrees with the JavaScript one on ${wasmAgreed} of ${trials} variants (${wasmLibs.wasm.decodes} streams decoded by it)`);
  }
}
process.exit(failures ? 1 : 0);
