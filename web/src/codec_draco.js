// Codec::Draco, the decoder half of mtfile/patch_codec_draco.cpp: a Draco mesh buffer after the
// payload header, POSITION as 3 x INT32 grid coordinates (qRel), GENERIC 2 x UINT8 octahedral
// normals and COLOR 4 x UINT8 when flagged. libs.draco is an instantiated Draco decoder module
// (DracoDecoderModule). Draco may split non-manifold vertices: more vertices than vertexCount.

import { kPayloadHeaderSize, kPayloadNormals, kPayloadColors } from './format.js';
import { bad, decodeOctahedral8 } from './codec_meshopt.js';

export function decodeDraco(data, h, libs, out) {
  const draco = libs.draco;
  if (!draco) bad('this file uses the Draco codec and no Draco decoder is loaded');
  const decoder = new draco.Decoder();
  const mesh = new draco.Mesh();
  const body = data.subarray(kPayloadHeaderSize);
  try {
    const status = decoder.DecodeArrayToMesh(body, body.length, mesh);
    if (!status.ok() || mesh.ptr === 0) bad(`Draco: ${status.error_msg()}`);
    const nf = mesh.num_faces(), nv = mesh.num_points();
    if (nf !== h.triangleCount) bad('triangle count mismatch');
    const triangles = new Uint32Array(nf * 3);
    const ptr = draco._malloc(nf * 12);
    decoder.GetTrianglesUInt32Array(mesh, nf * 12, ptr);
    triangles.set(new Uint32Array(draco.HEAPU32.buffer, ptr, nf * 3));
    draco._free(ptr);
    out.triangles = triangles;
    const attr = (type) => {
      const id = decoder.GetAttributeId(mesh, type);
      return id < 0 ? null : decoder.GetAttribute(mesh, id);
    };
    const readAttr = (a, comps, Typed, dataType) => {
      const bytes = nv * comps * Typed.BYTES_PER_ELEMENT;
      const p = draco._malloc(bytes);
      decoder.GetAttributeDataArrayForAllPoints(mesh, a, dataType, bytes, p);
      const outArr = new Typed(nv * comps);
      outArr.set(new Typed(draco.HEAPU8.buffer, p, nv * comps));
      draco._free(p);
      return outArr;
    };
    const pos = attr(draco.POSITION);
    if (!pos || pos.num_components() !== 3) bad('Draco: no 3-component position attribute');
    const qi = readAttr(pos, 3, Int32Array, draco.DT_INT32);
    const qRel = new Uint32Array(nv * 3);
    for (let i = 0; i < nv * 3; ++i) {
      if (qi[i] < 0) bad('Draco: negative grid coordinate');
      qRel[i] = qi[i];
    }
    if (h.flags & kPayloadNormals) {
      const g = attr(draco.GENERIC);
      if (!g) bad('Draco: normals flagged but absent');
      const oct = readAttr(g, 2, Uint8Array, draco.DT_UINT8);
      out.normals = new Float32Array(nv * 3);
      for (let v = 0; v < nv; ++v) decodeOctahedral8(oct[2 * v], oct[2 * v + 1], out.normals, 3 * v);
    }
    if (h.flags & kPayloadColors) {
      const c = attr(draco.COLOR);
      if (!c) bad('Draco: colours flagged but absent');
      out.colors = readAttr(c, 4, Uint8Array, draco.DT_UINT8);
    }
    return qRel;
  } finally {
    draco.destroy(mesh);
    draco.destroy(decoder);
  }
}
