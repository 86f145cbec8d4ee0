// STL reader, ascii and binary. STL is a triangle soup: each triangle brings three new vertices,
// delivered in file order (3k, 3k+1, 3k+2); welding equal positions is the ingest step's job.
// Facet normals and the binary attribute bytes are skipped (per-face data has no place in
// InputVertex, and normals are recomputed from the geometry anyway).
#include <string>

#include "patchstore/io/reader_util.h"

namespace mt::io {
namespace {

constexpr size_t kStlHeader = 84;  // 80 bytes of free text, then a little-endian u32 count
constexpr size_t kStlRecord = 50;  // normal, 3 vertices (12 floats), u16 attribute

class StlReader final : public MeshReader {
 public:
  StlReader(std::unique_ptr<InputFile> in, bool binary) : in_(std::move(in)), path_(in_->path()) {
    header_.format = binary ? MeshFormat::StlBinary : MeshFormat::StlAscii;
    header_.doublePrecision = !binary;  // decimal text: parsed and kept as double (see off_reader.cpp)
    if (binary) parseBinaryHeader();
  }

  const MeshHeader& header() const override { return header_; }

  ReadStats read(MeshSink& sink) override {
    ReadStats stats;
    Batcher batch(sink, stats);
    sink.begin(header_);
    if (header_.format == MeshFormat::StlBinary) readBinary(batch);
    else readAscii(batch);
    batch.flush();
    stats.bytes = in_->offset();
    if (stats.triangles == 0) fail(path_, "mesh has no triangles");
    sink.end(stats);
    return stats;
  }

 private:
  void parseBinaryHeader() {
    if (!in_->ensure(kStlHeader)) fail(path_, "unexpected end of file in STL header" + atByte(in_->size()));
    uint32_t count;
    std::memcpy(&count, in_->data() + 80, 4);
    in_->consume(kStlHeader);
    if (count == 0) fail(path_, "mesh has no triangles");
    if (3 * uint64_t(count) > kMaxVertices)
      fail(path_, std::to_string(3 * uint64_t(count)) + " vertices is more than the supported " +
                      std::to_string(kMaxVertices), ErrorKind::Resource);
    header_.declaredFaces = count;
    header_.declaredVertices = 3 * int64_t(count);
  }

  void readBinary(Batcher& batch) {
    const uint64_t count = uint64_t(header_.declaredFaces);
    for (uint64_t t = 0; t < count;) {
      if (!in_->ensure(kStlRecord))
        fail(path_, "unexpected end of file in triangle " + std::to_string(t) + atByte(in_->size()));
      size_t n = size_t(std::min<uint64_t>(count - t, in_->available() / kStlRecord));
      // A triangle's three vertices must land in one vertex batch with room to spare.
      size_t room;
      InputVertex* out = batch.vertexSlots(room);
      n = std::min(n, room / 3);
      if (n == 0) {
        batch.flush();
        continue;
      }
      const char* p = in_->data();
      for (size_t k = 0; k < n; ++k, p += kStlRecord) {
        float f[9];
        std::memcpy(f, p + 12, sizeof f);
        for (int c = 0; c < 3; ++c) {
          InputVertex& v = out[k * 3 + c];
          v = blankVertex();
          v.p[0] = f[c * 3 + 0];
          v.p[1] = f[c * 3 + 1];
          v.p[2] = f[c * 3 + 2];
          if (!isFinite(v))
            fail(path_, "vertex " + std::to_string(3 * (t + k) + c) + " has a non-finite coordinate" +
                            atByte(in_->offset() + uint64_t(p - in_->data())));
        }
      }
      in_->consume(n * kStlRecord);
      batch.commitVertices(3 * n);
      for (size_t k = 0; k < n; ++k) {
        uint32_t a = uint32_t(3 * (t + k));
        batch.addTriangle(a, a + 1, a + 2);
      }
      t += n;
    }
    if (!in_->atEnd())
      fail(path_, "unexpected data after triangle " + std::to_string(count - 1) + atByte(in_->offset()));
  }

  [[noreturn]] void syntax(const std::string& what) { fail(path_, what + atLine(in_->line())); }

  // Lines: solid NAME / facet normal x y z / outer loop / vertex x y z (3x) / endloop / endfacet /
  // endsolid NAME. Several solids in one file are accepted, one after the other.
  void readAscii(Batcher& batch) {
    std::string_view line, word;
    bool inSolid = false, inFacet = false, sawSolid = false;
    int corners = 0;
    uint64_t facet = 0;
    InputVertex pending[3];
    while (in_->nextLine(line)) {
      Tokens tok{line};
      if (!tok.next(word)) continue;
      if (word == "solid") {
        if (inSolid) syntax("'solid' inside a solid");
        inSolid = sawSolid = true;
      } else if (word == "endsolid") {
        if (!inSolid || inFacet) syntax("unexpected 'endsolid' at facet " + std::to_string(facet));
        inSolid = false;
      } else if (word == "facet") {
        if (!inSolid || inFacet) syntax("unexpected 'facet' at facet " + std::to_string(facet));
        inFacet = true;
        corners = 0;
      } else if (word == "vertex") {
        if (!inFacet) syntax("'vertex' outside a facet");
        if (corners == 3) syntax("facet " + std::to_string(facet) + " has more than 3 vertices");
        InputVertex& v = pending[corners];
        v = blankVertex();
        for (int k = 0; k < 3; ++k) {
          double f;
          if (!tok.next(word) || !parseNumber(word, f))
            syntax("invalid number " + quoted(word) + " at facet " + std::to_string(facet));
          v.p[k] = f;
        }
        if (!isFinite(v))
          syntax("vertex " + std::to_string(3 * facet + corners) + " has a non-finite coordinate");
        ++corners;
      } else if (word == "endfacet") {
        if (!inFacet) syntax("unexpected 'endfacet'");
        if (corners != 3)
          syntax("facet " + std::to_string(facet) + " has " + std::to_string(corners) + " vertices (3 needed)");
        uint32_t first = uint32_t(3 * facet);
        if (3 * (facet + 1) > kMaxVertices)
          fail(path_, "more vertices than the supported " + std::to_string(kMaxVertices) + atLine(in_->line()),
               ErrorKind::Resource);
        for (const InputVertex& v : pending) batch.addVertex() = v;
        batch.addTriangle(first, first + 1, first + 2);
        inFacet = false;
        ++facet;
      } else if (word != "outer" && word != "endloop") {
        syntax("unexpected " + quoted(word) + " in ascii STL");
      }
    }
    if (!sawSolid) fail(path_, "not an ascii STL file (no 'solid')");
    if (inFacet) fail(path_, "unexpected end of file in facet " + std::to_string(facet) + atLine(in_->line()));
    if (inSolid) fail(path_, "unexpected end of file (no 'endsolid')" + atLine(in_->line()));
  }

  std::unique_ptr<InputFile> in_;
  std::string path_;
  MeshHeader header_;
};

}  // namespace

std::unique_ptr<MeshReader> openStl(std::unique_ptr<InputFile> in, bool binary) {
  return std::make_unique<StlReader>(std::move(in), binary);
}

}  // namespace mt::io
