// The web viewer's module: open an MT file by URL, add it to a three.js scene.
export { MTObject } from './mt_object.js';
export { HttpSource, NoRangeError } from './source.js';
export { openMtFile } from './mtfile.js';
export { ExtractRender } from './extract.js';
export { makeView } from './camera.js';
