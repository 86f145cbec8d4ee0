// The level loop's checkpoints (see LevelBuilder in build.h) and the fingerprint a resume must
// match: the input's identity and every option that changes the bytes.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <xxhash.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <sstream>

#include "base/byte_io.h"
#include "base/env.h"
#include "mtbuild/level_state.h"
#include "mtbuild/work_dir.h"

namespace mt {

namespace {

namespace fs = std::filesystem;

// The modification time as "2026-12-02 05:27:00.123456789 UTC".
std::string utcTime(const struct timespec& t) {
  struct tm tm {};
  time_t sec = t.tv_sec;
  gmtime_r(&sec, &tm);
  char buf[64], out[96];
  std::strftime(buf, sizeof buf, "%Y-%m-%d %H:%M:%S", &tm);
  std::snprintf(out, sizeof out, "%s.%09ld UTC", buf, long(t.tv_nsec));
  return out;
}

// XXH3-64 of the whole file, streamed through an 8 MiB buffer (a 1 GB PLY: see docs/mtbuild.md).
uint64_t hashFile(const std::string& path) {
  int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) fail(path, std::string("cannot open: ") + std::strerror(errno));
  ::posix_fadvise(fd, 0, 0, POSIX_FADV_SEQUENTIAL);
  XXH3_state_t* state = XXH3_createState();
  XXH3_64bits_reset(state);
  std::vector<char> buf(8 << 20);
  uint64_t at = 0;
  for (;;) {
    ssize_t n = ::read(fd, buf.data(), buf.size());
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      std::string why = std::strerror(errno);
      XXH3_freeState(state);
      ::close(fd);
      fail(path, "read failed at byte offset " + std::to_string(at) + ": " + why);
    }
    if (n == 0) break;
    XXH3_64bits_update(state, buf.data(), size_t(n));
    at += uint64_t(n);
  }
  uint64_t h = XXH3_64bits_digest(state);
  XXH3_freeState(state);
  ::close(fd);
  return h;
}

struct ProducerEntry {
  PatchId patch;
  uint32_t node;
};

template <class T>
void putVector(ByteWriter& w, const std::vector<T>& v) {
  w.put<uint64_t>(v.size());
  if (!v.empty()) w.putRaw(v.data(), v.size() * sizeof(T));
}
template <class T>
std::vector<T> getVector(ByteReader& r) {
  uint64_t n = r.get<uint64_t>();
  if (n > (uint64_t(1) << 40) / sizeof(T)) fail("checkpoint", "vector of " + std::to_string(n) + " elements");
  std::vector<T> v(n);
  if (n) std::memcpy(v.data(), r.getRaw(n * sizeof(T)), n * sizeof(T));
  return v;
}

}  // namespace

std::string fingerprint(const std::string& input, const BuildOptions& o, bool storeInput) {
  std::ostringstream s;
  std::error_code ec;
  s << "format=" << format::kVersion << "." << kCheckpointVersion << "\n";
  s << "input=" << fs::weakly_canonical(input, ec).string() << "\n";
  if (storeInput) {
    uint64_t h = 0;
    std::vector<std::pair<std::string, uint64_t>> files;
    for (auto it = fs::recursive_directory_iterator(input, ec); !ec && it != fs::recursive_directory_iterator(); it.increment(ec))
      if (it->is_regular_file(ec)) files.push_back({fs::relative(it->path(), input, ec).string(), it->file_size(ec)});
    std::sort(files.begin(), files.end());
    for (auto& [name, size] : files) {
      h = XXH64(name.data(), name.size(), h);
      h = XXH64(&size, sizeof size, h);
    }
    std::string current;
    if (FILE* f = std::fopen((input + "/CURRENT").c_str(), "rb")) {
      char buf[256];
      size_t n = std::fread(buf, 1, sizeof buf, f);
      current.assign(buf, n);
      std::fclose(f);
    }
    s << "input_store_files=" << files.size() << "\ninput_store_hash=" << std::hex << XXH64(current.data(), current.size(), h)
      << std::dec << "\n";
  } else {
    // Size, modification time (readable, for a refused resume's message) and a hash of every
    // byte: an edit anywhere is caught, even one that kept the size and restored the mtime.
    struct stat st {};
    if (::stat(input.c_str(), &st) != 0) fail(input, std::string("cannot stat: ") + std::strerror(errno));
    s << "input_size=" << uint64_t(st.st_size) << "\ninput_mtime=" << utcTime(st.st_mtim) << "\ninput_hash=" << std::hex
      << hashFile(input) << std::dec << "\n";
  }
  s << "partition=" << (o.partition == PartitionKind::Regular ? "regular" : "irregular") << "\n";
  s << "patch_triangles=" << o.patchTriangles << "\n";
  s << "codec=" << (o.codec == format::Codec::Draco ? "draco" : "meshopt") << "\n";
  s << "index_order=" << (o.strips ? "strip" : "list") << "\n";
  s << "normals=" << (o.normals ? 1 : 0) << "\n";
  s << "simplifier=" << (o.simplifierByInput ? "auto" : o.simplifier == RegionSimplifier::Meshopt ? "meshopt" : "quadric") << "\n";
  if (o.colorWeight != kDefaultColorWeight) s << "color_weight=" << o.colorWeight << "\n";
  s << "root_triangles=" << o.rootTriangles << "\n";
  s << "texture_quality=" << o.textureQuality << "\n";
  // A mesh input's partition takes the option (0 is 2); a store's has its own ratio, in its bytes
  // above, and mtbuild refuses another before it resumes (requireStoreLevelRatio). The last line,
  // so a checkpoint written before it existed is refused naming it.
  if (!storeInput) s << "level_ratio=" << (o.levelRatio ? o.levelRatio : kDefaultLevelRatio) << "\n";
  return s.str();
}

std::string fingerprintDifference(const std::string& saved, const std::string& now) {
  std::istringstream a(saved), b(now);
  std::string la, lb;
  while (true) {
    bool ga = bool(std::getline(a, la)), gb = bool(std::getline(b, lb));
    if (!ga && !gb) return "";
    if (la != lb || ga != gb) {
      std::string key = la.substr(0, la.find('='));
      if (key.empty()) key = lb.substr(0, lb.find('='));
      auto value = [](const std::string& l) { return l.find('=') == std::string::npos ? std::string("?") : l.substr(l.find('=') + 1); };
      return key + " was " + value(la) + " for the killed build, is " + value(lb) + " now";
    }
  }
}

// The checkpoint is split in two so that it costs little memory and disk at any scale: what only
// grows (patch records, DAG nodes and spheres, arcs) is appended level by level to the side file
// OUT.work/checkpoint.dat, made durable before the store's commit; the store blob (committed with
// the level's write-backs) holds the small state, the producer map of the live patches, and the
// side file's length and chained XXH64 at that level. A resume reads the side file up to that
// length, so a chunk appended by a level that never committed is ignored and cut off.
std::string LevelBuilder::State::checkpointBytes() const {
  ByteWriter w;
  w.put<uint64_t>(kCheckpointMagic);
  w.put<uint32_t>(kCheckpointVersion);
  w.putString(fingerprint);
  w.put<uint32_t>(builtLevels);
  w.put<uint8_t>(finished ? 1 : 0);
  w.put<uint64_t>(liveTriangles);
  w.put(header);
  w.put<uint64_t>(writer->bytesWritten());
  w.put<uint64_t>(writer->patchCount());
  w.put<uint64_t>(nodes.size());
  w.put<uint64_t>(sideLength);
  w.put<uint64_t>(sideHash);
  std::vector<ProducerEntry> prod;
  for (auto& [id, node] : producer) prod.push_back({id, node});
  std::sort(prod.begin(), prod.end(), [](const ProducerEntry& a, const ProducerEntry& b) { return a.patch < b.patch; });
  putVector(w, prod);
  w.put<uint64_t>(report.inputTriangles);
  w.put<double>(report.gridStep);
  w.put<double>(report.ingestSeconds);
  w.put<double>(report.ingestUserSeconds);
  w.put<double>(report.ingestSysSeconds);
  w.put<uint64_t>(report.peakTempBytes);
  putVector(w, report.levels);
  w.put<uint64_t>(XXH64(w.bytes().data(), w.bytes().size(), 0));
  return w.bytes();
}

// Appends what grew since the last checkpoint to the side file and makes it durable.
void LevelBuilder::State::appendSideChunk() {
  ByteWriter w;
  const auto& records = writer->patchRecords();
  std::vector<format::PatchRecord> newRecords(records.begin() + long(ckPatches), records.end());
  putVector(w, newRecords);
  if (writer->textured()) {
    const auto& textures = writer->textureRecords();
    putVector(w, std::vector<format::TextureRecord>(textures.begin() + long(ckPatches), textures.end()));
  }
  putVector(w, std::vector<format::NodeRecord>(nodes.begin() + long(ckNodes), nodes.end()));
  putVector(w, std::vector<Sphere>(spheres.begin() + long(ckNodes), spheres.end()));
  uint64_t arcs = 0;
  for (auto& [key, ids] : arcPatches) arcs += key.second >= ckNodes;
  w.put<uint64_t>(arcs);
  for (auto& [key, ids] : arcPatches)
    if (key.second >= ckNodes) {
      w.put<uint32_t>(key.first);
      w.put<uint32_t>(key.second);
      putVector(w, ids);
    }
  ByteWriter chunk;
  chunk.put<uint64_t>(w.bytes().size());
  chunk.putRaw(w.bytes().data(), w.bytes().size());
  const std::string path = work + "/checkpoint.dat";
  // Cut off a chunk of a level that was never committed, then append; Io errors name the file and
  // the byte offset.
  std::unique_ptr<WritableFile> file = Env::Default()->newWritableFileAt(path, sideLength);
  file->append(chunk.bytes().data(), chunk.bytes().size());
  file->sync();
  file->close();
  sideHash = XXH64(chunk.bytes().data(), chunk.bytes().size(), sideHash);
  sideLength += chunk.bytes().size();
  ckPatches = records.size();
  ckNodes = nodes.size();
}

// Reads the side file up to `length`, checking the chained hash; fills records, nodes, spheres, arcs.
std::vector<format::PatchRecord> LevelBuilder::State::readSideFile(uint64_t length, uint64_t hash,
                                                                   std::vector<format::TextureRecord>& textures) {
  const bool textured = (header.vertexFlags & format::kHasTextures) != 0;
  const std::string path = work + "/checkpoint.dat";
  std::vector<format::PatchRecord> records;
  Env* env = Env::Default();
  if (!env->exists(path)) fail(path, "cannot --resume: missing (rerun without --resume to start over)");
  std::unique_ptr<RandomAccessFile> f = env->newRandomAccessFile(path);
  const uint64_t fileBytes = f->size();
  uint64_t at = 0, h = 0;  // at <= fileBytes: only whole chunks are passed
  std::string chunk;
  while (at < length) {
    const std::string truncated = "cannot --resume: chunk at byte offset " + std::to_string(at) + " is truncated";
    uint64_t size = 0;
    if (length - at < 8 || fileBytes - at < 8) fail(path, truncated + " (rerun without --resume to start over)");
    f->read(at, 8, &size);
    if (size > length - at - 8) fail(path, truncated + " (rerun without --resume to start over)");
    if (size > fileBytes - at - 8) fail(path, truncated);
    chunk.resize(size_t(size) + 8);
    std::memcpy(chunk.data(), &size, 8);
    if (size) f->read(at + 8, size_t(size), chunk.data() + 8);
    h = XXH64(chunk.data(), chunk.size(), h);
    ByteReader r(chunk.data() + 8, size_t(size), path, at + 8);
    for (auto& rec : getVector<format::PatchRecord>(r)) records.push_back(rec);
    if (textured)
      for (auto& rec : getVector<format::TextureRecord>(r)) textures.push_back(rec);
    for (auto& n : getVector<format::NodeRecord>(r)) nodes.push_back(n);
    for (auto& sp : getVector<Sphere>(r)) spheres.push_back(sp);
    uint64_t arcs = r.get<uint64_t>();
    for (uint64_t i = 0; i < arcs; ++i) {
      uint32_t from = r.get<uint32_t>(), to = r.get<uint32_t>();
      arcPatches[{from, to}] = getVector<uint32_t>(r);
    }
    at += chunk.size();
  }
  if (h != hash) fail(path, "cannot --resume: checksum mismatch before byte offset " + std::to_string(length) + " (rerun without --resume to start over)");
  sideLength = length;
  sideHash = hash;
  return records;
}

void LevelBuilder::State::restore(const std::string& bytes) {
  const std::string where = storeDir + " (blob " + kCheckpointBlob + ")";
  if (bytes.size() < 8 || XXH64(bytes.data(), bytes.size() - 8, 0) != [&] {
        uint64_t h;
        std::memcpy(&h, bytes.data() + bytes.size() - 8, 8);
        return h;
      }())
    fail(where, "checkpoint checksum mismatch (rerun without --resume to start over)");
  ByteReader r(bytes, where);
  if (r.get<uint64_t>() != kCheckpointMagic) fail(where, "not a checkpoint (bad magic at byte offset 0)");
  if (uint32_t v = r.get<uint32_t>(); v != kCheckpointVersion)
    fail(where, "checkpoint version " + std::to_string(v) + ", this build reads " + std::to_string(kCheckpointVersion));
  std::string saved = r.getString();
  if (saved != fingerprint)
    fail(work, "cannot --resume: the killed build used other input or options (" + fingerprintDifference(saved, fingerprint) +
                   "); rerun without --resume to start over");
  builtLevels = r.get<uint32_t>();
  finished = r.get<uint8_t>() != 0;
  liveTriangles = r.get<uint64_t>();
  header = r.get<format::FileHeader>();
  report.weldedVertices = header.weldedVertices;
  report.weldedTriangles = header.weldedTriangles;
  uint64_t length = r.get<uint64_t>();
  uint64_t patchCount = r.get<uint64_t>(), nodeCount = r.get<uint64_t>();
  uint64_t sideLen = r.get<uint64_t>(), sideH = r.get<uint64_t>();
  for (const ProducerEntry& e : getVector<ProducerEntry>(r)) producer[e.patch] = e.node;
  report.inputTriangles = r.get<uint64_t>();
  report.gridStep = r.get<double>();
  report.ingestSeconds = r.get<double>();
  report.ingestUserSeconds = r.get<double>();
  report.ingestSysSeconds = r.get<double>();
  report.peakTempBytes = r.get<uint64_t>();
  report.levels = getVector<LevelReport>(r);
  std::vector<format::TextureRecord> textures;
  std::vector<format::PatchRecord> records = readSideFile(sideLen, sideH, textures);
  if (records.size() != patchCount || nodes.size() != nodeCount || nodes.size() != spheres.size() || nodes.empty())
    fail(where, "checkpoint and " + work + "/checkpoint.dat disagree (rerun without --resume to start over)");
  ckPatches = records.size();
  ckNodes = nodes.size();
  for (PatchId id : store->patchIds())
    if (!producer.count(id)) fail(where, "checkpoint does not know live patch " + std::to_string(id));
  if (producer.size() != store->patchIds().size()) fail(where, "checkpoint names patches the store does not hold");
  writer = std::make_unique<MtFileWriter>(output, header, length, std::move(records), tempPath, Env::Default(), std::move(textures));
}

void LevelBuilder::State::writeCheckpoint() {
  // Payloads and the side file first: the checkpoint may only name bytes that are on disk. The
  // store then commits the level's write-backs and the checkpoint blob in one manifest edit
  // (store_format.h), so a kill at any point leaves either the previous level's state or this
  // one's, never a mix.
  writer->syncPayloads();
  appendSideChunk();
  std::string bytes = checkpointBytes();
  report.checkpointBytes = std::max<uint64_t>(report.checkpointBytes, bytes.size());
  store->putBlob(kCheckpointBlob, bytes);
  store->sync();
  report.peakTempBytes = std::max(report.peakTempBytes, treeBytes(work) + treeBytes(tempPath));
}

}  // namespace mt
