// Scanline rasterizer: one layer's oriented contours to a mask image (DESIGN.md, the paper's section 5).
//
// Winding (the paper's positive rule): every closed loop of every contour set adds its winding number,
// times the set's sign, to one count; a point is solid where the count is > 0. Outer loops are CCW (+1),
// holes CW (-1); a removal feature is passed with sign -1 (its contours reversed), so it subtracts one
// level: over an add-on that overlaps the model (count 2) it leaves count 1, which stays solid. Loops
// with loopClosed == 0 (open polylines) and loops with a non-finite coordinate take no part; see
// countSkippedLoops.
//
// Sampling rules, settled once (all tests rely on them):
// - Sample line v crosses edge (a, b) when (a.y <= v) != (b.y <= v) (half-open in y): a vertex exactly
//   on a sample line is counted once where the boundary passes through it and twice or not at all at a
//   local extreme; horizontal edges never cross. The crossing x is interpolated from the edge's lower
//   end, so an edge and its reverse give bit-identical crossings (a removal equal to the model cancels).
// - Along a sample line, crossings at equal x are summed before the count is tested, so the result
//   does not depend on their order. A solid run is [xa, xb) (half-open in x): a sample exactly on the
//   left/bottom boundary of a solid region is inside, on the right/top boundary outside. Two solids
//   sharing an edge therefore light every pixel centre on it exactly once.
// - Binary: pixel (i, j) is 255 when its centre (x0 + (i+1/2) p, y0 + (j+1/2) p) is solid, else 0.
// - Coverage: each pixel row is sampled by S sub-scanlines at y0 + (j + (s+1/2)/S) p, s = 0..S-1; along
//   each, the solid fraction f_s of every pixel's width is exact (fractional at run ends), and the
//   pixel value is round(255 * sum_s f_s / S) (halves round up). This is the midpoint rule in y: exact
//   over every sub-band where f varies linearly with y; a sub-band holding a vertex, a horizontal edge,
//   an edge crossing a pixel column boundary or two edges crossing adds at most 1/S to the pixel's
//   fraction (in practice far less; e.g. a horizontal edge adds at most 1/(2S)). The total area is
//   exact up to the midpoint error of the total solid width (piecewise linear in y, kinks only at
//   vertices and crossings) plus at most 0.5/255 of a pixel per partially covered pixel from rounding.
// Mirroring (grid.mirrorX/mirrorY) is applied when writing: pixel i goes to width-1-i, row j to
// height-1-j. Contours may extend beyond the grid; they are clipped, never wrapped.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "core/contours.h"
#include "core/mask_image.h"

namespace toposlice {

// One layer's contours with the sign of their contribution: +1 for the model and add-on features,
// -1 for removal features.
struct ContourSet {
  const LayerContours* layer;
  int sign;
};

// An edge that crosses at least one sample line, oriented from its lower end. `x` is its crossing with
// the current sample line while it is active.
struct RasterEdge {
  double x;
  double xLow, yLow;  // lower end
  double slope;       // dx/dy (0 for an edge so flat that dx/dy overflows)
  uint32_t first;     // first sample line crossed
  uint32_t end;       // one past the last sample line crossed
  int32_t winding;    // change of the winding count when crossing it left to right
};

// Reusable buffers of the rasterizers (one per thread). Nothing needs clearing between calls; memory
// depends on the layer's edge count and the grid size, never on the number of layers.
struct RasterScratch {
  std::vector<RasterEdge> edges;      // edges crossing the grid's sample lines, in input order
  std::vector<RasterEdge> bucketed;   // the same, grouped by first sample line (count, prefix sum, fill)
  std::vector<uint32_t> bucketStart;  // sample lines + 1 offsets into bucketed
  std::vector<RasterEdge> active;     // edges crossing the current sample line, sorted by x
  std::vector<double> partial;        // coverage: fractional solid length per pixel of the row
  std::vector<int32_t> fullDelta;     // coverage: difference array of whole-pixel counts (width + 1)
  std::vector<uint32_t> pixelStamp;   // coverage: last row that listed each pixel in `events`
  std::vector<uint32_t> events;       // coverage: pixels of the row with a fractional part or a count change
};

inline constexpr uint32_t kDefaultSubScanlines = 16;

// Binary mask of the sets' positive-winding region. Every set's layer is non-null, sign is +1 or -1;
// grid.pixel > 0 and grid.width * grid.height fits in memory. `out` is resized to width x height and
// every pixel is written (255 solid, 0 empty). O(edges + crossings log + width*height) per call.
// When litPixels is given it receives the number of lit pixels (counted from the runs, no extra pass).
void rasterizeBinary(std::span<const ContourSet> sets, const PixelGrid& grid, MaskImage& out,
                     RasterScratch& scratch, uint64_t* litPixels = nullptr);

// Anti-aliased mask: each pixel holds round(255 * covered fraction) of the positive-winding region,
// sampled with `subScanlines` (S, 1..256) sub-scanlines per row and exact coverage along each (see the
// file comment for the error bound). Same preconditions and output layout as rasterizeBinary; S is
// lowered where grid.height * S would not fit in 32 bits. O(edges + S * crossings + width*height).
void rasterizeCoverage(std::span<const ContourSet> sets, const PixelGrid& grid, MaskImage& out,
                       RasterScratch& scratch, uint32_t subScanlines = kDefaultSubScanlines);

// Number of loops of the sets that the rasterizers ignore: open polylines (loopClosed == 0) and closed
// loops with a non-finite coordinate. The caller reports them.
std::size_t countSkippedLoops(std::span<const ContourSet> sets);

// Number of pixels of `mask` with a non-zero value.
std::size_t countLitPixels(const MaskImage& mask);

// Solid area of a mask in mm^2: sum of pixel values / 255 times pixel^2 (for a binary mask, the lit
// pixel count times pixel^2). `pixel` is the grid's pixel edge length in mm.
double maskArea(const MaskImage& mask, double pixel);

}  // namespace toposlice
