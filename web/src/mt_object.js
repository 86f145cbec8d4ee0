// MTObject: an MT file as a three.js scene object. Add it to a scene like any other Object3D and
// call `update(camera, renderer)` once a frame before rendering: the cut follows the camera under
// the frame-time budget (extract.js), patches stream in by range requests (server.js) and are
// decoded by workers into a byte-capped cache (cache.js). Its children are one Mesh per patch of
// the cut; the object is placed at the model's centre (the patches' positions are relative to it,
// so float32 keeps its precision on georeferenced coordinates).

import { ClosedSurface, coarsestArcs, weldParts } from './closed_surface.js';
import * as THREE from 'three';
import { HttpSource } from './source.js';
import { openMtFile } from './mtfile.js';
import { makeView, extrapolate } from './camera.js';
import { ExtractRender, TimeModel, Urgency } from './extract.js';
import { PatchCache } from './cache.js';
import { PatchServer } from './server.js';
import { defaultLibUrls } from './libs.js';
import { OcclusionTests } from './occlusion.js';

export { Urgency };

export class MTObject extends THREE.Group {
  /**
   * Opens an MT file by URL and loads its coarsest cut.
   * @param {string} url
   * @param {{pixelTolerance?:number, budgetMs?:number, cacheBytes?:number, workers?:number,
   *          libs?:object, material?:THREE.Material, onWarning?:(msg:string)=>void, source?:object,
   *          precompile?:{renderer:THREE.WebGLRenderer, scene:THREE.Scene, camera:THREE.Camera},
   *          early?:object, tailBytes?:number, loadAhead?:boolean, aheadBatch?:number,
   *          aheadGate?:number, stillLoadingMs?:number}} [options]
   * `precompile`: the materials' shaders are compiled for that renderer and scene (its lights)
   * while the coarsest cut loads, so the first frame does not wait for them.
   * `loadAhead` (default true): while the camera moves, batches of `aheadBatch` (32) of the patches
   * the view would need once still are loaded after frames within `aheadGate` (0.6) of the budget
   * (ExtractRender.loadAheadOf). `stillLoadingMs` (250): while a still view's loads are pending,
   * its cut update runs at most this often (ExtractRender's option; 0: every frame).
   */
  static async open(url, options = {}) {
    const times = { start: performance.now() };  // the opening's milestones (performance.now(), ms)
    // `early`: the header and tail requests the page started before its modules loaded
    // (viewer.html; HttpSource.startEarly); the tail's bytes answer the index read and the
    // coarsest patches' reads when they lie in it.
    const source = options.source || new HttpSource(url, { early: options.early, tailBytes: options.tailBytes });
    const libs = Object.assign(defaultLibUrls(), options.libs || {});
    // Workers the page started (viewer.html, before its modules load), or started here: they load
    // the decoders while the index is read.
    const pool = options.pool || PatchServer.spawnWorkers(libs, options.workers);
    let scene;
    try {
      scene = await openMtFile(source);
    } catch (e) {
      for (const w of pool) w.terminate();
      throw e;
    }
    times.index = performance.now();
    times.file = scene.openTimes;
    const obj = new MTObject(scene, Object.assign({}, options, { libs, pool }));
    obj.openTimes = times;
    await obj._start();
    return obj;
  }

  constructor(scene, options) {
    super();
    this.name = 'MTObject';
    this.mt = scene;
    this.options = options;
    this.position.set(scene.center[0], scene.center[1], scene.center[2]);
    // Back faces are drawn only when they can be seen (the surface is open, or the eye is inside
    // it): a closed surface seen from outside is drawn single-sided, as a GPU culls it; an open
    // scan's inside shows through its holes. When they are drawn, a cut of few triangles (the
    // moving frames' coarse cuts: their cost is filling the screen) is drawn in two passes, the
    // front faces then the back faces lit per vertex (MTObject.backMaterial): SwiftShader shades the
    // fragments of the far side's back faces although they fail the depth test, and with the
    // per-fragment Lambert of the front that doubled the cost of such a frame. A cut of many
    // triangles (a still image: its cost is the vertices, which a second pass would process
    // again) is drawn in one pass, both sides (docs/web.md has the figures). A material given in the
    // options is drawn as it is, in one pass.
    this.material = options.material || MTObject.defaultMaterial(scene.hasColors, THREE.FrontSide);
    this.backMaterial = options.material ? null : MTObject.backMaterial(scene.hasColors);
    this.doubleMaterial = options.material ? null : MTObject.defaultMaterial(scene.hasColors, THREE.DoubleSide);
    // Two passes up to this many triangles in the cut drawn a pixel of the drawing buffer: 3600 at
    // 1280x720. Measured on SwiftShader (docs/web.md): two passes won on m53M's 1998-triangle
    // coarsest cut and lost on arm53M's 12,936-triangle one and on a 400 k-triangle cut.
    this.twoPassPerPixel = options.twoPassPerPixel ?? 1 / 256;
    this.backFaces = !!this.backMaterial;  // whether the last update drew the back pass
    this.cache = new PatchCache(options.cacheBytes || 256 * 2 ** 20, (id, e) => this._evicted(id, e));
    this.warnings = [];
    this.fatal = null;
    this.server = new PatchServer(scene, this.cache, {
      workers: options.workers,
      pool: options.pool,
      libs: options.libs || defaultLibUrls(),
      makeGeometry: (r) => this._geometry(r),
      onWarning: (m) => {
        this.warnings.push(m);
        console.warn(m);
        if (options.onWarning) options.onWarning(m);
      },
      onFatal: (e) => { this.fatal = e; },
    });
    this.extract = new ExtractRender(scene, this.cache, this.server, {
      pixelTolerance: options.pixelTolerance ?? 1,
      budgetMs: options.budgetMs ?? 50,  // mtrender's default: 20 fps, which a software renderer can hold
      fixedTriangles: options.fixedTriangles || 0,
      loadAhead: options.loadAhead ?? true,
      aheadBatch: options.aheadBatch ?? 32,
      aheadGate: options.aheadGate ?? 0.6,
      stillLoadingMs: options.stillLoadingMs ?? 250,
    });
    this.meshes = new Map();  // patch id -> Mesh (patches of the cut)
    this.backMeshes = new Map();  // patch id -> Mesh of its back faces (the back pass)
    this.frame = 0;
    this.lastTime = 0;
    this.prevPose = null;
    this.stats = null;
    this.drawnTriangles = 0;
    // Progressive refinement of a still view (mtrender/engine.h): once the camera stops, the cut may
    // grow to stillFrames frames' worth of the render budget and is drawn over that many frames into
    // an accumulation target, at most one frame's budget a frame; the screen keeps the last
    // complete image meanwhile. render() does this; update() + renderer.render() draws plainly.
    this.stillFrames = options.stillFrames ?? 128;
    // The still image's chunks are sized by a time model of their own, fitted to the chunks drawn
    // (each chunk's frame waits for its drawing), not by the moving frames' model: a moving frame's
    // cost here is mostly fixed (SwiftShader clears and presents 1280x720 whatever the cut), so that
    // model left the chunks at 1-6 k triangles and the still cut at 128 x its 1000-triangle floor.
    // A chunk has a fixed cost too (its render pass, the sync, the scene's traversal): a rate
    // (triangles / ms) taken over whole chunks counted it per triangle, and the chunks settled where
    // the fixed cost was most of them (14 k triangles a frame while loads were pending).
    // Until a chunk is measured, the still cut's unit and the first chunk are sized from this rate
    // (triangles a millisecond): SwiftShader drew 2.5 M triangles/s at 1280x720 (docs/web.md), a GPU
    // draws far more; the chunks' own times replace it from the first chunk drawn.
    this.stillPriorRate = options.stillPriorRate ?? 1000;
    this.stillModel = new TimeModel();
    this.stillModel.a = 5;
    this.stillModel.b = 1 / this.stillPriorRate;
    // The share of a still frame's budget its chunk may take: while the still view's patches still
    // load, a smaller one, so that the drawing leaves the cores to the decoding workers (on a
    // software renderer both compete for the same cores, and the cut at the tolerance waits for
    // its loads, not for the images on the way). Once nothing loads, 0.9: a chunk costs ~10 ms
    // besides its triangles (the wait for it, SwiftShader's drain), so fewer, larger ones draw the
    // image sooner (arm53M's orbit stop: 0.82-0.92 s against 0.91-1.14 s at 0.7), each frame still
    // within the budget.
    this.stillShare = options.stillShare ?? 0.9;
    this.stillShareLoading = options.stillShareLoading ?? 0.35;
    // While a still view's patches load, a new image (of the cut so far) starts only when the last
    // image on screen, or the stop, is this old: on a fast link the cut at the tolerance is then
    // drawn once, when its loads are done, instead of after a train of intermediate images whose
    // drawing took the cores from the decoding workers (SwiftShader draws on the same cores); on a
    // slow one the screen still improves every stillWaitMs.
    this.stillWaitMs = options.stillWaitMs ?? 3000;
    // A still image leaves out the patches hidden behind those drawn before them (occlusion.js):
    // after each chunk the next ones are tested by their boxes against the depth drawn so far, up to
    // `occlusionAhead` chunks' worth of triangles. `occlusion: false` draws every patch.
    this.occlusion = options.occlusion === false || options.material ? null : new OcclusionTests();
    this.occlusionAhead = options.occlusionAhead ?? 3;
    this.fixedStillChunk = options.fixedStillChunk || 0;
    this.imageAt = 0;  // when the image on screen was shown (moving: every frame)
    this.cutSettling = false;  // the last still update stopped at its deadline
    this.stillChunk = 0;  // triangles a still frame draws (0: not measured yet)
    this.stillFullChunk = 0;  // the same at the full share (stillShare): the still cut's unit
    this.stillCount = 0;
    this.accum = null;  // {list: Mesh[], next, err}
    this.shownErr = 0;
    this.shownTriangles = 0;  // triangles of the image on screen
    this.blitted = false;  // the last render() made the still image's target or showed an image
    // Every field an update or a render sets, made here: an object whose shape grows as the camera
    // first stops deoptimises the code compiled for it (V8 recompiled update() five times then).
    this.drawnPatches = 0;
    this.cutErr = 0;
    this.lastView = null;
    this.twoPass = false;
    this.cutChanged = false;
    this.meshesKey = '';  // _syncMeshes: the still cut its meshes were made for
    this.meshesTriangles = 0;
    this.progressive = false;
    this.progressiveNow = false;
    this.syncPixel = null;
    this.target = null;
    this._warmUp = null;
  }

  /**
   * The material mtrender draws with: both sides of every triangle (an open scan's inside shows
   * through its holes); per-vertex colours unlit (`mtrender --color vertex`: scan colours carry
   * their shading), shown as stored (interpolated in their sRGB bytes, as mtrender does); without
   * colours, a Lambert surface lit by the page's lights.
   */
  static defaultMaterial(hasColors, side = THREE.DoubleSide) {
    if (!hasColors) return new THREE.MeshLambertMaterial({ color: 0xd8cfc0, side });
    const m = new THREE.MeshBasicMaterial({ vertexColors: true, side });
    // three takes vertex colours as linear and encodes the output to sRGB: decode the stored bytes
    // per fragment so the screen shows them.
    m.onBeforeCompile = (sh) => {
      sh.fragmentShader = sh.fragmentShader.replace('#include <color_fragment>',
        '#include <color_fragment>\n\tdiffuseColor.rgb = sRGBTransferEOTF( vec4( diffuseColor.rgb, 1.0 ) ).rgb;');
    };
    return m;
  }

  /**
   * The back pass's material: the back faces (seen through a hole, or from inside) lit as the
   * default material lights the front, by the page's ambient, hemisphere and directional lights,
   * with the normal reversed, but per vertex (Gouraud) instead of per fragment: the fragments of
   * this pass are mostly hidden (they fail the depth test after the front pass) and a software
   * renderer shades them anyway. Per-vertex colours are unlit already (MeshBasicMaterial).
   */
  static backMaterial(hasColors, side = THREE.BackSide) {
    if (hasColors) return MTObject.defaultMaterial(true, side);
    return new THREE.ShaderMaterial({
      side,
      lights: true,
      uniforms: THREE.UniformsUtils.merge([THREE.UniformsLib.lights, { diffuse: { value: new THREE.Color(0xd8cfc0) } }]),
      vertexShader: `#include <common>
#include <lights_pars_begin>
uniform vec3 diffuse;
varying vec3 vLit;
void main() {
  vec3 n = normalize(normalMatrix * normal);
#ifdef FLIP_SIDED
  n = -n;
#endif
  vec3 irradiance = getAmbientLightIrradiance(ambientLightColor);
#if NUM_HEMI_LIGHTS > 0
  for (int i = 0; i < NUM_HEMI_LIGHTS; ++i) irradiance += getHemisphereLightIrradiance(hemisphereLights[i], n);
#endif
#if NUM_DIR_LIGHTS > 0
  for (int i = 0; i < NUM_DIR_LIGHTS; ++i) irradiance += saturate(dot(n, directionalLights[i].direction)) * directionalLights[i].color;
#endif
  vLit = irradiance * BRDF_Lambert(diffuse);
  gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0);
}`,
      fragmentShader: `varying vec3 vLit;
void main() {
  gl_FragColor = vec4(vLit, 1.0);
#include <colorspace_fragment>
}`,
    });
  }

  async _start() {
    // The materials' shader programs compiled while the workers start and the coarsest cut loads
    // (KHR_parallel_shader_compile: the page is not blocked), not in the first frame: SwiftShader
    // took 100-300 ms of the first image for them.
    const compiling = this._precompile(this.options.precompile);
    // The coarsest cut's reads start now; the workers take its payloads once their decoders are in.
    const ready = this.server.ready.then(() => {
      if (this.openTimes) this.openTimes.workers = performance.now(), (this.openTimes.worker = this.server.workerTimes);
    });
    this.extract.start();
    await ready;
    await new Promise((resolve, reject) => {
      const poll = () => {
        if (this.fatal) return reject(this.fatal);
        if (this.server.idle()) return resolve();
        setTimeout(poll, 5);
      };
      poll();
    });
    if (this.openTimes) this.openTimes.coarsest = performance.now();
    this.server.grow();
    // The file's tail, kept since the opening, has served the index and the coarsest cut.
    if (this.mt.source.release) {
      this.openReads = { kept: this.mt.source.keptReads, requests: this.mt.source.requests };
      this.mt.source.release();
    }
    await compiling;
    if (this.openTimes) this.openTimes.compiled = performance.now();
    this.extract.pinStart();
    this.extract.setSurface(this._coarsestSurface());
    if (this.openTimes) this.openTimes.surface = performance.now();
  }

  // The still image's accumulation target (w x h) and the full-screen quad that shows it.
  _stillTarget(w, h) {
    if (this.target) this.target.dispose();
    this.target = new THREE.WebGLRenderTarget(w, h, { depthBuffer: true, colorSpace: THREE.SRGBColorSpace });
    if (!this.blit) {
      this.blit = new THREE.Mesh(new THREE.PlaneGeometry(2, 2), new THREE.MeshBasicMaterial({ depthTest: false, depthWrite: false, transparent: true }));
      this.blitScene = new THREE.Scene();
      this.blitScene.add(this.blit);
      this.blitCamera = new THREE.OrthographicCamera(-1, 1, 1, -1, 0, 1);
    }
    this.blit.material.map = this.target.texture;  // the same program for any target of this kind
  }

  // Compiles the shader programs of the materials the cut may be drawn with, for `scene`'s lights
  // and `renderer`'s output, with a one-triangle stand-in of a patch's attributes.
  async _precompile(p) {
    if (!p || !p.renderer || !p.renderer.compileAsync) return;
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(new Float32Array(9), 3));
    // Normals as _geometry makes them (four bytes): SwiftShader's pipelines are per vertex format.
    g.setAttribute('normal', new THREE.BufferAttribute(new Int8Array(12), 4, true));
    if (this.mt.hasColors) g.setAttribute('color', new THREE.BufferAttribute(new Uint8Array(12), 4, true));
    g.setIndex(new THREE.BufferAttribute(new Uint16Array([0, 1, 2]), 1));
    const group = new THREE.Group();
    for (const m of [this.material, this.backMaterial, this.doubleMaterial]) if (m) group.add(new THREE.Mesh(g, m));
    // A textured file: the texture materials' program too (one texel stands in for an atlas).
    let texel = null;
    if (this.mt.hasTextures && !this.options.material) {
      g.setAttribute('uv', new THREE.BufferAttribute(new Uint16Array(6), 2, true));
      texel = new THREE.DataTexture(new Uint8Array([255, 255, 255, 255]), 1, 1);
      texel.needsUpdate = true;
      for (const side of [THREE.FrontSide, THREE.DoubleSide]) group.add(new THREE.Mesh(g, MTObject.textureMaterial(texel, side)));
    }
    try {
      await p.renderer.compileAsync(group, p.camera, p.scene);
    } catch (e) {
      console.warn(`shader precompile: ${e.message}`);  // the first frame compiles them then
    }
    // The still image's programs (three draws into a render target in linear sRGB, the screen in
    // sRGB: a variant of each, and the blit one more) and SwiftShader's machine code for each
    // pipeline (made at its first draw) took the first still image's first chunk and last frame
    // ~0.15 s; made here they would delay the first image (~0.3 s): _warmStill, in the second frame.
    // The occlusion tests' box too (its own material and vertex format; compiled at the first
    // still chunk it cost that chunk ~60 ms of the page and ~60 ms of drawing).
    if (this.occlusion) group.add(new THREE.Mesh(this.occlusion.geometry, this.occlusion.material));
    for (const m of group.children) m.frustumCulled = false;  // they sit at the origin
    this._warmUp = { group, g, texel };
  }

  // The second frame, before it draws (the start's frames are slow anyway; it adds ~0.4 s here):
  // the stand-ins drawn into the still image's target, cleared transparent, and its blit to the
  // screen (the frame's own drawing then covers it), so the first still image pays for neither.
  // The frame's time is not a drawing cost (`blitted`). The stand-ins' own texture materials stay
  // until dispose(): disposing a material releases its programs, the target's variant with them.
  _warmStill(renderer, scene, camera) {
    const { group } = this._warmUp;
    this._warmUp.done = true;
    this.blitted = true;
    // The target at the drawing buffer's size, as the first still image will want it (made then,
    // its allocation and first clear took that image's first chunk ~30 ms).
    const size = renderer.getDrawingBufferSize(new THREE.Vector2());
    if (!this.target) this._stillTarget(size.x, size.y);
    const visible = this.visible, auto = renderer.autoClear;
    this.visible = false;
    scene.add(group);
    try {
      renderer.setRenderTarget(this.target);
      MTObject.clearTransparent(renderer);
      renderer.autoClear = false;
      renderer.render(scene, camera);
      renderer.setRenderTarget(null);
      renderer.render(this.blitScene, this.blitCamera);
    } finally {
      renderer.autoClear = auto;
      renderer.setRenderTarget(null);
      scene.remove(group);
      this.visible = visible;
    }
  }

  // Clears the bound render target to transparent; the renderer's clear alpha stays as it was.
  static clearTransparent(renderer) {
    const alpha = renderer.getClearAlpha();
    renderer.setClearAlpha(0);
    try {
      renderer.clear();
    } finally {
      renderer.setClearAlpha(alpha);
    }
  }

  // The stand-ins of the shader precompile (_warmStill) and the still image's target and quad.
  _disposeStill() {
    if (this._warmUp) {
      const { group, g, texel } = this._warmUp;
      g.dispose();
      if (texel) {
        for (const m of group.children) if (m.material.map === texel) m.material.dispose();
        texel.dispose();
      }
      this._warmUp = null;
    }
    if (this.target) this.target.dispose(), (this.target = null);
    if (this.occlusion) this.occlusion.dispose();
    if (this.blit) this.blit.geometry.dispose(), this.blit.material.dispose(), (this.blit = null);
  }

  // The coarsest cut, welded, as a ClosedSurface in object space (when normal cones may cull:
  // closed_surface.js); null when one of its patches did not arrive whole (no cone culling).
  _coarsestSurface() {
    const { arcs: list, margin } = coarsestArcs(this.mt);
    const { arcs, arcPatches } = this.mt;
    const c = this.mt.center, parts = [];
    for (const a of list)
      for (let k = 0; k < arcs.patchCount[a]; ++k) {
        const e = this.cache.get(arcPatches[arcs.firstPatch[a] + k]);
        if (!e || !e.data || !e.data.index) return null;
        const rel = e.data.attributes.position.array, positions = new Float64Array(rel.length);
        for (let i = 0; i < rel.length; ++i) positions[i] = rel[i] + c[i % 3];
        parts.push({ positions, triangles: e.data.index.array });
      }
    const m = weldParts(parts);
    return new ClosedSurface(m.positions, m.triangles, margin);
  }

  _geometry(r) {
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(r.positions, 3));
    g.setAttribute('normal', new THREE.BufferAttribute(r.normals, 4, true));
    if (r.colors) g.setAttribute('color', new THREE.BufferAttribute(r.colors, 4, true));
    g.setIndex(new THREE.BufferAttribute(r.indices, 1));
    if (r.texture && !this.options.material) {
      // A textured patch: its coordinates (unorm16, vertices split per coordinate by the worker) and
      // its atlas (the ImageBitmap the worker decoded), drawn by a material of its own.
      g.setAttribute('uv', new THREE.BufferAttribute(r.uv, 2, true));
      const tex = new THREE.Texture(r.texture.image);
      tex.flipY = false;  // ignored for an ImageBitmap: the worker flipped the coordinates instead
      tex.minFilter = THREE.LinearMipmapLinearFilter;  // trilinear from the mips, as mtrender
      tex.magFilter = THREE.LinearFilter;
      tex.wrapS = tex.wrapT = THREE.ClampToEdgeWrapping;
      tex.needsUpdate = true;
      g.userData.mtTexture = { texture: tex, front: MTObject.textureMaterial(tex, THREE.FrontSide), double: MTObject.textureMaterial(tex, THREE.DoubleSide) };
    } else if (r.texture) {
      r.texture.image.close();
    }
    return g;
  }
  _evicted(id, e) {
    for (const map of [this.meshes, this.backMeshes]) {
      const m = map.get(id);
      if (m) {
        this.meshesKey = '';  // the next _syncMeshes makes the meshes again
        this.remove(m);
        map.delete(id);
      }
    }
    if (e.data) MTObject.disposeGeometry(e.data);
  }
  /** A patch's geometry and, textured, its atlas (GPU texture and ImageBitmap) and materials. */
  static disposeGeometry(g) {
    const t = g.userData.mtTexture;
    if (t) {
      t.texture.dispose();
      if (t.texture.image && t.texture.image.close) t.texture.image.close();
      t.front.dispose();
      t.double.dispose();
    }
    g.dispose();
  }

  /**
   * A textured patch's material: its atlas unlit (as `mtrender --color texture` draws it: a
   * photographic texture carries the light it was captured under), sampled trilinearly in the
   * stored sRGB bytes and shown as stored (as the vertex colours, defaultMaterial). One shader
   * program for every patch (the same cache key); each patch's material binds its own texture.
   */
  static textureMaterial(texture, side) {
    const m = new THREE.MeshBasicMaterial({ map: texture, side });
    m.onBeforeCompile = (sh) => {
      sh.fragmentShader = sh.fragmentShader.replace('#include <map_fragment>',
        '#include <map_fragment>\n\tdiffuseColor.rgb = sRGBTransferEOTF( vec4( diffuseColor.rgb, 1.0 ) ).rgb;');
    };
    m.customProgramCacheKey = () => 'mt-texture';
    return m;
  }

  /** The camera as an MT view (object space of the file). */
  _pose(camera) {
    camera.updateMatrixWorld();
    this.updateMatrixWorld();
    const inv = new THREE.Matrix4().copy(this.matrixWorld).invert();
    const c = this.mt.center;
    const eye = new THREE.Vector3().setFromMatrixPosition(camera.matrixWorld).applyMatrix4(inv);
    const dir = new THREE.Vector3(0, 0, -1).transformDirection(camera.matrixWorld).transformDirection(inv);
    const up = new THREE.Vector3(0, 1, 0).transformDirection(camera.matrixWorld).transformDirection(inv);
    const e = [eye.x + c[0], eye.y + c[1], eye.z + c[2]];
    return { eye: e, target: [e[0] + dir.x, e[1] + dir.y, e[2] + dir.z], up: [up.x, up.y, up.z], fovDeg: camera.fov };
  }

  /**
   * The frame's cut update and the meshes that draw it. `width`/`height`: the drawing buffer's
   * size in pixels (the screen errors are measured in them).
   */
  update(camera, width, height) {
    const t = performance.now();
    // The time model learns from frames that drew. A still frame that drew nothing touched no
    // pixel (the browser kept the image): its time says nothing about the cost of drawing.
    // Nor does a frame that made the still image's target or showed a finished image: the blit of
    // a full-screen sRGB texture costs SwiftShader 100-180 ms whatever the cut (docs/web.md), and
    // taken as the cost of the triangles drawn with it, it cut the budget so that the next image
    // was coarser than the one shown (the still view swung between two cuts for ever).
    if (this.lastTime && this.frame > 1 && !this.blitted && (this.drawnTriangles > 0 || !this.progressiveNow))
      this.extract.frameDone(this.drawnTriangles, t - this.lastTime);
    else if (this.frame > 1) this.extract.frameSkipped();
    this.blitted = false;
    this.lastTime = t;
    ++this.frame;
    const pose = this._pose(camera);
    const prev = this.prevPose || pose;
    this.prevPose = pose;
    const still = this.frame > 1 && ['eye', 'target', 'up'].every((k) => pose[k].every((x, i) => Math.abs(x - prev[k][i]) <= 1e-9 * this.mt.radius));
    this.stillCount = still ? this.stillCount + 1 : 0;
    const view = makeView(pose, width, height, this.mt.center, this.mt.radius);
    // Prefetching's enlarged frustum (Derzapf et al. 4.3): the views 2, 4, ..., 10 frames ahead.
    const ahead = [];
    if (this.stillCount === 0 && this.frame > 1)
      for (let k = 2; k <= 10; k += 2) ahead.push(makeView(extrapolate(prev, pose, k), width, height, this.mt.center, this.mt.radius));
    this.progressiveNow = this.progressive && this.stillCount >= 2 && this.stillFrames > 1;
    // The cut's update, the meshes that draw it, the still image's start and the frame's figures:
    // methods of their own, so that the branches a still view takes for the first time (and the
    // fields it changes) deoptimise small functions, not one whose recompilation took V8 85-137 ms
    // of a core each time, five times after the camera stopped (docs/web.md).
    const st = this._updateCut(view, ahead);
    this.lastView = view;
    const drawnTriangles = this._syncMeshes(view, width, height);
    if (!this.progressiveNow) this.imageAt = t;
    // A still image starts once its cut is final (every load done, the update through), or when the
    // image on screen is stillWaitMs old.
    const startImage = (this.server.idle() && !this.cutSettling) || t - this.imageAt >= this.stillWaitMs;
    if (this.progressiveNow && this.cutChanged && startImage && (!this.accum || this.accum.next >= this.accum.list.length)) {
      this.accum = { list: [...this.meshes.values(), ...this.backMeshes.values()].sort((x, y) => x.renderOrder - y.renderOrder), next: 0, err: st.maxScreenError, fresh: true, triangles: drawnTriangles, hiddenTriangles: 0 };
      this.cutChanged = false;
    }
    this.drawnTriangles = drawnTriangles;
    this._fillStats(st, drawnTriangles);
    this.stats = st;
    return st;
  }

  // The frame's cut update (update()): moving, the cut within the frame's budget; still, the image
  // being drawn keeps its cut (only the look-ahead runs), else a still update towards the tolerance.
  _updateCut(view, ahead) {
    let st;
    const drawingImage = this.progressiveNow && this.accum && this.accum.next < this.accum.list.length;
    if (!this.progressiveNow) {
      this.accum = null;
      this.extract.budgetScale = 1;
      this.extract.stillTriangles = 0;
      // The look-ahead's loads: what this view's first still image could hold.
      this.extract.aheadTriangles = this.stillFrames * (this.stillFullChunk || this._priorChunk(this.stillShare));
      st = this.extract.update(this.frame, view, ahead);
    } else if (drawingImage) {
      st = this.extract.requestAhead(this.frame, view);  // the image being drawn keeps its cut
      st.maxScreenError = this.shownErr;
    } else {
      this.extract.budgetScale = this.stillFrames;
      // The next image may hold K chunks, or 4x the image on screen: the images drawn before the
      // one at the tolerance then cost at most a third of its drawing (1/4 + 1/16 + ...), and the
      // screen still improves in steps meanwhile.
      this.extract.stillTriangles = Math.max(this.stillFrames * (this.stillFullChunk || this._priorChunk(this.stillShare)), 4 * this.shownTriangles);
      st = this.extract.update(this.frame, view, ahead);
      // Kept until an image of the cut starts (one may wait for the loads).
      this.cutChanged = this.cutChanged || st.refinements + st.coarsenings > 0 || !this.accum;
      // The update stopped at its deadline: the cut has not reached what the resident patches allow.
      this.cutSettling = st.interrupted;
    }
    // The error of the cut the update last chose (the image in progress is of it); the screen shows
    // `maxScreenError`, the last complete image's. Their gap is the drawing's share of a still view.
    if (!drawingImage) this.cutErr = st.maxScreenError;
    st.cutErr = this.cutErr;
    return st;
  }

  // The meshes of the cut's visible patches (update()): made, ordered, given their materials, and
  // those of patches no longer drawn removed. Returns the triangles drawn; this.drawnPatches the count.
  _syncMeshes(view, width, height) {
    // A still frame whose cut has not changed since the last one (nor the drawing buffer, nor the
    // field of view) draws the same meshes: ~2 ms a frame of the page's thread with ~1000 patches,
    // while a still view's loads and image take the cores (its cut's patches are pinned in the
    // cache: none goes).
    const key = this.stillCount > 0 ? `${this.extract.cutVersion} ${width} ${height} ${view.pixelsPerUnit}` : '';
    if (key && key === this.meshesKey) return this.meshesTriangles;
    this.meshesKey = key;
    // The meshes: one per patch of the cut's visible arcs, drawn front to back (as mtrender does):
    // three sorts opaque meshes by renderOrder first, here the distance from the eye to the arc's
    // sphere, so nearer surfaces fill the depth buffer first and the fragments they hide (the back
    // of the model, drawn since both sides are) fail the depth test before they are shaded.
    const { arcs, arcPatches } = this.mt;
    const { center, radius } = this.mt.nodes;
    const keep = new Set();
    let drawnTriangles = 0, drawnPatches = 0, minOrder = Infinity, maxOrder = -Infinity;
    const backs = !!this.backMaterial && !this.extract.outsideClosed(view);
    this.backFaces = backs;
    this.twoPass = false;
    const backIds = new Set();  // patches whose back faces may be seen (their arc's cone does not face the eye)
    for (const a of this.extract.cutArcs) {
      if (!this.extract.arcVisible(a, view)) continue;
      const s = arcs.cullNode[a];
      const order = Math.hypot(center[3 * s] - view.eye[0], center[3 * s + 1] - view.eye[1], center[3 * s + 2] - view.eye[2]) - radius[s];
      const back = backs && !this.extract.arcFacesEye(a, view);
      for (let k = 0; k < arcs.patchCount[a]; ++k) {
        const id = arcPatches[arcs.firstPatch[a] + k];
        const e = this.cache.get(id);
        if (!e || e.state !== 'ready') continue;
        keep.add(id);
        if (back) backIds.add(id);
        let m = this.meshes.get(id);
        if (!m) {
          m = new THREE.Mesh(e.data, this.material);
          m.frustumCulled = false;  // culled per arc above, by the DAG's spheres and normal cones
          m.matrixAutoUpdate = false;
          this.meshes.set(id, m);
          this.add(m);
        }
        m.renderOrder = order;
        minOrder = Math.min(minOrder, order);
        maxOrder = Math.max(maxOrder, order);
        drawnTriangles += e.data.index.count / 3;
        ++drawnPatches;
      }
    }
    for (const [id, m] of this.meshes)
      if (!keep.has(id)) {
        this.remove(m);
        this.meshes.delete(id);
      }
    // Both sides in one pass (a cut of many triangles) or the back pass: after every front face,
    // front to back as well; only the patches that may show a back face.
    const twoPass = backs && drawnTriangles <= this.twoPassPerPixel * width * height;
    this.twoPass = twoPass;
    for (const [id, m] of this.meshes) {
      const tex = m.geometry.userData.mtTexture;
      if (tex) {
        // A textured patch shows its atlas on both sides where its back may be seen (one pass).
        m.material = backs && backIds.has(id) ? tex.double : tex.front;
        backIds.delete(id);
      } else {
        m.material = backs && !twoPass && backIds.has(id) ? this.doubleMaterial : this.material;
      }
    }
    if (!twoPass) backIds.clear();
    for (const [id, m] of this.backMeshes)
      if (!backIds.has(id)) {
        this.remove(m);
        this.backMeshes.delete(id);
      }
    if (twoPass) {
      const base = maxOrder + 1;
      for (const id of backIds) {
        const f = this.meshes.get(id);
        let m = this.backMeshes.get(id);
        if (!m) {
          m = new THREE.Mesh(f.geometry, this.backMaterial);
          m.frustumCulled = false;
          m.matrixAutoUpdate = false;
          m.userData.mtBack = true;
          this.backMeshes.set(id, m);
          this.add(m);
        }
        m.renderOrder = base + (f.renderOrder - minOrder);
      }
    }
    this.drawnPatches = drawnPatches;
    this.meshesTriangles = drawnTriangles;
    return drawnTriangles;
  }

  // The frame's figures (update()'s result).
  _fillStats(st, drawnTriangles) {
    st.drawnTriangles = drawnTriangles;
    st.drawnPatches = this.drawnPatches;
    st.backPatches = this.backMeshes.size;
    st.hiddenTriangles = this.accum ? this.accum.hiddenTriangles : 0;  // left out of the still image in progress or shown: occluded
    st.cacheBytes = this.cache.usedBytes;
    st.cacheCap = this.cache.capBytes;
    st.evictions = this.cache.evictions;
    st.givenUp = this.cache.givenUp;
    st.loads = this.server.loads;
    st.bytesRead = this.mt.source.bytesFetched;
    st.badPatches = this.server.bad;
    st.badTextures = this.server.badTextures;
    let textured = 0;  // the textured patches drawn
    for (const [, m] of this.meshes) if (m.geometry.userData.mtTexture) ++textured;
    st.cacheTextureBytes = this.cache.textureBytes;  // the cache's atlases (RGBA8)
    st.texturedPatches = textured;
    st.loadsPending = this.server.queue.length + this.server.inFlight;
    st.requests = this.server.requests;
    st.fetchMs = this.server.fetchMs;
    st.decodeMs = this.server.decodeMs;
    st.textureMs = this.server.textureMs;
  }

  /**
   * Draws the frame: the whole cut while the camera moves; once it is still, the next chunk of the
   * still image (within one frame's render budget) into an accumulation target, shown when complete
   * (meanwhile the screen keeps the last image). Call after update(). Returns the triangles drawn.
   */
  render(renderer, scene, camera) {
    const t0 = performance.now();
    this.progressive = true;
    let drawn = 0, firstChunk = false;
    if (!this.progressiveNow) {
      // Moving: the whole cut, straight to the screen.
      if (this._warmUp && !this._warmUp.done && this.frame >= 2) this._warmStill(renderer, scene, camera);
      renderer.setRenderTarget(null);
      renderer.render(scene, camera);
      drawn = this.drawnTriangles;
      this.shownErr = this.stats ? this.stats.maxScreenError : 0;
      this.shownTriangles = this.drawnTriangles;
    } else if (this.accum && this.accum.next < this.accum.list.length) {
      // Still, an image in progress: its next chunk into the accumulation target, one a frame,
      // sized to end the frame's drawing share (counted from the frame's start, the update's). Few
      // large chunks draw faster than many small ones: each chunk is waited for, and SwiftShader's
      // threads idle between them (a 1.25 M-triangle image took 530 ms in one draw, 596 ms in
      // 80 k-triangle chunks one a frame, 644 ms in 40 k ones). The screen is not touched, so the
      // browser keeps showing the last image presented.
      const size = renderer.getDrawingBufferSize(new THREE.Vector2());
      const a = this.accum;
      if (!this.target || this.target.width !== size.x || this.target.height !== size.y) {
        this.blitted = true;
        this._stillTarget(size.x, size.y);
        // A new target holds nothing: the image starts again (its occlusion tests with it).
        a.next = 0;
        a.fresh = true;
        a.hiddenTriangles = 0;
      }
      // An image's first chunk also clears the target (and is often the first draw of many
      // patches): its time does not teach the still model (it halved the next chunk).
      firstChunk = a.fresh;
      const share = this.server.idle() ? this.stillShare : this.stillShareLoading;
      // What the still model fits in the time left, at most the frame's chunk (which grows at most
      // twofold a frame: a wrong model costs one frame, not many).
      const most = (this.server.idle() ? this.stillFullChunk : this.stillChunk) || this._priorChunk(share);
      const left = (this.lastTime || t0) + share * this.extract.options.budgetMs - performance.now();
      // Never less than a moving frame's budget (with fixedTriangles, the whole image in one frame).
      // `fixedStillChunk` (tests): that many triangles a chunk, whatever the time.
      const chunk = this.fixedStillChunk || Math.max(this.extract.frameBudget, 1000, this.blitted ? most : Math.min(most, this.stillModel.trianglesFor(left)));
      drawn = this._drawStillChunk(renderer, scene, camera, chunk);
      if (this.stats) this.stats.hiddenTriangles = a.hiddenTriangles;
      if (a.next >= a.list.length) {
        if (this.occlusion) this.occlusion.reset();
        renderer.render(this.blitScene, this.blitCamera);  // the complete image, shown once
        this.blitted = true;
        this.imageAt = performance.now();
        this.shownErr = a.err;
        this.shownTriangles = a.triangles;
      }
    }
    // Still and complete, or waiting for the loads of the next image: nothing to draw; the screen
    // keeps the image. A still frame that drew waits for its drawing (_sync), and its chunk's time
    // teaches the still model (not when it also made the target or showed the image).
    if (this.progressiveNow && (drawn > 0 || this.blitted)) {
      this._sync(renderer);
      if (!this.blitted && !firstChunk && drawn > 0) this._measureChunk(drawn, performance.now() - t0);
    }
    this.drawnTriangles = drawn;
    if (this.stats) {
      this.stats.drawnTriangles = drawn;
      if (this.progressiveNow) this.stats.maxScreenError = this.shownErr;
    }
    return drawn;
  }

  // The still image's next chunk: meshes in its order up to `budget` triangles (at least one),
  // drawn into the accumulation target (cleared transparent before the image's first chunk: the
  // blit draws the model over the screen's own clear, so the background colour is converted
  // exactly as a direct render's is). Returns the triangles drawn.
  _drawStillChunk(renderer, scene, camera, budget) {
    const a = this.accum;
    const chunk = new Set();
    let drawn = 0;
    if (a.fresh && this.occlusion) this.occlusion.reset();
    while (a.next < a.list.length) {
      const m = a.list[a.next];
      const t = m.geometry.index.count / 3;
      if (this.occlusion && this.occlusion.isHidden(m)) {
        ++a.next;
        a.hiddenTriangles += t;
        continue;
      }
      if (chunk.size > 0 && drawn + t > budget) break;
      ++a.next;
      chunk.add(m);
      drawn += t;
    }
    const visible = new Map();
    for (const m of this.children) visible.set(m, m.visible), (m.visible = chunk.has(m));
    const auto = renderer.autoClear;
    renderer.autoClear = false;
    renderer.setRenderTarget(this.target);
    if (a.fresh) {
      MTObject.clearTransparent(renderer);
      a.fresh = false;
    }
    renderer.render(scene, camera);
    renderer.autoClear = auto;
    for (const [m, v] of visible) m.visible = v;
    // The patches the next frames may draw, tested against the depth drawn so far (a perspective
    // camera, no clipping planes: occlusion.js).
    if (this.occlusion && a.next < a.list.length && camera.isPerspectiveCamera && renderer.clippingPlanes.length === 0) {
      const ahead = [];
      for (let i = a.next, t = 0; i < a.list.length && t < this.occlusionAhead * budget && ahead.length < 512; ++i) {
        ahead.push(a.list[i]);
        t += a.list[i].geometry.index.count / 3;
      }
      this.occlusion.issue(renderer, camera, ahead);
    }
    renderer.setRenderTarget(null);
    return drawn;
  }
  // Waits for the drawing issued so far. A still image's chunks are waited for: WebGL runs them
  // later in the GPU process, so a frame's measured time is that of an earlier frame's drawing, and
  // the still state's chunks (a 300 k-triangle chunk measured 10 ms, the frame after it 300 ms) let
  // the fitted budget run away. Moving frames draw a cut that changes slowly: the lag costs little
  // there, and waiting would cost the overlap of the page's work with the browser's.
  // gl.finish() does not wait in Chromium; reading one pixel back does.
  _sync(renderer) {
    const gl = renderer.getContext();
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, this.syncPixel || (this.syncPixel = new Uint8Array(4)));
  }
  // A chunk of `triangles` took `ms` to draw (synchronised): the still chunk becomes what fits in
  // the frame's drawing share (stillShare of the budget, stillShareLoading while loads are pending,
  // less the update's deadline), from the time model of the chunks so far, at most doubling a
  // frame (a wrong model costs one frame, not many).
  _measureChunk(triangles, ms) {
    const m = this.stillModel;
    m.add(triangles, Math.max(ms, 0.1));
    // Chunks of one size teach the model no slope: it keeps the prior's and moves its intercept,
    // which stops at 0 when the chunks draw faster than the prior slope allows. Then the slope is
    // the chunks' own time per triangle (with the prior's, the final image's chunks stayed at the
    // size the prior fitted in the share, whatever the share: 41 k triangles at 0.7 and at 0.9).
    if (m.a === 0) {
      let t = 0, y = 0;
      for (const [x, ms2] of m.window) t += x, (y += ms2);
      if (t > 0) m.b = Math.min(m.b, (y / t) * 1e-6);
    }
    // The cut's size follows the full share (a smaller cut while loading would load less); the
    // chunk drawn a frame, the share of the moment.
    this.stillFullChunk = this._chunkFor(this.stillShare, triangles, this.stillFullChunk);
    this.stillChunk = this._chunkFor(this.server.idle() ? this.stillShare : this.stillShareLoading, triangles, this.stillChunk);
  }
  // The still chunk for a share of the budget at the prior rate (before any chunk is measured).
  _priorChunk(share) {
    const extractMs = Math.min(2, this.extract.options.budgetMs / 20);
    return Math.max(1000, this.stillPriorRate * (share * this.extract.options.budgetMs - extractMs));
  }
  // The still chunk for a share of the budget, from the measured rate (at most doubling).
  _chunkFor(share, triangles, last) {
    const extractMs = Math.min(2, this.extract.options.budgetMs / 20);
    const fit = this.stillModel.trianglesFor(share * this.extract.options.budgetMs - extractMs);
    return Math.max(1000, Math.min(fit, 2 * Math.max(triangles, last)));
  }

  dispose() {
    this.server.dispose();
    for (const [, e] of this.cache.entries) if (e.data) MTObject.disposeGeometry(e.data);
    this._disposeStill();
  }
}
