// When normal-cone culling cannot change the image: mtrender/closed_surface.cpp, rule for rule.
// Both sides of every triangle are drawn and lit, so the inside of a scan shows through its holes;
// the cones may cull only a closed, consistently and outward oriented surface (every directed
// edge once, its reverse once, positive volume) seen from outside the solid it bounds, farther
// than the coarsest cut's largest node error from it. The surface is the file's coarsest cut
// (its borders are the input's: a hole never closes), welded by grid position.

/**
 * Welds decoded patches by position (exact: equal grid coordinates give equal positions) and drops
 * triangles with two corners at one point, as mtfile's assembleCut does.
 * @param {{positions:ArrayLike<number>, triangles:ArrayLike<number>}[]} parts positions 3 a vertex
 * @returns {{positions:number[], triangles:number[]}}
 */
export function weldParts(parts) {
  const index = new Map();
  const positions = [], triangles = [];
  for (const part of parts) {
    const local = new Uint32Array(part.positions.length / 3);
    for (let v = 0; v < local.length; ++v) {
      const x = part.positions[3 * v], y = part.positions[3 * v + 1], z = part.positions[3 * v + 2];
      const key = `${x},${y},${z}`;
      let id = index.get(key);
      if (id === undefined) {
        id = positions.length / 3;
        index.set(key, id);
        positions.push(x, y, z);
      }
      local[v] = id;
    }
    const t = part.triangles;
    for (let i = 0; i < t.length; i += 3) {
      const a = local[t[i]], b = local[t[i + 1]], c = local[t[i + 2]];
      if (a === b || b === c || c === a) continue;
      triangles.push(a, b, c);
    }
  }
  return { positions, triangles };
}

function closestOnTriangle(p, a, b, c) {
  const sub = (u, v) => [u[0] - v[0], u[1] - v[1], u[2] - v[2]];
  const dot = (u, v) => u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
  const axpy = (u, v, s) => [u[0] + v[0] * s, u[1] + v[1] * s, u[2] + v[2] * s];
  const ab = sub(b, a), ac = sub(c, a), ap = sub(p, a);
  const d1 = dot(ab, ap), d2 = dot(ac, ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const bp = sub(p, b);
  const d3 = dot(ab, bp), d4 = dot(ac, bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return axpy(a, ab, d1 / (d1 - d3));
  const cp = sub(p, c);
  const d5 = dot(ab, cp), d6 = dot(ac, cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return axpy(a, ac, d2 / (d2 - d6));
  const va = d3 * d6 - d5 * d4;
  if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0) return axpy(b, sub(c, b), (d4 - d3) / (d4 - d3 + (d5 - d6)));
  const denom = 1 / (va + vb + vc);
  return axpy(axpy(a, ab, vb * denom), ac, vc * denom);
}

const kDirs = [[0.8017837, 0.5345225, 0.2672612], [-0.3015113, 0.9045340, -0.3015113], [0.2357023, -0.2357023, -0.9428090]];

export class ClosedSurface {
  /** @param {ArrayLike<number>} positions @param {ArrayLike<number>} triangles @param {number} margin */
  constructor(positions, triangles, margin) {
    this.pos = Float64Array.from(positions);
    this.tri = Uint32Array.from(triangles);
    this.margin = margin;
    this.closed = false;
    this.boxMin = [0, 0, 0];
    this.boxMax = [0, 0, 0];
    const nv = this.pos.length / 3, nt = this.tri.length / 3;
    if (nt === 0) return;
    for (let a = 0; a < 3; ++a) this.boxMin[a] = this.boxMax[a] = this.pos[a];
    for (let v = 0; v < nv; ++v)
      for (let a = 0; a < 3; ++a) {
        this.boxMin[a] = Math.min(this.boxMin[a], this.pos[3 * v + a]);
        this.boxMax[a] = Math.max(this.boxMax[a], this.pos[3 * v + a]);
      }
    // Every directed edge once, and its reverse once.
    const edges = new Set();
    for (let t = 0; t < nt; ++t)
      for (let k = 0; k < 3; ++k) {
        const e = this.tri[3 * t + k] * 4294967296 + this.tri[3 * t + ((k + 1) % 3)];
        if (edges.has(e)) return;
        edges.add(e);
      }
    for (const e of edges) {
      const a = Math.floor(e / 4294967296), b = e % 4294967296;
      if (!edges.has(b * 4294967296 + a)) return;
    }
    const o = [0, 1, 2].map((a) => (this.boxMin[a] + this.boxMax[a]) / 2);
    let volume = 0;
    for (let t = 0; t < nt; ++t) {
      const [a, b, c] = [0, 1, 2].map((k) => this.vertex(this.tri[3 * t + k]).map((x, i) => x - o[i]));
      volume += a[0] * (b[1] * c[2] - b[2] * c[1]) + a[1] * (b[2] * c[0] - b[0] * c[2]) + a[2] * (b[0] * c[1] - b[1] * c[0]);
    }
    this.closed = volume > 0;
  }

  vertex(i) {
    return [this.pos[3 * i], this.pos[3 * i + 1], this.pos[3 * i + 2]];
  }

  /** Cone culling is sound for this eye (object space): closed, and the eye outside, past the margin. */
  eyeOutside(eye) {
    if (!this.closed) return false;
    const m = this.margin;
    let inBox = true;
    for (let a = 0; a < 3; ++a) inBox = inBox && eye[a] >= this.boxMin[a] - m && eye[a] <= this.boxMax[a] + m;
    if (!inBox) return true;
    const nt = this.tri.length / 3;
    for (let t = 0; t < nt; ++t) {
      const a = this.vertex(this.tri[3 * t]), b = this.vertex(this.tri[3 * t + 1]), c = this.vertex(this.tri[3 * t + 2]);
      let far = false;
      for (let k = 0; k < 3 && !far; ++k)
        far = eye[k] < Math.min(a[k], b[k], c[k]) - m || eye[k] > Math.max(a[k], b[k], c[k]) + m;
      if (far) continue;
      const q = closestOnTriangle(eye, a, b, c);
      const dx = eye[0] - q[0], dy = eye[1] - q[1], dz = eye[2] - q[2];
      if (dx * dx + dy * dy + dz * dz <= m * m) return false;
    }
    for (const dir of kDirs) {
      let hits = 0, ambiguous = false;
      for (let t = 0; t < nt && !ambiguous; ++t) {
        const a = this.vertex(this.tri[3 * t]), b = this.vertex(this.tri[3 * t + 1]), c = this.vertex(this.tri[3 * t + 2]);
        const e1 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]], e2 = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
        const h = [dir[1] * e2[2] - dir[2] * e2[1], dir[2] * e2[0] - dir[0] * e2[2], dir[0] * e2[1] - dir[1] * e2[0]];
        const det = e1[0] * h[0] + e1[1] * h[1] + e1[2] * h[2];
        const scale = Math.sqrt((e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]) * (e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2]));
        if (Math.abs(det) <= 1e-12 * scale) continue;
        const inv = 1 / det;
        const s = [eye[0] - a[0], eye[1] - a[1], eye[2] - a[2]];
        const u = (s[0] * h[0] + s[1] * h[1] + s[2] * h[2]) * inv;
        if (u < -1e-9 || u > 1 + 1e-9) continue;
        const q = [s[1] * e1[2] - s[2] * e1[1], s[2] * e1[0] - s[0] * e1[2], s[0] * e1[1] - s[1] * e1[0]];
        const v = (dir[0] * q[0] + dir[1] * q[1] + dir[2] * q[2]) * inv;
        if (v < -1e-9 || u + v > 1 + 1e-9) continue;
        const tt = (e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2]) * inv;
        if (tt <= 0) continue;
        if (u < 1e-9 || v < 1e-9 || u + v > 1 - 1e-9) ambiguous = true;
        ++hits;
      }
      if (!ambiguous) return hits % 2 === 0;
    }
    return false;
  }
}

/** The arcs of the coarsest cut (into the sink) and its margin (their from-nodes' largest error). */
export function coarsestArcs(scene) {
  const { nodes, arcs, inArcs } = scene;
  const sink = nodes.count - 1;
  const list = [];
  let margin = 0;
  for (let k = 0; k < nodes.inArcCount[sink]; ++k) {
    const a = inArcs[nodes.firstInArc[sink] + k];
    list.push(a);
    margin = Math.max(margin, nodes.error[arcs.from[a]]);
  }
  list.sort((x, y) => x - y);
  return { arcs: list, margin };
}
