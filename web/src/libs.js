// Where the worker finds the npm decoders and our own WebAssembly one. The defaults resolve inside
// this package: node_modules next to src/ (the layout `npm ci` makes and mtserve/nginx serve) and
// dist/ (CMake builds web/wasm/ into it); an application that bundles or hosts them elsewhere
// passes its own URLs (MTObject.open's `libs` option).
export function defaultLibUrls() {
  const u = (p) => new URL(p, import.meta.url).href;
  return {
    zstd: u('../node_modules/fzstd/esm/index.mjs'),
    meshopt: u('../node_modules/meshoptimizer/meshopt_decoder.mjs'),
    xxhash: u('../node_modules/xxhash-wasm/esm/xxhash-wasm.js'),
    // Draco's decoder as the three package ships it (wasm + its Emscripten wrapper).
    dracoWrapper: u('../node_modules/three/examples/jsm/libs/draco/draco_wasm_wrapper.js'),
    dracoWasm: u('../node_modules/three/examples/jsm/libs/draco/draco_decoder.wasm'),
    // Ours: the version-4 stream's decoder, built by CMake from the C++ (web/wasm/).
    decoder: u('../dist/mt_decode.wasm'),
  };
}
