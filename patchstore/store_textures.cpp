// The store's materials and tiled texture images: see store_textures.h.
#include "patchstore/store_textures.h"

#include <cstdio>

#include "base/byte_io.h"

namespace mt {

std::string encodeMaterials(const std::vector<StoreMaterial>& materials) {
  ByteWriter w;
  w.put<uint32_t>(1);  // version
  w.put<uint32_t>(uint32_t(materials.size()));
  for (const StoreMaterial& m : materials) {
    w.putString(m.name);
    w.putRaw(m.diffuse, 3);
    w.putString(m.file);
    w.putString(m.source);
    w.put<int32_t>(m.width);
    w.put<int32_t>(m.height);
    w.put<int32_t>(m.shift);
    w.put<uint64_t>(m.bytes);
  }
  return w.bytes();
}

std::vector<StoreMaterial> decodeMaterials(const std::string& bytes, const std::string& source) {
  std::vector<StoreMaterial> out;
  if (bytes.empty()) return out;
  ByteReader r(bytes, source);
  if (r.get<uint32_t>() != 1) failCorrupt(source, "materials blob has an unknown version");
  const uint32_t n = r.get<uint32_t>();
  if (n > (1u << 20)) failCorrupt(source, "materials blob is damaged (count)");
  out.resize(n);
  for (StoreMaterial& m : out) {
    m.name = r.getString();
    std::memcpy(m.diffuse, r.getRaw(3), 3);
    m.file = r.getString();
    m.source = r.getString();
    m.width = r.get<int32_t>();
    m.height = r.get<int32_t>();
    m.shift = r.get<int32_t>();
    m.bytes = r.get<uint64_t>();
    if (m.file.find('/') != std::string::npos) failCorrupt(source, "materials blob names a file outside the store");
  }
  if (!r.atEnd()) failCorrupt(source, "materials blob has trailing bytes");
  return out;
}

std::vector<StoreMaterial> storeMaterials(const PatchStore& store) {
  return decodeMaterials(store.blob(kMaterialsBlob), store.dir() + " (materials)");
}

std::vector<StoreMaterial> tileTextures(const std::vector<InputMaterial>& materials, const std::string& dir,
                                        uint64_t memoryBytes, bool progress, Env* env) {
  std::vector<StoreMaterial> out;
  for (size_t k = 0; k < materials.size(); ++k) {
    const InputMaterial& in = materials[k];
    StoreMaterial m;
    m.name = in.name;
    std::memcpy(m.diffuse, in.diffuse, 3);
    if (!in.texture.empty()) {
      m.file = "TEX-" + std::to_string(k) + ".tiles";
      m.source = in.texture;
      tex::TiledInfo info;
      try {
        info = tex::writeTiledImage(in.texture, dir + "/" + m.file, memoryBytes, env);
      } catch (const Error& e) {
        // The reader's message names the image and the byte offset; add who named it.
        throw Error(std::string(e.what()) + " (texture of material '" + in.name + "', named in " + in.source + ")", e.kind());
      }
      m.width = info.width;
      m.height = info.height;
      m.shift = info.shift;
      m.bytes = info.bytes;
      if (progress)
        std::fprintf(stderr, "ingest: texture %s: %d x %d%s, %.1f MiB tiled\n", in.texture.c_str(), info.sourceWidth,
                     info.sourceHeight, info.shift ? (" (scaled by 1/" + std::to_string(1 << info.shift) + " to fit the memory cap)").c_str() : "",
                     double(info.bytes) / double(1 << 20));
    }
    out.push_back(std::move(m));
  }
  return out;
}

std::shared_ptr<tex::TileCache> openTextureCache(const PatchStore& store, const std::vector<StoreMaterial>& materials,
                                                 uint64_t capBytes) {
  std::vector<std::shared_ptr<const tex::TiledImage>> images;
  for (const StoreMaterial& m : materials)
    images.push_back(m.file.empty() ? nullptr : std::shared_ptr<const tex::TiledImage>(tex::TiledImage::open(store.dir() + "/" + m.file)));
  return std::make_shared<tex::TileCache>(std::move(images), capBytes);
}

std::vector<std::string> checkTextures(const PatchStore& store) {
  std::vector<std::string> problems;
  std::vector<StoreMaterial> materials;
  try {
    materials = storeMaterials(store);
  } catch (const Error& e) {
    return {e.what()};
  }
  for (const StoreMaterial& m : materials) {
    if (m.file.empty()) continue;
    try {
      auto t = tex::TiledImage::open(store.dir() + "/" + m.file);
      if (t->width() != m.width || t->height() != m.height) problems.push_back(store.dir() + "/" + m.file + ": size differs from the materials blob");
      t->verify();
    } catch (const Error& e) {
      problems.push_back(e.what());
    }
  }
  return problems;
}

}  // namespace mt
