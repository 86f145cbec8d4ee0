// PLY reader: ascii, binary_little_endian and binary_big_endian, streamed element by element.
//
// The header is turned into a flat description of every element (property types, which
// InputVertex field each vertex property feeds, fixed record sizes), so the data loops only do
// a switch on a scalar type per mapped property. The common binary layout (little-endian,
// "list uchar int|uint vertex_indices" as the face's only property) has a dedicated triangle
// loop that copies 13-byte records straight into the batch; any face that is not a triangle
// drops to the generic path for that one record.
//
// Textures (MeshLab's conventions): "comment TextureFile NAME" lines name the images (material
// k is the k-th, resolved beside the PLY); texture coordinates come per vertex (texture_u /
// texture_v, or s / t) or per face corner (a "texcoord" list of 2 floats per corner), and a face's
// image by "texnumber" (0 without it). Per-vertex coordinates without texnumber go to the sink as
// they are; otherwise they go per corner and openMesh splits them (per-vertex coordinates with
// texnumber are then held in RAM, 8 bytes a vertex). Coordinates without any TextureFile are
// ignored (nothing to show). Errors name the element and its line or byte offset.
//
// Triangle strips (the "tristrips" element some scanning pipelines write, e.g. the Digital
// Michelangelo Project's models: "property list int int vertex_indices", one long list whose
// strips are separated by -1) are read as OpenGL's GL_TRIANGLE_STRIP: triangle k of a strip is
// (v[k], v[k+1], v[k+2]), its first two corners swapped when k is odd, so every triangle keeps
// the strip's orientation. The degenerate triangles that join strips (a repeated index) are
// stitching, not surface: they are dropped, not delivered. A file may hold faces, strips or both.
// With an unsigned index type of 8 or 16 bits, vertex 255 or 65535 cannot be used (it ends a
// strip, as OpenGL's fixed restart index does). Strips take per-vertex texture coordinates (image
// 0); a file whose faces carry per-corner coordinates leaves its strips untextured.
#include <cstdint>
#include <string>
#include <vector>

#include "patchstore/io/reader_util.h"

namespace mt::io {
namespace {

enum class Type : uint8_t { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };

bool parseType(std::string_view name, Type& type) {
  static const struct {
    const char* name;
    Type type;
  } kNames[] = {{"char", Type::Int8},     {"int8", Type::Int8},       {"uchar", Type::UInt8},
                {"uint8", Type::UInt8},   {"short", Type::Int16},     {"int16", Type::Int16},
                {"ushort", Type::UInt16}, {"uint16", Type::UInt16},   {"int", Type::Int32},
                {"int32", Type::Int32},   {"uint", Type::UInt32},     {"uint32", Type::UInt32},
                {"float", Type::Float32}, {"float32", Type::Float32}, {"double", Type::Float64},
                {"float64", Type::Float64}};
  for (const auto& n : kNames)
    if (name == n.name) {
      type = n.type;
      return true;
    }
  return false;
}

size_t typeSize(Type t) {
  static const size_t kSizes[] = {1, 1, 2, 2, 4, 4, 4, 8};
  return kSizes[size_t(t)];
}

bool isInteger(Type t) { return t != Type::Float32 && t != Type::Float64; }

// The InputVertex field a vertex property feeds; Indices marks the face's index list.
enum Slot : int8_t { kNone = -1, kX, kY, kZ, kNX, kNY, kNZ, kRed, kGreen, kBlue, kAlpha, kU, kV, kIndices, kTexcoords, kTexnumber };

struct Property {
  std::string name;
  Type type = Type::Float32;  // item type for lists
  bool isList = false;
  Type countType = Type::UInt8;
  Slot slot = kNone;
};

struct Element {
  std::string name;
  uint64_t count = 0;
  std::vector<Property> properties;
  bool fixedSize = true;  // no list properties: every record is recordSize bytes
  size_t recordSize = 0;
};

template <class U>
U loadBits(const char* p, bool swap) {
  U u;
  std::memcpy(&u, p, sizeof u);
  if (swap) {
    if constexpr (sizeof(U) == 2) u = __builtin_bswap16(u);
    if constexpr (sizeof(U) == 4) u = __builtin_bswap32(u);
    if constexpr (sizeof(U) == 8) u = __builtin_bswap64(u);
  }
  return u;
}

template <class T, class U>
T loadAs(const char* p, bool swap) {
  U u = loadBits<U>(p, swap);
  T t;
  std::memcpy(&t, &u, sizeof t);
  return t;
}

double loadScalar(const char* p, Type t, bool swap) {
  switch (t) {
    case Type::Int8: return double(int8_t(*p));
    case Type::UInt8: return double(uint8_t(*p));
    case Type::Int16: return double(loadAs<int16_t, uint16_t>(p, swap));
    case Type::UInt16: return double(loadBits<uint16_t>(p, swap));
    case Type::Int32: return double(loadAs<int32_t, uint32_t>(p, swap));
    case Type::UInt32: return double(loadBits<uint32_t>(p, swap));
    case Type::Float32: return double(loadAs<float, uint32_t>(p, swap));
    case Type::Float64: return loadAs<double, uint64_t>(p, swap);
  }
  return 0;
}

// Integer-typed list counts and indices (checked at header time to be integer types).
int64_t loadInteger(const char* p, Type t, bool swap) {
  switch (t) {
    case Type::Int8: return int8_t(*p);
    case Type::UInt8: return uint8_t(*p);
    case Type::Int16: return loadAs<int16_t, uint16_t>(p, swap);
    case Type::UInt16: return loadBits<uint16_t>(p, swap);
    case Type::Int32: return loadAs<int32_t, uint32_t>(p, swap);
    case Type::UInt32: return loadBits<uint32_t>(p, swap);
    default: return 0;
  }
}

// Colour channels: 8-bit as is, 16-bit scaled down, floats taken as 0..1 (reader_util.h says
// which values are refused). False for a refused value.
bool colorByte(double value, Type t, uint8_t& out) {
  switch (t) {
    case Type::Float32:
    case Type::Float64: return unitColorByte(value, out);
    case Type::Int16:
    case Type::UInt16:
    case Type::Int32:
    case Type::UInt32: return integerColorByte(value, t == Type::Int16 || t == Type::UInt16 ? 65535 : 255, out);
    default: return integerColorByte(value, 255, out);
  }
}

// False when a colour value is refused (the caller names the vertex and where it is).
bool store(InputVertex& v, Slot slot, double value, Type t) {
  switch (slot) {
    case kX:
    case kY:
    case kZ: v.p[slot - kX] = value; break;
    case kNX:
    case kNY:
    case kNZ: v.n[slot - kNX] = float(value); break;
    case kRed:
    case kGreen:
    case kBlue:
    case kAlpha: return colorByte(value, t, v.c[slot - kRed]);
    case kU:
    case kV: v.uv[slot - kU] = float(value); break;
    default: break;
  }
  return true;
}

const char* slotName(Slot slot) {
  switch (slot) {
    case kRed: return "red";
    case kGreen: return "green";
    case kBlue: return "blue";
    case kAlpha: return "alpha";
    default: return "?";
  }
}

class PlyReader final : public MeshReader {
 public:
  PlyReader(std::unique_ptr<InputFile> in, const MeshOpenOptions& options)
      : in_(std::move(in)), path_(in_->path()), options_(options) {
    parseHeader();
  }

  const MeshHeader& header() const override { return header_; }

  ReadStats read(MeshSink& sink) override {
    ReadStats stats;
    Batcher batch(sink, stats);
    if (header_.cornerTexcoords) batch.enableCorners();
    sink.begin(header_);
    for (const Element& e : elements_) {
      if (&e == vertex_) {
        readVertices(e, batch);
      } else if (&e == face_) {
        readFaces(e, batch);
      } else if (&e == strips_) {
        readStrips(e, batch);
      } else {
        skipElement(e);
      }
    }
    checkTrailing();
    batch.flush();
    stats.bytes = in_->offset();
    if (stats.triangles == 0) fail(path_, "mesh has no triangles");
    sink.end(stats);
    return stats;
  }

 private:
  // ---- header ----

  [[noreturn]] void headerError(const std::string& what) {
    fail(path_, what + " in PLY header" + atLine(in_->line()));
  }

  void parseHeader() {
    std::string_view line;
    if (!in_->nextLine(line) || line.substr(0, 3) != "ply" || !Tokens{line.substr(3)}.empty())
      fail(path_, "not a PLY file (first line is not 'ply')");
    bool haveFormat = false;
    for (;;) {
      // A header is small; a file that never says end_header is not a PLY file.
      if (in_->offset() > (1u << 20)) headerError("no end_header within 1 MiB");
      if (!in_->nextLine(line)) fail(path_, "unexpected end of file in PLY header (no end_header)");
      Tokens tok{line};
      std::string_view word;
      if (tok.next(word) && word == "comment") {
        std::string_view key;
        if (tok.next(key) && key == "TextureFile") {
          InputMaterial m;
          std::string name(tok.rest);
          while (!name.empty() && isSpace(name.front())) name.erase(name.begin());
          while (!name.empty() && isSpace(name.back())) name.pop_back();
          if (name.empty()) headerError("TextureFile comment without a file name");
          m.name = "texture" + std::to_string(header_.materials.size());
          m.texture = resolveBeside(path_, name);
          m.source = path_ + " (line " + std::to_string(in_->line()) + ")";
          header_.materials.push_back(std::move(m));
        }
        continue;
      }
      if (word.empty() || word == "comment" || word == "obj_info") continue;
      if (word == "end_header") break;
      if (word == "format") {
        std::string_view kind, version;
        tok.next(kind);
        if (!tok.next(version) || version.substr(0, 1) != "1") headerError("unsupported PLY version");
        if (kind == "ascii") header_.format = MeshFormat::PlyAscii;
        else if (kind == "binary_little_endian") header_.format = MeshFormat::PlyBinaryLE;
        else if (kind == "binary_big_endian") header_.format = MeshFormat::PlyBinaryBE;
        else headerError("unknown format " + quoted(kind));
        haveFormat = true;
      } else if (word == "element") {
        std::string_view name, count;
        Element e;
        if (!tok.next(name) || !tok.next(count) || !parseNumber(count, e.count))
          headerError("malformed element line");
        e.name = name;
        elements_.push_back(std::move(e));
      } else if (word == "property") {
        if (elements_.empty()) headerError("property before any element");
        parseProperty(tok, elements_.back());
      } else {
        headerError("unexpected keyword " + quoted(word));
      }
    }
    if (!haveFormat) fail(path_, "PLY header has no format line");
    binary_ = header_.format != MeshFormat::PlyAscii;
    swap_ = header_.format == MeshFormat::PlyBinaryBE;
    for (Element& e : elements_) {
      if (e.name == "vertex" && !vertex_) vertex_ = &e;
      if (e.name == "face" && !face_) {
        if (!vertex_) fail(path_, "PLY face element comes before the vertex element (cannot be streamed)");
        face_ = &e;
      }
      if (e.name == "tristrips" && !strips_) {
        if (!vertex_) fail(path_, "PLY tristrips element comes before the vertex element (cannot be streamed)");
        strips_ = &e;
      }
    }
    if (!vertex_) fail(path_, "PLY file has no vertex element");
    if (!face_ && !strips_) {
      // A point cloud, or a range image (Stanford's raw scans: a range_grid element of per-pixel
      // vertex lists): say which, since the file is not broken, only not a mesh.
      bool grid = false;
      for (const Element& e : elements_) grid = grid || e.name == "range_grid";
      fail(path_, "mesh has no triangles: no face or tristrips element, " +
                      (grid ? std::string("a range image (range_grid); triangulate it into a mesh first")
                            : "a point cloud of " + std::to_string(vertex_->count) + " vertices; mtbuild needs a triangle mesh"));
    }
    if (((!face_ || face_->count == 0) && (!strips_ || strips_->count == 0)) || vertex_->count == 0)
      fail(path_, "mesh has no triangles");
    if (vertex_->count > kMaxVertices)
      fail(path_, std::to_string(vertex_->count) + " vertices is more than the supported " +
                      std::to_string(kMaxVertices), ErrorKind::Resource);
    mapVertexProperties(*vertex_);
    if (face_) mapFaceProperties(*face_);
    if (strips_) mapStripProperties(*strips_);
    if (!header_.materials.empty() && (vertexUV_ || faceUV_)) {
      for (const InputMaterial& m : header_.materials) checkTextureFile(m);
      header_.cornerTexcoords = faceUV_ || texnumber_;
      header_.hasTexcoords = !header_.cornerTexcoords;
      keepVertexUV_ = vertexUV_ && header_.cornerTexcoords && !faceUV_;
      if (keepVertexUV_ && vertex_->count * 8 > options_.memoryBytes / 2)
        fail(path_, "per-vertex texture coordinates with per-face texnumber need 8 bytes a vertex in memory (" +
                        std::to_string((vertex_->count * 8) >> 20) + " MiB), more than half of the memory given",
             ErrorKind::Resource);
    } else {
      // No image: texture coordinates are not kept (clear their slots).
      for (Property& p : vertex_->properties)
        if (p.slot == kU || p.slot == kV) p.slot = kNone;
      if (face_)
        for (Property& p : face_->properties)
          if (p.slot == kTexcoords || p.slot == kTexnumber) p.slot = kNone;
      vertexUV_ = faceUV_ = texnumber_ = false;
    }
    // The offsets of the fixed-record path, from the final slots.
    for (const Property& p : vertex_->properties)
      if (p.slot != kNone) fields_.push_back({fieldOffsetOf(*vertex_, &p), p.type, p.slot});
    for (const Field& f : fields_)
      if (f.slot > kZ) extraFields_.push_back(f);
    for (int k = 0; k < 3; ++k) xyzOffset_[k] = fieldOffset(Slot(kX + k));
    header_.declaredVertices = int64_t(vertex_->count);
    // Strips hold an unknown number of triangles (joins dropped): the count is not declared.
    header_.declaredFaces = strips_ ? -1 : int64_t(face_->count);
  }

  void parseProperty(Tokens& tok, Element& e) {
    Property p;
    std::string_view word, name;
    if (!tok.next(word)) headerError("malformed property line");
    if (word == "list") {
      std::string_view countType, itemType;
      if (!tok.next(countType) || !tok.next(itemType)) headerError("malformed list property");
      if (!parseType(countType, p.countType)) headerError("unknown type " + quoted(countType));
      if (!isInteger(p.countType)) headerError("list count type must be an integer type");
      if (!parseType(itemType, p.type)) headerError("unknown type " + quoted(itemType));
      p.isList = true;
      e.fixedSize = false;
    } else if (!parseType(word, p.type)) {
      headerError("unknown type " + quoted(word));
    }
    if (!tok.next(name)) headerError("property without a name");
    p.name = name;
    if (!p.isList) e.recordSize += typeSize(p.type);
    e.properties.push_back(std::move(p));
  }

  Property* findScalar(Element& e, std::initializer_list<const char*> names) {
    for (Property& p : e.properties)
      for (const char* n : names)
        if (p.name == n && !p.isList) return &p;
    return nullptr;
  }

  void mapVertexProperties(Element& e) {
    Property* xyz[3] = {findScalar(e, {"x"}), findScalar(e, {"y"}), findScalar(e, {"z"})};
    if (!xyz[0] || !xyz[1] || !xyz[2]) fail(path_, "PLY vertex element lacks scalar x, y and z");
    for (int k = 0; k < 3; ++k) {
      xyz[k]->slot = Slot(kX + k);
      Type t = xyz[k]->type;
      // Decimal text is kept as double whatever type it declares: "property float x" above survey
      // coordinates with centimetres is common, and float32 would round them to half a metre.
      if (t == Type::Float64 || t == Type::Int32 || t == Type::UInt32 || !binary_) header_.doublePrecision = true;
    }
    Property* n[3] = {findScalar(e, {"nx"}), findScalar(e, {"ny"}), findScalar(e, {"nz"})};
    if (n[0] && n[1] && n[2]) {
      for (int k = 0; k < 3; ++k) n[k]->slot = Slot(kNX + k);
      header_.hasNormals = true;
    }
    Property* c[4] = {findScalar(e, {"red", "diffuse_red"}), findScalar(e, {"green", "diffuse_green"}),
                      findScalar(e, {"blue", "diffuse_blue"}), findScalar(e, {"alpha", "diffuse_alpha"})};
    if (c[0] && c[1] && c[2]) {
      for (int k = 0; k < 4; ++k)
        if (c[k]) c[k]->slot = Slot(kRed + k);
      header_.hasColors = true;
    }
    Property* uv[2] = {findScalar(e, {"texture_u", "s", "texture_s"}), findScalar(e, {"texture_v", "t", "texture_t"})};
    if (uv[0] && uv[1]) {
      uv[0]->slot = kU;
      uv[1]->slot = kV;
      vertexUV_ = true;
    }
    fastXyz_ = !swap_ && e.fixedSize && xyz[0]->type == Type::Float32 &&
               xyz[1]->type == Type::Float32 && xyz[2]->type == Type::Float32;
  }

  static size_t fieldOffsetOf(const Element& e, const Property* q) {
    size_t offset = 0;
    for (const Property& p : e.properties) {
      if (&p == q) return offset;
      offset += p.isList ? 0 : typeSize(p.type);
    }
    return offset;
  }

  size_t fieldOffset(Slot slot) const {
    for (const Field& f : fields_)
      if (f.slot == slot) return f.offset;
    return 0;
  }

  // The index list of a face or tristrips element (its first "vertex_indices" or "vertex_index"
  // property), checked and given the indices' slot.
  Property* indexList(Element& e) {
    Property* list = nullptr;
    for (Property& p : e.properties)
      if ((p.name == "vertex_indices" || p.name == "vertex_index") && !list) list = &p;
    if (!list || !list->isList) fail(path_, "PLY " + e.name + " element has no vertex_indices list");
    if (!isInteger(list->type)) fail(path_, "PLY " + e.name + " vertex_indices must have an integer index type");
    list->slot = kIndices;
    return list;
  }

  void mapFaceProperties(Element& e) {
    Property* list = indexList(e);
    for (Property& p : e.properties) {
      if (p.name == "texcoord" && p.isList) {
        if (isInteger(p.type)) fail(path_, "PLY face texcoord list must have a float type");
        p.slot = kTexcoords;
        faceUV_ = true;
      } else if (p.name == "texnumber" && !p.isList) {
        if (!isInteger(p.type)) fail(path_, "PLY face texnumber must have an integer type");
        p.slot = kTexnumber;
        texnumber_ = true;
      }
    }
    fastFaces_ = binary_ && !swap_ && e.properties.size() == 1 &&
                 (list->countType == Type::UInt8 || list->countType == Type::Int8) &&
                 (list->type == Type::Int32 || list->type == Type::UInt32);
    indexType_ = list->type;
  }

  // The strips' index list; a value of -1 (or, for an unsigned type, the type's largest) ends a strip.
  void mapStripProperties(Element& e) {
    const Property* list = indexList(e);
    stripEnd_ = -1;
    if (list->type == Type::UInt8 || list->type == Type::UInt16 || list->type == Type::UInt32)
      stripEnd_ = int64_t((uint64_t(1) << (8 * typeSize(list->type))) - 1);
  }

  // ---- errors ----

  // Binary: where the current record starts; ascii: the current line.
  std::string where(uint64_t recordStart) const {
    return binary_ ? atByte(recordStart) : atLine(in_->line());
  }
  [[noreturn]] void truncated(const char* element, uint64_t index) {
    fail(path_, std::string("unexpected end of file in ") + element + " " + std::to_string(index) +
                    (binary_ ? atByte(in_->size()) : atLine(in_->line())));
  }

  // ---- vertices ----

  void readVertices(const Element& e, Batcher& batch) {
    if (binary_ && e.fixedSize) {
      readFixedVertices(e, batch);
      return;
    }
    double values[kIndices];
    for (uint64_t i = 0; i < e.count; ++i) {
      uint64_t start = in_->offset();
      readRecord(e, "vertex", i, values, nullptr);
      InputVertex& v = batch.addVertex();
      v = blankVertex();
      for (const Field& f : fields_)
        if (!store(v, f.slot, values[f.slot], f.type)) badColor(i, f, values[f.slot], start);
      if (!isFinite(v)) nonFinite(i, start);
      if (vertexUV_) texcoordOf(v, i, start);
    }
  }

  // A vertex's texture coordinates: checked, kept for the faces (texnumber) or given material 0.
  void texcoordOf(InputVertex& v, uint64_t index, uint64_t start) {
    double u = v.uv[0], w = v.uv[1];
    if (!acceptTexcoord(u, w))
      fail(path_, "texture coordinate (" + std::to_string(v.uv[0]) + ", " + std::to_string(v.uv[1]) + ") of vertex " +
                      std::to_string(index) + " is outside [0, 1] (repeating textures are not supported)" + where(start));
    v.uv[0] = float(u);
    v.uv[1] = float(w);
    if (keepVertexUV_) vertexUVTable_.insert(vertexUVTable_.end(), {v.uv[0], v.uv[1]});
    v.material = header_.hasTexcoords ? 0 : kNoMaterial;
  }

  template <class F>
  [[noreturn]] void badColor(uint64_t index, const F& f, double value, uint64_t start) {
    const bool unit = f.type == Type::Float32 || f.type == Type::Float64;
    const double max = f.type == Type::Int16 || f.type == Type::UInt16 ? 65535 : 255;
    fail(path_, "vertex " + std::to_string(index) + " property " + slotName(f.slot) + ": " + badColorMessage(value, unit, max) +
                    where(start));
  }

  [[noreturn]] void nonFinite(uint64_t index, uint64_t start) {
    fail(path_, "vertex " + std::to_string(index) + " has a non-finite coordinate" + where(start));
  }

  void readFixedVertices(const Element& e, Batcher& batch) {
    const size_t rs = e.recordSize;
    const InputVertex blank = blankVertex();
    for (uint64_t i = 0; i < e.count;) {
      if (!in_->ensure(rs)) truncated("vertex", i);
      size_t room;
      InputVertex* out = batch.vertexSlots(room);
      size_t n = size_t(std::min<uint64_t>({room, e.count - i, in_->available() / rs}));
      const char* p = in_->data();
      if (fastXyz_) {
        for (size_t k = 0; k < n; ++k, p += rs) {
          uint32_t bits[3];
          for (int a = 0; a < 3; ++a) std::memcpy(&bits[a], p + xyzOffset_[a], 4);
          // A float is NaN or Inf exactly when its exponent bits are all ones.
          constexpr uint32_t kExponent = 0x7f800000;
          if (((bits[0] & kExponent) == kExponent) | ((bits[1] & kExponent) == kExponent) |
              ((bits[2] & kExponent) == kExponent))
            nonFinite(i + k, in_->offset() + uint64_t(p - in_->data()));
          float f[3];
          std::memcpy(f, bits, sizeof f);
          InputVertex v = blank;
          v.p[0] = f[0];
          v.p[1] = f[1];
          v.p[2] = f[2];
          for (const Field& fd : extraFields_) {
            const double x = loadScalar(p + fd.offset, fd.type, false);
            if (!store(v, fd.slot, x, fd.type)) badColor(i + k, fd, x, in_->offset() + uint64_t(p - in_->data()));
          }
          if (vertexUV_) texcoordOf(v, i + k, in_->offset() + uint64_t(p - in_->data()));
          out[k] = v;
        }
      } else {
        for (size_t k = 0; k < n; ++k, p += rs) {
          InputVertex v = blank;
          for (const Field& fd : fields_) {
            const double x = loadScalar(p + fd.offset, fd.type, swap_);
            if (!store(v, fd.slot, x, fd.type)) badColor(i + k, fd, x, in_->offset() + uint64_t(p - in_->data()));
          }
          if (!isFinite(v)) nonFinite(i + k, in_->offset() + uint64_t(p - in_->data()));
          if (vertexUV_) texcoordOf(v, i + k, in_->offset() + uint64_t(p - in_->data()));
          out[k] = v;
        }
      }
      in_->consume(n * rs);
      batch.commitVertices(n);
      i += n;
    }
  }

  // ---- faces ----

  void readFaces(const Element& e, Batcher& batch) {
    if (fastFaces_) {
      readTriangleFaces(e, batch);
      return;
    }
    for (uint64_t i = 0; i < e.count; ++i) readRecord(e, "face", i, nullptr, &batch);
  }

  // Little-endian "uchar count, int/uint indices" faces: whole runs of triangles are copied from
  // the read buffer into the batch; anything else (a polygon, a bad count, a record split by the
  // end of the buffer) goes through readRecord for that one face.
  void readTriangleFaces(const Element& e, Batcher& batch) {
    constexpr size_t kRecord = 13;
    const uint64_t vertexCount = vertex_->count;
    // Signed indices at or above 2^31 are negative; both are out of range.
    const uint64_t limit = std::min<uint64_t>(vertexCount, indexType_ == Type::Int32 ? 0x80000000ull : ~0ull);
    for (uint64_t i = 0; i < e.count;) {
      if (!in_->ensure(kRecord)) {
        readRecord(e, "face", i++, nullptr, &batch);
        continue;
      }
      size_t room;
      uint32_t* out = batch.triangleSlots(room);
      const char* begin = in_->data();
      const char* p = begin;
      size_t n = size_t(std::min<uint64_t>({room, e.count - i, in_->available() / kRecord}));
      size_t made = 0, degenerate = 0;
      for (; made < n && uint8_t(p[0]) == 3; ++made, p += kRecord) {
        uint32_t a, b, c;
        std::memcpy(&a, p + 1, 4);
        std::memcpy(&b, p + 5, 4);
        std::memcpy(&c, p + 9, 4);
        if (std::max({a, b, c}) >= limit) break;  // reported by readRecord below
        out[made * 3 + 0] = a;
        out[made * 3 + 1] = b;
        out[made * 3 + 2] = c;
        degenerate += (a == b) | (b == c) | (a == c);
      }
      in_->consume(size_t(p - begin));
      batch.commitTriangles(made, degenerate);
      i += made;
      if (made < n) readRecord(e, "face", i++, nullptr, &batch);
    }
  }

  // ---- triangle strips ----

  // Every record of the tristrips element: its index list unrolled into triangles (see the top of
  // the file), other properties read and dropped.
  void readStrips(const Element& e, Batcher& batch) {
    const uint64_t vertexCount = vertex_->count;
    for (uint64_t i = 0; i < e.count; ++i) {
      const uint64_t start = in_->offset();
      for (const Property& p : e.properties) {
        if (!p.isList) {
          scalar(p.type, "tristrips", i, false);
          continue;
        }
        const int64_t count = listLength(p, "tristrips", i, start);
        if (p.slot != kIndices) {
          skipItems(p.type, count, "tristrips", i);
          continue;
        }
        uint32_t a = 0, b = 0;
        uint64_t inStrip = 0;  // indices of the current strip so far
        for (int64_t k = 0; k < count; ++k) {
          const uint64_t at = in_->offset();
          const int64_t vi = integer(p.type, "tristrips", i);
          if (vi == stripEnd_ || vi == -1) {  // -1 also in ascii text of an unsigned type
            inStrip = 0;
            continue;
          }
          if (vi < 0 || uint64_t(vi) >= vertexCount)
            fail(path_, "index " + std::to_string(vi) + " out of range (" + std::to_string(vertexCount) + " vertices) at tristrips " +
                            std::to_string(i) + " entry " + std::to_string(k) + (binary_ ? atByte(at) : atLine(in_->line())));
          const uint32_t c = uint32_t(vi);
          // Triangle inStrip - 2 of the strip; odd ones swap their first two corners.
          if (inStrip >= 2 && a != b && b != c && a != c) {
            const uint32_t v[3] = {inStrip & 1 ? b : a, inStrip & 1 ? a : b, c};
            if (keepVertexUV_) {
              // Per-vertex coordinates kept for the faces' texnumber: a strip's triangles take
              // image 0 (a strip has no texnumber), with their corners' coordinates.
              float uv[6];
              for (int q = 0; q < 3; ++q) uv[2 * q] = vertexUVTable_[2 * size_t(v[q])], uv[2 * q + 1] = vertexUVTable_[2 * size_t(v[q]) + 1];
              batch.addTriangle(v, uv, 0);
            } else {
              batch.addTriangle(v[0], v[1], v[2]);
            }
          }
          a = b;
          b = c;
          ++inStrip;
        }
      }
    }
  }

  // ---- generic record walk (ascii, big-endian, lists anywhere) ----

  // Reads record `index` of element e. Scalars with a slot land in values[slot] (when given);
  // the index list of a face goes to the batch as a polygon; everything else is read and dropped.
  void readRecord(const Element& e, const char* kind, uint64_t index, double* values, Batcher* batch) {
    const uint64_t start = in_->offset();
    if (batch && header_.cornerTexcoords) {
      readTexturedFace(e, index, *batch);
      return;
    }
    for (const Property& p : e.properties) {
      if (!p.isList) {
        double v = scalar(p.type, kind, index, p.slot >= kX && p.slot <= kZ);
        if (values && p.slot != kNone && p.slot < kIndices) values[p.slot] = v;
        continue;
      }
      const int64_t count = listLength(p, kind, index, start);
      if (p.slot == kIndices && batch) {
        batch->beginFace();
        for (int64_t k = 0; k < count; ++k) {
          int64_t vi = integer(p.type, kind, index);
          if (vi < 0 || uint64_t(vi) >= vertex_->count)
            fail(path_, "index " + std::to_string(vi) + " out of range (" + std::to_string(vertex_->count) +
                            " vertices) at face " + std::to_string(index) + where(start));
          batch->addCorner(uint32_t(vi));
        }
        if (batch->endFace() < 3)
          fail(path_, "face " + std::to_string(index) + " has " + std::to_string(count) +
                          " corners (at least 3 needed)" + where(start));
      } else {
        skipItems(p.type, count, kind, index);
      }
    }
  }

  // The length of list property `p` of record `index` (of element `kind`, which starts at `start`).
  int64_t listLength(const Property& p, const char* kind, uint64_t index, uint64_t start) {
    const int64_t count = integer(p.countType, kind, index);
    if (count < 0)
      fail(path_, "negative list length " + std::to_string(count) + " at " + kind + " " + std::to_string(index) + where(start));
    return count;
  }

  // Reads and drops `count` items of type `t` of a list.
  void skipItems(Type t, int64_t count, const char* kind, uint64_t index) {
    if (binary_) {
      if (!in_->skip(uint64_t(count) * typeSize(t))) truncated(kind, index);
    } else {
      for (int64_t k = 0; k < count; ++k) scalar(t, kind, index, false);
    }
  }

  // A face of a per-corner textured PLY: its properties in any order, then its corners.
  void readTexturedFace(const Element& e, uint64_t index, Batcher& batch) {
    const uint64_t start = in_->offset();
    corners_.clear();
    cornerUV_.clear();
    int64_t texnumber = 0;
    for (const Property& p : e.properties) {
      if (!p.isList) {
        if (p.slot == kTexnumber) texnumber = integer(p.type, "face", index);
        else scalar(p.type, "face", index, false);
        continue;
      }
      const int64_t count = listLength(p, "face", index, start);
      for (int64_t k = 0; k < count; ++k) {
        if (p.slot == kIndices) {
          int64_t vi = integer(p.type, "face", index);
          if (vi < 0 || uint64_t(vi) >= vertex_->count)
            fail(path_, "index " + std::to_string(vi) + " out of range (" + std::to_string(vertex_->count) +
                            " vertices) at face " + std::to_string(index) + where(start));
          corners_.push_back(uint32_t(vi));
        } else if (p.slot == kTexcoords) {
          cornerUV_.push_back(scalar(p.type, "face", index, false));
        } else if (binary_) {
          if (!in_->skip(typeSize(p.type))) truncated("face", index);
        } else {
          scalar(p.type, "face", index, false);
        }
      }
    }
    if (corners_.size() < 3)
      fail(path_, "face " + std::to_string(index) + " has " + std::to_string(corners_.size()) + " corners (at least 3 needed)" +
                      where(start));
    if (faceUV_ && cornerUV_.size() != 2 * corners_.size())
      fail(path_, "face " + std::to_string(index) + " has " + std::to_string(cornerUV_.size()) + " texcoord values for " +
                      std::to_string(corners_.size()) + " corners (2 per corner needed)" + where(start));
    if (texnumber < 0 || uint64_t(texnumber) >= header_.materials.size())
      fail(path_, "texnumber " + std::to_string(texnumber) + " of face " + std::to_string(index) + " out of range (" +
                      std::to_string(header_.materials.size()) + " TextureFile comments)" + where(start));
    batch.beginFace(uint32_t(texnumber));
    for (size_t k = 0; k < corners_.size(); ++k) {
      double u, v;
      if (faceUV_) {
        u = cornerUV_[2 * k], v = cornerUV_[2 * k + 1];
        if (!acceptTexcoord(u, v))
          fail(path_, "texture coordinate (" + std::to_string(u) + ", " + std::to_string(v) + ") of face " + std::to_string(index) +
                          " corner " + std::to_string(k) + " is outside [0, 1] (repeating textures are not supported)" + where(start));
      } else {
        u = vertexUVTable_[2 * size_t(corners_[k])], v = vertexUVTable_[2 * size_t(corners_[k]) + 1];
      }
      batch.addCorner(corners_[k], float(u), float(v));
    }
    batch.endFace();
  }

  // One scalar of the current record; ascii coordinates of float type parse to the nearest
  // float32, as the contract says text input is float precision unless declared double.
  double scalar(Type t, const char* kind, uint64_t index, bool coordinate) {
    if (binary_) {
      if (!in_->ensure(typeSize(t))) truncated(kind, index);
      double v = loadScalar(in_->data(), t, swap_);
      in_->consume(typeSize(t));
      return v;
    }
    std::string_view tok = token(kind, index);
    if (isInteger(t)) {
      int64_t v;
      if (!parseNumber(tok, v)) badNumber(tok, kind, index);
      return double(v);
    }
    if (!coordinate) {
      float f;
      if (!parseNumber(tok, f)) badNumber(tok, kind, index);
      return f;
    }
    double d;
    if (!parseNumber(tok, d)) badNumber(tok, kind, index);
    return d;
  }

  int64_t integer(Type t, const char* kind, uint64_t index) {
    if (binary_) {
      if (!in_->ensure(typeSize(t))) truncated(kind, index);
      int64_t v = loadInteger(in_->data(), t, swap_);
      in_->consume(typeSize(t));
      return v;
    }
    std::string_view tok = token(kind, index);
    int64_t v;
    if (!parseNumber(tok, v)) badNumber(tok, kind, index);
    return v;
  }

  [[noreturn]] void badNumber(std::string_view tok, const char* kind, uint64_t index) {
    fail(path_, "invalid number " + quoted(tok) + " at " + kind + " " + std::to_string(index) +
                    atLine(in_->line()));
  }

  // Ascii PLY is a stream of whitespace-separated tokens; records usually match lines but need not.
  std::string_view token(const char* kind, uint64_t index) {
    std::string_view tok;
    while (!tokens_.next(tok)) {
      std::string_view line;
      if (!in_->nextLine(line)) truncated(kind, index);
      tokens_.rest = line;
    }
    return tok;
  }

  void skipElement(const Element& e) {
    if (binary_ && e.fixedSize) {
      const uint64_t start = in_->offset();
      if (!in_->skip(e.count * e.recordSize))
        truncated(e.name.c_str(), (in_->size() - start) / std::max<size_t>(e.recordSize, 1));
      return;
    }
    for (uint64_t i = 0; i < e.count; ++i) readRecord(e, e.name.c_str(), i, nullptr, nullptr);
  }

  // Data beyond the declared elements means the counts are wrong; refuse rather than guess.
  void checkTrailing() {
    if (binary_) {
      if (!in_->atEnd())
        fail(path_, "unexpected data after the last element" + atByte(in_->offset()));
      return;
    }
    std::string_view line;
    for (;;) {
      if (!tokens_.empty())
        fail(path_, "unexpected data after the last element" + atLine(in_->line()));
      if (!in_->nextLine(line)) return;
      tokens_.rest = line;
    }
  }

  struct Field {
    size_t offset;
    Type type;
    Slot slot;
  };

  std::unique_ptr<InputFile> in_;
  std::string path_;
  MeshOpenOptions options_;
  MeshHeader header_;
  bool vertexUV_ = false, faceUV_ = false, texnumber_ = false;
  bool keepVertexUV_ = false;           // per-vertex coordinates held for per-face texnumber
  std::vector<float> vertexUVTable_;    // 2 per vertex when keepVertexUV_
  std::vector<uint32_t> corners_;       // the current face (readTexturedFace)
  std::vector<double> cornerUV_;
  std::vector<Element> elements_;
  Element* vertex_ = nullptr;  // into elements_, which no longer changes after the header
  Element* face_ = nullptr;
  Element* strips_ = nullptr;  // "tristrips", when the file has one
  int64_t stripEnd_ = -1;      // the index value that ends a strip
  bool binary_ = false, swap_ = false;
  std::vector<Field> fields_;  // mapped vertex properties with their offsets in a fixed record
  std::vector<Field> extraFields_;  // the same without x, y, z: normals and colours
  bool fastXyz_ = false;
  size_t xyzOffset_[3] = {0, 0, 0};
  bool fastFaces_ = false;
  Type indexType_ = Type::Int32;
  Tokens tokens_;  // ascii: the rest of the current line
};

}  // namespace

std::unique_ptr<MeshReader> openPly(std::unique_ptr<InputFile> in, const MeshOpenOptions& options) {
  return std::make_unique<PlyReader>(std::move(in), options);
}

}  // namespace mt::io
