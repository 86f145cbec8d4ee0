// Patch payload decoding (the decoder half of mtfile/patch_codec.cpp): the payload header, the
// dispatch by codec, the grid coordinates to positions. Refuses what it does not know (a flag or a
// codec of a later format version) with a message, never guesses.

import { Codec, kPayloadHeaderSize, kPayloadKnownFlags } from './format.js';
import { decodeMeshopt, bad } from './codec_meshopt.js';
import { decodeDraco } from './codec_draco.js';

export { BadPayload } from './codec_meshopt.js';

/** PayloadHeader of a payload. */
export function parsePayloadHeader(data) {
  const dv = new DataView(data.buffer, data.byteOffset, data.byteLength);
  return {
    vertexCount: dv.getUint32(0, true),
    triangleCount: dv.getUint32(4, true),
    qMin: [dv.getUint32(8, true), dv.getUint32(12, true), dv.getUint32(16, true)],
    flags: data[20],
  };
}

/**
 * decodePatch: payload bytes -> { triangles: Uint32Array, q: Uint32Array (absolute grid
 * coordinates), normals?: Float32Array, colors?: Uint8Array }. Throws BadPayload.
 * @param {Uint8Array} data
 * @param {number} codec Codec
 * @param {{bits:number}} grid
 * @param {object} libs { zstd, meshopt, draco }
 */
export function decodePatch(data, codec, grid, libs) {
  if (data.length < kPayloadHeaderSize) bad(`shorter than its header (${data.length} bytes)`);
  const h = parsePayloadHeader(data);
  if (h.flags & ~kPayloadKnownFlags)
    bad(`unknown flags 0x${h.flags.toString(16)} (a later payload version? this viewer knows 0x${kPayloadKnownFlags.toString(16)})`);
  if (h.triangleCount > data.length * 64 + 64 || h.vertexCount > data.length * 64 + 64) bad('counts too large for the payload size');
  const out = { triangles: null, normals: null, colors: null, q: null };
  let qRel;
  if (codec === Codec.Meshopt) qRel = decodeMeshopt(data, h, libs, out);
  else if (codec === Codec.Draco) qRel = decodeDraco(data, h, libs, out);
  else bad(`unknown codec ${codec}`);
  const n = qRel.length / 3;
  const t = out.triangles;
  for (let i = 0; i < t.length; ++i) if (t[i] >= n) bad(`triangle index ${t[i]} out of range`);
  const limit = 2 ** grid.bits;
  const q = new Uint32Array(n * 3);
  const [m0, m1, m2] = h.qMin;
  for (let i = 0; i < n * 3; i += 3) {
    const x = qRel[i] + m0, y = qRel[i + 1] + m1, z = qRel[i + 2] + m2;
    if (x >= limit || y >= limit || z >= limit) bad('grid coordinate outside the grid');
    q[i] = x;
    q[i + 1] = y;
    q[i + 2] = z;
  }
  out.q = q;
  return out;
}
