// openMesh: format detection and dispatch to the per-format readers.
//
// Content wins over the extension, because scans get renamed and exported with the wrong suffix;
// the extension only decides when the first bytes are not conclusive. The order of the content
// checks matters: PLY's magic is exact; a binary STL is recognised by its size matching the
// triangle count (its 80-byte header is free text and often starts with "solid", which is why
// the size check comes before the ascii "solid" test); OFF has a keyword; OBJ has none, so it is
// recognised last by its first statement.
#include <cctype>
#include <cstring>
#include <string>
#include <string_view>

#include "patchstore/io/reader_util.h"

namespace mt {

const char* formatName(MeshFormat f) {
  switch (f) {
    case MeshFormat::PlyAscii: return "PLY (ascii)";
    case MeshFormat::PlyBinaryLE: return "PLY (binary little endian)";
    case MeshFormat::PlyBinaryBE: return "PLY (binary big endian)";
    case MeshFormat::Obj: return "OBJ";
    case MeshFormat::Off: return "OFF";
    case MeshFormat::StlAscii: return "STL (ascii)";
    case MeshFormat::StlBinary: return "STL (binary)";
    case MeshFormat::Gltf: return "glTF (JSON)";
    case MeshFormat::Glb: return "glTF (binary, GLB)";
    case MeshFormat::Unknown: break;
  }
  return "unknown";
}

namespace {

enum class Kind { Unknown, Ply, Obj, Off, StlAscii, StlBinary, Gltf, Glb };

// [ST][C][N][4][n]OFF, Geomview's family of OFF keywords; the OFF reader rejects the variants it
// cannot read (4D, n-dimensional) with a clear message instead of "unknown format".
bool isOffKeyword(std::string_view w) {
  for (std::string_view prefix : {"ST", "C", "N", "4", "n"})
    if (w.substr(0, prefix.size()) == prefix) w.remove_prefix(prefix.size());
  return w == "OFF";
}

// First token of the first line that is neither blank nor a '#' comment, within the sample.
// `whole` says the sample is the entire file, so its last line is complete even without "\n".
std::string_view firstStatement(std::string_view sample, bool whole, bool& complete) {
  complete = false;
  while (!sample.empty()) {
    size_t nl = sample.find('\n');
    if (nl == std::string_view::npos && !whole) return {};  // the sample may have cut this line
    io::Tokens tok{sample.substr(0, nl)};
    sample.remove_prefix(nl == std::string_view::npos ? sample.size() : nl + 1);
    std::string_view word;
    if (!tok.next(word) || word[0] == '#') continue;
    complete = true;
    return word;
  }
  return {};
}

bool isObjStatement(std::string_view w) {
  for (std::string_view s : {"v", "vn", "vt", "vp", "f", "g", "o", "s", "l", "p", "usemtl", "mtllib"})
    if (w == s) return true;
  return false;
}

Kind byContent(std::string_view sample, uint64_t size) {
  if (sample.substr(0, 4) == "ply\n" || sample.substr(0, 5) == "ply\r\n") return Kind::Ply;
  if (sample.substr(0, 4) == "glTF") return Kind::Glb;
  if (size >= 84 && sample.size() >= 84) {
    uint32_t count;
    std::memcpy(&count, sample.data() + 80, 4);  // STL is little-endian; so are the hosts we run on
    if (size == 84 + 50 * uint64_t(count)) return Kind::StlBinary;
  }
  io::Tokens lead{sample.substr(0, sample.find('\n'))};
  std::string_view word;
  if (lead.next(word) && word == "solid") return Kind::StlAscii;
  bool complete;
  word = firstStatement(sample, sample.size() == size, complete);
  if (!complete) return Kind::Unknown;
  // "OFF" may be glued to the counts on the first line ("OFF 8 6 0"), which Tokens handles.
  if (isOffKeyword(word)) return Kind::Off;
  if (isObjStatement(word)) return Kind::Obj;
  return Kind::Unknown;
}

Kind byExtension(const std::string& path) {
  size_t dot = path.rfind('.');
  if (dot == std::string::npos || path.find('/', dot) != std::string::npos) return Kind::Unknown;
  std::string ext = path.substr(dot + 1);
  for (char& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  if (ext == "ply") return Kind::Ply;
  if (ext == "obj") return Kind::Obj;
  if (ext == "off") return Kind::Off;
  if (ext == "stl") return Kind::StlBinary;
  if (ext == "gltf") return Kind::Gltf;
  if (ext == "glb") return Kind::Glb;  // an ascii STL starts with "solid" and is found by content
  return Kind::Unknown;
}

}  // namespace

std::unique_ptr<MeshReader> openFormat(const std::string& path, const MeshOpenOptions& options);

std::unique_ptr<MeshReader> openMesh(const std::string& path) { return openMesh(path, MeshOpenOptions{}); }

std::unique_ptr<MeshReader> openMesh(const std::string& path, const MeshOpenOptions& options) {
  std::unique_ptr<MeshReader> reader = openFormat(path, options);
  if (reader->header().cornerTexcoords) return io::splitWedges(std::move(reader), path, options);
  return reader;
}

std::unique_ptr<MeshReader> openFormat(const std::string& path, const MeshOpenOptions& options) {
  auto in = std::make_unique<io::InputFile>(path);
  if (in->size() == 0) fail(path, "empty file");
  // Enough to see a PLY magic, an STL header with its count, and the first lines of a text file.
  constexpr size_t kSample = 4096;
  in->ensure(kSample);
  std::string_view sample(in->data(), std::min(in->available(), kSample));
  Kind kind = byContent(sample, in->size());
  if (kind == Kind::Unknown) kind = byExtension(path);
  switch (kind) {
    case Kind::Ply: return io::openPly(std::move(in), options);
    case Kind::Obj: return io::openObj(std::move(in), options);
    case Kind::Off: return io::openOff(std::move(in));
    case Kind::StlAscii: return io::openStl(std::move(in), false);
    case Kind::StlBinary: return io::openStl(std::move(in), true);
    case Kind::Gltf: in.reset(); return io::openGltf(path, false, options);
    case Kind::Glb: in.reset(); return io::openGltf(path, true, options);
    case Kind::Unknown: break;
  }
  fail(path, "unknown mesh format (expected PLY, OBJ, OFF, STL or glTF)");
}

}  // namespace mt
