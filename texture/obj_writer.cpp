// Textured OBJ + MTL + PNG: see obj_writer.h.
#include "texture/obj_writer.h"

#include <algorithm>
#include <cinttypes>
#include <cstdio>
#include <cstring>
#include <unordered_map>

#include "base/output_path.h"
#include "texture/atlas_pack.h"

namespace mt::tex {

namespace {

std::string baseName(const std::string& path) { return path.substr(path.find_last_of('/') + 1); }

struct Wedge {
  uint32_t vertex, u, v;  // the coordinates' float bits
  bool operator==(const Wedge& o) const { return vertex == o.vertex && u == o.u && v == o.v; }
};
struct WedgeHash {
  size_t operator()(const Wedge& w) const {
    uint64_t h = (uint64_t(w.vertex) * 0x9E3779B97F4A7C15ull) ^ (uint64_t(w.u) << 32 | w.v);
    h ^= h >> 29;
    return size_t(h * 0xBF58476D1CE4E5B9ull);
  }
};

// Text written through Env in large appends, under a temporary name renamed over `path` by
// finish(). Until that rename has succeeded, the destructor removes the temporary file: nothing
// is left under either name when a write, the sync, the close or the rename fails.
class TextOut {
 public:
  TextOut(Env* env, const std::string& path) : path_(path), tmp_(uniqueTempName(path)), file_(env->newWritableFile(tmp_)), env_(env) {}
  ~TextOut() {
    if (renamed_) return;
    if (file_) {
      try {
        file_->close();
      } catch (...) {
      }
    }
    try {
      env_->removeFile(tmp_);
    } catch (...) {
    }
  }
  void put(const char* s, size_t n) {
    buf_.append(s, n);
    if (buf_.size() > (1 << 20)) flush();
  }
  void put(const std::string& s) { put(s.data(), s.size()); }
  void finish() {
    flush();
    file_->sync();
    file_->close();
    file_.reset();
    env_->renameFile(tmp_, path_);
    renamed_ = true;
  }

 private:
  void flush() {
    if (!buf_.empty()) file_->append(buf_.data(), buf_.size());
    buf_.clear();
  }
  std::string path_, tmp_, buf_;
  std::unique_ptr<WritableFile> file_;
  Env* env_;
  bool renamed_ = false;
};

}  // namespace

ObjWriteInfo writeTexturedObj(const std::string& path, const TexturedMeshView& m, int pageSide, Env* env) {
  ObjWriteInfo info;
  const std::string stem = path.size() > 4 && path.compare(path.size() - 4, 4, ".obj") == 0 ? path.substr(0, path.size() - 4) : path;
  try {
    // Pages: the textures packed (each keeps its texels), one PNG each.
    const std::vector<RgbImage>& tex = *m.textures;
    std::vector<uint32_t> pageOf(tex.size());
    std::vector<PackedRect> rects;
    std::vector<std::pair<int, int>> pageSize;
    for (size_t first = 0; first < tex.size();) {
      // As many textures as fit one page, in order.
      size_t last = first;
      std::vector<PackedRect> trial;
      int w = 0, h = 0;
      while (last < tex.size()) {
        trial.push_back({tex[last].width, tex[last].height});
        if (!packRects(trial, pageSide, w, h)) {
          trial.pop_back();
          break;
        }
        ++last;
      }
      if (last == first) throw Error(path + ": a texture is larger than a page");
      packRects(trial, pageSide, w, h);
      for (size_t i = first; i < last; ++i) pageOf[i] = uint32_t(pageSize.size());
      rects.insert(rects.end(), trial.begin(), trial.end());
      pageSize.push_back({w, h});
      first = last;
    }
    for (size_t p = 0; p < pageSize.size(); ++p) {
      RgbImage page(pageSize[p].first, pageSize[p].second);
      for (size_t i = 0; i < tex.size(); ++i)
        if (pageOf[i] == p)
          for (int y = 0; y < tex[i].height; ++y)
            std::memcpy(page.pixel(rects[i].x, rects[i].y + y), tex[i].pixel(0, y), size_t(tex[i].width) * 3);
      const std::string file = stem + "_" + std::to_string(p) + ".png";
      writeFileAtomically(file, encodePng(page), env);
      info.files.push_back(file);
      info.texels += uint64_t(page.width) * uint64_t(page.height);
    }
    info.pages = pageSize.size();
    {
      TextOut mtl(env, stem + ".mtl");
      mtl.put("# batched-mt mtextract: one material per texture page\n");
      for (size_t p = 0; p < pageSize.size(); ++p)
        mtl.put("newmtl page" + std::to_string(p) + "\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nillum 1\nmap_Kd " + baseName(stem) + "_" +
                std::to_string(p) + ".png\n");
      mtl.put("newmtl untextured\nKd 0.7 0.7 0.7\nillum 1\n");
      mtl.finish();
      info.files.push_back(stem + ".mtl");
    }
    TextOut obj(env, path);
    obj.put("# batched-mt mtextract: a cut of a textured MT file\nmtllib " + baseName(stem) + ".mtl\n");
    char line[128];
    for (size_t v = 0; v < m.vertexCount; ++v) {
      const int n = std::snprintf(line, sizeof line, "v %.17g %.17g %.17g\n", m.positions[3 * v], m.positions[3 * v + 1], m.positions[3 * v + 2]);
      obj.put(line, size_t(n));
    }
    // vt per distinct (vertex, page coordinate); faces grouped by page (usemtl once per run).
    std::unordered_map<Wedge, uint32_t, WedgeHash> vt;
    std::vector<uint32_t> cornerVt(3 * m.triangleCount, 0);
    uint32_t vts = 0;
    for (size_t t = 0; t < m.triangleCount; ++t) {
      const uint32_t k = m.triangleTexture[t];
      if (k == UINT32_MAX) continue;
      const int pw = pageSize[pageOf[k]].first, ph = pageSize[pageOf[k]].second;
      for (int c = 0; c < 3; ++c) {
        // Over the page: the texture's texel rectangle inside it.
        const double x = rects[k].x + double(m.cornerUV[6 * t + 2 * size_t(c)]) * tex[k].width;
        const double y = rects[k].y + (1.0 - double(m.cornerUV[6 * t + 2 * size_t(c) + 1])) * tex[k].height;
        const float u = float(x / pw), v = float(1.0 - y / ph);
        uint32_t ub, vb;
        std::memcpy(&ub, &u, 4);
        std::memcpy(&vb, &v, 4);
        auto [it, fresh] = vt.emplace(Wedge{m.triangles[3 * t + size_t(c)], ub, vb}, vts + 1);
        if (fresh) {
          ++vts;
          const int n = std::snprintf(line, sizeof line, "vt %.9g %.9g\n", double(u), double(v));
          obj.put(line, size_t(n));
        }
        cornerVt[3 * t + size_t(c)] = it->second;
      }
    }
    uint32_t current = UINT32_MAX - 1;
    for (size_t t = 0; t < m.triangleCount; ++t) {
      const uint32_t k = m.triangleTexture[t];
      const uint32_t page = k == UINT32_MAX ? UINT32_MAX : pageOf[k];
      if (page != current) {
        obj.put(page == UINT32_MAX ? std::string("usemtl untextured\n") : "usemtl page" + std::to_string(page) + "\n");
        current = page;
      }
      int n;
      if (page == UINT32_MAX)
        n = std::snprintf(line, sizeof line, "f %u %u %u\n", m.triangles[3 * t] + 1, m.triangles[3 * t + 1] + 1, m.triangles[3 * t + 2] + 1);
      else
        n = std::snprintf(line, sizeof line, "f %u/%u %u/%u %u/%u\n", m.triangles[3 * t] + 1, cornerVt[3 * t], m.triangles[3 * t + 1] + 1,
                          cornerVt[3 * t + 1], m.triangles[3 * t + 2] + 1, cornerVt[3 * t + 2]);
      obj.put(line, size_t(n));
    }
    obj.finish();
    info.files.push_back(path);
  } catch (...) {
    for (const std::string& f : info.files) {
      try {
        env->removeFile(f);
      } catch (...) {
      }
    }
    throw;
  }
  return info;
}

}  // namespace mt::tex
