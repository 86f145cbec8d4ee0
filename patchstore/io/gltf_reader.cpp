// glTF 2.0 reader (.gltf and .glb): a streaming parser of our own rather than tinygltf.
//
// Why not tinygltf (Debian libtinygltf-dev): it loads every buffer of the file into memory before
// returning, so a 50 GB GLB scan would need 50 GB of RAM, against the readers' contract
// (mesh_reader.h: memory independent of the file's size). Here the JSON (small: it describes the
// buffers, it does not hold them) is parsed whole with nlohmann::json, and the binary data is read
// accessor by accessor, kBatch elements at a time, with positional reads (base/env.h), from the
// GLB's BIN chunk or the external .bin files. Compressed data cannot be read piecewise: a
// KHR_draco_mesh_compression primitive is decoded whole (Debian libdraco) and an
// EXT_meshopt_compression buffer view is decoded whole (meshoptimizer's decoders) while its
// primitive is read, so their memory is bounded by the largest compressed primitive, not the file.
//
// What is read: every mesh instance of the default scene (scene, else scene 0; without scenes,
// every mesh once, untransformed), with its node's world transform applied in double (so a
// georeferenced model placed by a node translation keeps its precision); POSITION, NORMAL
// (transformed by the inverse transpose), COLOR_0 (to RGBA8), and the texture coordinates a
// material's pbrMetallicRoughness.baseColorTexture names (TEXCOORD_<texCoord>, flipped to v up as
// the other readers deliver them) with the material, per vertex (glTF's vertices are per primitive,
// so a seam already is two vertices); other attributes are checked for their accessor's bounds
// but not delivered;
// TRIANGLES, TRIANGLE_STRIP and TRIANGLE_FAN primitives, indexed or not; POINTS and LINES are
// skipped. A transform with a negative determinant flips the winding back (glTF 3.7.4). Sparse
// accessors, external buffers by URL (http...), and KHR_mesh_quantization's integer positions
// are handled as follows: sparse is refused with a message, URLs are refused, integer (normalized
// or not) components are converted as the glTF spec says.
//
// Every error is "PATH: what (accessor N / buffer view N / byte offset X)".
#include <draco/compression/decode.h>
#include <meshoptimizer.h>

#include <array>
#include <cmath>
#include <cstring>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>

#include "base/env.h"
#include "base/output_path.h"
#include "patchstore/io/reader_util.h"

namespace mt::io {

namespace {

using nlohmann::json;

constexpr uint32_t kGlbMagic = 0x46546C67, kChunkJson = 0x4E4F534A, kChunkBin = 0x004E4942;
// The JSON of a glTF describes, it does not hold data: 256 MiB is far beyond any real one and
// keeps a damaged length from allocating without limit. Data URIs count against it too.
constexpr uint64_t kMaxJson = uint64_t(256) << 20;

using Mat4 = std::array<double, 16>;  // column-major, as glTF
constexpr Mat4 kIdentity = {1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};

Mat4 multiply(const Mat4& a, const Mat4& b) {
  Mat4 r{};
  for (int c = 0; c < 4; ++c)
    for (int row = 0; row < 4; ++row) {
      double s = 0;
      for (int k = 0; k < 4; ++k) s += a[k * 4 + row] * b[c * 4 + k];
      r[c * 4 + row] = s;
    }
  return r;
}

int componentCount(const std::string& type) {
  if (type == "SCALAR") return 1;
  if (type == "VEC2") return 2;
  if (type == "VEC3") return 3;
  if (type == "VEC4") return 4;
  if (type == "MAT2") return 4;
  if (type == "MAT3") return 9;
  if (type == "MAT4") return 16;
  return 0;
}

int componentSize(int type) {
  switch (type) {
    case 5120: case 5121: return 1;
    case 5122: case 5123: return 2;
    case 5125: case 5126: return 4;
  }
  return 0;
}

double componentValue(const uint8_t* p, int type, bool normalized) {
  switch (type) {
    case 5120: { int8_t v; std::memcpy(&v, p, 1); return normalized ? std::max(v / 127.0, -1.0) : v; }
    case 5121: return normalized ? p[0] / 255.0 : p[0];
    case 5122: { int16_t v; std::memcpy(&v, p, 2); return normalized ? std::max(v / 32767.0, -1.0) : v; }
    case 5123: { uint16_t v; std::memcpy(&v, p, 2); return normalized ? v / 65535.0 : v; }
    case 5125: { uint32_t v; std::memcpy(&v, p, 4); return normalized ? v / 4294967295.0 : v; }
    case 5126: { float v; std::memcpy(&v, p, 4); return v; }
  }
  return 0;
}

std::vector<uint8_t> decodeBase64(std::string_view s, const std::string& path, const std::string& what) {
  auto value = [](char c) -> int {
    if (c >= 'A' && c <= 'Z') return c - 'A';
    if (c >= 'a' && c <= 'z') return c - 'a' + 26;
    if (c >= '0' && c <= '9') return c - '0' + 52;
    if (c == '+' || c == '-') return 62;
    if (c == '/' || c == '_') return 63;
    return -1;
  };
  std::vector<uint8_t> out;
  out.reserve(s.size() / 4 * 3);
  uint32_t acc = 0;
  int bits = 0;
  for (size_t i = 0; i < s.size(); ++i) {
    if (s[i] == '=') break;
    int v = value(s[i]);
    if (v < 0) fail(path, what + ": bad base64 character at position " + std::to_string(i) + " of its data URI");
    acc = (acc << 6) | uint32_t(v);
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out.push_back(uint8_t(acc >> bits));
    }
  }
  return out;
}

class GltfReader final : public MeshReader {
 public:
  GltfReader(const std::string& path, bool glb, const MeshOpenOptions& options) : path_(path), options_(options) {
    env_ = Env::Default();
    file_ = env_->newRandomAccessFile(path);
    size_ = file_->size();
    header_.format = glb ? MeshFormat::Glb : MeshFormat::Gltf;
    std::string text;
    if (glb) {
      text = readGlbContainer();
    } else {
      if (size_ > kMaxJson) fail(path_, "a .gltf JSON of " + std::to_string(size_) + " bytes is larger than the 256 MiB accepted");
      text.resize(size_t(size_));
      file_->read(0, text.size(), text.data());
      jsonStart_ = 0;
    }
    try {
      doc_ = json::parse(text);
    } catch (const json::parse_error& e) {
      fail(path_, std::string("bad JSON at byte offset ") + std::to_string(jsonStart_ + e.byte - (e.byte ? 1 : 0)) + ": " +
                      std::string(e.what()).substr(std::string(e.what()).find(':') + 2));
    } catch (const json::exception& e) {  // e.g. a number too large for a double (no byte offset known)
      fail(path_, std::string("bad JSON (from byte offset ") + std::to_string(jsonStart_) + "): " +
                      std::string(e.what()).substr(std::string(e.what()).find(']') + 2));
    }
    if (!doc_.is_object()) fail(path_, "the glTF JSON is not an object (byte offset " + std::to_string(jsonStart_) + ")");
    checkAsset();
    openBuffers();
    planInstances();
    planMaterials();
  }

  const MeshHeader& header() const override { return header_; }

  ReadStats read(MeshSink& sink) override {
    ReadStats stats;
    sink.begin(header_);
    Batcher batch(sink, stats);
    for (const Instance& inst : instances_) readPrimitive(inst, batch);
    batch.flush();
    stats.bytes = size_;
    sink.end(stats);
    return stats;
  }

 private:
  struct Buffer {
    std::unique_ptr<RandomAccessFile> file;  // null: memory (data URI)
    uint64_t base = 0;                        // offset of the buffer in `file`
    uint64_t length = 0;                      // declared byteLength (checked against what exists)
    std::vector<uint8_t> memory;
    std::string name;                         // for messages
  };
  struct Instance {
    Mat4 world;
    size_t mesh, primitive;
    uint32_t material = kNoMaterial;  // index into header_.materials when the primitive is textured
    int64_t texCoord = -1;            // its TEXCOORD_<n>
  };

  // ---- Container ------------------------------------------------------------------------------
  std::string readGlbContainer() {
    if (size_ < 20) fail(path_, "GLB shorter than its 12-byte header and a chunk header (" + std::to_string(size_) + " bytes)");
    uint32_t h[3];
    file_->read(0, 12, h);
    if (h[0] != kGlbMagic) fail(path_, "not a GLB: bad magic at byte offset 0");
    if (h[1] != 2) fail(path_, "GLB version " + std::to_string(h[1]) + " at byte offset 4 (only 2 is glTF 2.0)");
    if (h[2] != size_)
      fail(path_, "GLB length " + std::to_string(h[2]) + " at byte offset 8 differs from the file's " + std::to_string(size_) +
                      " bytes (truncated?)");
    std::string text;
    uint64_t at = 12;
    bool first = true;
    while (at < size_) {
      if (size_ - at < 8) fail(path_, "truncated GLB chunk header at byte offset " + std::to_string(at));
      uint32_t c[2];
      file_->read(at, 8, c);
      if (c[0] > size_ - at - 8)
        fail(path_, "GLB chunk length " + std::to_string(c[0]) + " at byte offset " + std::to_string(at) + " runs past the end of the file");
      if (first) {
        if (c[1] != kChunkJson) fail(path_, "the first GLB chunk is not JSON (byte offset " + std::to_string(at + 4) + ")");
        if (c[0] > kMaxJson) fail(path_, "GLB JSON chunk of " + std::to_string(c[0]) + " bytes is larger than the 256 MiB accepted");
        text.resize(c[0]);
        file_->read(at + 8, c[0], text.data());
        jsonStart_ = at + 8;
        first = false;
      } else if (c[1] == kChunkBin && binStart_ == UINT64_MAX) {
        binStart_ = at + 8;
        binLength_ = c[0];
      }
      at += 8 + ((uint64_t(c[0]) + 3) & ~uint64_t(3));
    }
    if (first) fail(path_, "GLB without a JSON chunk");
    return text;
  }

  void checkAsset() {
    auto it = doc_.find("asset");
    if (it == doc_.end() || !it->is_object() || !it->contains("version") || !(*it)["version"].is_string())
      fail(path_, "no asset.version: not a glTF document");
    const std::string v = (*it)["version"];
    if (v.substr(0, 2) != "2.") fail(path_, "glTF version " + v + " (this reader reads 2.x)");
    if (doc_.contains("extensionsRequired"))
      for (const auto& e : doc_["extensionsRequired"]) {
        const std::string name = e.is_string() ? e.get<std::string>() : "?";
        if (name != "KHR_draco_mesh_compression" && name != "EXT_meshopt_compression" && name != "KHR_mesh_quantization" &&
            name != "KHR_materials_unlit" && name != "KHR_texture_transform")
          fail(path_, "requires the extension " + name + ", which this reader does not read");
      }
  }

  // ---- Typed access to the JSON, with messages naming the element ------------------------------
  const json& array(const char* name) {
    static const json empty = json::array();
    auto it = doc_.find(name);
    if (it == doc_.end()) return empty;
    if (!it->is_array()) fail(path_, std::string("'") + name + "' is not an array");
    return *it;
  }
  const json& element(const char* name, int64_t index, const std::string& by) {
    const json& a = array(name);
    if (index < 0 || uint64_t(index) >= a.size() || !a[size_t(index)].is_object())
      fail(path_, by + " refers to " + name + " " + std::to_string(index) + ", which does not exist (" +
                      std::to_string(a.size()) + " " + name + ")");
    return a[size_t(index)];
  }
  static std::string text(const json& o, const char* key, const std::string& fallback, const std::string& path,
                          const std::string& what) {
    auto it = o.find(key);
    if (it == o.end()) return fallback;
    if (!it->is_string()) fail(path, what + ": " + key + " is not a string");
    return it->get<std::string>();
  }
  static bool flag(const json& o, const char* key, const std::string& path, const std::string& what) {
    auto it = o.find(key);
    if (it == o.end()) return false;
    if (!it->is_boolean()) fail(path, what + ": " + key + " is not true or false");
    return it->get<bool>();
  }
  static int64_t integer(const json& o, const char* key, int64_t fallback, const std::string& path, const std::string& what) {
    auto it = o.find(key);
    if (it == o.end()) {
      if (fallback == INT64_MIN) fail(path, what + " has no " + key);
      return fallback;
    }
    if (!it->is_number_integer() || it->get<int64_t>() < 0) fail(path, what + ": " + key + " is not a non-negative integer");
    return it->get<int64_t>();
  }

  // ---- Buffers ----------------------------------------------------------------------------------
  void openBuffers() {
    const json& bufs = array("buffers");
    for (size_t i = 0; i < bufs.size(); ++i) {
      const std::string what = "buffer " + std::to_string(i);
      const json& b = bufs[i];
      if (!b.is_object()) fail(path_, what + " is not an object");
      Buffer buf;
      buf.name = what;
      buf.length = uint64_t(integer(b, "byteLength", INT64_MIN, path_, what));
      auto uri = b.find("uri");
      if (uri == b.end()) {
        // The GLB's BIN chunk (buffer 0 only), or an EXT_meshopt_compression fallback with no data.
        bool fallback = b.contains("extensions") && b["extensions"].contains("EXT_meshopt_compression");
        if (i == 0 && binStart_ != UINT64_MAX) {
          if (buf.length > binLength_)
            fail(path_, what + ": byteLength " + std::to_string(buf.length) + " is larger than the GLB's BIN chunk (" +
                            std::to_string(binLength_) + " bytes at byte offset " + std::to_string(binStart_) + ")");
          buf.base = binStart_;
          buf.file = env_->newRandomAccessFile(path_);
        } else if (!fallback) {
          fail(path_, what + " has no uri and is not the GLB's BIN chunk");
        }
      } else {
        if (!uri->is_string()) fail(path_, what + ": uri is not a string");
        const std::string u = *uri;
        if (u.rfind("data:", 0) == 0) {
          const size_t comma = u.find(',');
          if (comma == std::string::npos || u.substr(0, comma).find(";base64") == std::string::npos)
            fail(path_, what + ": a data URI that is not base64");
          buf.memory = decodeBase64(std::string_view(u).substr(comma + 1), path_, what);
          if (buf.memory.size() < buf.length)
            fail(path_, what + ": its data URI holds " + std::to_string(buf.memory.size()) + " bytes, byteLength says " +
                            std::to_string(buf.length));
        } else {
          if (u.find("://") != std::string::npos) fail(path_, what + ": uri " + u + " is not a local file");
          const size_t slash = path_.find_last_of('/');
          const std::string file = (slash == std::string::npos ? "" : path_.substr(0, slash + 1)) + u;
          buf.name = file;
          buf.file = env_->newRandomAccessFile(file);  // Io "FILE: cannot open"
          if (buf.file->size() < buf.length)
            fail(file, "holds " + std::to_string(buf.file->size()) + " bytes, " + what + " of " + path_ + " says byteLength " +
                           std::to_string(buf.length) + " (truncated?)");
        }
      }
      buffers_.push_back(std::move(buf));
    }
  }

  // Bytes [offset, offset + size) of buffer `index` exist and hold data.
  void checkBufferRange(size_t index, uint64_t offset, uint64_t size, const std::string& what) const {
    if (index >= buffers_.size()) fail(path_, what + " refers to buffer " + std::to_string(index) + ", which does not exist");
    const Buffer& b = buffers_[index];
    if (offset > b.length || size > b.length - offset)
      fail(path_, what + ": bytes " + std::to_string(offset) + ".." + std::to_string(offset + size) + " are beyond " + b.name +
                      "'s " + std::to_string(b.length) + " bytes");
    if (size && !b.file && b.memory.empty())
      fail(path_, what + " reads " + b.name + ", which has no data (a meshopt fallback buffer)");
  }
  void readBuffer(size_t index, uint64_t offset, size_t size, uint8_t* out, const std::string& what) {
    checkBufferRange(index, offset, size, what);
    const Buffer& b = buffers_[index];
    if (b.file) b.file->read(b.base + offset, size, out);
    else if (size) std::memcpy(out, b.memory.data() + offset, size);
  }

  // A buffer view's bytes [offset, offset + size): from its buffer, or from its meshopt decoding.
  struct View {
    int64_t index;
    uint64_t length = 0;
    uint32_t stride = 0;
    const std::vector<uint8_t>* decoded = nullptr;
    size_t buffer = 0;
    uint64_t offset = 0;
  };
  View view(int64_t index, const std::string& by) {
    const json& v = element("bufferViews", index, by);
    const std::string what = "buffer view " + std::to_string(index);
    View r;
    r.index = index;
    r.buffer = size_t(integer(v, "buffer", INT64_MIN, path_, what));
    r.offset = uint64_t(integer(v, "byteOffset", 0, path_, what));
    r.length = uint64_t(integer(v, "byteLength", INT64_MIN, path_, what));
    const int64_t stride = integer(v, "byteStride", 0, path_, what);
    if (stride > 252) fail(path_, what + ": byteStride " + std::to_string(stride) + " is larger than glTF's 252");
    r.stride = uint32_t(stride);
    if (v.contains("extensions") && v["extensions"].contains("EXT_meshopt_compression")) {
      r.decoded = &meshoptView(index, v["extensions"]["EXT_meshopt_compression"], r.length);
    } else {
      checkBufferRange(r.buffer, r.offset, r.length, what);
    }
    return r;
  }
  void readView(const View& v, uint64_t offset, size_t size, uint8_t* out, const std::string& what) {
    if (offset > v.length || size > v.length - offset)
      fail(path_, what + ": bytes " + std::to_string(offset) + ".." + std::to_string(offset + size) + " are beyond buffer view " +
                      std::to_string(v.index) + "'s " + std::to_string(v.length) + " bytes");
    if (v.decoded) std::memcpy(out, v.decoded->data() + offset, size);
    else readBuffer(v.buffer, v.offset + offset, size, out, what);
  }

  const std::vector<uint8_t>& meshoptView(int64_t index, const json& ext, uint64_t length) {
    auto it = decoded_.find(index);
    if (it != decoded_.end()) return it->second;
    const std::string what = "buffer view " + std::to_string(index) + " (EXT_meshopt_compression)";
    const size_t buffer = size_t(integer(ext, "buffer", INT64_MIN, path_, what));
    const uint64_t offset = uint64_t(integer(ext, "byteOffset", 0, path_, what));
    const uint64_t clength = uint64_t(integer(ext, "byteLength", INT64_MIN, path_, what));
    const uint64_t stride = uint64_t(integer(ext, "byteStride", INT64_MIN, path_, what));
    const uint64_t count = uint64_t(integer(ext, "count", INT64_MIN, path_, what));
    const std::string mode = text(ext, "mode", "", path_, what);
    const std::string filter = text(ext, "filter", "NONE", path_, what);
    if (stride == 0 || stride > 256 || count > (uint64_t(1) << 32) || stride * count > length + stride ||
        length > stride * count + stride)
      fail(path_, what + ": byteStride " + std::to_string(stride) + " x count " + std::to_string(count) +
                      " does not fit the view's " + std::to_string(length) + " bytes");
    // meshopt's codecs spend at least one byte per 64 decoded (a 2-bit header per 16 bytes of a
    // vertex stream; a byte per triangle or index): more is damage, and would allocate without limit.
    if (stride * count > 64 * clength + 256)
      fail(path_, what + ": byteStride " + std::to_string(stride) + " x count " + std::to_string(count) +
                      " is more than " + std::to_string(clength) + " compressed bytes can hold");
    checkBufferRange(buffer, offset, clength, what);  // before allocating what it claims
    std::vector<uint8_t> code(clength);
    readBuffer(buffer, offset, code.size(), code.data(), what);
    std::vector<uint8_t> out(std::max<uint64_t>(length, stride * count));
    int rc = -1;
    if (mode == "ATTRIBUTES") {
      if (stride % 4) fail(path_, what + ": ATTRIBUTES with a byteStride that is not a multiple of 4");
      rc = meshopt_decodeVertexBuffer(out.data(), count, stride, code.data(), code.size());
      if (rc == 0) {
        if (filter == "OCTAHEDRAL") meshopt_decodeFilterOct(out.data(), count, stride);
        else if (filter == "QUATERNION") meshopt_decodeFilterQuat(out.data(), count, stride);
        else if (filter == "EXPONENTIAL") meshopt_decodeFilterExp(out.data(), count, stride);
        else if (filter != "NONE") fail(path_, what + ": unknown filter " + filter);
      }
    } else if (mode == "TRIANGLES" || mode == "INDICES") {
      if (stride != 2 && stride != 4) fail(path_, what + ": " + mode + " with byteStride " + std::to_string(stride) + " (2 or 4)");
      if (mode == "TRIANGLES" && count % 3) fail(path_, what + ": TRIANGLES with a count that is not a multiple of 3");
      rc = mode == "TRIANGLES" ? meshopt_decodeIndexBuffer(out.data(), count, stride, code.data(), code.size())
                               : meshopt_decodeIndexSequence(out.data(), count, stride, code.data(), code.size());
    } else {
      fail(path_, what + ": unknown mode '" + mode + "'");
    }
    if (rc != 0)
      fail(path_, what + ": the compressed data (buffer " + std::to_string(buffer) + ", bytes " + std::to_string(offset) + ".." +
                      std::to_string(offset + clength) + ") does not decode (meshopt error " + std::to_string(rc) + ")");
    return decoded_.emplace(index, std::move(out)).first->second;
  }

  // ---- Accessors ------------------------------------------------------------------------------
  struct Accessor {
    int64_t index = -1;
    std::string what;
    uint64_t count = 0;
    int type = 0, components = 0, size = 0;
    bool normalized = false;
    std::optional<View> view;  // none: every element is zero
    uint64_t offset = 0;       // byteOffset within the view
    uint32_t stride = 0;
  };
  Accessor accessor(int64_t index, const std::string& role) {
    Accessor a;
    a.index = index;
    a.what = "accessor " + std::to_string(index) + " (" + role + ")";
    const json& j = element("accessors", index, role);
    a.count = uint64_t(integer(j, "count", INT64_MIN, path_, a.what));
    a.type = int(integer(j, "componentType", INT64_MIN, path_, a.what));
    a.components = componentCount(text(j, "type", "", path_, a.what));
    a.size = componentSize(a.type);
    a.normalized = flag(j, "normalized", path_, a.what);
    if (!a.size || !a.components) fail(path_, a.what + ": bad componentType or type");
    if (j.contains("sparse")) fail(path_, a.what + ": sparse accessors are not read");
    a.offset = uint64_t(integer(j, "byteOffset", 0, path_, a.what));
    const uint32_t element = uint32_t(a.size * a.components);
    if (j.contains("bufferView")) {
      a.view = view(integer(j, "bufferView", INT64_MIN, path_, a.what), a.what);
      a.stride = a.view->stride ? a.view->stride : element;
      if (a.stride < element) fail(path_, a.what + ": byteStride " + std::to_string(a.stride) + " is smaller than an element");
      if (a.count && (a.offset > a.view->length || (a.count - 1) * a.stride + element > a.view->length - a.offset))
        fail(path_, a.what + ": " + std::to_string(a.count) + " elements from byte " + std::to_string(a.offset) +
                        " run past buffer view " + std::to_string(a.view->index) + "'s " + std::to_string(a.view->length) + " bytes");
    }
    return a;
  }
  // Elements [first, first + n) as doubles, components per element, into out.
  void readAccessor(const Accessor& a, uint64_t first, size_t n, std::vector<double>& out) {
    out.assign(n * size_t(a.components), 0.0);
    if (!a.view || n == 0) return;
    const uint32_t element = uint32_t(a.size * a.components);
    const uint64_t span = (n - 1) * uint64_t(a.stride) + element;
    raw_.resize(size_t(span));
    readView(*a.view, a.offset + first * a.stride, size_t(span), raw_.data(), a.what);
    for (size_t i = 0; i < n; ++i)
      for (int c = 0; c < a.components; ++c)
        out[i * a.components + c] = componentValue(raw_.data() + i * a.stride + c * a.size, a.type, a.normalized);
  }
  uint64_t elementOffset(const Accessor& a, uint64_t i) const {
    if (!a.view || a.view->decoded) return a.offset + i * a.stride;  // within the decoded view
    return buffers_[a.view->buffer].base + a.view->offset + a.offset + i * a.stride;
  }

  // ---- Scene ----------------------------------------------------------------------------------
  Mat4 localMatrix(const json& node, const std::string& what) {
    if (node.contains("matrix")) {
      const json& m = node["matrix"];
      if (!m.is_array() || m.size() != 16) fail(path_, what + ": matrix is not 16 numbers");
      Mat4 r;
      for (int i = 0; i < 16; ++i) {
        if (!m[i].is_number()) fail(path_, what + ": matrix is not 16 numbers");
        r[i] = m[i].get<double>();
      }
      return r;
    }
    auto vec = [&](const char* key, size_t n, std::array<double, 4> fallback) {
      if (!node.contains(key)) return fallback;
      const json& v = node[key];
      if (!v.is_array() || v.size() != n) fail(path_, what + ": " + key + " is not " + std::to_string(n) + " numbers");
      for (size_t i = 0; i < n; ++i) {
        if (!v[i].is_number()) fail(path_, what + ": " + key + " is not " + std::to_string(n) + " numbers");
        fallback[i] = v[i].get<double>();
      }
      return fallback;
    };
    const auto t = vec("translation", 3, {0, 0, 0, 0});
    const auto q = vec("rotation", 4, {0, 0, 0, 1});
    const auto s = vec("scale", 3, {1, 1, 1, 0});
    const double x = q[0], y = q[1], z = q[2], w = q[3];
    const double R[9] = {1 - 2 * (y * y + z * z), 2 * (x * y + z * w),     2 * (x * z - y * w),
                         2 * (x * y - z * w),     1 - 2 * (x * x + z * z), 2 * (y * z + x * w),
                         2 * (x * z + y * w),     2 * (y * z - x * w),     1 - 2 * (x * x + y * y)};  // columns
    Mat4 r = kIdentity;
    for (int c = 0; c < 3; ++c)
      for (int row = 0; row < 3; ++row) r[c * 4 + row] = R[c * 3 + row] * s[c];
    for (int row = 0; row < 3; ++row) r[12 + row] = t[row];
    return r;
  }

  void visit(int64_t index, const Mat4& parent, int depth) {
    const std::string what = "node " + std::to_string(index);
    if (depth > 1000) fail(path_, what + ": the node hierarchy is deeper than 1000 (a cycle?)");
    const json& node = element("nodes", index, depth ? "a node's children" : "the scene");
    // glTF's nodes form disjoint trees (each has at most one parent): a node reached twice would
    // repeat its subtree, and a few shared children per level make that exponential.
    visited_.resize(array("nodes").size());
    if (visited_[size_t(index)]) fail(path_, what + " is reached twice (a second parent or a cycle; glTF nodes form trees)");
    visited_[size_t(index)] = 1;
    const Mat4 world = multiply(parent, localMatrix(node, what));
    if (node.contains("mesh")) addMesh(integer(node, "mesh", INT64_MIN, path_, what), world, what);
    if (node.contains("children")) {
      if (!node["children"].is_array()) fail(path_, what + ": children is not an array");
      for (const json& c : node["children"]) {
        if (!c.is_number_integer()) fail(path_, what + ": a child is not a node index");
        visit(c.get<int64_t>(), world, depth + 1);
      }
    }
  }

  void addMesh(int64_t mesh, const Mat4& world, const std::string& by) {
    const json& m = element("meshes", mesh, by);
    if (!m.contains("primitives") || !m["primitives"].is_array())
      fail(path_, "mesh " + std::to_string(mesh) + " has no primitives array");
    for (size_t p = 0; p < m["primitives"].size(); ++p) instances_.push_back({world, size_t(mesh), p});
    if (world != kIdentity) header_.doublePrecision = true;  // transformed in double
  }

  void planInstances() {
    const json& scenes = array("scenes");
    if (scenes.empty()) {
      for (size_t m = 0; m < array("meshes").size(); ++m) addMesh(int64_t(m), kIdentity, "the document");
    } else {
      const int64_t scene = integer(doc_, "scene", 0, path_, "the document");
      const json& s = element("scenes", scene, "the document");
      if (s.contains("nodes")) {
        if (!s["nodes"].is_array()) fail(path_, "scene " + std::to_string(scene) + ": nodes is not an array");
        for (const json& n : s["nodes"]) {
          if (!n.is_number_integer()) fail(path_, "scene " + std::to_string(scene) + ": a node is not an index");
          visit(n.get<int64_t>(), kIdentity, 0);
        }
      }
    }
    for (const Instance& inst : instances_) {
      const json& prim = doc_["meshes"][inst.mesh]["primitives"][inst.primitive];
      if (!prim.is_object() || !prim.contains("attributes") || !prim["attributes"].is_object())
        fail(path_, "mesh " + std::to_string(inst.mesh) + " primitive " + std::to_string(inst.primitive) + " has no attributes");
      if (prim["attributes"].contains("NORMAL")) header_.hasNormals = true;
      if (prim["attributes"].contains("COLOR_0")) header_.hasColors = true;
    }
  }

  // ---- Materials and their base-colour images -----------------------------------------------
  // A primitive whose material has pbrMetallicRoughness.baseColorTexture is textured: its
  // TEXCOORD_<texCoord> is delivered per vertex with the material. The images become
  // InputMaterial::texture paths (what ingest tiles into the store, as for OBJ map_Kd): an
  // external image by its uri beside the file; one embedded in a buffer view or a data URI is
  // copied to a file in the scratch folder (MeshOpenOptions::scratchDir, which its owner removes;
  // without one, $TMPDIR, removed with the reader). Primitives without a base-colour texture are
  // untextured (kNoMaterial), as OBJ faces of a material without map_Kd.
  void planMaterials() {
    std::map<int64_t, uint32_t> used;  // glTF material -> header_.materials
    bool textured = false;
    for (Instance& inst : instances_) {
      const json& prim = doc_["meshes"][inst.mesh]["primitives"][inst.primitive];
      if (!prim.contains("material")) continue;
      const std::string what = "mesh " + std::to_string(inst.mesh) + " primitive " + std::to_string(inst.primitive);
      const int64_t m = integer(prim, "material", INT64_MIN, path_, what);
      const json& mat = element("materials", m, what);
      const std::string mwhat = "material " + std::to_string(m);
      auto pbr = mat.find("pbrMetallicRoughness");
      if (pbr == mat.end() || !pbr->is_object() || !pbr->contains("baseColorTexture")) continue;  // untextured
      const json& info = (*pbr)["baseColorTexture"];
      const std::string twhat = mwhat + " baseColorTexture";
      if (!info.is_object()) fail(path_, twhat + " is not an object");
      if (info.contains("extensions") && info["extensions"].contains("KHR_texture_transform"))
        fail(path_, twhat + ": KHR_texture_transform on a base-colour texture is not read");
      const int64_t texCoord = integer(info, "texCoord", 0, path_, twhat);
      const std::string attr = "TEXCOORD_" + std::to_string(texCoord);
      if (!prim["attributes"].contains(attr) &&
          !(prim.contains("extensions") && prim["extensions"].contains("KHR_draco_mesh_compression")))
        fail(path_, twhat + " uses texCoord " + std::to_string(texCoord) + ", but " + what + " has no " + attr);
      const int64_t texture = integer(info, "index", INT64_MIN, path_, twhat);
      const json& tex = element("textures", texture, twhat);
      const std::string xwhat = "texture " + std::to_string(texture);
      if (!tex.contains("source")) fail(path_, xwhat + " has no source image (only core glTF images, PNG and JPEG, are read)");
      const int64_t image = integer(tex, "source", INT64_MIN, path_, xwhat);
      element("images", image, xwhat);
      inst.material = materialIndex(used, m, mat, mwhat, image);
      inst.texCoord = texCoord;
      textured = true;
    }
    header_.hasTexcoords = textured;
  }

  uint32_t materialIndex(std::map<int64_t, uint32_t>& used, int64_t m, const json& mat, const std::string& what, int64_t image) {
    auto it = used.find(m);
    if (it != used.end()) return it->second;
    InputMaterial out;
    out.name = text(mat, "name", what, path_, what);
    out.source = path_ + " (" + what + ")";
    auto pbr = mat.find("pbrMetallicRoughness");
    if (pbr != mat.end() && pbr->is_object() && pbr->contains("baseColorFactor")) {
      const json& f = (*pbr)["baseColorFactor"];
      if (!f.is_array() || f.size() != 4) fail(path_, what + ": baseColorFactor is not 4 numbers");
      for (int c = 0; c < 3; ++c) {
        if (!f[size_t(c)].is_number()) fail(path_, what + ": baseColorFactor is not 4 numbers");
        out.diffuse[c] = uint8_t(std::lround(std::clamp(f[size_t(c)].get<double>(), 0.0, 1.0) * 255.0));
      }
    }
    if (image >= 0) {
      out.texture = imageFile(image, out.source);
      out.source = path_ + " (" + what + ", image " + std::to_string(image) + ")";
    }
    header_.materials.push_back(out);
    return used.emplace(m, uint32_t(header_.materials.size() - 1)).first->second;
  }

  // The path of image `index`'s bytes (its own file, or a copy of embedded bytes), its format
  // checked by the magic bytes (PNG or JPEG); deeper damage is found when ingest decodes it, with
  // the material and image named.
  std::string imageFile(int64_t index, const std::string& by) {
    auto done = imageFiles_.find(index);
    if (done != imageFiles_.end()) return done->second;
    const json& img = element("images", index, by);
    const std::string what = "image " + std::to_string(index);
    const std::string mime = text(img, "mimeType", "", path_, what);
    std::string file, where;
    std::vector<uint8_t> head(8, 0);
    size_t headSize = 0;
    if (img.contains("uri") && !(img["uri"].is_string() && img["uri"].get<std::string>().rfind("data:", 0) == 0)) {
      const std::string u = text(img, "uri", "", path_, what);
      if (u.find("://") != std::string::npos) fail(path_, what + ": uri " + u + " is not a local file");
      file = resolveBeside(path_, percentDecoded(u, what));
      where = " (" + file + ")";
      struct stat st;
      if (::stat(file.c_str(), &st) != 0) fail(path_, what + where + ": cannot open: " + std::strerror(errno));
      if (!S_ISREG(st.st_mode)) fail(path_, what + where + " is not a regular file");
      auto f = env_->newRandomAccessFile(file);
      headSize = size_t(std::min<uint64_t>(8, f->size()));
      f->read(0, headSize, head.data());
    } else {
      // Embedded: a data URI or a buffer view. Copied to the scratch folder in 1 MiB pieces.
      std::vector<uint8_t> memory;
      std::optional<View> v;
      uint64_t size = 0;
      if (img.contains("uri")) {
        const std::string u = img["uri"];
        const size_t comma = u.find(',');
        if (comma == std::string::npos || u.substr(0, comma).find(";base64") == std::string::npos)
          fail(path_, what + ": a data URI that is not base64");
        memory = decodeBase64(std::string_view(u).substr(comma + 1), path_, what);
        size = memory.size();
        where = " (data URI)";
      } else if (img.contains("bufferView")) {
        if (mime.empty()) fail(path_, what + ": an image in a buffer view needs a mimeType");
        v = view(integer(img, "bufferView", INT64_MIN, path_, what), what);
        size = v->length;
        where = " (buffer view " + std::to_string(v->index) +
                (v->decoded ? std::string(")") : ", byte offset " + std::to_string(buffers_[v->buffer].base + v->offset) + ")");
      } else {
        fail(path_, what + " has neither uri nor bufferView");
      }
      const std::string ext = mime == "image/png" ? ".png" : ".jpg";
      std::string dir = options_.scratchDir;
      const bool own = dir.empty();
      if (own) {
        const char* t = std::getenv("TMPDIR");
        dir = t && *t ? t : "/tmp";
      }
      const std::string base = path_.substr(path_.find_last_of('/') + 1);
      file = dir + "/" + base + "-image" + std::to_string(index) + ext;
      if (own) file = uniqueTempName(file) + ext;
      auto out = env_->newWritableFile(file);
      if (own) ownedFiles_.paths.push_back(file);  // else the scratch folder's owner removes it
      std::vector<uint8_t> piece;
      for (uint64_t off = 0; off < size; off += piece.size()) {
        piece.resize(size_t(std::min<uint64_t>(1 << 20, size - off)));
        if (v) readView(*v, off, piece.size(), piece.data(), what);
        else std::memcpy(piece.data(), memory.data() + off, piece.size());
        if (off == 0) {
          headSize = std::min<size_t>(8, piece.size());
          std::memcpy(head.data(), piece.data(), headSize);
        }
        out->append(piece.data(), piece.size());
      }
      out->close();
    }
    static const uint8_t kPng[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
    const bool png = headSize == 8 && std::memcmp(head.data(), kPng, 8) == 0;
    const bool jpeg = headSize >= 3 && head[0] == 0xFF && head[1] == 0xD8 && head[2] == 0xFF;
    if (!png && !jpeg)
      fail(path_, what + where + " is neither PNG nor JPEG (bad magic bytes): a corrupt image or another format");
    imageFiles_.emplace(index, file);
    return file;
  }

  std::string percentDecoded(const std::string& u, const std::string& what) {
    std::string out;
    for (size_t i = 0; i < u.size(); ++i) {
      if (u[i] != '%') {
        out += u[i];
        continue;
      }
      auto hex = [&](char c) -> int {
        if (c >= '0' && c <= '9') return c - '0';
        if (c >= 'a' && c <= 'f') return c - 'a' + 10;
        if (c >= 'A' && c <= 'F') return c - 'A' + 10;
        return -1;
      };
      if (i + 2 >= u.size() || hex(u[i + 1]) < 0 || hex(u[i + 2]) < 0) fail(path_, what + ": bad %-escape in uri " + u);
      out += char(hex(u[i + 1]) * 16 + hex(u[i + 2]));
      i += 2;
    }
    return out;
  }

  // ---- Primitives -----------------------------------------------------------------------------
  void readPrimitive(const Instance& inst, Batcher& batch) {
    const json& prim = doc_["meshes"][inst.mesh]["primitives"][inst.primitive];
    const std::string what = "mesh " + std::to_string(inst.mesh) + " primitive " + std::to_string(inst.primitive);
    const int64_t mode = integer(prim, "mode", 4, path_, what);
    if (mode < 4) return;  // points and lines: no triangles
    if (mode > 6) fail(path_, what + ": unknown mode " + std::to_string(mode));
    decoded_.clear();
    const Mat4& M = inst.world;
    // Normals go through the inverse transpose (the cofactor matrix, up to the determinant's scale).
    const double a = M[0], b = M[4], c = M[8], d = M[1], e = M[5], f = M[9], g = M[2], h = M[6], k = M[10];
    const double C[9] = {e * k - f * h, -(d * k - f * g), d * h - e * g, -(b * k - c * h), a * k - c * g,
                         -(a * h - b * g), b * f - c * e, -(a * f - c * d), a * e - b * d};  // rows
    const double det = a * C[0] + b * C[1] + c * C[2];
    const bool flip = det < 0;
    const uint64_t base = nextVertex_;

    const json& attrs = prim["attributes"];
    const bool draco = prim.contains("extensions") && prim["extensions"].contains("KHR_draco_mesh_compression");
    uint64_t vertexCount = 0;
    std::vector<uint32_t> dracoIndices;
    if (draco) {
      vertexCount = readDraco(prim["extensions"]["KHR_draco_mesh_compression"], what, M, C, batch, dracoIndices, inst);
    } else {
      if (!attrs.contains("POSITION")) fail(path_, what + " has no POSITION");
      Accessor pos = accessor(integer(attrs, "POSITION", INT64_MIN, path_, what), "POSITION of " + what);
      if (pos.components != 3) fail(path_, pos.what + " is not VEC3");
      if (!pos.view && pos.count) fail(path_, pos.what + " has no bufferView: every position would be zero (sparse is not read)");
      std::optional<Accessor> nor, col, uvs;
      if (inst.texCoord >= 0) {
        const std::string name = "TEXCOORD_" + std::to_string(inst.texCoord);
        uvs = accessor(integer(attrs, name.c_str(), INT64_MIN, path_, what), name + " of " + what);
        if (uvs->components != 2 || uvs->count != pos.count) fail(path_, uvs->what + " is not VEC2 with one per vertex");
        if (uvs->type != 5126 && !((uvs->type == 5121 || uvs->type == 5123) && uvs->normalized))
          fail(path_, uvs->what + ": not float, normalized unsigned byte or normalized unsigned short");
      }
      if (attrs.contains("NORMAL")) {
        nor = accessor(integer(attrs, "NORMAL", INT64_MIN, path_, what), "NORMAL of " + what);
        if (nor->components != 3 || nor->count != pos.count) fail(path_, nor->what + " is not VEC3 with one per vertex");
      }
      if (attrs.contains("COLOR_0")) {
        col = accessor(integer(attrs, "COLOR_0", INT64_MIN, path_, what), "COLOR_0 of " + what);
        if ((col->components != 3 && col->components != 4) || col->count != pos.count)
          fail(path_, col->what + " is not VEC3/VEC4 with one per vertex");
      }
      for (auto& [name, value] : attrs.items())  // the others: bounds checked, not delivered
        if (name != "POSITION" && name != "NORMAL" && name != "COLOR_0" && value.is_number_integer())
          accessor(value.get<int64_t>(), name + " of " + what);
      vertexCount = pos.count;
      std::vector<double> P, Nn, Cc, Uv;
      for (uint64_t first = 0; first < pos.count; first += kBatch) {
        const size_t n = size_t(std::min<uint64_t>(kBatch, pos.count - first));
        readAccessor(pos, first, n, P);
        if (nor) readAccessor(*nor, first, n, Nn);
        if (col) readAccessor(*col, first, n, Cc);
        if (uvs) readAccessor(*uvs, first, n, Uv);
        for (size_t i = 0; i < n; ++i) {
          InputVertex& v = batch.addVertex();
          if (!(std::isfinite(P[3 * i]) && std::isfinite(P[3 * i + 1]) && std::isfinite(P[3 * i + 2])))
            fail(path_, pos.what + " element " + std::to_string(first + i) + ": non-finite position at byte offset " +
                            std::to_string(elementOffset(pos, first + i)));
          transform(M, C, &P[3 * i], nor ? &Nn[3 * i] : nullptr, v);
          if (!(std::isfinite(v.p[0]) && std::isfinite(v.p[1]) && std::isfinite(v.p[2])))
            fail(path_, pos.what + " element " + std::to_string(first + i) + ": the node transform makes its position non-finite");
          color(col ? &Cc[size_t(col->components) * i] : nullptr, col ? col->components : 0, v);
          if (uvs) {
            if (!texcoord(Uv[2 * i], Uv[2 * i + 1], inst.material, v))
              fail(path_, uvs->what + " element " + std::to_string(first + i) + ": texture coordinate (" + std::to_string(Uv[2 * i]) +
                              ", " + std::to_string(Uv[2 * i + 1]) + ") is outside [0, 1] (repeating textures are not supported), at byte offset " +
                              std::to_string(elementOffset(*uvs, first + i)));
          } else {
            texcoord(0, 1, kNoMaterial, v);
          }
        }
      }
    }
    if (base + vertexCount > kMaxVertices) fail(path_, what + ": more than 2^32 - 2 vertices in all");
    nextVertex_ = base + vertexCount;

    // Triangles.
    auto emit = [&](uint64_t i0, uint64_t i1, uint64_t i2) {
      if (flip) std::swap(i1, i2);
      batch.addTriangle(uint32_t(base + i0), uint32_t(base + i1), uint32_t(base + i2));
    };
    auto assemble = [&](auto indexAt, uint64_t n) {
      if (mode == 4) {
        for (uint64_t t = 0; t + 2 < n; t += 3) emit(indexAt(t), indexAt(t + 1), indexAt(t + 2));
      } else if (mode == 5) {
        for (uint64_t t = 0; t + 2 < n; ++t)
          if (t % 2 == 0) emit(indexAt(t), indexAt(t + 1), indexAt(t + 2));
          else emit(indexAt(t + 1), indexAt(t), indexAt(t + 2));
      } else {
        for (uint64_t t = 1; t + 1 < n; ++t) emit(indexAt(0), indexAt(t), indexAt(t + 1));
      }
    };
    if (draco) {
      if (mode != 4) fail(path_, what + ": a Draco primitive that is not TRIANGLES");
      assemble([&](uint64_t i) { return uint64_t(dracoIndices[size_t(i)]); }, dracoIndices.size());
      return;
    }
    if (!prim.contains("indices")) {
      assemble([](uint64_t i) { return i; }, vertexCount);
      return;
    }
    Accessor idx = accessor(integer(prim, "indices", INT64_MIN, path_, what), "indices of " + what);
    if (idx.components != 1 || idx.normalized || (idx.type != 5121 && idx.type != 5123 && idx.type != 5125))
      fail(path_, idx.what + ": not SCALAR unsigned byte, short or int");
    if (!idx.view && idx.count) fail(path_, idx.what + " has no bufferView: every index would be zero (sparse is not read)");
    if (mode == 4 && idx.count % 3) fail(path_, idx.what + ": " + std::to_string(idx.count) + " indices is not a multiple of 3");
    // Strips and fans refer back to their first corners: read them whole (a fan's first is kept).
    std::vector<double> I;
    std::vector<uint64_t> window;
    uint64_t fanFirst = 0;
    const uint64_t chunk = mode == 4 ? kBatch * 3 : kBatch;
    for (uint64_t first = 0; first < idx.count; first += chunk) {
      const size_t n = size_t(std::min<uint64_t>(chunk, idx.count - first));
      readAccessor(idx, first, n, I);
      for (size_t i = 0; i < n; ++i)
        if (I[i] >= double(vertexCount))
          fail(path_, idx.what + " element " + std::to_string(first + i) + ": index " + std::to_string(uint64_t(I[i])) +
                          " >= the primitive's " + std::to_string(vertexCount) + " vertices, at byte offset " +
                          std::to_string(elementOffset(idx, first + i)));
      if (mode == 4) {
        for (size_t t = 0; t + 2 < n; t += 3) emit(uint64_t(I[t]), uint64_t(I[t + 1]), uint64_t(I[t + 2]));
        continue;
      }
      // Strip/fan: keep the last two indices (and the fan's first) across chunks.
      for (size_t i = 0; i < n; ++i) {
        const uint64_t v = uint64_t(I[i]), at = first + i;
        if (at == 0) fanFirst = v;
        window.push_back(v);
        if (window.size() > 3) window.erase(window.begin());
        if (at < 2) continue;
        if (mode == 5) {
          if (at % 2 == 0) emit(window[0], window[1], window[2]);
          else emit(window[1], window[0], window[2]);
        } else {
          emit(fanFirst, window[1], window[2]);
        }
      }
    }
  }

  static void transform(const Mat4& M, const double C[9], const double* p, const double* n, InputVertex& v) {
    for (int r = 0; r < 3; ++r) v.p[r] = M[r] * p[0] + M[4 + r] * p[1] + M[8 + r] * p[2] + M[12 + r];
    if (n) {
      double t[3];
      for (int r = 0; r < 3; ++r) t[r] = C[3 * r] * n[0] + C[3 * r + 1] * n[1] + C[3 * r + 2] * n[2];
      const double len = std::sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2]);
      for (int r = 0; r < 3; ++r) v.n[r] = len > 0 && std::isfinite(len) ? float(t[r] / len) : 0.0f;
    } else {
      v.n[0] = v.n[1] = v.n[2] = 0;
    }
  }
  // glTF's v runs down the image; the readers deliver v up (OBJ's convention).
  static bool texcoord(double u, double v, uint32_t material, InputVertex& out) {
    double uu = u, vv = 1.0 - v;
    if (!acceptTexcoord(uu, vv)) return false;
    out.uv[0] = float(uu);
    out.uv[1] = float(vv);
    out.material = material;
    return true;
  }
  static void color(const double* c, int components, InputVertex& v) {
    for (int i = 0; i < 4; ++i) {
      const double x = i < components ? c[i] : 1.0;
      v.c[i] = uint8_t(std::lround(std::clamp(x, 0.0, 1.0) * 255.0));
    }
  }

  uint64_t readDraco(const json& ext, const std::string& what, const Mat4& M, const double C[9], Batcher& batch,
                     std::vector<uint32_t>& indices, const Instance& inst) {
    const std::string dwhat = what + " (KHR_draco_mesh_compression)";
    View v = view(integer(ext, "bufferView", INT64_MIN, path_, dwhat), dwhat);
    std::vector<uint8_t> bytes(size_t(v.length));
    readView(v, 0, bytes.size(), bytes.data(), dwhat);
    draco::DecoderBuffer in;
    in.Init(reinterpret_cast<const char*>(bytes.data()), bytes.size());
    draco::Decoder decoder;
    auto status = decoder.DecodeMeshFromBuffer(&in);
    if (!status.ok())
      fail(path_, dwhat + ": buffer view " + std::to_string(v.index) + " does not decode: " + status.status().error_msg_string());
    std::unique_ptr<draco::Mesh> mesh = std::move(status).value();
    if (!ext.contains("attributes") || !ext["attributes"].is_object()) fail(path_, dwhat + " has no attributes");
    const json& attrs = ext["attributes"];
    auto attribute = [&](const char* name) -> const draco::PointAttribute* {
      if (!attrs.contains(name)) return nullptr;
      const int64_t id = integer(attrs, name, INT64_MIN, path_, dwhat);
      const draco::PointAttribute* a = mesh->GetAttributeByUniqueId(uint32_t(id));
      if (!a) fail(path_, dwhat + ": the Draco data has no attribute " + std::to_string(id) + " for " + name);
      return a;
    };
    const draco::PointAttribute* pos = attribute("POSITION");
    if (!pos || pos->num_components() != 3) fail(path_, dwhat + ": no 3-component POSITION");
    const draco::PointAttribute* nor = attribute("NORMAL");
    const draco::PointAttribute* col = attribute("COLOR_0");
    const std::string uvName = "TEXCOORD_" + std::to_string(inst.texCoord);
    const draco::PointAttribute* uvs = inst.texCoord >= 0 ? attribute(uvName.c_str()) : nullptr;
    if (inst.texCoord >= 0 && (!uvs || uvs->num_components() != 2))
      fail(path_, dwhat + ": no 2-component " + uvName + " for its material's base-colour texture");
    const uint32_t points = mesh->num_points();
    for (uint32_t i = 0; i < points; ++i) {
      const draco::PointIndex pi(i);
      float p[3] = {0, 0, 0}, n[3] = {0, 0, 0}, c[4] = {1, 1, 1, 1};
      pos->ConvertValue<float>(pos->mapped_index(pi), 3, p);
      if (nor) nor->ConvertValue<float>(nor->mapped_index(pi), 3, n);
      int cc = 0;
      if (col) {
        cc = std::min<int>(4, col->num_components());
        if (col->data_type() == draco::DT_UINT8) {
          uint8_t u[4] = {255, 255, 255, 255};
          col->ConvertValue<uint8_t>(col->mapped_index(pi), int8_t(cc), u);
          for (int k = 0; k < 4; ++k) c[k] = u[k] / 255.0f;
        } else {
          col->ConvertValue<float>(col->mapped_index(pi), int8_t(cc), c);
        }
      }
      const double pd[3] = {p[0], p[1], p[2]}, nd[3] = {n[0], n[1], n[2]}, cd[4] = {c[0], c[1], c[2], c[3]};
      if (!(std::isfinite(pd[0]) && std::isfinite(pd[1]) && std::isfinite(pd[2])))
        fail(path_, dwhat + ": point " + std::to_string(i) + " has a non-finite position");
      InputVertex& out = batch.addVertex();
      transform(M, C, pd, nor ? nd : nullptr, out);
      if (!(std::isfinite(out.p[0]) && std::isfinite(out.p[1]) && std::isfinite(out.p[2])))
        fail(path_, dwhat + ": point " + std::to_string(i) + ": the node transform makes its position non-finite");
      color(col ? cd : nullptr, col ? 4 : 0, out);
      float uv[2] = {0, 1};
      if (uvs) uvs->ConvertValue<float>(uvs->mapped_index(pi), 2, uv);
      if (!texcoord(uv[0], uv[1], uvs ? inst.material : kNoMaterial, out))
        fail(path_, dwhat + ": point " + std::to_string(i) + ": texture coordinate (" + std::to_string(uv[0]) + ", " +
                        std::to_string(uv[1]) + ") is outside [0, 1] (repeating textures are not supported)");
    }
    indices.clear();
    indices.reserve(size_t(mesh->num_faces()) * 3);
    for (uint32_t f = 0; f < mesh->num_faces(); ++f) {
      const auto& face = mesh->face(draco::FaceIndex(f));
      for (int k = 0; k < 3; ++k) {
        if (face[k].value() >= points) fail(path_, dwhat + ": face " + std::to_string(f) + " refers to a point past the end");
        indices.push_back(face[k].value());
      }
    }
    return points;
  }

  std::string path_;
  MeshOpenOptions options_;
  std::map<int64_t, std::string> imageFiles_;  // image index -> the file holding its bytes
  // The copies of embedded images made in $TMPDIR: removed with the reader, and when its
  // constructor throws (e.g. at a later image with bad magic bytes), for then the members are
  // destroyed but not the reader.
  struct OwnedFiles {
    std::vector<std::string> paths;
    OwnedFiles() = default;
    OwnedFiles(const OwnedFiles&) = delete;
    OwnedFiles& operator=(const OwnedFiles&) = delete;
    ~OwnedFiles() {
      for (const std::string& f : paths) {
        try {
          Env::Default()->removeFile(f);
        } catch (const Error&) {
        }
      }
    }
  };
  OwnedFiles ownedFiles_;
  Env* env_ = nullptr;
  std::unique_ptr<RandomAccessFile> file_;
  uint64_t size_ = 0, jsonStart_ = 0, binStart_ = UINT64_MAX, binLength_ = 0;
  json doc_;
  MeshHeader header_;
  std::vector<Buffer> buffers_;
  std::vector<Instance> instances_;
  std::vector<uint8_t> visited_;  // nodes of the scene seen so far
  std::map<int64_t, std::vector<uint8_t>> decoded_;  // meshopt views of the current primitive
  std::vector<uint8_t> raw_;
  uint64_t nextVertex_ = 0;
};

}  // namespace

std::unique_ptr<MeshReader> openGltf(const std::string& path, bool glb, const MeshOpenOptions& options) {
  return std::make_unique<GltfReader>(path, glb, options);
}

}  // namespace mt::io
