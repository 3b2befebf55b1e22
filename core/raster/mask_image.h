// One layer's mask image, as produced by the rasterizer and consumed by the mask writers.
//
// Pixel (i, j) covers [x0 + i p, x0 + (i+1) p) x [y0 + j p, y0 + (j+1) p) in model millimetres
// (DESIGN.md). Rows are stored bottom-up: row j is the j-th row from the lowest y, so pixels[j * width + i]
// is pixel (i, j). Writers of top-down formats (PNG, EXR) emit row height-1 first. Values are 0 (dark)
// to 255 (fully lit); a binary mask holds only 0 and 255.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace toposlice {

// A mask value dimmed by a light-uniformity map's relative intensity m: round(v * m / 255).
inline uint8_t lightValue(uint8_t v, uint8_t m) {
  return static_cast<uint8_t>((unsigned{v} * m + 127u) / 255u);
}

struct PixelGrid {
  double x0 = 0, y0 = 0;  // lower-left corner of pixel (0, 0), mm
  double pixel = 0.05;    // pixel edge length, mm
  uint32_t width = 0, height = 0;
  bool mirrorX = false, mirrorY = false;  // applied by the rasterizer: pixel i becomes width-1-i, etc.
  // Portrait images: the grid's x runs along the model's y and its y along the model's x (x0 is then a
  // y and y0 an x); the rasterizer swaps every point's coordinates, which also reverses each loop.
  bool transposed = false;
};

struct MaskImage {
  uint32_t width = 0, height = 0;
  std::vector<uint8_t> pixels;  // width * height, row j = j-th row from the lowest y
  // Optional tight extents of the non-zero pixels of each stored row r: pixels[r * width + i] != 0 only
  // for litBegin[r] <= i < litEnd[r], and both ends are non-zero pixels (begin >= end: a dark row).
  // Either both vectors hold `height` entries or both are empty (extents unknown). The binary
  // rasterizer keeps them, clears only what it lit before, and writers skip dark pixels with them;
  // anyone else changing `pixels` must clear them.
  std::vector<uint32_t> litBegin, litEnd;
  bool hasExtents() const { return litBegin.size() == height && litEnd.size() == height && height > 0; }
  // Optional, binary masks only (values 0 and 255): the lit runs of each stored row r, in increasing x
  // and maximal (no two touch): pixel i is 255 where runs[2k] <= i < runs[2k + 1] for some k in
  // [rowRuns[2r], rowRuns[2r] + rowRuns[2r + 1]), and 0 elsewhere in the row. rowRuns holds 2 * height
  // entries when the runs are known (always with the extents), else none. The binary rasterizer keeps
  // them, so the PNG coder and the clearing of the next layer touch lit pixels only, not the dark gaps
  // between the parts of a plate.
  std::vector<uint32_t> runs, rowRuns;
  bool hasRuns() const { return rowRuns.size() == std::size_t{2} * height && height > 0 && hasExtents(); }
  // Optional, anti-aliased masks: stretches of one value of each stored row r (inside its lit extent,
  // or dark: value 0), as triples (begin, end, value) in increasing x, none overlapping:
  // pixels[r * width + i] == value for begin <= i < end, for the triples [rowFills[2r],
  // rowFills[2r] + rowFills[2r + 1]). Not every constant stretch need be listed. rowFills holds
  // 2 * height entries when known (always with the extents), else none. The exact-coverage rasterizer keeps
  // the runs it fills between edge pixels, so the PNG coder does not read the insides of lit regions back.
  std::vector<uint32_t> fills, rowFills;
  bool hasFills() const { return rowFills.size() == std::size_t{2} * height && height > 0 && hasExtents(); }
  // Forgets the extents, the runs and the fills: for anyone who changes `pixels` another way.
  void forgetLayout() {
    litBegin.clear();
    litEnd.clear();
    runs.clear();
    rowRuns.clear();
    fills.clear();
    rowFills.clear();
  }
};

// Splits [begin, end) of stored row `stored` of `mask` into the row's listed constant stretches
// (MaskImage::fills, when known) and the stretches between them, left to right: fill(a, b, value) for
// pixels [a, b) known to hold `value` (not read), gap(a, b) for pixels [a, b) the caller must read.
// Together they cover [begin, end) exactly, in order (nothing when it is empty); none is empty.
template <class Fill, class Gap>
void forEachRowStretch(const MaskImage& mask, std::size_t stored, std::size_t begin, std::size_t end,
                       Fill&& fill, Gap&& gap) {
  if (begin >= end) return;
  std::size_t p = begin;
  if (mask.hasFills()) {
    const uint32_t* f = mask.fills.data() + 3 * std::size_t{mask.rowFills[2 * stored]};
    const uint32_t* const last = f + 3 * std::size_t{mask.rowFills[2 * stored + 1]};
    for (; f != last && f[0] < end; f += 3) {
      if (f[1] <= p) continue;
      const std::size_t a = f[0] > p ? f[0] : p, b = f[1] < end ? f[1] : end;
      if (p < a) gap(p, a);
      fill(a, b, static_cast<uint8_t>(f[2]));
      p = b;
    }
  }
  if (p < end) gap(p, end);
}

// For a coder that goes down the image (stored rows in decreasing order, as PNG and EXR files run) and
// reads the stretches forEachRowStretch gives it: the pixels of the stored row it reads
// kCoderRowsAhead rows after `stored` (its own where none is left), where it prefetches the stretches
// it reads in `stored`. Edges move little from row to row, and the rasterizer wrote those pixels a
// whole layer before, a row apart in an image that may be larger than the caches.
constexpr std::size_t kCoderRowsAhead = 3;
inline const uint8_t* rowAhead(const MaskImage& mask, std::size_t stored) {
  return mask.pixels.data() + (stored >= kCoderRowsAhead ? stored - kCoderRowsAhead : stored) * mask.width;
}

}  // namespace toposlice
