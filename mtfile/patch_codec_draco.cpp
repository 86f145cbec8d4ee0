// Codec::Draco (patch_codec.h; byte layout in mt_format.h): edgebreaker, positions as a lossless
// INT32 attribute (no Draco quantization), so the grid coordinates round-trip bit-exactly.
#include <cstring>
#include <memory>
#include <string>

#include <draco/compression/decode.h>
#include <draco/compression/encode.h>
#include <draco/core/decoder_buffer.h>
#include <draco/core/encoder_buffer.h>
#include <draco/mesh/mesh.h>

#include "base/error.h"
#include "mtfile/patch_codec_detail.h"

namespace mt::codec_detail {

using format::PayloadHeader;

std::vector<uint8_t> encodeDraco(const Prepared& p, const PatchCodecOptions& options) {
  const PayloadHeader& h = p.header;
  size_t n = h.vertexCount;
  draco::Mesh mesh;
  mesh.set_num_points(uint32_t(n));
  // Positions as lossless 3 x INT32: Draco predicts them (parallelogram) and entropy-codes the
  // residuals without quantizing, so the grid coordinates survive bit for bit.
  draco::GeometryAttribute pa;
  pa.Init(draco::GeometryAttribute::POSITION, nullptr, 3, draco::DT_INT32, false, 12, 0);
  int posId = mesh.AddAttribute(pa, true, uint32_t(n));
  for (size_t v = 0; v < n; ++v)
    mesh.attribute(posId)->SetAttributeValue(draco::AttributeValueIndex(uint32_t(v)), &p.q[v * 3]);
  if (!p.oct.empty()) {
    draco::GeometryAttribute na;
    na.Init(draco::GeometryAttribute::GENERIC, nullptr, 2, draco::DT_UINT8, false, 2, 0);
    int id = mesh.AddAttribute(na, true, uint32_t(n));
    for (size_t v = 0; v < n; ++v)
      mesh.attribute(id)->SetAttributeValue(draco::AttributeValueIndex(uint32_t(v)), &p.oct[v * 2]);
  }
  if (!p.colors.empty()) {
    draco::GeometryAttribute ca;
    ca.Init(draco::GeometryAttribute::COLOR, nullptr, 4, draco::DT_UINT8, true, 4, 0);
    int id = mesh.AddAttribute(ca, true, uint32_t(n));
    for (size_t v = 0; v < n; ++v)
      mesh.attribute(id)->SetAttributeValue(draco::AttributeValueIndex(uint32_t(v)), &p.colors[v * 4]);
  }
  mesh.SetNumFaces(h.triangleCount);
  for (uint32_t t = 0; t < h.triangleCount; ++t)
    mesh.SetFace(draco::FaceIndex(t), {draco::PointIndex(p.indices[t * 3]), draco::PointIndex(p.indices[t * 3 + 1]),
                                       draco::PointIndex(p.indices[t * 3 + 2])});

  draco::Encoder encoder;
  encoder.SetSpeedOptions(options.dracoSpeed, options.dracoSpeed);
  encoder.SetEncodingMethod(draco::MESH_EDGEBREAKER_ENCODING);
  draco::EncoderBuffer buffer;
  draco::Status status = encoder.EncodeMeshToBuffer(mesh, &buffer);
  if (!status.ok()) throw Error("encodePatch: draco: " + status.error_msg_string());

  std::vector<uint8_t> out;
  appendBytes(out, &h, sizeof h);
  appendBytes(out, buffer.data(), buffer.size());
  return out;
}

void decodeDraco(const uint8_t* data, size_t size, const PayloadHeader& h, DecodedPatch& out,
                 std::vector<uint32_t>& qRel) {
  draco::DecoderBuffer buffer;
  buffer.Init(reinterpret_cast<const char*>(data + sizeof(PayloadHeader)), size - sizeof(PayloadHeader));
  draco::Decoder decoder;
  auto result = decoder.DecodeMeshFromBuffer(&buffer);
  if (!result.ok()) bad("draco: " + result.status().error_msg_string());
  std::unique_ptr<draco::Mesh> mesh = std::move(result).value();
  if (mesh->num_faces() != h.triangleCount) bad("draco triangle count does not match the header");
  // Draco may split non-manifold vertices, so up to 3 points per triangle are acceptable.
  uint64_t n = mesh->num_points();
  if (n > uint64_t(h.triangleCount) * 3 + h.vertexCount) bad("draco vertex count out of range");
  const draco::PointAttribute* pos = mesh->GetNamedAttribute(draco::GeometryAttribute::POSITION);
  if (!pos || pos->num_components() != 3 || pos->data_type() != draco::DT_INT32) bad("draco positions missing");
  const draco::PointAttribute* nor = nullptr;
  const draco::PointAttribute* col = nullptr;
  if (h.flags & format::kPayloadNormals) {
    nor = mesh->GetNamedAttribute(draco::GeometryAttribute::GENERIC);
    if (!nor || nor->num_components() != 2 || nor->data_type() != draco::DT_UINT8) bad("draco normals missing");
    out.normals.resize(n * 3);
  }
  if (h.flags & format::kPayloadColors) {
    col = mesh->GetNamedAttribute(draco::GeometryAttribute::COLOR);
    if (!col || col->num_components() != 4 || col->data_type() != draco::DT_UINT8) bad("draco colours missing");
    out.colors.resize(n * 4);
  }
  qRel.resize(n * 3);
  for (uint32_t v = 0; v < n; ++v) {
    draco::PointIndex pi(v);
    int32_t q[3];
    pos->GetValue(pos->mapped_index(pi), q);
    std::memcpy(&qRel[size_t(v) * 3], q, 12);
    if (nor) {
      uint8_t o[2];
      nor->GetValue(nor->mapped_index(pi), o);
      decodeOctahedral8(o, &out.normals[size_t(v) * 3]);
    }
    if (col) col->GetValue(col->mapped_index(pi), &out.colors[size_t(v) * 4]);
  }
  out.triangles.resize(size_t(h.triangleCount) * 3);
  for (uint32_t t = 0; t < h.triangleCount; ++t) {
    const auto& f = mesh->face(draco::FaceIndex(t));
    for (int k = 0; k < 3; ++k) out.triangles[size_t(t) * 3 + k] = f[k].value();
  }
}

}  // namespace mt::codec_detail
