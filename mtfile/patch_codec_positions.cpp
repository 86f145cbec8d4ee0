// The decoder half of the position code (patch_codec_positions.h).
#include <memory>
#include <string>

#include "mtfile/patch_codec_detail.h"
#include "mtfile/patch_codec_positions.h"

namespace mt::codec_detail {

void storeDecodedPositions(const std::vector<int64_t>& q, size_t seenCount, size_t n, std::vector<uint32_t>& qRel) {
  if (seenCount != n) bad("vertices not referenced by any triangle");
  qRel.resize(n * 3);
  for (size_t i = 0; i < n * 3; ++i) {
    if (q[i] < 0 || q[i] > kMaxQ) bad("decoded grid coordinate out of range");
    qRel[i] = uint32_t(q[i]);
  }
}

void decodeContextPositions(RangeDecoder& rc, const std::vector<uint32_t>& triangles, size_t n,
                            std::vector<uint32_t>& qRel) {
  std::vector<int64_t> q(n * 3, 0);
  const int64_t range[3] = {kMaxQ, kMaxQ, kMaxQ};
  size_t seenCount = 0;
  bool tooWide = false;
  auto model = std::make_unique<ContextModel>();
  parallelogramWalk(triangles.data(), triangles.size(), n, q.data(), range,
                    [&](uint32_t v, const int64_t pred[3], const Prediction& how) {
                      for (uint32_t x = 0; x < 3; ++x) {
                        uint32_t z = 0;
                        if (!decodeResidual(rc, *model, how.kind, x, z)) tooWide = true;
                        q[v * 3 + x] = pred[x] + unzigzag(z);
                      }
                      if (rc.overrun() > 0) bad("position stream truncated");
                      ++seenCount;
                    });
  if (tooWide) bad("position stream names a residual wider than 32 bits");
  if (rc.overrun() > 0) bad("position stream truncated");
  storeDecodedPositions(q, seenCount, n, qRel);
}

}  // namespace mt::codec_detail
