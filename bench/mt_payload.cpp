// Where the bytes of an MT file go, and how fast its patches decode (bench/size_scan.sh runs it).
//   bench_mt_payload FILE.mt [--repeat R] [--reencode] [--json] [--same-as OTHER.mt]
// Per level (of the node whose fragment holds the patch) and in total, bytes per input triangle:
//   header   PayloadHeader + the two frame sizes (32 bytes per patch),
//   index    the index code: the zstd frame (v2 payloads, and v3 ones that keep it there: it holds
//            the attribute code too, when there is one) or its range-coded bytes (v3),
//   attr     the frame when it holds only the sizes and the attribute code (v3),
//   position the range-coded positions (meshopt v2/v3 payloads),
//   pad      the alignment padding between payloads, meta = DAG + index + header + footer.
// Decode: every payload held in memory, decodePatch on one thread, best of R passes, as payload
// MB/s and M stored triangles/s (what the renderer's loader threads do).
// --reencode: decode every patch and encode it again with this binary's codec, with the options
// the builder uses (level >= 1 = simplified), and print the sizes: a codec change measured on the
// patches of a real build without rebuilding it (the grid step, hence the patches, stay the same).
// --same-as: checks that OTHER.mt (e.g. the same input built by another codec version) has the same
// grid, DAG, node errors and, patch by patch, the same triangles on the same grid points (in any
// order and rotation), and exits 1 if not: a codec change that keeps geometry and errors.
#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include <zstd.h>

#include "mtfile/mt_file.h"
#include "mtfile/patch_codec.h"

using namespace mt;
using Clock = std::chrono::steady_clock;

namespace {

struct Split {
  uint64_t patches = 0, triangles = 0, vertices = 0, payload = 0, header = 0, frame = 0, rawIndex = 0,
           rawAttr = 0, position = 0, reencoded = 0, reencodedPosition = 0;
  void add(const Split& o) {
    patches += o.patches, triangles += o.triangles, vertices += o.vertices, payload += o.payload;
    header += o.header, frame += o.frame, rawIndex += o.rawIndex, rawAttr += o.rawAttr;
    position += o.position, reencoded += o.reencoded, reencodedPosition += o.reencodedPosition;
  }
};

void split(const std::vector<uint8_t>& p, format::Codec codec, Split& s) {
  PayloadBytes b = payloadBytes(p.data(), p.size(), codec);
  s.header += b.header, s.frame += b.index, s.rawAttr += b.attributes, s.position += b.positions + b.other;
}

uint64_t positionBytes(const std::vector<uint8_t>& p, format::Codec codec) {
  return payloadBytes(p.data(), p.size(), codec).positions;
}

// The patch's triangles as sorted grid-coordinate triples, each rotated to start at its smallest
// corner (winding kept): equal for two codings of the same triangles in any order and numbering.
std::vector<std::array<uint32_t, 9>> triangleKeys(const DecodedPatch& d) {
  std::vector<std::array<uint32_t, 9>> keys(d.triangleCount());
  for (size_t t = 0; t < keys.size(); ++t) {
    std::array<uint32_t, 3> c[3];
    for (int k = 0; k < 3; ++k)
      for (int x = 0; x < 3; ++x) c[k][x] = d.q[d.triangles[t * 3 + k] * 3 + x];
    int r = 0;
    for (int k = 1; k < 3; ++k)
      if (c[k] < c[r]) r = k;
    for (int k = 0; k < 3; ++k)
      for (int x = 0; x < 3; ++x) keys[t][k * 3 + x] = c[(r + k) % 3][x];
  }
  std::sort(keys.begin(), keys.end());
  return keys;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s FILE.mt [--repeat R] [--reencode] [--json] [--same-as OTHER.mt]\n", argv[0]);
    return 2;
  }
  int repeat = 3;
  bool reencode = false, json = false;
  const char* sameAs = nullptr;
  for (int i = 2; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--repeat") && i + 1 < argc) repeat = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--reencode")) reencode = true;
    else if (!std::strcmp(argv[i], "--json")) json = true;
    else if (!std::strcmp(argv[i], "--same-as") && i + 1 < argc) sameAs = argv[++i];
  }
  try {
    auto r = MtFileReader::open(argv[1]);
    if (sameAs) {
      auto o = MtFileReader::open(sameAs);
      auto fail = [&](const std::string& what) {
        std::fprintf(stderr, "%s and %s differ: %s\n", argv[1], sameAs, what.c_str());
        return 1;
      };
      if (r->grid().step != o->grid().step || std::memcmp(r->grid().origin, o->grid().origin, sizeof r->grid().origin))
        return fail("grid");
      if (r->nodes().size() != o->nodes().size() || r->patches().size() != o->patches().size()) return fail("counts");
      for (size_t i = 0; i < r->nodes().size(); ++i)
        if (r->nodes()[i].error != o->nodes()[i].error || r->nodes()[i].triangles != o->nodes()[i].triangles)
          return fail("node " + std::to_string(i));
      for (uint32_t i = 0; i < r->patches().size(); ++i)
        if (r->patches()[i].arc != o->patches()[i].arc || triangleKeys(r->readPatch(i)) != triangleKeys(o->readPatch(i)))
          return fail("patch " + std::to_string(i));
      std::printf("%s and %s: same grid, %zu nodes with the same errors, %zu patches with the same triangles\n",
                  argv[1], sameAs, r->nodes().size(), r->patches().size());
      return 0;
    }
    const auto& hdr = r->header();
    bool meshopt = r->codec() == format::Codec::Meshopt;
    QuantizationGrid grid = r->grid();
    std::vector<uint32_t> levelOf(r->patches().size(), 0);
    for (const auto& a : r->arcs()) {
      const auto& pr = r->patchRefs();
      for (uint32_t k = 0; k < a.patchCount; ++k) levelOf[pr[a.firstPatchRef + k]] = r->nodes()[a.from].level;
    }
    std::vector<std::vector<uint8_t>> payloads(r->patches().size());
    std::vector<Split> levels(hdr.levelCount + 1);
    uint64_t payloadEnd = hdr.headerSize;
    for (uint32_t i = 0; i < payloads.size(); ++i) {
      payloads[i] = r->readPayload(i);
      const auto& rec = r->patches()[i];
      Split& s = levels[levelOf[i]];
      ++s.patches;
      s.triangles += rec.triangles;
      s.vertices += rec.vertices;
      s.payload += rec.size;
      payloadEnd = std::max<uint64_t>(payloadEnd, rec.offset + rec.size);
      split(payloads[i], r->codec(), s);
      if (reencode) {
        DecodedPatch d = decodePatch(payloads[i].data(), payloads[i].size(), r->codec(), grid);
        std::vector<double> pos(d.q.size());
        for (size_t k = 0; k < d.q.size(); ++k) pos[k] = grid.dequantize(int(k % 3), d.q[k]);
        PatchInput in{pos.data(), d.vertexCount(), d.triangles.data(), d.triangleCount(),
                      d.normals.empty() ? nullptr : d.normals.data(), d.colors.empty() ? nullptr : d.colors.data()};
        PatchCodecOptions o;
        o.codec = r->codec();
        o.normals = !d.normals.empty();
        o.simplified = levelOf[i] >= 1 || std::getenv("MT_FAN0");
        std::vector<uint8_t> e = encodePatch(in, grid, o);
        DecodedPatch back = decodePatch(e.data(), e.size(), r->codec(), grid);
        if (back.q.size() != d.q.size() || back.triangles.size() != d.triangles.size() ||
            triangleKeys(back) != triangleKeys(d))
          throw std::runtime_error("re-encoded patch " + std::to_string(i) + " does not round-trip");
        s.reencoded += e.size();
        if (meshopt) s.reencodedPosition += positionBytes(e, r->codec());
      }
    }
    Split total;
    for (const Split& s : levels) total.add(s);
    // Decode speed: one thread, payloads in memory, best of `repeat` passes.
    double best = 1e30;
    uint64_t check = 0;
    for (int k = 0; k < repeat; ++k) {
      auto t0 = Clock::now();
      for (const auto& p : payloads) check += decodePatch(p.data(), p.size(), r->codec(), grid).q.size();
      best = std::min(best, std::chrono::duration<double>(Clock::now() - t0).count());
    }
    double in = double(hdr.inputTriangles);
    uint64_t pad = payloadEnd - hdr.headerSize - total.payload;
    uint64_t meta = r->fileSize() - total.payload - pad;
    if (json) {
      std::printf("{\"file_bytes\": %llu, \"input_triangles\": %llu, \"stored_triangles\": %llu, \"bpt\": %.4f, "
                  "\"header\": %.4f, \"index\": %.4f, \"attr\": %.4f, \"position\": %.4f, \"pad\": %.4f, "
                  "\"meta\": %.4f, \"decode_mb_s\": %.2f, \"decode_mtri_s\": %.3f, \"grid_step\": %.9g",
                  (unsigned long long)r->fileSize(), (unsigned long long)hdr.inputTriangles,
                  (unsigned long long)total.triangles, r->fileSize() / in, total.header / in, total.frame / in,
                  total.rawAttr / in, total.position / in, pad / in, meta / in, total.payload / best / 1e6,
                  total.triangles / best / 1e6, grid.step);
      if (reencode) std::printf(", \"reencoded_bpt\": %.4f", (r->fileSize() - total.payload + total.reencoded) / in);
      std::printf("}\n");
      return 0;
    }
    std::printf("%s: %llu bytes, %.4f B/input triangle (%s), grid step %.6g\n", argv[1],
                (unsigned long long)r->fileSize(), r->fileSize() / in, meshopt ? "meshopt" : "not split",
                grid.step);
    std::printf("level patches   tri/patch  V/T   B/stored tri: header  index  (attr)  position  | B/input tri%s\n",
                reencode ? "  | reencoded B/stored (pos)" : "");
    auto line = [&](const char* name, const Split& s) {
      double t = double(std::max<uint64_t>(s.triangles, 1));
      std::printf("%5s %7llu %9.0f %6.3f   %13.3f %6.3f (%5.3f) %8.3f   | %8.3f", name, (unsigned long long)s.patches,
                  s.triangles / double(std::max<uint64_t>(s.patches, 1)), s.vertices / t, s.header / t,
                  s.frame / t, s.rawAttr / t, s.position / t, s.payload / in);
      if (reencode) std::printf("  | %6.3f (%5.3f)", s.reencoded / t, s.reencodedPosition / t);
      std::printf("\n");
    };
    for (size_t l = 0; l < levels.size(); ++l)
      if (levels[l].patches) line(std::to_string(l).c_str(), levels[l]);
    line("all", total);
    std::printf("per input triangle: header %.3f  index %.3f  attr %.3f  position %.3f  pad %.3f  meta %.3f\n",
                total.header / in, total.frame / in, total.rawAttr / in, total.position / in, pad / in, meta / in);
    if (reencode)
      std::printf("re-encoded with this binary: %.4f B/input triangle (positions %.3f)\n",
                  (r->fileSize() - total.payload + total.reencoded) / in, total.reencodedPosition / in);
    std::printf("decode (1 thread, best of %d): %.1f MB/s payload, %.2f M stored triangles/s (%.3f s)\n", repeat,
                total.payload / best / 1e6, total.triangles / best / 1e6, best);
    (void)check;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s\n", e.what());
    return 1;
  }
  return 0;
}
