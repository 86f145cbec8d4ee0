// Writing and reading MT files (layout in mt_format.h).
//
// MtFileWriter streams: payloads are appended as the builder produces patches, the DAG and the
// patch index are written at the end, and the file is built under a temporary name beside PATH
// (PATH.tmp, or the name the caller gives: the builder passes one unique to its process, so two
// builds of one output never write the same file) and renamed to PATH only once complete and
// synced, so a crash never leaves a half-written file under the final name.
//
// MtFileReader validates everything it trusts before returning from open(): magic, version,
// footer, the metadata checksum, and every offset and count against the file size and each other.
// Payloads are verified when read (their own checksum). Every error is a one-line mt::Error of the
// form "PATH: what, where (patch N / byte offset X)".
//
// Both reach the file system only through an Env (base/env.h; Env::Default() unless a test passes
// a fault-injecting one): failures are Io errors naming the file and the byte offset, damage is
// Corruption. mtrender links this library without the patch store.
#pragma once

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "base/env.h"
#include "mtfile/mt_format.h"
#include "mtfile/patch_codec.h"
#include "mtfile/texture_payload.h"

namespace mt {

// An arc as the builder describes it: the patches (ids from appendPatch) that `from`'s fragment
// holds inside `to`'s floor.
struct DagArc {
  uint32_t from = 0, to = 0;
  std::vector<uint32_t> patches;
};

class MtFileWriter {
 public:
  // `header` gives codec, vertexFlags, levelCount, input counts, bounds and grid; the writer fills
  // magic, version, sizes, counts and offsets. Creates (truncates) `tempPath` (empty: PATH.tmp),
  // which must be beside PATH (renamed over it). Throws mt::Error.
  MtFileWriter(const std::string& path, const format::FileHeader& header, const std::string& tempPath = {},
               Env* env = Env::Default());
  ~MtFileWriter();  // removes the temporary file unless finish() completed
  MtFileWriter(const MtFileWriter&) = delete;
  MtFileWriter& operator=(const MtFileWriter&) = delete;

  // Appends one payload (aligned); returns its patch id (0, 1, 2, ... in call order).
  uint32_t appendPatch(const uint8_t* data, size_t size, uint32_t triangles, uint32_t vertices);
  // Textured files (header vertexFlags & kHasTextures): the texture payload of the patch just
  // appended (mt_format.h "Textures"), at most once per patch; a patch without one has none.
  void appendTexture(uint32_t patch, const uint8_t* data, size_t size, uint16_t width, uint16_t height, uint32_t imageBytes);
  uint32_t patchCount() const { return uint32_t(patches_.size()); }
  // An entry of the file's metadata block (mt_format.h "The metadata block"), e.g. "crs"; an empty
  // value removes the key. No entries: no block (the file is as without this call).
  void setMetadata(const std::string& key, const std::string& value);
  // Header fields known only at the end of a build (levelCount, input counts) may be set here
  // before finish(); finish() fills the counts and offsets itself.
  format::FileHeader& header() { return header_; }
  uint64_t bytesWritten() const { return offset_; }

  // The file being written, renamed to PATH by finish().
  const std::string& tempPath() const { return tmp_; }

  // Writes the DAG, the index and the footer, syncs, renames the temporary file to PATH and syncs the
  // directory (best effort: the file is complete and in place by then). nodes: every field except
  // firstArc/arcCount/firstBackArc/backArcCount/triangles,
  // which are derived from `arcs`. Every patch must be on exactly one arc. Throws mt::Error.
  void finish(std::vector<format::NodeRecord> nodes, std::vector<DagArc> arcs);

  // Stops and removes the temporary file (also done by the destructor).
  void abandon();

  // ---- Checkpointing (mtbuild --resume; added by the cluster/resume work) ----
  // Reopens the temporary file `tempPath` (empty: PATH.tmp) of a killed build to continue it:
  // `length` and `patches` are what bytesWritten() and patchRecords() returned when the
  // checkpoint was taken (after syncPayloads()). Bytes past `length` (payloads of an unfinished
  // level) are cut off. Throws mt::Error when the file is missing or shorter than `length`.
  MtFileWriter(const std::string& path, const format::FileHeader& header, uint64_t length,
               std::vector<format::PatchRecord> patches, const std::string& tempPath = {}, Env* env = Env::Default(),
               std::vector<format::TextureRecord> textures = {});
  // Makes every payload appended so far durable (fdatasync), so a checkpoint may refer to them.
  void syncPayloads();
  const std::vector<format::PatchRecord>& patchRecords() const { return patches_; }
  const std::vector<format::TextureRecord>& textureRecords() const { return textures_; }
  bool textured() const { return (header_.vertexFlags & format::kHasTextures) != 0; }
  // Closes the temporary file but keeps it, for a build that stopped after a checkpoint and may resume.
  void detach();

 private:
  void write(const void* data, size_t size);
  // finish()'s steps: the arc, backward-star and patch-reference arrays from `arcs` (filling the
  // nodes' star ranges and triangle counts); the header's counts and offsets; the file's end.
  struct Stars {
    std::vector<format::ArcRecord> arcs;
    std::vector<uint32_t> backArcs, patchRefs;
  };
  Stars linkArcs(std::vector<format::NodeRecord>& nodes, std::vector<DagArc>& arcs);
  void fillHeader(size_t nodeCount, const Stars& stars);
  void writeTail(const std::vector<uint8_t>& meta);
  std::string path_, tmp_;
  Env* env_;
  std::unique_ptr<WritableFile> file_;  // null once finished, abandoned or detached
  uint64_t offset_ = 0;
  format::FileHeader header_;
  std::vector<format::PatchRecord> patches_;
  std::vector<format::TextureRecord> textures_;  // textured files: one per patch
  std::map<std::string, std::string> metadata_;
};

class MtFileReader {
 public:
  static std::unique_ptr<MtFileReader> open(const std::string& path, Env* env = Env::Default());
  // The header alone, its magic and version checked and the footer's agreeing with it; the index
  // is neither read nor checked (open() does that). For questions the header answers (the vertex
  // flags) without reading a large file's whole index.
  static format::FileHeader readHeader(const std::string& path, Env* env = Env::Default());
  ~MtFileReader();

  const std::string& path() const { return path_; }
  const format::FileHeader& header() const { return header_; }
  format::Codec codec() const { return format::Codec(header_.codec); }
  QuantizationGrid grid() const;
  uint64_t fileSize() const { return size_; }

  const std::vector<format::NodeRecord>& nodes() const { return nodes_; }
  const std::vector<format::ArcRecord>& arcs() const { return arcs_; }
  const std::vector<uint32_t>& backArcs() const { return backArcs_; }
  const std::vector<uint32_t>& patchRefs() const { return patchRefs_; }
  const std::vector<format::PatchRecord>& patches() const { return patches_; }
  // The metadata block's entries (every key, known or not), and the coordinate reference system
  // given to the builder ("" when none).
  const std::map<std::string, std::string>& metadata() const { return metadata_; }
  std::string crs() const;

  // The payload bytes of patch i, checksum verified. Thread-safe (positional reads).
  std::vector<uint8_t> readPayload(uint32_t patch) const;
  // readPayload + decodePatch; a damaged payload throws "PATH: patch N: ...".
  DecodedPatch readPatch(uint32_t patch) const;

  // Textured files (mt_format.h "Textures"): one record per patch (empty for other files), and a
  // patch's texture payload, checksum verified (empty when the patch has none). Thread-safe.
  bool hasTextures() const { return !textures_.empty(); }
  const std::vector<format::TextureRecord>& textures() const { return textures_; }
  std::vector<uint8_t> readTexturePayload(uint32_t patch) const;
  // readTexturePayload + decodeTexturePayload over the patch as decoded (its triangles name the
  // vertices the coordinates go with); the image is checked to be the format it says, not
  // decoded. A damaged one throws Corruption "PATH: texture of patch N ...". No texture: empty.
  TexturePayload readTexture(uint32_t patch, const DecodedPatch& decoded) const;

 private:
  MtFileReader() = default;
  // open()'s steps: the footer (after the header's magic and version); the index section, checked
  // to tile [metaOffset, footer) and against the footer's checksum; the cross-checks of the
  // records against the header and each other.
  format::Footer readHeaderAndFooter();
  void readIndex(const format::Footer& footer);
  void checkIndex() const;
  std::string path_;
  std::unique_ptr<RandomAccessFile> file_;
  uint64_t size_ = 0;
  format::FileHeader header_{};
  std::vector<format::NodeRecord> nodes_;
  std::vector<format::ArcRecord> arcs_;
  std::vector<uint32_t> backArcs_, patchRefs_;
  std::vector<format::PatchRecord> patches_;
  std::vector<format::TextureRecord> textures_;
  std::map<std::string, std::string> metadata_;
};

}  // namespace mt
