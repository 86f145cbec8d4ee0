// Codec::Meshopt, the decoder half of mtfile/patch_codec_meshopt.cpp, ported function by function
// (readMeshoptFrame, decodeMeshoptTriangles, decodeMeshoptAttributes, decodeIndexCode,
// decodeResidual, ResidualModel, parallelogramWalk, decodeContextPositions, decodeLegacyPositions,
// decodeMeshopt), and of the decoder half of mtfile/patch_codec_connectivity.cpp (OpenEdges,
// EdgeFifo, ConnectivityModel, decodeExplicit, decodeConnectivity: the version-4 connectivity
// code), so that a change of the C++ decoder ports line by line. Byte layouts: mt_format.h.
// `libs` brings the npm decoders: libs.zstd(bytes, rawSize) -> Uint8Array (fzstd) and libs.meshopt
// (meshoptimizer's MeshoptDecoder, ready); and libs.wasm (codec_wasm.js), when set, decodes the
// version-4 stream in place of decodeConnectivity and decodeContextPositions.

import {
  kPayloadHeaderSize, kPayloadNormals, kPayloadColors, kPayloadWide, kPayloadStrip, kPayloadRangePositions,
  kPayloadRangeIndices, kPayloadPositionContexts, kPayloadConnectivity, attributeStride,
} from './format.js';
import { RangeDecoder, countedBits } from './range_coder.js';

export class BadPayload extends Error {
  constructor(what) {
    super(`bad patch payload: ${what}`);
    this.name = 'BadPayload';
  }
}
export const bad = (what) => { throw new BadPayload(what); };

// Working arrays reused from one patch to the next (a worker decodes thousands of small patches):
// fresh typed arrays for each took a fifth of the decoding time in Chromium, whose array buffers
// live outside the JS heap (their allocation and accounting, and the collections it brings on).
// The decoder is not reentrant; what it returns is never one of these.
const pool = new Map();
function scratch(key, Type, length) {
  let a = pool.get(key);
  if (!a || a.length < length) {
    a = new Type(Math.max(length, a ? 2 * a.length : 0));
    pool.set(key, a);
  }
  return a;
}

const kMaxQ = 0x7fffffff;
const kIndexHeaderV1 = 0xe1;
const kCodeAuxTableV1 = [0x00, 0x76, 0x87, 0x56, 0x67, 0x78, 0xa9, 0x86, 0x65, 0x89, 0x68, 0x98, 0x01, 0x69, 0x00, 0x00];

// Prediction kinds (the version-3 position contexts).
const kParallelogram = 0, kMidpoint = 1, kOneKnown = 2, kNoneKnown = 3;

function unzigzag(z) { return z & 1 ? -Math.floor(z / 2) - 1 : Math.floor(z / 2); }

// meshopt's bounds (meshoptimizer.h), for the size checks.
function encodeIndexBufferBound(indexCount, vertexCount) {
  let vertexBits = 1;
  while (vertexBits < 32 && vertexCount > 2 ** vertexBits) vertexBits++;
  const vertexGroups = Math.floor((vertexBits + 1 + 6) / 7);
  return 1 + (indexCount / 3) * (2 + 3 * vertexGroups) + 16;
}
function encodeIndexSequenceBound(indexCount, vertexCount) {
  let vertexBits = 1;
  while (vertexBits < 32 && vertexCount > 2 ** vertexBits) vertexBits++;
  const vertexGroups = Math.floor((vertexBits + 1 + 1 + 6) / 7);
  return 1 + indexCount * vertexGroups + 4;
}
function encodeVertexBufferBound(vertexCount, vertexSize) {
  const kVertexBlockMaxSize = 256, kByteGroupSize = 16, kTailMaxSize = 32;
  let vertexBlockSize = Math.floor(8192 / vertexSize) & ~(kByteGroupSize - 1);
  vertexBlockSize = Math.min(vertexBlockSize, kVertexBlockMaxSize);
  const vertexBlockCount = Math.ceil(vertexCount / vertexBlockSize);
  const vertexBlockHeaderSize = Math.floor((vertexBlockSize / kByteGroupSize + 3) / 4);
  const vertexBlockDataSize = vertexBlockSize;
  const tailSize = Math.max(vertexSize, kTailMaxSize);
  return 1 + vertexBlockCount * vertexSize * (vertexBlockHeaderSize + vertexBlockDataSize) + tailSize;
}

/**
 * The directed-edge -> opposite-vertex map of the parallelogram rule (a later put replaces): open
 * addressing with linear probing in typed arrays, sized for `edgeCount` puts at half load. (A JS
 * Map keyed by a * n + b took 28% of the decoding time, and most of its garbage.)
 */
class EdgeMap {
  constructor(edgeCount) {
    let cap = 16;
    while (cap < 2 * edgeCount) cap *= 2;
    this.mask = cap - 1;
    this.from = scratch('edgeFrom', Int32Array, cap).fill(0, 0, cap);  // a + 1 (0: an empty slot)
    this.to = scratch('edgeTo', Int32Array, cap);
    this.opposite = scratch('edgeOpposite', Int32Array, cap);
  }
  slot(a, b) {
    const { from, to, mask } = this;
    let h = (Math.imul(a, 0x9e3779b1) ^ Math.imul(b + 0x7f4a7c15, 0x85ebca77)) & mask;
    while (from[h] !== 0 && (from[h] !== a + 1 || to[h] !== b)) h = (h + 1) & mask;
    return h;
  }
  put(a, b, c) {
    const h = this.slot(a, b);
    this.from[h] = a + 1;
    this.to[h] = b;
    this.opposite[h] = c;
  }
  get(a, b) {
    const h = this.slot(a, b);
    return this.from[h] === 0 ? undefined : this.opposite[h];
  }
}

/**
 * parallelogramWalk: visits the vertices in first-use order of `indices` and calls
 * f(v, pred[3], kind) with the prediction of v from already visited vertices; f must set q[v].
 */
function parallelogramWalk(indices, vertexCount, q, f) {
  const known = scratch('known', Uint8Array, vertexCount).fill(0, 0, vertexCount);
  const edges = new EdgeMap(indices.length);
  const pred = [0, 0, 0];
  let last = -1;
  for (let t = 0; t < indices.length; t += 3) {
    for (let k = 0; k < 3; ++k) {
      const v = indices[t + k];
      if (known[v]) continue;
      const a = indices[t + (k + 1) % 3], b = indices[t + (k + 2) % 3];
      let kind = kNoneKnown;
      pred[0] = pred[1] = pred[2] = 0;
      if (known[a] && known[b]) {
        let c = edges.get(b, a);
        if (c === undefined) c = edges.get(a, b);
        if (c !== undefined) {
          for (let x = 0; x < 3; ++x) pred[x] = q[a * 3 + x] + q[b * 3 + x] - q[c * 3 + x];
          kind = kParallelogram;
        } else {
          for (let x = 0; x < 3; ++x) pred[x] = Math.floor((q[a * 3 + x] + q[b * 3 + x]) / 2);
          kind = kMidpoint;
        }
      } else if (known[a] || known[b]) {
        const s = known[a] ? a : b;
        for (let x = 0; x < 3; ++x) pred[x] = q[s * 3 + x];
        kind = kOneKnown;
      } else if (last >= 0) {
        for (let x = 0; x < 3; ++x) pred[x] = q[last * 3 + x];
      }
      for (let x = 0; x < 3; ++x) pred[x] = Math.min(Math.max(pred[x], 0), kMaxQ);
      f(v, pred, kind);
      known[v] = 1;
      last = v;
    }
    const a = indices[t], b = indices[t + 1], c = indices[t + 2];
    edges.put(a, b, c);
    edges.put(b, c, a);
    edges.put(c, a, b);
  }
}

/** ResidualModel::decode (version 2): per axis, the bit length as a 6-bit tree, then the mantissa. */
class ResidualModel {
  constructor() {
    this.length = new Uint16Array(3 * 64).fill(1024);
    this.mantissa = new Uint16Array(3 * 33 * 32).fill(1024);
  }
  decode(rc, axis) {
    let m = 1;
    for (let i = 0; i < 6; ++i) m = (m << 1) | rc.bit11(this.length, axis * 64 + m);
    const k = m - 64;
    if (k > 32) return -1;
    if (k === 0) return 0;
    let z = 1;
    for (let i = k - 1; i-- > 0;) z = z * 2 + rc.bit11(this.mantissa, (axis * 33 + k) * 32 + i);
    return z;
  }
}

// A model of counted bits reused from patch to patch (reset to its initial state), as the scratch
// arrays are: made afresh for every patch, the models were most of a worker's garbage.
function pooledBits(key, count) {
  let c = pool.get(key);
  if (!c) {
    c = countedBits(count);
    pool.set(key, c);
  } else {
    c.p.fill(2048);
    c.n.fill(0);
  }
  return c;
}

/** ContextModel: length[kind][axis][64], mantissa[axis][33][32], counted bits. */
function contextModel() {
  return { length: pooledBits('ctxLength', 4 * 3 * 64), mantissa: pooledBits('ctxMantissa', 3 * 33 * 32) };
}

/** decodeResidual: -1 when the stream names a length above 32 (damaged payload). */
function decodeResidual(rc, m, kind, axis) {
  const k = rc.tree(m.length, (kind * 3 + axis) * 64, 6);
  if (k > 32) return -1;
  if (k <= 1) return k;
  const base = (axis * 33 + k) * 32;
  let z = 1;
  for (let i = k - 1; i-- > 0;) z = z * 2 + rc.bit(m.mantissa, base + i);
  return z;
}

/** decodeIndexCode: the meshopt index code's bytes out of the range-coded stream. */
function decodeIndexCode(rc, code, triangles) {
  const bytes = code.length;
  const standard = countedBits(1);
  const hi = countedBits(32 * 16), lo = countedBits(32 * 16), data = countedBits(2 * 256);
  const tail = bytes - 16;
  if (rc.bit(standard, 0) === 0) {
    code[0] = kIndexHeaderV1;
    for (let i = 0; i < 16; ++i) code[tail + i] = kCodeAuxTableV1[i];
  } else {
    code[0] = rc.tree(data, 0, 8);
    for (let i = 0; i < 16; ++i) code[tail + i] = rc.tree(data, 0, 8);
  }
  let ctx = 0;
  for (let t = 0; t < triangles; ++t) {
    const h = rc.tree(hi, ctx * 16, 4);
    const l = rc.tree(lo, ((h << 1) | (ctx & 1)) * 16, 4);
    code[1 + t] = (h << 4) | l;
    ctx = (h << 1) | (l === 0 ? 1 : 0);
  }
  let cont = 0;
  for (let i = 1 + triangles; i < bytes - 16; ++i) {
    code[i] = rc.tree(data, cont * 256, 8);
    cont = code[i] >> 7;
  }
}

// ---- The connectivity code (version 4): patch_codec_connectivity.cpp's decoder half ----

const kNil = 0xffffffff;

/**
 * OpenEdges: the open half-edges of the decoded region, per vertex: out[u] lists v for every
 * open u->v, in[v] lists u, most recent first (singly linked lists in one pool of `val`/`nxt`).
 * Every add pushes at most two nodes, so 6 per triangle bound the pool.
 */
class OpenEdges {
  constructor(vertexCount, triangleCount) {
    this.outHead = scratch('openOut', Uint32Array, vertexCount).fill(kNil, 0, vertexCount);
    this.inHead = scratch('openIn', Uint32Array, vertexCount).fill(kNil, 0, vertexCount);
    this.val = scratch('openVal', Uint32Array, triangleCount * 6);
    this.nxt = scratch('openNxt', Uint32Array, triangleCount * 6);
    this.size = 0;
  }
  /** OpenEdges::add: closes the twin v->u if it is open, else opens u->v. */
  add(u, v) {
    if (this.remove(this.outHead, v, u)) {
      this.remove(this.inHead, u, v);
      return;
    }
    this.push(this.outHead, u, v);
    this.push(this.inHead, v, u);
  }
  firstOut(u) { const h = this.outHead[u]; return h === kNil ? kNil : this.val[h]; }
  firstIn(v) { const h = this.inHead[v]; return h === kNil ? kNil : this.val[h]; }
  /** push(head[w], v) */
  push(heads, w, v) {
    const i = this.size++;
    this.val[i] = v;
    this.nxt[i] = heads[w];
    heads[w] = i;
  }
  /** remove(head[w], v): unlinks the first entry equal to v; false when there is none. */
  remove(heads, w, v) {
    let prev = kNil;
    for (let i = heads[w]; i !== kNil; prev = i, i = this.nxt[i]) {
      if (this.val[i] === v) {
        if (prev === kNil) heads[w] = this.nxt[i];
        else this.nxt[prev] = this.nxt[i];
        return true;
      }
    }
    return false;
  }
}

/** EdgeFifo: the 16 most recent candidate edges; slot(i) is the push i pushes ago (0: the last). */
class EdgeFifo {
  constructor() {
    this.e = new Uint32Array(32).fill(kNil);
    this.offset = 0;
  }
  push(a, b) {
    this.e[this.offset * 2] = a;
    this.e[this.offset * 2 + 1] = b;
    this.offset = (this.offset + 1) & 15;
  }
  /** The index into e of slot i's edge (e0 at it, e1 after it). */
  slot(i) { return ((this.offset - 1 - i) & 15) * 2; }
}

// Third-vertex symbols of an attached triangle.
const kNew = 0, kOpenOut = 1, kOpenIn = 2, kExplicit = 3;
const kNoEdge = 16;  // the triangle is not attached to a FIFO edge

/** ConnectivityModel: slot0[16], slot1[16], slotRest[16][16], third[12][4], fresh[3], length[64], mantissa[33][32]. */
function connectivityModel() {
  return {
    slot0: pooledBits('conSlot0', 16), slot1: pooledBits('conSlot1', 16), slotRest: pooledBits('conSlotRest', 16 * 16),
    third: pooledBits('conThird', 12 * 4), fresh: pooledBits('conFresh', 3),
    length: pooledBits('conLength', 64), mantissa: pooledBits('conMantissa', 33 * 32),
  };
}

function bucket(slot) { return slot < 2 ? slot : 2; }

/** decodeExplicit: the vertex next - 1 - d, or -1 when the code names no vertex decoded so far. */
function decodeExplicit(rc, m, next) {
  const k = rc.tree(m.length, 0, 6);
  if (k > 32) return -1;
  let d = k;
  if (k >= 2) {
    d = 1;
    for (let i = k - 1; i-- > 0;) d = d * 2 + rc.bit(m.mantissa, k * 32 + i);
  }
  if (d >= next) return -1;
  return next - 1 - d;
}

/**
 * decodeConnectivity: `triangleCount` triangles over `vertexCount` vertices out of the range-coded
 * stream (mt_format.h, kPayloadConnectivity). Throws BadPayload on every damage the C++ throws on.
 * @returns {Uint32Array} the triangle list
 */
export function decodeConnectivity(rc, triangleCount, vertexCount) {
  const m = connectivityModel();
  const open = new OpenEdges(vertexCount, triangleCount);
  const fifo = new EdgeFifo();
  const fe = fifo.e;
  const triangles = new Uint32Array(triangleCount * 3);
  let next = 0, ctx = 3 * 4 + kExplicit;
  let v0 = 0, v1 = 0, v2 = 0;
  for (let t = 0; t < triangles.length; t += 3) {
    let slot = 0;
    if (rc.bit(m.slot0, ctx)) {
      slot = 1;
      if (rc.bit(m.slot1, ctx)) slot = 2 + rc.tree(m.slotRest, ctx * 16, 4);
    }
    if (slot > kNoEdge) bad(`connectivity code names edge slot ${slot}`);
    let sym = kExplicit;
    if (slot !== kNoEdge) {
      const e = fifo.slot(slot);
      if (fe[e] === kNil) bad('connectivity code names an empty edge slot');
      v0 = fe[e];
      v1 = fe[e + 1];
      sym = rc.tree(m.third, (bucket(slot) * 4 + (ctx & 3)) * 4, 2);
      if (sym === kNew) {
        v2 = next++;
      } else if (sym === kOpenOut) {
        v2 = open.firstOut(v0);
      } else if (sym === kOpenIn) {
        v2 = open.firstIn(v1);
      } else {
        v2 = decodeExplicit(rc, m, next);
        if (v2 < 0) bad('connectivity code names a vertex not decoded yet');
      }
      if (v2 === kNil) bad('connectivity code names an open edge that does not exist');
    } else {
      for (let k = 0; k < 3; ++k) {
        let v;
        if (!rc.bit(m.fresh, k)) v = next++;
        else if ((v = decodeExplicit(rc, m, next)) < 0) bad('connectivity code names a vertex not decoded yet');
        if (k === 0) v0 = v;
        else if (k === 1) v1 = v;
        else v2 = v;
      }
    }
    if (next > vertexCount) bad('connectivity code has more vertices than the header');
    // Not in the C++ loop (it checks once, after it): a stream that ran out cannot decode, so stop
    // here rather than decode up to the header's triangle count out of zeros.
    if (rc.overrun > 0) bad('connectivity stream truncated');
    triangles[t] = v0;
    triangles[t + 1] = v1;
    triangles[t + 2] = v2;
    open.add(v0, v1);
    open.add(v1, v2);
    open.add(v2, v0);
    if (slot === kNoEdge) fifo.push(v1, v0);
    fifo.push(v2, v1);
    fifo.push(v0, v2);
    ctx = (slot === kNoEdge ? 3 : bucket(slot)) * 4 + sym;
  }
  if (rc.overrun > 0) bad('connectivity stream truncated');
  if (next !== vertexCount) bad('vertices not referenced by any triangle');
  return triangles;
}

/** readMeshoptFrame: the zstd frame (or stored bytes) after the payload header. */
function readMeshoptFrame(data, h, libs) {
  const size = data.length;
  let pos = kPayloadHeaderSize;
  if (size < pos + 8) bad('truncated before the zstd frame');
  const dv = new DataView(data.buffer, data.byteOffset, data.byteLength);
  const rawSize = dv.getUint32(pos, true), zSize = dv.getUint32(pos + 4, true);
  pos += 8;
  const ranged = (h.flags & kPayloadRangePositions) !== 0;
  const rangeIndices = (h.flags & kPayloadRangeIndices) !== 0;
  const contextual = (h.flags & kPayloadPositionContexts) !== 0;
  const connectivity = (h.flags & kPayloadConnectivity) !== 0;
  if ((rangeIndices || contextual) && !ranged) bad('version-3 flags without range-coded positions');
  if (rangeIndices && (h.flags & kPayloadStrip)) bad('range-coded indices cannot be a strip');
  if (connectivity && (!contextual || rangeIndices || (h.flags & kPayloadStrip)))
    bad(`connectivity code with flags ${h.flags}`);
  // Version 3 with range-coded indices, and version 4 with the connectivity code, may store the
  // raw bytes as they are (zSize 0).
  const stored = (rangeIndices || connectivity) && zSize === 0;
  const frameBytes = stored ? rawSize : zSize;
  if (ranged ? frameBytes > size - pos : size - pos !== zSize) bad(`zstd frame size ${zSize} does not match payload`);
  const n = h.vertexCount, tri3 = h.triangleCount * 3;
  const maxRaw = 12 + encodeIndexSequenceBound(tri3 + h.triangleCount, n) + encodeIndexBufferBound(tri3, n) +
    encodeVertexBufferBound(n, 8) + n * 12;
  if (rawSize > maxRaw) bad(`raw size ${rawSize} too large for its counts`);
  let raw;
  if (stored) {
    raw = data.slice(pos, pos + rawSize);
  } else {
    try {
      raw = libs.zstd(data.subarray(pos, pos + zSize), rawSize);
    } catch (e) {
      bad('zstd frame does not decompress');
    }
    if (raw.length !== rawSize) bad('zstd frame does not decompress');
  }
  if (rawSize < 12) bad('raw stream too short');
  const rdv = new DataView(raw.buffer, raw.byteOffset, raw.byteLength);
  const sizes = [rdv.getUint32(0, true), rdv.getUint32(4, true), rdv.getUint32(8, true)];
  return { raw, sizes, rangeBegin: pos + frameBytes };
}

/** meshopt_unstripify (meshoptimizer stripifier.cpp) with restart index ~0u. */
function unstripify(strip) {
  const out = [];
  let start = 0;
  for (let i = 0; i < strip.length; ++i) {
    if (strip[i] === 0xffffffff) {
      start = i + 1;
    } else if (i - start >= 2) {
      let a = strip[i - 2], b = strip[i - 1];
      const c = strip[i];
      if ((i - start) & 1) { const t = a; a = b; b = t; }
      if (a !== b && a !== c && b !== c) out.push(a, b, c);
    }
  }
  return Uint32Array.from(out);
}

/** decodeMeshoptTriangles: the triangle list from the index code `ib` (list, or strip). */
function decodeMeshoptTriangles(h, ib, sizes, libs) {
  const n = h.vertexCount, tri3 = h.triangleCount * 3, indexCount = sizes[1];
  let triangles;
  if (h.flags & kPayloadStrip) {
    if (indexCount > tri3 + h.triangleCount + 3) bad('strip too long');
    const s = new Uint32Array(indexCount);
    if (indexCount) {
      try {
        libs.meshopt.decodeIndexSequence(new Uint8Array(s.buffer), indexCount, 4, ib.subarray(0, sizes[0]));
      } catch (e) {
        bad('index sequence does not decode');
      }
    }
    for (const i of s) if (i !== 0xffffffff && i >= n) bad('strip index out of range');
    triangles = unstripify(s);
  } else {
    if (indexCount !== tri3) bad('index count does not match triangle count');
    triangles = new Uint32Array(indexCount);
    if (indexCount) {
      try {
        libs.meshopt.decodeIndexBuffer(new Uint8Array(triangles.buffer), indexCount, 4, ib.subarray(0, sizes[0]));
      } catch (e) {
        bad('index stream does not decode');
      }
    }
  }
  if (triangles.length !== tri3) bad('triangle count mismatch');
  for (const i of triangles) if (i >= n) bad(`triangle index ${i} out of range`);
  return triangles;
}

/** Octahedral 8-bit normal (mt_format.h) to a unit vector, into out[o..o+2]. */
export function decodeOctahedral8(x8, y8, out, o) {
  let x = x8 / 255 * 2 - 1, y = y8 / 255 * 2 - 1;
  const z = 1 - Math.abs(x) - Math.abs(y);
  if (z < 0) {
    const fx = (1 - Math.abs(y)) * (x >= 0 ? 1 : -1);
    const fy = (1 - Math.abs(x)) * (y >= 0 ? 1 : -1);
    x = fx;
    y = fy;
  }
  const len = Math.sqrt(x * x + y * y + z * z);
  out[o] = x / len;
  out[o + 1] = y / len;
  out[o + 2] = z / len;
}

/** decodeMeshoptAttributes: normals (float, 3 a vertex) and colours (RGBA8) from the vertex code. */
function decodeMeshoptAttributes(h, ab, bytes, libs, out) {
  const n = h.vertexCount;
  const stride = attributeStride(h.flags);
  if (stride === 0) {
    if (bytes !== 0) bad('attribute stream present without attributes');
    return;
  }
  const attrs = new Uint8Array(n * stride);
  if (n) {
    try {
      libs.meshopt.decodeVertexBuffer(attrs, n, stride, ab.subarray(0, bytes));
    } catch (e) {
      bad('attribute stream does not decode');
    }
  }
  if (h.flags & kPayloadNormals) out.normals = new Float32Array(n * 3);
  if (h.flags & kPayloadColors) out.colors = new Uint8Array(n * 4);
  for (let v = 0; v < n; ++v) {
    let d = v * stride;
    if (h.flags & kPayloadNormals) decodeOctahedral8(attrs[d], attrs[d + 1], out.normals, v * 3), (d += 2);
    if (h.flags & kPayloadColors) for (let k = 0; k < 4; ++k) out.colors[v * 4 + k] = attrs[d + k];
  }
}

/** storeDecodedPositions: checks q and returns it as qRel. */
function storeDecodedPositions(q, seenCount, n) {
  if (seenCount !== n) bad('vertices not referenced by any triangle');
  const qRel = scratch('qRel', Uint32Array, n * 3).subarray(0, n * 3);  // decodePatch copies it
  for (let i = 0; i < n * 3; ++i) {
    if (!(q[i] >= 0 && q[i] <= kMaxQ)) bad('decoded grid coordinate out of range');
    qRel[i] = q[i];
  }
  return qRel;
}

/** decodeContextPositions: kPayloadPositionContexts (version 3). */
function decodeContextPositions(rc, triangles, n) {
  const q = scratch('q', Float64Array, n * 3);  // every vertex is set, or seenCount tells
  let seenCount = 0, tooWide = false;
  const model = contextModel();
  parallelogramWalk(triangles, n, q, (v, pred, kind) => {
    for (let x = 0; x < 3; ++x) {
      let z = decodeResidual(rc, model, kind, x);
      if (z < 0) tooWide = true, (z = 0);
      q[v * 3 + x] = pred[x] + unzigzag(z);
    }
    ++seenCount;
  });
  if (tooWide) bad('position stream names a residual wider than 32 bits');
  if (rc.overrun > 0) bad('position stream truncated');
  return storeDecodedPositions(q, seenCount, n);
}

/** decodeLegacyPositions: version 1 (byte planes in the frame) and version 2 (range-coded per axis). */
function decodeLegacyPositions(rc, ranged, planes, raw, pbOffset, triangles, n) {
  let res = null;
  if (ranged) {
    res = new Float64Array(n * 3);
    const model = new ResidualModel();
    for (let i = 0; i < n * 3; ++i) {
      const z = model.decode(rc, i % 3);
      if (z < 0) bad('position stream names a residual wider than 32 bits');
      res[i] = z;
    }
    if (rc.overrun > 0) bad('position stream truncated');
  }
  const q = new Float64Array(n * 3);
  let seenCount = 0;
  parallelogramWalk(triangles, n, q, (v, pred) => {
    for (let x = 0; x < 3; ++x) {
      let z = 0;
      if (ranged) z = res[v * 3 + x];
      else for (let b = 0; b < planes; ++b) z += raw[pbOffset + (x * planes + b) * n + v] * 2 ** (8 * b);
      q[v * 3 + x] = pred[x] + unzigzag(z);
    }
    ++seenCount;
  });
  return storeDecodedPositions(q, seenCount, n);
}

/**
 * decodeMeshopt: fills out.triangles (Uint32Array), out.normals, out.colors; returns qRel.
 * @param {Uint8Array} data the payload
 */
export function decodeMeshopt(data, h, libs, out) {
  const f = readMeshoptFrame(data, h, libs);
  const ranged = (h.flags & kPayloadRangePositions) !== 0;
  const rangeIndices = (h.flags & kPayloadRangeIndices) !== 0;
  const n = h.vertexCount;
  const planes = ranged ? 0 : (h.flags & kPayloadWide) ? 4 : 2;
  const sizes = f.sizes;
  const rc = new RangeDecoder(data, f.rangeBegin, data.length);
  let ib = f.raw.subarray(12);
  let abOffset = 12 + sizes[0];
  if (h.flags & kPayloadConnectivity) {
    if (sizes[2] + 12 !== f.raw.length || sizes[0] !== 0 || sizes[1] !== h.triangleCount * 3)
      bad('stream sizes do not add up');
    if (libs.wasm) {
      // The same decoder in WebAssembly (codec_wasm.js).
      const r = libs.wasm.decode(data.subarray(f.rangeBegin), h.triangleCount, n);
      out.triangles = r.triangles;
      decodeMeshoptAttributes(h, f.raw.subarray(12), sizes[2], libs, out);
      return r.positions;
    }
    out.triangles = decodeConnectivity(rc, h.triangleCount, n);
    decodeMeshoptAttributes(h, f.raw.subarray(12), sizes[2], libs, out);
    return decodeContextPositions(rc, out.triangles, n);
  }
  if (rangeIndices) {
    if (sizes[2] + 12 !== f.raw.length) bad('stream sizes do not add up');
    if (sizes[0] < 1 + h.triangleCount + 16 || sizes[0] > encodeIndexBufferBound(h.triangleCount * 3, n))
      bad(`index code size ${sizes[0]} does not fit the triangle count`);
    const code = new Uint8Array(sizes[0]);
    decodeIndexCode(rc, code, h.triangleCount);
    if (rc.overrun > 0) bad('index stream truncated');
    ib = code;
    abOffset = 12;
  } else if (sizes[0] + sizes[2] + 12 + n * 3 * planes !== f.raw.length) {
    bad('stream sizes do not add up');
  }
  out.triangles = decodeMeshoptTriangles(h, ib, sizes, libs);
  decodeMeshoptAttributes(h, f.raw.subarray(abOffset), sizes[2], libs, out);
  if (h.flags & kPayloadPositionContexts) return decodeContextPositions(rc, out.triangles, n);
  return decodeLegacyPositions(rc, ranged, planes, f.raw, abOffset + sizes[2], out.triangles, n);
}
