// Texture payloads (mt_format.h "Textures"; version 6): the decoder half of
// mtfile/texture_payload.cpp (decodeTexturePayload) and the checks of MtFileReader::readTexture
// (the image's size and format against the TextureRecord), then what the viewer draws from them:
// the patch's vertices split per distinct (vertex, corner coordinate) pair, as
// mtrender/gl_renderer.cpp's splitTexturedVertices does for GL. The image itself is decoded by the
// browser (createImageBitmap, worker.js).

import { kTexturePayloadHeaderSize, kMaxAtlasSide, kImageJpeg, kImagePng, kUvCornerLists } from './format.js';

/** A damaged texture payload (the worker reports it as a warning; the patch is drawn untextured). */
export class BadTexture extends Error {
  constructor(what) {
    super(what);
    this.name = 'BadTexture';
  }
}
const bad = (what) => { throw new BadTexture(what); };

function unzigzag(z) { return z & 1 ? -Math.floor(z / 2) - 1 : Math.floor(z / 2); }

/**
 * ZSTD_getFrameContentSize: the decompressed size a zstd frame's header states (RFC 8878 3.1.1.1),
 * -1 when it states none or the bytes are not a frame header.
 */
export function zstdFrameContentSize(b) {
  if (b.length < 5 || b[0] !== 0x28 || b[1] !== 0xb5 || b[2] !== 0x2f || b[3] !== 0xfd) return -1;
  const d = b[4];
  const fcsFlag = d >> 6, single = (d >> 5) & 1, dictFlag = d & 3;
  let p = 5 + (single ? 0 : 1) + [0, 1, 2, 4][dictFlag];
  const n = fcsFlag === 0 ? (single ? 1 : 0) : [0, 2, 4, 8][fcsFlag];
  if (n === 0 || b.length < p + n) return -1;
  let v = 0;
  for (let k = n - 1; k >= 0; --k) v = v * 256 + b[p + k];
  return n === 2 ? v + 256 : v;
}

/**
 * decodeTexturePayload + readTexture's checks: payload bytes of a patch whose decoded triangles
 * are `triangles` (indices < vertexCount) -> { width, height, imageFormat, image (Uint8Array, a
 * view of `data`), cornerUV (Float32Array, 6 per triangle, v = 0 at the image's bottom row) }.
 * `record`: the patch's TextureRecord fields {width, height, imageBytes}. Throws BadTexture.
 * @param {Uint8Array} data
 * @param {Uint32Array} triangles
 * @param {number} vertexCount
 * @param {{width:number, height:number, imageBytes:number}} record
 * @param {(bytes:Uint8Array, n:number)=>Uint8Array} zstd
 */
export function decodeTexturePayload(data, triangles, vertexCount, record, zstd) {
  const size = data.length;
  if (size < kTexturePayloadHeaderSize) bad('texture payload shorter than its header');
  const dv = new DataView(data.buffer, data.byteOffset, data.byteLength);
  const triangleCount = triangles.length / 3;
  const h = {
    triangleCount: dv.getUint32(0, true), width: dv.getUint16(4, true), height: dv.getUint16(6, true),
    imageFormat: data[8], uvCoding: data[9], reserved: dv.getUint16(10, true), uvBytes: dv.getUint32(12, true),
  };
  if (h.triangleCount !== triangleCount) bad(`texture payload has ${h.triangleCount} triangles, the patch ${triangleCount}`);
  if (h.uvCoding !== kUvCornerLists || h.reserved !== 0) bad('texture payload: unknown coordinate coding');
  if (h.imageFormat !== kImageJpeg && h.imageFormat !== kImagePng) bad('texture payload: unknown image format');
  if (h.width === 0 || h.height === 0 || h.width > kMaxAtlasSide || h.height > kMaxAtlasSide) bad('texture payload: image size out of range');
  if (h.uvBytes > size - kTexturePayloadHeaderSize) bad('texture payload: coordinates run past its end');
  const frame = data.subarray(kTexturePayloadHeaderSize, kTexturePayloadHeaderSize + h.uvBytes);
  const rawSize = zstdFrameContentSize(frame);
  // Kinds (3 per triangle) and at most one value (two varints of up to 5 bytes) per corner.
  if (rawSize < 0 || rawSize < 3 * triangleCount || rawSize > 33 * triangleCount) bad('texture payload: bad coordinate frame');
  let raw;
  try {
    raw = zstd(frame, rawSize);
  } catch (_) {
    bad('texture payload: damaged coordinate frame');
  }
  if (!raw || raw.length !== rawSize) bad('texture payload: damaged coordinate frame');
  const image = data.subarray(kTexturePayloadHeaderSize + h.uvBytes);
  // readTexture: the image against the index, and its bytes against the format the payload names.
  if (h.width !== record.width || h.height !== record.height || image.length !== record.imageBytes) bad('image size differs from the index');
  const magic = h.imageFormat === kImageJpeg
    ? image.length >= 3 && image[0] === 0xff && image[1] === 0xd8 && image[2] === 0xff
    : image.length >= 4 && image[0] === 0x89 && image[1] === 0x50 && image[2] === 0x4e && image[3] === 0x47;
  if (!magic) bad('the image is not the format the payload names');
  // The corners in decoded order; each vertex's distinct coordinates as a list (kind k: its k-th).
  const cornerUV = new Float32Array(6 * triangleCount);
  const first = new Int32Array(vertexCount).fill(-1), last = new Int32Array(vertexCount).fill(-1);
  const listST = [], listNext = [];
  let value = 3 * triangleCount;
  const varint = () => {
    let v = 0;
    for (let shift = 0; ; shift += 7) {
      if (value >= raw.length || shift > 28) bad('texture payload: coordinate values end early or are damaged');
      const b = raw[value++];
      v += (b & 0x7f) * 2 ** shift;
      if (!(b & 0x80)) return v >>> 0;
    }
  };
  let prevS = 0, prevT = 0;
  const su = 1 / (16 * h.width), sv = 1 / (16 * h.height);
  const maxS = 16 * h.width, maxT = 16 * h.height;
  for (let t = 0; t < triangleCount; ++t)
    for (let c = 0; c < 3; ++c) {
      const v = triangles[3 * t + c];
      if (v >= vertexCount) bad('texture payload: triangle names a vertex out of range');
      const kind = raw[3 * t + c];
      let st;
      if (kind === 255) {
        prevS += unzigzag(varint());
        prevT += unzigzag(varint());
        if (prevS < 0 || prevT < 0 || prevS > maxS || prevT > maxT) bad('texture payload: a coordinate lies outside the image');
        st = prevS * 65536 + prevT;
        listST.push(st);
        listNext.push(-1);
        const id = listST.length - 1;
        if (first[v] < 0) first[v] = id;
        else listNext[last[v]] = id;
        last[v] = id;
      } else {
        let e = first[v];
        for (let k = 0; k < kind && e >= 0; ++k) e = listNext[e];
        if (e < 0) bad('texture payload: a corner names a coordinate its vertex does not have');
        st = listST[e];
      }
      cornerUV[6 * t + 2 * c] = Math.fround(Math.floor(st / 65536) * su);
      cornerUV[6 * t + 2 * c + 1] = Math.fround((st % 65536) * sv);
    }
  if (value !== raw.length) bad('texture payload: trailing coordinate values');
  return { width: h.width, height: h.height, imageFormat: h.imageFormat, image, cornerUV };
}

/**
 * splitTexturedVertices: one vertex per distinct (vertex, coordinate) pair of the corners, so each
 * corner's coordinate is a vertex attribute. Coordinates as unorm16 (mtrender's TexturedVertex),
 * v flipped (1 - v): the browser uploads an ImageBitmap top row first, GL's texture rows are bottom
 * first. Returns { remap (new vertex -> old), uv (Uint16Array, 2 per new vertex), triangles }.
 * @param {Uint32Array} triangles
 * @param {number} vertexCount
 * @param {Float32Array} cornerUV
 */
export function splitTexturedVertices(triangles, vertexCount, cornerUV) {
  const head = new Int32Array(vertexCount).fill(-1);
  const remap = [], uvs = [], next = [];
  const out = new Uint32Array(triangles.length);
  for (let i = 0; i < triangles.length; ++i) {
    const v = triangles[i];
    const u = Math.round(Math.min(Math.max(cornerUV[2 * i], 0), 1) * 65535);
    const w = 65535 - Math.round(Math.min(Math.max(cornerUV[2 * i + 1], 0), 1) * 65535);
    let k = head[v];
    while (k >= 0 && (uvs[2 * k] !== u || uvs[2 * k + 1] !== w)) k = next[k];
    if (k < 0) {
      k = remap.length;
      remap.push(v);
      uvs.push(u, w);
      next.push(head[v]);
      head[v] = k;
    }
    out[i] = k;
  }
  return { remap: Uint32Array.from(remap), uv: Uint16Array.from(uvs), triangles: out };
}

/**
 * The bound the cache reserves for a textured patch before it loads (Scene::decodedBytesBound's
 * texture part): every corner may become a vertex of its own (position 12, normal 4, colour 4,
 * coordinate 4 bytes: 24), 12 index bytes a triangle, and the atlas decoded as
 * RGBA8. The cache holds the actual bytes once the patch is decoded.
 */
export function texturedBytesBound(triangles, width, height) {
  return 3 * triangles * 24 + 12 * triangles + 4 * width * height;
}
