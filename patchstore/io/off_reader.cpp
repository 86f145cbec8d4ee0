// OFF reader (Geomview's Object File Format), streamed line by line.
//
// Header keyword [ST][C][N]OFF: N adds a per-vertex normal, C a per-vertex colour, ST texture
// coordinates (skipped). The counts "vertices faces [edges]" follow, on the keyword's line or the
// next one. Each vertex is one line "x y z [nx ny nz] [r g b [a]] [s t]"; colours are integers
// 0..255, or floats 0..1 when written with a decimal point or exponent (a value outside is
// refused). Each face is one line
// "n i0 ... i(n-1) [face colour]"; face colours are skipped. '#' starts a comment anywhere.
#include <string>

#include "patchstore/io/reader_util.h"

namespace mt::io {
namespace {

class OffReader final : public MeshReader {
 public:
  explicit OffReader(std::unique_ptr<InputFile> in) : in_(std::move(in)), path_(in_->path()) {
    header_.format = MeshFormat::Off;
    // Decimal text carries whatever precision its writer gave it (survey coordinates in metres
    // need more than float32): parsed and kept as double.
    header_.doublePrecision = true;
    parseHeader();
  }

  const MeshHeader& header() const override { return header_; }

  ReadStats read(MeshSink& sink) override {
    ReadStats stats;
    Batcher batch(sink, stats);
    sink.begin(header_);
    for (uint64_t i = 0; i < vertexCount_; ++i) readVertex(i, batch);
    for (uint64_t i = 0; i < faceCount_; ++i) readFace(i, batch);
    // Data after the last face means the declared counts are wrong.
    Tokens tok;
    if (nextDataLine(tok))
      fail(path_, "unexpected data after the last face" + atLine(in_->line()));
    batch.flush();
    stats.bytes = in_->offset();
    if (stats.triangles == 0) fail(path_, "mesh has no triangles");
    sink.end(stats);
    return stats;
  }

 private:
  // Next line with something besides blanks and comments; false at end of file.
  bool nextDataLine(Tokens& tok) {
    std::string_view line;
    while (in_->nextLine(line)) {
      size_t hash = line.find('#');
      tok.rest = line.substr(0, hash);
      if (!tok.empty()) return true;
    }
    return false;
  }

  [[noreturn]] void truncated(const char* kind, uint64_t index) {
    fail(path_, std::string("unexpected end of file in ") + kind + " " + std::to_string(index) + atLine(in_->line()));
  }

  std::string_view need(Tokens& tok, const char* kind, uint64_t index) {
    std::string_view word;
    if (!tok.next(word))
      fail(path_, std::string("missing value at ") + kind + " " + std::to_string(index) + atLine(in_->line()));
    return word;
  }

  template <class T>
  T number(Tokens& tok, const char* kind, uint64_t index) {
    std::string_view word = need(tok, kind, index);
    T value;
    if (!parseNumber(word, value))
      fail(path_, "invalid number " + quoted(word) + " at " + kind + " " + std::to_string(index) + atLine(in_->line()));
    return value;
  }

  void parseHeader() {
    Tokens tok;
    std::string_view word;
    if (!nextDataLine(tok) || !tok.next(word)) fail(path_, "not an OFF file (no OFF keyword)");
    std::string_view keyword = word;
    if (keyword.substr(0, 2) == "ST") texture_ = true, keyword.remove_prefix(2);
    if (keyword.substr(0, 1) == "C") header_.hasColors = true, keyword.remove_prefix(1);
    if (keyword.substr(0, 1) == "N") header_.hasNormals = true, keyword.remove_prefix(1);
    if (keyword != "OFF")
      fail(path_, "unsupported OFF variant " + quoted(word) + " (only [ST][C][N]OFF in 3D)" + atLine(in_->line()));
    if (tok.empty() && !nextDataLine(tok)) fail(path_, "unexpected end of file in OFF header" + atLine(in_->line()));
    int64_t v = number<int64_t>(tok, "header", 0), f = number<int64_t>(tok, "header", 0);
    if (v < 0 || f < 0) fail(path_, "negative element count in OFF header" + atLine(in_->line()));
    if (uint64_t(v) > kMaxVertices)
      fail(path_, std::to_string(v) + " vertices is more than the supported " + std::to_string(kMaxVertices),
           ErrorKind::Resource);
    if (v == 0 || f == 0) fail(path_, "mesh has no triangles");
    vertexCount_ = uint64_t(v);
    faceCount_ = uint64_t(f);
    header_.declaredVertices = v;
    header_.declaredFaces = f;
  }

  void readVertex(uint64_t index, Batcher& batch) {
    Tokens tok;
    if (!nextDataLine(tok)) truncated("vertex", index);
    InputVertex& v = batch.addVertex();
    v = blankVertex();
    for (int k = 0; k < 3; ++k) v.p[k] = number<double>(tok, "vertex", index);
    if (!isFinite(v))
      fail(path_, "vertex " + std::to_string(index) + " has a non-finite coordinate" + atLine(in_->line()));
    if (header_.hasNormals)
      for (int k = 0; k < 3; ++k) v.n[k] = number<float>(tok, "vertex", index);
    if (header_.hasColors) {
      // What is left is r g b [a], then s t when the keyword has ST.
      std::string_view channel[6];
      int n = 0;
      while (n < 6 && tok.next(channel[n])) ++n;
      if (texture_) n = std::max(n - 2, 0);
      if (n < 3 || n > 4)
        fail(path_, "vertex " + std::to_string(index) + " needs 3 or 4 colour values" + atLine(in_->line()));
      bool unit = false;
      for (int k = 0; k < n; ++k) unit |= channel[k].find_first_of(".eE") != std::string_view::npos;
      for (int k = 0; k < n; ++k) {
        double c;
        if (!parseNumber(channel[k], c))
          fail(path_, "invalid number " + quoted(channel[k]) + " at vertex " + std::to_string(index) + atLine(in_->line()));
        if (!(unit ? unitColorByte(c, v.c[k]) : integerColorByte(c, 255, v.c[k])))
          fail(path_, "vertex " + std::to_string(index) + " colour channel " + std::to_string(k) + ": " +
                          badColorMessage(c, unit, 255) + atLine(in_->line()));
      }
    }
  }

  void readFace(uint64_t index, Batcher& batch) {
    Tokens tok;
    if (!nextDataLine(tok)) truncated("face", index);
    int64_t corners = number<int64_t>(tok, "face", index);
    if (corners < 3)
      fail(path_, "face " + std::to_string(index) + " has " + std::to_string(corners) +
                      " corners (at least 3 needed)" + atLine(in_->line()));
    batch.beginFace();
    for (int64_t k = 0; k < corners; ++k) {
      int64_t i = number<int64_t>(tok, "face", index);
      if (i < 0 || uint64_t(i) >= vertexCount_)
        fail(path_, "index " + std::to_string(i) + " out of range (" + std::to_string(vertexCount_) +
                        " vertices) at face " + std::to_string(index) + atLine(in_->line()));
      batch.addCorner(uint32_t(i));
    }
    batch.endFace();
  }

  std::unique_ptr<InputFile> in_;
  std::string path_;
  MeshHeader header_;
  uint64_t vertexCount_ = 0, faceCount_ = 0;
  bool texture_ = false;  // ST: vertices end with texture coordinates
};

}  // namespace

std::unique_ptr<MeshReader> openOff(std::unique_ptr<InputFile> in) {
  return std::make_unique<OffReader>(std::move(in));
}

}  // namespace mt::io
