// Not a fuzz target: writes the Draco seeds of fuzz_reader_gltf (bench/fuzz.sh --seeds), GLB files
// with a KHR_draco_mesh_compression primitive: a small wavy grid, positions only and with normals
// and RGBA8 colours. (The meshopt seeds come from mtextract --meshopt; the plain ones from
// make_seeds.py.)  Usage: fuzz_seed_gltf OUTDIR
#include <draco/compression/encode.h>
#include <draco/mesh/triangle_soup_mesh_builder.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

namespace {

bool writeGlb(const std::string& path, const std::string& json, const draco::EncoderBuffer& data) {
  std::string text = json;
  while (text.size() % 4) text += ' ';
  std::string bin(data.data(), data.size());
  while (bin.size() % 4) bin += '\0';
  std::string out;
  auto u32 = [&](uint32_t v) { out.append(reinterpret_cast<const char*>(&v), 4); };
  u32(0x46546C67), u32(2), u32(uint32_t(12 + 8 + text.size() + 8 + bin.size()));
  u32(uint32_t(text.size())), u32(0x4E4F534A);
  out += text;
  u32(uint32_t(bin.size())), u32(0x004E4942);
  out += bin;
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (!f) return false;
  const bool ok = std::fwrite(out.data(), 1, out.size(), f) == out.size();
  return std::fclose(f) == 0 && ok;
}

bool seed(const std::string& path, bool attributes) {
  const int n = 5;
  std::vector<float> p;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) p.insert(p.end(), {0.25f * float(i), 0.25f * float(j), 0.125f * float(std::sin(i) * std::cos(j))});
  draco::TriangleSoupMeshBuilder builder;
  builder.Start(2 * (n - 1) * (n - 1));
  const int pos = builder.AddAttribute(draco::GeometryAttribute::POSITION, 3, draco::DT_FLOAT32);
  const int nor = attributes ? builder.AddAttribute(draco::GeometryAttribute::NORMAL, 3, draco::DT_FLOAT32) : -1;
  const int col = attributes ? builder.AddAttribute(draco::GeometryAttribute::COLOR, 4, draco::DT_UINT8) : -1;
  uint32_t face = 0;
  const float up[3] = {0, 0, 1};
  for (int j = 0; j + 1 < n; ++j)
    for (int i = 0; i + 1 < n; ++i) {
      const int a = j * n + i, b = a + 1, c = a + n, d = c + 1;
      for (auto [x, y, z] : {std::array<int, 3>{a, b, d}, std::array<int, 3>{a, d, c}}) {
        const draco::FaceIndex f(face++);
        builder.SetAttributeValuesForFace(pos, f, &p[3 * x], &p[3 * y], &p[3 * z]);
        if (attributes) {
          builder.SetAttributeValuesForFace(nor, f, up, up, up);
          const uint8_t rgba[4] = {uint8_t(40 * i), uint8_t(40 * j), 128, 255};
          builder.SetAttributeValuesForFace(col, f, rgba, rgba, rgba);
        }
      }
    }
  std::unique_ptr<draco::Mesh> mesh = builder.Finalize();
  if (!mesh) return false;
  draco::Encoder encoder;
  encoder.SetSpeedOptions(5, 5);
  if (attributes) encoder.SetAttributeQuantization(draco::GeometryAttribute::POSITION, 14);
  draco::EncoderBuffer buffer;
  if (!encoder.EncodeMeshToBuffer(*mesh, &buffer).ok()) return false;
  std::string attrs = "\"POSITION\":" + std::to_string(mesh->attribute(pos)->unique_id());
  if (attributes)
    attrs += ",\"NORMAL\":" + std::to_string(mesh->attribute(nor)->unique_id()) +
             ",\"COLOR_0\":" + std::to_string(mesh->attribute(col)->unique_id());
  const std::string json =
      "{\"asset\":{\"version\":\"2.0\"},\"extensionsUsed\":[\"KHR_draco_mesh_compression\"],"
      "\"extensionsRequired\":[\"KHR_draco_mesh_compression\"],"
      "\"buffers\":[{\"byteLength\":" + std::to_string((buffer.size() + 3) / 4 * 4) + "}],"
      "\"bufferViews\":[{\"buffer\":0,\"byteLength\":" + std::to_string(buffer.size()) + "}],"
      "\"accessors\":[{\"componentType\":5126,\"count\":" + std::to_string(mesh->num_points()) +
      ",\"type\":\"VEC3\",\"min\":[0,0,-0.2],\"max\":[1,1,0.2]},{\"componentType\":5125,\"count\":" +
      std::to_string(3 * mesh->num_faces()) + ",\"type\":\"SCALAR\"}],"
      "\"meshes\":[{\"primitives\":[{\"attributes\":{\"POSITION\":0},\"indices\":1,\"extensions\":"
      "{\"KHR_draco_mesh_compression\":{\"bufferView\":0,\"attributes\":{" + attrs + "}}}}]}],"
      "\"nodes\":[{\"mesh\":0,\"translation\":[500000.0,4000000.0,0.0]}],\"scenes\":[{\"nodes\":[0]}],\"scene\":0}";
  return writeGlb(path, json, buffer);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: fuzz_seed_gltf OUTDIR\n");
    return 1;
  }
  const std::string dir = argv[1];
  if (!seed(dir + "/draco.glb", false) || !seed(dir + "/draco_normals_colors.glb", true)) {
    std::fprintf(stderr, "fuzz_seed_gltf: cannot write the seeds in %s\n", dir.c_str());
    return 1;
  }
  return 0;
}
