// mtgen --texture: see texture_atlas.h.
#include "testing/texture_atlas.h"

#include <algorithm>
#include <cmath>

#include "texture/image_codec.h"

namespace mtgen {

TextureAtlas::TextureAtlas(const ScanGenerator& gen, const TextureOptions& options) : gen_(gen), o_(options) {
  if (o_.fragmented) o_.chartRows = 1, o_.chartCols = 2, o_.gutter = std::min(o_.gutter, 1);
  for (const Component& c : gen.components()) {
    firstChart_.push_back(charts_);
    const uint32_t down = (c.rows + uint32_t(o_.chartRows) - 1) / uint32_t(o_.chartRows);
    const uint32_t across = (c.cols + uint32_t(o_.chartCols) - 1) / uint32_t(o_.chartCols);
    chartsAcross_.push_back(across);
    charts_ += uint64_t(down) * across;
  }
  firstChart_.push_back(charts_);
  slotW_ = o_.chartCols * o_.texelsPerCell + 2 * o_.gutter;
  slotH_ = o_.chartRows * o_.texelsPerCell + 2 * o_.gutter;
  if (slotW_ > o_.pageSide || slotH_ > o_.pageSide) throw mt::Error("mtgen --texture: a chart does not fit a page");
  slotsPerRow_ = o_.pageSide / slotW_;
  slotRowsPerPage_ = o_.pageSide / slotH_;
  const uint64_t perPage = uint64_t(slotsPerRow_) * uint64_t(slotRowsPerPage_);
  pages_ = int((charts_ + perPage - 1) / perPage);
  pageWidth_ = int(std::min<uint64_t>(charts_, uint64_t(slotsPerRow_))) * slotW_;
}

int TextureAtlas::pageHeight(int page) const {
  const uint64_t perPage = uint64_t(slotsPerRow_) * uint64_t(slotRowsPerPage_);
  const uint64_t inPage = std::min<uint64_t>(perPage, charts_ - uint64_t(page) * perPage);
  return int((inPage + uint64_t(slotsPerRow_) - 1) / uint64_t(slotsPerRow_)) * slotH_;
}

TextureAtlas::Slot TextureAtlas::slotOf(uint64_t chart) const {
  const size_t c = size_t(std::upper_bound(firstChart_.begin(), firstChart_.end(), chart) - firstChart_.begin()) - 1;
  const uint64_t local = chart - firstChart_[c];
  return {uint32_t(c), uint32_t(local / chartsAcross_[c]), uint32_t(local % chartsAcross_[c])};
}

void TextureAtlas::cornerUV(uint32_t component, uint32_t row, uint32_t col, double dr, double dc, float uv[2], uint32_t& page) const {
  const uint32_t cr = row / uint32_t(o_.chartRows), cc = col / uint32_t(o_.chartCols);
  const uint64_t chart = firstChart_[component] + uint64_t(cr) * chartsAcross_[component] + cc;
  const uint64_t perPage = uint64_t(slotsPerRow_) * uint64_t(slotRowsPerPage_);
  page = uint32_t(chart / perPage);
  const uint64_t inPage = chart % perPage;
  const double x = double(inPage % uint64_t(slotsPerRow_)) * slotW_ + o_.gutter +
                   (double(col - cc * uint32_t(o_.chartCols)) + dc) * o_.texelsPerCell;
  const double y = double(inPage / uint64_t(slotsPerRow_)) * slotH_ + o_.gutter +
                   (double(row - cr * uint32_t(o_.chartRows)) + dr) * o_.texelsPerCell;
  uv[0] = float(x / pageWidth_);
  uv[1] = float(1.0 - y / pageHeight(int(page)));
}

void TextureAtlas::colorAt(uint32_t component, double row, double col, uint8_t rgb[3]) const {
  const Component& c = gen_.components()[component];
  // Torus angles as fractions of a turn (the grid's own spacing, before the density warp:
  // rowFraction / colFraction interpolated between grid lines).
  auto frac = [](auto fn, const Component& k, double x, uint32_t n) {
    const double f = std::floor(x);
    const uint32_t i = uint32_t(std::clamp(f, 0.0, double(n)));
    const double a = fn(k, i), b = fn(k, i + 1);
    return a + (b - a) * (x - f);
  };
  const double a = frac(ScanGenerator::rowFraction, c, row, c.rows), b = frac(ScanGenerator::colFraction, c, col, c.cols);
  const bool check = ((int(std::floor(a * 48)) + int(std::floor(b * 24))) & 1) != 0;
  const double la = a * 192 - std::floor(a * 192), lb = b * 96 - std::floor(b * 96);
  const bool line = la < 0.1 || lb < 0.1;
  const uint64_t h = mix64(component + 17);
  const double tint[3] = {0.75 + 0.25 * double(h & 255) / 255.0, 0.75 + 0.25 * double((h >> 8) & 255) / 255.0,
                          0.75 + 0.25 * double((h >> 16) & 255) / 255.0};
  static const double kA[3] = {225, 196, 90}, kB[3] = {60, 120, 190};
  for (int k = 0; k < 3; ++k) {
    double v = (check ? kA[k] : kB[k]) * tint[k];
    if (line) v *= 0.25;
    // A gentle ramp along the tube, so flat squares are not flat colours.
    v *= 0.8 + 0.2 * std::sin(6.283185307179586 * b);
    rgb[k] = uint8_t(std::clamp(std::lround(v), 0l, 255l));
  }
}

void TextureAtlas::writePage(int page, const std::string& path) const {
  const int w = pageWidth_, h = pageHeight(page);
  mt::tex::JpegRowWriter out(path, w, h, o_.quality);
  std::vector<uint8_t> row(size_t(w) * 3);
  const uint64_t perPage = uint64_t(slotsPerRow_) * uint64_t(slotRowsPerPage_);
  for (int y = 0; y < h; ++y) {
    const int slotRow = y / slotH_, ty = y % slotH_;
    for (int x = 0; x < w; ++x) {
      uint8_t* px = &row[size_t(x) * 3];
      const uint64_t chart = uint64_t(page) * perPage + uint64_t(slotRow) * uint64_t(slotsPerRow_) + uint64_t(x / slotW_);
      if (chart >= charts_) {
        px[0] = px[1] = px[2] = 0;
        continue;
      }
      const Slot s = slotOf(chart);
      const Component& c = gen_.components()[s.component];
      // The texel centre in cell units of the chart, clamped to the chart (the gutter repeats its
      // border) and to the component's grid.
      const int tx = x % slotW_;
      const double lc = std::clamp((tx - o_.gutter + 0.5) / o_.texelsPerCell, 0.0, double(o_.chartCols));
      const double lr = std::clamp((ty - o_.gutter + 0.5) / o_.texelsPerCell, 0.0, double(o_.chartRows));
      const double col = std::min(double(c.cols), s.chartCol * double(o_.chartCols) + lc);
      const double rowf = std::min(double(c.rows), s.chartRow * double(o_.chartRows) + lr);
      colorAt(s.component, rowf, col, px);
    }
    out.writeRow(row.data());
  }
  out.finish();
}

}  // namespace mtgen
