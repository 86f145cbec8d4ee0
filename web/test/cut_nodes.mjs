// node cut_nodes.mjs FILE.mt VIEWS TOLERANCE WIDTH HEIGHT: the web module's converged cut for each
// view, printed exactly as tests/web_cut_nodes.cpp prints ExtractRender's (see there).
import fs from 'node:fs';
import { FileSource } from '../src/source.js';
import { openMtFile } from '../src/mtfile.js';
import { makeView } from '../src/camera.js';
import { ExtractRender } from '../src/extract.js';

const [file, viewsPath, tol, w, h] = process.argv.slice(2);
if (!h) {
  console.error('usage: node cut_nodes.mjs FILE.mt VIEWS TOLERANCE WIDTH HEIGHT');
  process.exit(2);
}
try {
  const scene = await openMtFile(new FileSource(file, fs));
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
