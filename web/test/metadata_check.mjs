// node metadata_check.mjs WITH_CRS.mt CRS WITHOUT.mt [--dump DIR]: the metadata block (mt_format.h "The
// metadata block") as the web module reads it (format.js readMetadata, indexRange; mtfile.js).
//  - WITH_CRS.mt (built by mtbuild --crs CRS) opens with scene.crs === CRS; WITHOUT.mt with ''.
//  - Variants of WITH_CRS.mt made here, each with a valid footer checksum so that the reader's
//    checks (not the checksum) must find the damage: every rule of the block broken once is refused
//    with an MtError naming it; unknown keys are ignored; a block changed without fixing the
//    checksum is refused by the checksum (the block is covered by it).
//  - With --dump DIR each variant is also written to DIR/NN.mt, and DIR/expect lists "NN.mt opens
//    CRS" or "NN.mt refused" (the caller checks that the C++ reader agrees).
import fs from 'node:fs';
import { FileSource } from '../src/source.js';
import { openMtFile, hasher } from '../src/mtfile.js';
import { MtError, kHeaderSize, kFooterSize } from '../src/format.js';

const [withCrs, crs, without] = process.argv.slice(2);
const dumpAt = process.argv.indexOf('--dump');
const dump = dumpAt > 0 ? process.argv[dumpAt + 1] : null;
const expect = [];
const save = (bytes, what) => {
  if (!dump) return;
  const name = `${String(expect.length).padStart(2, '0')}.mt`;
  fs.writeFileSync(`${dump}/${name}`, bytes);
  expect.push(`${name} ${what}`);
};
if (!without) {
  console.error('usage: node metadata_check.mjs WITH_CRS.mt CRS WITHOUT.mt');
  process.exit(2);
}
let failures = 0;
const fail = (what) => { console.error(`metadata_check: FAILED: ${what}`); ++failures; };

const a = await openMtFile(new FileSource(withCrs, fs));
if (a.crs !== crs) fail(`${withCrs}: crs '${a.crs}', expected '${crs}'`);
else console.log(`${withCrs}: crs ${a.crs} (metadata block of ${a.header.metadataSize} bytes at byte offset ${a.header.metadataOffset})`);
if (!(a.header.metadataSize > 0)) fail(`${withCrs}: no metadata block`);
const b = await openMtFile(new FileSource(without, fs));
if (b.crs !== '' || b.header.metadataSize !== 0 || b.header.metadataOffset !== 0) fail(`${without}: has a metadata block or a crs`);

/** A byte source over a Uint8Array (source.js's interface). */
class MemorySource {
  constructor(name, bytes) { this.path = name; this.bytes = bytes; this.size = bytes.length; this.bytesFetched = 0; }
  async openTail(n) { return this.read(Math.max(0, this.size - n), this.size); }
  async read(begin, end) { return this.bytes.slice(begin, end).buffer; }
}

const file = new Uint8Array(fs.readFileSync(withCrs));
const h = a.header;
const { h64Raw } = await hasher();
const u32 = (n) => { const x = new Uint8Array(4); new DataView(x.buffer).setUint32(0, n, true); return x; };
const utf8 = (s) => new TextEncoder().encode(s);
const entry = (k, v) => [u32(k.length), k, u32(v.length), v];
const cat = (parts) => {
  const out = new Uint8Array(parts.reduce((n, p) => n + p.length, 0));
  let o = 0;
  for (const p of parts) out.set(p, o), (o += p.length);
  return out;
};

/**
 * The file with `block` as its metadata block (header fields set), then `edit(bytes)` applied, and
 * the footer checksum recomputed unless `keepChecksum`.
 */
function variant(block, { size = block.length, offset = h.metadataOffset, edit = null, keepChecksum = false } = {}) {
  const body = cat([file.subarray(0, h.metadataOffset), block]);
  const footer = file.slice(file.length - kFooterSize);
  const out = cat([body, footer]);
  const dv = new DataView(out.buffer);
  dv.setUint32(180, size, true);
  dv.setUint32(248, offset % 4294967296, true);
  dv.setUint32(252, Math.floor(offset / 4294967296), true);
  if (edit) edit(out, dv);
  if (!keepChecksum) {
    const sum = h64Raw(cat([out.subarray(0, kHeaderSize), out.subarray(h.metaOffset, out.length - kFooterSize)]), 0n);
    dv.setBigUint64(out.length - kFooterSize + 8, sum, true);
  }
  return out;
}

async function expectOpens(name, bytes, wantCrs) {
  save(bytes, `opens ${wantCrs}`);
  try {
    const s = await openMtFile(new MemorySource(name, bytes));
    if (s.crs !== wantCrs) fail(`${name}: crs '${s.crs}', expected '${wantCrs}'`);
    else console.log(`${name}: opens, crs '${s.crs}'`);
  } catch (e) {
    fail(`${name}: refused: ${e.message}`);
  }
}
async function expectRefused(name, bytes, words) {
  save(bytes, 'refused');
  try {
    await openMtFile(new MemorySource(name, bytes));
    fail(`${name}: opened, expected a refusal naming '${words}'`);
  } catch (e) {
    if (!(e instanceof MtError) || !e.message.includes(words)) fail(`${name}: ${e.name}: ${e.message} (expected an MtError naming '${words}')`);
    else console.log(`${name}: refused: ${e.message}`);
  }
}

const crsEntry = entry(utf8('crs'), utf8(crs));
await expectOpens('same block, checksum recomputed', variant(cat(crsEntry)), crs);
await expectOpens('an unknown key is ignored', variant(cat([...entry(utf8('x-later'), utf8('v')), ...crsEntry])), crs);
await expectOpens('an empty value', variant(cat(entry(utf8('crs'), new Uint8Array(0)))), '');
await expectRefused('a key twice', variant(cat([...crsEntry, ...crsEntry])), 'a key appears twice');
await expectRefused('an empty key', variant(cat(entry(new Uint8Array(0), utf8('v')))), 'bad key length 0');
await expectRefused('a 256-byte key', variant(cat(entry(new Uint8Array(256).fill(65), utf8('v')))), 'bad key length 256');
await expectRefused('a block ending after a key', variant(cat([u32(3), utf8('crs')])), 'truncated value length');
await expectRefused('a block ending inside a length', variant(cat([...crsEntry, new Uint8Array(2)])), 'truncated key length');
await expectRefused('a value longer than the block', variant(cat([u32(3), utf8('crs'), u32(1000), utf8('x')])), 'bad value length 1000');
await expectRefused('a block size over the limit', variant(cat(crsEntry), { size: (1 << 20) + 1 }), 'bad metadata block size');
await expectRefused('no block but an offset', variant(new Uint8Array(0), { size: 0 }), 'bad metadata block size 0');
await expectRefused('a block not right after the patch index',
  variant(cat([new Uint8Array(8), ...crsEntry]), { size: crsEntry.reduce((n, p) => n + p.length, 0), offset: h.metadataOffset + 8 }),
  'bad metadata block offset');
await expectRefused('a block changed without its checksum',
  variant(cat(crsEntry), { keepChecksum: true, edit: (o) => { o[o.length - kFooterSize - 1] ^= 1; } }), 'checksum mismatch');
await expectRefused('footer reserved bytes not zero', variant(cat(crsEntry), { edit: (o) => { o[o.length - kFooterSize + 20] = 1; } }),
  'footer reserved bytes');
if (dump) fs.writeFileSync(`${dump}/expect`, expect.join('\n') + '\n');
process.exit(failures ? 1 : 0);
