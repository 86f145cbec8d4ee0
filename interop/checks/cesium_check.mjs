// Renders a 3D Tiles tileset in CesiumJS in headless Chromium (Debian's /usr/bin/chromium, WebGL on
// SwiftShader) and checks that the model is drawn where it should be.
//   node cesium_check.mjs SPEC.json
// SPEC: { "tileset": DIR, "screenshot": PNG, "radius": R (the model's half diagonal, metres),
//         and where the model's centre must be, either "geodetic": [lon, lat, h] (degrees, degrees,
//         metres above the WGS84 ellipsoid) or "ecef": [x, y, z] (Cesium's world frame, metres),
//         "points": [{ "local": [x, y, z], "geodetic": [lon, lat, h] }, ...] (optional: points of the
//         tileset's frame and where they must land), "tolerance": metres for those }.
// The caller computes the expected places from the MT file and PROJ's cs2cs, not from the tileset.
// The camera is flown to the expected place (geodetic: looking straight down from above it, north
// up; ecef: looking at it obliquely); the check passes when the tileset is loaded, its bounding
// sphere's centre is within R/2 of the expected point, the model covers a good part of the picture
// and the centroid of its pixels is near the picture's centre, and every point of "points", put
// through the root tile's computed transform by Cesium, is within the tolerance of where
// Cesium.Cartesian3.fromDegrees puts its geodetic position. Everything is served from localhost:
// no Ion token, no imagery, no terrain, no globe; any request elsewhere is refused and fails.
import fs from 'node:fs';
import http from 'node:http';
import path from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const specFile = process.argv[2];
if (!specFile) { console.error('usage: node cesium_check.mjs SPEC.json'); process.exit(2); }
const spec = JSON.parse(fs.readFileSync(specFile, 'utf8'));
const dir = spec.tileset, shot = spec.screenshot, radius = Number(spec.radius);
if (!dir || !shot || !(radius > 0) || !(spec.geodetic || spec.ecef)) { console.error(`${specFile}: incomplete spec`); process.exit(2); }
const here = path.dirname(fileURLToPath(import.meta.url));
const cesiumDir = path.join(here, 'node_modules/cesium/Build/Cesium');

const page = `<!doctype html><html><head><meta charset="utf-8">
<script>window.CESIUM_BASE_URL = '/cesium/';</script>
<script src="/cesium/Cesium.js"></script>
<link href="/cesium/Widgets/widgets.css" rel="stylesheet">
<style>html,body,#c{margin:0;width:100%;height:100%;overflow:hidden;background:#000}</style></head>
<body><div id="c"></div></body></html>`;
const types = { '.js': 'text/javascript', '.json': 'application/json', '.glb': 'model/gltf-binary', '.css': 'text/css',
  '.wasm': 'application/wasm', '.png': 'image/png', '.svg': 'image/svg+xml' };
const server = http.createServer((req, res) => {
  const url = decodeURIComponent(new URL(req.url, 'http://x').pathname);
  let file = null;
  if (url === '/') { res.writeHead(200, { 'content-type': 'text/html' }); res.end(page); return; }
  if (url.startsWith('/cesium/')) file = path.join(cesiumDir, url.slice(8));
  else if (url.startsWith('/tiles/')) file = path.join(dir, url.slice(7));
  if (!file || file.includes('..') || !fs.existsSync(file) || fs.statSync(file).isDirectory()) { res.writeHead(404); res.end(); return; }
  res.writeHead(200, { 'content-type': types[path.extname(file)] || 'application/octet-stream' });
  fs.createReadStream(file).pipe(res);
});
await new Promise((r) => server.listen(0, '127.0.0.1', r));
const origin = `http://127.0.0.1:${server.address().port}`;

const browser = await chromium.launch({
  executablePath: '/usr/bin/chromium', headless: true,
  args: ['--no-sandbox', '--disable-gpu', '--disable-background-networking', '--disable-component-update', '--disable-sync',
    '--no-first-run', '--use-angle=swiftshader', '--enable-unsafe-swiftshader'],
});
const outside = [];
let failed = false;
try {
  const ctx = await browser.newContext({ viewport: { width: 640, height: 480 } });
  const p = await ctx.newPage();
  await p.route('**/*', (route) => {
    const u = route.request().url();
    if (u.startsWith(origin) || u.startsWith('data:') || u.startsWith('blob:')) return route.continue();
    outside.push(u);
    return route.abort();
  });
  p.on('console', (m) => { if (m.type() === 'error') console.error('page:', m.text()); });
  await p.goto(origin + '/');
  const result = await p.evaluate(async (spec) => {
    const radius = spec.radius;
    Cesium.Ion.defaultAccessToken = '';
    const viewer = new Cesium.Viewer('c', {
      baseLayer: false, globe: false, skyBox: false, skyAtmosphere: false, geocoder: false, baseLayerPicker: false,
      timeline: false, animation: false, homeButton: false, sceneModePicker: false, navigationHelpButton: false,
      fullscreenButton: false, infoBox: false, selectionIndicator: false, requestRenderMode: false,
      contextOptions: { webgl: { preserveDrawingBuffer: true } },
    });
    viewer.scene.backgroundColor = Cesium.Color.BLACK;
    viewer.scene.light = new Cesium.DirectionalLight({ direction: new Cesium.Cartesian3(0.3, -0.5, -0.8) });
    const tileset = await Cesium.Cesium3DTileset.fromUrl('/tiles/tileset.json', { maximumScreenSpaceError: 4 });
    // Shading from the screen-space derivatives of the position (the GLBs carry normals only when
    // the MT has them): the picture shows the surface, not only its silhouette. It multiplies the
    // material's own colour (white, the vertex colours, or a textured content's base-colour texture).
    tileset.customShader = new Cesium.CustomShader({
      lightingModel: Cesium.LightingModel.UNLIT,
      fragmentShaderText: `void fragmentMain(FragmentInput fsInput, inout czm_modelMaterial material) {
        vec3 p = fsInput.attributes.positionEC;
        vec3 n = normalize(cross(dFdx(p), dFdy(p)));
        material.diffuse *= 0.25 + 0.75 * abs(n.z);
      }`,
    });
    viewer.scene.primitives.add(tileset);
    let target;
    if (spec.geodetic) {
      // Flown to the expected geodetic position: straight down from 3.2 radii above it, north up.
      const [lon, lat, h] = spec.geodetic;
      target = Cesium.Cartesian3.fromDegrees(lon, lat, h);
      viewer.camera.setView({ destination: Cesium.Cartesian3.fromDegrees(lon, lat, h + radius * 3.2),
        orientation: { heading: 0, pitch: -Cesium.Math.PI_OVER_TWO, roll: 0 } });
    } else {
      target = new Cesium.Cartesian3(...spec.ecef);
      viewer.camera.lookAt(target, new Cesium.HeadingPitchRange(0.3, -0.6, radius * 3.2));
    }
    const t0 = performance.now();
    while (!tileset.tilesLoaded && performance.now() - t0 < 60000) await new Promise((r) => setTimeout(r, 100));
    for (let i = 0; i < 10; ++i) { viewer.scene.render(); await new Promise((r) => requestAnimationFrame(r)); }
    const bs = tileset.boundingSphere;
    // Points of the tileset's frame through the root's transform (as Cesium composes it), against
    // where Cesium's ellipsoid puts their expected geodetic positions.
    const points = (spec.points || []).map((q) => {
      const world = Cesium.Matrix4.multiplyByPoint(tileset.root.computedTransform, new Cesium.Cartesian3(...q.local), new Cesium.Cartesian3());
      const expected = Cesium.Cartesian3.fromDegrees(...q.geodetic);
      return Cesium.Cartesian3.distance(world, expected);
    });
    const canvas = viewer.scene.canvas;
    const gl2d = document.createElement('canvas');
    gl2d.width = canvas.width; gl2d.height = canvas.height;
    const g = gl2d.getContext('2d');
    g.drawImage(canvas, 0, 0);
    const px = g.getImageData(0, 0, gl2d.width, gl2d.height).data;
    let n = 0, sx = 0, sy = 0;
    for (let y = 0; y < gl2d.height; ++y)
      for (let x = 0; x < gl2d.width; ++x) {
        const k = 4 * (y * gl2d.width + x);
        if (px[k] + px[k + 1] + px[k + 2] > 30) { n++; sx += x; sy += y; }
      }
    return {
      loaded: tileset.tilesLoaded, seconds: (performance.now() - t0) / 1000,
      sphereCenter: [bs.center.x, bs.center.y, bs.center.z], sphereRadius: bs.radius, points,
      target: [target.x, target.y, target.z],
      coverage: n / (gl2d.width * gl2d.height), centroid: n ? [sx / n / gl2d.width, sy / n / gl2d.height] : null,
      triangles: tileset.statistics ? tileset.statistics.numberOfTrianglesSelected : -1,
    };
  }, spec);
  await p.screenshot({ path: shot });
  const d = Math.hypot(...result.sphereCenter.map((c, i) => c - result.target[i]));
  const worst = result.points.length ? Math.max(...result.points) : 0;
  console.log(`cesium: loaded ${result.loaded} in ${result.seconds.toFixed(1)} s; bounding sphere centre ${d.toFixed(3)} m from the expected ` +
    `point (radius ${result.sphereRadius.toFixed(2)}); coverage ${(100 * result.coverage).toFixed(1)}%; centroid ` +
    `${result.centroid ? result.centroid.map((c) => c.toFixed(3)).join(',') : '-'}; triangles ${result.triangles}; ` +
    (result.points.length ? `${result.points.length} points within ${worst.toExponential(2)} m of their geodetic positions; ` : '') +
    `screenshot ${shot}`);
  const why = [];
  if (!result.loaded) why.push('the tileset did not finish loading');
  if (!(d < radius * 0.5)) why.push(`the tileset is ${d} m from where the model should be`);
  if (!(result.coverage > 0.03)) why.push('the model covers less than 3% of the picture');
  if (!result.centroid || Math.hypot(result.centroid[0] - 0.5, result.centroid[1] - 0.5) > 0.15)
    why.push('the model is not drawn around the expected point (centroid of its pixels off the picture centre)');
  if (!(worst <= (spec.tolerance ?? 1e-3))) why.push(`a point of the tileset's frame lands ${worst} m from its geodetic position`);
  if (outside.length) why.push(`requests outside localhost: ${outside.slice(0, 3).join(' ')}`);
  if (why.length) { console.error('cesium: FAILED: ' + why.join('; ')); failed = true; }
} finally {
  await browser.close();
  server.close();
}
process.exit(failed ? 1 : 0);
