// node decode_check.mjs FILE.mt: decodes every patch of a meshopt file in node with the web module's
// decoder (checksums too) and prints "patches N triangles T vertices V qsum S tsum I" (S: the sum of
// every decoded grid coordinate, I: sum over each patch's index list of (i % 1021 + 1) * index,
// modulo 2^64: fingerprints compared with the C++ decoder's (web_cut_nodes --decode) by the test).
// Also prints, on stderr, how many payloads of each kind it met and their decode time (CPU time
// of the process, user + sys, ms: wall time means nothing on a shared machine). A textured file
// (version 6) adds "textures N imagebytes B uvsum U" (texture.js's decoder; U as web_cut_nodes
// --decode defines it); with --require-connectivity it fails when no payload has kPayloadConnectivity (the
// file does not test the version-4 decoder). With --wasm PATH the version-4 streams are decoded by
// the WebAssembly decoder at PATH (codec_wasm.js; web/dist/mt_decode.wasm) instead of the
// JavaScript port.
import fs from 'node:fs';
import { decompress } from 'fzstd';
import { MeshoptDecoder } from 'meshoptimizer/decoder';
import { FileSource } from '../src/source.js';
import { openMtFile, hasher } from '../src/mtfile.js';
import { decodePatch } from '../src/patch_codec.js';
import { decodeTexturePayload } from '../src/texture.js';
import { loadWasmDecoder } from '../src/codec_wasm.js';

const file = process.argv[2];
const requireConnectivity = process.argv.includes('--require-connectivity');
const wasmAt = process.argv.indexOf('--wasm');
const wasm = wasmAt > 0 ? await loadWasmDecoder(fs.readFileSync(process.argv[wasmAt + 1])) : null;
const kinds = new Map();  // kind -> { patches, triangles, ms }
const kindOf = (flags) => (flags & 0x80 ? 'v4-connectivity' : flags & 0x20 ? 'v3-range-indices' : flags & 0x10 ? 'v2-range-positions' : 'v1');
await MeshoptDecoder.ready;
const { h64Raw } = await hasher();
const scene = await openMtFile(new FileSource(file, fs));
const libs = { zstd: (b, n) => decompress(b, new Uint8Array(n)), meshopt: MeshoptDecoder, draco: null, wasm };
const p = scene.patches;
let tris = 0, verts = 0, qsum = 0n, tsum = 0n, textures = 0, imageBytes = 0, uvsum = 0n;
const tx = scene.textures;
for (let i = 0; i < p.count; ++i) {
  const data = new Uint8Array(await scene.source.read(p.offset[i], p.offset[i] + p.size[i]));
  const sum = h64Raw(data, 0n);
  if (sum !== ((BigInt(p.checksumHi[i]) << 32n) | BigInt(p.checksumLo[i]))) throw new Error(`patch ${i}: checksum mismatch`);
  const t0 = process.cpuUsage();
  const d = decodePatch(data, scene.header.codec, { bits: scene.header.gridBits }, libs);
  const dt = process.cpuUsage(t0);
  const ms = (dt.user + dt.system) / 1000;
  const kind = scene.header.codec === 1 ? kindOf(data[20]) : 'draco';
  const k = kinds.get(kind) || { patches: 0, triangles: 0, ms: 0 };
  k.patches++, (k.triangles += d.triangles.length / 3), (k.ms += ms);
  kinds.set(kind, k);
  if (d.triangles.length / 3 !== p.triangles[i]) throw new Error(`patch ${i}: ${d.triangles.length / 3} triangles, index says ${p.triangles[i]}`);
  tris += d.triangles.length / 3;
  verts += d.q.length / 3;
  let s = 0;
  for (const v of d.q) s += v;
  qsum += BigInt(s);
  // (i % 1021 + 1) * index < 2^42: 1000 terms stay exact in a double
  const t = d.triangles;
  for (let k0 = 0; k0 < t.length; k0 += 1000) {
    let w = 0;
    for (let k = k0; k < Math.min(t.length, k0 + 1000); ++k) w += (k % 1021 + 1) * t[k];
    tsum += BigInt(w);
  }
  if (tx && tx.size[i]) {
    const td = new Uint8Array(await scene.source.read(tx.offset[i], tx.offset[i] + tx.size[i]));
    if (h64Raw(td, 0n) !== ((BigInt(tx.checksumHi[i]) << 32n) | BigInt(tx.checksumLo[i]))) throw new Error(`texture of patch ${i}: checksum mismatch`);
    const rec = { width: tx.width[i], height: tx.height[i], imageBytes: tx.imageBytes[i] };
    const t = decodeTexturePayload(td, d.triangles, d.q.length / 3, rec, libs.zstd);
    ++textures;
    imageBytes += t.image.length;
    let u = 0;  // exact: a corner adds < 2^27, a patch has far fewer than 2^26 corners
    for (let k = 0; k < t.cornerUV.length / 2; ++k)
      u += (k % 1021 + 1) * (Math.round(t.cornerUV[2 * k] * 16 * t.width) + 3 * Math.round(t.cornerUV[2 * k + 1] * 16 * t.height));
    uvsum += BigInt(u);
  }
}
uvsum = BigInt.asUintN(64, uvsum);
tsum = BigInt.asUintN(64, tsum);
for (const [kind, k] of kinds)
  console.error(`${kind}${wasm && kind === 'v4-connectivity' ? ' (wasm)' : ''}: ${k.patches} patches, ${k.triangles} triangles, ${k.ms.toFixed(1)} ms CPU (${(k.triangles / k.ms / 1000).toFixed(2)} M triangles/s)`);
// With --wasm, the module decoded every version-4 stream (not the JavaScript port).
const v4 = kinds.has('v4-connectivity') ? kinds.get('v4-connectivity').patches : 0;
if (wasm && wasm.decodes !== v4) {
  console.error(`decode_check: ${file}: the wasm decoder decoded ${wasm.decodes} streams of ${v4} version-4 payloads`);
  process.exit(1);
}
if (requireConnectivity && !kinds.has('v4-connectivity')) {
  console.error(`decode_check: ${file}: no payload has kPayloadConnectivity`);
  process.exit(1);
}
console.log(`patches ${p.count} triangles ${tris} vertices ${verts} qsum ${qsum} tsum ${tsum}` +
  (tx ? ` textures ${textures} imagebytes ${imageBytes} uvsum ${uvsum}` : ''));
