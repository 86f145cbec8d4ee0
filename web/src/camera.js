// Views: a port of mtrender/camera.cpp's makeView (glm's lookAt and perspective, in double, so
// frustum planes and pixels-per-unit match ExtractRender's to the last bit or so) and extrapolate.

const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const length = (a) => Math.sqrt(dot(a, a));
// glm::normalize: v * inversesqrt(dot(v, v))
const normalize = (a) => scale(a, 1 / Math.sqrt(dot(a, a)));

export { dot, sub, add, scale, cross, length, normalize };

/**
 * @typedef {{eye:number[], target:number[], up?:number[], fovDeg?:number}} CameraPose
 * @typedef {{eye:number[], forward:number[], planes:number[][], pixelsPerUnit:number,
 *            nearPlane:number, farPlane:number, width:number, height:number,
 *            viewMatrix:number[][], projMatrix:number[][]}} View
 */

/** makeView(pose, width, height, sceneCenter, sceneRadius): near/far fitted to the scene's sphere. */
export function makeView(pose, width, height, c, r) {
  const up0 = pose.up || [0, 0, 1];
  const fovDeg = pose.fovDeg || 45;
  let dir = sub(pose.target, pose.eye);
  if (length(dir) < 1e-12) dir = [0, 1, 0];
  const forward = normalize(dir);
  let up = up0;
  if (length(cross(forward, up)) < 1e-6) up = Math.abs(forward[2]) < 0.9 ? [0, 0, 1] : [0, 1, 0];
  const dist = length(sub(c, pose.eye));
  const farPlane = dist + r * 1.01;
  let nearPlane = Math.max(r * 5e-4, (dist - r) * 0.9);
  if (nearPlane >= farPlane) nearPlane = farPlane * 1e-3;
  const fovy = fovDeg * 0.017453292519943295;
  const pixelsPerUnit = height / (2.0 * Math.tan(fovy / 2));
  // glm::lookAt (right-handed), as rows of the matrix.
  const center = add(pose.eye, forward);
  const f = normalize(sub(center, pose.eye));
  const s = normalize(cross(f, up));
  const u = cross(s, f);
  const V = [
    [s[0], s[1], s[2], -dot(s, pose.eye)],
    [u[0], u[1], u[2], -dot(u, pose.eye)],
    [-f[0], -f[1], -f[2], dot(f, pose.eye)],
    [0, 0, 0, 1],
  ];
  // glm::perspective (right-handed, depth -1..1).
  const aspect = width / height, th = Math.tan(fovy / 2);
  const P = [
    [1 / (aspect * th), 0, 0, 0],
    [0, 1 / th, 0, 0],
    [0, 0, -(farPlane + nearPlane) / (farPlane - nearPlane), -(2 * farPlane * nearPlane) / (farPlane - nearPlane)],
    [0, 0, -1, 0],
  ];
  const M = [0, 1, 2, 3].map((i) => [0, 1, 2, 3].map((j) => {
    let acc = 0;
    for (let k = 0; k < 4; ++k) acc += P[i][k] * V[k][j];
    return acc;
  }));
  const rowAdd = (a, b, sg) => [a[0] + sg * b[0], a[1] + sg * b[1], a[2] + sg * b[2], a[3] + sg * b[3]];
  const planes = [
    rowAdd(M[3], M[0], 1), rowAdd(M[3], M[0], -1),
    rowAdd(M[3], M[1], 1), rowAdd(M[3], M[1], -1),
    rowAdd(M[3], M[2], 1), rowAdd(M[3], M[2], -1),
  ].map((p) => {
    const l = Math.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
    return [p[0] / l, p[1] / l, p[2] / l, p[3] / l];
  });
  return { eye: pose.eye.slice(), forward, planes, pixelsPerUnit, nearPlane, farPlane, width, height, viewMatrix: V, projMatrix: P };
}

/** The pose `frames` frames ahead, extrapolating prev -> cur (camera.cpp extrapolate). */
export function extrapolate(prev, cur, frames) {
  const eye = add(cur.eye, scale(sub(cur.eye, prev.eye), frames));
  const d0 = normalize(sub(prev.target, prev.eye)), d1 = normalize(sub(cur.target, cur.eye));
  let d = add(d1, scale(sub(d1, d0), frames));
  if (length(d) < 1e-9) d = d1;
  const target = add(eye, scale(normalize(d), length(sub(cur.target, cur.eye))));
  return { eye, target, up: cur.up, fovDeg: cur.fovDeg };
}

/** The default view: from the -y side, slightly above, the whole model in view. */
export function defaultPose(c, r) {
  return { eye: [c[0], c[1] - 2.2 * r, c[2] + 1.1 * r], target: c.slice(), up: [0, 0, 1], fovDeg: 45 };
}
