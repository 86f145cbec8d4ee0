// Occlusion tests for a still image drawn in chunks (MTObject.render): after a chunk is drawn, the
// patches that come next in the image's front-to-back order are tested against the depth drawn so
// far, each by its bounding box (WebGL2 occlusion queries), and a patch whose box passes no sample
// is left out of the image. Only what is hidden is left out: the depth buffer only gets nearer as
// the image goes on, so a patch hidden when tested stays hidden, and the box encloses the patch, so
// where a patch's fragment would pass, the box's passes first (the box is padded, and a box that
// reaches the near plane is not tested). On an open scan (double-sided, holes) seen at a still
// view, the patches wholly hidden (mostly the far side's) are a third to a half of the image's
// triangles, and a software renderer still processes their vertices and rasterises them; on
// SwiftShader leaving them out made the orbit's final still image of two 53 M builds 9-25% faster
// to redraw (docs/web.md). The argument needs the patches' materials to test depth LessEqual and no
// clipping planes: MTObject runs the tests only with its own materials and none set.
// Results are read a frame later: WebGL makes a query's result available only after the page
// returns to the browser, and a still frame waits for its drawing, so by then they are in. A
// patch whose result is not in is drawn.

import * as THREE from 'three';

export class OcclusionTests {
  constructor() {
    this.geometry = new THREE.BoxGeometry(1, 1, 1);
    // Depth test only: no colour, no depth written (the patches' materials test LessEqual, as this
    // one does). Front faces only: the near plane check below keeps the eye outside the box, so its
    // front faces cover every pixel it covers, each nearer than the back face behind it.
    this.material = new THREE.MeshBasicMaterial({ colorWrite: false, depthWrite: false });
    this.scene = new THREE.Scene();
    this.scene.matrixWorldAutoUpdate = false;
    this.proxies = [];  // box meshes, reused
    this.pending = new Map();  // patch mesh -> WebGLQuery
    this.free = [];  // queries read, reused
    this.gl = null;  // the context of the last tests
    this._corner = new THREE.Vector3();
    this._m = new THREE.Matrix4();
    this._c = new THREE.Vector3();
    this._s = new THREE.Vector3();
    this._q = new THREE.Quaternion();
  }

  // Tests each of `meshes` (not drawn yet; matrixWorld current) against the depth of the target
  // bound now, seen by `camera` (a perspective one: MTObject tests nothing else). A mesh whose test
  // is pending is not tested again; one whose result was read (visible) is, against more depth.
  issue(renderer, camera, meshes) {
    const gl = (this.gl = renderer.getContext());
    const view = camera.matrixWorldInverse;
    const near = camera.near;
    let n = 0;
    for (const m of meshes) {
      if (this.pending.has(m)) continue;
      const g = m.geometry;
      if (!g.boundingBox) g.computeBoundingBox();
      const bb = g.boundingBox;
      if (bb.isEmpty()) continue;
      bb.getCenter(this._c);
      bb.getSize(this._s);
      // Padded by 1% of its largest side on every side (the box's depth is interpolated over other
      // triangles than the patch's; a flat patch still gets a box with some depth).
      const pad = 0.02 * Math.max(this._s.x, this._s.y, this._s.z) + 1e-6;  // added to each extent: 1% a side
      this._s.addScalar(pad);
      let p = this.proxies[n];
      if (!p) {
        p = new THREE.Mesh(this.geometry, this.material);
        p.matrixAutoUpdate = false;
        p.matrixWorldAutoUpdate = false;
        p.frustumCulled = false;
        p.onBeforeRender = (r) => r.getContext().beginQuery(r.getContext().ANY_SAMPLES_PASSED_CONSERVATIVE, p.userData.query);
        p.onAfterRender = (r) => r.getContext().endQuery(r.getContext().ANY_SAMPLES_PASSED_CONSERVATIVE);
        this.proxies.push(p);
      }
      p.matrixWorld.multiplyMatrices(m.matrixWorld, this._m.compose(this._c, this._q, this._s));
      // A box that reaches the near plane (or holds the eye) is clipped: its drawn part may miss
      // the patch's pixels. Such a patch is drawn untested.
      this._m.multiplyMatrices(view, p.matrixWorld);
      let clipped = false;
      for (let k = 0; k < 8 && !clipped; ++k) {
        this._corner.set(k & 1 ? 0.5 : -0.5, k & 2 ? 0.5 : -0.5, k & 4 ? 0.5 : -0.5).applyMatrix4(this._m);
        clipped = -this._corner.z <= near * 1.01;
      }
      if (clipped) continue;
      const q = this.free.pop() || gl.createQuery();
      p.userData.query = q;
      p.renderOrder = n;
      this.pending.set(m, q);
      this.scene.add(p);
      ++n;
    }
    if (n === 0) return;
    const auto = renderer.autoClear;
    renderer.autoClear = false;
    try {
      renderer.render(this.scene, camera);
    } finally {
      renderer.autoClear = auto;
      this.scene.clear();
    }
  }

  // True when `mesh` was tested and no sample of its box passed (it is hidden in the image); false
  // when it passed, was not tested, or its result is not in yet.
  isHidden(mesh) {
    const q = this.pending.get(mesh);
    if (!q) return false;
    const gl = this.gl;
    if (!gl.getQueryParameter(q, gl.QUERY_RESULT_AVAILABLE)) return false;
    const hidden = !gl.getQueryParameter(q, gl.QUERY_RESULT);
    this.pending.delete(mesh);
    this.free.push(q);
    return hidden;
  }

  // A new image (the tests made against the last one's depth no longer hold), or an image done
  // (the patches tested are let go).
  reset() {
    for (const [, q] of this.pending) this.free.push(q);
    this.pending.clear();
  }

  dispose() {
    this.reset();
    if (this.gl) for (const q of this.free) this.gl.deleteQuery(q);
    this.free = [];
    this.geometry.dispose();
    this.material.dispose();
  }
}
