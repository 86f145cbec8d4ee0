// Opening an MT file from a byte source (source.js): footer and header at once, then the DAG and
// the index in one range read (or none: an HTTP source's tail read usually holds them), the footer checksum checked (XXH64 over header + index + metadata block), the
// records cross-checked and the metadata block read (format.js), the scene built (scene.js).
// Payloads are read later, on demand.

import xxhash from 'xxhash-wasm';
import {
  kHeaderSize, kFooterSize, kMetadataCrs, readHeaderAndFooter, indexRange, readIndex, readMetadata, checkIndex, MtError,
} from './format.js';
import { buildScene } from './scene.js';

let hasherPromise = null;
/** xxhash-wasm, instantiated once per realm. */
export function hasher() {
  if (!hasherPromise) hasherPromise = xxhash();
  return hasherPromise;
}

/**
 * @param {{path:string, size:number, openTail:Function, read:Function}} source
 * @returns {Promise<object>} the scene (scene.js) with `source` attached
 */
export async function openMtFile(source) {
  // One suffix read gives the size and the footer; the header follows.
  const now = () => performance.now();
  const times = { begin: now() };  // the opening's steps (the bench's profile of the first image)
  const hashing = hasher();  // its wasm compiled while the reads are under way
  // The header is read at the same time (it does not need the size). An HTTP source's tail read
  // takes the file's last few MiB, which usually hold the whole index section (then the read
  // below is answered from them) and the coarsest patches.
  const [tailRead, headRead] = await Promise.allSettled([source.openTail(kFooterSize), source.read(0, kHeaderSize)]);
  if (tailRead.status === 'rejected') throw tailRead.reason;
  const tail = tailRead.value;
  times.tail = now();
  const size = source.size;
  if (size < kHeaderSize + kFooterSize)
    throw new MtError(source.path, `not an MT file: ${size} bytes is shorter than header + footer (truncated?)`);
  if (headRead.status === 'rejected') throw headRead.reason;
  const headerBuf = headRead.value;
  const { header, footer } = readHeaderAndFooter(source.path, size, headerBuf, tail);
  const range = indexRange(source.path, size, header);
  times.header = now();
  const meta = await source.read(range.begin, range.end);
  times.read = now();
  const { create64 } = await hashing;
  const h = create64(0n);
  h.update(new Uint8Array(headerBuf));
  h.update(new Uint8Array(meta));
  const sum = h.digest();
  const want = (BigInt(footer.checksumHi) << 32n) | BigInt(footer.checksumLo);
  if (sum !== want)
    throw new MtError(source.path, `checksum mismatch over header + DAG + index (bytes 0-${kHeaderSize} and ${range.begin}-${range.end})`);
  times.hashed = now();
  const idx = readIndex(header, meta);
  const metadata = readMetadata(source.path, header, meta);
  checkIndex(source.path, header, idx);
  times.parsed = now();
  const scene = buildScene(header, idx);
  times.built = now();
  scene.openTimes = times;
  // The metadata block (MtFileReader::crs()): '' when the file names no coordinate system.
  scene.metadata = metadata;
  scene.crs = metadata.get(kMetadataCrs) || '';
  scene.source = source;
  scene.path = source.path;
  scene.fileSize = size;
  return scene;
}
