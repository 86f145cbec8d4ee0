// The browser's decoder of the meshopt payloads' range-coded stream (mt_format.h,
// kPayloadConnectivity with kPayloadPositionContexts, what mtbuild writes): the connectivity code
// and the position code, compiled to WebAssembly from the C++ decoder itself
// (mtfile/patch_codec_connectivity.cpp, mtfile/patch_codec_positions.cpp), so the browser and
// mtfile decode with one implementation. The page's worker (web/src/codec_wasm.js) does the rest of
// a payload (header, zstd frame, attributes) in JavaScript.
//
// Interface (plain data, one patch at a time, not reentrant; a WASI reactor: _initialize first):
//   mt_input(size)            -> where to copy the stream's `size` bytes
//   mt_decode(T, V)           decodes the stream (the payload's bytes after its frame) into T
//                             triangles over V vertices; 1 on success. A damaged stream traps
//                             (bad() below): the message is then at mt_error() (mt_error_size()
//                             bytes; none when the trap was not bad()'s). The next mt_input
//                             starts clean (the arena below) once the page has put back
//                             __stack_pointer (exported), which the trap left where it was.
//   mt_triangles()            3T vertex indices
//   mt_positions()            3V grid coordinates relative to the payload's qMin
#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <new>
#include <string>
#include <vector>

#include "mtfile/patch_codec_detail.h"
#include "mtfile/patch_codec_positions.h"
#include "mtfile/range_coder.h"

namespace {

// The module's heap is an arena emptied at each mt_input: every allocation of a decode (the C++
// decoders' working arrays, the results) lives until the next patch, and a trap, which skips the
// destructors, leaks nothing. One block, sized to the largest patch so far; what does not fit
// in it goes to its own malloc block (freed at the next reset, which then makes the block larger).
struct Arena {
  struct Spill {
    Spill* next;
    alignas(16) unsigned char data[];
  };
  unsigned char* block = nullptr;
  size_t blockSize = 0, used = 0, spilled = 0;
  Spill* spills = nullptr;

  // Empties the arena. A larger block is made before the old one goes: if it cannot be had, the
  // old one stays and what does not fit spills again.
  void reset() {
    size_t wanted = used + spilled;
    for (Spill* s = spills; s;) {
      Spill* next = s->next;
      std::free(s);
      s = next;
    }
    spills = nullptr;
    used = spilled = 0;
    if (wanted > blockSize && wanted < SIZE_MAX / 3) {
      size_t size = wanted + wanted / 2;
      if (auto* b = static_cast<unsigned char*>(std::malloc(size))) {
        std::free(block);
        block = b;
        blockSize = size;
      }
    }
  }
  void* allocate(size_t n) {
    if (n > SIZE_MAX / 2) __builtin_trap();
    n = (std::max<size_t>(n, 1) + 15) & ~size_t(15);  // never null, 16-byte aligned
    if (n <= blockSize - used) {
      void* p = block + used;
      used += n;
      return p;
    }
    Spill* s = static_cast<Spill*>(std::malloc(sizeof(Spill) + n));
    if (!s) __builtin_trap();  // no memory: the page sees a trap that is not bad()'s
    s->next = spills;
    spills = s;
    spilled += n;
    return s->data;
  }
};
Arena arena;

// What a decode keeps, made afresh in the arena by mt_input.
struct State {
  std::vector<uint8_t> input;
  std::vector<uint32_t> triangles, positions;
  std::string error;
};
State* state = nullptr;

}  // namespace

void* operator new(size_t n) { return arena.allocate(n); }
void* operator new[](size_t n) { return arena.allocate(n); }
void operator delete(void*) noexcept {}
void operator delete[](void*) noexcept {}
void operator delete(void*, size_t) noexcept {}
void operator delete[](void*, size_t) noexcept {}

namespace mt::codec_detail {
// The C++ decoders report damage by bad(); without exceptions the message is kept and the call
// ends in a trap, which the page catches as a WebAssembly.RuntimeError.
[[noreturn]] void bad(const std::string& what) {
  state->error = what;
  __builtin_trap();
}
}  // namespace mt::codec_detail

extern "C" {

__attribute__((export_name("mt_input"))) uint8_t* mtInput(uint32_t size) {
  state = nullptr;
  arena.reset();
  state = new State;
  state->input.resize(size);
  return state->input.data();
}

__attribute__((export_name("mt_decode"))) uint32_t mtDecode(uint32_t triangleCount, uint32_t vertexCount) {
  using namespace mt::codec_detail;
  std::vector<uint8_t>& in = state->input;
  // The counts the decoders size their arrays by, bounded as the C++ reader bounds them (a patch
  // has at most kMaxPayloadTriangles triangles, each brings at most three new vertices).
  if (triangleCount > mt::format::kMaxPayloadTriangles || uint64_t(vertexCount) > 3 * uint64_t(triangleCount))
    bad("counts out of range for a patch");
  RangeDecoder rc(in.data(), in.data() + in.size());
  decodeConnectivity(rc, triangleCount, vertexCount, state->triangles);
  decodeContextPositions(rc, state->triangles, vertexCount, state->positions);
  return 1;
}

__attribute__((export_name("mt_triangles"))) const uint32_t* mtTriangles() { return state->triangles.data(); }
__attribute__((export_name("mt_positions"))) const uint32_t* mtPositions() { return state->positions.data(); }
__attribute__((export_name("mt_error"))) const char* mtError() { return state ? state->error.data() : nullptr; }
__attribute__((export_name("mt_error_size"))) uint32_t mtErrorSize() { return state ? uint32_t(state->error.size()) : 0; }

}  // extern "C"
