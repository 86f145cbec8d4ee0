// Wavefront OBJ reader, streamed line by line.
//
// Kept: "v x y z [w]" positions (w is ignored: it only matters for rational curves), the
// "v x y z r g b" colour extension when the file's first vertex has it (floats 0..1; a value
// outside, or a colour on a later vertex when the first has none, is refused), and "f"
// faces in every corner form (v, v/vt, v//vn, v/vt/vn), with negative indices counted back from
// the last vertex seen so far. Every other statement (vn, vp, g, o, s, l, p, curves...) is
// skipped.
//
// Textures: "mtllib" files (read when the statement is met; those in the file's first MiB are
// known before the data, which is where writers put them) give materials ("newmtl", "Kd",
// "map_Kd" with its options skipped); "usemtl" picks the material of the faces that follow. When
// some material has a texture image, the texture coordinates of every face corner ("vt" by index,
// negative ones counted back) go to the sink per corner (MeshSink::cornerTexcoords) and openMesh
// splits them into per-vertex ones. The "vt" values are held in RAM (8 bytes each, within the
// memory the caller gives): a "vt" may be named by any later face. Errors name the line: a vt
// index out of range, a coordinate outside [0, 1], an unknown material, a missing texture image
// (a missing MTL file leaves the mesh untextured: geometry-only files often name one).
//
// Normals are not kept. In OBJ a normal belongs to a face corner, and "vn" lines usually come
// after all "v" lines, so giving each vertex its normal would mean holding the vertices back until
// the faces have been read: unbounded memory, which a streaming reader cannot afford. The ingest
// step computes normals from the geometry instead; header.hasNormals is always false here.
//
// OBJ interleaves vertices and faces, so indices are checked against the vertices seen so far.
#include <map>
#include <set>
#include <string>

#include "patchstore/io/reader_util.h"

namespace mt::io {
namespace {

class ObjReader final : public MeshReader {
 public:
  ObjReader(std::unique_ptr<InputFile> in, const MeshOpenOptions& options)
      : in_(std::move(in)), path_(in_->path()), options_(options) {
    header_.format = MeshFormat::Obj;
    header_.doublePrecision = true;  // decimal text: parsed and kept as double (see off_reader.cpp)
    header_.hasColors = firstVertexHasColor();
    for (const InputMaterial& m : header_.materials)
      if (!m.texture.empty()) textured_ = true;
    header_.cornerTexcoords = textured_;
    if (textured_)
      for (const InputMaterial& m : header_.materials) checkTextureFile(m);
  }

  const MeshHeader& header() const override { return header_; }

  ReadStats read(MeshSink& sink) override {
    ReadStats stats;
    Batcher batch(sink, stats);
    if (textured_) batch.enableCorners();
    sink.begin(header_);
    std::string_view line;
    uint64_t faces = 0;
    while (in_->nextLine(line)) {
      size_t i = 0;
      while (i < line.size() && isSpace(line[i])) ++i;
      if (i + 1 >= line.size()) continue;
      if (!isSpace(line[i + 1])) {  // not "v " or "f "
        if (line[i] == 'v' && line[i + 1] == 't' && i + 2 < line.size() && isSpace(line[i + 2])) {
          if (textured_) readTexcoord(line.substr(i + 3));
        } else if (line.substr(i, 7) == "usemtl " || line.substr(i, 7) == "usemtl\t") {
          useMaterial(line.substr(i + 7));
        } else if (line.substr(i, 7) == "mtllib " || line.substr(i, 7) == "mtllib\t") {
          if (in_->offset() > firstChunk_ && !seenLibraries_.count(std::string(line.substr(i + 7))))
            fail(path_, "mtllib after the file's first MiB is not supported (the materials must be known before the data)" +
                            atLine(in_->line()));
        }
        continue;
      }
      if (line[i] == 'v') readVertex(line.substr(i + 2), stats.vertices, batch);
      else if (line[i] == 'f') readFace(line.substr(i + 2), faces++, stats.vertices, batch);
    }
    batch.flush();
    stats.bytes = in_->offset();
    if (stats.triangles == 0) fail(path_, "mesh has no triangles");
    sink.end(stats);
    return stats;
  }

 private:
  // The colour extension is decided once, from the first vertex in the file's first chunk, so
  // that begin() can announce it before any data is streamed.
  // Also reads the MTL files named in the first chunk (their materials are in the header).
  bool firstVertexHasColor() {
    in_->ensure(kReadChunk);
    std::string_view text(in_->data(), in_->available());
    firstChunk_ = text.size();
    bool color = false, sawVertex = false;
    uint64_t lineNo = 0;
    for (size_t pos = 0; pos < text.size();) {
      size_t nl = text.find('\n', pos);
      if (nl == std::string_view::npos && text.size() == kReadChunk) break;  // a cut line
      std::string_view line = text.substr(pos, nl == std::string_view::npos ? text.npos : nl - pos);
      pos = nl == std::string_view::npos ? text.size() : nl + 1;
      ++lineNo;
      if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
      Tokens tok{line};
      std::string_view word;
      if (!tok.next(word)) continue;
      if (word == "mtllib") {
        // The names are the rest of the line (one or more files; a single name may hold spaces).
        std::string rest(trim(tok.rest));
        seenLibraries_.insert(rest);
        readLibraries(rest, lineNo);
        continue;
      }
      if (word != "v" || sawVertex) continue;
      sawVertex = true;
      int values = 0;
      while (tok.next(word)) ++values;
      color = values == 6 || values == 7;  // x y z r g b, or with a trailing w some tools add
    }
    return color;
  }

  static std::string_view trim(std::string_view s) {
    while (!s.empty() && isSpace(s.front())) s.remove_prefix(1);
    while (!s.empty() && isSpace(s.back())) s.remove_suffix(1);
    return s;
  }

  void readLibraries(const std::string& names, uint64_t lineNo) {
    const std::string where = path_ + " (line " + std::to_string(lineNo) + ")";
    // One file with that whole name, else whitespace-separated names.
    if (::access(resolveBeside(path_, names).c_str(), F_OK) == 0) {
      readLibrary(resolveBeside(path_, names), where);
      return;
    }
    Tokens tok{names};
    std::string_view name;
    while (tok.next(name)) readLibrary(resolveBeside(path_, std::string(name)), where);
  }

  // An MTL file: newmtl, Kd, map_Kd (options before the file name are skipped). A library that
  // is not there leaves the mesh untextured, as it was read before textures were (geometry-only
  // OBJ files often name an MTL they come without); a texture image that a library names and
  // that is not there is an error.
  void readLibrary(const std::string& mtl, const std::string& namedIn) {
    (void)namedIn;
    if (::access(mtl.c_str(), R_OK) != 0) return;
    auto f = std::make_unique<InputFile>(mtl);
    std::string_view line;
    InputMaterial* current = nullptr;
    while (f->nextLine(line)) {
      Tokens tok{line};
      std::string_view word;
      if (!tok.next(word) || word[0] == '#') continue;
      if (word == "newmtl") {
        std::string name(trim(tok.rest));
        if (name.empty()) fail(mtl, "newmtl without a name" + atLine(f->line()));
        auto it = materialIndex_.find(name);
        if (it == materialIndex_.end()) {
          it = materialIndex_.emplace(name, uint32_t(header_.materials.size())).first;
          header_.materials.emplace_back();
          header_.materials.back().name = name;
        }
        current = &header_.materials[it->second];
        current->source = mtl + " (line " + std::to_string(f->line()) + ")";
        continue;
      }
      if (!current) continue;
      if (word == "Kd") {
        double rgb[3];
        for (double& c : rgb) {
          std::string_view t;
          if (!tok.next(t) || !parseNumber(t, c)) fail(mtl, "invalid Kd colour" + atLine(f->line()));
        }
        for (int k = 0; k < 3; ++k) current->diffuse[k] = unitToByte(rgb[k]);
      } else if (word == "map_Kd") {
        std::string_view rest = tok.rest;
        // Options: -name followed by up to 3 values (numbers or on/off or a channel letter).
        for (;;) {
          Tokens look{rest};
          std::string_view opt;
          if (!look.next(opt) || opt.size() < 2 || opt[0] != '-') break;
          rest = look.rest;
          for (int k = 0; k < 3; ++k) {
            Tokens arg{rest};
            std::string_view a;
            double d;
            if (!arg.next(a) || !(parseNumber(a, d) || a == "on" || a == "off" || (a.size() == 1 && std::isalpha(uint8_t(a[0])))))
              break;
            rest = arg.rest;
            if (opt != "-o" && opt != "-s" && opt != "-t" && opt != "-mm") break;  // one value
          }
        }
        std::string file(trim(rest));
        if (file.empty()) fail(mtl, "map_Kd without a file name" + atLine(f->line()));
        current->texture = resolveBeside(mtl, file);
        current->source = mtl + " (line " + std::to_string(f->line()) + ")";
      }
    }
  }

  void readTexcoord(std::string_view rest) {
    Tokens tok{rest};
    double uv[2];
    std::string_view word;
    for (double& c : uv)
      if (!tok.next(word) || !parseNumber(word, c))
        fail(path_, "invalid texture coordinate " + quoted(rest) + " at vt " + std::to_string(texcoords_.size() / 2 + 1) +
                        atLine(in_->line()));
    if (!acceptTexcoord(uv[0], uv[1]))
      fail(path_, "texture coordinate (" + std::to_string(uv[0]) + ", " + std::to_string(uv[1]) + ") of vt " +
                      std::to_string(texcoords_.size() / 2 + 1) + " is outside [0, 1] (repeating textures are not supported)" +
                      atLine(in_->line()));
    if ((texcoords_.size() + 2) * sizeof(float) > options_.memoryBytes / 2)
      fail(path_, "more texture coordinates (vt) than fit in half of the memory given (" +
                      std::to_string(options_.memoryBytes >> 20) + " MiB); give more --memory" + atLine(in_->line()),
           ErrorKind::Resource);
    texcoords_.push_back(float(uv[0]));
    texcoords_.push_back(float(uv[1]));
  }

  void useMaterial(std::string_view rest) {
    std::string name(trim(rest));
    auto it = materialIndex_.find(name);
    if (it == materialIndex_.end()) {
      if (!textured_) return;  // no textures: materials do not matter
      fail(path_, "usemtl '" + name + "' names no material of the mtllib files" + atLine(in_->line()));
    }
    material_ = it->second;
  }

  void readVertex(std::string_view rest, uint64_t index, Batcher& batch) {
    if (index >= kMaxVertices)
      fail(path_, "more vertices than the supported " + std::to_string(kMaxVertices), ErrorKind::Resource);
    Tokens tok{rest};
    double values[6];
    int n = 0;
    std::string_view word;
    while (n < 6 && tok.next(word)) {
      if (!parseNumber(word, values[n]))
        fail(path_, "invalid number " + quoted(word) + " at vertex " + std::to_string(index) + atLine(in_->line()));
      ++n;
    }
    if (n < 3) fail(path_, "vertex " + std::to_string(index) + " has fewer than 3 coordinates" + atLine(in_->line()));
    InputVertex& v = batch.addVertex();
    v = blankVertex();
    v.p[0] = values[0];
    v.p[1] = values[1];
    v.p[2] = values[2];
    if (!isFinite(v))
      fail(path_, "vertex " + std::to_string(index) + " has a non-finite coordinate" + atLine(in_->line()));
    if (n == 6 && !header_.hasColors)
      fail(path_, "vertex " + std::to_string(index) +
                      " has a colour but the file's first vertex has none (OBJ vertex colours go on every vertex or none)" +
                      atLine(in_->line()));
    if (n == 6)
      for (int k = 0; k < 3; ++k)
        if (!unitColorByte(values[3 + k], v.c[k]))
          fail(path_, "vertex " + std::to_string(index) + " " + (k == 0 ? "red" : k == 1 ? "green" : "blue") + ": " + badColorMessage(values[3 + k], true, 255) +
                          atLine(in_->line()));
  }

  void readFace(std::string_view rest, uint64_t index, uint64_t vertexCount, Batcher& batch) {
    Tokens tok{rest};
    std::string_view corner;
    const bool textured = textured_ && material_ != kNoMaterial && !header_.materials[material_].texture.empty();
    batch.beginFace(textured ? material_ : kNoMaterial);
    while (tok.next(corner)) {
      const char* end = corner.data() + corner.size();
      int64_t i = 0;
      auto [ptr, ec] = std::from_chars(corner.data(), end, i);
      if (ec != std::errc() || (ptr != end && *ptr != '/'))
        fail(path_, "invalid face corner " + quoted(corner) + " at face " + std::to_string(index) + atLine(in_->line()));
      // 1-based; negative counts back from the newest vertex (-1 is the last one).
      int64_t resolved = i > 0 ? i - 1 : int64_t(vertexCount) + i;
      if (i == 0 || resolved < 0 || uint64_t(resolved) >= vertexCount)
        fail(path_, "index " + std::to_string(i) + " out of range (" + std::to_string(vertexCount) +
                        " vertices so far) at face " + std::to_string(index) + atLine(in_->line()));
      if (!textured_) {
        batch.addCorner(uint32_t(resolved));  // the /vt/vn parts are skipped
        continue;
      }
      float u = 0, v = 0;
      if (textured && ptr != end && ptr + 1 != end && ptr[1] != '/') {
        int64_t t = 0;
        auto [tp, tec] = std::from_chars(ptr + 1, end, t);
        if (tec != std::errc() || (tp != end && *tp != '/'))
          fail(path_, "invalid face corner " + quoted(corner) + " at face " + std::to_string(index) + atLine(in_->line()));
        const uint64_t known = texcoords_.size() / 2;
        int64_t r = t > 0 ? t - 1 : int64_t(known) + t;
        if (t == 0 || r < 0 || uint64_t(r) >= known)
          fail(path_, "texture coordinate index " + std::to_string(t) + " out of range (" + std::to_string(known) +
                          " vt so far) at face " + std::to_string(index) + atLine(in_->line()));
        u = texcoords_[size_t(r) * 2];
        v = texcoords_[size_t(r) * 2 + 1];
      } else if (textured) {
        fail(path_, "face " + std::to_string(index) + " of textured material '" + header_.materials[material_].name +
                        "' has a corner without a texture coordinate" + atLine(in_->line()));
      }
      batch.addCorner(uint32_t(resolved), u, v);
    }
    uint64_t corners = batch.endFace();
    if (corners < 3)
      fail(path_, "face " + std::to_string(index) + " has " + std::to_string(corners) +
                      " corners (at least 3 needed)" + atLine(in_->line()));
  }

  std::unique_ptr<InputFile> in_;
  std::string path_;
  MeshOpenOptions options_;
  MeshHeader header_;
  bool textured_ = false;              // some material has a texture image
  std::map<std::string, uint32_t> materialIndex_;
  std::set<std::string> seenLibraries_;  // mtllib lines of the first chunk
  size_t firstChunk_ = 0;
  uint32_t material_ = kNoMaterial;    // the current usemtl
  std::vector<float> texcoords_;       // every vt so far, 2 per vt
};

}  // namespace

std::unique_ptr<MeshReader> openObj(std::unique_ptr<InputFile> in, const MeshOpenOptions& options) {
  return std::make_unique<ObjReader>(std::move(in), options);
}

}  // namespace mt::io
