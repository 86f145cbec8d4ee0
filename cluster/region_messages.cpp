// Region messages (see region_messages.h): flat vectors back to back, a magic per kind and an
// XXH64 of the body so a torn or mixed-up message is an error, not a wrong file.
#include "cluster/region_messages.h"

#include <xxhash.h>

#include <cstring>

#include "base/byte_io.h"

namespace mt::cluster {

namespace {

constexpr uint32_t kContextMagic = 0x5843544d;  // "MTCX"
constexpr uint32_t kTaskMagic = 0x4b54544d;     // "MTTK"
constexpr uint32_t kResultMagic = 0x5352544d;   // "MTRS"

template <class T>
void putVector(ByteWriter& w, const std::vector<T>& v) {
  static_assert(std::is_trivially_copyable_v<T>);
  w.put<uint64_t>(v.size());
  if (!v.empty()) w.putRaw(v.data(), v.size() * sizeof(T));
}

template <class T>
void getVector(ByteReader& r, std::vector<T>& v, size_t limit) {
  uint64_t n = r.get<uint64_t>();
  if (n > limit / sizeof(T)) fail("message", "vector of " + std::to_string(n) + " elements exceeds the message");
  v.resize(size_t(n));
  if (n) std::memcpy(v.data(), r.getRaw(size_t(n) * sizeof(T)), size_t(n) * sizeof(T));
}

std::string seal(ByteWriter& w) {
  uint64_t h = XXH64(w.bytes().data(), w.bytes().size(), 0);
  w.put(h);
  return std::move(w.bytes());
}

// Checks magic and checksum; returns a reader over the body.
ByteReader open(const std::string& bytes, uint32_t magic, const char* what) {
  if (bytes.size() < 12) fail(what, "message of " + std::to_string(bytes.size()) + " bytes is truncated");
  uint64_t h;
  std::memcpy(&h, bytes.data() + bytes.size() - 8, 8);
  if (XXH64(bytes.data(), bytes.size() - 8, 0) != h) fail(what, "message checksum mismatch");
  ByteReader r(bytes.data(), bytes.size() - 8, what);
  if (r.get<uint32_t>() != magic) fail(what, "wrong message kind at byte offset 0");
  return r;
}

}  // namespace

std::string encodeContext(const RegionContext& c, const std::string& sequenceBytes) {
  ByteWriter w;
  w.put(kContextMagic);
  w.put(c.grid);
  w.put(c.codec);
  w.put(c.partitionLevels);
  w.put(c.rootTriangles);
  w.put(c.simplifier);
  w.put(c.colorWeight);
  w.putString(sequenceBytes);
  return seal(w);
}

void decodeContext(const std::string& bytes, WorkerContext& out) {
  ByteReader r = open(bytes, kContextMagic, "context message");
  out.context.grid = r.get<QuantizationGrid>();
  out.context.codec = r.get<PatchCodecOptions>();
  out.context.partitionLevels = r.get<uint32_t>();
  out.context.rootTriangles = r.get<uint64_t>();
  out.context.simplifier = r.get<RegionSimplifier>();
  out.context.colorWeight = r.get<double>();
  out.sequence = PartitionSequence::deserialize(r.getString());
  out.context.sequence = &out.sequence;
}

std::string encodeTask(uint64_t index, const RegionTask& t) {
  ByteWriter w;
  w.put(kTaskMagic);
  w.put(index);
  w.put(t.level);
  w.put(t.region);
  w.put<uint8_t>(t.root ? 1 : 0);
  w.put(t.rootDeviationLimit);
  w.put(t.loadSeconds);
  const LoadedMesh& m = t.mesh;
  putVector(w, m.patches);
  putVector(w, m.positions);
  putVector(w, m.normals);
  putVector(w, m.colors);
  putVector(w, m.triangles);
  putVector(w, m.trianglePatch);
  putVector(w, m.locked);
  w.put<uint64_t>(m.unifiedOf.size());
  for (const auto& u : m.unifiedOf) putVector(w, u);
  // (m.external stays on rank 0: writeBack re-reads it there; processRegion needs only `locked`.)
  return seal(w);
}

RegionTask decodeTask(const std::string& bytes, uint64_t& index) {
  ByteReader r = open(bytes, kTaskMagic, "task message");
  RegionTask t;
  index = r.get<uint64_t>();
  t.level = r.get<uint32_t>();
  t.region = r.get<uint32_t>();
  t.root = r.get<uint8_t>() != 0;
  t.rootDeviationLimit = r.get<double>();
  t.loadSeconds = r.get<double>();
  LoadedMesh& m = t.mesh;
  const size_t n = bytes.size();
  getVector(r, m.patches, n);
  getVector(r, m.positions, n);
  getVector(r, m.normals, n);
  getVector(r, m.colors, n);
  getVector(r, m.triangles, n);
  getVector(r, m.trianglePatch, n);
  getVector(r, m.locked, n);
  uint64_t maps = r.get<uint64_t>();
  if (maps != m.patches.size()) fail("task message", "vertex maps do not match the patch count");
  m.unifiedOf.resize(size_t(maps));
  for (auto& u : m.unifiedOf) getVector(r, u, n);
  if (!r.atEnd()) fail("task message", "trailing bytes at byte offset " + std::to_string(r.position()));
  return t;
}

std::string encodeResult(uint64_t index, const RegionResult& res) {
  ByteWriter w;
  w.put(kResultMagic);
  w.put(index);
  w.put<uint64_t>(res.encoded.size());
  for (const EncodedPatch& e : res.encoded) {
    w.put(e.storeId);
    w.put(e.triangles);
    w.put(e.vertices);
    putVector(w, e.payload);
  }
  const ReplacementMesh& m = res.replacement;
  putVector(w, m.positions);
  putVector(w, m.normals);
  putVector(w, m.colors);
  putVector(w, m.triangles);
  putVector(w, m.origin);
  putVector(w, m.triangleCell);
  w.put(m.level);
  w.put(res.deviation);
  w.put(res.colorDeviation);
  w.put(res.sphere);
  w.put(res.coneAxis);
  w.put(res.coneCutoff);
  w.put(res.seconds);
  w.put(res.simplifierRuns);
  return seal(w);
}

RegionResult decodeResult(const std::string& bytes, uint64_t& index) {
  ByteReader r = open(bytes, kResultMagic, "result message");
  RegionResult res;
  const size_t n = bytes.size();
  index = r.get<uint64_t>();
  uint64_t patches = r.get<uint64_t>();
  if (patches > n) fail("result message", "bad patch count");
  res.encoded.resize(size_t(patches));
  for (EncodedPatch& e : res.encoded) {
    e.storeId = r.get<PatchId>();
    e.triangles = r.get<uint32_t>();
    e.vertices = r.get<uint32_t>();
    getVector(r, e.payload, n);
  }
  ReplacementMesh& m = res.replacement;
  getVector(r, m.positions, n);
  getVector(r, m.normals, n);
  getVector(r, m.colors, n);
  getVector(r, m.triangles, n);
  getVector(r, m.origin, n);
  getVector(r, m.triangleCell, n);
  m.level = r.get<uint32_t>();
  res.deviation = r.get<double>();
  res.colorDeviation = r.get<double>();
  std::memcpy(res.sphere, r.getRaw(sizeof res.sphere), sizeof res.sphere);
  std::memcpy(res.coneAxis, r.getRaw(sizeof res.coneAxis), sizeof res.coneAxis);
  res.coneCutoff = r.get<float>();
  res.seconds = r.get<double>();
  res.simplifierRuns = r.get<uint32_t>();
  if (!r.atEnd()) fail("result message", "trailing bytes at byte offset " + std::to_string(r.position()));
  return res;
}

}  // namespace mt::cluster
