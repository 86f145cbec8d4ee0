// MT file writer and reader (see mt_file.h, layout in mt_format.h).
#include "mtbuild/mt_file.h"

#include <fcntl.h>
#include <unistd.h>
#include <xxhash.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <type_traits>
#include <string>

#include "base/error.h"

namespace mt {

using namespace format;

namespace {

std::string errnoText() { return std::strerror(errno); }

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

}  // namespace

// ---------------------------------------------------------------------------------------------
// Writer

MtFileWriter::MtFileWriter(const std::string& path, const FileHeader& header, const std::string& tempPath)
    : path_(path), tmp_(tempPath.empty() ? path + ".tmp" : tempPath), header_(header) {
  fd_ = ::open(tmp_.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd_ < 0) fail(tmp_, "cannot create: " + errnoText());
  if (header_.payloadAlignment == 0) header_.payloadAlignment = kDefaultPayloadAlignment;
  if (header_.payloadAlignment & (header_.payloadAlignment - 1)) {
    abandon();
    fail(path_, "payload alignment must be a power of two");
  }
  // The header is rewritten with its final counts and offsets by finish().
  FileHeader placeholder{};
  write(&placeholder, sizeof placeholder);
}

MtFileWriter::~MtFileWriter() { abandon(); }

void MtFileWriter::abandon() {
  if (fd_ >= 0) {
    ::close(fd_);
    fd_ = -1;
    ::unlink(tmp_.c_str());
  }
}

MtFileWriter::MtFileWriter(const std::string& path, const FileHeader& header, uint64_t length,
                           std::vector<PatchRecord> patches, const std::string& tempPath)
    : path_(path), tmp_(tempPath.empty() ? path + ".tmp" : tempPath), offset_(length), header_(header), patches_(std::move(patches)) {
  fd_ = ::open(tmp_.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd_ < 0) fail(tmp_, "cannot reopen to resume: " + errnoText());
  off_t end = ::lseek(fd_, 0, SEEK_END);
  if (end < 0 || uint64_t(end) < length) {
    ::close(fd_);
    fd_ = -1;  // keep the file: it is the killed build's, not ours to remove
    fail(tmp_, "cannot resume: " + std::to_string(end) + " bytes, the checkpoint recorded " + std::to_string(length));
  }
  if (::ftruncate(fd_, off_t(length)) != 0 || ::lseek(fd_, off_t(length), SEEK_SET) != off_t(length)) {
    std::string why = errnoText();
    ::close(fd_);
    fd_ = -1;
    fail(tmp_, "cannot cut back to the checkpoint at byte offset " + std::to_string(length) + ": " + why);
  }
}

void MtFileWriter::syncPayloads() {
  if (fd_ < 0) fail(tmp_, "sync after finish or failure");
  if (::fdatasync(fd_) != 0) fail(tmp_, "fdatasync failed: " + errnoText());
}

void MtFileWriter::detach() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

void MtFileWriter::write(const void* data, size_t size) {
  if (fd_ < 0) fail(tmp_, "write after finish or failure");
  const char* p = static_cast<const char*>(data);
  while (size > 0) {
    ssize_t n = ::write(fd_, p, size);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      std::string why = n < 0 ? errnoText() : "short write";
      abandon();
      fail(tmp_, "write failed at byte offset " + std::to_string(offset_) + ": " + why);
    }
    p += n, size -= size_t(n), offset_ += uint64_t(n);
  }
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
  return uint32_t(patches_.size() - 1);
}

void MtFileWriter::finish(std::vector<NodeRecord> nodes, std::vector<DagArc> arcs) {
  if (fd_ < 0) fail(path_, "finish after failure");
  uint32_t nodeCount = uint32_t(nodes.size());
  for (size_t i = 0; i < arcs.size(); ++i)
    if (arcs[i].from >= nodeCount || arcs[i].to >= nodeCount || arcs[i].from == arcs[i].to)
      fail(path_, "arc " + std::to_string(i) + " has bad nodes " + std::to_string(arcs[i].from) + " -> " +
                      std::to_string(arcs[i].to));
  // Forward stars: arcs sorted by (from, to). Stable, so equal pairs keep the caller's order.
  std::stable_sort(arcs.begin(), arcs.end(),
                   [](const DagArc& a, const DagArc& b) { return a.from != b.from ? a.from < b.from : a.to < b.to; });
  std::vector<ArcRecord> arcRecs(arcs.size());
  std::vector<uint32_t> patchRefs;
  for (auto& n : nodes) n.firstArc = n.arcCount = n.firstBackArc = n.backArcCount = n.triangles = 0;
  for (size_t i = 0; i < arcs.size(); ++i) {
    ArcRecord& a = arcRecs[i];
    a.from = arcs[i].from, a.to = arcs[i].to;
    a.firstPatchRef = uint32_t(patchRefs.size());
    a.patchCount = uint32_t(arcs[i].patches.size());
    for (uint32_t p : arcs[i].patches) {
      if (p >= patches_.size()) fail(path_, "arc " + std::to_string(i) + " names unknown patch " + std::to_string(p));
      if (patches_[p].arc != ~0u) fail(path_, "patch " + std::to_string(p) + " is on two arcs");
      patches_[p].arc = uint32_t(i);
      patchRefs.push_back(p);
      nodes[a.from].triangles += patches_[p].triangles;
    }
    NodeRecord& n = nodes[a.from];
    if (n.arcCount == 0) n.firstArc = uint32_t(i);
    n.arcCount++;
  }
  for (size_t p = 0; p < patches_.size(); ++p)
    if (patches_[p].arc == ~0u) fail(path_, "patch " + std::to_string(p) + " is on no arc");
  // Backward stars: arc ids sorted by (to, from).
  std::vector<uint32_t> backArcs(arcs.size());
  for (size_t i = 0; i < backArcs.size(); ++i) backArcs[i] = uint32_t(i);
  std::stable_sort(backArcs.begin(), backArcs.end(), [&](uint32_t a, uint32_t b) {
    return arcRecs[a].to != arcRecs[b].to ? arcRecs[a].to < arcRecs[b].to : arcRecs[a].from < arcRecs[b].from;
  });
  for (size_t i = 0; i < backArcs.size(); ++i) {
    NodeRecord& n = nodes[arcRecs[backArcs[i]].to];
    if (n.backArcCount == 0) n.firstBackArc = uint32_t(i);
    n.backArcCount++;
  }

  // Metadata section, padded to 8 bytes so the records are naturally aligned.
  uint64_t pad = (8 - offset_ % 8) % 8;
  static const uint8_t zeros[8] = {};
  write(zeros, size_t(pad));
  FileHeader& h = header_;
  std::memcpy(h.magic, kMagic, 8);
  h.version = kVersion;
  h.headerSize = kHeaderSize;
  h.nodeCount = nodes.size();
  h.arcCount = arcRecs.size();
  h.patchRefCount = patchRefs.size();
  h.patchCount = patches_.size();
  h.storedTriangles = 0;
  for (const auto& p : patches_) h.storedTriangles += p.triangles;
  h.metaOffset = offset_;
  h.nodesOffset = offset_;
  h.arcsOffset = h.nodesOffset + nodes.size() * sizeof(NodeRecord);
  h.backArcsOffset = h.arcsOffset + arcRecs.size() * sizeof(ArcRecord);
  h.patchRefsOffset = h.backArcsOffset + backArcs.size() * 4;
  h.patchesOffset = h.patchRefsOffset + patchRefs.size() * 4;
  std::memset(h.reserved, 0, sizeof h.reserved);
  h.reserved0 = 0;

  std::vector<uint8_t> meta;
  appendVec(meta, nodes);
  appendVec(meta, arcRecs);
  appendVec(meta, backArcs);
  appendVec(meta, patchRefs);
  appendVec(meta, patches_);
  write(meta.data(), meta.size());

  XXH64_state_t* st = XXH64_createState();
  XXH64_reset(st, 0);
  XXH64_update(st, &h, sizeof h);
  XXH64_update(st, meta.data(), meta.size());
  Footer f{};
  f.metaOffset = h.metaOffset;
  f.checksum = XXH64_digest(st);
  XXH64_freeState(st);
  f.version = kVersion;
  std::memcpy(f.magic, kFooterMagic, 8);
  write(&f, sizeof f);

  if (::pwrite(fd_, &h, sizeof h, 0) != ssize_t(sizeof h)) {
    std::string why = errnoText();
    abandon();
    fail(tmp_, "cannot write the header: " + why);
  }
  if (::fdatasync(fd_) != 0) {
    std::string why = errnoText();
    abandon();
    fail(tmp_, "fdatasync failed: " + why);
  }
  ::close(fd_);
  fd_ = -1;
  if (::rename(tmp_.c_str(), path_.c_str()) != 0) {
    std::string why = errnoText();
    ::unlink(tmp_.c_str());
    fail(path_, "cannot rename " + tmp_ + " into place: " + why);
  }
  int dfd = ::open(dirOf(path_).c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
}

// ---------------------------------------------------------------------------------------------
// Reader

namespace {

void preadExact(int fd, const std::string& path, uint64_t offset, size_t size, void* out) {
  char* p = static_cast<char*>(out);
  uint64_t at = offset;
  while (size > 0) {
    ssize_t n = ::pread(fd, p, size, off_t(at));
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) failIo(path, "read failed at byte offset " + std::to_string(at) + ": " + errnoText());
    if (n == 0) failCorrupt(path, "unexpected end of file at byte offset " + std::to_string(at));
    p += n, size -= size_t(n), at += uint64_t(n);
  }
}

template <typename T>
std::vector<T> readArray(int fd, const std::string& path, uint64_t offset, uint64_t count) {
  std::vector<T> v(static_cast<size_t>(count));
  if (count) preadExact(fd, path, offset, size_t(count * sizeof(T)), v.data());
  return v;
}

}  // namespace

std::unique_ptr<MtFileReader> MtFileReader::open(const std::string& path) {
  std::unique_ptr<MtFileReader> r(new MtFileReader());
  r->path_ = path;
  r->fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (r->fd_ < 0) failIo(path, "cannot open: " + errnoText());
  off_t end = ::lseek(r->fd_, 0, SEEK_END);
  if (end < 0) fail(path, "cannot seek: " + errnoText());
  r->size_ = uint64_t(end);
  const uint64_t size = r->size_;
  if (size < kHeaderSize + kFooterSize)
    fail(path, "not an MT file: " + std::to_string(size) + " bytes is shorter than header + footer (truncated?)");

  FileHeader& h = r->header_;
  preadExact(r->fd_, path, 0, sizeof h, &h);
  if (std::memcmp(h.magic, kMagic, 8) != 0) fail(path, "not an MT file: bad magic at byte offset 0");
  // Version 2 only added a payload flag (kPayloadRangePositions): version 1 files still read.
  if (h.version < kMinReadableVersion || h.version > kVersion)
    fail(path, "unsupported MT version " + std::to_string(h.version) + " (this build reads " +
                   std::to_string(kMinReadableVersion) + ".." + std::to_string(kVersion) + ") at byte offset 8");
  if (h.headerSize != kHeaderSize) fail(path, "bad header size at byte offset 12");

  Footer f;
  uint64_t footerAt = size - kFooterSize;
  preadExact(r->fd_, path, footerAt, sizeof f, &f);
  if (std::memcmp(f.magic, kFooterMagic, 8) != 0)
    failCorrupt(path, "bad footer magic at byte offset " + std::to_string(footerAt + 24) + " (truncated or damaged file)");
  if (f.version != h.version) failCorrupt(path, "footer version mismatch at byte offset " + std::to_string(footerAt + 16));
  if (f.metaOffset != h.metaOffset || h.metaOffset < kHeaderSize || h.metaOffset > footerAt)
    failCorrupt(path, "footer index offset " + std::to_string(f.metaOffset) + " out of range (file " + std::to_string(size) +
                   " bytes) at byte offset " + std::to_string(footerAt));

  // The metadata must tile [metaOffset, footer) exactly, section by section.
  uint64_t metaSize = footerAt - h.metaOffset;
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
  if (expect != footerAt)
    failCorrupt(path, "index section is " + std::to_string(metaSize) + " bytes, header describes " +
                   std::to_string(expect - h.metaOffset) + " (truncated or damaged)");

  std::vector<uint8_t> meta(static_cast<size_t>(metaSize));
  if (metaSize) preadExact(r->fd_, path, h.metaOffset, size_t(metaSize), meta.data());
  XXH64_state_t* st = XXH64_createState();
  XXH64_reset(st, 0);
  XXH64_update(st, &h, sizeof h);
  XXH64_update(st, meta.data(), meta.size());
  uint64_t sum = XXH64_digest(st);
  XXH64_freeState(st);
  if (sum != f.checksum)
    failCorrupt(path, "checksum mismatch over header + DAG + index (bytes 0-" + std::to_string(kHeaderSize) + " and " +
                   std::to_string(h.metaOffset) + "-" + std::to_string(footerAt) + ")");

  auto take = [&](uint64_t off, auto* dst, uint64_t count) {
    using T = std::remove_pointer_t<decltype(dst)>;
    dst->resize(size_t(count));
    if (count) std::memcpy(dst->data(), meta.data() + (off - h.metaOffset), size_t(count) * sizeof(typename T::value_type));
  };
  take(h.nodesOffset, &r->nodes_, h.nodeCount);
  take(h.arcsOffset, &r->arcs_, h.arcCount);
  take(h.backArcsOffset, &r->backArcs_, h.arcCount);
  take(h.patchRefsOffset, &r->patchRefs_, h.patchRefCount);
  take(h.patchesOffset, &r->patches_, h.patchCount);

  // Cross-checks: a valid checksum says the writer wrote it, these say the writer was right.
  if (h.codec != uint32_t(Codec::Meshopt) && h.codec != uint32_t(Codec::Draco))
    failCorrupt(path, "unknown codec " + std::to_string(h.codec) + " in header");
  if (h.payloadAlignment == 0 || (h.payloadAlignment & (h.payloadAlignment - 1)))
    failCorrupt(path, "bad payload alignment in header");
  if (!(h.gridStep > 0) || h.gridBits == 0 || h.gridBits > 31) failCorrupt(path, "bad quantization grid in header");
  for (size_t i = 0; i < r->patches_.size(); ++i) {
    const PatchRecord& p = r->patches_[i];
    if (p.offset < kHeaderSize || p.offset % h.payloadAlignment || p.offset + p.size > h.metaOffset ||
        p.offset + p.size < p.offset)
      failCorrupt(path, "patch " + std::to_string(i) + ": payload at byte offset " + std::to_string(p.offset) + " size " +
                     std::to_string(p.size) + " outside the payload area");
    if (p.arc >= h.arcCount) failCorrupt(path, "patch " + std::to_string(i) + ": arc " + std::to_string(p.arc) + " out of range");
  }
  for (size_t i = 0; i < r->arcs_.size(); ++i) {
    const ArcRecord& a = r->arcs_[i];
    if (a.from >= h.nodeCount || a.to >= h.nodeCount || uint64_t(a.firstPatchRef) + a.patchCount > h.patchRefCount)
      failCorrupt(path, "arc " + std::to_string(i) + " out of range");
    for (uint32_t k = 0; k < a.patchCount; ++k)
      if (r->patchRefs_[a.firstPatchRef + k] >= h.patchCount)
        failCorrupt(path, "arc " + std::to_string(i) + " names patch out of range");
  }
  for (uint32_t b : r->backArcs_)
    if (b >= h.arcCount) failCorrupt(path, "backward star names arc out of range");
  for (size_t i = 0; i < r->nodes_.size(); ++i) {
    const NodeRecord& n = r->nodes_[i];
    if (uint64_t(n.firstArc) + n.arcCount > h.arcCount || uint64_t(n.firstBackArc) + n.backArcCount > h.arcCount)
      failCorrupt(path, "node " + std::to_string(i) + ": arc range out of bounds");
    for (uint32_t k = 0; k < n.arcCount; ++k)
      if (r->arcs_[n.firstArc + k].from != i) failCorrupt(path, "node " + std::to_string(i) + ": forward star inconsistent");
    for (uint32_t k = 0; k < n.backArcCount; ++k)
      if (r->arcs_[r->backArcs_[n.firstBackArc + k]].to != i)
        failCorrupt(path, "node " + std::to_string(i) + ": backward star inconsistent");
  }
  return r;
}

MtFileReader::~MtFileReader() {
  if (fd_ >= 0) ::close(fd_);
}

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
  std::vector<uint8_t> data(p.size);
  preadExact(fd_, path_, p.offset, p.size, data.data());
  if (XXH64(data.data(), data.size(), 0) != p.checksum)
    failCorrupt(path_, "patch " + std::to_string(patch) + " is damaged: checksum mismatch in payload at byte offset " +
                    std::to_string(p.offset) + " (" + std::to_string(p.size) + " bytes)");
  return data;
}

DecodedPatch MtFileReader::readPatch(uint32_t patch) const {
  std::vector<uint8_t> data = readPayload(patch);
  try {
    DecodedPatch d = decodePatch(data.data(), data.size(), codec(), grid());
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
