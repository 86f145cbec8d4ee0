// web_cut_nodes FILE.mt VIEWS TOLERANCE WIDTH HEIGHT: ExtractRender's converged cut for each view,
// one line per view, "view K: n0 n1 ..." (the nodes of the cut's set S, ascending). The web
// viewer's port of ExtractRender (web/src/extract.js, run by web/test/cut_nodes.mjs) must print the
// same lines: tests/web_cut_compare.sh compares them.
//
// VIEWS: one view per line, "EX EY EZ TX TY TZ" in unit space (p = centre + radius * v of the
// scene's bounding sphere, as mtrender's camera paths), up = +z, 45 degree vertical field of view.
// Convergence: no cache (everything resident), an unbounded render budget and no deadline, so the
// update is repeated until a frame moves nothing.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>

#include "base/error.h"
#include "mtrender/camera.h"
#include "mtrender/extract.h"
#include "mtrender/scene.h"

// web_cut_nodes --decode FILE.mt: every patch (and texture) decoded by the C++ decoder, printed as
// web/test/decode_check.mjs prints the web decoder's (patches, triangles, vertices, the sum of
// every decoded grid coordinate, and a weighted sum of every patch's index list in decoded order:
// sum over i of (i % 1021 + 1) * triangles[i], modulo 2^64, which a changed order or index changes).
// A textured file (version 6) adds "textures N imagebytes B uvsum U": the patches with a texture,
// their images' bytes, and over every corner k of each texture's coordinates, in decoded order,
// the sum of (k % 1021 + 1) * (s + 3 t) with (s, t) the coordinate in 1/16 texel (mt_format.h
// kUvCornerLists), which a changed coordinate or order changes.
static int decodeAll(const char* path) {
  auto r = mt::MtFileReader::open(path);
  uint64_t tris = 0, verts = 0, qsum = 0, tsum = 0, textures = 0, imageBytes = 0, uvsum = 0;
  for (uint32_t i = 0; i < r->patches().size(); ++i) {
    mt::DecodedPatch d = r->readPatch(i);
    tris += d.triangleCount();
    verts += d.q.size() / 3;
    for (uint32_t v : d.q) qsum += v;
    for (size_t k = 0; k < d.triangles.size(); ++k) tsum += uint64_t(k % 1021 + 1) * d.triangles[k];
    if (!r->hasTextures()) continue;
    const mt::TexturePayload t = r->readTexture(i, d);
    if (t.image.empty()) continue;
    ++textures;
    imageBytes += t.image.size();
    for (size_t k = 0; k < t.cornerUV.size() / 2; ++k) {
      const uint64_t s = uint64_t(std::lround(double(t.cornerUV[2 * k]) * 16.0 * t.width));
      const uint64_t q = uint64_t(std::lround(double(t.cornerUV[2 * k + 1]) * 16.0 * t.height));
      uvsum += uint64_t(k % 1021 + 1) * (s + 3 * q);
    }
  }
  std::printf("patches %zu triangles %llu vertices %llu qsum %llu tsum %llu", r->patches().size(), (unsigned long long)tris,
              (unsigned long long)verts, (unsigned long long)qsum, (unsigned long long)tsum);
  if (r->hasTextures())
    std::printf(" textures %llu imagebytes %llu uvsum %llu", (unsigned long long)textures, (unsigned long long)imageBytes,
                (unsigned long long)uvsum);
  std::printf("\n");
  return 0;
}

int main(int argc, char** argv) {
  if (argc == 3 && std::string(argv[1]) == "--decode") {
    try {
      return decodeAll(argv[2]);
    } catch (const mt::Error& e) {
      std::fprintf(stderr, "web_cut_nodes: %s\n", e.what());
      return 1;
    }
  }
  if (argc != 6) {
    std::fprintf(stderr, "usage: web_cut_nodes FILE.mt VIEWS TOLERANCE WIDTH HEIGHT\n");
    return 2;
  }
  try {
    mt::render::Scene scene({argv[1]});
    double c[3], r;
    scene.boundingSphere(c, r);
    const glm::dvec3 center(c[0], c[1], c[2]);
    mt::render::ExtractOptions opt;
    opt.pixelTolerance = std::atof(argv[3]);
    opt.fixedTriangles = uint64_t(1) << 60;
    opt.extractMs = 1e9;
    opt.prefetch = false;
    const int width = std::atoi(argv[4]), height = std::atoi(argv[5]);
    std::ifstream in(argv[2]);
    if (!in) mt::fail(argv[2], "cannot open the views");
    std::string line;
    int k = 0;
    while (std::getline(in, line)) {
      std::istringstream ss(line);
      double v[6];
      int n = 0;
      while (n < 6 && ss >> v[n]) ++n;
      if (n == 0) continue;
      if (n != 6) mt::fail(argv[2], "line " + std::to_string(k + 1) + ": expected 6 numbers");
      mt::render::CameraPose pose;
      pose.eye = center + r * glm::dvec3(v[0], v[1], v[2]);
      pose.target = center + r * glm::dvec3(v[3], v[4], v[5]);
      const mt::render::View view = mt::render::makeView(pose, width, height, center, r);
      mt::render::ExtractRender er(scene, nullptr, nullptr, opt);
      er.start(0);
      for (uint64_t frame = 1; frame < 100000; ++frame) {
        mt::render::FrameStats st = er.update(frame, view, view);
        if (st.refinements == 0 && st.coarsenings == 0) break;
      }
      std::printf("view %d:", k);
      const auto& s = er.inSet();
      for (size_t i = 0; i < s.size(); ++i)
        if (s[i]) std::printf(" %zu", i);
      std::printf("\n");
      ++k;
    }
  } catch (const mt::Error& e) {
    std::fprintf(stderr, "web_cut_nodes: %s\n", e.what());
    return 1;
  }
  return 0;
}
