// mtrender: the budgeted, interruptible out-of-core renderer for MT files (BMT section 5).
//   mtrender FILE.mt... --headless --camera-path P --frames N --budget-ms MS --cache SIZE
//            --width W --height H --stats frames.csv [--screenshots DIR] [--plot DIR]
//   mtrender FILE.mt...            (the interactive viewer: GLFW window, Dear ImGui HUD)
// docs/mtrender.md describes the options, the camera path format and the CSV columns.
#include <CLI/CLI.hpp>
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cstdio>
#include <filesystem>
#include <future>
#include <fstream>
#include <memory>
#include <numeric>
#include <string>
#include <thread>
#include <vector>

#include "base/error.h"
#include "base/exit_code.h"
#include "base/output_path.h"
#include "base/process.h"
#include "base/size.h"
#include "mtrender/color_mode.h"
#include "mtrender/engine.h"
#include "mtrender/viewer.h"
#include "base/cli_checks.h"

using namespace mt::render;
using Clock = std::chrono::steady_clock;

namespace {

// Removes a temporary file unless it was renamed over its final name.
struct TemporaryFile {
  std::string path;
  bool kept = false;
  ~TemporaryFile() {
    if (!kept) std::remove(path.c_str());
  }
};

void writeCsv(const std::string& path, const std::vector<FrameRecord>& frames) {
  TemporaryFile tmpFile{mt::uniqueTempName(path)};
  const std::string& tmp = tmpFile.path;
  {
    std::ofstream out(tmp);
    if (!out) mt::fail(path, "cannot write the stats CSV");
    out << "frame,frame_ms,extract_ms,triangles,patches,loads,misses,cache_bytes,max_screen_error,"
           "drawn_triangles,drawn_patches,budget_triangles,gpu_bytes,lod_scale,moving,requests,prefetches,"
           "refinements,coarsenings,model_fixed_ms,model_ms_per_mtri,accumulating,image_frames,"
           "occluded_arcs,occluded_nodes,coned_patches,nodes_keyed,interrupted,loaded_triangles,new_misses,"
           "occlusion_ms,occlusion_tests,occlusion_frame,extract_cpu_ms,stale_keys\n";
    char buf[512];
    for (size_t i = 0; i < frames.size(); ++i) {
      const FrameRecord& f = frames[i];
      std::snprintf(buf, sizeof buf, "%zu,%.3f,%.4f,%llu,%u,%u,%u,%llu,%.4f,%llu,%u,%llu,%llu,%.3f,%d,%u,%u,%u,%u,%.3f,%.1f,%d,%u,%u,%u,%u,%u,%d,%llu,%u,%.3f,%u,%d,%.4f,%u\n", i,
                    f.frameMs, f.extractMs, (unsigned long long)f.triangles, f.patches, f.loads, f.misses,
                    (unsigned long long)f.cacheBytes, f.maxScreenError, (unsigned long long)f.drawnTriangles,
                    f.drawnPatches, (unsigned long long)f.budgetTriangles, (unsigned long long)f.gpuBytes, f.lodScale,
                    f.moving ? 1 : 0, f.requests, f.prefetches, f.refinements, f.coarsenings, f.modelA, f.modelB,
                    f.accumulating ? 1 : 0, f.imageFrames, f.occludedArcs, f.occludedNodes, f.conedPatches, f.nodesKeyed,
                    f.interrupted ? 1 : 0, (unsigned long long)f.loadedTriangles, f.newMisses,
                    f.occlusionMs, f.occlusionTests, f.occlusionFrame ? 1 : 0, f.extractCpuMs, f.staleKeys);
      out << buf;
    }
    if (!out) mt::fail(path, "write failed");
  }
  std::filesystem::rename(tmp, path);
  tmpFile.kept = true;
}

void writePlots(const std::string& dir, const std::string& csv, double budgetMs, uint64_t cap) {
  std::filesystem::create_directories(dir);
  const std::string script = dir + "/plots.gnuplot";
  {
    std::ofstream g(script);
    g << "set datafile separator ','\nset terminal png size 900,400 noenhanced\nset key autotitle columnhead\n"
         "set xlabel 'frame'\nset grid\n";
    auto plot = [&](const std::string& name, const std::string& title, const std::string& cols) {
      g << "set output '" << dir << "/" << name << ".png'\nset title '" << title << "'\nplot " << cols << "\n";
    };
    const std::string f = "'" + csv + "'";
    plot("frame_ms", "frame time (ms)", f + " using 1:2 with lines, " + f + " using 1:3 with lines, " +
                                            std::to_string(budgetMs) + " title 'budget' with lines dt 2");
    plot("triangles", "triangles", f + " using 1:4 with lines, " + f + " using 1:10 with lines, " + f +
                                       " using 1:12 with lines");
    plot("loads_misses", "patch loads and misses per frame", f + " using 1:6 with lines, " + f + " using 1:7 with lines");
    plot("cache_bytes", "RAM cache bytes", f + " using 1:8 with lines, " + std::to_string(cap) + " title 'cap' with lines dt 2");
    plot("screen_error", "max screen-space error (px)", f + " using 1:9 with lines, 1 title '1 px' with lines dt 2");
  }
  std::string cmd = "gnuplot '" + script + "' 2>&1";
  if (std::system(cmd.c_str()) != 0) throw mt::Error(script + ": gnuplot failed (is gnuplot installed?)");
}

// The outputs may not replace an input MT file (or each other's folder): checked before anything
// is opened or rendered. Folders get the names written inside them checked.
void checkOutputs(const std::vector<std::string>& files, const std::string& statsPath, const std::string& screenshotPath,
                  const std::string& recordPath, bool recordGiven, const std::string& screenshotDir,
                  const std::string& plotDir) {
  if (!statsPath.empty()) mt::checkOutputPath(statsPath, files);
  if (!screenshotPath.empty()) {
    mt::checkOutputPath(screenshotPath, files);
    const std::string ext = std::filesystem::path(screenshotPath).extension().string();
    if (ext != ".png" && ext != ".PNG") mt::fail(screenshotPath, "the screenshot is a PNG: the name must end in .png");
  }
  if (recordGiven) mt::checkOutputPath(recordPath, files);
  auto checkFolder = [&](const std::string& dir, const char* option) {
    std::error_code ec;
    if (std::filesystem::exists(dir, ec) && !std::filesystem::is_directory(dir, ec))
      mt::fail(dir, std::string("is not a directory (") + option + " names the folder the images are written into)");
  };
  if (!screenshotDir.empty()) {
    checkFolder(screenshotDir, "--screenshots");
    // Screenshots are frame_NNNNN.png inside the folder: none of them may be an input.
    for (const std::string& f : files) {
      const std::filesystem::path p(f);
      const std::string name = p.filename().string();
      const std::string parent = p.parent_path().empty() ? "." : p.parent_path().string();
      if (name.rfind("frame_", 0) == 0 && p.extension() == ".png" && mt::sameFile(parent, screenshotDir))
        mt::fail(f, "is an input and would be overwritten by a screenshot in " + screenshotDir);
    }
  }
  if (!plotDir.empty()) {
    checkFolder(plotDir, "--plot");
    for (const char* name : {"frames.csv", "plots.gnuplot", "frame_ms.png", "triangles.png", "loads_misses.png",
                             "cache_bytes.png", "screen_error.png"}) {
      const std::string out = plotDir + "/" + name;
      for (const std::string& f : files)
        if (mt::sameFile(out, f)) mt::fail(out, "is the input " + f + "; choose another --plot folder (the input is never overwritten)");
    }
  }
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

// The command line, as parsed.
struct CliOptions {
  std::vector<std::string> files;
  bool headless = false, baseline = false, noPrefetch = false, noCull = false, quiet = false, wireframe = false;
  bool noOcclusion = false;
  std::string occlusionTest = "pyramid", cones = "closed", rekey = "bounded";
  bool cold = false;
  std::string cameraPath, statsPath, screenshotDir, plotDir, cacheText = "256M", gpuCacheText, colorMode = "auto";
  std::string screenshotPath, recordPath = "mtrender-path.txt";
  bool recordGiven = false;
  int frames = 0, width = 1280, height = 720, screenshotEvery = 1, maxFrames = 0;
  double budgetMs = 0, tolerance = 0, readDelayMs = 0, extractMs = 0, frameInterval = 0;
  uint64_t fixedTriangles = 0;
  uint32_t loadBudget = 0, stillFrames = 0, occlusionEvery = 0;
  std::vector<int> background;
};

constexpr uint64_t kMaxFrames = 10'000'000;

// The options of the cut, the budgets and the cache, with their ranges (checked as the command
// line is parsed, shown by --help) and the engine's own defaults.
void addRenderOptions(CLI::App& app, CliOptions& o) {
  const EngineOptions engineDefaults;
  o.budgetMs = engineDefaults.extract.budgetMs;
  o.tolerance = engineDefaults.extract.pixelTolerance;
  o.stillFrames = engineDefaults.stillFrames;
  const mt::cli::Interval kBudgetMs{0, 60000, true, false, "ms"}, kTolerance{0, 10000, true, false, "pixels"},
      kExtractMs{0, 60000, true, false, "ms"};
  app.add_option("files", o.files, "MT files to show together (they share one cache and one budget)")->required();
  app.add_flag("--headless", o.headless, "render offscreen on EGL surfaceless (no X), for tests and benchmarks");
  app.add_option("--camera-path", o.cameraPath,
                 "camera path: a path file (docs/mtrender.md) or a built-in: orbit, flythrough, fixed "
                 "(headless default: fixed; in the viewer the path is replayed)");
  app.add_option("--frames", o.frames, "frames to render (headless; default: the path's length, or 100)")
      ->check(mt::cli::countIn(1, kMaxFrames));
  app.add_option("--budget-ms", o.budgetMs, "frame-time budget in ms")->check(mt::cli::numberIn(kBudgetMs))->capture_default_str();
  app.add_option("--cache", o.cacheText, "RAM patch cache cap, from 1M to 1024T, e.g. 64M, 1G (K, M, G, T: powers of 1024)")
      ->capture_default_str();
  app.add_option("--gpu-cache", o.gpuCacheText, "GPU buffer cache cap, from 1M to 1024T (default: same as --cache)");
  app.add_option("--width", o.width, "image width in pixels")->check(mt::cli::countIn(16, 16384))->capture_default_str();
  app.add_option("--height", o.height, "image height in pixels")->check(mt::cli::countIn(16, 16384))->capture_default_str();
  app.add_option("--stats", o.statsPath, "write one CSV row per frame (columns in docs/mtrender.md); not an input file");
  app.add_option("--screenshots", o.screenshotDir, "headless: write frame_NNNNN.png into this directory");
  app.add_option("--screenshot-every", o.screenshotEvery, "headless: a screenshot every K frames (and the last one)")
      ->check(mt::cli::countIn(1, kMaxFrames))
      ->capture_default_str();
  app.add_option("--plot", o.plotDir, "write PNG charts of the per-frame series with gnuplot into this directory");
  app.add_flag("--baseline-mmap", o.baseline,
               "baseline: map the files and render the same kind of cut with no RAM cache, no PatchServer "
               "thread and no prefetch (patches decoded inside the frame)");
  app.add_option("--tolerance", o.tolerance, "target screen-space error in pixels")
      ->check(mt::cli::numberIn(kTolerance))
      ->capture_default_str();
  app.add_option("--fixed-triangles", o.fixedTriangles,
                 "a fixed render budget (triangles per frame) instead of the time model (default: the time model)")
      ->check(mt::cli::countIn(1, 1'000'000'000'000ull));
  app.add_option("--extract-ms", o.extractMs, "deadline of the cut update per frame (default min(2, budget/20))")
      ->check(mt::cli::numberIn(kExtractMs));
  app.add_option("--load-budget", o.loadBudget, "patches requested per frame (default: from the measured load time)")
      ->check(mt::cli::countIn(1, 1'000'000));
  app.add_option("--still-frames", o.stillFrames,
                 "progressive refinement of a still view: once the camera stops, a finer cut is drawn over up to "
                 "this many frames (each within --budget-ms) and shown when complete; 1 turns it off")
      ->check(mt::cli::countIn(1, 64))
      ->capture_default_str();
  app.add_flag("--no-prefetch", o.noPrefetch, "no prefetching");
  app.add_flag("--no-cull", o.noCull, "no frustum / normal-cone / occlusion culling");
  app.add_flag("--no-occlusion", o.noOcclusion,
               "no occlusion culling (by default patches hidden behind nearer geometry in the frame's depth are "
               "neither refined, loaded nor drawn)");
  app.add_option("--cones", o.cones,
                 "normal-cone (back-face) culling: closed (default: only for a file whose surface is closed, seen "
                 "from outside it; both sides are lit, so elsewhere a back face can show through a hole), always "
                 "(every cone: changes the image of an open scan), off")
      ->check(CLI::IsMember({"closed", "always", "off"}));
  app.add_option("--rekey", o.rekey,
                 "how the cut update re-keys its heaps for the new view: bounded (default: within half the extract "
                 "deadline, from a rotating start; the candidates it does not reach keep their last key) or all (every "
                 "candidate every frame, whatever the deadline: for measuring what the bound saves)")
      ->check(CLI::IsMember({"bounded", "all"}));
  app.add_option("--occlusion-test", o.occlusionTest,
                 "how occlusion culling finds what is hidden: pyramid (the frame's depth read back into a max-depth "
                 "pyramid, spheres tested on the CPU) or queries (GL occlusion queries of the spheres' boxes); "
                 "docs/mtrender.md compares them")
      ->check(CLI::IsMember({"pyramid", "queries"}))
      ->capture_default_str();
  app.add_option("--occlusion-every", o.occlusionEvery,
                 "run the occlusion tests on every N-th frame; 0 (default) = adaptive, every k-th frame with k in "
                 "1..16 keeping their measured cost near 5% of the budget (so what is loaded depends on the "
                 "machine's speed; a fixed N does not)")
      ->check(mt::cli::countIn(0, 1000))
      ->capture_default_str();
}

// Drawing, pacing, test hooks and the viewer's options.
void addDisplayOptions(CLI::App& app, CliOptions& o, CLI::Option*& recordOption) {
  const mt::cli::Interval kDelayMs{0, 60000, false, false, "ms"};
  app.add_option("--color", o.colorMode,
                 "auto (texture when the files have node textures, else vertex when they have per-vertex colours, else "
                 "shaded), shaded (geometry only), vertex (the per-vertex colours as captured, unlit), texture (the node "
                 "textures, unlit, in both caches' bytes; a file without them falls back to vertex colours, saying so), "
                 "patch or lod colours")
      ->check(CLI::IsMember(mt::render::colorModeNames()))
      ->capture_default_str();
  app.add_flag("--wireframe", o.wireframe, "draw edges only");
  app.add_option("--background", o.background, "background colour R G B, each 0-255 (default 20 23 28)")
      ->expected(3)
      ->check(mt::cli::countIn(0, 255));
  app.add_option("--frame-interval-ms", o.frameInterval,
                 "headless: start frames at this interval, like a display refresh (0: back to back, the default); "
                 "frame_ms does not include the wait")
      ->check(mt::cli::numberIn(kDelayMs));
  app.add_option("--test-read-delay-ms", o.readDelayMs, "test hook: add this latency to every patch read (a slow disk)")
      ->check(mt::cli::numberIn(kDelayMs))
      ->capture_default_str();
  app.add_flag("--cold", o.cold,
               "drop the MT files from the OS page cache first (posix_fadvise DONTNEED), for cold-start figures");
  app.add_flag("-q,--quiet", o.quiet, "no progress or warnings on stderr");
  app.add_option("--max-frames", o.maxFrames, "viewer: close after this many frames (for tests; default: when closed)")
      ->check(mt::cli::countIn(1, 1'000'000'000));
  app.add_option("--screenshot", o.screenshotPath, "viewer: write the last frame to this PNG (.png) when closing");
  recordOption = app.add_option("--record", o.recordPath, "viewer: where key R records the camera path")->capture_default_str();
}

// Every input a regular file (a FIFO would block the reader, a device or folder mislead it),
// every output none of them, before anything is opened.
void checkFiles(const CliOptions& o) {
  for (const std::string& f : o.files) mt::requireRegularFile(f, "an MT file");
  if (!o.cameraPath.empty() && o.cameraPath != "orbit" && o.cameraPath != "flythrough" && o.cameraPath != "fixed")
    mt::requireRegularFile(o.cameraPath, "a camera path file");
  checkOutputs(o.files, o.statsPath, o.screenshotPath, o.recordPath, o.recordGiven, o.screenshotDir, o.plotDir);
}

void dropFromPageCache(const std::vector<std::string>& files) {
  for (const auto& f : files) {
    int fd = ::open(f.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd >= 0) {
      ::fdatasync(fd);
      ::posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED);
      ::close(fd);
    }
  }
}

EngineOptions engineOptions(const CliOptions& o) {
  EngineOptions eo;
  eo.files = o.files;
  // Below 1M no useful cut fits; the cache is sized by what the files need, so a large cap
  // costs nothing.
  constexpr uint64_t kMinCache = uint64_t(1) << 20, kMaxCache = uint64_t(1) << 50;
  eo.cacheBytes = mt::cli::sizeOption(o.cacheText, "--cache", kMinCache, kMaxCache, "1M", "1024T");
  eo.gpuCacheBytes =
      o.gpuCacheText.empty() ? 0 : mt::cli::sizeOption(o.gpuCacheText, "--gpu-cache", kMinCache, kMaxCache, "1M", "1024T");
  eo.baseline = o.baseline;
  eo.readDelayMs = o.readDelayMs;
  eo.quiet = o.quiet;
  eo.stillFrames = o.stillFrames;
  eo.extract.budgetMs = o.budgetMs;
  eo.extract.pixelTolerance = o.tolerance;
  eo.extract.fixedTriangles = o.fixedTriangles;
  eo.extract.extractMs = o.extractMs;
  eo.extract.loadBudget = o.loadBudget;
  eo.extract.prefetch = !o.noPrefetch && !o.baseline;
  eo.extract.cull = !o.noCull;
  eo.extract.cones = o.cones == "always" ? ExtractOptions::Cones::Always
                     : o.cones == "off"  ? ExtractOptions::Cones::Off
                                         : ExtractOptions::Cones::Closed;
  eo.extract.occlusion = !o.noOcclusion;
  eo.extract.boundedRekey = o.rekey != "all";
  eo.occlusionTest = o.occlusionTest == "queries" ? OcclusionTest::Queries : OcclusionTest::Pyramid;
  eo.occlusionEvery = o.occlusionEvery;
  return eo;
}

DrawSettings drawSettings(const CliOptions& o) {
  DrawSettings ds;
  ds.wireframe = o.wireframe;
  std::string note;
  ds.mode = resolveColorMode(o.colorMode, colorSupportOf(o.files), &note);
  if (!note.empty() && !o.quiet) std::fprintf(stderr, "mtrender: %s\n", note.c_str());
  if (o.background.size() == 3)
    ds.background = glm::vec3(float(o.background[0]), float(o.background[1]), float(o.background[2])) / 255.0f;
  return ds;
}

int runViewerFor(const CliOptions& o, const EngineOptions& eo, const DrawSettings& ds) {
  ViewerOptions vo;
  vo.engine = eo;
  vo.width = o.width;
  vo.height = o.height;
  vo.cameraPath = o.cameraPath;
  vo.maxFrames = o.maxFrames;
  vo.screenshotPath = o.screenshotPath;
  vo.recordPath = o.recordPath;
  vo.statsPath = o.statsPath;
  vo.draw = ds;
  vo.colors = colorSupportOf(o.files);
  return runViewer(vo);
}

double msSince(Clock::time_point t) { return std::chrono::duration<double, std::milli>(Clock::now() - t).count(); }

// The headless run's engine and GL context, and how long bringing them up took.
struct Headless {
  std::unique_ptr<EglContext> egl;
  std::unique_ptr<GlRenderer> gl;
  std::unique_ptr<Engine> engine;  // destroyed first, before the GL context
  double eglMs = 0, openMs = 0, startMs = 0;
};

// Opening the files and loading the coarsest cut overlap with bringing up GL (loading the Mesa
// driver dominates a cold start).
Headless startHeadless(const EngineOptions& eo, const DrawSettings& ds, int width, int height) {
  Headless h;
  auto pending = std::async(std::launch::async, [&] {
    auto t = Clock::now();
    auto e = std::make_unique<Engine>(eo);
    h.openMs = msSince(t);
    t = Clock::now();
    e->start();
    h.startMs = msSince(t);
    return e;
  });
  auto t0 = Clock::now();
  h.egl = std::make_unique<EglContext>();
  h.gl = std::make_unique<GlRenderer>(eo.gpuCacheBytes ? eo.gpuCacheBytes : eo.cacheBytes);
  h.gl->useOffscreen(width, height);
  h.gl->warmUp(ds);
  h.eglMs = msSince(t0);
  h.engine = pending.get();
  return h;
}

// Renders `frames` frames along `path`, with the screenshots and progress lines asked for.
std::vector<FrameRecord> renderFrames(const CliOptions& o, int frames, const CameraPath& path, Headless& h,
                                      const DrawSettings& ds, Clock::time_point programStart, double& firstFrameMs) {
  std::vector<FrameRecord> recs;
  recs.reserve(size_t(frames));
  auto nextFrame = Clock::now();
  for (int f = 0; f < frames; ++f) {
    if (o.frameInterval > 0) {
      std::this_thread::sleep_until(nextFrame);
      nextFrame += std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double, std::milli>(o.frameInterval));
    }
    const CameraPose& pose = path.at(size_t(f));
    const CameraPose& prev = path.at(size_t(f > 0 ? f - 1 : 0));
    FrameRecord r = h.engine->frame(pose, prev, *h.gl, ds, o.width, o.height);
    if (f == 0) firstFrameMs = msSince(programStart);
    recs.push_back(r);
    if (!o.screenshotDir.empty() && (f % o.screenshotEvery == 0 || f + 1 == frames)) {
      char name[64];
      std::snprintf(name, sizeof name, "/frame_%05d.png", f);
      writePng(o.screenshotDir + name, h.gl->readPixels());
    }
    if (!o.quiet && (f + 1) % 100 == 0)
      std::fprintf(stderr, "mtrender: frame %d/%d, %.1f ms, %llu triangles, %.2f px\n", f + 1, frames, r.frameMs,
                   (unsigned long long)r.triangles, r.maxScreenError);
  }
  return recs;
}

// Prints the run's summary (bench/render.sh parses these lines).
void printSummary(const CliOptions& o, const EngineOptions& eo, const std::vector<FrameRecord>& recs, Headless& h,
                  double firstFrameMs) {
  const int frames = int(recs.size());
  size_t within = 0;
  uint64_t maxCache = 0, maxGpu = 0, drawnSum = 0, loadedSum = 0;
  double wantedSum = 0, missSum = 0, newMissSum = 0;
  size_t extractWithin = 0, extractCpuWithin = 0;
  double extractCpuMax = 0;
  const double deadline = eo.extract.extractMs > 0 ? eo.extract.extractMs : std::min(2.0, o.budgetMs / 20);
  std::vector<double> extract, frameMs;
  for (const auto& r : recs) {
    within += r.frameMs <= o.budgetMs;
    extractWithin += r.extractMs <= deadline;
    extractCpuWithin += r.extractCpuMs <= deadline;
    extractCpuMax = std::max(extractCpuMax, r.extractCpuMs);
    drawnSum += r.drawnTriangles;
    loadedSum += r.loadedTriangles;
    maxCache = std::max(maxCache, r.cacheBytes);
    maxGpu = std::max(maxGpu, r.gpuBytes);
    extract.push_back(r.extractMs);
    frameMs.push_back(r.frameMs);
    missSum += r.misses;
    newMissSum += r.newMisses;
    wantedSum += r.misses + r.drawnPatches;
  }
  const double missRate = wantedSum > 0 ? missSum / wantedSum : 0;
  // After the camera stops: from the first frame of the final still stretch to the first frame
  // whose visible screen error is within the tolerance.
  int stop = frames;
  while (stop > 0 && !recs[size_t(stop - 1)].moving) --stop;
  double settleMs = -1, acc = 0;
  for (int f = stop; f < frames; ++f) {
    if (recs[size_t(f)].maxScreenError <= o.tolerance) {
      settleMs = acc;
      break;
    }
    acc += recs[size_t(f)].frameMs;
  }
  Engine& engine = *h.engine;
  auto cs = engine.cache() ? engine.cache()->stats() : CacheStats{};
  std::printf("frames %d\n", frames);
  std::printf("within_budget_pct %.2f\n", 100.0 * double(within) / double(std::max(1, frames)));
  std::printf("frame_ms_median %.3f\n", median(frameMs));
  std::printf("frame_ms_max %.3f\n", frameMs.empty() ? 0 : *std::max_element(frameMs.begin(), frameMs.end()));
  std::printf("extract_ms_median %.4f\n", median(extract));
  std::printf("extract_ms_max %.4f\n", extract.empty() ? 0 : *std::max_element(extract.begin(), extract.end()));
  std::printf("extract_within_deadline_pct %.2f (deadline %.3f ms, heaps and prefetch included)\n",
              100.0 * double(extractWithin) / double(std::max(1, frames)), deadline);
  std::printf("extract_cpu_within_deadline_pct %.2f (its thread's CPU time: the update's own cost, without waits for a core)\n",
              100.0 * double(extractCpuWithin) / double(std::max(1, frames)));
  std::printf("extract_cpu_ms_max %.4f\n", extractCpuMax);
  std::printf("drawn_triangles_total %llu\n", (unsigned long long)drawnSum);
  std::printf("loaded_triangles_total %llu\n", (unsigned long long)loadedSum);
  std::printf("first_frame_ms %.1f\n", firstFrameMs);
  std::printf("startup_ms gl %.1f open %.1f coarsest_cut %.1f first_frame %.1f\n", h.eglMs, h.openMs, h.startMs,
              recs.empty() ? 0.0 : recs[0].frameMs);
  std::printf("cache_cap_bytes %llu\n", (unsigned long long)eo.cacheBytes);
  std::printf("cache_max_bytes %llu\n", (unsigned long long)maxCache);
  std::printf("cache_slots %u classes %u largest_slot_bytes %llu arena_bytes %llu\n", cs.slots, cs.classes,
              (unsigned long long)cs.slotBytes, (unsigned long long)cs.arenaBytes);
  std::printf("gpu_max_bytes %llu\n", (unsigned long long)maxGpu);
  std::printf("gpu_peak_bytes %llu\n", (unsigned long long)h.gl->gpuPeakBytes());
  std::printf("gpu_texture_bytes %llu textured_draws %llu (atlases with mips, held at the end; draws with a texture)\n",
              (unsigned long long)h.gl->gpuTextureBytes(), (unsigned long long)h.gl->texturedDraws());
  std::printf("gpu_cap_bytes %llu\n", (unsigned long long)(eo.gpuCacheBytes ? eo.gpuCacheBytes : eo.cacheBytes));
  std::printf("miss_rate %.4f\n", missRate);
  std::printf("misses_total %.0f\n", missSum);
  std::printf("new_misses_total %.0f\n", newMissSum);
  std::printf("second_chance %llu evictions %llu urgent_evictions %llu given_up %llu\n",
              (unsigned long long)cs.secondChance, (unsigned long long)cs.evictions,
              (unsigned long long)cs.urgentEvictions, (unsigned long long)cs.givenUp);
  std::printf("bad_patches %llu\n", (unsigned long long)engine.badPatches());
  std::printf("undrawn_files %zu\n", engine.warnUndrawnFiles());
  {
    const Scene& sc = engine.scene();
    uint32_t closed = 0, coarse = 0;
    for (uint32_t f = 0; f < sc.fileCount(); ++f) closed += sc.surface(f).closed(), coarse += sc.surface(f).triangleCount();
    std::printf("closed_files %u of %zu (normal cones cull only these, seen from outside; coarsest cuts %u triangles)\n", closed,
                sc.fileCount(), coarse);
  }
  std::printf("stop_frame %d\n", stop);
  if (stop >= frames) std::printf("settle_ms none (the camera never stops)\n");
  else if (settleMs < 0) std::printf("settle_ms not_reached (final error %.2f px)\n", recs.back().maxScreenError);
  else std::printf("settle_ms %.1f\n", settleMs);
}

int runHeadless(CliOptions o, const EngineOptions& eo, const DrawSettings& ds, Clock::time_point programStart) {
  Headless h = startHeadless(eo, ds, o.width, o.height);
  CameraPath path;
  const int pathFrames = o.frames > 0 ? o.frames : 100;
  if (o.cameraPath.empty()) o.cameraPath = "fixed";
  if (!builtinCameraPath(o.cameraPath, pathFrames, h.engine->center(), h.engine->radius(), path))
    path = loadCameraPath(o.cameraPath, h.engine->center(), h.engine->radius());
  const int frames = o.frames > 0 ? o.frames : int(path.poses.size());
  if (!o.screenshotDir.empty()) std::filesystem::create_directories(o.screenshotDir);
  double firstFrameMs = 0;
  const std::vector<FrameRecord> recs = renderFrames(o, frames, path, h, ds, programStart, firstFrameMs);
  if (!o.statsPath.empty()) writeCsv(o.statsPath, recs);
  if (!o.plotDir.empty()) {
    std::string csv = o.statsPath;
    if (csv.empty()) {
      csv = o.plotDir + "/frames.csv";
      std::filesystem::create_directories(o.plotDir);
      writeCsv(csv, recs);
    }
    writePlots(o.plotDir, std::filesystem::absolute(csv).string(), o.budgetMs, eo.cacheBytes);
  }
  printSummary(o, eo, recs, h, firstFrameMs);
  return 0;
}

// The run's start: now, or, in the process mt::reexecWithMallocHugePages re-executed, the
// original process's start (steady_clock is CLOCK_MONOTONIC, one clock across the exec), so
// first_frame_ms counts the re-execution too.
Clock::time_point runStart() {
  constexpr const char* kVar = "MT_RENDER_START_NS";
  const auto now = Clock::now();
  if (const char* given = std::getenv(kVar)) {
    // Only a value this run's own exec left (a stale one, inherited, is not a start).
    const long long ns = std::atoll(given);
    const auto start = Clock::time_point(std::chrono::duration_cast<Clock::duration>(std::chrono::nanoseconds(ns)));
    unsetenv(kVar);
    if (std::getenv("MT_HUGEPAGES_REEXEC") && ns > 0 && start <= now) return start;
  }
  const long long ns = std::chrono::duration_cast<std::chrono::nanoseconds>(now.time_since_epoch()).count();
  setenv(kVar, std::to_string(ns).c_str(), 1);
  return now;
}

}  // namespace

int main(int argc, char** argv) {
  const auto programStart = runStart();
  // Opening a large file fills arrays of tens of MB (1.2 M patch records and their scene copies
  // at a billion triangles); on 4 KiB pages their page faults were most of the open's time
  // (docs/mtrender.md "Opening a large file").
  mt::reexecWithMallocHugePages(argv);
  unsetenv("MT_RENDER_START_NS");  // no exec happened: nothing to hand on
  CLI::App app{"mtrender: view MT files with a guaranteed frame-time budget, loading patches out of core.\n"
               "Without --headless it opens the interactive viewer (GLFW window; see docs/mtrender.md for keys)."};
  app.footer(
      "Huge pages: mtrender restarts itself once with GLIBC_TUNABLES=glibc.malloc.hugetlb=1 (appended to any\n"
      "GLIBC_TUNABLES), so that opening a large file fills its DAG and index arrays on transparent huge pages\n"
      "(a billion-triangle file's open took 0.8 s of page faults on 4 KiB pages; docs/mtrender.md). Not when\n"
      "MT_NO_HUGEPAGES=1, when GLIBC_TUNABLES already sets glibc.malloc.hugetlb, or when the kernel's mode is never.");
  CliOptions o;
  CLI::Option* recordOption = nullptr;
  addRenderOptions(app, o);
  addDisplayOptions(app, o, recordOption);
  if (int code = mt::cli::parse(app, argc, argv, "mtrender"); code >= 0) return code;
  o.recordGiven = recordOption->count() > 0;
  try {
    checkFiles(o);
    if (o.cold) dropFromPageCache(o.files);
    EngineOptions eo = engineOptions(o);
    const DrawSettings ds = drawSettings(o);
    // The viewer keeps the atlases (its C key may switch to texture at any time); a headless run
    // draws one mode, and loads texels only for texture.
    if (!o.headless) return runViewerFor(o, eo, ds);
    eo.textures = ds.mode == ColorMode::Texture;
    return runHeadless(o, eo, ds, programStart);
  } catch (const std::exception& e) {
    return mt::reportError("mtrender", e);  // one line "mtrender: MESSAGE"; the exit code by kind
  }
}
