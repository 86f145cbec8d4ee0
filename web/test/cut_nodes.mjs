// node cut_nodes.mjs FILE.mt VIEWS TOLERANCE WIDTH HEIGHT: the web module's converged cut for each
// view, printed exactly as tests/web_cut_nodes.cpp prints ExtractRender's (see there).
import fs from 'node:fs';
import { FileSource } from '../src/source.js';
import { openMtFile } from '../src/mtfile.js';
import { makeView } from '../src/camera.js';
import { ExtractRender } from '../src/extract.js';
import { decodePatch } from '../src/patch_codec.js';
import { ClosedSurface, coarsestArcs, weldParts } from '../src/closed_surface.js';
import { decompress } from 'fzstd';
import { MeshoptDecoder } from 'meshoptimizer/decoder';

// The coarsest cut decoded in node (the page decodes it in its workers), welded, as the surface
// that says when normal cones may cull (closed_surface.js), as mtrender's Scene reads it at open.
async function coarsestSurface(scene) {
  await MeshoptDecoder.ready;
  let draco = null;
  if (scene.header.codec === 2) {
    const draco3d = (await import('draco3d')).default;
    draco = await draco3d.createDecoderModule({});
  }
  const libs = { zstd: (b, n) => decompress(b, new Uint8Array(n)), meshopt: MeshoptDecoder, draco };
  const { arcs: list, margin } = coarsestArcs(scene);
  const o = scene.header.gridOrigin, st = scene.header.gridStep, p = scene.patches, parts = [];
  for (const a of list)
    for (let k = 0; k < scene.arcs.patchCount[a]; ++k) {
      const id = scene.arcPatches[scene.arcs.firstPatch[a] + k];
      const data = new Uint8Array(await scene.source.read(p.offset[id], p.offset[id] + p.size[id]));
      const d = decodePatch(data, scene.header.codec, { bits: scene.header.gridBits }, libs);
      const positions = new Float64Array(d.q.length);
      for (let i = 0; i < d.q.length; ++i) positions[i] = o[i % 3] + st * d.q[i];
      parts.push({ positions, triangles: d.triangles });
    }
  const m = weldParts(parts);
  return new ClosedSurface(m.positions, m.triangles, margin);
}

const [file, viewsPath, tol, w, h] = process.argv.slice(2);
if (!h) {
  console.error('usage: node cut_nodes.mjs FILE.mt VIEWS TOLERANCE WIDTH HEIGHT');
  process.exit(2);
}
try {
  const scene = await openMtFile(new FileSource(file, fs));
  const surface = await coarsestSurface(scene);
  console.error(`cut_nodes: ${file}: coarsest cut ${surface.tri.length / 3} triangles, closed ${surface.closed}`);
  const { center: c, radius: r } = scene;
  const lines = fs.readFileSync(viewsPath, 'utf8').split('\n');
  let k = 0;
  for (const line of lines) {
    const v = line.trim().split(/\s+/).filter((s) => s.length).map(Number);
    if (v.length === 0) continue;
    if (v.length !== 6 || v.some((x) => !Number.isFinite(x))) throw new Error(`${viewsPath}: line ${k + 1}: expected 6 numbers`);
    const pose = {
      eye: [c[0] + r * v[0], c[1] + r * v[1], c[2] + r * v[2]],
      target: [c[0] + r * v[3], c[1] + r * v[4], c[2] + r * v[5]],
      up: [0, 0, 1],
      fovDeg: 45,
    };
    const view = makeView(pose, Number(w), Number(h), c, r);
    const er = new ExtractRender(scene, null, null, { pixelTolerance: Number(tol), fixedTriangles: 2 ** 60, extractMs: 1e9, prefetch: false });
    er.setSurface(surface);
    er.start();
    for (let frame = 1; frame < 100000; ++frame) {
      const st = er.update(frame, view, view);
      if (st.refinements === 0 && st.coarsenings === 0) break;
    }
    console.log(`view ${k}:` + er.nodeSet().map((n) => ` ${n}`).join(''));
    ++k;
  }
} catch (e) {
  console.error(`cut_nodes: ${e.message}`);
  process.exit(1);
}
