// Fault injection for every file a build writes: each write, fsync and rename that goes through
// the Env (the patch store of the work directory, the checkpoint side file, the MT file) fails in
// turn, on a small build, as a disk that fills up fails it (ENOSPC, with half of a failing write on
// disk): the message names the file, the exit code is 4 (base/exit_code.h), what is left under the
// output's name is nothing or the complete file, and --resume then gives the same bytes as a build
// that never failed. The same for the PLY, glTF and 3D Tiles outputs and for heal's updates.
#include <gtest/gtest.h>

#include <cerrno>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>

#include "base/env.h"
#include "base/error.h"
#include "base/exit_code.h"
#include "base/output_path.h"
#include "interop/gltf_writer.h"
#include "interop/tiles_export.h"
#include "mtbuild/build.h"
#include "mtbuild/work_dir.h"
#include "mtfile/mt_cut.h"
#include "mtfile/mt_file.h"
#include "patchstore/cell_assigner.h"
#include "patchstore/heal/heal.h"
#include "patchstore/io/ply_writer.h"
#include "patchstore/patch_store.h"
#include "test_support.h"

namespace fs = std::filesystem;
using mt::test::TempDir;
using mt::test::readFile;
using mt::test::writeFile;

namespace {

// A wavy 20 x 20 grid (722 triangles): small enough to build in a fraction of a second, large
// enough for three levels with 100-triangle patches. `degenerate` adds that many triangles with a
// repeated vertex (work for heal's --remove-degenerate).
std::string writeGrid(const TempDir& tmp, int degenerate = 0) {
  const int n = 20;
  std::ostringstream s;
  s << "OFF\n" << n * n << " " << 2 * (n - 1) * (n - 1) + degenerate << " 0\n";
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) s << x << " " << y << " " << 0.7 * std::sin(0.6 * x) * std::cos(0.45 * y) << "\n";
  for (int y = 0; y + 1 < n; ++y)
    for (int x = 0; x + 1 < n; ++x) {
      const int a = y * n + x, b = a + 1, c = a + n, d = c + 1;
      s << "3 " << a << " " << b << " " << d << "\n3 " << a << " " << d << " " << c << "\n";
    }
  for (int i = 0; i < degenerate; ++i) s << "3 " << 17 * i % (n * n) << " " << 17 * i % (n * n) << " " << (17 * i + 1) % (n * n) << "\n";
  const std::string path = tmp.file("grid.off");
  writeFile(path, s.str());
  return path;
}

mt::BuildOptions smallBuild() {
  mt::BuildOptions o;
  o.threads = 1;
  o.patchTriangles = 100;
  o.memoryBytes = 64ull << 20;
  o.progress = false;
  return o;
}

// Files beside `out` whose name starts with out's file name (the output, its temporary, its work
// directory, its lock).
std::vector<std::string> filesOf(const std::string& out) {
  std::vector<std::string> names;
  const std::string base = fs::path(out).filename().string();
  for (const auto& e : fs::directory_iterator(fs::path(out).parent_path()))
    if (e.path().filename().string().rfind(base, 0) == 0) names.push_back(e.path().filename().string());
  return names;
}

void removeOutputs(const std::string& out) {
  for (const std::string& name : filesOf(out)) fs::remove_all(fs::path(out).parent_path() / name);
}

// The face count of a PLY's header.
uint64_t facesOf(const std::string& ply) {
  const size_t at = ply.find("element face ");
  return at == std::string::npos ? 0 : std::stoull(ply.substr(at + 13));
}

const char* opName(mt::FaultInjectionEnv::Op op) {
  return op == mt::FaultInjectionEnv::Op::Write ? "write" : op == mt::FaultInjectionEnv::Op::Sync ? "fsync" : "rename";
}

}  // namespace

TEST(Faults, EveryWriteFsyncAndRenameOfABuildLeavesNothingOrTheWholeFileAndResumes) {
  TempDir tmp;
  const std::string input = writeGrid(tmp);
  const mt::BuildOptions options = smallBuild();
  mt::buildMt(input, tmp.file("ref.mt"), options);
  const std::string reference = readFile(tmp.file("ref.mt"));
  ASSERT_GT(reference.size(), 0u);

  // Count the operations of a whole build (the same build writes in the same order every time:
  // one thread, the same input and options).
  mt::FaultInjectionEnv env(mt::Env::Default());
  {
    mt::ScopedDefaultEnv scoped(&env);
    mt::buildMt(input, tmp.file("count.mt"), options);
  }
  EXPECT_EQ(readFile(tmp.file("count.mt")), reference);
  const int64_t counts[3] = {env.writes, env.syncs, env.renames};
  ASSERT_GT(counts[0], 10);
  ASSERT_GT(counts[1], 2);
  ASSERT_GT(counts[2], 0);

  const std::string out = tmp.file("out.mt");
  int injected = 0, resumedFromCheckpoint = 0, checkedFiles = 0;
  for (auto op : {mt::FaultInjectionEnv::Op::Write, mt::FaultInjectionEnv::Op::Sync, mt::FaultInjectionEnv::Op::Rename}) {
    const int64_t count = counts[int(op)];
    for (int64_t k = 1; k <= count; ++k) {
      SCOPED_TRACE(std::string(opName(op)) + " " + std::to_string(k) + " of " + std::to_string(count));
      removeOutputs(out);
      // A full disk: ENOSPC, with half of a failing write on disk.
      env.failAfter(op, k, ENOSPC, /*partial=*/true);
      bool failed = false;
      {
        mt::ScopedDefaultEnv scoped(&env);
        try {
          mt::buildMt(input, out, options);
        } catch (const mt::Error& e) {
          failed = true;
          const std::string message = e.what();
          EXPECT_NE(message.find("injected"), std::string::npos) << message;
          EXPECT_NE(message.find("No space left on device"), std::string::npos) << message;
          EXPECT_NE(message.find(tmp.path() + "/"), std::string::npos) << "names the file: " << message;
          EXPECT_EQ(mt::exitCodeFor(e), mt::kExitIo) << message;
        }
      }
      env.disarm();
      ASSERT_TRUE(env.fired());
      ASSERT_TRUE(failed);
      ++injected;
      // Nothing, or the whole file, under the final name.
      if (fs::exists(out)) {
        EXPECT_EQ(readFile(out), reference);
      }
      // Every file the failed build left for --resume (its work directory, its temporary output)
      // was written through the Env: no write of the build escapes this test.
      // (A file counts as written through the Env when it, or a directory above it, was opened or
      // renamed to through it: the ingest renames its finished store directory into place.)
      auto throughEnv = [&](fs::path p) {
        for (; p.has_relative_path(); p = p.parent_path())
          if (env.written.count(p.string())) return true;
        return false;
      };
      for (const std::string& name : filesOf(out)) {
        const fs::path p = fs::path(out).parent_path() / name;
        if (name == "out.mt.lock") continue;  // a lock: no data
        if (fs::is_regular_file(p)) {
          EXPECT_TRUE(throughEnv(p)) << p << " was not written through the Env";
        }
        if (fs::is_directory(p))
          for (const auto& e : fs::recursive_directory_iterator(p))
            if (e.is_regular_file() && e.path().filename() != mt::kWorkLock) {
              EXPECT_TRUE(throughEnv(e.path())) << e.path() << " was not written through the Env";
              ++checkedFiles;
            }
      }
      // --resume (from the checkpoint, or from the input when there is none) gives the same bytes
      // and leaves nothing else behind.
      mt::BuildOptions resume = options;
      resume.resume = true;
      const mt::BuildReport r = mt::buildMt(input, out, resume);
      if (r.resumedAtLevel > 0) ++resumedFromCheckpoint;
      ASSERT_EQ(readFile(out), reference);
      EXPECT_EQ(filesOf(out), std::vector<std::string>{"out.mt"});
    }
  }
  std::printf("[ faults ] %d failures injected (%lld writes, %lld fsyncs, %lld renames); %d resumed from a "
              "checkpoint\n",
              injected, (long long)counts[0], (long long)counts[1], (long long)counts[2], resumedFromCheckpoint);
  EXPECT_GT(resumedFromCheckpoint, 0);
  EXPECT_GT(checkedFiles, 0);
}

// mtextract's and mtstore export's writer: every write, fsync and rename of a PLY fails in turn;
// nothing is left under the final name, nor the temporary file.
TEST(Faults, EveryWriteOfAPlyOutputLeavesNothingUnderItsName) {
  TempDir tmp;
  auto write = [&](const std::string& path) {
    mt::PlyWriter w(path, {});
    for (int i = 0; i < 3000; ++i) {
      const double p[3] = {double(i), double(i % 7), 0.5 * i};
      w.addVertex(p);
    }
    for (uint32_t i = 0; i + 2 < 3000; ++i) w.addTriangle(i, i + 1, i + 2);
    w.finish();
  };
  write(tmp.file("ref.ply"));
  const std::string reference = readFile(tmp.file("ref.ply"));
  mt::FaultInjectionEnv env(mt::Env::Default());
  {
    mt::ScopedDefaultEnv scoped(&env);
    write(tmp.file("count.ply"));
  }
  EXPECT_EQ(readFile(tmp.file("count.ply")), reference);
  const int64_t counts[3] = {env.writes, env.syncs, env.renames};
  ASSERT_GE(counts[0], 2);
  int injected = 0;
  for (auto op : {mt::FaultInjectionEnv::Op::Write, mt::FaultInjectionEnv::Op::Sync, mt::FaultInjectionEnv::Op::Rename})
    for (int64_t k = 1; k <= counts[int(op)]; ++k) {
      SCOPED_TRACE(std::string(opName(op)) + " " + std::to_string(k));
      env.failAfter(op, k, ENOSPC, /*partial=*/true);
      std::string message;
      {
        mt::ScopedDefaultEnv scoped(&env);
        try {
          write(tmp.file("out.ply"));
        } catch (const mt::Error& e) {
          message = e.what();
        }
      }
      env.disarm();
      ++injected;
      EXPECT_NE(message.find(tmp.file("out.ply")), std::string::npos) << message;
      EXPECT_NE(message.find("No space left on device"), std::string::npos) << message;
      EXPECT_EQ(filesOf(tmp.file("out.ply")), std::vector<std::string>{}) << message;
    }
  std::printf("[ faults ] PLY output: %d failures injected\n", injected);
}

// A whole small file (a stats JSON, a PNG): every write, fsync, rename and fsync of its folder
// that fails leaves nothing under its name, nor the temporary file, with an error naming it; the
// folder's fsync is counted (the rename is not durable without it).
TEST(Faults, EveryOperationOfAWholeFileWriteLeavesNothingUnderItsName) {
  TempDir tmp;
  const std::string bytes(100000, 'x');
  mt::FaultInjectionEnv env(mt::Env::Default());
  mt::writeWholeFile(tmp.file("count.json"), bytes, &env);
  EXPECT_EQ(readFile(tmp.file("count.json")), bytes);
  using Op = mt::FaultInjectionEnv::Op;
  const std::pair<Op, int64_t> counts[] = {{Op::Write, env.writes}, {Op::Sync, env.syncs}, {Op::Rename, env.renames},
                                           {Op::DirSync, env.dirSyncs}};
  for (const auto& [op, count] : counts) {
    ASSERT_GE(count, 1) << int(op);
    for (int64_t k = 1; k <= count; ++k) {
      SCOPED_TRACE("operation " + std::to_string(int(op)) + ", " + std::to_string(k) + " of " + std::to_string(count));
      env.failAfter(op, k, ENOSPC, /*partial=*/true);
      std::string message;
      try {
        mt::writeWholeFile(tmp.file("out.json"), bytes, &env);
      } catch (const mt::Error& e) {
        message = e.what();
      }
      env.disarm();
      EXPECT_NE(message.find(op == Op::DirSync ? tmp.path() : tmp.file("out.json")), std::string::npos) << message;
      EXPECT_NE(message.find("No space left on device"), std::string::npos) << message;
      EXPECT_EQ(filesOf(tmp.file("out.json")), std::vector<std::string>{}) << message;
    }
  }
}

// mtextract's and mtexport's glTF outputs (a .glb; a .gltf and its .bin; a 3D Tiles directory)
// go through the Env: every write, fsync and rename fails in turn (ENOSPC, half written); the
// error names a file of the output, and nothing is left under the final names, nor a temporary.
TEST(Faults, EveryWriteOfAGltfOrTilesOutputLeavesNothingUnderItsName) {
  TempDir tmp;
  const std::string input = writeGrid(tmp);
  mt::buildMt(input, tmp.file("in.mt"), smallBuild());
  auto reader = mt::MtFileReader::open(tmp.file("in.mt"));
  std::vector<uint32_t> finest;  // the arcs leaving the source: the full-resolution cut
  for (uint32_t a = 0; a < reader->arcs().size(); ++a)
    if (reader->arcs()[a].from == 0) finest.push_back(a);
  const mt::WeldedMesh mesh = mt::assembleCut(*reader, finest);
  ASSERT_GT(mesh.triangleCount(), 0u);
  const mt::interop::GltfMeshView view = mt::interop::gltfMeshViewOf(mesh, reader->header().gridOrigin, reader->header().gridStep);
  struct Output {
    std::string name;
    std::vector<std::string> finals;  // every name the output appears under
    std::function<void(const std::string&)> write;
  };
  mt::interop::GltfOptions draco;
  draco.quantize = draco.draco = true;
  const Output outputs[] = {
      {"cut.glb", {"cut.glb"}, [&](const std::string& p) { mt::interop::writeGltfFile(p, view, draco); }},
      {"cut.gltf", {"cut.gltf", "cut.bin"}, [&](const std::string& p) { mt::interop::writeGltfFile(p, view, {}); }},
      {"tiles", {"tiles"}, [&](const std::string& p) { mt::interop::exportTiles(*reader, p, {}); }},
  };
  int injected = 0;
  for (const Output& o : outputs) {
    mt::FaultInjectionEnv env(mt::Env::Default());
    {
      mt::ScopedDefaultEnv scoped(&env);
      o.write(tmp.file("count_" + o.name));
    }
    const int64_t counts[3] = {env.writes, env.syncs, env.renames};
    ASSERT_GE(counts[0], 1) << o.name;
    ASSERT_GE(counts[1], 1) << o.name;
    ASSERT_GE(counts[2], 1) << o.name;
    for (auto op : {mt::FaultInjectionEnv::Op::Write, mt::FaultInjectionEnv::Op::Sync, mt::FaultInjectionEnv::Op::Rename})
      for (int64_t k = 1; k <= counts[int(op)]; ++k) {
        SCOPED_TRACE(o.name + ": " + opName(op) + " " + std::to_string(k));
        env.failAfter(op, k, ENOSPC, /*partial=*/true);
        std::string message;
        int code = 0;
        {
          mt::ScopedDefaultEnv scoped(&env);
          try {
            o.write(tmp.file(o.name));
          } catch (const mt::Error& e) {
            message = e.what();
            code = mt::exitCodeFor(e);
          }
        }
        env.disarm();
        ASSERT_TRUE(env.fired());
        ++injected;
        EXPECT_NE(message.find(tmp.path()), std::string::npos) << "names the file: " << message;
        EXPECT_NE(message.find("No space left on device"), std::string::npos) << message;
        EXPECT_EQ(code, mt::kExitIo) << message;
        for (const std::string& name : o.finals) {
          EXPECT_EQ(filesOf(tmp.file(name)), std::vector<std::string>{}) << message;
        }
      }
  }
  std::printf("[ faults ] glTF and 3D Tiles outputs: %d failures injected\n", injected);
}

// heal's updates go through the store's Env: every write, fsync and rename of a heal pass fails in
// turn; the store then opens, checks clean, and holds the old surface, the healed one, or one
// between them (a pass commits in steps, each whole): never fewer triangles than healed, never a
// triangle that was not there.
TEST(Faults, EveryWriteOfAHealPassLeavesTheOldOrTheHealedStore) {
  TempDir tmp;
  const std::string input = writeGrid(tmp, 40);
  {
    auto assigner = mt::makeGridAssigner(100);
    mt::IngestOptions o;
    o.progress = false;
    mt::PatchStore::ingest(input, tmp.file("base"), *assigner, o);
  }
  auto exportOf = [&](const std::string& dir) {
    auto store = mt::PatchStore::open(dir);
    store->exportPly(tmp.file("e.ply"));
    return readFile(tmp.file("e.ply"));
  };
  auto heal = [&](mt::Env* env) {
    fs::remove_all(tmp.file("s"));
    fs::copy(tmp.file("base"), tmp.file("s"), fs::copy_options::recursive);
    auto store = mt::PatchStore::open(tmp.file("s"), env);
    mt::heal::HealOptions options;
    options.memoryBytes = 64ull << 20;
    mt::heal::removeDegenerate(*store, options);
    store->sync();
  };
  const std::string before = exportOf(tmp.file("base"));
  mt::FaultInjectionEnv env(mt::Env::Default());
  {
    mt::ScopedDefaultEnv scoped(&env);
    heal(&env);
  }
  const std::string after = exportOf(tmp.file("s"));
  ASSERT_NE(before, after) << "the pass must change something";
  const int64_t counts[3] = {env.writes, env.syncs, env.renames};
  int injected = 0, old = 0, healed = 0;
  for (auto op : {mt::FaultInjectionEnv::Op::Write, mt::FaultInjectionEnv::Op::Sync, mt::FaultInjectionEnv::Op::Rename})
    for (int64_t k = 1; k <= counts[int(op)]; ++k) {
      SCOPED_TRACE(std::string(opName(op)) + " " + std::to_string(k));
      env.failAfter(op, k);
      {
        mt::ScopedDefaultEnv scoped(&env);
        try {
          heal(&env);
        } catch (const mt::Error&) {
        }
      }
      env.disarm();
      ++injected;
      {
        auto store = mt::PatchStore::open(tmp.file("s"));
        mt::CheckReport c = store->check();
        ASSERT_TRUE(c.ok) << (c.problems.empty() ? "" : c.problems[0]);
      }
      const std::string now = exportOf(tmp.file("s"));
      const uint64_t faces = facesOf(now);
      EXPECT_TRUE(faces >= facesOf(after) && faces <= facesOf(before)) << faces;
      old += now == before;
      healed += now == after;
    }
  std::printf("[ faults ] heal: %d failures injected (%lld writes, %lld fsyncs, %lld renames): %d old, %d healed\n",
              injected, (long long)counts[0], (long long)counts[1], (long long)counts[2], old, healed);
  EXPECT_GT(old, 0);
}
