// node decode_check.mjs FILE.mt: decodes every patch of a meshopt file in node with the web module's
// decoder (checksums too) and prints "patches N triangles T vertices V qsum S" (S: the sum of every
// decoded grid coordinate, a fingerprint compared with the C++ decoder's by the test).
import fs from 'node:fs';
import { decompress } from 'fzstd';
import { MeshoptDecoder } from 'meshoptimizer/decoder';
import { FileSource } from '../src/source.js';
import { openMtFile, hasher } from '../src/mtfile.js';
import { decodePatch } from '../src/patch_codec.js';

const file = process.argv[2];
await MeshoptDecoder.ready;
const { h64Raw } = await hasher();
const scene = await openMtFile(new FileSource(file, fs));
const libs = { zstd: (b, n) => decompress(b, new Uint8Array(n)), meshopt: MeshoptDecoder, draco: null };
const p = scene.patches;
let tris = 0, verts = 0, qsum = 0n;
for (let i = 0; i < p.count; ++i) {
  const data = new Uint8Array(await scene.source.read(p.offset[i], p.offset[i] + p.size[i]));
  const sum = h64Raw(data, 0n);
  if (sum !== ((BigInt(p.checksumHi[i]) << 32n) | BigInt(p.checksumLo[i]))) throw new Error(`patch ${i}: checksum mismatch`);
  const d = decodePatch(data, scene.header.codec, { bits: scene.header.gridBits }, libs);
  if (d.triangles.length / 3 !== p.triangles[i]) throw new Error(`patch ${i}: ${d.triangles.length / 3} triangles, index says ${p.triangles[i]}`);
  tris += d.triangles.length / 3;
  verts += d.q.length / 3;
  let s = 0;
  for (const v of d.q) s += v;
  qsum += BigInt(s);
}
console.log(`patches ${p.count} triangles ${tris} vertices ${verts} qsum ${qsum}`);
