// mtextract: extract one cut of an MT file as a single welded PLY.
//   mtextract OUT.mt --error E -o CUT.ply                 every rendered node within error E
//   mtextract OUT.mt --triangles N -o CUT.ply             best cut of at most N triangles
//   mtextract OUT.mt --eye X,Y,Z --target X,Y,Z [--fov DEG] [--width PX] [--pixels TOL]
//                    [--triangles N] -o CUT.ply           view-dependent (BMT 5.1)
// The cut is chosen by mtfile/mt_cut.h, its patches decoded and welded by exact grid position,
// and written with PlyWriter under a name unique to the process (CUT.ply.tmp.PID.RANDOM), renamed
// over CUT.ply when complete: on any error nothing is left under CUT.ply. The input is never the
// output (refused by inode), and the output format is chosen by the extension: .ply, .glb/.gltf
// (with a textured file: texture coordinates and the patch atlases embedded, interop/gltf_writer.h),
// or .obj (with a textured file: + .mtl and the textures re-packed into PNG pages beside it).
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cctype>
#include <cinttypes>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "base/error.h"
#include "base/exit_code.h"
#include "base/interrupt.h"
#include "base/output_path.h"
#include "base/process.h"
#include "mtfile/mt_cut.h"
#include "mtfile/mt_cut_writer.h"
#include "mtfile/mt_file.h"
#include "mtfile/textured_cut.h"
#include "patchstore/io/ply_writer.h"
#include "texture/obj_writer.h"
#include "base/cli_checks.h"
#include "interop/gltf_writer.h"

namespace {

struct Options {
  std::string input, output;
  double error = NAN;
  uint64_t triangles = 0;
  std::string eye, target;
  uint64_t memoryBytes = uint64_t(1) << 30;
  double fov = 60, width = 1920, pixels = 1;
  bool hasError = false, hasTriangles = false, hasEye = false, hasTarget = false;
  bool meshopt = false, quantize = false;  // glTF output only
};

void parseVector(const std::string& text, const char* option, double out[3]) {
  std::stringstream s(text);
  std::string part;
  int n = 0;
  while (std::getline(s, part, ',')) {
    if (n == 3) throw mt::Error(std::string(option) + " wants X,Y,Z: too many components in '" + text + "'");
    size_t used = 0;
    try {
      out[n] = std::stod(part, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != part.size() || !std::isfinite(out[n]))
      throw mt::Error(std::string(option) + " wants X,Y,Z: '" + part + "' is not a number");
    ++n;
  }
  if (n != 3) throw mt::Error(std::string(option) + " wants X,Y,Z: got '" + text + "'");
}

// The ranges of the numeric options, checked by CLI11 as the command line is parsed and shown by
// --help. Budgets far above any file's triangle count are refused as typos (they would mean the
// finest cut anyway).
constexpr uint64_t kMaxTriangles = 1'000'000'000'000ull;
const mt::cli::Interval kErrorRange{0, INFINITY, false, false, "object units"};
const mt::cli::Interval kFovRange{0, 180, true, true, "degrees"};
const mt::cli::Interval kWidthRange{1, 1e6, false, false, "pixels"};
const mt::cli::Interval kPixelsRange{0, 1e6, true, false, "pixels"};

// The output's format by its extension (case-insensitive): binary PLY, glTF (.glb, .gltf) or OBJ;
// any other name (.xyz, none) is refused rather than given bytes under a misleading name. True:
// glTF; `obj` says .obj.
bool checkOutputFormat(const std::string& output, bool* obj = nullptr) {
  const std::string name = output.substr(output.find_last_of('/') + 1);
  const size_t dot = name.find_last_of('.');
  std::string ext = dot == std::string::npos || dot == 0 ? "" : name.substr(dot);
  for (auto& c : ext) c = char(std::tolower(static_cast<unsigned char>(c)));
  if (obj) *obj = ext == ".obj";
  if (ext == ".ply" || ext == ".obj") return false;
  if (ext == ".glb" || ext == ".gltf") return true;
  if (ext.empty()) mt::fail(output, "the output name has no extension: cannot choose its format (supported: .ply, .glb, .gltf, .obj)");
  mt::fail(output, "cannot write the format " + name.substr(dot) + " (supported: .ply, .glb, .gltf, .obj)");
}

// OBJ output (textured files: + MTL + PNG pages; texture/obj_writer.h), assembled in RAM.
int writeObj(const Options& o, const mt::MtFileReader& r, const std::vector<uint32_t>& arcs, const mt::CutStats& stats) {
  uint64_t texels = 0;
  for (uint32_t p : mt::cutPatchIdsOf(r, arcs))
    if (r.hasTextures()) texels += uint64_t(r.textures()[p].width) * r.textures()[p].height;
  // The welded mesh, the decoded textures and the pages they are packed into.
  const uint64_t need = mt::assembledCutBytes(r, arcs) + 7 * texels;
  if (need > o.memoryBytes)
    throw mt::Error(o.output + ": this cut needs about " + std::to_string(need >> 20) + " MiB to write as OBJ, more than --memory (" +
                        std::to_string(o.memoryBytes >> 20) + " MiB): raise --memory, choose a coarser cut, or write .ply",
                    mt::ErrorKind::Resource);
  mt::TexturedCut cut = mt::assembleTexturedCut(r, arcs);
  mt::checkInterrupt(o.output);
  std::vector<mt::tex::RgbImage> images;
  for (const mt::CutTexture& t : cut.textures)
    images.push_back(mt::tex::decodeImage(t.image.data(), t.image.size(), o.input + ": texture of patch " + std::to_string(t.patch)));
  mt::tex::TexturedMeshView view;
  view.positions = cut.mesh.positions.data();
  view.vertexCount = cut.mesh.vertexCount();
  view.triangles = cut.mesh.triangles.data();
  view.triangleCount = cut.mesh.triangleCount();
  view.cornerUV = cut.cornerUV.data();
  view.triangleTexture = cut.triangleTexture.data();
  view.textures = &images;
  const mt::tex::ObjWriteInfo info = mt::tex::writeTexturedObj(o.output, view);
  std::fprintf(stderr, "mtextract: %s: %u triangles, %u vertices from %" PRIu64 " patches, %zu textures in %zu pages (%" PRIu64
               " texels); %u nodes in the set, %u on the front; max error %.9g\n", o.output.c_str(), cut.mesh.triangleCount(),
               cut.mesh.vertexCount(), cut.mesh.patches, images.size(), info.pages, info.texels, stats.nodes, stats.frontNodes,
               stats.maxError);
  return 0;
}

// The PLY header's choices for a welded cut, on both paths (in RAM and streamed): float coordinates
// unless the grid is finer than float spacing at this distance from the origin (distinct grid
// points must stay distinct in the PLY: it is "welded").
mt::PlyWriteOptions plyOptionsFor(double maxAbsCoordinate, double gridStep, bool normals, bool colors) {
  mt::PlyWriteOptions options;
  options.doublePrecision = maxAbsCoordinate * 0x1.0p-23 > gridStep * 0.5;
  options.normals = normals;
  options.colors = colors;
  return options;
}

// The PLY writer as the streamed weld's sink.
class PlySink : public mt::WeldedCutSink {
 public:
  PlySink(const std::string& output, double gridStep) : output_(output), gridStep_(gridStep) {}
  void begin(const mt::WeldedCutInfo& info) override {
    ply_ = std::make_unique<mt::PlyWriter>(output_, plyOptionsFor(info.maxAbsCoordinate, gridStep_, info.normals, info.colors));
  }
  void vertex(const double p[3], const float* n, const uint8_t* c) override { ply_->addVertex(p, n, c); }
  void triangle(uint32_t a, uint32_t b, uint32_t c) override { ply_->addTriangle(a, b, c); }
  void finish() { ply_->finish(); }

 private:
  std::string output_;
  double gridStep_;
  std::unique_ptr<mt::PlyWriter> ply_;
};

// The cut welded in bounded memory: sorts spill to a folder beside the output, removed at the end
// (or when an error or a signal unwinds).
int writeStreamedPly(const Options& o, const mt::MtFileReader& r, const std::vector<uint32_t>& arcs,
                     const mt::CutStats& stats, const mt::ViewParams& view) {
  struct ScratchDir {
    std::string path;
    ~ScratchDir() {
      std::error_code ec;
      if (!path.empty()) std::filesystem::remove_all(path, ec);
    }
  } scratch{mt::uniqueTempName(o.output) + ".sort"};
  if (!std::filesystem::create_directory(scratch.path)) mt::fail(scratch.path, "cannot create the scratch folder");
  mt::WeldedCutOptions options;
  options.memoryBytes = o.memoryBytes;
  options.scratchDir = scratch.path;
  options.poll = [&] { mt::checkInterrupt(o.output); };
  PlySink sink(o.output, r.header().gridStep);
  const mt::WeldedCutInfo info = mt::writeWeldedCut(r, arcs, options, sink);
  mt::checkInterrupt(o.output);
  sink.finish();
  std::fprintf(stderr, "mtextract: %s: %" PRIu64 " triangles, %" PRIu64 " vertices from %" PRIu64 " patches; %u nodes in the "
               "set, %u on the front; max error %.9g", o.output.c_str(), info.triangles, info.vertices, info.patches,
               stats.nodes, stats.frontNodes, stats.maxError);
  if (o.hasEye) {
    double worst = 0;
    for (uint32_t a : arcs) worst = std::max(worst, mt::screenSpaceError(r.nodes()[r.arcs()[a].from], view));
    std::fprintf(stderr, ", max screen-space error %.3g px", worst);
  }
  if (info.degenerateTriangles) std::fprintf(stderr, "; %" PRIu64 " degenerate triangles dropped", info.degenerateTriangles);
  std::fprintf(stderr, " (welded in bounded memory)\n");
  return 0;
}

int run(const Options& o) {
  // Argument checks first: a bad command line opens nothing and writes nothing.
  if (o.hasError && o.hasTriangles) throw mt::Error("--error and --triangles are exclusive: give one");
  if (o.hasEye && o.hasError) throw mt::Error("--error and --eye are exclusive (with --eye use --pixels, and --triangles as a budget)");
  if (!o.hasEye && !o.hasError && !o.hasTriangles) throw mt::Error("give --error E, --triangles N or --eye/--target");
  if (o.hasEye != o.hasTarget) throw mt::Error("--eye and --target go together");
  // CLI11 checked the ranges; these hold for values that reach run() another way.
  if (o.hasError && !kErrorRange.contains(o.error)) throw mt::Error("--error must be " + kErrorRange.text());
  if (o.hasTriangles && (o.triangles < 1 || o.triangles > kMaxTriangles))
    throw mt::Error("--triangles must be an integer in [1, " + std::to_string(kMaxTriangles) + "]");
  mt::ViewParams view;
  if (o.hasEye) {
    parseVector(o.eye, "--eye", view.eye);
    parseVector(o.target, "--target", view.target);
    if (!kFovRange.contains(o.fov)) throw mt::Error("--fov must be " + kFovRange.text());
    if (!kWidthRange.contains(o.width)) throw mt::Error("--width must be " + kWidthRange.text());
    if (!kPixelsRange.contains(o.pixels)) throw mt::Error("--pixels must be " + kPixelsRange.text());
    if (view.eye[0] == view.target[0] && view.eye[1] == view.target[1] && view.eye[2] == view.target[2])
      throw mt::Error("--eye and --target are the same point");
    view.fovDegrees = o.fov;
    view.widthPixels = o.width;
    view.pixelTolerance = o.pixels;
    if (o.hasTriangles) view.maxTriangles = o.triangles;
  }

  // A FIFO or a device would block the reader or be read as garbage; the output may not replace
  // the input.
  mt::requireRegularFile(o.input, "an MT file");
  mt::checkOutputPath(o.output, {o.input});
  bool obj = false;
  const bool gltf = checkOutputFormat(o.output, &obj);
  if ((o.meshopt || o.quantize) && !gltf) throw mt::Error("--meshopt and --quantize are for glTF output (.glb, .gltf)");

  auto reader = mt::MtFileReader::open(o.input);
  const mt::MtFileReader& r = *reader;
  mt::Cut cut = o.hasEye ? mt::cutViewDependent(r, view)
                : o.hasError ? mt::cutByError(r, o.error)
                             : mt::cutByTriangles(r, o.triangles);
  std::string why;
  if (!mt::isValidCut(r, cut.inSet, &why)) mt::fail(o.input, "internal error: extracted an invalid cut: " + why);
  if (cut.excludedByClosure)
    std::fprintf(stderr, "mtextract: warning: %s: errors are not monotone; %u nodes within the error were left out so "
                 "the bound holds (run mtverify)\n", o.input.c_str(), cut.excludedByClosure);
  mt::CutStats stats = mt::cutStats(r, cut.inSet);
  if (o.hasTriangles && stats.triangles > o.triangles)
    std::fprintf(stderr, "mtextract: warning: the coarsest cut has %" PRIu64 " triangles, more than --triangles %" PRIu64
                 "; writing it\n", stats.triangles, o.triangles);

  if (obj) return writeObj(o, r, mt::cutArcs(r, cut.inSet), stats);
  // A cut whose assembled mesh would not fit --memory is welded through external sorts and
  // streamed to the PLY (same bytes, mtfile/mt_cut_writer.h).
  // glTF output is assembled in RAM (its buffers are sized before they are written), so a cut too
  // large for --memory is refused there rather than let the tool exceed its cap.
  if (const std::vector<uint32_t> arcs = mt::cutArcs(r, cut.inSet); mt::assembledCutBytes(r, arcs) > o.memoryBytes) {
    if (!gltf) return writeStreamedPly(o, r, arcs, stats, view);
    throw mt::Error(o.output + ": this cut needs about " + std::to_string(mt::assembledCutBytes(r, arcs) >> 20) +
                        " MiB to write as glTF, more than --memory (" + std::to_string(o.memoryBytes >> 20) +
                        " MiB): raise --memory, choose a coarser cut, or write .ply (streamed within the cap)",
                    mt::ErrorKind::Resource);
  }
  if (gltf && r.hasTextures()) {
    // Textured: a vertex per distinct texture coordinate, a material per patch atlas, the atlases
    // embedded as stored (gltf_writer.h).
    const std::vector<uint32_t> arcs = mt::cutArcs(r, cut.inSet);
    uint64_t imageBytes = 0;
    for (uint32_t p : mt::cutPatchIdsOf(r, arcs)) imageBytes += r.textures()[p].imageBytes;
    // The welded cut, its split copy (about as large) and the images twice (the cut's, the GLB's).
    const uint64_t need = 2 * mt::assembledCutBytes(r, arcs) + 2 * imageBytes;
    if (need > o.memoryBytes)
      throw mt::Error(o.output + ": this cut needs about " + std::to_string(need >> 20) + " MiB to write as textured glTF, more than --memory (" +
                          std::to_string(o.memoryBytes >> 20) + " MiB): raise --memory or choose a coarser cut",
                      mt::ErrorKind::Resource);
    mt::TexturedCut tcut = mt::assembleTexturedCut(r, arcs);
    mt::checkInterrupt(o.output);
    mt::interop::TexturedGltfMesh tmesh;
    mt::interop::texturedGltfMeshOf(tcut, r.header().gridOrigin, r.header().gridStep, tmesh);
    mt::interop::GltfOptions go;
    go.meshopt = o.meshopt;
    go.quantize = o.quantize;
    go.generator = "batched-mt mtextract";
    go.crs = r.crs();
    mt::interop::GltfInfo info = mt::interop::writeGltfFile(o.output, tmesh.view, go);
    if (o.quantize && !info.quantized)
      std::fprintf(stderr, "mtextract: warning: %s: float positions, not KHR_mesh_quantization: %s\n", o.output.c_str(),
                   info.fallbackReason.c_str());
    std::fprintf(stderr, "mtextract: %s: %u triangles, %zu vertices (split at texture seams) from %" PRIu64
                 " patches, %zu textures (%" PRIu64 " bytes); %u nodes in the set, %u on the front; max error %.9g\n",
                 o.output.c_str(), tcut.mesh.triangleCount(), tmesh.view.vertexCount, tcut.mesh.patches, tcut.textures.size(),
                 tcut.textureBytes(), stats.nodes, stats.frontNodes, stats.maxError);
    return 0;
  }
  mt::WeldedMesh mesh = mt::assembleCut(r, mt::cutArcs(r, cut.inSet));
  mt::checkInterrupt(o.output);

  if (gltf) {
    // The whole cut as one glTF mesh; positions relative to a grid point (gltf_writer.h).
    const mt::interop::GltfMeshView meshView = mt::interop::gltfMeshViewOf(mesh, r.header().gridOrigin, r.header().gridStep);
    mt::interop::GltfOptions go;
    go.meshopt = o.meshopt;
    go.quantize = o.quantize;
    go.generator = "batched-mt mtextract";
    go.crs = r.crs();
    mt::interop::GltfInfo info = mt::interop::writeGltfFile(o.output, meshView, go);
    if (o.quantize && !info.quantized)
      std::fprintf(stderr, "mtextract: warning: %s: float positions, not KHR_mesh_quantization: %s\n", o.output.c_str(),
                   info.fallbackReason.c_str());
  } else {
  double maxAbs = 0;
  for (double p : mesh.positions) maxAbs = std::max(maxAbs, std::abs(p));
  const mt::PlyWriteOptions plyOptions =
      plyOptionsFor(maxAbs, r.header().gridStep, !mesh.normals.empty(), !mesh.colors.empty());
  // PlyWriter writes under uniqueTempName(output) and renames when finished; an error or a
  // signal (polled here) unwinds through its destructor, which removes the temporary file.
  mt::PlyWriter ply(o.output, plyOptions);
  for (uint32_t v = 0; v < mesh.vertexCount(); ++v) {
    if ((v & 0xfffff) == 0) mt::checkInterrupt(o.output);
    ply.addVertex(&mesh.positions[3 * v], plyOptions.normals ? &mesh.normals[3 * v] : nullptr,
                  plyOptions.colors ? &mesh.colors[4 * v] : nullptr);
  }
  for (uint32_t t = 0; t < mesh.triangleCount(); ++t) {
    if ((t & 0xfffff) == 0) mt::checkInterrupt(o.output);
    ply.addTriangle(mesh.triangles[3 * t], mesh.triangles[3 * t + 1], mesh.triangles[3 * t + 2]);
  }
  ply.finish();
  }

  std::fprintf(stderr, "mtextract: %s: %u triangles, %u vertices from %" PRIu64 " patches; %u nodes in the set, %u on the "
               "front; max error %.9g", o.output.c_str(), mesh.triangleCount(), mesh.vertexCount(), mesh.patches,
               stats.nodes, stats.frontNodes, stats.maxError);
  if (o.hasEye) {
    double worst = 0;
    for (uint32_t a : mt::cutArcs(r, cut.inSet))
      worst = std::max(worst, mt::screenSpaceError(r.nodes()[r.arcs()[a].from], view));
    std::fprintf(stderr, ", max screen-space error %.3g px", worst);
  }
  if (mesh.degenerateTriangles) std::fprintf(stderr, "; %" PRIu64 " degenerate triangles dropped", mesh.degenerateTriangles);
  std::fprintf(stderr, "\n");
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"mtextract: extract one cut of a batched Multi-Triangulation file (.mt) as a single welded binary\n"
               "PLY, GLB or glTF (by the output's extension). Choose the cut with exactly one of:\n"
               "  --error E      every rendered node within object-space error E (the coarsest such cut)\n"
               "  --triangles N  the best cut of at most N triangles (refine largest error first)\n"
               "  --eye/--target view-dependent: refine while a node's error, projected at its bounding sphere's\n"
               "                 nearest point, exceeds --pixels; --triangles N then caps the triangles.\n"
               "Prints the cut's triangles, nodes and max error on stderr. On any error: one line, the exit code of\n"
               "its kind (1 invalid input, 3 corrupt file, 4 I/O error, 5 resource limit: README, \"Exit codes\"),\n"
               "and no file under the output name."};
  Options o;
  app.add_option("file", o.input, "The MT file")->required();
  app.add_option("-o,--output", o.output,
                 "The file to write, by its extension: .ply (binary little-endian, welded), .glb or .gltf (+ .bin "
                 "beside it; a textured file's cut: texture coordinates and one material per patch atlas, the "
                 "atlases embedded as stored), or .obj (a textured file's cut: + CUT.mtl and its textures re-packed into CUT_<k>.png pages "
                 "beside it); may not be the input")
      ->required();
  auto* err = app.add_option("--error", o.error, "Maximum object-space error of the cut")
                  ->check(mt::cli::numberIn(kErrorRange));
  auto* tri = app.add_option("--triangles", o.triangles, "Maximum triangles of the cut (a budget with --eye)")
                  ->check(mt::cli::countIn(1, kMaxTriangles));
  auto* eye = app.add_option("--eye", o.eye, "View-dependent: eye position X,Y,Z (object space)");
  auto* target = app.add_option("--target", o.target, "View-dependent: point looked at X,Y,Z (needed with --eye)");
  app.add_option("--fov", o.fov, "View-dependent: horizontal field of view in degrees")
      ->check(mt::cli::numberIn(kFovRange))
      ->capture_default_str();
  app.add_option("--width", o.width, "View-dependent: viewport width in pixels")
      ->check(mt::cli::numberIn(kWidthRange))
      ->capture_default_str();
  app.add_option("--pixels", o.pixels, "View-dependent: tolerated screen-space error in pixels")
      ->check(mt::cli::numberIn(kPixelsRange))
      ->capture_default_str();
  std::string memory = "1G";
  app.add_option("--memory", memory,
                 "Memory for the weld, from 1M to 1024T, e.g. 512M, 4G (K, M, G, T are powers of 1024): a cut whose "
                 "welded mesh (about 60 bytes per triangle) would not fit is welded through external sorts in a folder "
                 "beside the output, streamed, same bytes")
      ->capture_default_str();
  app.add_flag("--meshopt", o.meshopt,
               "glTF output: compress every buffer view with EXT_meshopt_compression (meshoptimizer's codecs)");
  app.add_flag("--quantize", o.quantize,
               "glTF output: KHR_mesh_quantization: positions as the MT grid's uint16 coordinates (exact), normals as int16;\n"
               "falls back to float positions, with a warning, when the cut spans more than 65536 grid steps on an axis");
  app.footer(
      "Huge pages: with --memory 256M or more (the default 1G), mtextract restarts itself once with\n"
      "GLIBC_TUNABLES=glibc.malloc.hugetlb=1 (appended to any GLIBC_TUNABLES), so that glibc's malloc asks for\n"
      "transparent huge pages: less time filling large arrays, the same results. Not when MT_NO_HUGEPAGES=1, when\n"
      "GLIBC_TUNABLES already sets glibc.malloc.hugetlb, or when the kernel's transparent huge pages are never.");
  if (int code = mt::cli::parse(app, argc, argv, "mtextract"); code >= 0) return code;
  o.hasError = err->count() > 0;
  o.hasTriangles = tri->count() > 0;
  o.hasEye = eye->count() > 0;
  o.hasTarget = target->count() > 0;
  try {
    o.memoryBytes = mt::cli::sizeOption(memory, "--memory", uint64_t(1) << 20, uint64_t(1) << 50, "1M", "1024T");
  } catch (const std::exception& e) {
    return mt::reportError("mtextract", e);
  }
  // glibc's malloc on transparent huge pages (base/process.h), as mtbuild and mtverify; before the
  // interrupt handlers, so that no Ctrl-C can arrive in the image the exec replaces.
  if (o.memoryBytes >= mt::kMallocHugePagesFromMemory) mt::reexecWithMallocHugePages(argv);
  mt::installInterruptHandlers();
  try {
    return run(o);
  } catch (const mt::Interrupted& e) {
    std::fprintf(stderr, "mtextract: %s; nothing was written\n", e.what());
    return 128 + e.signal();
  } catch (const std::exception& e) {
    return mt::reportError("mtextract", e);
  }
}
