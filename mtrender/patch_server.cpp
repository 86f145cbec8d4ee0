#include "mtrender/patch_server.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <algorithm>

#include "base/error.h"
#include "texture/image_codec.h"

namespace mt::render {

std::pair<uint32_t, uint32_t> decodeInto(const Scene& scene, uint32_t id, const DecodedPatch& p, uint8_t* out,
                                         uint64_t capacity, PatchBound* bound) {
  const uint32_t nv = p.vertexCount(), nt = p.triangleCount();
  const ScenePatch sp = scene.patch(id);
  if (renderPatchBytes(nv, nt) > capacity)
    throw Error("patch " + std::to_string(sp.local) + ": decodes to " +
                std::to_string(renderPatchBytes(nv, nt)) + " bytes, more than its place holder (" +
                std::to_string(capacity) + ")");
  auto* v = reinterpret_cast<RenderVertex*>(out);
  auto* idx = reinterpret_cast<uint32_t*>(out + uint64_t(nv) * sizeof(RenderVertex));
  std::memcpy(idx, p.triangles.data(), p.triangles.size() * sizeof(uint32_t));
  // Positions relative to the patch's origin, in double from the exact grid coordinates: the
  // file's floats (origin + step * q rounded to float) lose centimetres millions of units out.
  const QuantizationGrid& grid = scene.reader(sp.file).grid();
  const double* origin = scene.patchOrigin(id);
  for (uint32_t i = 0; i < nv; ++i)
    for (int a = 0; a < 3; ++a) v[i].position[a] = float(grid.dequantize(a, p.q[3 * i + a]) - origin[a]);
  std::vector<float> normals;
  const float* nsrc = p.normals.empty() ? nullptr : p.normals.data();
  double axis[3] = {0, 0, 0};
  if (!nsrc || bound) {
    // The files usually store no normals (patch_codec.h): area-weighted vertex normals of the
    // patch. Positions are bit-identical across patch borders, so silhouettes never crack; only
    // the shading may show a faint seam.
    if (!nsrc) normals.assign(size_t(nv) * 3, 0.0f);
    for (uint32_t t = 0; t < nt; ++t) {
      const uint32_t a = p.triangles[3 * t], b = p.triangles[3 * t + 1], c = p.triangles[3 * t + 2];
      const float* pa = v[a].position;
      const float* pb = v[b].position;
      const float* pc = v[c].position;
      float e1[3] = {pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]};
      float e2[3] = {pc[0] - pa[0], pc[1] - pa[1], pc[2] - pa[2]};
      float n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
      for (int i = 0; i < 3; ++i) axis[i] += n[i];
      if (!nsrc)
        for (uint32_t k : {a, b, c})
          for (int i = 0; i < 3; ++i) normals[3 * k + i] += n[i];
    }
    if (!nsrc) nsrc = normals.data();
  }
  if (bound) {
    // The normal cone of the patch's triangles (the builder's rule for nodes: the mean normal and
    // the widest angle from it), and its bounding sphere (box centre, farthest vertex).
    *bound = PatchBound();
    const double len = std::sqrt(axis[0] * axis[0] + axis[1] * axis[1] + axis[2] * axis[2]);
    if (len > 0 && nt > 0) {
      double cutoff = 1;
      for (uint32_t t = 0; t < nt && cutoff > -1; ++t) {
        const float* pa = v[p.triangles[3 * t]].position;
        const float* pb = v[p.triangles[3 * t + 1]].position;
        const float* pc = v[p.triangles[3 * t + 2]].position;
        double e1[3] = {pb[0] - pa[0], pb[1] - pa[1], pb[2] - pa[2]};
        double e2[3] = {pc[0] - pa[0], pc[1] - pa[1], pc[2] - pa[2]};
        double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
        const double nl = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
        if (nl > 0) cutoff = std::min(cutoff, (n[0] * axis[0] + n[1] * axis[1] + n[2] * axis[2]) / (nl * len));
      }
      for (int i = 0; i < 3; ++i) bound->coneAxis[i] = float(axis[i] / len);
      // A little slack for the float rounding of the axis and of the test.
      bound->coneCutoff = cutoff > 0.01 ? float(cutoff - 0.005) : -2.0f;
    }
    float lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};
    for (uint32_t i = 0; i < nv; ++i)
      for (int a = 0; a < 3; ++a) {
        lo[a] = i ? std::min(lo[a], v[i].position[a]) : v[i].position[a];
        hi[a] = i ? std::max(hi[a], v[i].position[a]) : v[i].position[a];
      }
    double r2 = 0;
    for (int a = 0; a < 3; ++a) bound->center[a] = 0.5f * (lo[a] + hi[a]);
    for (uint32_t i = 0; i < nv; ++i) {
      double d2 = 0;
      for (int a = 0; a < 3; ++a) d2 += std::pow(double(v[i].position[a]) - bound->center[a], 2);
      r2 = std::max(r2, d2);
    }
    bound->radius = float(std::sqrt(r2) * 1.0001 + 1e-6);
  }
  for (uint32_t i = 0; i < nv; ++i) {
    RenderVertex& r = v[i];
    float n[3] = {nsrc[3 * i], nsrc[3 * i + 1], nsrc[3 * i + 2]};
    float len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    if (len > 0)
      for (float& c : n) c /= len;
    r.normal = packNormal(n);
    if (p.colors.size() >= size_t(nv) * 4)
      std::memcpy(r.color, &p.colors[4 * i], 4);
    else
      r.color[0] = r.color[1] = r.color[2] = r.color[3] = 255;
  }
  return {nv, nt * 3};
}

std::pair<uint16_t, uint16_t> decodeTextureInto(const TexturePayload& t, uint32_t nv, uint32_t nt, uint8_t* out,
                                                uint64_t capacity) {
  if (t.image.empty() || !t.width || !t.height) return {0, 0};
  if (textureOffset(nv, nt) + renderTextureBytes(nt, t.width, t.height) > capacity)
    throw Error("texture: " + std::to_string(t.width) + " x " + std::to_string(t.height) +
                " texels do not fit the patch's place holder (" + std::to_string(capacity) + " bytes)");
  if (t.cornerUV.size() != size_t(nt) * 6) throw Error("texture: corner coordinates do not match the triangles");
  auto* uv = reinterpret_cast<uint16_t*>(out + textureOffset(nv, nt));
  for (size_t i = 0; i < t.cornerUV.size(); ++i)
    uv[i] = uint16_t(std::lround(std::clamp(t.cornerUV[i], 0.0f, 1.0f) * 65535.0f));
  auto decoder = tex::ImageDecoder::openMemory(t.image.data(), t.image.size(), "texture");
  if (decoder->width() != t.width || decoder->height() != t.height)
    throw Error("texture: the image is " + std::to_string(decoder->width()) + " x " + std::to_string(decoder->height()) +
                ", the payload says " + std::to_string(t.width) + " x " + std::to_string(t.height));
  uint8_t* texels = out + texelOffset(nv, nt);
  const size_t row = size_t(t.width) * 3;
  // The image's top row first; GL's texture rows bottom first (v = 0 at the bottom).
  for (int y = 0; y < t.height; ++y) decoder->readRow(texels + size_t(t.height - 1 - y) * row);
  return {t.width, t.height};
}

PatchServer::PatchServer(const Scene& scene, PatchCache& cache, Options options)
    : scene_(scene), cache_(cache), options_(options), thread_([this] { run(); }) {}

PatchServer::~PatchServer() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
  }
  cv_.notify_all();
  thread_.join();
}

void PatchServer::submit(std::vector<LoadRequest> requests, uint64_t frame) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    queue_.assign(requests.begin(), requests.end());
    frame_ = frame;
  }
  cv_.notify_one();
}

bool PatchServer::waitIdle(double timeoutMs) {
  std::unique_lock<std::mutex> lock(mu_);
  return idleCv_.wait_for(lock, std::chrono::duration<double, std::milli>(timeoutMs),
                          [&] { return queue_.empty() && !busy_; });
}

double PatchServer::meanLoadMs() const {
  std::lock_guard<std::mutex> lock(mu_);
  uint64_t n = loads_.load();
  return n ? loadMsSum_ / double(n) : 0.0;
}

std::vector<std::string> PatchServer::warnings() const {
  std::lock_guard<std::mutex> lock(mu_);
  return warnings_;
}

void PatchServer::run() {
  for (;;) {
    LoadRequest req;
    uint64_t frame;
    {
      std::unique_lock<std::mutex> lock(mu_);
      busy_ = false;
      if (queue_.empty()) idleCv_.notify_all();
      cv_.wait(lock, [&] { return stop_ || !queue_.empty(); });
      if (stop_) return;
      req = queue_.front();
      queue_.pop_front();
      frame = frame_;
      busy_ = true;
    }
    int slot = cache_.reserve(req.id, req.urgency, frame);
    if (slot < 0) continue;  // present, bad, or no room (3.3.2: give up; asked again next frame)
    const auto t0 = std::chrono::steady_clock::now();
    const ScenePatch sp = scene_.patch(req.id);
    const MtFileReader& reader = scene_.reader(sp.file);
    try {
      if (options_.readDelayMs > 0)
        std::this_thread::sleep_for(std::chrono::duration<double, std::milli>(options_.readDelayMs));
      DecodedPatch decoded = reader.readPatch(sp.local);
      std::pair<uint32_t, uint32_t> counts;
      std::pair<uint16_t, uint16_t> atlas{0, 0};
      PatchBound bound;
      // The reader's errors name the file; ours are prefixed with it.
      TexturePayload texture;
      const bool textured = scene_.loadsTextures(sp.file);
      if (textured) texture = reader.readTexture(sp.local, decoded);
      try {
        counts = decodeInto(scene_, req.id, decoded, cache_.slotData(slot), cache_.slotBytes(slot), &bound);
      } catch (const Error& e) {
        throw Error(reader.path() + ": " + e.what());
      }
      try {
        atlas = decodeTextureInto(texture, counts.first, counts.second / 3, cache_.slotData(slot), cache_.slotBytes(slot));
      } catch (const Error& e) {
        throw Error(reader.path() + ": patch " + std::to_string(sp.local) + ": " + e.what());
      }
      cache_.commit(slot, counts.first, counts.second, bound, atlas.first, atlas.second);
      bytesRead_ += textured ? reader.textures()[sp.local].size : 0;
      bytesRead_ += sp.fileBytes;
      trianglesLoaded_ += sp.triangles;
      const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
      {
        std::lock_guard<std::mutex> lock(mu_);
        loadMsSum_ += ms;
      }
      ++loads_;
    } catch (const std::exception& e) {
      cache_.abort(slot, true);
      ++bad_;
      std::string msg = std::string("warning: ") + e.what() + " (patch skipped, rendering continues)";
      if (!options_.quiet) std::fprintf(stderr, "%s\n", msg.c_str());
      std::lock_guard<std::mutex> lock(mu_);
      warnings_.push_back(msg);
    }
  }
}

}  // namespace mt::render
