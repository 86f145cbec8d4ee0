// Validates what the interop library writes. Arguments: .glb/.gltf files and tileset directories.
//  - every glTF (and every tile content) with the Khronos glTF-Validator: any error or warning fails;
//  - every tileset.json against the 3D Tiles 1.1 rules we rely on (the npm registry has no
//    3d-tiles-validator package): asset.version "1.1", geometricError >= 0 and never above the
//    parent's, refine REPLACE/ADD, a bounding volume per tile, every child's sphere inside its
//    parent's (same frame), every content uri an existing file.
// The validator cannot look inside EXT_meshopt_compression (it says so as an info): such a file is
// also decoded (meshoptimizer's JS decoder) into a plain GLB, which must validate clean too.
// Prints one line per file; exit 1 on any problem.
import fs from 'node:fs';
import path from 'node:path';
import validator from 'gltf-validator';
import { MeshoptDecoder } from 'meshoptimizer';

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

async function validateGltf(file) {
  await validateBytes(file, new Uint8Array(fs.readFileSync(file)));
  const { json } = load(file);
  if ((json.extensionsUsed || []).includes('EXT_meshopt_compression'))
    await validateBytes(`${file} (meshopt decoded)`, await decodeMeshopt(file));
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
