// The DAG in RAM, as the cut walks it: a port of mtrender/scene.cpp for one MT file (the arcs'
// triangle counts, in/out triangles per node, the node whose sphere and cone bound each arc).
// Node centres are kept as float32 values, as Scene does, so screen errors match ExtractRender's.

import { texturedBytesBound } from './texture.js';

/**
 * @param {object} header parsed FileHeader (format.js)
 * @param {object} idx records from readIndex (format.js)
 */
export function buildScene(header, idx) {
  const { nodes: rn, arcs: ra, backArcs, patchRefs, patches: rp, textures } = idx;
  const nc = rn.count, ac = ra.count;
  const nodes = {
    count: nc,
    center: new Float64Array(nc * 3),  // float32-rounded
    radius: rn.radius,
    error: new Float64Array(nc),
    coneAxis: rn.coneAxis,
    coneCutoff: rn.coneCutoff,
    level: rn.level,
    firstArc: rn.firstArc,
    arcCount: rn.arcCount,
    firstInArc: rn.firstBackArc,
    inArcCount: rn.backArcCount,
    outTriangles: new Float64Array(nc),
    inTriangles: new Float64Array(nc),
    source: new Uint8Array(nc),
    sink: new Uint8Array(nc),
  };
  for (let i = 0; i < nc * 3; ++i) nodes.center[i] = Math.fround(rn.center[i]);
  for (let i = 0; i < nc; ++i) {
    nodes.error[i] = rn.error[i];
    nodes.source[i] = i === 0 ? 1 : 0;
    nodes.sink[i] = i + 1 === nc ? 1 : 0;
  }
  if (nc) nodes.error[nc - 1] = Number.POSITIVE_INFINITY;
  const arcs = {
    count: ac,
    from: ra.from,
    to: ra.to,
    firstPatch: ra.firstPatchRef,
    patchCount: ra.patchCount,
    triangles: new Float64Array(ac),
    cullNode: new Uint32Array(ac),
  };
  for (let a = 0; a < ac; ++a) {
    let t = 0;
    for (let k = 0; k < ra.patchCount[a]; ++k) t += rp.triangles[patchRefs[ra.firstPatchRef[a] + k]];
    arcs.triangles[a] = t;
    // The source's sphere has radius 0; its patches lie in `to`'s floor, which `to`'s sphere encloses.
    arcs.cullNode[a] = ra.from[a] === 0 ? ra.to[a] : ra.from[a];
  }
  for (let n = 0; n < nc; ++n) {
    let o = 0, i = 0;
    for (let k = 0; k < nodes.arcCount[n]; ++k) o += arcs.triangles[nodes.firstArc[n] + k];
    for (let k = 0; k < nodes.inArcCount[n]; ++k) i += arcs.triangles[backArcs[nodes.firstInArc[n] + k]];
    nodes.outTriangles[n] = o;
    nodes.inTriangles[n] = i;
  }
  // Decoded size of a patch in the renderer's layout (Scene::decodedBytesBound): 20 bytes a vertex
  // (position 12, normal 4, colour 4), 12 a triangle; Draco may split non-manifold vertices, a
  // quarter more.
  const decodedBytes = new Float64Array(rp.count);
  for (let p = 0; p < rp.count; ++p) {
    let v = rp.vertices[p];
    if (header.codec === 2) v = Math.min(3 * rp.triangles[p], v + Math.floor(v / 4) + 64);
    decodedBytes[p] = v * 20 + rp.triangles[p] * 12;
    // A textured patch (version 6): its split vertices, coordinates and RGBA8 atlas (texture.js).
    if (textures && textures.size[p]) decodedBytes[p] = texturedBytesBound(rp.triangles[p], textures.width[p], textures.height[p]);
  }
  // Where a patch's read ends: its texture payload follows its geometry (one range read for both).
  const loadEnd = new Float64Array(rp.count);
  for (let p = 0; p < rp.count; ++p)
    loadEnd[p] = textures && textures.size[p] ? textures.offset[p] + textures.size[p] : rp.offset[p] + rp.size[p];
  const c = [0, 0, 0];
  let d2 = 0;
  for (let a = 0; a < 3; ++a) {
    c[a] = 0.5 * (header.boundsMin[a] + header.boundsMax[a]);
    d2 += (header.boundsMax[a] - c[a]) * (header.boundsMax[a] - c[a]);
  }
  return {
    header,
    nodes,
    arcs,
    inArcs: backArcs,
    arcPatches: patchRefs,
    patches: rp,
    decodedBytes,
    loadEnd,
    textures,  // TextureRecord arrays (format.js readIndex), null for a file without textures
    center: c,
    radius: Math.max(Math.sqrt(d2), 1e-9),
    hasColors: (header.vertexFlags & 2) !== 0,
    hasTextures: textures !== null,
  };
}
