// The MT file format as the browser reads it: a port of mtfile/mt_format.h (THE spec) and of the
// reader half of mtfile/mt_file.cpp, function by function (readHeaderAndFooter, readIndex,
// checkIndex), so a change of the format ports mechanically. Everything here works on
// ArrayBuffers; fetching them is source.js's business.

export const kMagic = 'BMT-MT\r\n';
export const kFooterMagic = 'BMT-END\n';
// Readers accept kMinReadableVersion..kVersion (mt_format.h); a later file version is refused with
// a message naming it, never guessed at.
export const kVersion = 6;
export const kMinReadableVersion = 1;
// Version 5: NodeRecord.colorError (was reserved and zero: older files read as 0, not measured).
export const kFirstColorErrorVersion = 5;
// Version 6: textured files (kHasTextures): a TextureRecord per patch after the patch index.
export const kFirstTextureVersion = 6;
export const kHeaderSize = 256;
export const kFooterSize = 32;

export const Codec = Object.freeze({ Meshopt: 1, Draco: 2 });

export const kHasNormals = 1 << 0;
export const kHasColors = 1 << 1;
export const kHasTextures = 1 << 2;  // a TextureRecord per patch (version 6)

export const kNodeRecordSize = 80;
export const kArcRecordSize = 16;
export const kPatchRecordSize = 32;
export const kPayloadHeaderSize = 24;
// Textures (mt_format.h "Textures"): TextureRecord (32 B: offset u64, size u32, width u16,
// height u16, checksum u64, imageBytes u32, reserved u32) and the payload's 16-byte header.
export const kTextureRecordSize = 32;
export const kTexturePayloadHeaderSize = 16;
export const kMaxAtlasSide = 2048;
export const kImageJpeg = 1;
export const kImagePng = 2;
export const kUvCornerLists = 1;

// PayloadHeader flags.
export const kPayloadNormals = 1 << 0;
export const kPayloadColors = 1 << 1;
export const kPayloadWide = 1 << 2;
export const kPayloadStrip = 1 << 3;
export const kPayloadRangePositions = 1 << 4;
export const kPayloadRangeIndices = 1 << 5;
export const kPayloadPositionContexts = 1 << 6;
export const kPayloadConnectivity = 1 << 7;  // version 4: triangles by the connectivity code
// Every flag this reader knows; a payload with another bit set is refused.
export const kPayloadKnownFlags = 0xff;

// The metadata block (optional, mt_format.h "The metadata block").
export const kMaxMetadataSize = 1 << 20;
export const kMaxMetadataKey = 255;
export const kMetadataCrs = 'crs';
export const kMetadataSizeOffset = 180;  // offsetof(FileHeader, metadataSize)

/** attributeStride(payloadFlags) of mt_format.h. */
export function attributeStride(flags) {
  let s = 0;
  if (flags & kPayloadNormals) s += 2;
  if (flags & kPayloadColors) s += 4;
  return (s + 3) & ~3;
}

/** An error that names the file (as mt::Error's "PATH: what" messages do). */
export class MtError extends Error {
  constructor(path, what) {
    super(`${path}: ${what}`);
    this.name = 'MtError';
  }
}

function str(bytes, off, n) {
  let s = '';
  for (let i = 0; i < n; ++i) s += String.fromCharCode(bytes[off + i]);
  return s;
}

// uint64 as a JS number (exact below 2^53, which every offset and count of a real file is).
const littleEndian = new Uint8Array(new Uint32Array([1]).buffer)[0] === 1;

function u64(dv, off) {
  const lo = dv.getUint32(off, true), hi = dv.getUint32(off + 4, true);
  if (hi >= 0x200000) return Number.POSITIVE_INFINITY;  // beyond 2^53: surely damaged
  return hi * 4294967296 + lo;
}

/**
 * FileHeader (the first kHeaderSize bytes) as an object.
 * @param {ArrayBuffer} buf at least kHeaderSize bytes
 */
export function parseHeader(buf) {
  const dv = new DataView(buf, 0, kHeaderSize);
  const b = new Uint8Array(buf, 0, kHeaderSize);
  const d3 = (o) => [dv.getFloat64(o, true), dv.getFloat64(o + 8, true), dv.getFloat64(o + 16, true)];
  return {
    magic: str(b, 0, 8),
    version: dv.getUint32(8, true),
    headerSize: dv.getUint32(12, true),
    codec: dv.getUint32(16, true),
    vertexFlags: dv.getUint32(20, true),
    payloadAlignment: dv.getUint32(24, true),
    levelCount: dv.getUint32(28, true),
    nodeCount: u64(dv, 32),
    arcCount: u64(dv, 40),
    patchRefCount: u64(dv, 48),
    patchCount: u64(dv, 56),
    inputTriangles: u64(dv, 64),
    inputVertices: u64(dv, 72),
    storedTriangles: u64(dv, 80),
    boundsMin: d3(88),
    boundsMax: d3(112),
    gridOrigin: d3(136),
    gridStep: dv.getFloat64(160, true),
    quantizationError: dv.getFloat64(168, true),
    gridBits: dv.getUint32(176, true),
    metadataSize: dv.getUint32(180, true),
    metaOffset: u64(dv, 184),
    nodesOffset: u64(dv, 192),
    arcsOffset: u64(dv, 200),
    backArcsOffset: u64(dv, 208),
    patchRefsOffset: u64(dv, 216),
    patchesOffset: u64(dv, 224),
    weldedVertices: u64(dv, 232),
    weldedTriangles: u64(dv, 240),
    metadataOffset: u64(dv, 248),
  };
}

/** Footer (the last kFooterSize bytes). */
export function parseFooter(buf) {
  const dv = new DataView(buf);
  return {
    metaOffset: u64(dv, 0),
    checksumLo: dv.getUint32(8, true),
    checksumHi: dv.getUint32(12, true),
    version: dv.getUint32(16, true),
    reserved: dv.getUint32(20, true),
    magic: str(new Uint8Array(buf), 24, 8),
  };
}

/**
 * MtFileReader::readHeaderAndFooter: magic, version, header size, footer.
 * @param {string} path for messages
 * @param {number} size file size in bytes
 * @param {ArrayBuffer} headerBuf bytes [0, kHeaderSize)
 * @param {ArrayBuffer} footerBuf bytes [size - kFooterSize, size)
 */
export function readHeaderAndFooter(path, size, headerBuf, footerBuf) {
  if (size < kHeaderSize + kFooterSize)
    throw new MtError(path, `not an MT file: ${size} bytes is shorter than header + footer (truncated?)`);
  const h = parseHeader(headerBuf);
  if (h.magic !== kMagic) throw new MtError(path, 'not an MT file: bad magic at byte offset 0');
  if (h.version < kMinReadableVersion || h.version > kVersion)
    throw new MtError(path, `unsupported MT version ${h.version} (this viewer reads ${kMinReadableVersion}..${kVersion}) at byte offset 8`);
  if (h.headerSize !== kHeaderSize) throw new MtError(path, 'bad header size at byte offset 12');
  const f = parseFooter(footerBuf);
  const footerAt = size - kFooterSize;
  if (f.magic !== kFooterMagic)
    throw new MtError(path, `bad footer magic at byte offset ${footerAt + 24} (truncated or damaged file)`);
  if (f.version !== h.version) throw new MtError(path, `footer version mismatch at byte offset ${footerAt + 16}`);
  if (f.reserved !== 0) throw new MtError(path, `footer reserved bytes at byte offset ${footerAt + 20} are not zero`);
  if (f.metaOffset !== h.metaOffset || h.metaOffset < kHeaderSize || h.metaOffset > footerAt)
    throw new MtError(path, `footer index offset ${f.metaOffset} out of range (file ${size} bytes) at byte offset ${footerAt}`);
  return { header: h, footer: f };
}

/**
 * The byte range of the index section ([metaOffset, size - kFooterSize)), after the section
 * offsets (the optional metadata block last) were checked to tile it (MtFileReader::readIndex,
 * first part).
 */
export function indexRange(path, size, h) {
  const footerAt = size - kFooterSize;
  const metaSize = footerAt - h.metaOffset;
  const maxCount = metaSize;
  if (h.nodeCount > maxCount || h.arcCount > maxCount || h.patchRefCount > maxCount || h.patchCount > maxCount)
    throw new MtError(path, 'header counts larger than the index section (damaged header)');
  let expect = h.metaOffset;
  const section = (off, bytes, name) => {
    if (off !== expect) throw new MtError(path, `bad ${name} offset ${off} in header`);
    expect += bytes;
  };
  section(h.nodesOffset, h.nodeCount * kNodeRecordSize, 'node array');
  section(h.arcsOffset, h.arcCount * kArcRecordSize, 'arc array');
  section(h.backArcsOffset, h.arcCount * 4, 'backward-star array');
  section(h.patchRefsOffset, h.patchRefCount * 4, 'patch reference array');
  section(h.patchesOffset, h.patchCount * kPatchRecordSize, 'patch index');
  const textured = (h.vertexFlags & kHasTextures) !== 0;
  if (textured && h.version < kFirstTextureVersion) throw new MtError(path, `textures flagged in a version ${h.version} file`);
  if (textured) expect += h.patchCount * kTextureRecordSize;  // TextureRecord[patchCount], right after the patch index
  if (h.metadataSize > kMaxMetadataSize || (h.metadataSize === 0 && h.metadataOffset !== 0))
    throw new MtError(path, `bad metadata block size ${h.metadataSize} in header (byte offset ${kMetadataSizeOffset})`);
  if (h.metadataSize) section(h.metadataOffset, h.metadataSize, 'metadata block');
  if (expect !== footerAt)
    throw new MtError(path, `index section is ${metaSize} bytes, header describes ${expect - h.metaOffset} (truncated or damaged)`);
  return { begin: h.metaOffset, end: footerAt };
}

/**
 * MtFileReader::readIndex, second half: the records out of the index section's bytes (the
 * footer checksum over header + section is checked by the caller, which has the hash).
 * Returns typed arrays (structure of arrays), which is what the cut loop walks.
 */
export function readIndex(h, meta) {
  const dv = new DataView(meta);
  const base = h.metaOffset;
  const nc = h.nodeCount, ac = h.arcCount, pc = h.patchCount;
  const nodes = {
    count: nc,
    center: new Float64Array(nc * 3),
    radius: new Float32Array(nc),
    error: new Float32Array(nc),
    coneAxis: new Float32Array(nc * 3),
    coneCutoff: new Float32Array(nc),
    level: new Uint32Array(nc),
    region: new Uint32Array(nc),
    firstArc: new Uint32Array(nc),
    arcCount: new Uint32Array(nc),
    firstBackArc: new Uint32Array(nc),
    backArcCount: new Uint32Array(nc),
    triangles: new Uint32Array(nc),
    colorError: new Float32Array(nc),  // mt_format.h NodeRecord::colorError (0 before version 5)
  };
  // The records are read through typed arrays over each section (a copy only when it is
  // not aligned),
  // not a DataView call per field: on a 61 k-patch index that was most of the 0.3-0.8 s the page
  // spent opening the file before its first image. Typed arrays read the platform's byte order;
  // the file is little-endian, so a big-endian platform takes the DataView path.
  const copy = (offset, bytes) => {
    const b = offset - base;
    return b % 8 === 0 ? new DataView(meta, b, bytes) : new DataView(meta.slice(b, b + bytes));  // a view when aligned
  };
  const view = (T, d) => new T(d.buffer, d.byteOffset, d.byteLength / T.BYTES_PER_ELEMENT);
  if (littleEndian) {
    const nb = copy(h.nodesOffset, nc * kNodeRecordSize);
    const f64 = view(Float64Array, nb), f32 = view(Float32Array, nb), u32 = view(Uint32Array, nb);
    for (let i = 0; i < nc; ++i) {
      const d = 10 * i, w = 20 * i;
      nodes.center[3 * i] = f64[d];
      nodes.center[3 * i + 1] = f64[d + 1];
      nodes.center[3 * i + 2] = f64[d + 2];
      nodes.radius[i] = f32[w + 6];
      nodes.error[i] = f32[w + 7];
      nodes.coneAxis[3 * i] = f32[w + 8];
      nodes.coneAxis[3 * i + 1] = f32[w + 9];
      nodes.coneAxis[3 * i + 2] = f32[w + 10];
      nodes.coneCutoff[i] = f32[w + 11];
      nodes.level[i] = u32[w + 12];
      nodes.region[i] = u32[w + 13];
      nodes.firstArc[i] = u32[w + 14];
      nodes.arcCount[i] = u32[w + 15];
      nodes.firstBackArc[i] = u32[w + 16];
      nodes.backArcCount[i] = u32[w + 17];
      nodes.triangles[i] = u32[w + 18];
      nodes.colorError[i] = f32[w + 19];
    }
  } else {
    for (let i = 0; i < nc; ++i) {
      const o = h.nodesOffset - base + i * kNodeRecordSize;
      for (let a = 0; a < 3; ++a) nodes.center[i * 3 + a] = dv.getFloat64(o + 8 * a, true);
      nodes.radius[i] = dv.getFloat32(o + 24, true);
      nodes.error[i] = dv.getFloat32(o + 28, true);
      for (let a = 0; a < 3; ++a) nodes.coneAxis[i * 3 + a] = dv.getFloat32(o + 32 + 4 * a, true);
      nodes.coneCutoff[i] = dv.getFloat32(o + 44, true);
      nodes.level[i] = dv.getUint32(o + 48, true);
      nodes.region[i] = dv.getUint32(o + 52, true);
      nodes.firstArc[i] = dv.getUint32(o + 56, true);
      nodes.arcCount[i] = dv.getUint32(o + 60, true);
      nodes.firstBackArc[i] = dv.getUint32(o + 64, true);
      nodes.backArcCount[i] = dv.getUint32(o + 68, true);
      nodes.triangles[i] = dv.getUint32(o + 72, true);
      nodes.colorError[i] = dv.getFloat32(o + 76, true);
    }
  }
  const arcs = {
    count: ac,
    from: new Uint32Array(ac),
    to: new Uint32Array(ac),
    firstPatchRef: new Uint32Array(ac),
    patchCount: new Uint32Array(ac),
  };
  let backArcs, patchRefs;
  const patches = {
    count: pc,
    offset: new Float64Array(pc),
    size: new Uint32Array(pc),
    arc: new Uint32Array(pc),
    triangles: new Uint32Array(pc),
    vertices: new Uint32Array(pc),
    checksumLo: new Uint32Array(pc),
    checksumHi: new Uint32Array(pc),
  };
  if (littleEndian) {
    const au = view(Uint32Array, copy(h.arcsOffset, ac * kArcRecordSize));
    for (let i = 0; i < ac; ++i) {
      arcs.from[i] = au[4 * i];
      arcs.to[i] = au[4 * i + 1];
      arcs.firstPatchRef[i] = au[4 * i + 2];
      arcs.patchCount[i] = au[4 * i + 3];
    }
    backArcs = view(Uint32Array, copy(h.backArcsOffset, 4 * ac)).slice();
    patchRefs = view(Uint32Array, copy(h.patchRefsOffset, 4 * h.patchRefCount)).slice();
    const pu = view(Uint32Array, copy(h.patchesOffset, pc * kPatchRecordSize));
    for (let i = 0; i < pc; ++i) {
      const w = 8 * i;
      patches.offset[i] = pu[w + 1] >= 0x200000 ? Number.POSITIVE_INFINITY : pu[w] + pu[w + 1] * 4294967296;  // as u64()
      patches.size[i] = pu[w + 2];
      patches.arc[i] = pu[w + 3];
      patches.triangles[i] = pu[w + 4];
      patches.vertices[i] = pu[w + 5];
      patches.checksumLo[i] = pu[w + 6];
      patches.checksumHi[i] = pu[w + 7];
    }
  } else {
    for (let i = 0; i < ac; ++i) {
      const o = h.arcsOffset - base + i * kArcRecordSize;
      arcs.from[i] = dv.getUint32(o, true);
      arcs.to[i] = dv.getUint32(o + 4, true);
      arcs.firstPatchRef[i] = dv.getUint32(o + 8, true);
      arcs.patchCount[i] = dv.getUint32(o + 12, true);
    }
    backArcs = new Uint32Array(ac);
    for (let i = 0; i < ac; ++i) backArcs[i] = dv.getUint32(h.backArcsOffset - base + 4 * i, true);
    patchRefs = new Uint32Array(h.patchRefCount);
    for (let i = 0; i < h.patchRefCount; ++i) patchRefs[i] = dv.getUint32(h.patchRefsOffset - base + 4 * i, true);
    for (let i = 0; i < pc; ++i) {
      const o = h.patchesOffset - base + i * kPatchRecordSize;
      patches.offset[i] = u64(dv, o);
      patches.size[i] = dv.getUint32(o + 8, true);
      patches.arc[i] = dv.getUint32(o + 12, true);
      patches.triangles[i] = dv.getUint32(o + 16, true);
      patches.vertices[i] = dv.getUint32(o + 20, true);
      patches.checksumLo[i] = dv.getUint32(o + 24, true);
      patches.checksumHi[i] = dv.getUint32(o + 28, true);
    }
  }
  // TextureRecord[patchCount] (textured files only; `textures` is null otherwise).
  let textures = null;
  if (h.vertexFlags & kHasTextures) {
    const at = h.patchesOffset + pc * kPatchRecordSize - base;
    textures = {
      count: pc,
      offset: new Float64Array(pc),
      size: new Uint32Array(pc),
      width: new Uint16Array(pc),
      height: new Uint16Array(pc),
      checksumLo: new Uint32Array(pc),
      checksumHi: new Uint32Array(pc),
      imageBytes: new Uint32Array(pc),
      reserved: new Uint32Array(pc),
    };
    for (let i = 0; i < pc; ++i) {
      const o = at + i * kTextureRecordSize;
      textures.offset[i] = u64(dv, o);
      textures.size[i] = dv.getUint32(o + 8, true);
      textures.width[i] = dv.getUint16(o + 12, true);
      textures.height[i] = dv.getUint16(o + 14, true);
      textures.checksumLo[i] = dv.getUint32(o + 16, true);
      textures.checksumHi[i] = dv.getUint32(o + 20, true);
      textures.imageBytes[i] = dv.getUint32(o + 24, true);
      textures.reserved[i] = dv.getUint32(o + 28, true);
    }
  }
  return { nodes, arcs, backArcs, patchRefs, patches, textures };
}

/**
 * MtFileReader::readIndex, last part: the metadata block's entries (uint32 length + key, uint32
 * length + value, filling the block exactly; keys unique) as a Map key -> value (UTF-8 text).
 * Empty when the file has no block. Called after the footer checksum was checked.
 * @param {ArrayBuffer} meta bytes [metaOffset, footer)
 */
export function readMetadata(path, h, meta) {
  const out = new Map();
  if (!h.metadataSize) return out;
  const begin = h.metadataOffset - h.metaOffset, end = begin + h.metadataSize;
  const dv = new DataView(meta);
  const bytes = new Uint8Array(meta);
  const utf8 = new TextDecoder('utf-8');
  let p = begin;
  const seen = new Set();
  const text = (maxLength, what) => {
    const at = h.metadataOffset + (p - begin);
    if (end - p < 4) throw new MtError(path, `metadata block: truncated ${what} length at byte offset ${at}`);
    const n = dv.getUint32(p, true);
    p += 4;
    if (n > end - p || n > maxLength || (n === 0 && maxLength === kMaxMetadataKey))
      throw new MtError(path, `metadata block: bad ${what} length ${n} at byte offset ${at}`);
    const s = bytes.subarray(p, p + n);
    p += n;
    return s;
  };
  while (p < end) {
    const key = text(kMaxMetadataKey, 'key');
    const value = text(kMaxMetadataSize, 'value');
    // Keys compared as bytes, as the C++ reader does (not after UTF-8 decoding).
    const raw = String.fromCharCode(...key);
    if (seen.has(raw)) throw new MtError(path, 'metadata block: a key appears twice');
    seen.add(raw);
    out.set(utf8.decode(key), utf8.decode(value));
  }
  return out;
}

/** MtFileReader::checkIndex: cross-checks of the records (the writer was right, not only honest). */
export function checkIndex(path, h, idx) {
  if (h.codec !== Codec.Meshopt && h.codec !== Codec.Draco) throw new MtError(path, `unknown codec ${h.codec} in header`);
  if (h.payloadAlignment === 0 || (h.payloadAlignment & (h.payloadAlignment - 1)))
    throw new MtError(path, 'bad payload alignment in header');
  if (!(h.gridStep > 0) || h.gridBits === 0 || h.gridBits > 31) throw new MtError(path, 'bad quantization grid in header');
  const { nodes, arcs, backArcs, patchRefs, patches } = idx;
  for (let i = 0; i < patches.count; ++i) {
    const off = patches.offset[i], size = patches.size[i];
    if (off < kHeaderSize || off % h.payloadAlignment || off + size > h.metaOffset)
      throw new MtError(path, `patch ${i}: payload at byte offset ${off} size ${size} outside the payload area`);
    if (patches.arc[i] >= h.arcCount) throw new MtError(path, `patch ${i}: arc ${patches.arc[i]} out of range`);
  }
  const t = idx.textures;
  for (let i = 0; t && i < t.count; ++i) {
    // A texture payload lies after its patch's payload and before the next one (or the index).
    const next = i + 1 < patches.count ? patches.offset[i + 1] : h.metaOffset;
    const empty = t.size[i] === 0 && t.offset[i] === 0 && t.width[i] === 0 && t.height[i] === 0 && t.imageBytes[i] === 0 &&
      t.checksumLo[i] === 0 && t.checksumHi[i] === 0;
    if (t.reserved[i] !== 0 ||
        (!empty && (t.size[i] === 0 || t.offset[i] < patches.offset[i] + patches.size[i] || t.offset[i] % h.payloadAlignment ||
                    t.offset[i] + t.size[i] > next || t.width[i] === 0 || t.height[i] === 0 || t.width[i] > kMaxAtlasSide ||
                    t.height[i] > kMaxAtlasSide || t.imageBytes[i] > t.size[i])))
      throw new MtError(path, `texture of patch ${i}: record (payload at byte offset ${t.offset[i]} size ${t.size[i]}) is damaged or outside its place`);
  }
  for (let i = 0; i < arcs.count; ++i) {
    if (arcs.from[i] >= h.nodeCount || arcs.to[i] >= h.nodeCount || arcs.firstPatchRef[i] + arcs.patchCount[i] > h.patchRefCount)
      throw new MtError(path, `arc ${i} out of range`);
    for (let k = 0; k < arcs.patchCount[i]; ++k)
      if (patchRefs[arcs.firstPatchRef[i] + k] >= h.patchCount) throw new MtError(path, `arc ${i} names patch out of range`);
  }
  for (const b of backArcs) if (b >= h.arcCount) throw new MtError(path, 'backward star names arc out of range');
  for (let i = 0; i < nodes.count; ++i) {
    if (nodes.firstArc[i] + nodes.arcCount[i] > h.arcCount || nodes.firstBackArc[i] + nodes.backArcCount[i] > h.arcCount)
      throw new MtError(path, `node ${i}: arc range out of bounds`);
    for (let k = 0; k < nodes.arcCount[i]; ++k)
      if (arcs.from[nodes.firstArc[i] + k] !== i) throw new MtError(path, `node ${i}: forward star inconsistent`);
    for (let k = 0; k < nodes.backArcCount[i]; ++k)
      if (arcs.to[backArcs[nodes.firstBackArc[i] + k]] !== i) throw new MtError(path, `node ${i}: backward star inconsistent`);
  }
}
