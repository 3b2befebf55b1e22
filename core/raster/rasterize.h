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
// - Coverage (exact): pixel (i, j) gets round(255 * A / p^2), A the area of the positive-winding region
//   inside the pixel's square, computed analytically (no sub-sampling). Each pixel row is cut into
//   horizontal sub-bands at the y of every vertex inside it and, where two edges cross inside the row,
//   at the crossing; inside a sub-band no edge starts, ends or crosses another, so the winding is
//   constant between consecutive edges and the region's boundary there is the set of edges where the
//   count passes from <= 0 to > 0 (+1) or back (-1). Each such boundary segment adds, per pixel it
//   crosses, (signed) dy times the part of the pixel right of it, split over the pixel and its right
//   neighbour as area and cover (the accumulation of scanline font rasterizers); a prefix sum along the
//   row then gives every pixel's covered area, so the cost is the edge pixels plus the runs between
//   them, which are filled, and dark pixels are never touched.
//   Clusters (most rows, no cutting): where the count is 0 or 1 everywhere in the row, every edge is a
//   boundary and accumulates with its own winding, nothing to decide. The row's edge parts are grouped
//   into clusters of touching u ranges (parts of different clusters never meet, so the count between
//   clusters is the same at every y); a cluster is proven to keep the count in {0, 1} either as one
//   chain of one winding from the row's bottom to its top, or, for clusters holding local extremes of
//   the loops, by checking that no two parts meet except loop neighbours at their shared vertex, that no
//   loop lies inside the row, and that the count stays in {0, 1} along the row's bottom and top lines
//   (every region between the parts then touches one of those lines). Where the same checks find the
//   count at least 1 all round instead (a grown layer's detour tip inside the grown region: counts 1
//   and 2), no part is a boundary and the cluster adds nothing. A cluster where any of this fails
//   (overlapping loops, crossings, a horizontal edge inside the row, whose u range then joins the
//   cluster, a loop inside one row) is decided with its own edges alone, starting from the count left
//   of it, so its pixels do not depend on other parts in the row (a plate's other parts). With at most
//   16 edges (a grown layer's detour, two loops crossing), part by part: each edge's part in the row is
//   cut where another part crosses it, where an end of another part lies on it and at the height of
//   every horizontal edge inside the row; then nothing crosses a piece and the count beside it is the
//   same all along it, so the piece is a boundary where the counts just left and just right of it,
//   taken along the horizontal line through its middle (half-open, as the sample lines), lie on both
//   sides of 0 (coincident pieces decide together). Larger clusters take the banded path below.
//   Banded path: when the row's edges link, vertex to vertex, into chains that each run from the row's
//   bottom to its top with one winding, and neighbouring chains (ordered at the bottom) never swap
//   sides (checked at every vertex of either), the order is the same at every y of the row: the
//   boundary is decided once per chain and no sub-bands are needed (chains that touch or coincide are
//   fine: the +1/-1 steps of two neighbours add up to the step across both). Any other row takes the
//   sub-bands.
//   Exception, for pathological input only: a band where edges cross and more than 64 edges overlap
//   (e.g. a self-intersecting loop of thousands of random vertices) is not cut at its crossings, which
//   would cost O(edges^3) per row, but sampled by 16 lines per pixel height, exact in x (the midpoint
//   rule in y: each crossing, vertex or run end between two lines adds at most 1/16 of a pixel's area).
//   Coincident edges of opposite sign (a removal equal to the model) cancel exactly: edges are interpolated
//   from their lower end and summed. Rounding rule: value = floor(255 * a + 1/2) with a the computed fraction
//   clamped to [0, 1] (halves round up). a is exact up to floating-point rounding (relative 1e-12 of a pixel
//   in practice), so a value differs from the exact area's rounding only when 255 * area is within about 1e-9
//   of a half.
// Mirroring (grid.mirrorX/mirrorY) is applied when writing: pixel i goes to width-1-i, row j to
// height-1-j. Contours may extend beyond the grid; they are clipped, never wrapped.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "core/raster/mask_image.h"
#include "core/slicing/contours.h"

namespace toposlice {

// One layer's contours with the sign of their contribution: +1 for the model and add-on features,
// -1 for removal features.
struct ContourSet {
  const LayerContours* layer;
  int sign;
};

// An edge of the exact coverage rasterizer in pixel units, from its lower end (v0 < v1).
struct CoverageEdge {
  double u0, v0, u1, v1;
  double slope;       // du/dv (0 where it overflows)
  uint32_t firstRow;  // first pixel row it overlaps
  uint32_t endRow;    // one past the last
  int32_t winding;    // change of the winding count when crossing it left to right
  uint32_t id;        // index in RasterScratch::coverageEdges
  int32_t above;      // id of the edge of the same loop that continues it upwards from (u1, v1), or -1
  int32_t atTop;      // id of its loop neighbour at (u1, v1), or -1 (horizontal or not in the table)
  int32_t atBottom;   // id of its loop neighbour at (u0, v0), or -1
  bool rowLoop;       // its loop lies inside one pixel row
};

// An edge's span of one sub-band: u at the bottom, middle and top.
struct CoveragePiece {
  double ua, um, ub;
  uint32_t edge;  // index into the active list
  int32_t winding;
};

// An edge's part inside the current pixel row (fast path): u at the bottom and top of the part, its
// y range, the next part of its chain (or -1) and the edge (index into the active list).
struct CoverageRowPiece {
  double ua, ub, va, vb;
  int32_t next;
  uint32_t edge;
  bool linked;  // some piece continues into this one
};

// A chain spanning a band of the row: u at the band's bottom and top, its piece at the bottom.
struct ChainCursor {
  double ua, ub;
  double lo, hi;  // u range of its pieces that meet the band (a superset of its range in the band)
  uint32_t first;
};

// An edge overlapping the current row: u at the row's bottom (its sort key) and its index.
struct ActiveKey {
  double x;
  uint32_t index;
};

// Parts [begin, end) of a row's pieces whose u ranges touch (coverClusteredRow): their u range, how
// many start at the row's bottom (the last one: head) and end at its top, parts starting inside the
// row minus parts ending inside it, their winding (0 where they differ), and whether every part ending
// inside the row is continued by the next edge of its chain. They form one chain from the row's bottom
// to its top when chain() holds.
struct RowCluster {
  uint32_t begin, end, head;
  double lo, hi;
  int32_t bottoms, tops, inside, winding;
  bool continued;
  bool loop = false;      // holds a part of a loop that lies inside the row
  int32_t left = 0;       // the count left of the cluster
  int32_t net = 0;        // the count's change across it (its parts' windings along the row's bottom)
  bool accepted = false;  // the count provably stays in {0, 1}: accumulated without bands
  bool interior = false;  // the count provably stays at least 1: no part is a boundary
  bool chain() const { return winding != 0 && continued && bottoms == 1 && tops == 1 && inside == 0; }
};

// A part crossing the bottom or top line of a row: u there, the order of parts at the same u, winding.
struct LineCrossing {
  double u, slope;
  int32_t winding;
};

// Cells [begin, end] of a row touched by one boundary segment.
struct CellSpan {
  uint32_t begin, end;
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
  uint32_t next;      // index in RasterScratch::edges of the edge taking its place at line `end`, or none
};

// Reusable buffers of the rasterizers (one per thread). Nothing needs clearing between calls; memory
// depends on the layer's edge count and the grid size, never on the number of layers.
struct RasterScratch {
  std::vector<RasterEdge> edges;      // edges crossing the grid's sample lines, in input order
  std::vector<RasterEdge> bucketed;   // chain heads (not `linked`), grouped by first sample line
  std::vector<uint32_t> bucketStart;  // sample lines + 1 offsets into bucketed
  std::vector<RasterEdge> active;     // edges crossing the current sample line, sorted by x
  std::vector<RasterEdge> incoming;   // chains whose first sample line is the current one (many)
  std::vector<uint32_t> previousRuns, previousRowRuns;  // the image's runs before this call (binary)
  std::vector<uint32_t> lineOfPoint;                    // first sample line at or above each point of a loop
  std::vector<uint8_t> linked;  // per edge: 1 where an edge before it in its chain hands on to it
  // Exact coverage (pixel units: u = (x - x0) / p, v = (y - y0) / p).
  std::vector<CoverageEdge> coverageEdges;       // non-horizontal edges overlapping the grid's rows
  std::vector<CoverageEdge> coverageBucketed;    // the same, grouped by first row
  std::vector<uint32_t> coverageRowStart;        // height + 1 offsets into coverageBucketed
  std::vector<CoverageEdge> coverageActive;      // the same edges (or a cluster's), copied for coverRow
  std::vector<uint32_t> clusterEdgeStart;        // where each cluster's edges start in coverageActive
  std::vector<std::array<double, 2>> flatReach;  // u range of each edge's horizontal neighbours (if any)
  std::vector<ActiveKey> activeKeys;             // edges overlapping the current row (coverageBucketed)
  std::vector<RowCluster> clusters;              // clusters of the current row's parts
  std::vector<LineCrossing> lineCrossings;       // one cluster's crossings of a row line
  std::vector<CoveragePiece> pieces;             // active edges spanning the current sub-band
  std::vector<CoverageRowPiece> rowPieces;       // active edges clipped to the current row
  std::vector<uint32_t> pieceOfEdge;             // row piece of each edge id (valid where it points back)
  std::vector<int32_t> loopIds;                  // edge ids of one loop while the table is built
  std::vector<uint32_t> chainStarts;  // fast path: pieces starting inside the row, then chain heads
  std::vector<double> rowCuts;        // where chains start or end inside the row
  std::vector<ChainCursor> chains;    // chains spanning the current band
  std::vector<double> bandYs;         // sub-band limits of the current row
  std::vector<double> smallCuts;      // where a small cluster's parts are cut (coverSmallCluster)
  std::vector<double> cells;          // area/cover accumulation of the row (width + 2)
  std::vector<CellSpan> spans;        // cell ranges touched in the row
  std::vector<uint32_t> rowFills;     // the row's fills as they are found (coverage)
  // Tests only: every row of rasterizeCoverage by the banded path (coverRow), none by the clusters.
  bool alwaysBanded = false;
  // Rows of rasterizeCoverage done by clusters alone (of them, rows with a cluster that is not one
  // chain) and rows where some cluster (or, with alwaysBanded, the row) took the banded path, summed;
  // and clusters the cluster proof did not accept that were decided part by part (small ones).
  std::size_t clusteredRows = 0, extremeRows = 0, bandedRows = 0, smallClusters = 0;
  std::size_t interiorClusters = 0;  // clusters with the count at least 1 all round: nothing to add
};

// A light-uniformity map: relative intensities (0-255) in a mask's stored order, with the stretches of
// one value in each row, so that a lit run is dimmed one stretch at a time: row r's stretches start at
// starts[rowFirst[r]], ..., starts[rowFirst[r + 1] - 1] (the first at 0), each ending where the next
// starts or at the row's end.
struct LightMap {
  uint32_t width = 0, height = 0;
  std::vector<uint8_t> pixels;
  std::vector<uint32_t> starts, rowFirst;
  bool empty() const { return pixels.empty(); }
};
LightMap lightMapOf(const MaskImage& map);

// A non-decreasing map of the exact covered fraction a in [0, 1] to a value 0-255 (gamma, a threshold),
// given by its steps: value(a) is the number of v in 1..255 with a >= thresholds[v], so that it is
// exact on the coverage itself, not on the coverage rounded to 8 bits first (which dropped every pixel
// under 1/510 covered, whatever the gamma). thresholds[v] > 0 (value(0) = 0: dark pixels stay dark) and
// non-decreasing in v. A table of the value at k / kSteps gives the start of a short search.
struct CoverageCurve {
  static constexpr uint32_t kSteps = 4096;
  std::array<double, 257> thresholds{};  // [0] unused; [256] infinity, which ends every search
  std::array<uint8_t, kSteps + 1> start{};
  uint8_t value(double a) const {
    if (!(a > 0)) return 0;
    if (a >= 1) return start[kSteps];
    unsigned v = start[static_cast<std::size_t>(a * kSteps)];
    while (a >= thresholds[v + 1]) ++v;
    return static_cast<uint8_t>(v);
  }
};
// The curve of `thresholds` (thresholds[1..255] as above; [0] is ignored).
CoverageCurve coverageCurve(const std::array<double, 256>& thresholds);

// Optional transfer applied as the coverage values are written (gamma, threshold, light map), so that
// it costs no second pass over the image:
// - curve: the written value is curve->value(a) instead of round(255 a) (gamma, a threshold).
// - row: called once per row holding a non-zero value, right after the row is written (in cache), with
//   the stored row index r (after mirroring) and the row's lit extent [begin, end); it may change any
//   value in that span (a light-uniformity map scales it; values may become 0) but none outside it.
//   The extent is then trimmed of zeros at its ends and the value sum taken from the span.
// - lightMap: a light-uniformity map of the grid's size (lightMapOf); every written value v (after the
//   table) becomes round(v * m / 255), m the map's value at that pixel, as it is written: only lit
//   pixels are touched, a run between edge pixels with one value per stretch of the map, and those
//   stretches are listed as fills (one dimmed to 0 too, like the dark stretches between parts). The
//   extents are trimmed of pixels dimmed to 0 at their ends. Not together with `row`.
// valueSum is the sum of round(255 a) whatever the curve and the light map (the part's area: gamma and
// the map change the light, not the part), or with a row hook the sum of the values it leaves.
struct LightMap;
struct CoverageTransfer {
  const CoverageCurve* curve = nullptr;
  const LightMap* lightMap = nullptr;
  void (*row)(void* context, uint32_t r, uint32_t begin, uint32_t end, uint8_t* rowPixels) = nullptr;
  void* context = nullptr;
};

// Binary mask of the sets' positive-winding region. Every set's layer is non-null, sign is +1 or -1;
// grid.pixel > 0 and grid.width * grid.height fits in memory. `out` is resized to width x height and
// holds the mask (255 solid, 0 empty). O(edges + crossings log + width*height) per call; when `out`
// already holds a binary mask of the same size with its runs (the previous layer), only the rows whose
// runs changed are rewritten: O(edges + crossings log + height + changed rows' pixels).
// When litPixels is given it receives the number of lit pixels (counted from the runs, no extra pass).
void rasterizeBinary(std::span<const ContourSet> sets, const PixelGrid& grid, MaskImage& out,
                     RasterScratch& scratch, uint64_t* litPixels = nullptr);

// Anti-aliased mask: each pixel holds round(255 * covered fraction) of the positive-winding region,
// computed exactly (see the file comment for the rounding rule), then mapped through `transfer` when
// given. Same preconditions and output layout as rasterizeBinary, and the same lit extents (tight, dark
// pixels untouched; only the previous image's lit spans are cleared), plus the fills (MaskImage::fills:
// the stretches of 8 or more pixels written with one value between edge pixels) unless the transfer
// has a row hook. When valueSum is given it
// receives the sum of all pixel values (maskArea without a pass over the image).
// O(edges + vertices * active edges + edge pixels + lit runs) per call; rows where edges cross cost
// O(active^2) for finding the crossings.
void rasterizeCoverage(std::span<const ContourSet> sets, const PixelGrid& grid, MaskImage& out,
                       RasterScratch& scratch, uint64_t* valueSum = nullptr,
                       const CoverageTransfer* transfer = nullptr);

// Number of loops of the sets that the rasterizers ignore: open polylines (loopClosed == 0) and closed
// loops with a non-finite coordinate. The caller reports them.
std::size_t countSkippedLoops(std::span<const ContourSet> sets);

// Number of pixels of `mask` with a non-zero value.
std::size_t countLitPixels(const MaskImage& mask);

// Solid area of a mask in mm^2: sum of pixel values / 255 times pixel^2 (for a binary mask, the lit
// pixel count times pixel^2). `pixel` is the grid's pixel edge length in mm.
double maskArea(const MaskImage& mask, double pixel);

}  // namespace toposlice
