// The adaptive binary range coder of the meshopt payloads: the decoder half of
// mtfile/range_coder.h (LZMA's coder with 11-bit probabilities for version 2, the counted
// probabilities of version 3), ported function by function.

export const kCountedBitLimit = 30;
const kRate = new Uint32Array(kCountedBitLimit + 1);
for (let n = 0; n <= kCountedBitLimit; ++n) kRate[n] = Math.floor(65536 / (n + 2));

/** CountedBit[] as two arrays: p (P(bit = 0) in 1/4096, from 2048) and n (updates, to 30). */
export function countedBits(count) {
  // Plain arrays of small integers, not typed arrays: a new typed array costs Chromium far more to
  // make (its buffer lives outside the JS heap). codec_meshopt.js keeps the version-4 models from
  // patch to patch (pooledBits); the index-code models of version 3 are still made per patch.
  const p = [], n = [];
  for (let i = 0; i < count; ++i) p.push(2048), n.push(0);
  return { p, n };
}

export class RangeDecoder {
  /** @param {Uint8Array} bytes the stream (the encoder's always-zero first byte not stored) */
  constructor(bytes, begin, end) {
    this.b = bytes;
    this.pos = begin;
    this.end = end;
    this.begin = begin;
    this.code = 0;
    this.range = 0xffffffff;
    this.overrun = 0;
    for (let i = 0; i < 4; ++i) this.code = this.code * 256 + this.next();
  }
  next() {
    if (this.pos < this.end) return this.b[this.pos++];
    ++this.overrun;
    return 0;
  }
  normalize() {
    while (this.range < 16777216) {
      this.range = this.range * 256;
      this.code = this.code * 256 + this.next();
    }
  }
  /** LZMA bit with an 11-bit probability probs[i] (version 2). */
  bit11(probs, i) {
    const p = probs[i];
    const bound = (this.range >>> 11) * p;
    let b;
    if (this.code < bound) {
      this.range = bound;
      probs[i] = p + ((2048 - p) >> 5);
      b = 0;
    } else {
      this.code -= bound;
      this.range -= bound;
      probs[i] = p - (p >> 5);
      b = 1;
    }
    this.normalize();
    return b;
  }
  /** Counted bit c[i] (version 3): bound from 12-bit p, then adapt by 1/(n+2). */
  bit(c, i) {
    const p = c.p[i];
    const bound = (this.range >>> 12) * p;
    let b;
    if (this.code < bound) {
      this.range = bound;
      b = 0;
    } else {
      this.code -= bound;
      this.range -= bound;
      b = 1;
    }
    // adapt()
    const rate = kRate[c.n[i]];
    let q = p;
    if (!b) q += ((4096 - p) * rate) >>> 16;
    else q -= (p * rate) >>> 16;
    c.p[i] = Math.min(Math.max(q, 31), 4065);
    if (c.n[i] < kCountedBitLimit) ++c.n[i];
    this.normalize();
    return b;
  }
  /** nbits MSB first through the binary tree c[base + 1 .. base + 2^nbits - 1]. */
  tree(c, base, nbits) {
    let m = 1;
    for (let i = 0; i < nbits; ++i) m = (m << 1) | this.bit(c, base + m);
    return m - (1 << nbits);
  }
  consumed() { return this.pos - this.begin + this.overrun; }
}
