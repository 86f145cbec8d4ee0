// Validates what the interop library writes. Arguments: .glb/.gltf files and tileset directories.
//  - every glTF (and every tile content) with the Khronos glTF-Validator: any error or warning fails;
//  - every tileset.json against the 3D Tiles 1.1 rules we rely on (the npm registry has no
//    3d-tiles-validator package): asset.version "1.1", geometricError >= 0 and never above the
//    parent's, refine REPLACE/ADD, a bounding volume per tile, every child's sphere inside its
//    parent's (same frame), every content uri an existing file.
// The validator cannot look inside EXT_meshopt_compression nor KHR_draco_mesh_compression (it says
// so as an info): such a file is also decoded (meshoptimizer's and Draco's own JS decoders) into a
// plain GLB, which must validate clean too.
// Prints one line per file; exit 1 on any problem.
import fs from 'node:fs';
import path from 'node:path';
import validator from 'gltf-validator';
import { MeshoptDecoder } from 'meshoptimizer';
import draco3d from 'draco3d';

let problems = 0;
const complain = (msg) => { console.error(msg); problems++; };

// GLB or .gltf -> { json, bin } (bin: buffer 0's bytes).
function load(file) {
  const data = fs.readFileSync(file);
  if (data.readUInt32LE(0) === 0x46546c67) {
    const jsonLength = data.readUInt32LE(12);
    const json = JSON.parse(data.subarray(20, 20 + jsonLength).toString('utf8'));
    const at = 20 + jsonLength;
    const bin = at < data.length ? data.subarray(at + 8, at + 8 + data.readUInt32LE(at)) : Buffer.alloc(0);
    return { json, bin };
  }
  const json = JSON.parse(data.toString('utf8'));
  return { json, bin: fs.readFileSync(path.join(path.dirname(file), json.buffers[0].uri)) };
}

// The same document with every meshopt-compressed view decoded, as a GLB.
async function decodeMeshopt(file) {
  await MeshoptDecoder.ready;
  const { json, bin } = load(file);
  const parts = [];
  let size = 0;
  json.bufferViews = json.bufferViews.map((v) => {
    const e = v.extensions && v.extensions.EXT_meshopt_compression;
    let bytes;
    if (e) {
      bytes = new Uint8Array(Math.max(e.count * e.byteStride, v.byteLength));
      const src = new Uint8Array(bin.buffer, bin.byteOffset + (e.byteOffset || 0), e.byteLength);
      MeshoptDecoder.decodeGltfBuffer(bytes, e.count, e.byteStride, src, e.mode, e.filter || 'NONE');
    } else {
      bytes = new Uint8Array(bin.buffer, bin.byteOffset + (v.byteOffset || 0), v.byteLength);
    }
    const nv = { ...v, buffer: 0, byteOffset: size, byteLength: v.byteLength };
    delete nv.extensions;
    parts.push(bytes.subarray(0, v.byteLength));
    size += v.byteLength;
    while (size % 4) { parts.push(new Uint8Array(1)); size++; }
    return nv;
  });
  const out = Buffer.concat(parts.map((p) => Buffer.from(p.buffer, p.byteOffset, p.byteLength)));
  json.buffers = [{ byteLength: out.length }];
  const drop = (list) => (list || []).filter((x) => x !== 'EXT_meshopt_compression');
  json.extensionsUsed = drop(json.extensionsUsed);
  json.extensionsRequired = drop(json.extensionsRequired);
  if (!json.extensionsUsed.length) delete json.extensionsUsed;
  if (!json.extensionsRequired.length) delete json.extensionsRequired;
  let text = Buffer.from(JSON.stringify(json));
  text = Buffer.concat([text, Buffer.alloc((4 - (text.length % 4)) % 4, 0x20)]);
  const header = Buffer.alloc(20);
  header.writeUInt32LE(0x46546c67, 0); header.writeUInt32LE(2, 4);
  header.writeUInt32LE(12 + 8 + text.length + 8 + out.length, 8);
  header.writeUInt32LE(text.length, 12); header.writeUInt32LE(0x4e4f534a, 16);
  const binHeader = Buffer.alloc(8);
  binHeader.writeUInt32LE(out.length, 0); binHeader.writeUInt32LE(0x004e4942, 4);
  return new Uint8Array(Buffer.concat([header, text, binHeader, out]));
}

// A GLB of a document and its buffer 0.
function glbOf(json, out) {
  let text = Buffer.from(JSON.stringify(json));
  text = Buffer.concat([text, Buffer.alloc((4 - (text.length % 4)) % 4, 0x20)]);
  const header = Buffer.alloc(20);
  header.writeUInt32LE(0x46546c67, 0); header.writeUInt32LE(2, 4);
  header.writeUInt32LE(12 + 8 + text.length + 8 + out.length, 8);
  header.writeUInt32LE(text.length, 12); header.writeUInt32LE(0x4e4f534a, 16);
  const binHeader = Buffer.alloc(8);
  binHeader.writeUInt32LE(out.length, 0); binHeader.writeUInt32LE(0x004e4942, 4);
  return new Uint8Array(Buffer.concat([header, text, binHeader, out]));
}

// The same document with every Draco primitive decoded into plain buffer views (vertex strides
// padded to 4 bytes), as a GLB. The decoded counts must be the accessors' counts.
let dracoModule = null;
async function decodeDraco(file) {
  dracoModule ||= await draco3d.createDecoderModule({});
  const D = dracoModule;
  const { json, bin } = load(file);
  const parts = [];
  let size = 0;
  const views = [];
  const push = (bytes, stride, target) => {
    while (size % 4) { parts.push(Buffer.alloc(1)); size++; }
    const v = { buffer: 0, byteOffset: size, byteLength: bytes.byteLength, target };
    if (stride) v.byteStride = stride;
    parts.push(Buffer.from(bytes.buffer, bytes.byteOffset, bytes.byteLength)); size += bytes.byteLength;
    views.push(v);
    return views.length - 1;
  };
  for (const mesh of json.meshes) for (const prim of mesh.primitives) {
    const ext = prim.extensions && prim.extensions.KHR_draco_mesh_compression;
    if (!ext) continue;
    const v = json.bufferViews[ext.bufferView];
    const src = new Uint8Array(bin.buffer, bin.byteOffset + (v.byteOffset || 0), v.byteLength);
    const decoder = new D.Decoder();
    const buffer = new D.DecoderBuffer();
    buffer.Init(new Int8Array(src.buffer, src.byteOffset, src.byteLength), src.byteLength);
    const dm = new D.Mesh();
    const status = decoder.DecodeBufferToMesh(buffer, dm);
    if (!status.ok()) throw new Error(`${file}: Draco cannot decode: ${status.error_msg()}`);
    const points = dm.num_points(), faces = dm.num_faces();
    for (const [name, id] of Object.entries(ext.attributes)) {
      const acc = json.accessors[prim.attributes[name]];
      if (acc.count !== points) complain(`${file}: ${name} accessor count ${acc.count}, Draco decodes ${points} points`);
      const att = decoder.GetAttributeByUniqueId(dm, id);
      const comps = att.num_components();
      const kinds = { 5126: [Float32Array, D.DT_FLOAT32, 4], 5123: [Uint16Array, D.DT_UINT16, 2], 5121: [Uint8Array, D.DT_UINT8, 1],
        5122: [Int16Array, D.DT_INT16, 2], 5120: [Int8Array, D.DT_INT8, 1] };
      const [Type, dt, bytesPer] = kinds[acc.componentType];
      const n = points * comps, ptr = D._malloc(n * bytesPer);
      decoder.GetAttributeDataArrayForAllPoints(dm, att, dt, n * bytesPer, ptr);
      const values = new Type(D.HEAPU8.buffer.slice(ptr, ptr + n * bytesPer));
      D._free(ptr);
      const stride = Math.ceil((comps * bytesPer) / 4) * 4;
      const out = new Uint8Array(points * stride);
      const raw = new Uint8Array(values.buffer);
      for (let i = 0; i < points; ++i) out.set(raw.subarray(i * comps * bytesPer, (i + 1) * comps * bytesPer), i * stride);
      acc.bufferView = push(out, stride, 34962);
    }
    const ia = json.accessors[prim.indices];
    if (ia.count !== 3 * faces) complain(`${file}: indices accessor count ${ia.count}, Draco decodes ${faces} faces`);
    const idx = new Uint32Array(3 * faces);
    const ptr = D._malloc(idx.byteLength);
    decoder.GetTrianglesUInt32Array(dm, idx.byteLength, ptr);
    idx.set(new Uint32Array(D.HEAPU8.buffer.slice(ptr, ptr + idx.byteLength)));
    D._free(ptr);
    ia.bufferView = push(ia.componentType === 5123 ? Uint16Array.from(idx) : idx, 0, 34963);
    delete prim.extensions.KHR_draco_mesh_compression;
    if (!Object.keys(prim.extensions).length) delete prim.extensions;
    D.destroy(dm); D.destroy(buffer); D.destroy(decoder);
  }
  json.bufferViews = views;
  while (size % 4) { parts.push(Buffer.alloc(1)); size++; }
  const out = Buffer.concat(parts);
  json.buffers = [{ byteLength: out.length }];
  const drop = (list) => (list || []).filter((x) => x !== 'KHR_draco_mesh_compression');
  json.extensionsUsed = drop(json.extensionsUsed);
  json.extensionsRequired = drop(json.extensionsRequired);
  if (!json.extensionsUsed.length) delete json.extensionsUsed;
  if (!json.extensionsRequired.length) delete json.extensionsRequired;
  return glbOf(json, out);
}

async function validateGltf(file) {
  await validateBytes(file, new Uint8Array(fs.readFileSync(file)));
  const { json } = load(file);
  if ((json.extensionsUsed || []).includes('EXT_meshopt_compression'))
    await validateBytes(`${file} (meshopt decoded)`, await decodeMeshopt(file));
  if ((json.extensionsUsed || []).includes('KHR_draco_mesh_compression'))
    await validateBytes(`${file} (Draco decoded)`, await decodeDraco(file));
}

async function validateBytes(file, data) {
  const report = await validator.validateBytes(data, {
    uri: path.basename(file.split(' ')[0]),
    maxIssues: 50,
    externalResourceFunction: (uri) =>
      new Promise((resolve, reject) => {
        try { resolve(new Uint8Array(fs.readFileSync(path.join(path.dirname(file.split(' ')[0]), decodeURIComponent(uri))))); }
        catch (e) { reject(e.toString()); }
      }),
  });
  const i = report.issues;
  const bad = i.messages.filter((m) => m.severity <= 1);
  console.log(`${file}: glTF-Validator ${report.validatorVersion}: ${i.numErrors} errors, ${i.numWarnings} warnings, ${i.numInfos} infos, ${i.numHints} hints`);
  for (const m of bad) complain(`${file}: ${m.severity === 0 ? 'error' : 'warning'} ${m.code} at ${m.pointer || '-'}: ${m.message}`);
  if (i.numErrors + i.numWarnings > 0 && bad.length === 0) complain(`${file}: ${i.numErrors} errors, ${i.numWarnings} warnings`);
}

function sphereOf(tile, where) {
  const bv = tile.boundingVolume;
  if (!bv || (!bv.sphere && !bv.box && !bv.region)) { complain(`${where}: no boundingVolume`); return null; }
  if (bv.sphere && (bv.sphere.length !== 4 || bv.sphere[3] < 0)) { complain(`${where}: bad sphere`); return null; }
  return bv.sphere || null;
}

async function validateTileset(dir) {
  const file = path.join(dir, 'tileset.json');
  const ts = JSON.parse(fs.readFileSync(file, 'utf8'));
  if (!ts.asset || ts.asset.version !== '1.1') complain(`${file}: asset.version is not "1.1"`);
  if (!(ts.geometricError >= 0)) complain(`${file}: no geometricError`);
  if (!ts.root) { complain(`${file}: no root`); return; }
  if (!['REPLACE', 'ADD'].includes(ts.root.refine)) complain(`${file}: root.refine is not REPLACE or ADD`);
  const contents = new Set();
  let tiles = 0, depth = 0;
  const walk = (tile, parent, parentSphere, where, d) => {
    tiles++; depth = Math.max(depth, d);
    if (!(tile.geometricError >= 0)) complain(`${where}: geometricError missing or negative`);
    if (parent && tile.geometricError > parent.geometricError) complain(`${where}: geometricError ${tile.geometricError} above its parent's ${parent.geometricError}`);
    if (tile.refine && !['REPLACE', 'ADD'].includes(tile.refine)) complain(`${where}: bad refine`);
    if (tile.transform && (tile.transform.length !== 16 || tile.transform.some((x) => !Number.isFinite(x)))) complain(`${where}: bad transform`);
    const s = sphereOf(tile, where);
    if (s && parentSphere && !tile.transform) {
      const dist = Math.hypot(s[0] - parentSphere[0], s[1] - parentSphere[1], s[2] - parentSphere[2]);
      if (dist + s[3] > parentSphere[3] * (1 + 1e-9) + 1e-9) complain(`${where}: sphere not inside its parent's (${dist + s[3]} > ${parentSphere[3]})`);
    }
    if (tile.content) {
      const uri = tile.content.uri;
      if (!uri || !fs.existsSync(path.join(dir, uri))) complain(`${where}: content ${uri} does not exist`);
      else contents.add(uri);
    }
    (tile.children || []).forEach((c, k) => walk(c, tile, s, `${where}/children/${k}`, d + 1));
  };
  walk(ts.root, null, null, `${file}#/root`, 0);
  console.log(`${file}: ${tiles} tiles, depth ${depth}, ${contents.size} contents`);
  for (const uri of [...contents].sort()) await validateGltf(path.join(dir, uri));
}

const args = process.argv.slice(2);
if (args.length === 0) { console.error('usage: node validate.mjs FILE.glb|FILE.gltf|TILESET_DIR...'); process.exit(2); }
for (const a of args) {
  try {
    if (fs.statSync(a).isDirectory()) await validateTileset(a);
    else await validateGltf(a);
  } catch (e) { complain(`${a}: ${e}`); }
}
if (problems) { console.error(`validate: ${problems} problems`); process.exit(1); }
console.log('validate: no error, no warning');
