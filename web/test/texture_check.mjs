// node texture_check.mjs TEXTURED.mt DIR: the web module on a textured (version 6) file and on broken
// copies of it, with the verdicts of `mtinfo --check` (the caller, tests/web_format_check.sh, runs
// mtinfo on the same copies and compares).
//  - The check: openMtFile (format.js: header, footer, the footer checksum, the sections, the
//    TextureRecords), then every patch's payload (XXH64, decodePatch) and texture payload (XXH64,
//    decodeTexturePayload with readTexture's checks), as mtfile's checkAllPatches does. Verdict:
//    "refused" (the file does not open), or "opens" and the damaged patches, ascending.
//  - The copies (DIR/NN.mt, DIR/expect lists "NN.mt VERDICT [patch ...]" and what was broken):
//    truncated, a bad footer checksum, a damaged texture payload (its checksum), damaged texture
//    contents under a valid checksum (coordinates, triangle count, image format, image size against
//    the index), damaged TextureRecords and header counts under a valid footer checksum, textures
//    flagged in a version-5 file. Each must get the verdict written next to it, and the intact file
//    must open with no damage.
import fs from 'node:fs';
import { decompress } from 'fzstd';
import { MeshoptDecoder } from 'meshoptimizer/decoder';
import { openMtFile, hasher } from '../src/mtfile.js';
import { decodePatch } from '../src/patch_codec.js';
import { decodeTexturePayload } from '../src/texture.js';
import { kHeaderSize, kFooterSize, kTextureRecordSize, kPatchRecordSize, kTexturePayloadHeaderSize, MtError } from '../src/format.js';

const [file, dir] = process.argv.slice(2);
if (!dir) {
  console.error('usage: node texture_check.mjs TEXTURED.mt DIR');
  process.exit(2);
}
await MeshoptDecoder.ready;
const { h64Raw } = await hasher();
const libs = { zstd: (b, n) => decompress(b, new Uint8Array(n)), meshopt: MeshoptDecoder, draco: null };
let failures = 0;
const fail = (what) => { console.error(`texture_check: FAILED: ${what}`); ++failures; };

class MemorySource {
  constructor(name, bytes) { this.path = name; this.bytes = bytes; this.size = bytes.length; this.bytesFetched = 0; }
  async openTail(n) { return this.read(Math.max(0, this.size - n), this.size); }
  async read(begin, end) { return this.bytes.slice(begin, end).buffer; }
}

/** The verdict of the web module on `bytes`: {opens, damaged: [patch], messages}. */
async function verdict(name, bytes) {
  let scene;
  try {
    scene = await openMtFile(new MemorySource(name, bytes));
  } catch (e) {
    if (!(e instanceof MtError)) throw e;
    return { opens: false, damaged: [], messages: [e.message] };
  }
  const p = scene.patches, tx = scene.textures, damaged = [], messages = [];
  const sum = (lo, hi) => (BigInt(hi) << 32n) | BigInt(lo);
  for (let i = 0; i < p.count; ++i) {
    try {
      const data = bytes.subarray(p.offset[i], p.offset[i] + p.size[i]);
      if (h64Raw(data, 0n) !== sum(p.checksumLo[i], p.checksumHi[i])) throw new Error(`patch ${i} is damaged: checksum mismatch`);
      const d = decodePatch(data, scene.header.codec, { bits: scene.header.gridBits }, libs);
      if (d.triangles.length / 3 !== p.triangles[i]) throw new Error(`patch ${i}: triangle count differs from the index`);
      if (tx && tx.size[i]) {
        const td = bytes.subarray(tx.offset[i], tx.offset[i] + tx.size[i]);
        if (h64Raw(td, 0n) !== sum(tx.checksumLo[i], tx.checksumHi[i])) throw new Error(`texture of patch ${i} is damaged: checksum mismatch`);
        decodeTexturePayload(td, d.triangles, d.q.length / 3, { width: tx.width[i], height: tx.height[i], imageBytes: tx.imageBytes[i] }, libs.zstd);
      }
    } catch (e) {
      damaged.push(i);
      messages.push(`patch ${i}: ${e.message}`);
    }
  }
  return { opens: true, damaged, messages };
}

const file0 = new Uint8Array(fs.readFileSync(file));
const base = await openMtFile(new MemorySource(file, file0));
if (!base.textures) {
  console.error(`texture_check: ${file} has no textures`);
  process.exit(1);
}
const h = base.header, tx = base.textures, pr = base.patches;
const texAt = h.patchesOffset + h.patchCount * kPatchRecordSize;  // TextureRecord[0]
// A textured patch in the middle of the file (its texture payload and its record are edited).
const textured = [];
for (let i = 0; i < tx.count; ++i) if (tx.size[i] && tx.imageBytes[i] > 64) textured.push(i);
if (textured.length < 2) {
  console.error(`texture_check: ${file}: fewer than 2 textured patches`);
  process.exit(1);
}
const k = textured[textured.length >> 1];
const dv = (b) => new DataView(b.buffer, b.byteOffset, b.byteLength);
const cat = (...parts) => {
  const out = new Uint8Array(parts.reduce((n, x) => n + x.length, 0));
  let o = 0;
  for (const x of parts) out.set(x, o), (o += x.length);
  return out;
};
const rec = (b, i) => texAt + i * kTextureRecordSize;
// The footer checksum recomputed over header + index (the damage must be found by a later check).
const fixFooter = (b) => {
  const s = h64Raw(cat(b.subarray(0, kHeaderSize), b.subarray(h.metaOffset, b.length - kFooterSize)), 0n);
  dv(b).setBigUint64(b.length - kFooterSize + 8, s, true);
};
// Patch i's texture checksum recomputed (in its record), then the footer's.
const fixTexture = (b, i) => {
  const s = h64Raw(b.subarray(tx.offset[i], tx.offset[i] + tx.size[i]), 0n);
  dv(b).setBigUint64(rec(b, i) + 16, s, true);
  fixFooter(b);
};

const variants = [];
const add = (what, want, edit) => {
  const b = file0.slice();
  const out = edit(b) || b;
  variants.push({ what, want, bytes: out });
};
const uvFrame = tx.offset[k] + kTexturePayloadHeaderSize;
const imageAt = tx.offset[k] + tx.size[k] - tx.imageBytes[k];
add('intact', 'opens', () => {});
add('truncated by 1000 bytes', 'refused', (b) => b.slice(0, b.length - 1000));
add('truncated in the payloads (the footer kept)', 'refused', (b) => cat(b.subarray(0, tx.offset[k] + 8), b.subarray(b.length - kFooterSize)));
add('a TextureRecord changed without its checksum', 'refused', (b) => { b[rec(b, k) + 12] ^= 1; });
add(`texture of patch ${k}: a byte of its image changed`, `opens ${k}`, (b) => { b[imageAt + (tx.imageBytes[k] >> 1)] ^= 0x5a; });
add(`texture of patch ${k}: its coordinate frame damaged under a valid checksum`, `opens ${k}`, (b) => { b[uvFrame + 5] ^= 0xff; b[uvFrame + 6] ^= 0x33; fixTexture(b, k); });
add(`texture of patch ${k}: its triangle count + 1 under a valid checksum`, `opens ${k}`, (b) => { dv(b).setUint32(tx.offset[k], pr.triangles[k] + 1, true); fixTexture(b, k); });
add(`texture of patch ${k}: its image not the format it names, under a valid checksum`, `opens ${k}`, (b) => { b[imageAt] ^= 0xff; fixTexture(b, k); });
add(`texture of patch ${k}: its record's width one less than the image's`, `opens ${k}`, (b) => { dv(b).setUint16(rec(b, k) + 12, tx.width[k] - 1, true); fixFooter(b); });
add(`texture of patch ${k}: its record's width over 2048`, 'refused', (b) => { dv(b).setUint16(rec(b, k) + 12, 4096, true); fixFooter(b); });
add(`texture of patch ${k}: imageBytes over its size`, 'refused', (b) => { dv(b).setUint32(rec(b, k) + 24, tx.size[k] + 1, true); fixFooter(b); });
add(`texture of patch ${k}: reserved word not zero`, 'refused', (b) => { dv(b).setUint32(rec(b, k) + 28, 1, true); fixFooter(b); });
add(`texture of patch ${k}: its payload over its patch's`, 'refused', (b) => { dv(b).setUint32(rec(b, k), pr.offset[k], true); fixFooter(b); });
add(`texture of patch ${k}: size 0 with an image`, 'refused', (b) => { dv(b).setUint32(rec(b, k) + 8, 0, true); fixFooter(b); });
add('header patch count + 1', 'refused', (b) => { dv(b).setUint32(56, h.patchCount + 1, true); fixFooter(b); });
add('header node count - 1', 'refused', (b) => { dv(b).setUint32(32, h.nodeCount - 1, true); fixFooter(b); });
add('textures flagged in a version-5 file', 'refused', (b) => { dv(b).setUint32(8, 5, true); dv(b).setUint32(b.length - kFooterSize + 16, 5, true); fixFooter(b); });
add('version 7', 'refused', (b) => { dv(b).setUint32(8, 7, true); dv(b).setUint32(b.length - kFooterSize + 16, 7, true); fixFooter(b); });

const expect = [];
for (let i = 0; i < variants.length; ++i) {
  const v = variants[i];
  const name = `${String(i).padStart(2, '0')}.mt`;
  fs.writeFileSync(`${dir}/${name}`, v.bytes);
  const r = await verdict(name, v.bytes);
  const got = r.opens ? ['opens', ...r.damaged].join(' ') : 'refused';
  if (got !== v.want) fail(`${name} (${v.what}): the web module says '${got}', expected '${v.want}' (${r.messages[0] || ''})`);
  else console.log(`${name} ${v.what}: ${got}${r.messages.length ? ` (${r.messages[0]})` : ''}`);
  expect.push(`${name} ${got}`);
}
fs.writeFileSync(`${dir}/expect`, expect.join('\n') + '\n');
console.log(`textured file: ${tx.count} patches, ${textured.length} textured; ${variants.length} copies checked`);
process.exit(failures ? 1 : 0);
