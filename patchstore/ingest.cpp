// Ingest: a mesh file of any size into a new patch store, within the --memory cap.
//
// Memory depends on the cap, not on the input (BMT section 6 needs the store to exist before
// anything fits in RAM). Two paths give the same store byte for byte:
//
// Resident path, when the vertex records (one state byte and a bit per thread per vertex, and a
// reserve of max(128 MiB, cap/4)) fit in the cap (a 53 M-triangle scan at 512M): the records stay
// in RAM, so every pass that needs a position reads it directly instead of joining through an
// external sort. Faces are read from face.bin, or in place from a binary PLY of triangles.
//   1 parse      the reader on its own thread: vertex records in RAM, faces to a chunk queue (and
//                face.bin unless read in place); the main thread's pipeline computes the
//                (Morton code, face) of every chunk in parallel into a stable radix sort (12 bytes
//                a face, runs spilled by a background task)
//   2 sample     the merge of the runs, in key ranges on parallel threads, picks every stride-th
//                face (the irregular V-partition's sample, CentroidSource::sample); one more read
//                of the faces gives their centroids. An assigner that wants the whole stream (grid,
//                regular) gets it materialized.
//   3 assign     faces in face order -> centroid -> cell key (a shuffled order: looked up in
//                batch-local Morton order); corners grouped by key (KeyGroupSorter: counting-sorted
//                runs, whole groups merged, faces staying in face order)
//   4 shared     one pass over the groups marks the vertices held by two or more patches
//   5 patches    a second pass builds every patch (local order = ascending input index) with
//                positions read from RAM, in parallel, appended in order; shared vertices ->
//                (vertex, patch, local); edge use counts
// Chunked path, otherwise (bounded by the cap whatever the input size): the positions do not fit,
// so every pass that needs them joins each face with its corners' positions (FaceJoin,
// ingest_join.h: a sweep in face order with two windows of positions, then buckets of vertex
// chunks for the faces the windows missed). A binary PLY's vertex and face records are read in
// place (no vert.bin, no face.bin) when their layout allows.
//   1 parse      input -> bounding box, counts (and vert.bin, face.bin unless read in place)
//   2 morton     join: (Morton code, face) of every face into a stable radix sort (12 bytes a face)
//   3 sample     the sort merged in key ranges on parallel threads picks every stride-th face in
//                (code, face) order; a join of the picked faces alone gives their centroids
//                (an assigner that streams every centroid gets the stream materialized)
//   4 assign     join: every face's cell key; faces grouped by key (KeyGroupSorter, put back in
//                face order within a group)
//   5 group      first pass over the groups: patches 0..P-1; unique (vertex, patch) pairs sorted
//                by vertex; merge-joined with the vertex records -> (patch, vertex, data) sorted
//                by patch
//   6 patches    second pass over the groups: one geometry block per patch (local order =
//                ascending input index); shared vertices -> (vertex, patch, local) sorted by
//                vertex; edge use counts
// Scratch files read once are given back to the file system as they are read (hole punching),
// so the peak is about the unread part of the data in flight, not all of it.
// Both paths end with
//   7 boundary   grouped by vertex -> (p, vp, q, vq) sorted by p -> one boundary block per patch
//
// The rooms: this file is the driver (build) and the common stages (7 boundary, the commit);
// ingest_parse.cpp stage 1; ingest_resident.cpp and ingest_chunked.cpp the two paths (ingest_join.h
// the chunked path's join);
// ingest_internal.h what they share.
#include <malloc.h>
#include <signal.h>
#include <tbb/task_arena.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <filesystem>
#include <sstream>

#include "base/file_lock.h"
#include "base/output_path.h"
#include "patchstore/ingest_internal.h"
#include "patchstore/store_textures.h"

namespace mt {
namespace ingest {
namespace {

namespace fs = std::filesystem;

std::string encodeReport(const IngestReport& r) {
  std::ostringstream s;
  s << "input=" << r.input << "\nformat=" << r.format << "\ninputVertices=" << r.inputVertices
    << "\ninputTriangles=" << r.inputTriangles << "\ninputBytes=" << r.inputBytes << "\npolygons=" << r.polygons
    << "\ndegenerateTriangles=" << r.degenerateTriangles << "\nduplicateTriangles=" << r.duplicateTriangles
    << "\nunreferencedVertices=" << r.unreferencedVertices << "\nnonManifoldEdges=" << r.nonManifoldEdges
    << "\nweldedVertices=" << r.weldedVertices << "\nassigner=" << r.assigner << "\nseconds=" << r.seconds
    << "\npeakBytes=" << r.peakBytes << "\n";
  return s.str();
}
// Edges shared between patches: their uses summed over the patches that hold them; an edge used
// more than twice is non-manifold.
uint64_t countCrossEdges(EdgeSorter& edges) {
  checkInterrupt("ingest: sort");
  edges.finish();
  uint64_t nonManifold = 0;
  EdgeRec e;
  bool have = edges.next(e);
  while (have) {
    uint64_t key = e.key;
    uint32_t count = 0;
    while (have && e.key == key) {
      count += e.count;
      have = edges.next(e);
    }
    if (count > 2) ++nonManifold;
  }
  return nonManifold;
}

// Stage 7: shared vertices grouped by vertex -> (p, vp, q, vq) sorted by p -> one boundary block
// per patch.
void boundaryStage(IngestContext& ctx, PatchStageOutput& patches) {
  const uint32_t P = uint32_t(patches.patchKey.size());
  SharedSorter& shared = *patches.shared;
  checkInterrupt("ingest: sort");
  shared.finish();
  // The entries' sorter gets what the V-partition, the patch records and the shared-vertex
  // merge leave of the cap (MemoryPlan::boundarySorterBesides), measured with the heap trimmed.
  malloc_trim(0);
  EntrySorter entries(ctx.scratch + "/s6", ctx.plan.boundarySorterBesides(currentRssBytes()));
  {
    LocalRec r;
    bool have = shared.next(r);
    std::vector<std::pair<uint32_t, uint32_t>> group;  // (patch, local)
    while (have) {
      uint32_t v = uint32_t(r.key >> 32);
      group.clear();
      while (have && uint32_t(r.key >> 32) == v) {
        group.push_back({uint32_t(r.key), r.local});
        have = shared.next(r);
      }
      // The group is in ascending patch order (the key's low half), so each (patch, local)
      // key gets its entries here, consecutively, by ascending neighbour.
      for (auto& a : group)
        for (auto& b : group)
          if (a.first != b.first) entries.add({uint64_t(a.first) << 32 | a.second, b.first, b.second});
    }
  }
  checkInterrupt("ingest: sort");
  entries.finish();
  EntryRec e;
  bool have = entries.next(e);
  std::vector<BoundaryEntry> list;
  for (uint32_t k = 0; k < P; ++k) {
    list.clear();
    while (have && uint32_t(e.key >> 32) == k) {
      list.push_back({uint32_t(e.key), e.neighbour, e.remote});
      have = entries.next(e);
    }
    assert(std::is_sorted(list.begin(), list.end()));  // sorted by (local, neighbour, remote)
    PatchRecord& rec = ctx.impl.patches[k];
    rec.boundary = ctx.impl.appendBlock(encodeBoundary(list));
    rec.meta.boundaryEntries = uint32_t(list.size());
  }
  assert(!have);  // every entry names a patch in range
  ctx.clock.mark("boundary");
}

// Commit: segment durable, then the first manifest and CURRENT.
void commit(IngestContext& ctx, uint32_t patches, double seconds) {
  PatchStore::Impl& impl = ctx.impl;
  impl.nextPatchId = patches;
  for (auto& [id, rec] : impl.patches) impl.addLive(rec, +1);
  ctx.report.seconds = seconds;
  ctx.report.peakBytes = peakRssBytes();
  impl.blobs["ingest"] = encodeReport(ctx.report);
  std::string assignerBytes = ctx.assigner.serialize();
  if (!assignerBytes.empty()) impl.blobs["assigner"] = assignerBytes;
  impl.activeWriter->sync();
  impl.activeWriter->close();
  impl.activeWriter.reset();
  impl.writeNewManifest();
}

// The main ingest body, building the store in `dir` (already created, empty).
IngestReport build(const std::string& input, const std::string& dir, const std::string& scratch, CellAssigner& assigner,
                   const IngestOptions& opt, Env* env) {
  using Clock = std::chrono::steady_clock;
  auto t0 = Clock::now();
  IngestReport report;
  report.input = input;
  // The cap is about RSS: multi-MiB buffers in their own mappings, small ones kept for reuse
  // (patch_store.h); malloc_trim at the end of each pass returns the rest.
  useStreamingAllocator();
  StageClock clock(opt.progress);
  auto impl = std::make_unique<PatchStore::Impl>();
  // Every buffer's share of the cap (base/memory_plan.h).
  const MemoryPlan plan = planMemory(opt.memoryBytes, unsigned(std::max(1, tbb::this_task_arena::max_concurrency())));
  IngestContext ctx{scratch, opt, plan, opt.progress, assigner, report, *impl, clock};
  ParsedInput in = parseInput(input, ctx);
  impl->env = env;
  impl->dir = dir;
  impl->layout = {in.layout.doublePrecision, in.layout.normals, in.layout.colors, in.layout.texcoords};
  impl->bounds = in.bounds;
  PatchStageOutput patches;
  if (in.resident)
    residentStages(ctx, in, patches);
  else if (in.layout.doublePrecision || in.layout.normals || in.layout.colors || in.layout.texcoords)
    chunkedStages<true>(ctx, in, patches);
  else
    chunkedStages<false>(ctx, in, patches);
  assert(patches.shared && patches.edges && impl->patches.size() == patches.patchKey.size());
  report.unreferencedVertices = in.vertices - patches.distinctReferenced - report.weldedVertices;
  report.nonManifoldEdges += countCrossEdges(*patches.edges);
  clock.mark("edges");
  boundaryStage(ctx, patches);
  if (in.layout.texcoords) {
    // The materials' images, tiled into the store (store_textures.h).
    impl->blobs[kMaterialsBlob] = encodeMaterials(tileTextures(in.materials, dir, opt.memoryBytes / 4, opt.progress, env));
    clock.mark("textures");
  }
  commit(ctx, uint32_t(patches.patchKey.size()), std::chrono::duration<double>(Clock::now() - t0).count());
  return report;
}

}  // namespace

uint64_t releaseAssignerLookups(IngestContext& ctx) {
  const uint64_t before = currentRssBytes();
  if (!ctx.options.keepAssignerLookups) ctx.assigner.releaseLookups();
  malloc_trim(0);
  return before - std::min(before, currentRssBytes());
}

}  // namespace ingest

namespace {

namespace fs = std::filesystem;

constexpr const char* kIngestLockName = "INGEST-LOCK";

// Folders `prefix`PID left in `folder` by an ingest that was killed: each holds the lock file
// kIngestLockName while its ingest runs, so one whose lock no process holds, and whose PID names
// no running process, is certainly dead (a folder without the lock file is never touched).
void removeDeadLeftovers(const std::string& folder, const std::string& prefix) {
  std::error_code ec;
  for (fs::directory_iterator it(folder.empty() ? "." : folder, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    if (name.size() <= prefix.size() || name.compare(0, prefix.size(), prefix) != 0) continue;
    const std::string digits = name.substr(prefix.size());
    if (digits.find_first_not_of("0123456789") != std::string::npos || digits.size() > 9) continue;
    const long pid = std::stol(digits);
    const std::string path = it->path().string(), lock = path + "/" + kIngestLockName;
    std::error_code e2;
    if (pid == long(getpid()) || !fs::is_directory(path, e2) || !fs::exists(lock, e2)) continue;
    if (FileLock::holder(lock) != 0 || ::kill(pid_t(pid), 0) == 0 || errno != ESRCH) continue;
    fs::remove_all(path, e2);
    if (!e2)
      std::fprintf(stderr, "ingest: removed %s, left by an ingest that was killed (process %ld is gone)\n", path.c_str(), pid);
  }
}

std::string parentOf(const std::string& path) {
  std::string parent = fs::path(path).parent_path().string();
  return parent.empty() ? "." : parent;
}

}  // namespace

IngestReport PatchStore::ingest(const std::string& input, const std::string& dirIn, CellAssigner& assigner,
                                const IngestOptions& options, Env* env) {
  std::string dir = dirIn;
  while (dir.size() > 1 && dir.back() == '/') dir.pop_back();
  // A directory, FIFO or device would block or be misread; say what it is.
  requireRegularFile(input, "a mesh file");
  // The store directory is made here and only here: an existing folder (even an empty one, which
  // may be a mount point or carry permissions) is the user's, never removed or replaced.
  if (fs::is_directory(dir))
    fail(dir, std::string(env->exists(dir + "/CURRENT") ? "is an existing patch store" : "is an existing folder") +
                  "; ingest creates the store directory itself: choose a name that does not exist (nothing was changed)");
  if (env->exists(dir)) fail(dir, "already exists (remove it or choose another store directory)");
  const std::string base = fs::path(dir).filename().string();
  removeDeadLeftovers(parentOf(dir), base + ".ingest-");
  if (!options.tempDir.empty()) removeDeadLeftovers(options.tempDir, "mt-ingest-");
  std::string building = dir + ".ingest-" + std::to_string(getpid());
  std::error_code ec;
  fs::remove_all(building, ec);  // our own PID: a leftover of a dead process that had it
  env->createDir(building);
  std::string scratch = options.tempDir.empty() ? building + "/tmp" : options.tempDir + "/mt-ingest-" + std::to_string(getpid());
  try {
    // Held while the folders are in use, so that another ingest knows they are not leftovers.
    auto buildingLock = std::make_unique<FileLock>(building + "/" + kIngestLockName, building);
    std::unique_ptr<FileLock> scratchLock;
    env->createDir(scratch);
    if (!options.tempDir.empty()) scratchLock = std::make_unique<FileLock>(scratch + "/" + kIngestLockName, scratch);
    IngestReport report = ingest::build(input, building, scratch, assigner, options, env);
    checkInterrupt("ingest");
    scratchLock.reset();
    fs::remove_all(scratch, ec);
    buildingLock.reset();  // removes the lock file: the store holds only its own files
    env->renameFile(building, dir);
    env->syncDir(parentOf(dir));
    return report;
  } catch (...) {
    fs::remove_all(scratch, ec);
    fs::remove_all(building, ec);
    throw;
  }
}

}  // namespace mt
