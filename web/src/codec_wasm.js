// The WebAssembly decoder of the meshopt payloads' range-coded stream (kPayloadConnectivity with
// kPayloadPositionContexts, what mtbuild writes): web/wasm/mt_decode.cpp, which is mtfile's C++
// decoder (patch_codec_connectivity.cpp, patch_codec_positions.cpp) compiled to WebAssembly, built
// by CMake into web/dist/mt_decode.wasm. It decodes faster than the JavaScript port
// (codec_meshopt.js; docs/web.md has the figures), which stays for the earlier payload versions and
// for a page served without the built module. codec_meshopt.js calls it through `libs.wasm`.
import { bad } from './codec_meshopt.js';

export class WasmDecoder {
  /** @param {WebAssembly.Module} module */
  constructor(module) {
    this.module = module;
    this.decodes = 0;  // streams decoded (the tests check the module did the work)
    this._instantiate();
  }
  _instantiate() {
    // A WASI reactor that imports nothing: _initialize runs its static constructors.
    this.x = new WebAssembly.Instance(this.module, {}).exports;
    this.x._initialize();
    // The C++ stack's pointer with no call under way: a trap skips the epilogues that would give
    // back its frames, so it is put back after one (else each trap leaves it lower, until the
    // stack runs over the module's data).
    this.stackTop = this.x.__stack_pointer.value;
  }
  /**
   * The triangles and grid coordinates (relative to the payload's qMin) of the range-coded stream
   * `data` (the payload's bytes after its frame). Throws BadPayload with the C++ decoder's message
   * on a damaged stream.
   * @returns {{triangles: Uint32Array, positions: Uint32Array}} triangles are the caller's;
   *   positions is a view into the module's memory, valid until the next decode.
   */
  decode(data, triangleCount, vertexCount) {
    const x = this.x;
    try {
      const at = x.mt_input(data.length);
      new Uint8Array(x.memory.buffer, at, data.length).set(data);
      x.mt_decode(triangleCount, vertexCount);
    } catch (e) {
      // A trap (RuntimeError), or the engine's stack overflow (RangeError).
      if (!(e instanceof WebAssembly.RuntimeError || e instanceof RangeError)) throw e;
      x.__stack_pointer.value = this.stackTop;
      // bad() kept its message and trapped; the next decode starts clean (its heap is an arena
      // emptied by mt_input). Any other trap (memory refused, a fault) leaves the module as it
      // was: a new instance replaces it.
      const n = x.mt_error_size();
      if (n) bad(new TextDecoder().decode(new Uint8Array(x.memory.buffer, x.mt_error(), n)));
      this._instantiate();
      bad(`the decoder trapped (${e.message})`);
    }
    ++this.decodes;
    const buf = x.memory.buffer;
    return {
      triangles: new Uint32Array(buf, x.mt_triangles(), triangleCount * 3).slice(),
      positions: new Uint32Array(buf, x.mt_positions(), vertexCount * 3),
    };
  }
}

/**
 * The decoder from a URL (fetched) or the module's bytes.
 * @param {string|URL|ArrayBuffer|Uint8Array} source
 */
export async function loadWasmDecoder(source) {
  let bytes = source;
  if (typeof source === 'string' || source instanceof URL) {
    const r = await fetch(source);
    if (!r.ok) throw new Error(`${source}: HTTP ${r.status}`);
    bytes = await r.arrayBuffer();
  }
  return new WasmDecoder(await WebAssembly.compile(bytes));
}
