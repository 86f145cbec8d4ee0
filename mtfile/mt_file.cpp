// MT file writer and reader (see mt_file.h, layout in mt_format.h).
#include "mtfile/mt_file.h"

#include <xxhash.h>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <memory>
#include <new>
#include <type_traits>
#include <string>

#include "base/buffered_file.h"
#include "base/fuzzing.h"
#include "base/error.h"
#include "base/process.h"

namespace mt {

using namespace format;

namespace {

std::string dirOf(const std::string& path) {
  size_t s = path.find_last_of('/');
  if (s == std::string::npos) return ".";
  if (s == 0) return "/";
  return path.substr(0, s);
}

template <typename T>
void appendVec(std::vector<uint8_t>& out, const std::vector<T>& v) {
  const uint8_t* p = reinterpret_cast<const uint8_t*>(v.data());
  out.insert(out.end(), p, p + v.size() * sizeof(T));
}

// XXH64 of the header followed by the index section: the footer's checksum.
uint64_t metaChecksum(const FileHeader& h, const void* meta, size_t size) {
  XXH64_state_t* st = XXH64_createState();
  XXH64_reset(st, 0);
  XXH64_update(st, &h, sizeof h);
  XXH64_update(st, meta, size);
  uint64_t sum = XXH64_digest(st);
  XXH64_freeState(st);
  return sum;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// Writer

MtFileWriter::MtFileWriter(const std::string& path, const FileHeader& header, const std::string& tempPath, Env* env)
    : path_(path), tmp_(tempPath.empty() ? path + ".tmp" : tempPath), env_(env), header_(header) {
  if (header_.payloadAlignment == 0) header_.payloadAlignment = kDefaultPayloadAlignment;
  if (header_.payloadAlignment & (header_.payloadAlignment - 1)) fail(path_, "payload alignment must be a power of two");
  // Payloads of a few hundred bytes each: appended through a buffer, written in large blocks.
  file_ = std::make_unique<BufferedWritableFile>(env_->newWritableFile(tmp_));
  // The header is rewritten with its final counts and offsets by finish().
  FileHeader placeholder{};
  write(&placeholder, sizeof placeholder);
}

MtFileWriter::~MtFileWriter() { abandon(); }

void MtFileWriter::abandon() {
  if (!file_) return;
  file_.reset();  // closes
  try {
    env_->removeFile(tmp_);
  } catch (const Error&) {
    // Already failing (or in a destructor): a temporary name left behind is harmless.
  }
}

MtFileWriter::MtFileWriter(const std::string& path, const FileHeader& header, uint64_t length,
                           std::vector<PatchRecord> patches, const std::string& tempPath, Env* env,
                           std::vector<TextureRecord> textures)
    : path_(path), tmp_(tempPath.empty() ? path + ".tmp" : tempPath), env_(env), offset_(length), header_(header),
      patches_(std::move(patches)), textures_(std::move(textures)) {
  if (textured() && textures_.size() != patches_.size()) fail(tmp_, "cannot resume: texture records do not match the patches");
  // On failure the file is kept: it is the killed build's, not ours to remove.
  if (!env_->exists(tmp_)) failIo(tmp_, "cannot reopen to resume: no such file");
  if (uint64_t have = env_->fileSize(tmp_); have < length)
    fail(tmp_, "cannot resume: " + std::to_string(have) + " bytes, the checkpoint recorded " + std::to_string(length));
  file_ = std::make_unique<BufferedWritableFile>(env_->newWritableFileAt(tmp_, length));  // cuts off the payloads of an unfinished level
  assert(file_->size() == offset_);
}

void MtFileWriter::syncPayloads() {
  if (!file_) fail(tmp_, "sync after finish or failure");
  file_->sync();
}

void MtFileWriter::detach() {
  // What was appended is written out (the buffer) and the file closed; an error here changes
  // nothing: a resume cuts the file back to its checkpoint anyway.
  try {
    if (file_) file_->close();
  } catch (const Error&) {
  }
  file_.reset();
}

void MtFileWriter::write(const void* data, size_t size) {
  if (!file_) fail(tmp_, "write after finish or failure");
  try {
    file_->append(data, size);  // an error names the temporary file and the byte offset
  } catch (const Error&) {
    abandon();
    throw;
  }
  offset_ += size;
  assert(file_->size() == offset_);
}

uint32_t MtFileWriter::appendPatch(const uint8_t* data, size_t size, uint32_t triangles, uint32_t vertices) {
  if (size > 0xFFFFFFFFu) fail(path_, "patch " + std::to_string(patches_.size()) + " larger than 4 GiB");
  static const uint8_t zeros[4096] = {};
  uint64_t pad = (header_.payloadAlignment - offset_ % header_.payloadAlignment) % header_.payloadAlignment;
  while (pad > 0) {
    size_t n = size_t(std::min<uint64_t>(pad, sizeof zeros));
    write(zeros, n);
    pad -= n;
  }
  PatchRecord r{};
  r.offset = offset_;
  r.size = uint32_t(size);
  r.arc = ~0u;
  r.triangles = triangles;
  r.vertices = vertices;
  r.checksum = XXH64(data, size, 0);
  write(data, size);
  patches_.push_back(r);
  if (textured()) textures_.push_back(TextureRecord{});
  return uint32_t(patches_.size() - 1);
}

void MtFileWriter::appendTexture(uint32_t patch, const uint8_t* data, size_t size, uint16_t width, uint16_t height,
                                 uint32_t imageBytes) {
  if (!textured()) fail(path_, "texture for patch " + std::to_string(patch) + " in a file without textures");
  if (patch + 1 != patches_.size() || textures_[patch].size != 0)
    fail(path_, "texture for patch " + std::to_string(patch) + " does not follow its patch");
  if (size == 0 || size > 0xFFFFFFFFu || imageBytes > size || width == 0 || height == 0 || width > kMaxAtlasSide ||
      height > kMaxAtlasSide)
    fail(path_, "texture for patch " + std::to_string(patch) + " has a bad size");
  static const uint8_t zeros[4096] = {};
  uint64_t pad = (header_.payloadAlignment - offset_ % header_.payloadAlignment) % header_.payloadAlignment;
  while (pad > 0) {
    size_t n = size_t(std::min<uint64_t>(pad, sizeof zeros));
    write(zeros, n);
    pad -= n;
  }
  TextureRecord& t = textures_[patch];
  t.offset = offset_;
  t.size = uint32_t(size);
  t.width = width;
  t.height = height;
  t.checksum = XXH64(data, size, 0);
  t.imageBytes = imageBytes;
  write(data, size);
}

MtFileWriter::Stars MtFileWriter::linkArcs(std::vector<NodeRecord>& nodes, std::vector<DagArc>& arcs) {
  const uint32_t nodeCount = uint32_t(nodes.size());
  for (size_t i = 0; i < arcs.size(); ++i)
    if (arcs[i].from >= nodeCount || arcs[i].to >= nodeCount || arcs[i].from == arcs[i].to)
      fail(path_, "arc " + std::to_string(i) + " has bad nodes " + std::to_string(arcs[i].from) + " -> " +
                      std::to_string(arcs[i].to));
  // Forward stars: arcs sorted by (from, to). Stable, so equal pairs keep the caller's order.
  // The builder passes them sorted already (from its map): then no sort, and no buffer the size
  // of the arcs beside them.
  auto byFromTo = [](const DagArc& a, const DagArc& b) { return a.from != b.from ? a.from < b.from : a.to < b.to; };
  if (!std::is_sorted(arcs.begin(), arcs.end(), byFromTo)) std::stable_sort(arcs.begin(), arcs.end(), byFromTo);
  Stars s;
  s.arcs.resize(arcs.size());
  s.patchRefs.reserve(patches_.size());  // each patch is on exactly one arc (checked below)
  for (auto& n : nodes) n.firstArc = n.arcCount = n.firstBackArc = n.backArcCount = n.triangles = 0;
  for (size_t i = 0; i < arcs.size(); ++i) {
    ArcRecord& a = s.arcs[i];
    a.from = arcs[i].from, a.to = arcs[i].to;
    a.firstPatchRef = uint32_t(s.patchRefs.size());
    a.patchCount = uint32_t(arcs[i].patches.size());
    for (uint32_t p : arcs[i].patches) {
      if (p >= patches_.size()) fail(path_, "arc " + std::to_string(i) + " names unknown patch " + std::to_string(p));
      if (patches_[p].arc != ~0u) fail(path_, "patch " + std::to_string(p) + " is on two arcs");
      patches_[p].arc = uint32_t(i);
      s.patchRefs.push_back(p);
      nodes[a.from].triangles += patches_[p].triangles;
    }
    NodeRecord& n = nodes[a.from];
    if (n.arcCount == 0) n.firstArc = uint32_t(i);
    n.arcCount++;
  }
  for (size_t p = 0; p < patches_.size(); ++p)
    if (patches_[p].arc == ~0u) fail(path_, "patch " + std::to_string(p) + " is on no arc");
  // Backward stars: arc ids sorted by (to, from).
  s.backArcs.resize(arcs.size());
  for (size_t i = 0; i < s.backArcs.size(); ++i) s.backArcs[i] = uint32_t(i);
  std::stable_sort(s.backArcs.begin(), s.backArcs.end(), [&](uint32_t a, uint32_t b) {
    return s.arcs[a].to != s.arcs[b].to ? s.arcs[a].to < s.arcs[b].to : s.arcs[a].from < s.arcs[b].from;
  });
  for (size_t i = 0; i < s.backArcs.size(); ++i) {
    NodeRecord& n = nodes[s.arcs[s.backArcs[i]].to];
    if (n.backArcCount == 0) n.firstBackArc = uint32_t(i);
    n.backArcCount++;
  }
  return s;
}

void MtFileWriter::fillHeader(size_t nodeCount, const Stars& s) {
  FileHeader& h = header_;
  std::memcpy(h.magic, kMagic, 8);
  h.version = textured() ? kVersion : kUntexturedVersion;
  h.headerSize = kHeaderSize;
  h.nodeCount = nodeCount;
  h.arcCount = s.arcs.size();
  h.patchRefCount = s.patchRefs.size();
  h.patchCount = patches_.size();
  h.storedTriangles = 0;
  for (const auto& p : patches_) h.storedTriangles += p.triangles;
  h.metaOffset = offset_;
  h.nodesOffset = offset_;
  h.arcsOffset = h.nodesOffset + nodeCount * sizeof(NodeRecord);
  h.backArcsOffset = h.arcsOffset + s.arcs.size() * sizeof(ArcRecord);
  h.patchRefsOffset = h.backArcsOffset + s.backArcs.size() * 4;
  h.patchesOffset = h.patchRefsOffset + s.patchRefs.size() * 4;
  h.metadataOffset = 0;
  h.metadataSize = 0;
}

void MtFileWriter::setMetadata(const std::string& key, const std::string& value) {
  if (key.empty() || key.size() > kMaxMetadataKey) fail(path_, "metadata key '" + key + "': 1 to 255 bytes");
  if (value.empty()) metadata_.erase(key);
  else metadata_[key] = value;
}

void MtFileWriter::writeTail(const std::vector<uint8_t>& meta) {
  write(meta.data(), meta.size());
  Footer f{};
  f.metaOffset = header_.metaOffset;
  f.checksum = metaChecksum(header_, meta.data(), meta.size());
  f.version = header_.version;
  std::memcpy(f.magic, kFooterMagic, 8);
  write(&f, sizeof f);
  try {
    file_->writeAt(0, &header_, sizeof header_);
    file_->sync();
    file_->close();
  } catch (const Error&) {
    abandon();
    throw;
  }
  file_.reset();
}

void MtFileWriter::finish(std::vector<NodeRecord> nodes, std::vector<DagArc> arcs) {
  if (!file_) fail(path_, "finish after failure");
  const Stars stars = linkArcs(nodes, arcs);
  std::vector<DagArc>().swap(arcs);  // the stars hold all the file needs of them
  // Metadata section, padded to 8 bytes so the records are naturally aligned.
  uint64_t pad = (8 - offset_ % 8) % 8;
  static const uint8_t zeros[8] = {};
  write(zeros, size_t(pad));
  fillHeader(nodes.size(), stars);
  // The index in one buffer, reserved at its final size: grown by doubling instead, it held up to
  // three times its size at the moment of a copy.
  size_t metadataBlock = 0;
  for (const auto& [key, value] : metadata_) metadataBlock += 8 + key.size() + value.size();
  std::vector<uint8_t> meta;
  meta.reserve(nodes.size() * sizeof(NodeRecord) + stars.arcs.size() * sizeof(ArcRecord) +
               (stars.backArcs.size() + stars.patchRefs.size()) * sizeof(uint32_t) + patches_.size() * sizeof(PatchRecord) +
               (textured() ? textures_.size() * sizeof(TextureRecord) : 0) + metadataBlock);
  appendVec(meta, nodes);
  appendVec(meta, stars.arcs);
  appendVec(meta, stars.backArcs);
  appendVec(meta, stars.patchRefs);
  appendVec(meta, patches_);
  assert(header_.metaOffset + meta.size() == header_.patchesOffset + patches_.size() * sizeof(PatchRecord));
  if (textured()) appendVec(meta, textures_);  // right after the patch index (mt_format.h "Textures")
  if (!metadata_.empty()) {
    // The metadata block, after the patch index, inside the checksummed range (mt_format.h).
    std::vector<uint8_t> block;
    auto put = [&](const std::string& text) {
      const uint32_t n = uint32_t(text.size());
      block.insert(block.end(), reinterpret_cast<const uint8_t*>(&n), reinterpret_cast<const uint8_t*>(&n) + 4);
      block.insert(block.end(), text.begin(), text.end());
    };
    for (const auto& [key, value] : metadata_) put(key), put(value);
    if (block.size() > kMaxMetadataSize)
      fail(path_, "metadata block of " + std::to_string(block.size()) + " bytes is larger than " +
                      std::to_string(kMaxMetadataSize));
    header_.metadataOffset = header_.metaOffset + meta.size();
    header_.metadataSize = uint32_t(block.size());
    meta.insert(meta.end(), block.begin(), block.end());
  }
  writeTail(meta);
  try {
    env_->renameFile(tmp_, path_);
  } catch (const Error&) {
    try {
      env_->removeFile(tmp_);
    } catch (const Error&) {
      // The rename's error is the one to report.
    }
    throw;
  }
  // Best effort: a file system that refuses to sync a directory only loses the rename's
  // durability across a power cut, and the file is complete under its name.
  try {
    env_->syncDir(dirOf(path_));
  } catch (const Error&) {
  }
}

// ---------------------------------------------------------------------------------------------
// Reader

std::unique_ptr<MtFileReader> MtFileReader::open(const std::string& path, Env* env) {
  std::unique_ptr<MtFileReader> r(new MtFileReader());
  r->path_ = path;
  r->file_ = env->newRandomAccessFile(path);  // Io "PATH: cannot open: ..."
  r->size_ = r->file_->size();
  const Footer f = r->readHeaderAndFooter();
  r->readIndex(f);
  r->checkIndex();
  return r;
}

FileHeader MtFileReader::readHeader(const std::string& path, Env* env) {
  MtFileReader r;
  r.path_ = path;
  r.file_ = env->newRandomAccessFile(path);
  r.size_ = r.file_->size();
  r.readHeaderAndFooter();
  return r.header_;
}

Footer MtFileReader::readHeaderAndFooter() {
  const std::string& path = path_;
  const uint64_t size = size_;
  if (size < kHeaderSize + kFooterSize)
    fail(path, "not an MT file: " + std::to_string(size) + " bytes is shorter than header + footer (truncated?)");
  FileHeader& h = header_;
  file_->read(0, sizeof h, &h);
  if (std::memcmp(h.magic, kMagic, 8) != 0) fail(path, "not an MT file: bad magic at byte offset 0");
  // Version 2 only added a payload flag (kPayloadRangePositions): version 1 files still read.
  if (h.version < kMinReadableVersion || h.version > kVersion)
    fail(path, "unsupported MT version " + std::to_string(h.version) + " (this build reads " +
                   std::to_string(kMinReadableVersion) + ".." + std::to_string(kVersion) + ") at byte offset 8");
  if (h.headerSize != kHeaderSize) fail(path, "bad header size at byte offset 12");

  Footer f;
  const uint64_t footerAt = size - kFooterSize;
  file_->read(footerAt, sizeof f, &f);
  if (std::memcmp(f.magic, kFooterMagic, 8) != 0)
    failCorrupt(path, "bad footer magic at byte offset " + std::to_string(footerAt + 24) + " (truncated or damaged file)");
  if (f.version != h.version) failCorrupt(path, "footer version mismatch at byte offset " + std::to_string(footerAt + 16));
  if (f.reserved != 0) failCorrupt(path, "footer reserved bytes at byte offset " + std::to_string(footerAt + 20) + " are not zero");
  if (f.metaOffset != h.metaOffset || h.metaOffset < kHeaderSize || h.metaOffset > footerAt)
    failCorrupt(path, "footer index offset " + std::to_string(f.metaOffset) + " out of range (file " + std::to_string(size) +
                   " bytes) at byte offset " + std::to_string(footerAt));
  return f;
}

void MtFileReader::readIndex(const Footer& f) {
  const std::string& path = path_;
  const FileHeader& h = header_;
  const uint64_t footerAt = size_ - kFooterSize;
  // The metadata must tile [metaOffset, footer) exactly, section by section.
  const uint64_t metaSize = footerAt - h.metaOffset;
  const uint64_t maxCount = metaSize;  // every record is >= 4 bytes: counts cannot exceed this
  if (h.nodeCount > maxCount || h.arcCount > maxCount || h.patchRefCount > maxCount || h.patchCount > maxCount)
    failCorrupt(path, "header counts larger than the index section (damaged header)");
  uint64_t expect = h.metaOffset;
  auto section = [&](uint64_t off, uint64_t bytes, const char* name) {
    if (off != expect) failCorrupt(path, std::string("bad ") + name + " offset " + std::to_string(off) + " in header");
    expect += bytes;
  };
  section(h.nodesOffset, h.nodeCount * sizeof(NodeRecord), "node array");
  section(h.arcsOffset, h.arcCount * sizeof(ArcRecord), "arc array");
  section(h.backArcsOffset, h.arcCount * 4, "backward-star array");
  section(h.patchRefsOffset, h.patchRefCount * 4, "patch reference array");
  section(h.patchesOffset, h.patchCount * sizeof(PatchRecord), "patch index");
  const bool textured = (h.vertexFlags & kHasTextures) != 0;
  if (textured && h.version < kFirstTextureVersion) failCorrupt(path, "textures flagged in a version " + std::to_string(h.version) + " file");
  const uint64_t texturesOffset = expect;
  if (textured) expect += h.patchCount * sizeof(TextureRecord);
  if (h.metadataSize > kMaxMetadataSize || (h.metadataSize == 0 && h.metadataOffset != 0))
    failCorrupt(path, "bad metadata block size " + std::to_string(h.metadataSize) + " in header (byte offset " + std::to_string(offsetof(FileHeader, metadataSize)) + ")");
  if (h.metadataSize) section(h.metadataOffset, h.metadataSize, "metadata block");
  if (expect != footerAt)
    failCorrupt(path, "index section is " + std::to_string(metaSize) + " bytes, header describes " +
                   std::to_string(expect - h.metaOffset) + " (truncated or damaged)");

  // Each section is read straight into its array (no staging copy: a billion-triangle file's
  // index is ~78 MB), then the checksum runs over the arrays in file order. Nothing read is
  // trusted, or kept, unless the checksum matches (open() throws, and the reader goes with its
  // arrays).
  std::vector<FileRange> pieces;
  auto take = [&](uint64_t off, auto* dst, uint64_t count) {
    using T = typename std::remove_pointer_t<decltype(dst)>::value_type;
    dst->reserve(size_t(count));
    adviseHugePages(dst->data(), count * sizeof(T));  // before the first touch (resize zeroes it)
    dst->resize(size_t(count));
    if (count) pieces.push_back({off, size_t(count) * sizeof(T), dst->data()});
  };
  take(h.nodesOffset, &nodes_, h.nodeCount);
  take(h.arcsOffset, &arcs_, h.arcCount);
  take(h.backArcsOffset, &backArcs_, h.arcCount);
  take(h.patchRefsOffset, &patchRefs_, h.patchRefCount);
  take(h.patchesOffset, &patches_, h.patchCount);
  if (textured) take(texturesOffset, &textures_, h.patchCount);
  std::vector<uint8_t> block;
  take(h.metadataOffset, &block, h.metadataSize);
  readRanges(*file_, pieces);  // several reads in flight for a large index
  XXH64_state_t* sum = XXH64_createState();
  if (!sum) throw std::bad_alloc();
  std::unique_ptr<XXH64_state_t, XXH_errorcode (*)(XXH64_state_t*)> sumOwner(sum, XXH64_freeState);
  XXH64_reset(sum, 0);
  XXH64_update(sum, &h, sizeof h);
  for (const FileRange& p : pieces) XXH64_update(sum, p.to, p.bytes);
  if (kChecksumsChecked && XXH64_digest(sum) != f.checksum)
    failCorrupt(path, "checksum mismatch over header + DAG + index (bytes 0-" + std::to_string(kHeaderSize) + " and " +
                          std::to_string(h.metaOffset) + "-" + std::to_string(footerAt) + ")");
  if (h.metadataSize) {
    // Entries: uint32 length + key, uint32 length + value, filling the block exactly.
    const uint8_t* p = block.data();
    const uint8_t* end = p + h.metadataSize;
    auto text = [&](uint32_t maxLength, const char* what) {
      uint32_t n;
      const uint64_t at = h.metadataOffset + uint64_t(p - block.data());
      if (end - p < 4) failCorrupt(path, std::string("metadata block: truncated ") + what + " length at byte offset " + std::to_string(at));
      std::memcpy(&n, p, 4);
      p += 4;
      if (n > uint64_t(end - p) || n > maxLength || (n == 0 && maxLength == kMaxMetadataKey))
        failCorrupt(path, std::string("metadata block: bad ") + what + " length " + std::to_string(n) + " at byte offset " +
                              std::to_string(at));
      std::string s(reinterpret_cast<const char*>(p), n);
      p += n;
      return s;
    };
    while (p < end) {
      std::string key = text(kMaxMetadataKey, "key");
      std::string value = text(kMaxMetadataSize, "value");
      if (!metadata_.emplace(std::move(key), std::move(value)).second)
        failCorrupt(path, "metadata block: a key appears twice");
    }
  }
}

std::string MtFileReader::crs() const {
  auto it = metadata_.find(kMetadataCrs);
  return it == metadata_.end() ? std::string() : it->second;
}

// Cross-checks: a valid checksum says the writer wrote it, these say the writer was right.
void MtFileReader::checkIndex() const {
  const std::string& path = path_;
  const FileHeader& h = header_;
  if (h.codec != uint32_t(Codec::Meshopt) && h.codec != uint32_t(Codec::Draco))
    failCorrupt(path, "unknown codec " + std::to_string(h.codec) + " in header");
  if (h.payloadAlignment == 0 || (h.payloadAlignment & (h.payloadAlignment - 1)))
    failCorrupt(path, "bad payload alignment in header");
  if (!(h.gridStep > 0) || h.gridBits == 0 || h.gridBits > 31) failCorrupt(path, "bad quantization grid in header");
  for (size_t i = 0; i < patches_.size(); ++i) {
    const PatchRecord& p = patches_[i];
    if (p.offset < kHeaderSize || p.offset % h.payloadAlignment || p.offset + p.size > h.metaOffset ||
        p.offset + p.size < p.offset)
      failCorrupt(path, "patch " + std::to_string(i) + ": payload at byte offset " + std::to_string(p.offset) + " size " +
                     std::to_string(p.size) + " outside the payload area");
    if (p.arc >= h.arcCount) failCorrupt(path, "patch " + std::to_string(i) + ": arc " + std::to_string(p.arc) + " out of range");
  }
  for (size_t i = 0; i < textures_.size(); ++i) {
    const TextureRecord& t = textures_[i];
    const PatchRecord& p = patches_[i];
    const uint64_t next = i + 1 < patches_.size() ? patches_[i + 1].offset : h.metaOffset;
    const bool empty = t.size == 0 && t.offset == 0 && t.width == 0 && t.height == 0 && t.imageBytes == 0 && t.checksum == 0;
    if (t.reserved != 0 ||
        (!empty && (t.size == 0 || t.offset < p.offset + p.size || t.offset % h.payloadAlignment || t.offset + t.size > next ||
                    t.width == 0 || t.height == 0 || t.width > kMaxAtlasSide || t.height > kMaxAtlasSide ||
                    t.imageBytes > t.size)))
      failCorrupt(path, "texture of patch " + std::to_string(i) + ": record (payload at byte offset " + std::to_string(t.offset) +
                            " size " + std::to_string(t.size) + ") is damaged or outside its place");
  }
  for (size_t i = 0; i < arcs_.size(); ++i) {
    const ArcRecord& a = arcs_[i];
    if (a.from >= h.nodeCount || a.to >= h.nodeCount || uint64_t(a.firstPatchRef) + a.patchCount > h.patchRefCount)
      failCorrupt(path, "arc " + std::to_string(i) + " out of range");
    for (uint32_t k = 0; k < a.patchCount; ++k)
      if (patchRefs_[a.firstPatchRef + k] >= h.patchCount)
        failCorrupt(path, "arc " + std::to_string(i) + " names patch out of range");
  }
  for (uint32_t b : backArcs_)
    if (b >= h.arcCount) failCorrupt(path, "backward star names arc out of range");
  for (size_t i = 0; i < nodes_.size(); ++i) {
    const NodeRecord& n = nodes_[i];
    if (uint64_t(n.firstArc) + n.arcCount > h.arcCount || uint64_t(n.firstBackArc) + n.backArcCount > h.arcCount)
      failCorrupt(path, "node " + std::to_string(i) + ": arc range out of bounds");
    for (uint32_t k = 0; k < n.arcCount; ++k)
      if (arcs_[n.firstArc + k].from != i) failCorrupt(path, "node " + std::to_string(i) + ": forward star inconsistent");
    for (uint32_t k = 0; k < n.backArcCount; ++k)
      if (arcs_[backArcs_[n.firstBackArc + k]].to != i)
        failCorrupt(path, "node " + std::to_string(i) + ": backward star inconsistent");
  }
}

MtFileReader::~MtFileReader() = default;

QuantizationGrid MtFileReader::grid() const {
  QuantizationGrid g;
  for (int a = 0; a < 3; ++a) g.origin[a] = header_.gridOrigin[a];
  g.step = header_.gridStep;
  g.bits = header_.gridBits;
  return g;
}

std::vector<uint8_t> MtFileReader::readPayload(uint32_t patch) const {
  if (patch >= patches_.size())
    fail(path_, "patch " + std::to_string(patch) + " does not exist (" + std::to_string(patches_.size()) + " patches)");
  const PatchRecord& p = patches_[patch];
  // The payload and the zero padding after it (up to the next payload, or the index after the
  // last one), in one read: no checksum covers the padding, so a flipped byte there is found by
  // its not being zero. Gaps the writer never makes (over 4 KiB) are not read.
  const uint64_t end = p.offset + p.size;
  uint64_t next = patch + 1 < patches_.size() ? patches_[patch + 1].offset : header_.metaOffset;
  if (!textures_.empty() && textures_[patch].size) next = textures_[patch].offset;  // the patch's texture follows it
  const size_t gap = next > end && next - end <= 4096 ? size_t(next - end) : 0;
  std::vector<uint8_t> data(p.size + gap);
  file_->read(p.offset, data.size(), data.data());  // checked against the file size by open()
  if (kChecksumsChecked && XXH64(data.data(), p.size, 0) != p.checksum)
    failCorrupt(path_, "patch " + std::to_string(patch) + " is damaged: checksum mismatch in payload at byte offset " +
                    std::to_string(p.offset) + " (" + std::to_string(p.size) + " bytes)");
  for (size_t i = p.size; i < data.size(); ++i)
    if (data[i] != 0)
      failCorrupt(path_, "patch " + std::to_string(patch) + " is damaged: padding after its payload is not zero at byte offset " +
                      std::to_string(p.offset + i));
  data.resize(p.size);
  return data;
}

std::vector<uint8_t> MtFileReader::readTexturePayload(uint32_t patch) const {
  if (patch >= patches_.size())
    fail(path_, "patch " + std::to_string(patch) + " does not exist (" + std::to_string(patches_.size()) + " patches)");
  if (textures_.empty() || textures_[patch].size == 0) return {};
  const TextureRecord& t = textures_[patch];
  const uint64_t end = t.offset + t.size;
  const uint64_t next = patch + 1 < patches_.size() ? patches_[patch + 1].offset : header_.metaOffset;
  const size_t gap = next > end && next - end <= 4096 ? size_t(next - end) : 0;
  std::vector<uint8_t> data(t.size + gap);
  file_->read(t.offset, data.size(), data.data());
  if (kChecksumsChecked && XXH64(data.data(), t.size, 0) != t.checksum)
    failCorrupt(path_, "texture of patch " + std::to_string(patch) + " is damaged: checksum mismatch in payload at byte offset " +
                           std::to_string(t.offset) + " (" + std::to_string(t.size) + " bytes)");
  for (size_t i = t.size; i < data.size(); ++i)
    if (data[i] != 0)
      failCorrupt(path_, "texture of patch " + std::to_string(patch) + " is damaged: padding after its payload is not zero at byte offset " +
                             std::to_string(t.offset + i));
  data.resize(t.size);
  return data;
}

TexturePayload MtFileReader::readTexture(uint32_t patch, const DecodedPatch& d) const {
  std::vector<uint8_t> data = readTexturePayload(patch);
  if (data.empty()) return {};
  try {
    TexturePayload t = decodeTexturePayload(data.data(), data.size(), d.triangles.data(), d.triangleCount(), d.vertexCount());
    const TextureRecord& rec = textures_[patch];
    if (t.width != rec.width || t.height != rec.height || t.image.size() != rec.imageBytes)
      throw Error("image size differs from the index");
    static const uint8_t kJpeg[3] = {0xFF, 0xD8, 0xFF}, kPng[4] = {0x89, 'P', 'N', 'G'};
    const bool magic = t.imageFormat == kImageJpeg ? t.image.size() >= 3 && std::memcmp(t.image.data(), kJpeg, 3) == 0
                                                    : t.image.size() >= 4 && std::memcmp(t.image.data(), kPng, 4) == 0;
    if (!magic) throw Error("the image is not the format the payload names");
    return t;
  } catch (const Error& e) {
    failCorrupt(path_, "texture of patch " + std::to_string(patch) + " at byte offset " + std::to_string(textures_[patch].offset) +
                           ": " + e.what());
  }
}

DecodedPatch MtFileReader::readPatch(uint32_t patch) const {
  std::vector<uint8_t> data = readPayload(patch);
  try {
    DecodedPatch d = decodePatch(data.data(), data.size(), codec(), grid(), patches_[patch].triangles);
    const PatchRecord& p = patches_[patch];
    if (d.triangleCount() != p.triangles)
      throw Error("triangle count " + std::to_string(d.triangleCount()) + " differs from the index (" +
                  std::to_string(p.triangles) + ")");
    return d;
  } catch (const Error& e) {
    failCorrupt(path_, "patch " + std::to_string(patch) + " at byte offset " + std::to_string(patches_[patch].offset) +
                    ": " + e.what());
  }
}

}  // namespace mt
