// mtgen --texture: texture coordinates and texture images for the procedural scan. Every
// component's grid of cells is cut into charts of chartRows x chartCols cells; each chart gets a
// slot of texelsPerCell texels per cell (plus a gutter) in one of the texture pages, so a
// vertex on a chart's border has a different texture coordinate in each chart around it: the
// seams a parametrized scan has. `fragmented` makes charts of 1 x 2 cells (four triangles):
// thousands of tiny charts, the case that stops tools which keep the input's charts.
//
// A texel shows the colour of the surface point its chart maps to it, a function of the torus
// angles (sharp-edged checks and thin lines, a tint per component): the same pattern whatever
// the parametrization, so a re-baked atlas can be compared with the input's texture. Everything
// is a pure function of (component, row, column), like the surface itself; pages are written one
// texel row at a time (JPEG), in memory O(page width).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "testing/scan_generator.h"

namespace mtgen {

struct TextureOptions {
  bool fragmented = false;
  int chartRows = 48, chartCols = 48;  // cells per chart (fragmented: 1 x 2)
  int texelsPerCell = 2;               // texels per cell side
  int gutter = 2;                      // texels around each chart's slot (fragmented: 1)
  int pageSide = 4096;                 // the largest page side (pages are square or shorter)
  int quality = 90;                    // JPEG quality of the pages
};

class TextureAtlas {
 public:
  TextureAtlas(const ScanGenerator& generator, const TextureOptions& options);
  int pages() const { return pages_; }
  int pageWidth() const { return pageWidth_; }
  int pageHeight(int page) const;
  uint64_t charts() const { return charts_; }
  // The texture coordinates (over its page, v = 0 at the bottom row) of the corner at offset
  // (dr, dc) (0, 1, or 0.5 for a T-junction's midpoint) of cell (row, col) of a component, in
  // the chart of that cell; and the page.
  void cornerUV(uint32_t component, uint32_t row, uint32_t col, double dr, double dc, float uv[2], uint32_t& page) const;
  // The colour of a component's surface at fractional grid position (row, col).
  void colorAt(uint32_t component, double row, double col, uint8_t rgb[3]) const;
  // Writes page k to path (JPEG).
  void writePage(int page, const std::string& path) const;

 private:
  struct Slot {
    uint32_t component, chartRow, chartCol;
  };
  Slot slotOf(uint64_t chart) const;
  const ScanGenerator& gen_;
  TextureOptions o_;
  std::vector<uint64_t> firstChart_;  // per component (and the total at the end)
  std::vector<uint32_t> chartsAcross_;  // per component: charts along the columns
  uint64_t charts_ = 0;
  int slotW_ = 0, slotH_ = 0, slotsPerRow_ = 0, slotRowsPerPage_ = 0, pages_ = 0, pageWidth_ = 0;
};

}  // namespace mtgen
