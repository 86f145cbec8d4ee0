// The standalone viewer page: viewer.html?file=URL[&tol=1][&budget=50][&cache=256][&bg=20242a]
// [&path=orbit|fixed&frames=600][&view=EX,EY,EZ,TX,TY,TZ (unit space)]. Orbit/pan/zoom with the
// mouse (three's OrbitControls); the HUD shows fps, triangles, cache (and its textures' share for a
// textured file), loads and the screen error, and the file's coordinate reference system when its
// metadata block names one.
// `side=front` culls back faces, `side=double` draws both in one pass, `twopass=T` sets MTObject's twoPassPerPixel, `occlusion=0` turns a still image's occlusion tests off, `occlahead=K` tests K chunks ahead, `chunk=N` draws a still image in chunks of N triangles (measurements, tests). `plain` draws with renderer.render (no progressive still image). `capture` keeps the drawing buffer for reading the image back (the tests). `path` plays a recorded camera path frame by frame (the browser tests and bench/web.sh); the
// per-frame figures are in window.mtViewer.frames.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { MTObject } from './src/mt_object.js';

const q = new URLSearchParams(location.search);
const hud = document.getElementById('hud');
const errBox = document.getElementById('error');
const warnBox = document.getElementById('warn');
const state = (window.mtViewer = { ready: false, error: null, warnings: [], frames: [], firstImageMs: null, done: false });

function showError(msg) {
  state.error = msg;
  errBox.textContent = msg;
  errBox.style.display = 'block';
  hud.textContent = 'error';
}

// A camera path in unit space (p = centre + radius * v): one turn with elevation changes and
// zooms, the last 15% of the frames still.
function orbitPose(i, frames) {
  const moving = Math.floor(frames * 0.85);
  const f = Math.min(i, moving) / moving;
  const a = 2 * Math.PI * f - Math.PI / 2;
  const d = 2.3 + 1.1 * Math.cos(3 * Math.PI * f);
  const el = 0.25 + 0.35 * Math.sin(2 * Math.PI * f);
  return { eye: [d * Math.cos(a), d * Math.sin(a), d * el], target: [0.15 * Math.sin(4 * Math.PI * f), 0, 0] };
}

async function main() {
  const file = q.get('file');
  if (!file) return showError('viewer.html?file=URL: no MT file given');
  // The file's opening (three range reads, the workers loading their decoders, the coarsest cut)
  // starts first; making the WebGL context (SwiftShader: 100-300 ms of the main thread) overlaps it.
  const precompile = {};  // filled below, before the opening needs it (its first awaits are reads)
  const opening = MTObject.open(file, {
    precompile,
    pool: window.mtWorkerPool,
    early: window.mtEarly && window.mtEarly.url === file ? window.mtEarly : undefined,
    pixelTolerance: Number(q.get('tol') || 1),
    budgetMs: Number(q.get('budget') || 50),
    fixedTriangles: Number(q.get('fixed') || 0),
    // ahead=0: no look-ahead loads while the camera moves; aheadbatch=N, aheadgate=S: their batch
    // and frame-time gate (ExtractRender's loadAhead, aheadBatch, aheadGate).
    loadAhead: q.get('ahead') !== '0',
    aheadBatch: Number.isFinite(Number(q.get('aheadbatch'))) && q.has('aheadbatch') ? Number(q.get('aheadbatch')) : undefined,
    aheadGate: Number.isFinite(Number(q.get('aheadgate'))) && q.has('aheadgate') ? Number(q.get('aheadgate')) : undefined,
    // side=front: back faces always culled by the GL (measurement only: an open scan's inside
    // then shows the background through its holes); side=double: both sides in one pass
    // (THREE.DoubleSide, the viewer's drawing before the two passes; docs/web.md compares them).
    material: q.get('side') === 'front' || q.get('side') === 'double' ? MTObject.defaultMaterial(false, q.get('side') === 'front' ? THREE.FrontSide : THREE.DoubleSide) : undefined,
    cacheBytes: Number(q.get('cache') || 256) * 2 ** 20,
    // twopass=T: back faces in a second pass up to T triangles a pixel (default 1/256; 0: one pass).
    twoPassPerPixel: q.has('twopass') ? Number(q.get('twopass')) : undefined,
    // loadshare=S: the still frames' drawing share while loads are pending (MTObject.stillShareLoading).
    stillShareLoading: q.has('loadshare') ? Number(q.get('loadshare')) : undefined,
    // stillshare=S: the still frames' drawing share once nothing loads (MTObject.stillShare).
    stillShare: q.has('stillshare') ? Number(q.get('stillshare')) : undefined,
    // stillupdate=MS: while a still view's patches load, its cut update runs at most every MS (ExtractRender's stillLoadingMs; 0: every frame).
    stillLoadingMs: q.has('stillupdate') ? Number(q.get('stillupdate')) : undefined,
    // stillwait=MS: while a still view's patches load, a new image starts when the last one is this old (MTObject.stillWaitMs).
    stillWaitMs: q.has('stillwait') ? Number(q.get('stillwait')) : undefined,
    // occlusion=0: a still image draws every patch of its cut (no occlusion tests, occlusion.js);
    // occlahead=K: the patches tested after a chunk, K chunks' worth (MTObject.occlusionAhead);
    // chunk=N: a still image's chunks of N triangles whatever they take (tests).
    occlusion: q.get('occlusion') !== '0',
    occlusionAhead: q.has('occlahead') ? Number(q.get('occlahead')) : undefined,
    fixedStillChunk: Number(q.get('chunk') || 0),
    // workers=N: at most N decoding workers (default: one while the page starts, then two or cores - 1).
    workers: q.has('workers') ? Number(q.get('workers')) : undefined,
    onWarning: (m) => {
      state.warnings.push(m);
      warnBox.textContent = `${state.warnings.length} damaged patch(es) ${/drawn untextured/.test(m) ? 'drawn untextured' : 'skipped'}: ${m}`;
    },
  });
  opening.catch(() => {});  // reported below
  const width = window.innerWidth, height = window.innerHeight;
  const renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: q.has('capture'), powerPreference: 'high-performance' });
  renderer.setPixelRatio(1);
  renderer.setSize(width, height);
  document.body.appendChild(renderer.domElement);
  const bg = new THREE.Color('#' + (q.get('bg') || '20242a'));
  renderer.setClearColor(bg);
  const scene = new THREE.Scene();
  const camera = new THREE.PerspectiveCamera(45, width / height, 0.01, 100);
  camera.up.set(0, 0, 1);
  scene.add(new THREE.HemisphereLight(0xffffff, 0x404040, 1.2));
  const sun = new THREE.DirectionalLight(0xffffff, 1.6);
  camera.add(sun);
  sun.position.set(0.5, 1, 0.3);
  scene.add(camera);
  Object.assign(precompile, { renderer, scene, camera });

  let mt;
  try {
    mt = await opening;
  } catch (e) {
    return showError(e.message);
  }
  scene.add(mt);
  const r = mt.mt.radius;
  const c = new THREE.Vector3(...mt.mt.center);
  const unit = (v) => new THREE.Vector3(v[0], v[1], v[2]).multiplyScalar(r).add(c);
  camera.near = r * 1e-3;
  camera.far = r * 20;
  camera.updateProjectionMatrix();
  const controls = new OrbitControls(camera, renderer.domElement);
  const setPose = (p) => {
    camera.position.copy(unit(p.eye));
    controls.target.copy(unit(p.target));
    camera.lookAt(controls.target);
  };
  const v = (q.get('view') || '').split(',').map(Number);
  setPose(v.length === 6 && v.every(Number.isFinite) ? { eye: v.slice(0, 3), target: v.slice(3) } : { eye: [0, -2.2, 1.1], target: [0, 0, 0] });
  controls.update();
  const path = q.get('path');
  const frames = Number(q.get('frames') || 600);
  state.canvas = renderer.domElement;
  state.renderer = renderer;
  state.camera = camera;
  state.mt = mt;
  // The cut's meshes drawn whole, straight to the screen, `reps` times, each waited for (one pixel
  // read back): the software renderer's raw rate on this cut (bench/web.sh: the floor under the
  // time a still view takes to reach the tolerance).
  state.drawRate = (reps = 3) => {
    const gl = renderer.getContext(), px = new Uint8Array(4), ms = [];
    let triangles = 0;
    for (const m of mt.children) if (m.isMesh && m.visible && !m.userData.mtBack) triangles += m.geometry.index.count / 3;
    for (let k = 0; k < reps; ++k) {
      const t = performance.now();
      renderer.setRenderTarget(null);
      renderer.render(scene, camera);
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
      ms.push(performance.now() - t);
    }
    return { triangles, ms };
  };
  state.ready = true;
  state.fileSize = mt.mt.fileSize;
  state.decoder = mt.server.decoder;  // 'wasm', or 'javascript' when web/dist/mt_decode.wasm did not load
  state.crs = mt.mt.crs;  // the file's coordinate reference system ('' when it names none)
  state.openBytes = mt.mt.source.bytesFetched;  // header, DAG, index and the coarsest cut
  state.openReads = mt.openReads;  // {requests, kept}: range requests to the coarsest cut, reads answered from the file's tail
  state.budgetMs = mt.extract.options.budgetMs;
  state.tolerance = mt.extract.options.pixelTolerance;
  let i = 0, fpsAvg = 0, last = performance.now();
  const loop = () => {
    if (mt.fatal) return showError(mt.fatal.message);
    const now = performance.now();
    const dt = now - last;
    last = now;
    if (path === 'orbit') setPose(orbitPose(i, frames));
    else controls.update();
    const tu = performance.now();
    const st = mt.update(camera, width, height);
    const updateMs = performance.now() - tu;
    // Near/far hug the model so depth precision holds close to the surface.
    const dist = camera.position.distanceTo(c);
    camera.near = Math.max(r * 5e-4, (dist - r) * 0.9);
    camera.far = dist + r * 1.01;
    camera.updateProjectionMatrix();
    const tr = performance.now();
    if (q.has('plain')) renderer.render(scene, camera);
    else mt.render(renderer, scene, camera);
    const renderMs = performance.now() - tr;
    if (state.firstImageMs === null) {
      // The first image: its drawing waited for (one pixel read back), so the time is when it is on
      // screen, not when its commands were issued.
      const tf = performance.now(), gl = renderer.getContext();
      gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array(4));
      state.firstImageMs = performance.now();
      state.openTimes = Object.assign({}, mt.openTimes, { frame: now, update: tr, render: tf, drawn: state.firstImageMs });
    }
    if (i > 0) fpsAvg = fpsAvg ? 0.9 * fpsAvg + 0.1 * (1000 / dt) : 1000 / dt;
    state.frames.push({
      t: now, frameMs: i > 0 ? dt : 0, updateMs, renderMs, drawn: st.drawnTriangles, patches: st.drawnPatches, backPatches: st.backPatches, cacheBytes: st.cacheBytes,
      cacheCap: st.cacheCap, bytesRead: st.bytesRead, err: st.maxScreenError, cutErr: st.cutErr, accumulating: mtAccumulating(mt), pending: st.loadsPending,
      budget: st.budgetTriangles, modelA: st.modelA, modelB: st.modelB, loads: st.loads, moves: st.refinements + st.coarsenings, requests: st.requests, fetchMs: st.fetchMs, decodeMs: st.decodeMs, evictions: st.evictions, givenUp: st.givenUp, triangles: st.triangles, still: path === 'orbit' ? i >= Math.floor(frames * 0.85) : null,
      hidden: st.hiddenTriangles, textureMs: st.textureMs, cacheTextureBytes: st.cacheTextureBytes, texturedPatches: st.texturedPatches, badTextures: st.badTextures,
    });
    if (state.frames.length > 5000) state.frames.shift();
    if (i % 10 === 0) hud.textContent =
      `fps ${fpsAvg.toFixed(1)}  (budget ${state.budgetMs} ms)\n` +
      `triangles ${(st.triangles / 1e6).toFixed(2)} M in the cut, ${(st.drawnTriangles / 1e6).toFixed(2)} M drawn this frame, ${st.drawnPatches} patches\n` +
      `cache ${(st.cacheBytes / 2 ** 20).toFixed(1)} / ${(st.cacheCap / 2 ** 20).toFixed(0)} MiB` +
      (mt.mt.hasTextures ? ` (textures ${(st.cacheTextureBytes / 2 ** 20).toFixed(1)} MiB, ${st.texturedPatches} textured patches drawn)` : '') + '\n' +
      `loads ${st.loads}, pending ${st.loadsPending}, fetched ${(st.bytesRead / 2 ** 20).toFixed(1)} MiB of ${(mt.mt.fileSize / 2 ** 20).toFixed(1)}\n` +
      `screen error ${st.maxScreenError.toFixed(2)} px (tolerance ${state.tolerance})` +
      (state.crs ? `\ncrs ${state.crs.length > 60 ? state.crs.slice(0, 57) + '...' : state.crs}` : '');
    ++i;
    if (path && i >= frames) state.done = true;
    requestAnimationFrame(loop);
  };
  requestAnimationFrame(loop);
}
// Whether a still image is being drawn (its chunks go to the accumulation target).
function mtAccumulating(mt) {
  return !!(mt.progressiveNow && mt.accum);
}
// The image as RGBA bytes (the drawing buffer is preserved).
function pixels() {
  const cv = state.canvas;
  const c2 = document.createElement('canvas');
  c2.width = cv.width;
  c2.height = cv.height;
  const g = c2.getContext('2d');
  g.drawImage(cv, 0, 0);
  return g.getImageData(0, 0, cv.width, cv.height);
}
// Background pixels not connected to the image border through background: holes inside the
// silhouette. Components under `maxArea` pixels are counted as cracks (a real hole of the surface,
// or the torus' middle, is large). Returns {crackPixels, components, surfacePixels}.
// inject: paint a 1x20-pixel slit of background into a solid part of the surface first (the check
// of the detector itself: it must find it).
state.cracks = (bgHex, maxArea = 400, inject = false) => {
  const img = pixels();
  const { width: w, height: h, data } = img;
  const bg = [parseInt(bgHex.slice(0, 2), 16), parseInt(bgHex.slice(2, 4), 16), parseInt(bgHex.slice(4, 6), 16)];
  const isBg = new Uint8Array(w * h);
  let surface = 0;
  for (let i = 0; i < w * h; ++i) {
    const d = Math.abs(data[4 * i] - bg[0]) + Math.abs(data[4 * i + 1] - bg[1]) + Math.abs(data[4 * i + 2] - bg[2]);
    isBg[i] = d < 12 ? 1 : 0;
    if (!isBg[i]) ++surface;
  }
  if (inject) {
    // The first place (scanning from the middle row down) with a 3x22 block of surface.
    const solid = (x, y) => { for (let yy = y - 1; yy < y + 21; ++yy) for (let xx = x - 1; xx <= x + 1; ++xx) if (isBg[yy * w + xx]) return false; return true; };
    let done = false;
    for (let y = h >> 2; y < h - 22 && !done; y += 4)
      for (let x = 2; x < w - 2 && !done; x += 2)
        if (solid(x, y)) {
          for (let yy = y; yy < y + 20; ++yy) isBg[yy * w + x] = 1;
          done = true;
        }
  }
  const seen = new Uint8Array(w * h);
  const stack = [];
  const fill = (start) => {
    let area = 0;
    stack.push(start);
    seen[start] = 1;
    let border = false;
    while (stack.length) {
      const i = stack.pop();
      ++area;
      const x = i % w, y = (i / w) | 0;
      if (x === 0 || y === 0 || x === w - 1 || y === h - 1) border = true;
      for (const j of [x > 0 ? i - 1 : -1, x < w - 1 ? i + 1 : -1, y > 0 ? i - w : -1, y < h - 1 ? i + w : -1])
        if (j >= 0 && isBg[j] && !seen[j]) seen[j] = 1, stack.push(j);
    }
    return { area, border };
  };
  let crackPixels = 0, components = 0;
  for (let i = 0; i < w * h; ++i)
    if (isBg[i] && !seen[i]) {
      const c = fill(i);
      if (!c.border && c.area < maxArea) crackPixels += c.area, ++components;
    }
  return { crackPixels, components, surfacePixels: surface };
};
// The RGBA8 pixels of the PNG at `url`, or {error} when its size is not the image's `img`.
async function referencePixels(url, img) {
  const ref = await new Promise((resolve, reject) => {
    const im = new Image();
    im.onload = () => resolve(im);
    im.onerror = () => reject(new Error(`cannot load ${url}`));
    im.src = url;
  });
  if (ref.width !== img.width || ref.height !== img.height) return { error: `size ${ref.width}x${ref.height} vs ${img.width}x${img.height}` };
  const c = document.createElement('canvas');
  c.width = ref.width;
  c.height = ref.height;
  const g = c.getContext('2d');
  g.drawImage(ref, 0, 0);
  return g.getImageData(0, 0, ref.width, ref.height).data;
}
// The image against a PNG at `url`: the share of pixels whose RGB differs by more than `tol`
// (sum of absolute differences), and the mean absolute difference per channel.
state.compare = async (url, tol = 48) => {
  const img = pixels();
  const r = await referencePixels(url, img);
  if (r.error) return r;
  let off = 0, sum = 0;
  const n = img.width * img.height;
  for (let i = 0; i < n; ++i) {
    const d = Math.abs(img.data[4 * i] - r[4 * i]) + Math.abs(img.data[4 * i + 1] - r[4 * i + 1]) + Math.abs(img.data[4 * i + 2] - r[4 * i + 2]);
    sum += d;
    if (d > tol) ++off;
  }
  return { differing: off / n, mean: sum / (3 * n) };
};
// The cache's bytes recounted from what it holds: each ready patch's arrays (positions, normals,
// colours, coordinates, indices) and, textured, its atlas as RGBA8 (the ImageBitmap's size), each
// against the entry's bytes and the bound the load reserved and the cut's budget counts
// (scene.decodedBytes); loading entries hold their reservation. Returns the sums.
state.cacheAudit = () => {
  const mt = state.mt, cache = mt.cache;
  let ready = 0, loading = 0, textures = 0, texturedPatches = 0, mismatched = 0, overBound = 0, atlasOutsideBound = 0;
  for (const [id, e] of cache.entries) {
    if (e.state === 'loading') { loading += e.bytes; continue; }
    if (e.state !== 'ready') continue;
    const g = e.data;
    let b = g.index.array.byteLength;
    for (const a of Object.values(g.attributes)) b += a.array.byteLength;
    const t = g.userData.mtTexture;
    if (t) {
      const atlas = 4 * t.texture.image.width * t.texture.image.height;
      b += atlas;
      textures += atlas;
      ++texturedPatches;
      if (mt.mt.decodedBytes[id] < atlas) ++atlasOutsideBound;
    }
    if (b !== e.bytes) ++mismatched;
    if (b > mt.mt.decodedBytes[id]) ++overBound;
    ready += b;
  }
  return { usedBytes: cache.usedBytes, textureBytes: cache.textureBytes, capBytes: cache.capBytes, peakBytes: cache.peakBytes, ready, loading, textures, texturedPatches,
    mismatched, overBound, atlasOutsideBound, evictions: cache.evictions, textureBytesDecoded: mt.server.textureBytes };
};
// PSNR of the image against a PNG at `url` (mtrender's screenshot of the same view): over every
// pixel, and over the pixels the model covers in either image (a pixel within 3 levels of the
// background `bgHex` in both is background), as mtrender/image.h's psnr does.
state.psnr = async (url, bgHex) => {
  const img = pixels();
  const r = await referencePixels(url, img);
  if (r.error) return r;
  const bg = [parseInt(bgHex.slice(0, 2), 16), parseInt(bgHex.slice(2, 4), 16), parseInt(bgHex.slice(4, 6), 16)];
  const isBg = (d, i) => Math.abs(d[4 * i] - bg[0]) <= 3 && Math.abs(d[4 * i + 1] - bg[1]) <= 3 && Math.abs(d[4 * i + 2] - bg[2]) <= 3;
  let all = 0, covered = 0, n = 0;
  const N = img.width * img.height;
  for (let i = 0; i < N; ++i) {
    let e = 0;
    for (let k = 0; k < 3; ++k) e += (img.data[4 * i + k] - r[4 * i + k]) ** 2;
    all += e;
    if (!isBg(img.data, i) || !isBg(r, i)) covered += e, ++n;
  }
  const db = (sse, count) => (sse === 0 ? Infinity : 10 * Math.log10((255 * 255) / (sse / (3 * count))));
  return { all: db(all, N), covered: db(covered, Math.max(n, 1)), coveredPixels: n };
};
// The colours on screen against the stored ones: on a grid of pixels, a ray through the pixel's
// centre finds the surface (the cut's meshes); the expected colour is the stored per-vertex colour
// interpolated at the hit (the decoded patch's RGBA8, as in the file). Returns the hits, how many are
// within `tol` levels in every channel, and the median of the largest channel difference.
state.colours = (grid = 32, tol = 8) => {
  const { width: w, height: h, data } = pixels();
  const ray = new THREE.Raycaster();
  const meshes = state.mt.children.filter((m) => m.isMesh && m.geometry.attributes.color);
  const diffs = [];
  for (let gy = 1; gy < grid; ++gy)
    for (let gx = 1; gx < grid; ++gx) {
      const px = Math.floor((gx * w) / grid), py = Math.floor((gy * h) / grid);
      ray.setFromCamera(new THREE.Vector2(((px + 0.5) / w) * 2 - 1, 1 - ((py + 0.5) / h) * 2), state.camera);
      const hit = ray.intersectObjects(meshes, false)[0];
      if (!hit || !hit.barycoord) continue;
      const col = hit.object.geometry.attributes.color, f = hit.face, b = hit.barycoord;
      let d = 0;
      for (let k = 0; k < 3; ++k) {
        const get = (i) => col.getComponent(i, k);
        const want = 255 * (b.x * get(f.a) + b.y * get(f.b) + b.z * get(f.c));
        d = Math.max(d, Math.abs(data[4 * (py * w + px) + k] - want));
      }
      diffs.push(d);
    }
  diffs.sort((a, b) => a - b);
  return { hits: diffs.length, within: diffs.filter((d) => d <= tol).length, median: diffs.length ? diffs[diffs.length >> 1] : NaN };
};
// Back faces seen through holes: the cut drawn once more, both sides in one pass with the depth
// test, white where the nearest surface shows its back face (a view into the inside of an open
// scan, through a hole or past its border), black elsewhere: an oracle independent of the viewer's
// two passes. Returns the back-face pixels and how many of them the image on screen (taken first)
// shows as background. The screen then holds the oracle's image.
state.backFaces = (bgHex) => {
  const img = pixels();
  const bg = [parseInt(bgHex.slice(0, 2), 16), parseInt(bgHex.slice(2, 4), 16), parseInt(bgHex.slice(4, 6), 16)];
  const scene = state.mt.parent;
  const oracle = new THREE.ShaderMaterial({
    side: THREE.DoubleSide,
    vertexShader: 'void main() { gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0); }',
    fragmentShader: 'void main() { gl_FragColor = gl_FrontFacing ? vec4(0.0, 0.0, 0.0, 1.0) : vec4(1.0, 1.0, 1.0, 1.0); }',
  });
  const renderer = state.renderer;
  scene.overrideMaterial = oracle;
  const clear = renderer.getClearColor(new THREE.Color()), alpha = renderer.getClearAlpha();
  renderer.setClearColor(0x000000, 1);
  renderer.setRenderTarget(null);
  renderer.render(scene, state.camera);
  scene.overrideMaterial = null;
  renderer.setClearColor(clear, alpha);
  const o = pixels();
  let back = 0, backBg = 0, backDark = 0;
  for (let i = 0; i < o.width * o.height; ++i) {
    if (o.data[4 * i] < 128) continue;
    ++back;
    const d = Math.abs(img.data[4 * i] - bg[0]) + Math.abs(img.data[4 * i + 1] - bg[1]) + Math.abs(img.data[4 * i + 2] - bg[2]);
    if (d < 12) ++backBg;
    if (img.data[4 * i] + img.data[4 * i + 1] + img.data[4 * i + 2] < 30) ++backDark;
  }
  return { back, backBg, backDark, backFaces: state.mt.backFaces, twoPass: state.mt.twoPass };
};
state.png = () => state.canvas.toDataURL('image/png');
state.pixels = pixels;
main().catch((e) => showError(e.stack || e.message));
