// The textured test grid: see textured_grid.h.
#include "testing/textured_grid.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <vector>

#include "texture/image_codec.h"

namespace mt::testing {

double texturedGridHeight(double x, double y) { return 0.08 * std::sin(6.0 * x) * std::cos(5.0 * y); }

void texturedColor(double x, double y, uint8_t rgb[3]) {
  const int cx = int(std::floor(x * 8)), cy = int(std::floor(y * 8));
  const bool check = ((cx + cy) & 1) != 0;
  const bool stripe = std::fmod(x + 2 * y + 10, 0.25) < 0.04;
  rgb[0] = uint8_t(check ? 220 : 40);
  rgb[1] = uint8_t(stripe ? 240 : 30 + int(180 * x));
  rgb[2] = uint8_t(30 + int(200 * y));
}

std::string writeTexturedGrid(const std::string& dir, const std::string& name, const TexturedGridOptions& o) {
  const int n = o.n, C = o.charts, T = o.textureSize;
  const int per = n / C;  // quads per chart side (n divisible by C)
  // Chart c = (ci, cj) goes to texture cell perm[c] of a C x C layout (a fixed shuffle).
  std::vector<int> perm(size_t(C * C));
  for (int c = 0; c < C * C; ++c) perm[size_t(c)] = (c * 7 + 3) % (C * C);
  for (int c = 0; c < C * C; ++c)  // make it a permutation when 7 shares a factor with C*C
    for (int d = 0; d < c; ++d)
      if (perm[size_t(d)] == perm[size_t(c)]) perm[size_t(c)] = (perm[size_t(c)] + 1) % (C * C), d = -1;
  const double cell = 1.0 / C, margin = 2.0 / T;  // a 2-texel gutter inside each cell
  auto uvOf = [&](int ci, int cj, int i, int j, double& u, double& v) {
    const int p = perm[size_t(cj * C + ci)];
    const double fx = double(i - ci * per) / per, fy = double(j - cj * per) / per;
    u = (p % C) * cell + margin + fx * (cell - 2 * margin);
    v = (p / C) * cell + margin + fy * (cell - 2 * margin);
  };
  // The texture: for each texel, the surface point it shows.
  tex::RgbImage img(T, T);
  for (int ty = 0; ty < T; ++ty)
    for (int tx = 0; tx < T; ++tx) {
      const double u = (tx + 0.5) / T, v = 1.0 - (ty + 0.5) / T;  // row 0 is the top (v = 1)
      const int p = std::min(C * C - 1, int(v / cell) * C + std::min(C - 1, int(u / cell)));
      int chart = 0;
      for (int c = 0; c < C * C; ++c)
        if (perm[size_t(c)] == p) chart = c;
      const double fx = std::clamp((u - (p % C) * cell - margin) / (cell - 2 * margin), 0.0, 1.0);
      const double fy = std::clamp((v - (p / C) * cell - margin) / (cell - 2 * margin), 0.0, 1.0);
      const double x = ((chart % C) + fx) * cell, y = ((chart / C) + fy) * cell;
      texturedColor(x, y, img.pixel(tx, ty));
    }
  const std::string image = name + (o.jpeg ? ".jpg" : ".png");
  tex::writeFileAtomically(dir + "/" + image, o.jpeg ? tex::encodeJpeg(img, 95) : tex::encodePng(img));
  std::ostringstream out;
  auto vid = [&](int i, int j) { return j * (n + 1) + i; };
  if (!o.ply) {
    std::ofstream(dir + "/" + name + ".mtl") << "newmtl skin\nKd 1 1 1\nmap_Kd " << image << "\n";
    out << "mtllib " << name << ".mtl\n";
    for (int j = 0; j <= n; ++j)
      for (int i = 0; i <= n; ++i) {
        const double x = double(i) / n, y = double(j) / n;
        out << "v " << x << " " << y << " " << texturedGridHeight(x, y) << "\n";
      }
    // vt per (chart, corner): written per face corner, in face order (repeats allowed).
    out << "usemtl skin\n";
    int vt = 0;
    std::ostringstream faces;
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const int ci = i / per, cj = j / per;
        const int qi[4] = {i, i + 1, i + 1, i}, qj[4] = {j, j, j + 1, j + 1};
        int t[4];
        for (int k = 0; k < 4; ++k) {
          double u, v;
          uvOf(ci, cj, qi[k], qj[k], u, v);
          out << "vt " << u << " " << v << "\n";
          t[k] = ++vt;
        }
        faces << "f " << vid(qi[0], qj[0]) + 1 << "/" << t[0] << " " << vid(qi[1], qj[1]) + 1 << "/" << t[1] << " "
              << vid(qi[2], qj[2]) + 1 << "/" << t[2] << "\n";
        faces << "f " << vid(qi[0], qj[0]) + 1 << "/" << t[0] << " " << vid(qi[2], qj[2]) + 1 << "/" << t[2] << " "
              << vid(qi[3], qj[3]) + 1 << "/" << t[3] << "\n";
      }
    out << faces.str();
    std::ofstream(dir + "/" + name + ".obj") << out.str();
    return dir + "/" + name + ".obj";
  }
  out << "ply\nformat ascii 1.0\ncomment TextureFile " << image << "\nelement vertex " << (n + 1) * (n + 1)
      << "\nproperty float x\nproperty float y\nproperty float z\nelement face " << 2 * n * n
      << "\nproperty list uchar int vertex_indices\nproperty list uchar float texcoord\nend_header\n";
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const double x = double(i) / n, y = double(j) / n;
      out << x << " " << y << " " << texturedGridHeight(x, y) << "\n";
    }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int ci = i / per, cj = j / per;
      const int qi[4] = {i, i + 1, i + 1, i}, qj[4] = {j, j, j + 1, j + 1};
      double u[4], v[4];
      for (int k = 0; k < 4; ++k) uvOf(ci, cj, qi[k], qj[k], u[k], v[k]);
      static const int kTris[2][3] = {{0, 1, 2}, {0, 2, 3}};
      for (const int* tri : kTris) {
        out << "3";
        for (int k = 0; k < 3; ++k) out << " " << vid(qi[tri[k]], qj[tri[k]]);
        out << " 6";
        for (int k = 0; k < 3; ++k) out << " " << u[tri[k]] << " " << v[tri[k]];
        out << "\n";
      }
    }
  std::ofstream(dir + "/" + name + ".ply") << out.str();
  return dir + "/" + name + ".ply";
}

}  // namespace mt::testing
