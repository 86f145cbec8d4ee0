// node sphere_ply.mjs OUT.ply ROWS [HOLES]: a smooth unit sphere (latitude-longitude grid of ROWS x
// 2 ROWS quads, poles closed by fans, outward winding) as ASCII PLY, with HOLES round holes cut out
// (quads whose centre lies within 0.25 rad of a hole centre). Smooth, so the MT's node normal cones
// are narrow and cone culling matters (mtgen's noisy surfaces give cones too wide to cull):
// tests/web_cut_compare.sh uses it to compare the cone rule of the two implementations.
import fs from 'node:fs';

const [out, rowsText, holesText] = process.argv.slice(2);
const rows = Number(rowsText), cols = 2 * rows, holes = Number(holesText || 0);
if (!out || !(rows >= 4)) {
  console.error('usage: node sphere_ply.mjs OUT.ply ROWS [HOLES]');
  process.exit(2);
}
const dir = (t, p) => [Math.sin(t) * Math.cos(p), Math.sin(t) * Math.sin(p), Math.cos(t)];
const verts = [dir(0, 0)];
for (let i = 1; i < rows; ++i) for (let j = 0; j < cols; ++j) verts.push(dir((Math.PI * i) / rows, (2 * Math.PI * j) / cols));
verts.push(dir(Math.PI, 0));
const south = verts.length - 1;
const v = (i, j) => 1 + (i - 1) * cols + (j % cols);  // ring i in 1..rows-1
// Hole centres spread over the sphere, away from the poles.
const centres = [];
for (let h = 0; h < holes; ++h) centres.push(dir(0.6 + (1.9 * (h + 0.5)) / holes, 2.4 * h + 0.3));
const inHole = (ids) => {
  const c = [0, 0, 0];
  for (const id of ids) for (let a = 0; a < 3; ++a) c[a] += verts[id][a] / ids.length;
  const n = Math.hypot(...c);
  return centres.some((h) => Math.acos(Math.min(1, (c[0] * h[0] + c[1] * h[1] + c[2] * h[2]) / n)) < 0.25);
};
const tris = [];
const add = (a, b, c) => { if (!inHole([a, b, c])) tris.push([a, b, c]); };
for (let j = 0; j < cols; ++j) add(0, v(1, j), v(1, j + 1));
for (let i = 1; i < rows - 1; ++i)
  for (let j = 0; j < cols; ++j) {
    const q = [v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)];
    if (inHole(q)) continue;
    tris.push([q[0], q[1], q[2]], [q[0], q[2], q[3]]);
  }
for (let j = 0; j < cols; ++j) add(south, v(rows - 1, j + 1), v(rows - 1, j));
const lines = ['ply', 'format ascii 1.0', `element vertex ${verts.length}`, 'property float x', 'property float y', 'property float z',
  `element face ${tris.length}`, 'property list uchar int vertex_indices', 'end_header'];
for (const p of verts) lines.push(p.map((x) => x.toFixed(7)).join(' '));
for (const t of tris) lines.push(`3 ${t.join(' ')}`);
fs.writeFileSync(out, lines.join('\n') + '\n');
