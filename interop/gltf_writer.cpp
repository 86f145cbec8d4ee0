// glTF 2.0 writer (layout and precision: gltf_writer.h).
#include "interop/gltf_writer.h"

#include <draco/compression/decode.h>
#include <draco/compression/encode.h>
#include <draco/mesh/mesh.h>
#include <meshoptimizer.h>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstring>
#include <limits>
#include <nlohmann/json.hpp>
#include <unordered_map>

#include "base/error.h"
#include "base/output_path.h"
#include "mtfile/mt_format.h"

namespace mt::interop {

namespace {

using nlohmann::json;

constexpr int kFloat = 5126, kUnsignedShort = 5123, kShort = 5122, kUnsignedByte = 5121, kUnsignedInt = 5125;
constexpr int kArrayBuffer = 34962, kElementArrayBuffer = 34963;

void pad4(std::vector<uint8_t>& v, uint8_t fill = 0) {
  while (v.size() % 4) v.push_back(fill);
}

// One stream of the mesh (a vertex attribute or the indices) in its uncompressed layout.
struct Stream {
  std::vector<uint8_t> bytes;
  uint32_t stride = 0;  // element size in bytes (a multiple of 4 for attributes, 2 or 4 for indices)
  size_t count = 0;     // elements
  bool indices = false;
};

// Appends a stream as a buffer view (compressed when asked) and returns its index.
class Views {
 public:
  Views(bool meshopt, std::vector<uint8_t>& bin) : meshopt_(meshopt), bin_(bin) {}

  int add(const Stream& s) {
    json view;
    if (!meshopt_) {
      pad4(bin_);
      view = {{"buffer", 0}, {"byteOffset", bin_.size()}, {"byteLength", s.bytes.size()}};
      bin_.insert(bin_.end(), s.bytes.begin(), s.bytes.end());
    } else {
      // The fallback buffer (no data) holds the decoded layout; buffer 0 the compressed bytes.
      fallback_ = (fallback_ + 3) & ~size_t(3);
      view = {{"buffer", 1}, {"byteOffset", fallback_}, {"byteLength", s.bytes.size()}};
      fallback_ += s.bytes.size();
      std::vector<uint8_t> code;
      if (s.indices) {
        assert(s.count % 3 == 0);
        code.resize(meshopt_encodeIndexBufferBound(s.count, s.count ? s.count : 1));
        size_t n = s.stride == 4
                       ? meshopt_encodeIndexBuffer(code.data(), code.size(), reinterpret_cast<const uint32_t*>(s.bytes.data()), s.count)
                       : meshopt_encodeIndexBuffer(code.data(), code.size(), reinterpret_cast<const uint16_t*>(s.bytes.data()), s.count);
        code.resize(n);
      } else {
        code.resize(meshopt_encodeVertexBufferBound(s.count, s.stride));
        code.resize(meshopt_encodeVertexBuffer(code.data(), code.size(), s.bytes.data(), s.count, s.stride));
      }
      if (code.empty()) throw Error("glTF writer: meshopt encoding failed");
      pad4(bin_);
      view["extensions"]["EXT_meshopt_compression"] = {
          {"buffer", 0}, {"byteOffset", bin_.size()}, {"byteLength", code.size()}, {"byteStride", s.stride},
          {"count", s.count}, {"mode", s.indices ? "TRIANGLES" : "ATTRIBUTES"}};
      bin_.insert(bin_.end(), code.begin(), code.end());
    }
    if (s.indices) {
      view["target"] = kElementArrayBuffer;
    } else {
      view["target"] = kArrayBuffer;
      view["byteStride"] = s.stride;
    }
    views_.push_back(std::move(view));
    return int(views_.size() - 1);
  }
  // Bytes stored as they are (an image): buffer 0, no stride, no target.
  int addRaw(const uint8_t* data, size_t size) {
    pad4(bin_);
    views_.push_back({{"buffer", 0}, {"byteOffset", bin_.size()}, {"byteLength", size}});
    bin_.insert(bin_.end(), data, data + size);
    return int(views_.size() - 1);
  }
  json& views() { return views_; }
  size_t fallbackBytes() const { return fallback_; }

 private:
  bool meshopt_;
  std::vector<uint8_t>& bin_;
  json views_ = json::array();
  size_t fallback_ = 0;
};

template <class T>
void put(std::vector<uint8_t>& out, T v) {
  const size_t at = out.size();
  out.resize(at + sizeof v);
  std::memcpy(out.data() + at, &v, sizeof v);
}

// The mesh's own arrays in the order meshopt's codecs compress best: triangles reordered for the
// vertex cache (meshopt_optimizeVertexCache), then vertices in first-use order
// (meshopt_optimizeVertexFetchRemap). The index codec codes a triangle that reuses the last
// triangles' edges and recently used vertices in a few bits; the MT's cut comes patch by patch in
// decoding order. Measured on a 10M-triangle build's tiles (docs/interop.md): indices 1.48 -> 1.19
// bytes per triangle, positions 1.22 -> 1.40 (the vertex codec's deltas prefer the grid order the
// cut had), 3.6% smaller in all for 1.8x the CPU time. The same triangles (orientation kept) and
// vertices: only their order changes (and unreferenced vertices are dropped).
struct Reordered {
  std::vector<double> positions;
  std::vector<uint32_t> triangles, q;
  std::vector<float> normals;
  std::vector<uint8_t> colors;
  GltfMeshView view;
};

void reorderForCompression(const GltfMeshView& m, Reordered& r) {
  const size_t indexCount = 3 * m.triangleCount, n = m.vertexCount;
  r.triangles.resize(indexCount);
  meshopt_optimizeVertexCache(r.triangles.data(), m.triangles, indexCount, n);
  std::vector<uint32_t> remap(n);
  const size_t used = meshopt_optimizeVertexFetchRemap(remap.data(), r.triangles.data(), indexCount, n);
  for (uint32_t& i : r.triangles) i = remap[i];
  r.positions.resize(3 * used);
  if (m.q) r.q.resize(3 * used);
  if (m.normals) r.normals.resize(3 * used);
  if (m.colors) r.colors.resize(4 * used);
  for (size_t v = 0; v < n; ++v) {
    const uint32_t to = remap[v];
    if (to == ~0u) continue;  // no triangle uses it
    std::copy(m.positions + 3 * v, m.positions + 3 * v + 3, &r.positions[3 * to]);
    if (m.q) std::copy(m.q + 3 * v, m.q + 3 * v + 3, &r.q[3 * to]);
    if (m.normals) std::copy(m.normals + 3 * v, m.normals + 3 * v + 3, &r.normals[3 * to]);
    if (m.colors) std::copy(m.colors + 4 * v, m.colors + 4 * v + 4, &r.colors[4 * to]);
  }
  r.view = m;
  r.view.vertexCount = used;
  r.view.positions = r.positions.data();
  r.view.triangles = r.triangles.data();
  r.view.q = m.q ? r.q.data() : nullptr;
  r.view.normals = m.normals ? r.normals.data() : nullptr;
  r.view.colors = m.colors ? r.colors.data() : nullptr;
}

// One KHR_draco_mesh_compression primitive: Draco's edgebreaker connectivity and parallelogram
// prediction, the coding the MT file's own codec is closest to (mt_format.h), about 3x smaller than
// meshopt's byte codecs on scan tiles (docs/interop.md). Positions go in as the grid coordinates
// q - qMin, a UINT16 attribute that Draco codes losslessly (no Draco quantization), so the decoded
// file holds exactly the MT's grid points, as with KHR_mesh_quantization; colours as UINT8 (also
// lossless), normals as floats with Draco's 10-bit octahedral quantization (the MT stores 8 bits).
struct DracoPrimitive {
  std::vector<uint8_t> bytes;
  size_t points = 0, faces = 0;
  int position = -1, normal = -1, color = -1;  // Draco attribute unique ids
};

DracoPrimitive encodeDraco(const GltfMeshView& m, const uint32_t qMin[3], int speed) {
  const size_t n = m.vertexCount;
  draco::Mesh mesh;
  mesh.set_num_points(uint32_t(n));
  auto add = [&](draco::GeometryAttribute::Type type, int components, draco::DataType dt, bool normalized, int size) {
    draco::GeometryAttribute ga;
    ga.Init(type, nullptr, int8_t(components), dt, normalized, int64_t(components) * size, 0);
    return mesh.AddAttribute(ga, true, uint32_t(n));
  };
  const int pos = add(draco::GeometryAttribute::POSITION, 3, draco::DT_UINT16, false, 2);
  for (size_t v = 0; v < n; ++v) {
    uint16_t q[3];
    for (int a = 0; a < 3; ++a) q[a] = uint16_t(m.q[3 * v + a] - qMin[a]);
    mesh.attribute(pos)->SetAttributeValue(draco::AttributeValueIndex(uint32_t(v)), q);
  }
  int nor = -1, col = -1;
  if (m.normals) {
    nor = add(draco::GeometryAttribute::NORMAL, 3, draco::DT_FLOAT32, false, 4);
    for (size_t v = 0; v < n; ++v) {
      double x = m.normals[3 * v], y = m.normals[3 * v + 1], z = m.normals[3 * v + 2];
      double len = std::sqrt(x * x + y * y + z * z);
      if (!(len > 1e-12) || !std::isfinite(len)) x = 0, y = 0, z = 1, len = 1;  // as in the plain path
      const float f[3] = {float(x / len), float(y / len), float(z / len)};
      mesh.attribute(nor)->SetAttributeValue(draco::AttributeValueIndex(uint32_t(v)), f);
    }
  }
  if (m.colors) {
    col = add(draco::GeometryAttribute::COLOR, 4, draco::DT_UINT8, true, 1);
    for (size_t v = 0; v < n; ++v) mesh.attribute(col)->SetAttributeValue(draco::AttributeValueIndex(uint32_t(v)), m.colors + 4 * v);
  }
  for (size_t t = 0; t < m.triangleCount; ++t) {
    draco::Mesh::Face f;
    for (int k = 0; k < 3; ++k) f[k] = draco::PointIndex(m.triangles[3 * t + k]);
    mesh.AddFace(f);
  }
  draco::Encoder encoder;
  encoder.SetSpeedOptions(speed, speed);
  if (m.normals) encoder.SetAttributeQuantization(draco::GeometryAttribute::NORMAL, 10);
  draco::EncoderBuffer buffer;
  const draco::Status status = encoder.EncodeMeshToBuffer(mesh, &buffer);
  if (!status.ok()) throw Error("glTF writer: Draco encoding failed: " + status.error_msg_string());
  DracoPrimitive d;
  d.bytes.assign(buffer.data(), buffer.data() + buffer.size());
  d.position = int(mesh.attribute(pos)->unique_id());
  if (nor >= 0) d.normal = int(mesh.attribute(nor)->unique_id());
  if (col >= 0) d.color = int(mesh.attribute(col)->unique_id());
  // The accessors must state the decoded counts (Draco may split or merge points): decode to know.
  draco::DecoderBuffer in;
  in.Init(reinterpret_cast<const char*>(d.bytes.data()), d.bytes.size());
  draco::Decoder decoder;
  auto decoded = decoder.DecodeMeshFromBuffer(&in);
  if (!decoded.ok()) throw Error("glTF writer: Draco cannot decode what it encoded: " + decoded.status().error_msg_string());
  d.points = decoded.value()->num_points();
  d.faces = decoded.value()->num_faces();
  if (d.faces != m.triangleCount) throw Error("glTF writer: Draco changed the triangle count");
  return d;
}

}  // namespace

GltfBytes buildGltf(const GltfMeshView& input, const GltfOptions& o, const std::string& binUri) {
  if (input.vertexCount == 0 || input.triangleCount == 0) throw Error("glTF writer: the mesh has no triangles");
  if (input.vertexCount > 0xFFFFFFFEu) throw Error("glTF writer: more vertices than 32-bit indices address");
  // Textured meshes keep their order (the triangles are grouped per image below).
  const bool textured = input.texcoords && input.triangleImage;
  Reordered reordered;
  if (o.meshopt && !o.draco && !textured) reorderForCompression(input, reordered);
  const GltfMeshView& m = reordered.view.positions ? reordered.view : input;
  GltfBytes out;
  GltfInfo& info = out.info;
  const size_t n = m.vertexCount;

  // The grid box of the mesh, when it is on a grid.
  uint32_t qMin[3] = {UINT32_MAX, UINT32_MAX, UINT32_MAX}, qMax[3] = {0, 0, 0};
  if (m.q)
    for (size_t v = 0; v < n; ++v)
      for (int a = 0; a < 3; ++a) qMin[a] = std::min(qMin[a], m.q[3 * v + a]), qMax[a] = std::max(qMax[a], m.q[3 * v + a]);
  bool quantized = false;
  if (o.quantize) {
    if (!m.q || !(m.gridStep > 0)) {
      info.fallbackReason = "the mesh is not on a grid";
    } else {
      quantized = true;
      for (int a = 0; a < 3; ++a)
        if (qMax[a] - qMin[a] > 65535) {
          quantized = false;
          info.fallbackReason = "the mesh spans " + std::to_string(qMax[a] - qMin[a] + 1ull) + " grid steps on axis " +
                                std::to_string(a) + " (KHR_mesh_quantization holds 65536)";
        }
    }
  }
  info.quantized = quantized;
  // Draco codes the grid coordinates: without the grid (or wider than 16 bits) the plain layout.
  const bool draco = o.draco && quantized && !textured;
  if (o.draco && !quantized) info.fallbackReason += "; written without Draco";
  if (o.draco && textured) info.fallbackReason += "textured: written without Draco";

  // The node translation: a grid point (exact in double) near the mesh, so the stored differences
  // are small; the bounding box's centre when there is no grid.
  double t[3];
  if (quantized) {
    for (int a = 0; a < 3; ++a) t[a] = m.gridOrigin[a] + m.gridStep * double(qMin[a]);
  } else if (m.q && m.gridStep > 0) {
    for (int a = 0; a < 3; ++a) t[a] = m.gridOrigin[a] + m.gridStep * double(qMin[a] + (qMax[a] - qMin[a]) / 2);
  } else {
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t v = 0; v < n; ++v)
      for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], m.positions[3 * v + a]), hi[a] = std::max(hi[a], m.positions[3 * v + a]);
    for (int a = 0; a < 3; ++a) t[a] = 0.5 * (lo[a] + hi[a]);
  }
  for (int a = 0; a < 3; ++a) info.translation[a] = t[a];

  std::vector<Stream> streams;
  json posMin = json::array(), posMax = json::array();
  Stream pos;
  pos.count = n;
  if (quantized) {
    pos.stride = 8;  // uint16 x 3, padded: meshopt and glTF want 4-byte aligned vertex strides
    pos.bytes.reserve(n * 8);
    for (size_t v = 0; v < n; ++v) {
      for (int a = 0; a < 3; ++a) put<uint16_t>(pos.bytes, uint16_t(m.q[3 * v + a] - qMin[a]));
      put<uint16_t>(pos.bytes, 0);
    }
    for (int a = 0; a < 3; ++a) posMin.push_back(0), posMax.push_back(qMax[a] - qMin[a]);
  } else {
    pos.stride = 12;
    pos.bytes.reserve(n * 12);
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t v = 0; v < n; ++v)
      for (int a = 0; a < 3; ++a) {
        const float f = float(m.positions[3 * v + a] - t[a]);
        lo[a] = std::min(lo[a], f), hi[a] = std::max(hi[a], f);
        put<float>(pos.bytes, f);
      }
    for (int a = 0; a < 3; ++a) posMin.push_back(lo[a]), posMax.push_back(hi[a]);
  }
  streams.push_back(std::move(pos));

  if (m.normals) {
    Stream nor;
    nor.count = n;
    nor.stride = quantized ? 8 : 12;
    for (size_t v = 0; v < n; ++v) {
      double x = m.normals[3 * v], y = m.normals[3 * v + 1], z = m.normals[3 * v + 2];
      double len = std::sqrt(x * x + y * y + z * z);
      // A zero (or broken) normal is not a unit vector; the validator refuses it. +Z stands in.
      if (!(len > 1e-12) || !std::isfinite(len)) x = 0, y = 0, z = 1, len = 1;
      x /= len, y /= len, z /= len;
      if (quantized) {
        for (double c : {x, y, z}) put<int16_t>(nor.bytes, int16_t(std::lround(c * 32767.0)));
        put<int16_t>(nor.bytes, 0);
      } else {
        for (double c : {x, y, z}) put<float>(nor.bytes, float(c));
      }
    }
    streams.push_back(std::move(nor));
  }
  if (m.colors) {
    Stream col;
    col.count = n;
    col.stride = 4;
    col.bytes.assign(m.colors, m.colors + 4 * n);
    streams.push_back(std::move(col));
  }
  if (textured) {
    // glTF's v runs down the image, as the view's does. Always float: the MT keeps 1/16 texel of
    // atlases up to 2048 texels, which 16-bit normalized coordinates would not hold exactly.
    Stream uv;
    uv.count = n;
    uv.stride = 8;
    for (size_t v = 0; v < n; ++v)
      for (int c = 0; c < 2; ++c) put<float>(uv.bytes, std::clamp(m.texcoords[2 * v + c], 0.0f, 1.0f));
    streams.push_back(std::move(uv));
  }
  // The triangles: one index stream, or with textures one per image (then the untextured ones).
  std::vector<uint32_t> groupImage;  // per index stream: its image, UINT32_MAX none
  {
    std::vector<std::vector<uint32_t>> groups(textured ? m.imageCount + 1 : 1);
    for (size_t t = 0; t < m.triangleCount; ++t) {
      size_t g = 0;
      if (textured) {
        const uint32_t img = m.triangleImage[t];
        assert(img == UINT32_MAX || img < m.imageCount);
        g = img == UINT32_MAX || img >= m.imageCount ? m.imageCount : img;
      }
      groups[g].push_back(uint32_t(t));
    }
    for (size_t g = 0; g < groups.size(); ++g) {
      if (groups[g].empty()) continue;
      Stream idx;
      idx.indices = true;
      idx.count = 3 * groups[g].size();
      idx.stride = n <= 65535 ? 2 : 4;
      idx.bytes.reserve(idx.count * idx.stride);
      for (uint32_t t : groups[g])
        for (int k = 0; k < 3; ++k) {
          const uint32_t i = m.triangles[3 * size_t(t) + size_t(k)];
          assert(i < n);
          if (idx.stride == 2) put<uint16_t>(idx.bytes, uint16_t(i));
          else put<uint32_t>(idx.bytes, i);
        }
      streams.push_back(std::move(idx));
      groupImage.push_back(textured && g < m.imageCount ? uint32_t(g) : UINT32_MAX);
    }
  }

  Views views(o.meshopt && !draco, out.bin);
  json accessors = json::array();
  json attributes = json::object();
  json primitiveExtensions;
  std::vector<size_t> indexAccessors;
  size_t s = 0;
  if (draco) {
    // The accessors describe the decoded data and have no buffer view; the one view holds Draco's bytes.
    const DracoPrimitive d = encodeDraco(m, qMin, o.dracoSpeed);
    out.bin = d.bytes;
    json dviews = json::array({{{"buffer", 0}, {"byteOffset", 0}, {"byteLength", d.bytes.size()}}});
    views.views() = dviews;
    accessors.push_back({{"componentType", kUnsignedShort}, {"count", d.points}, {"type", "VEC3"}, {"min", posMin}, {"max", posMax}});
    attributes["POSITION"] = 0;
    json dattr = {{"POSITION", d.position}};
    if (m.normals) {
      accessors.push_back({{"componentType", kFloat}, {"count", d.points}, {"type", "VEC3"}});
      attributes["NORMAL"] = accessors.size() - 1;
      dattr["NORMAL"] = d.normal;
    }
    if (m.colors) {
      accessors.push_back({{"componentType", kUnsignedByte}, {"normalized", true}, {"count", d.points}, {"type", "VEC4"}});
      attributes["COLOR_0"] = accessors.size() - 1;
      dattr["COLOR_0"] = d.color;
    }
    accessors.push_back({{"componentType", d.points <= 65535 ? kUnsignedShort : kUnsignedInt}, {"count", 3 * d.faces}, {"type", "SCALAR"}});
    indexAccessors.push_back(accessors.size() - 1);
    primitiveExtensions["KHR_draco_mesh_compression"] = {{"bufferView", 0}, {"attributes", dattr}};
  } else {
    json p = {{"bufferView", views.add(streams[s++])}, {"componentType", quantized ? kUnsignedShort : kFloat},
              {"count", n}, {"type", "VEC3"}, {"min", posMin}, {"max", posMax}};
    accessors.push_back(p);
    attributes["POSITION"] = accessors.size() - 1;
    if (m.normals) {
      json a = {{"bufferView", views.add(streams[s++])}, {"componentType", quantized ? kShort : kFloat},
                {"count", n}, {"type", "VEC3"}};
      if (quantized) a["normalized"] = true;
      accessors.push_back(a);
      attributes["NORMAL"] = accessors.size() - 1;
    }
    if (m.colors) {
      json a = {{"bufferView", views.add(streams[s++])}, {"componentType", kUnsignedByte}, {"normalized", true},
                {"count", n}, {"type", "VEC4"}};
      accessors.push_back(a);
      attributes["COLOR_0"] = accessors.size() - 1;
    }
    if (textured) {
      json a = {{"bufferView", views.add(streams[s++])}, {"componentType", kFloat}, {"count", n}, {"type", "VEC2"}};
      accessors.push_back(a);
      attributes["TEXCOORD_0"] = accessors.size() - 1;
    }
    for (; s < streams.size(); ++s) {
      const Stream& is = streams[s];
      json a = {{"bufferView", views.add(is)}, {"componentType", is.stride == 2 ? kUnsignedShort : kUnsignedInt},
                {"count", is.count}, {"type", "SCALAR"}};
      accessors.push_back(a);
      indexAccessors.push_back(accessors.size() - 1);
    }
  }
  // The images, one material each (only those some triangle uses), stored as they are.
  json images = json::array(), textures = json::array(), materials = json::array();
  std::vector<int> materialOfImage(textured ? m.imageCount : 0, -1);
  for (uint32_t img : groupImage) {
    if (img == UINT32_MAX) continue;
    const GltfMeshView::Image& im = m.images[img];
    images.push_back({{"bufferView", views.addRaw(im.data, im.size)}, {"mimeType", im.png ? "image/png" : "image/jpeg"}});
    textures.push_back({{"source", images.size() - 1}, {"sampler", 0}});
    materials.push_back({{"pbrMetallicRoughness", {{"baseColorTexture", {{"index", textures.size() - 1}}}, {"metallicFactor", 0.0}}}});
    materialOfImage[img] = int(materials.size() - 1);
  }
  pad4(out.bin);

  json doc;
  doc["asset"] = {{"version", "2.0"}, {"generator", o.generator}};
  if (!o.crs.empty()) doc["asset"]["extras"] = {{"crs", o.crs}};
  json used = json::array();
  if (quantized) used.push_back("KHR_mesh_quantization");
  if (o.meshopt && !draco) used.push_back("EXT_meshopt_compression");
  if (draco) used.push_back("KHR_draco_mesh_compression");
  if (!used.empty()) {
    doc["extensionsUsed"] = used;
    doc["extensionsRequired"] = used;
  }
  json buffers = json::array();
  json b0 = {{"byteLength", out.bin.size()}};
  if (!binUri.empty()) b0["uri"] = binUri;
  buffers.push_back(b0);
  if (o.meshopt && !draco)
    buffers.push_back({{"byteLength", views.fallbackBytes()}, {"extensions", {{"EXT_meshopt_compression", {{"fallback", true}}}}}});
  doc["buffers"] = buffers;
  doc["bufferViews"] = views.views();
  doc["accessors"] = accessors;
  if (!materials.empty()) {
    // Linear filtering, mipmaps, clamped: the atlases' gutters hold the border texels.
    doc["samplers"] = json::array({{{"magFilter", 9729}, {"minFilter", 9987}, {"wrapS", 33071}, {"wrapT", 33071}}});
    doc["images"] = images;
    doc["textures"] = textures;
    doc["materials"] = materials;
  }
  json primitives = json::array();
  for (size_t g = 0; g < indexAccessors.size(); ++g) {
    json primitive = {{"attributes", attributes}, {"indices", indexAccessors[g]}, {"mode", 4}};
    if (!primitiveExtensions.is_null()) primitive["extensions"] = primitiveExtensions;
    if (g < groupImage.size() && groupImage[g] != UINT32_MAX) primitive["material"] = materialOfImage[groupImage[g]];
    primitives.push_back(primitive);
  }
  doc["meshes"] = json::array({{{"primitives", primitives}}});
  json meshNode = {{"mesh", 0}};
  double local[3];
  for (int a = 0; a < 3; ++a) local[a] = t[a] - o.frame[a];
  if (local[0] != 0 || local[1] != 0 || local[2] != 0) meshNode["translation"] = {local[0], local[1], local[2]};
  if (quantized) meshNode["scale"] = {m.gridStep, m.gridStep, m.gridStep};
  json nodes = json::array();
  if (o.zUpToYUp) {
    // Column-major: (x, y, z) -> (x, z, -y), exact; the 3D Tiles runtime applies the inverse.
    nodes.push_back({{"matrix", {1, 0, 0, 0, 0, 0, -1, 0, 0, 1, 0, 0, 0, 0, 0, 1}}, {"children", json::array({1})}});
  }
  nodes.push_back(meshNode);
  doc["nodes"] = nodes;
  doc["scenes"] = json::array({{{"nodes", json::array({0})}}});
  doc["scene"] = 0;
  out.json = doc.dump();
  return out;
}

std::vector<uint8_t> encodeGlb(const GltfBytes& g) {
  std::vector<uint8_t> jsonChunk(g.json.begin(), g.json.end());
  pad4(jsonChunk, ' ');
  std::vector<uint8_t> out;
  const uint64_t total = 12 + 8 + jsonChunk.size() + (g.bin.empty() ? 0 : 8 + ((g.bin.size() + 3) & ~size_t(3)));
  if (total > 0xFFFFFFFFull) throw Error("glTF writer: a GLB holds at most 4 GiB (" + std::to_string(total) + " bytes); write .gltf");
  out.reserve(size_t(total));
  put<uint32_t>(out, 0x46546C67u);  // "glTF"
  put<uint32_t>(out, 2);
  put<uint32_t>(out, uint32_t(total));
  put<uint32_t>(out, uint32_t(jsonChunk.size()));
  put<uint32_t>(out, 0x4E4F534Au);  // "JSON"
  out.insert(out.end(), jsonChunk.begin(), jsonChunk.end());
  if (!g.bin.empty()) {
    put<uint32_t>(out, uint32_t((g.bin.size() + 3) & ~size_t(3)));
    put<uint32_t>(out, 0x004E4942u);  // "BIN\0"
    out.insert(out.end(), g.bin.begin(), g.bin.end());
    pad4(out);
  }
  assert(out.size() == total);
  return out;
}

namespace {

void writeTemp(const std::string& tmp, const void* data, size_t size, Env* env) {
  auto f = env->newWritableFile(tmp);
  f->append(data, size);
  f->sync();
  f->close();
}

void removeQuietly(Env* env, const std::string& path) {
  try {
    env->removeFile(path);
  } catch (const Error&) {
  }
}

}  // namespace

static std::string parentOf(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  return slash == std::string::npos ? "." : slash == 0 ? "/" : path.substr(0, slash);
}

void writeFileAtomic(const std::string& path, const void* data, size_t size, Env* env) {
  const std::string tmp = uniqueTempName(path);
  try {
    writeTemp(tmp, data, size, env);
    env->renameFile(tmp, path);
  } catch (...) {
    removeQuietly(env, tmp);
    throw;
  }
  env->syncDir(parentOf(path));  // the new name survives a crash
}

GltfInfo writeGltfFile(const std::string& path, const GltfMeshView& mesh, const GltfOptions& options, Env* env) {
  const std::string name = path.substr(path.find_last_of('/') + 1);
  const size_t dot = name.find_last_of('.');
  std::string ext = dot == std::string::npos ? "" : name.substr(dot);
  for (auto& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  if (ext == ".glb") {
    GltfBytes g = buildGltf(mesh, options);
    std::vector<uint8_t> glb = encodeGlb(g);
    writeFileAtomic(path, glb.data(), glb.size(), env);
    return g.info;
  }
  if (ext != ".gltf") fail(path, "not a glTF name (.glb or .gltf)");
  // The JSON and its buffer: both complete under temporary names before either is renamed.
  const std::string binPath = path.substr(0, path.size() - ext.size()) + ".bin";
  const std::string binName = binPath.substr(binPath.find_last_of('/') + 1);
  GltfBytes g = buildGltf(mesh, options, binName);
  const std::string binTmp = uniqueTempName(binPath), jsonTmp = uniqueTempName(path);
  bool binRenamed = false;
  try {
    writeTemp(binTmp, g.bin.data(), g.bin.size(), env);
    writeTemp(jsonTmp, g.json.data(), g.json.size(), env);
    env->renameFile(binTmp, binPath);
    binRenamed = true;
    env->renameFile(jsonTmp, path);
  } catch (...) {
    removeQuietly(env, binRenamed ? binPath : binTmp);
    removeQuietly(env, jsonTmp);
    throw;
  }
  env->syncDir(parentOf(path));
  return g.info;
}

void texturedGltfMeshOf(const TexturedCut& cut, const double gridOrigin[3], double gridStep, TexturedGltfMesh& out) {
  const WeldedMesh& m = cut.mesh;
  const size_t triangles = m.triangleCount();
  assert(cut.cornerUV.size() == 6 * triangles && cut.triangleTexture.size() == triangles);
  // A vertex per distinct (welded vertex, texture, coordinate): the coordinates are the MT's
  // (multiples of 1/16 texel), compared as the floats written.
  std::unordered_map<uint64_t, uint32_t> first;  // (vertex, texture) -> first split vertex: a chain
  std::vector<uint32_t> next;                     // of the split vertices of one key
  std::vector<uint32_t> source;                   // split vertex -> welded vertex
  std::vector<uint64_t> uvKey;                    // split vertex -> the float bits of u, 1 - v
  out.triangles.resize(3 * triangles);
  out.triangleImage.assign(cut.triangleTexture.begin(), cut.triangleTexture.end());
  for (size_t t = 0; t < triangles; ++t)
    for (int k = 0; k < 3; ++k) {
      const uint32_t w = m.triangles[3 * t + size_t(k)];
      const uint32_t tex = cut.triangleTexture[t];
      uint64_t key = 0;
      if (tex != UINT32_MAX) {
        const float u = std::clamp(cut.cornerUV[6 * t + 2 * size_t(k)], 0.0f, 1.0f);
        const float v = float(1.0 - double(std::clamp(cut.cornerUV[6 * t + 2 * size_t(k) + 1], 0.0f, 1.0f)));
        uint32_t bu, bv;
        std::memcpy(&bu, &u, 4);
        std::memcpy(&bv, &v, 4);
        key = uint64_t(bu) << 32 | bv;
      }
      const uint64_t vk = uint64_t(w) << 32 | tex;
      auto it = first.find(vk);
      uint32_t found = UINT32_MAX;
      if (it != first.end())
        for (uint32_t s = it->second; s != UINT32_MAX; s = next[s])
          if (uvKey[s] == key) {
            found = s;
            break;
          }
      if (found == UINT32_MAX) {
        found = uint32_t(source.size());
        source.push_back(w);
        uvKey.push_back(key);
        if (it == first.end()) {
          next.push_back(UINT32_MAX);
          first.emplace(vk, found);
        } else {
          next.push_back(it->second);
          it->second = found;
        }
      }
      out.triangles[3 * t + size_t(k)] = found;
    }
  const size_t n = source.size();
  out.positions.resize(3 * n);
  out.q.resize(m.q.empty() ? 0 : 3 * n);
  out.normals.resize(m.normals.empty() ? 0 : 3 * n);
  out.colors.resize(m.colors.empty() ? 0 : 4 * n);
  out.texcoords.resize(2 * n);
  for (size_t v = 0; v < n; ++v) {
    const size_t w = source[v];
    std::copy_n(&m.positions[3 * w], 3, &out.positions[3 * v]);
    if (!m.q.empty()) std::copy_n(&m.q[3 * w], 3, &out.q[3 * v]);
    if (!m.normals.empty()) std::copy_n(&m.normals[3 * w], 3, &out.normals[3 * v]);
    if (!m.colors.empty()) std::copy_n(&m.colors[4 * w], 4, &out.colors[4 * v]);
    const uint32_t bu = uint32_t(uvKey[v] >> 32), bv = uint32_t(uvKey[v]);
    std::memcpy(&out.texcoords[2 * v], &bu, 4);
    std::memcpy(&out.texcoords[2 * v + 1], &bv, 4);
  }
  out.images.clear();
  for (const CutTexture& t : cut.textures) {
    GltfMeshView::Image im;
    im.data = t.image.data();
    im.size = t.image.size();
    im.png = t.imageFormat == format::kImagePng;
    out.images.push_back(im);
  }
  GltfMeshView& view = out.view;
  view = GltfMeshView{};
  view.vertexCount = n;
  view.triangleCount = triangles;
  view.positions = out.positions.data();
  view.triangles = out.triangles.data();
  view.normals = out.normals.empty() ? nullptr : out.normals.data();
  view.colors = out.colors.empty() ? nullptr : out.colors.data();
  view.q = out.q.empty() ? nullptr : out.q.data();
  for (int a = 0; a < 3; ++a) view.gridOrigin[a] = gridOrigin[a];
  view.gridStep = gridStep;
  view.texcoords = out.texcoords.data();
  view.triangleImage = out.triangleImage.data();
  view.images = out.images.data();
  view.imageCount = out.images.size();
}

}  // namespace mt::interop
