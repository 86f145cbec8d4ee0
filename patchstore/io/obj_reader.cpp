// Wavefront OBJ reader, streamed line by line.
//
// Kept: "v x y z [w]" positions (w is ignored: it only matters for rational curves), the
// "v x y z r g b" colour extension when the file's first vertex has it (floats 0..1; a value
// outside, or a colour on a later vertex when the first has none, is refused), and "f"
// faces in every corner form (v, v/vt, v//vn, v/vt/vn), with negative indices counted back from
// the last vertex seen so far. Every other statement (vt, vn, vp, g, o, s, usemtl, mtllib, l, p,
// curves...) is skipped.
//
// Normals are not kept. In OBJ a normal belongs to a face corner, and "vn" lines usually come
// after all "v" lines, so giving each vertex its normal would mean holding the vertices back until
// the faces have been read: unbounded memory, which a streaming reader cannot afford. The ingest
// step computes normals from the geometry instead; header.hasNormals is always false here.
//
// OBJ interleaves vertices and faces, so indices are checked against the vertices seen so far.
#include <string>

#include "patchstore/io/reader_util.h"

namespace mt::io {
namespace {

class ObjReader final : public MeshReader {
 public:
  explicit ObjReader(std::unique_ptr<InputFile> in) : in_(std::move(in)), path_(in_->path()) {
    header_.format = MeshFormat::Obj;
    header_.doublePrecision = true;  // decimal text: parsed and kept as double (see off_reader.cpp)
    header_.hasColors = firstVertexHasColor();
  }

  const MeshHeader& header() const override { return header_; }

  ReadStats read(MeshSink& sink) override {
    ReadStats stats;
    Batcher batch(sink, stats);
    sink.begin(header_);
    std::string_view line;
    uint64_t faces = 0;
    while (in_->nextLine(line)) {
      size_t i = 0;
      while (i < line.size() && isSpace(line[i])) ++i;
      if (i + 1 >= line.size() || !isSpace(line[i + 1])) continue;  // not "v " or "f "
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
  bool firstVertexHasColor() {
    in_->ensure(kReadChunk);
    std::string_view text(in_->data(), in_->available());
    for (size_t pos = 0; pos < text.size();) {
      size_t nl = text.find('\n', pos);
      std::string_view line = text.substr(pos, nl == std::string_view::npos ? text.npos : nl - pos);
      pos = nl == std::string_view::npos ? text.size() : nl + 1;
      Tokens tok{line};
      std::string_view word;
      if (!tok.next(word) || word != "v") continue;
      int values = 0;
      while (tok.next(word)) ++values;
      return values == 6 || values == 7;  // x y z r g b, or with a trailing w some tools add
    }
    return false;
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
    batch.beginFace();
    while (tok.next(corner)) {
      // Only the position index matters; the /vt/vn parts are skipped.
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
      batch.addCorner(uint32_t(resolved));
    }
    uint64_t corners = batch.endFace();
    if (corners < 3)
      fail(path_, "face " + std::to_string(index) + " has " + std::to_string(corners) +
                      " corners (at least 3 needed)" + atLine(in_->line()));
  }

  std::unique_ptr<InputFile> in_;
  std::string path_;
  MeshHeader header_;
};

}  // namespace

std::unique_ptr<MeshReader> openObj(std::unique_ptr<InputFile> in) {
  return std::make_unique<ObjReader>(std::move(in));
}

}  // namespace mt::io
