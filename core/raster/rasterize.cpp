#include "core/raster/rasterize.h"

#include <algorithm>
#include <bit>
#include <cassert>
#include <cmath>
#include <cstring>
#include <limits>

#include "core/prefetch.h"

// Scanline conversion with an active edge table: edges are bucketed by the first sample line they cross
// (count, prefix sum, fill), the active list is kept sorted by x from one sample line to the next
// (insertion sort on nearly sorted data) and swept left to right accumulating the winding count.

namespace toposlice {
namespace {

// Bands where edges cross are cut at every crossing, found pairwise: exact, but O(edges^2) per band and
// O(edges^3) per row when most pairs cross. Above this many edges such a band is sampled instead.
constexpr std::size_t kMaxExactCrossingEdges = 64;
constexpr double kSampleLinesPerPixel = 16.0;
// Shortest constant stretch of an anti-aliased row listed in MaskImage::fills (shorter ones cost the
// PNG coder less to read than to look up).
constexpr uint32_t kMinFill = 8;
// Above this many edges starting on one sample line, they are sorted apart and merged into the active
// list (advanceTo).
constexpr uint32_t kMergeIncoming = 32;

double samplePosition(double origin, double pitch, uint32_t k) {
  return origin + (static_cast<double>(k) + 0.5) * pitch;
}

// Smallest k in [0, count] with samplePosition(k) >= v (count when there is none). The product with
// 1 / pitch only guesses; the answer is settled with the same expression every caller uses for the
// sample position.
uint32_t firstSampleAtOrAbove(double v, double origin, double pitch, double inversePitch, uint32_t count) {
  const double guess = std::ceil((v - origin) * inversePitch - 0.5);
  uint32_t k = 0;
  if (guess >= static_cast<double>(count)) {
    k = count;
  } else if (guess > 0.0) {
    k = static_cast<uint32_t>(guess);
  }
  while (k > 0 && samplePosition(origin, pitch, k - 1) >= v) --k;
  while (k < count && samplePosition(origin, pitch, k) < v) ++k;
  return k;
}

bool allFinite(std::span<const Point2d> loop) {
  for (const Point2d& p : loop) {
    if (!std::isfinite(p.x) || !std::isfinite(p.y)) return false;
  }
  return true;
}

// Calls f(loop, sign) for every closed loop with finite points of every set (open polylines and loops
// with a NaN or infinity enclose nothing). On a transposed grid (x and y swapped, see gridPoint) every
// loop runs the other way round: the sign given is then the set's negated, so that the loop's points,
// swapped, and this sign give the set's region.
template <class F>
void forEachClosedFiniteLoop(std::span<const ContourSet> sets, bool transposed, F&& f) {
  for (const ContourSet& set : sets) {
    assert(set.layer != nullptr && (set.sign == 1 || set.sign == -1));
    const LayerContours& layer = *set.layer;
    for (std::size_t l = 0; l < layer.loopCount(); ++l) {
      if (layer.loopClosed[l] == 0) continue;
      const std::span<const Point2d> loop = layer.loopPoints(l);
      if (allFinite(loop)) f(loop, transposed ? -set.sign : set.sign);
    }
  }
}

// A model point in the grid's axes (PixelGrid::transposed: x and y swapped).
Point2d gridPoint(Point2d p, bool transposed) {
  return transposed ? Point2d{p.y, p.x} : p;
}

// Groups the edges i of `edges` with keep(i) by first(edge) < count, keeping their order inside a group
// (a counting sort): bucketed[start[k], start[k + 1]) are those whose first is k.
template <class Edge, class First, class Keep>
void bucketByFirst(const std::vector<Edge>& edges, uint32_t count, First first, Keep keep,
                   std::vector<Edge>& bucketed, std::vector<uint32_t>& start) {
  start.assign(static_cast<std::size_t>(count) + 1, 0);
  std::size_t kept = 0;
  for (std::size_t i = 0; i < edges.size(); ++i)
    if (keep(i)) {
      ++start[first(edges[i]) + 1];
      ++kept;
    }
  for (uint32_t k = 0; k < count; ++k) start[k + 1] += start[k];
  bucketed.resize(kept);
  for (std::size_t i = 0; i < edges.size(); ++i)
    if (keep(i)) bucketed[start[first(edges[i])]++] = edges[i];  // start[k] becomes start[k+1]
  for (uint32_t k = count; k > 0; --k) start[k] = start[k - 1];
  start[0] = 0;
}

constexpr uint32_t kNoEdge = std::numeric_limits<uint32_t>::max();

// Links the edges of one loop, edges[begin, end) in loop order, into chains: where an edge ends at
// sample line k and the next edge of the loop running the same way (upwards: the next one; downwards:
// the previous one) starts at k, that edge takes its place in the active list (RasterEdge::next).
// Consecutive edges of a loop meet, so the one that follows sits where the one before was: the active
// list stays in order from line to line, where appending it would have moved it through the list. The
// links are only a placement: every edge is still active on exactly the lines it crosses.
void linkChains(std::vector<RasterEdge>& edges, std::size_t begin, std::size_t end, int32_t sign,
                std::vector<uint8_t>& linked) {
  for (std::size_t m = begin; m < end; ++m) {
    const std::size_t n = m + 1 == end ? begin : m + 1;
    RasterEdge& p = edges[m];
    RasterEdge& q = edges[n];
    if (m == n || p.winding != q.winding) continue;
    const bool upward = p.winding == -sign;
    RasterEdge& lower = upward ? p : q;
    RasterEdge& upper = upward ? q : p;
    if (upper.first != lower.end) continue;
    lower.next = static_cast<uint32_t>(upward ? n : m);
    linked[upward ? n : m] = 1;
  }
}

// Collects the edges of all closed, finite loops that cross at least one of `count` sample lines
// origin + (k + 1/2) pitch, links them into chains (linkChains), then groups the chains' first edges
// by first line into scratch.bucketed / bucketStart.
void buildEdgeTable(std::span<const ContourSet> sets, double origin, double pitch, uint32_t count,
                    bool transposed, RasterScratch& scratch) {
  std::vector<RasterEdge>& edges = scratch.edges;
  std::vector<uint8_t>& linked = scratch.linked;
  edges.clear();
  linked.clear();
  const double inversePitch = 1.0 / pitch;
  std::vector<uint32_t>& lineOf = scratch.lineOfPoint;
  forEachClosedFiniteLoop(sets, transposed, [&](std::span<const Point2d> loop, int32_t sign) {
    const std::size_t n = loop.size();
    const std::size_t begin = edges.size();
    // The first sample line at or above each point: an edge crosses the lines from its lower end's to
    // its upper end's (none when they are equal, as for a horizontal edge: the half-open rule).
    lineOf.resize(n);
    for (std::size_t i = 0; i < n; ++i)
      lineOf[i] = firstSampleAtOrAbove(gridPoint(loop[i], transposed).y, origin, pitch, inversePitch, count);
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t i1 = i + 1 == n ? 0 : i + 1;
      if (lineOf[i] == lineOf[i1]) continue;
      const Point2d a = gridPoint(loop[i], transposed);
      const Point2d b = gridPoint(loop[i1], transposed);
      const bool upward = a.y < b.y;  // the lines differ, so the heights do, in the same order
      const Point2d lo = upward ? a : b;
      const Point2d hi = upward ? b : a;
      const uint32_t first = upward ? lineOf[i] : lineOf[i1];
      const uint32_t end = upward ? lineOf[i1] : lineOf[i];
      double slope = (hi.x - lo.x) / (hi.y - lo.y);
      if (!std::isfinite(slope)) slope = 0.0;  // dy is so small that any x of the edge is as good
      // A CCW outer loop runs downwards on its left side: crossing it left to right enters the solid.
      const int32_t winding = upward ? -sign : sign;
      edges.push_back(RasterEdge{0.0, lo.x, lo.y, slope, first, end, winding, kNoEdge});
    }
    linked.resize(edges.size(), 0);
    linkChains(edges, begin, edges.size(), sign, linked);
  });

  bucketByFirst(
      edges, count, [](const RasterEdge& e) { return e.first; },
      [&](std::size_t m) { return linked[m] == 0; }, scratch.bucketed, scratch.bucketStart);

  scratch.active.clear();
  scratch.active.reserve(edges.size());
}

// Sorts by x. Insertion sort while the data is nearly sorted (the usual case from one sample line to the
// next); falls back to std::sort once the moves exceed a budget linear in the size.
void sortByX(std::vector<RasterEdge>& edges) {
  const std::size_t n = edges.size();
  std::size_t budget = 4 * n + 64;
  for (std::size_t i = 1; i < n; ++i) {
    const RasterEdge e = edges[i];
    std::size_t j = i;
    while (j > 0 && edges[j - 1].x > e.x) {
      edges[j] = edges[j - 1];
      --j;
      if (--budget == 0) {
        edges[j] = e;
        std::sort(edges.begin(), edges.end(),
                  [](const RasterEdge& p, const RasterEdge& q) { return p.x < q.x; });
        return;
      }
    }
    edges[j] = e;
  }
}

// Moves the active edge table to sample line k at height y: an edge that ended hands its place to the
// next edge of its chain (or leaves), the chains starting on line k are added, every crossing is computed
// and the list sorted by x. The list stays nearly sorted from line to line (insertion sort); a few new
// chains are appended and moved into place by it, many (the parts of a plate) are sorted on their own
// and merged in, so that they do not make the whole line's order be sorted again. Edges of equal x may
// come in any order: the runs sum their windings first.
void advanceTo(uint32_t k, double y, RasterScratch& scratch) {
  std::vector<RasterEdge>& active = scratch.active;
  const RasterEdge* edges = scratch.edges.data();
  std::size_t kept = 0;
  for (std::size_t i = 0; i < active.size(); ++i) {
    RasterEdge e = active[i];
    if (e.end <= k) {
      if (e.next == kNoEdge) continue;
      e = edges[e.next];
      assert(e.first == k);
    }
    e.x = e.xLow + (y - e.yLow) * e.slope;
    active[kept++] = e;
  }
  active.resize(kept);
  const uint32_t b0 = scratch.bucketStart[k], b1 = scratch.bucketStart[k + 1];
  if (b1 - b0 <= kMergeIncoming) {  // a few: appended and moved into place by the insertion sort
    for (uint32_t b = b0; b < b1; ++b) {
      RasterEdge e = scratch.bucketed[b];
      e.x = e.xLow + (y - e.yLow) * e.slope;
      active.push_back(e);
    }
    sortByX(active);
    return;
  }
  sortByX(active);
  std::vector<RasterEdge>& incoming = scratch.incoming;
  incoming.assign(scratch.bucketed.begin() + b0, scratch.bucketed.begin() + b1);
  for (RasterEdge& e : incoming) e.x = e.xLow + (y - e.yLow) * e.slope;
  sortByX(incoming);
  // Merged from the back, in place.
  active.resize(kept + incoming.size());
  std::size_t w = active.size(), i = kept, j = incoming.size();
  while (j > 0) {
    if (i > 0 && active[i - 1].x > incoming[j - 1].x)
      active[--w] = active[--i];
    else
      active[--w] = incoming[--j];
  }
}

bool hasWork(uint32_t k, const RasterScratch& scratch) {
  return !scratch.active.empty() || scratch.bucketStart[k] != scratch.bucketStart[k + 1];
}

// Calls emit(xa, xb) for each maximal run [xa, xb) of positive winding along the current sample line.
// Crossings at the same x are summed first, so their order does not matter.
template <class Emit>
void forEachSolidRun(std::span<const RasterEdge> active, Emit&& emit) {
  int32_t winding = 0;
  double runStart = 0.0;
  std::size_t i = 0;
  while (i < active.size()) {
    const double x = active[i].x;
    int32_t next = winding;
    do {
      next += active[i].winding;
      ++i;
    } while (i < active.size() && active[i].x == x);
    if (winding <= 0 && next > 0) {
      runStart = x;
    } else if (winding > 0 && next <= 0) {
      emit(runStart, x);
    }
    winding = next;
  }
}

bool usableGrid(const PixelGrid& grid) {
  return grid.pixel > 0.0 && std::isfinite(grid.pixel);
}

// ---- Exact coverage ----

// u of edge e at height v, exact at its ends (so consecutive edges of a loop meet exactly) and kept
// within its u range elsewhere.
inline double edgeU(const CoverageEdge& e, double v) {
  if (v <= e.v0) return e.u0;
  if (v >= e.v1) return e.u1;
  const double u = e.u0 + (v - e.v0) * e.slope;
  return std::clamp(u, std::min(e.u0, e.u1), std::max(e.u0, e.u1));
}

// Collects the non-horizontal edges of all closed, finite loops that overlap rows [0, height) in pixel
// units, grouped by first row into scratch.coverageBucketed / coverageRowStart.
void buildCoverageTable(std::span<const ContourSet> sets, const PixelGrid& grid, RasterScratch& scratch) {
  std::vector<CoverageEdge>& edges = scratch.coverageEdges;
  edges.clear();
  scratch.flatReach.clear();
  const uint32_t height = grid.height;
  const double inv = 1.0 / grid.pixel;
  const double top = static_cast<double>(height);
  forEachClosedFiniteLoop(sets, grid.transposed, [&](std::span<const Point2d> loop, int32_t sign) {
    const std::size_t n = loop.size();
    std::vector<int32_t>& ids = scratch.loopIds;
    ids.assign(n, -1);
    double vLow = std::numeric_limits<double>::infinity(), vHigh = -vLow;  // of its edges in the table
    for (std::size_t i = 0; i < n; ++i) {
      const Point2d a = gridPoint(loop[i], grid.transposed);
      const Point2d b = gridPoint(loop[i + 1 == n ? 0 : i + 1], grid.transposed);
      const double av = (a.y - grid.y0) * inv, bv = (b.y - grid.y0) * inv;
      if (av == bv) continue;  // horizontal: encloses no area of its own
      const bool upward = av < bv;
      const double v0 = upward ? av : bv, v1 = upward ? bv : av;
      if (v1 <= 0.0 || v0 >= top) continue;
      const double u0 = ((upward ? a.x : b.x) - grid.x0) * inv;
      const double u1 = ((upward ? b.x : a.x) - grid.x0) * inv;
      double slope = (u1 - u0) / (v1 - v0);
      if (!std::isfinite(slope)) slope = 0.0;
      const uint32_t first = v0 <= 0.0 ? 0 : static_cast<uint32_t>(v0);
      const uint32_t end = v1 >= top ? height : static_cast<uint32_t>(std::ceil(v1));
      if (first >= end) continue;
      const int32_t winding = upward ? -sign : sign;
      ids[i] = static_cast<int32_t>(edges.size());
      edges.push_back(CoverageEdge{u0, v0, u1, v1, slope, first, end, winding,
                                   static_cast<uint32_t>(edges.size()), -1, -1, -1, false});
      scratch.flatReach.push_back(
          {std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity()});
      vLow = std::min(vLow, v0);
      vHigh = std::max(vHigh, v1);
    }
    // The loop's neighbours at each end: for an upward edge the next edge is at its top and the
    // previous one at its bottom, for a downward edge the other way round. The neighbour at the top
    // continues the chain upwards when it runs the same way (else the chain ends there).
    const bool inOneRow = vLow <= vHigh && std::ceil(vHigh) - std::floor(vLow) <= 1.0;
    for (std::size_t i = 0; i < n; ++i) {
      if (ids[i] < 0) continue;
      CoverageEdge& e = edges[static_cast<std::size_t>(ids[i])];
      const bool upward = e.winding == -sign;
      const int32_t next = ids[i + 1 == n ? 0 : i + 1], previous = ids[i == 0 ? n - 1 : i - 1];
      e.atTop = upward ? next : previous;
      e.atBottom = upward ? previous : next;
      if (e.atTop >= 0 && edges[static_cast<std::size_t>(e.atTop)].winding == e.winding) e.above = e.atTop;
      e.rowLoop = inOneRow;
      // Horizontal neighbours: the u range of the horizontal edges that follow the edge's ends (they
      // join the edge to the loop's next non-horizontal edge across that range; see coverRowByClusters).
      if (next >= 0 && previous >= 0) continue;
      std::array<double, 2>& reach = scratch.flatReach[static_cast<std::size_t>(ids[i])];
      const auto flat = [&](std::size_t k) {
        const Point2d a = gridPoint(loop[k], grid.transposed),
                      b = gridPoint(loop[k + 1 == n ? 0 : k + 1], grid.transposed);
        return (a.y - grid.y0) * inv == (b.y - grid.y0) * inv;
      };
      const auto extend = [&](std::size_t k) {
        const double u = (gridPoint(loop[k], grid.transposed).x - grid.x0) * inv;
        reach[0] = std::min(reach[0], u);
        reach[1] = std::max(reach[1], u);
      };
      for (std::size_t k = i + 1 == n ? 0 : i + 1, steps = 0; steps < n && flat(k);
           k = k + 1 == n ? 0 : k + 1, ++steps)
        extend(k + 1 == n ? 0 : k + 1);
      for (std::size_t k = i == 0 ? n - 1 : i - 1, steps = 0; steps < n && flat(k);
           k = k == 0 ? n - 1 : k - 1, ++steps)
        extend(k);
    }
  });
  bucketByFirst(
      edges, height, [](const CoverageEdge& e) { return e.firstRow; }, [](std::size_t) { return true; },
      scratch.coverageBucketed, scratch.coverageRowStart);
  scratch.coverageActive.clear();
  scratch.pieceOfEdge.resize(edges.size());
}

// Insertion sort while nearly sorted, std::sort once the moves exceed a linear budget.
template <class T, class Less>
void sortNearlySortedBy(std::vector<T>& items, Less less) {
  const std::size_t n = items.size();
  std::size_t budget = 4 * n + 64;
  for (std::size_t i = 1; i < n; ++i) {
    const T item = items[i];
    std::size_t j = i;
    while (j > 0 && less(item, items[j - 1])) {
      items[j] = items[j - 1];
      --j;
      if (--budget == 0) {
        items[j] = item;
        std::sort(items.begin(), items.end(), less);
        return;
      }
    }
    items[j] = item;
  }
}

template <class T, class Key>
void sortNearlySorted(std::vector<T>& items, Key key) {
  sortNearlySortedBy(items, [&](const T& p, const T& q) { return key(p) < key(q); });
}

// Adds sign * (the part of the row right of the segment from u = ua to u = ub over a height dy) to the
// row's cells: per pixel i the segment crosses, dy_i * (1 - f) to cell i and dy_i * f to cell i + 1,
// f the mean position of the segment inside the pixel. The prefix sum of the cells is then the covered
// area per pixel. u is clipped to [0, width]: left of the grid the whole row is to the right (cell 0),
// right of it nothing is.
void addBoundarySegment(double ua, double ub, double dy, uint32_t width, double* cells) {
  const double w = static_cast<double>(width);
  double lo = std::min(ua, ub), hi = std::max(ua, ub);
  const double len = hi - lo;
  if (!(len > 0.0)) {  // vertical
    if (lo >= w) return;
    if (lo <= 0.0) {
      cells[0] += dy;
      return;
    }
    const auto i = static_cast<uint32_t>(lo);
    const double f = lo - i;
    cells[i] += dy * (1.0 - f);
    cells[i + 1] += dy * f;
    return;
  }
  const double perU = dy / len;
  if (lo < 0.0) {
    cells[0] += perU * (std::min(hi, 0.0) - lo);
    if (hi <= 0.0) return;
    lo = 0.0;
  }
  if (lo >= w) return;
  hi = std::min(hi, w);
  auto i = static_cast<uint32_t>(lo);
  for (;;) {
    const double cellLo = static_cast<double>(i);
    const double a = std::max(lo, cellLo), b = std::min(hi, cellLo + 1.0);
    const double d = perU * (b - a);
    const double f = 0.5 * (a + b) - cellLo;
    cells[i] += d * (1.0 - f);
    cells[i + 1] += d * f;
    if (cellLo + 1.0 >= hi) break;
    ++i;
  }
}

// Cells touched by addBoundarySegment(ua, ub, ...).
CellSpan segmentCells(double ua, double ub, uint32_t width) {
  const double w = static_cast<double>(width);
  const auto cell = [w](double u) { return u <= 0.0 ? 0u : static_cast<uint32_t>(std::min(u, w)); };
  return {cell(std::min(ua, ub)), cell(std::max(ua, ub)) + 1};
}

// Accumulates the boundary of the positive-winding region over the sub-band [ya, yb], whose pieces
// (sorted by um) neither start, end nor cross inside it.
void accumulateBand(std::span<const CoveragePiece> pieces, double dy, uint32_t width, double* cells,
                    std::vector<CellSpan>& spans, int32_t winding0) {
  int32_t winding = winding0;
  std::size_t i = 0;
  while (i < pieces.size()) {
    const std::size_t group = i;
    int32_t next = winding;
    do {
      next += pieces[i].winding;
      ++i;
    } while (i < pieces.size() && pieces[i].um == pieces[group].um);
    if ((winding <= 0) != (next <= 0)) {
      addBoundarySegment(pieces[group].ua, pieces[group].ub, next > 0 ? dy : -dy, width, cells);
      spans.push_back(segmentCells(pieces[group].ua, pieces[group].ub, width));
    }
    winding = next;
  }
}

void fillPieces(std::span<const CoverageEdge> active, double ya, double yb,
                std::vector<CoveragePiece>& pieces) {
  pieces.clear();
  const double ym = 0.5 * (ya + yb);
  for (uint32_t k = 0; k < active.size(); ++k) {
    const CoverageEdge& e = active[k];
    if (e.v0 > ya || e.v1 < yb) continue;
    pieces.push_back(CoveragePiece{edgeU(e, ya), edgeU(e, ym), edgeU(e, yb), k, e.winding});
  }
  sortNearlySorted(pieces, [](const CoveragePiece& p) { return p.um; });
}

// One sub-band of a row: finds crossings of its pieces (then cuts it at each crossing) and accumulates.
void coverBand(std::span<const CoverageEdge> active, double ya, double yb, uint32_t width,
               RasterScratch& scratch, int32_t winding0) {
  std::vector<CoveragePiece>& pieces = scratch.pieces;
  fillPieces(active, ya, yb, pieces);
  if (pieces.empty()) return;
  bool ordered = true;
  for (std::size_t k = 1; k < pieces.size() && ordered; ++k)
    ordered = pieces[k - 1].ua <= pieces[k].ua && pieces[k - 1].ub <= pieces[k].ub;
  double* cells = scratch.cells.data();
  if (ordered) {
    accumulateBand(pieces, yb - ya, width, cells, scratch.spans, winding0);
    return;
  }
  // Edges cross inside the band: cut it at every crossing (pairs whose order differs at an end).
  std::vector<double> cuts{ya, yb};
  for (std::size_t k = 0; k < pieces.size(); ++k) {
    for (std::size_t l = k + 1; l < pieces.size(); ++l) {
      const double da = pieces[k].ua - pieces[l].ua, db = pieces[k].ub - pieces[l].ub;
      if ((da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0)) {
        const double y = ya + (yb - ya) * (da / (da - db));
        if (y > ya && y < yb) cuts.push_back(y);
      }
    }
  }
  std::sort(cuts.begin(), cuts.end());
  cuts.erase(std::unique(cuts.begin(), cuts.end()), cuts.end());
  for (std::size_t c = 0; c + 1 < cuts.size(); ++c) {
    fillPieces(active, cuts[c], cuts[c + 1], pieces);
    accumulateBand(pieces, cuts[c + 1] - cuts[c], width, cells, scratch.spans, winding0);
  }
}

// A band of a row by sub-bands cut at every vertex inside it (the general path, see rasterize.h).
// The band [ya, yb] by sample lines (kSampleLinesPerPixel per pixel height, at least one): along each,
// the solid runs are exact in x and weigh the band's height / lines (the midpoint rule in y). Used where
// too many edges cross for the exact cuts (see rasterize.h).
void coverBandBySampling(std::span<const CoverageEdge> active, double ya, double yb, uint32_t width,
                         RasterScratch& scratch, int32_t winding0) {
  const auto lines = static_cast<uint32_t>(std::max(1.0, std::ceil(kSampleLinesPerPixel * (yb - ya))));
  const double h = (yb - ya) / lines;
  std::vector<CoveragePiece>& crossings = scratch.pieces;
  double* cells = scratch.cells.data();
  for (uint32_t l = 0; l < lines; ++l) {
    const double y = ya + (l + 0.5) * h;
    crossings.clear();
    for (uint32_t k = 0; k < active.size(); ++k) {
      const CoverageEdge& e = active[k];
      if (e.v0 <= y && y < e.v1) {
        const double u = edgeU(e, y);
        crossings.push_back({u, u, u, k, e.winding});
      }
    }
    sortNearlySorted(crossings, [](const CoveragePiece& p) { return p.um; });
    // A run [ua, ub) of height h is a rising boundary at ua and a falling one at ub.
    accumulateBand(crossings, h, width, cells, scratch.spans, winding0);
  }
}

void coverBandByVertices(std::span<const CoverageEdge> active, double ya, double yb, uint32_t width,
                         RasterScratch& scratch, int32_t winding0) {
  std::size_t overlapping = 0;
  for (const CoverageEdge& e : active) overlapping += e.v0 < yb && e.v1 > ya ? 1 : 0;
  if (overlapping > kMaxExactCrossingEdges) {
    coverBandBySampling(active, ya, yb, width, scratch, winding0);
    return;
  }
  std::vector<double>& ys = scratch.bandYs;
  ys.clear();
  ys.push_back(ya);
  for (const CoverageEdge& e : active) {
    if (e.v0 > ya && e.v0 < yb) ys.push_back(e.v0);
    if (e.v1 > ya && e.v1 < yb) ys.push_back(e.v1);
  }
  ys.push_back(yb);
  if (ys.size() > 2) {
    std::sort(ys.begin() + 1, ys.end() - 1);
    ys.erase(std::unique(ys.begin(), ys.end()), ys.end());
  }
  for (std::size_t b = 0; b + 1 < ys.size(); ++b)
    coverBand(active, ys[b], ys[b + 1], width, scratch, winding0);
}

// a where `take`, else b, without a branch.
inline double pick(bool take, double a, double b) {
  const uint64_t mask = 0 - static_cast<uint64_t>(take);
  return std::bit_cast<double>((std::bit_cast<uint64_t>(a) & mask) | (std::bit_cast<uint64_t>(b) & ~mask));
}

// Clusters the cluster proof does not accept and that have at most this many edges go by
// coverSmallCluster instead of coverRow.
constexpr std::size_t kMaxSmallCluster = 16;

// One cluster of a row (its own edges, the count left of it `winding0`) that the cluster proof does
// not accept, decided part by part (rasterize.h): each edge's part in the row is cut where another part
// crosses it, where an end of another part lies on it (coincident parts start or stop there) and at
// the height of every horizontal edge inside the row (which may pass over it). Along each piece so cut
// the count left of it then stays the same (a loop passing through a vertex or turning there does not
// change it), so it is taken once, on the horizontal line through the piece's middle: `winding0` plus
// the windings of the parts that cross that line left of it (an edge from v0 up to v1 crosses at y when
// v0 <= y < v1). Parts at the same u there (coincident) count together and the first of them stands for
// all. A piece is a boundary of the positive-winding region where the counts left and right of it lie
// on both sides of 0, and accumulates as accumulateBand's pieces do: exact to rounding, like the banded
// path (whose different sums may round a value the other way at a tie). Kept out of line, as the
// clusters' row loop is hot and most rows never come here.
[[gnu::noinline]] void coverSmallCluster(std::span<const CoverageEdge> active, double y0, double y1,
                                         uint32_t width, RasterScratch& scratch, int32_t winding0) {
  const std::size_t n = active.size();
  assert(n <= kMaxSmallCluster);
  if (n == 1) {  // one part alone (next to a horizontal edge, or inside another loop): nothing to cut
    const CoverageEdge& e = active[0];
    const double va = std::max(e.v0, y0), vb = std::min(e.v1, y1);
    const int32_t right = winding0 + e.winding;
    if (!(vb > va) || (winding0 <= 0) == (right <= 0)) return;
    const double ua = edgeU(e, va), ub = edgeU(e, vb);
    addBoundarySegment(ua, ub, right > 0 ? vb - va : va - vb, width, scratch.cells.data());
    scratch.spans.push_back(segmentCells(std::min(ua, ub), std::max(ua, ub), width));
    return;
  }
  // The parts, as the crossing counts below read them: its v range in the row, and edgeU's terms.
  std::array<double, kMaxSmallCluster> va, vb, u0s, v0s, u1s, v1s, slopes, uLows, uHighs;
  std::array<int32_t, kMaxSmallCluster> windings;
  // edgeU(active[k], v), its ends chosen by masks rather than branches.
  const auto uAt = [&](std::size_t k, double v) {
    const double inside = std::clamp(u0s[k] + (v - v0s[k]) * slopes[k], uLows[k], uHighs[k]);
    return pick(v <= v0s[k], u0s[k], pick(v >= v1s[k], u1s[k], inside));
  };
  std::array<double, 2 * kMaxSmallCluster> flats;  // where a horizontal edge inside the row joins two parts
  std::size_t flatCount = 0;
  // Piece k's cuts: cuts[k * stride, k * stride + cutCount[k]) (crossings, ends on it, horizontal
  // edges: at most 5 n - 5), then its top.
  const std::size_t stride = 5 * n;
  if (scratch.smallCuts.size() < n * stride) scratch.smallCuts.resize(n * stride);
  double* const cutStore = scratch.smallCuts.data();
  const auto cuts = [cutStore, stride](std::size_t k) { return cutStore + k * stride; };
  std::array<uint8_t, kMaxSmallCluster> cutCount{};
  for (std::size_t k = 0; k < n; ++k) {
    const CoverageEdge& e = active[k];
    va[k] = std::max(e.v0, y0);
    vb[k] = std::min(e.v1, y1);
    u0s[k] = e.u0;
    v0s[k] = e.v0;
    u1s[k] = e.u1;
    v1s[k] = e.v1;
    slopes[k] = e.slope;
    uLows[k] = std::min(e.u0, e.u1);
    uHighs[k] = std::max(e.u0, e.u1);
    windings[k] = e.winding;
    if (va[k] > y0 && e.atBottom < 0) flats[flatCount++] = va[k];
    if (vb[k] < y1 && e.atTop < 0) flats[flatCount++] = vb[k];
  }
  for (std::size_t k = 0; k < n; ++k)
    for (std::size_t f = 0; f < flatCount; ++f)
      if (flats[f] > va[k] && flats[f] < vb[k]) cuts(k)[cutCount[k]++] = flats[f];
  for (std::size_t k = 0; k < n; ++k) {
    for (std::size_t l = k + 1; l < n; ++l) {
      const double a = std::max(va[k], va[l]), b = std::min(vb[k], vb[l]);
      if (!(b > a)) continue;
      const double da = uAt(k, a) - uAt(l, a), db = uAt(k, b) - uAt(l, b);
      if ((da < 0.0 && db > 0.0) || (da > 0.0 && db < 0.0)) {
        const double y = a + (b - a) * (da / (da - db));
        if (y > a && y < b) {
          cuts(k)[cutCount[k]++] = y;
          cuts(l)[cutCount[l]++] = y;
        }
      }
      // An end of one part on the other (where they start or stop being coincident, or one touches the
      // other): the other is cut there too.
      if (da == 0.0) {
        if (a > va[k]) cuts(k)[cutCount[k]++] = a;
        if (a > va[l]) cuts(l)[cutCount[l]++] = a;
      }
      if (db == 0.0) {
        if (b < vb[k]) cuts(k)[cutCount[k]++] = b;
        if (b < vb[l]) cuts(l)[cutCount[l]++] = b;
      }
    }
  }
  double* cells = scratch.cells.data();
  double lo = std::numeric_limits<double>::max(), hi = std::numeric_limits<double>::lowest();
  for (std::size_t k = 0; k < n; ++k) {
    const CoverageEdge& e = active[k];
    double* first = cuts(k);
    double* last = first + cutCount[k];
    std::sort(first, last);
    *last++ = vb[k];
    double s0 = va[k], u0 = uAt(k, s0);
    for (const double* at = first; at != last; ++at) {
      const double s1 = *at, u1 = uAt(k, s1);
      if (!(s1 > s0)) continue;
      const double ym = 0.5 * (s0 + s1), um = uAt(k, ym);
      int32_t left = winding0, here = e.winding, follows = 0;
      for (std::size_t f = 0; f < n; ++f) {  // without branches: which parts cross, and where, is data
        // edgeU(part f, ym) where the part crosses the line (v0 <= ym < v1)
        const double uf = std::clamp(u0s[f] + (ym - v0s[f]) * slopes[f], uLows[f], uHighs[f]);
        const int32_t crosses = static_cast<int32_t>(va[f] <= ym) & static_cast<int32_t>(ym < vb[f]) &
                                static_cast<int32_t>(f != k);
        const int32_t same = crosses & static_cast<int32_t>(uf == um);
        left += windings[f] & -(crosses & static_cast<int32_t>(uf < um));
        here += windings[f] & -same;
        follows |= same & static_cast<int32_t>(f < k);
      }
      const int32_t right = left + here;
      if (follows == 0 && (left <= 0) != (right <= 0)) {
        addBoundarySegment(u0, u1, right > 0 ? s1 - s0 : s0 - s1, width, cells);
        lo = std::min({lo, u0, u1});
        hi = std::max({hi, u0, u1});
      }
      s0 = s1;
      u0 = u1;
    }
  }
  if (lo <= hi) scratch.spans.push_back(segmentCells(lo, hi, width));
}

// Whether two parts of a row's edges meet (cross, touch or overlap), decided on their bounding boxes
// and orientations; collinear parts with overlapping boxes count as meeting. Used only to prove that
// parts do not meet, so an answer of "meet" where they do not merely sends the row to coverRow.
bool partsMeet(const CoverageRowPiece& p, const CoverageRowPiece& q) {
  if (std::max(p.ua, p.ub) < std::min(q.ua, q.ub) || std::max(q.ua, q.ub) < std::min(p.ua, p.ub))
    return false;
  if (p.vb < q.va || q.vb < p.va) return false;
  const auto orient = [](double ax, double ay, double bx, double by, double cx, double cy) {
    return (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
  };
  const auto apart = [](double s, double t) { return (s > 0.0 && t > 0.0) || (s < 0.0 && t < 0.0); };
  if (apart(orient(q.ua, q.va, q.ub, q.vb, p.ua, p.va), orient(q.ua, q.va, q.ub, q.vb, p.ub, p.vb)))
    return false;
  return !apart(orient(p.ua, p.va, p.ub, p.vb, q.ua, q.va), orient(p.ua, p.va, p.ub, p.vb, q.ub, q.vb));
}

// The winding just inside one of the row's lines (its bottom, y0, or its top, y1), left to right over
// one cluster's crossings of it, starting from `winding` left of the cluster: the lowest and highest
// count it takes there, and the winding right of the cluster in `winding`. Crossings at the same u and
// slope (coincident parts) are summed before the count is taken; at the same u they are ordered by the
// u they reach just inside the row.
void lineWindings(std::vector<LineCrossing>& line, int32_t& winding, int32_t& lowest, int32_t& highest) {
  sortNearlySortedBy(line, [](const LineCrossing& a, const LineCrossing& b) {
    return a.u < b.u || (a.u == b.u && a.slope < b.slope);
  });
  for (std::size_t i = 0; i < line.size();) {
    const std::size_t group = i;
    do {
      winding += line[i].winding;
      ++i;
    } while (i < line.size() && line[i].u == line[group].u && line[i].slope == line[group].slope);
    lowest = std::min(lowest, winding);
    highest = std::max(highest, winding);
  }
}

// Adds cluster `b`, which follows `a` in the row's pieces, to `a`.
void mergeClusters(RowCluster& a, const RowCluster& b) {
  if (a.bottoms == 0) a.head = b.head;
  a.end = b.end;
  a.lo = std::min(a.lo, b.lo);
  a.hi = std::max(a.hi, b.hi);
  a.bottoms += b.bottoms;
  a.tops += b.tops;
  a.inside += b.inside;
  if (a.winding != b.winding) a.winding = 0;
  a.continued = a.continued && b.continued;
  a.loop = a.loop || b.loop;
  a.net += b.net;
}

void coverRow(std::span<const CoverageEdge> active, double y0, double y1, uint32_t width,
              RasterScratch& scratch, int32_t winding0);

// The common row, decided without cutting it (see rasterize.h, "clusters"). The parts of the active
// edges in the row are grouped into clusters: each part joins the last cluster when its u range touches
// it, and clusters that then touch are merged, so every cluster lies strictly right of the ones before
// it; parts of different clusters never meet and the winding between clusters is the same at every y
// of the row. A cluster is accepted when the count stays 0 or 1 everywhere inside it:
// - a chain: its parts have one winding and form one chain from the row's bottom to its top (one part
//   starts at the bottom, one ends at the top, every part that ends inside the row is continued by
//   the loop's next edge, so every part that starts inside is such a continuation). At every y one
//   part is crossed, so the count is the one left of it or that plus the winding;
// - otherwise (local extremes of loops inside the row, several chains): no two parts meet except loop
//   neighbours at their shared vertex, no loop lies inside the row, and every part that ends inside
//   the row is continued there by its loop neighbour. Then every region of the row between the parts
//   touches the row's bottom or top line (a region that touches neither would be enclosed by parts
//   alone, that is by a whole loop inside the row), so checking the counts along both lines checks
//   every region.
// In an accepted cluster every part is a boundary of the positive region and accumulates with its own
// winding: a chain in chain order, as coverRow would for the same row (the same bytes), any other
// cluster in the active list's order. Any other cluster (overlapping or crossing loops, a loop inside the
// row, a count left of it outside {0, 1}, a part next to a horizontal edge inside the row, whose u range
// then joins the cluster) goes to coverRow with its own edges alone, starting from the count left of it:
// its pixels do not depend on what else lies in the row (another part of a plate). Returns whether every
// cluster was accepted (none went to coverRow).
bool coverRowByClusters(const CoverageEdge* edges, std::span<const ActiveKey> active, double y0, double y1,
                        uint32_t width, RasterScratch& scratch) {
  const auto edgeAt = [edges, active](uint32_t k) -> const CoverageEdge& { return edges[active[k].index]; };
  std::vector<CoverageRowPiece>& pieces = scratch.rowPieces;
  std::vector<RowCluster>& clusters = scratch.clusters;
  pieces.clear();
  clusters.clear();
  for (uint32_t k = 0; k < active.size(); ++k) {
    const CoverageEdge& e = edgeAt(k);
    const double va = std::max(e.v0, y0), vb = std::min(e.v1, y1);
    const double ua = edgeU(e, va), ub = edgeU(e, vb);
    const auto index = static_cast<uint32_t>(pieces.size());
    RowCluster part{index,
                    index + 1,
                    index,
                    std::min(ua, ub),
                    std::max(ua, ub),
                    va == y0 ? 1 : 0,
                    vb == y1 ? 1 : 0,
                    (va > y0 ? 1 : 0) - (vb < y1 ? 1 : 0),
                    e.winding,
                    vb == y1 || e.above >= 0};
    part.loop = e.rowLoop;
    part.net = va == y0 ? e.winding : 0;
    if ((va > y0 && e.atBottom < 0) || (vb < y1 && e.atTop < 0)) {
      // A horizontal neighbour inside the row joins this part to another across its u range: both go
      // into one cluster, which coverRow covers.
      const std::array<double, 2>& reach = scratch.flatReach[e.id];
      part.lo = std::min(part.lo, reach[0]);
      part.hi = std::max(part.hi, reach[1]);
      part.loop = true;
    }
    // The part joins the last cluster when it touches it, and that one the clusters before it while they
    // touch (the active list is sorted by u at the row's bottom, not by the parts' u ranges).
    if (!clusters.empty() && part.lo <= clusters.back().hi) {
      mergeClusters(clusters.back(), part);
      while (clusters.size() > 1 && clusters.back().lo <= clusters[clusters.size() - 2].hi) {
        mergeClusters(clusters[clusters.size() - 2], clusters.back());
        clusters.pop_back();
      }
    } else {
      clusters.push_back(part);
    }
    scratch.pieceOfEdge[e.id] = index;
    pieces.push_back({ua, ub, va, vb, -1, k, false});
  }

  int32_t winding = 0;  // left of the cluster
  std::vector<LineCrossing>& line = scratch.lineCrossings;
  // A cluster that is not one chain: whether no two parts meet except loop neighbours and the counts
  // along both lines (from `winding`, the count left of it) agree right of it; if so, the lowest and
  // highest count along them.
  const auto lineCounts = [&](const RowCluster& c, int32_t& lowest, int32_t& highest) {
    for (uint32_t a = c.begin; a < c.end; ++a) {
      const CoverageEdge& e = edgeAt(pieces[a].edge);
      for (uint32_t b = a + 1; b < c.end; ++b) {
        const CoverageEdge& f = edgeAt(pieces[b].edge);
        if (e.atTop == static_cast<int32_t>(f.id) || e.atBottom == static_cast<int32_t>(f.id)) continue;
        if (partsMeet(pieces[a], pieces[b])) return false;
      }
    }
    int32_t bottom = winding, top = winding;
    lowest = highest = winding;
    line.clear();
    for (uint32_t a = c.begin; a < c.end; ++a)
      if (pieces[a].va == y0)
        line.push_back({pieces[a].ua, edgeAt(pieces[a].edge).slope, edgeAt(pieces[a].edge).winding});
    lineWindings(line, bottom, lowest, highest);
    line.clear();
    for (uint32_t a = c.begin; a < c.end; ++a)
      if (pieces[a].vb == y1)
        line.push_back({pieces[a].ub, -edgeAt(pieces[a].edge).slope, edgeAt(pieces[a].edge).winding});
    lineWindings(line, top, lowest, highest);
    return top == bottom;
  };
  bool extremes = false, allClustered = true;
  for (RowCluster& c : clusters) {
    c.left = winding;
    // A chain's count is `winding` left of it and `winding` plus its winding right of it.
    int32_t lowest = std::min(winding, winding + c.winding), highest = std::max(winding, winding + c.winding);
    const bool decided = !c.loop && (c.chain() || lineCounts(c, lowest, highest));
    c.accepted = decided && lowest >= 0 && highest <= 1;
    c.interior = decided && lowest >= 1 && !c.accepted;
    scratch.interiorClusters += c.interior ? 1 : 0;
    allClustered = allClustered && (c.accepted || c.interior);
    extremes = extremes || (c.accepted && !c.chain());
    winding += c.net;
  }
  if (extremes) ++scratch.extremeRows;

  double* cells = scratch.cells.data();
  std::vector<CoverageEdge>& own = scratch.coverageActive;
  std::vector<uint32_t>& ownStart = scratch.clusterEdgeStart;
  own.clear();
  ownStart.clear();
  for (const RowCluster& c : clusters) {
    if (c.interior) continue;  // the count is at least 1 on both sides of every part: no boundary
    if (!c.accepted) {
      ownStart.push_back(static_cast<uint32_t>(own.size()));
      for (uint32_t k = c.begin; k < c.end; ++k) own.push_back(edgeAt(pieces[k].edge));
      continue;
    }
    if (c.chain()) {
      uint32_t k = c.head;
      const double sign = edgeAt(pieces[k].edge).winding > 0 ? 1.0 : -1.0;
      for (;;) {
        const CoverageRowPiece& p = pieces[k];
        addBoundarySegment(p.ua, p.ub, sign * (p.vb - p.va), width, cells);
        if (p.vb >= y1) break;
        k = scratch.pieceOfEdge[static_cast<std::size_t>(edgeAt(p.edge).above)];
      }
    } else {
      for (uint32_t k = c.begin; k < c.end; ++k) {
        const CoverageRowPiece& p = pieces[k];
        const double sign = edgeAt(p.edge).winding > 0 ? 1.0 : -1.0;
        addBoundarySegment(p.ua, p.ub, sign * (p.vb - p.va), width, cells);
      }
    }
    scratch.spans.push_back(segmentCells(c.lo, c.hi, width));
  }
  if (allClustered) return true;
  // coverRow reuses the row's pieces: the clusters it covers were copied out above.
  ownStart.push_back(static_cast<uint32_t>(own.size()));
  std::size_t r = 0;
  for (const RowCluster& c : clusters) {
    if (c.accepted || c.interior) continue;
    const std::span<const CoverageEdge> mine =
        std::span<const CoverageEdge>(own).subspan(ownStart[r], ownStart[r + 1] - ownStart[r]);
    if (mine.size() <= kMaxSmallCluster) {
      coverSmallCluster(mine, y0, y1, width, scratch, c.left);
      ++scratch.smallClusters;
    } else {
      coverRow(mine, y0, y1, width, scratch, c.left);
    }
    ++r;
  }
  sortNearlySorted(scratch.spans, [](const CellSpan& s) { return s.begin; });
  return false;
}

// Where a row's fills are written as they are found: three entries each (MaskImage::fills), at most
// one per kMinFill pixels of the row, so a buffer of rowFillCapacity(width) entries holds any row.
// Plain stores: GCC 12 keeps std::vector's push_back and resize out of line here.
struct FillSink {
  uint32_t* at;
};
std::size_t rowFillCapacity(uint32_t width) {
  return 3 * (std::size_t{width} / kMinFill + 1);
}

// Stored pixels [a, b) of a row (dark before) set to `value`, and listed in `fills` (when given) as a
// stretch of one value when it holds kMinFill pixels or more.
void putStretch(uint8_t* row, uint32_t a, uint32_t b, uint8_t value, FillSink* fills) {
  if (fills && b - a >= kMinFill) {
    fills->at[0] = a;
    fills->at[1] = b;
    fills->at[2] = value;
    fills->at += 3;
  }
  if (value != 0) std::memset(row + a, value, b - a);
}

// Stored pixels [at, end) of row r at `value` dimmed by the light map, one putStretch per stretch of
// the map, in the order of the pass over the row: backwards when the row is mirrored (the row's fills
// are reversed after it). Kept out of line: the row loop is hot and this runs only with a light map.
[[gnu::noinline]] void dimByStretches(const LightMap& light, uint32_t r, uint32_t at, uint32_t end,
                                      uint8_t value, bool mirrored, FillSink* fills, uint8_t* row) {
  const uint8_t* map = light.pixels.data() + static_cast<std::size_t>(r) * light.width;
  const uint32_t* first = light.starts.data() + light.rowFirst[r];
  const uint32_t* last = light.starts.data() + light.rowFirst[r + 1];
  const auto dim = [&](uint32_t a, uint32_t b) { putStretch(row, a, b, lightValue(value, map[a]), fills); };
  if (!mirrored) {
    const uint32_t* next = std::upper_bound(first + 1, last, at);  // the stretch after at's
    for (uint32_t a = at; a < end; ++next) {
      const uint32_t b = next < last ? std::min(*next, end) : end;
      dim(a, b);
      a = b;
    }
  } else {
    const uint32_t* start = std::upper_bound(first + 1, last, end - 1) - 1;  // end - 1's stretch
    for (uint32_t b = end;; --start) {
      const uint32_t a = std::max(*start, at);
      dim(a, b);
      if (a == at) break;
      b = a;
    }
  }
}

// One pixel row [y0, y1] (see rasterize.h): the active edges' parts in the row are linked, vertex to
// vertex, into chains of one winding; the row is cut where a chain starts or ends inside it (local
// extremes, horizontal edges, touching loops). In each band the chains spanning it are ordered at its
// bottom; if no two neighbours swap sides (checked at every vertex of either) the boundary is decided
// once per chain, else the band is cut at every vertex and crossing (coverBandByVertices).
void coverRow(std::span<const CoverageEdge> active, double y0, double y1, uint32_t width,
              RasterScratch& scratch, int32_t winding0) {
  std::vector<CoverageRowPiece>& pieces = scratch.rowPieces;
  std::vector<uint32_t>& starts = scratch.chainStarts;
  pieces.clear();
  starts.clear();
  for (uint32_t k = 0; k < active.size(); ++k) {
    const CoverageEdge& e = active[k];
    const double va = std::max(e.v0, y0), vb = std::min(e.v1, y1);
    if (va > y0) starts.push_back(static_cast<uint32_t>(pieces.size()));
    scratch.pieceOfEdge[e.id] = static_cast<uint32_t>(pieces.size());
    pieces.push_back({edgeU(e, va), edgeU(e, vb), va, vb, -1, k, false});
  }
  // Link each piece ending inside the row to the piece of the edge continuing it (its loop neighbour).
  std::vector<double>& cuts = scratch.rowCuts;
  cuts.clear();
  cuts.push_back(y0);
  for (CoverageRowPiece& p : pieces) {
    if (p.vb >= y1) continue;
    const int32_t above = active[p.edge].above;
    if (above >= 0) {
      const uint32_t q = scratch.pieceOfEdge[static_cast<std::size_t>(above)];
      if (q < pieces.size() && active[pieces[q].edge].id == static_cast<uint32_t>(above) &&
          pieces[q].va == p.vb && pieces[q].ua == p.ub) {
        p.next = static_cast<int32_t>(q);
        pieces[q].linked = true;
        continue;
      }
    }
    cuts.push_back(p.vb);  // a chain ends inside the row
  }
  for (const uint32_t q : starts)
    if (!pieces[q].linked) cuts.push_back(pieces[q].va);  // a chain starts inside the row
  cuts.push_back(y1);
  if (cuts.size() > 2) {
    std::sort(cuts.begin() + 1, cuts.end() - 1);
    cuts.erase(std::unique(cuts.begin(), cuts.end()), cuts.end());
  }

  std::vector<ChainCursor>& live = scratch.chains;
  double* cells = scratch.cells.data();
  const auto uAt = [&](uint32_t k, double y) { return edgeU(active[pieces[k].edge], y); };
  for (std::size_t c = 0; c + 1 < cuts.size(); ++c) {
    const double ya = cuts[c], yb = cuts[c + 1];
    live.clear();
    for (uint32_t k = 0; k < pieces.size(); ++k) {
      if (pieces[k].linked) continue;  // not a chain head
      uint32_t first = k;
      while (pieces[first].vb <= ya && pieces[first].next >= 0)
        first = static_cast<uint32_t>(pieces[first].next);
      if (pieces[first].va > ya || pieces[first].vb <= ya) continue;  // the chain does not span the band
      uint32_t last = first;
      double lo = std::min(pieces[first].ua, pieces[first].ub),
             hi = std::max(pieces[first].ua, pieces[first].ub);
      while (pieces[last].vb < yb && pieces[last].next >= 0) {
        last = static_cast<uint32_t>(pieces[last].next);
        lo = std::min({lo, pieces[last].ua, pieces[last].ub});
        hi = std::max({hi, pieces[last].ua, pieces[last].ub});
      }
      if (pieces[last].vb < yb) continue;
      live.push_back({uAt(first, ya), uAt(last, yb), lo, hi, first});
    }
    sortNearlySortedBy(live, [](const ChainCursor& p, const ChainCursor& q) {
      return p.ua < q.ua || (p.ua == q.ua && p.ub < q.ub);
    });
    bool ordered = true;
    for (std::size_t h = 1; h < live.size() && ordered; ++h) {
      if (live[h - 1].hi < live[h].lo) continue;  // apart over the whole band
      uint32_t a = live[h - 1].first, b = live[h].first;
      for (;;) {
        const double y = std::min({pieces[a].vb, pieces[b].vb, yb});
        if (uAt(a, y) > uAt(b, y)) {
          ordered = false;
          break;
        }
        if (y >= yb) break;
        if (pieces[a].vb == y) a = static_cast<uint32_t>(pieces[a].next);
        if (pieces[b].vb == y) b = static_cast<uint32_t>(pieces[b].next);
      }
    }
    if (!ordered) {
      coverBandByVertices(active, ya, yb, width, scratch, winding0);
      continue;
    }
    int32_t winding = winding0;
    for (const ChainCursor& chain : live) {
      const int32_t next = winding + active[pieces[chain.first].edge].winding;
      const bool boundary = (winding <= 0) != (next <= 0);
      winding = next;
      if (!boundary) continue;
      const double sign = next > 0 ? 1.0 : -1.0;
      double lo = chain.ua, hi = lo;
      for (uint32_t k = chain.first;; k = static_cast<uint32_t>(pieces[k].next)) {
        const double va = std::max(pieces[k].va, ya), vb = std::min(pieces[k].vb, yb);
        const double ua = va == pieces[k].va ? pieces[k].ua : uAt(k, va);
        const double ub = vb == pieces[k].vb ? pieces[k].ub : uAt(k, vb);
        addBoundarySegment(ua, ub, sign * (vb - va), width, cells);
        lo = std::min({lo, ua, ub});
        hi = std::max({hi, ua, ub});
        if (pieces[k].vb >= yb) break;
      }
      scratch.spans.push_back(segmentCells(lo, hi, width));
    }
  }
  sortNearlySorted(scratch.spans, [](const CellSpan& s) { return s.begin; });
}

// Sets the pixels of stored row r's runs (MaskImage::runs, rowRuns) to zero.
void clearRowRuns(uint8_t* row, const std::vector<uint32_t>& runs, const std::vector<uint32_t>& rowRuns,
                  uint32_t r) {
  const uint32_t* run = runs.data() + 2 * std::size_t{rowRuns[2 * r]};
  for (uint32_t k = 0; k < rowRuns[2 * r + 1]; ++k)
    std::memset(row + run[2 * k], 0, run[2 * k + 1] - run[2 * k]);
}

// Turns a row lit on the runs `from` into one lit on the runs `to` (both increasing [begin, end) pairs,
// none empty, none touching the next): only the pixels lit in one and not in the other are written,
// so a row whose outline moved by a pixel costs a few bytes, not its runs twice, and an unchanged row
// costs none. With no `from` (a dark row) it lights the runs of `to`.
void changeRowRuns(uint8_t* row, std::span<const uint32_t> from, std::span<const uint32_t> to) {
  constexpr uint32_t kNone = std::numeric_limits<uint32_t>::max();
  std::size_t i = 0, j = 0;
  bool inFrom = false, inTo = false;
  uint32_t at = 0;
  while (i < from.size() || j < to.size()) {
    const uint32_t x = std::min(i < from.size() ? from[i] : kNone, j < to.size() ? to[j] : kNone);
    if (inFrom != inTo) std::memset(row + at, inTo ? 255 : 0, x - at);
    if (i < from.size() && from[i] == x) {
      inFrom = !inFrom;
      ++i;
    }
    if (j < to.size() && to[j] == x) {
      inTo = !inTo;
      ++j;
    }
    at = x;
  }
}

// Clears `out` for a new layer of `grid`: only the previous image's lit spans when it has extents.
// Leaves every row dark with empty extents.
void prepareImage(const PixelGrid& grid, MaskImage& out) {
  const uint32_t width = grid.width, height = grid.height;
  const bool reuse = out.width == width && out.height == height && out.hasExtents() &&
                     out.pixels.size() == static_cast<std::size_t>(width) * height;
  out.width = width;
  out.height = height;
  out.pixels.resize(static_cast<std::size_t>(width) * height);
  if (!reuse) std::fill(out.pixels.begin(), out.pixels.end(), uint8_t{0});
  out.litBegin.resize(height);
  out.litEnd.resize(height);
  const bool runs = reuse && out.hasRuns();  // then only the runs are lit, not the gaps between them
  for (uint32_t r = 0; r < height; ++r) {
    uint8_t* row = out.pixels.data() + static_cast<std::size_t>(r) * width;
    if (runs) {
      clearRowRuns(row, out.runs, out.rowRuns, r);
    } else if (reuse) {
      // The lit extent, less the dark stretches among the fills (between the parts of a layer, inside
      // a hollow one), which are dark already.
      const auto clear = [row](std::size_t a, std::size_t b) { std::memset(row + a, 0, b - a); };
      forEachRowStretch(
          out, r, out.litBegin[r], out.litEnd[r],
          [&](std::size_t a, std::size_t b, uint8_t value) {
            if (value != 0) clear(a, b);
          },
          clear);
    }
    out.litBegin[r] = width;
    out.litEnd[r] = 0;
  }
  out.runs.clear();
  out.rowRuns.clear();
  out.fills.clear();
  out.rowFills.clear();
}

}  // namespace

void rasterizeBinary(std::span<const ContourSet> sets, const PixelGrid& grid, MaskImage& out,
                     RasterScratch& scratch, uint64_t* litPixels) {
  assert(usableGrid(grid));
  if (litPixels) *litPixels = 0;
  const uint32_t width = grid.width, height = grid.height;
  // With the previous binary mask of this size and its runs in `out`, rows are updated in place: a row
  // whose runs are unchanged (most rows of consecutive thin layers) is not written at all, a changed
  // row has only the pixels between its old and new run ends written (changeRowRuns), and rows left
  // dark are cleared at the end. Otherwise the image is cleared first (only its lit spans when it has
  // extents).
  const bool update = width > 0 && height > 0 && usableGrid(grid) && out.width == width &&
                      out.height == height && out.hasRuns() &&
                      out.pixels.size() == static_cast<std::size_t>(width) * height;
  std::vector<uint32_t>& oldRuns = scratch.previousRuns;
  std::vector<uint32_t>& oldRowRuns = scratch.previousRowRuns;
  if (update) {
    oldRuns.swap(out.runs);
    oldRowRuns.swap(out.rowRuns);
    out.runs.clear();
    std::fill(out.litBegin.begin(), out.litBegin.end(), width);
    std::fill(out.litEnd.begin(), out.litEnd.end(), 0u);
  } else {
    prepareImage(grid, out);
  }
  if (width == 0 || height == 0 || !usableGrid(grid)) return;

  out.rowRuns.assign(std::size_t{2} * height, 0);
  std::vector<uint32_t>& runs = out.runs;
  buildEdgeTable(sets, grid.y0, grid.pixel, height, grid.transposed, scratch);
  const double inversePixel = 1.0 / grid.pixel;
  for (uint32_t j = 0; j < height; ++j) {
    if (!hasWork(j, scratch)) continue;
    const uint32_t r = grid.mirrorY ? height - 1 - j : j;
    uint8_t* row = out.pixels.data() + static_cast<std::size_t>(r) * width;
    advanceTo(j, samplePosition(grid.y0, grid.pixel, j), scratch);
    const std::size_t first = runs.size();
    forEachSolidRun(scratch.active, [&](double xa, double xb) {
      const uint32_t ia = firstSampleAtOrAbove(xa, grid.x0, grid.pixel, inversePixel, width);
      const uint32_t ib = firstSampleAtOrAbove(xb, grid.x0, grid.pixel, inversePixel, width);
      if (ia >= ib) return;
      runs.push_back(grid.mirrorX ? width - ib : ia);
      runs.push_back(grid.mirrorX ? width - ia : ib);
      if (litPixels) *litPixels += ib - ia;
    });
    if (runs.size() == first) continue;
    // Runs in increasing x (a mirror emits them right to left), then joined where they touch (two solid
    // runs with no pixel centre between them).
    if (grid.mirrorX) {
      for (std::size_t p = first, q = runs.size() - 2; p < q; p += 2, q -= 2) {
        std::swap(runs[p], runs[q]);
        std::swap(runs[p + 1], runs[q + 1]);
      }
    }
    std::size_t kept = first;
    for (std::size_t p = first + 2; p < runs.size(); p += 2) {
      if (runs[p] == runs[kept + 1]) {
        runs[kept + 1] = runs[p + 1];
      } else {
        kept += 2;
        runs[kept] = runs[p];
        runs[kept + 1] = runs[p + 1];
      }
    }
    runs.resize(kept + 2);
    out.rowRuns[2 * r] = static_cast<uint32_t>(first / 2);
    out.rowRuns[2 * r + 1] = static_cast<uint32_t>((runs.size() - first) / 2);
    out.litBegin[r] = runs[first];
    out.litEnd[r] = runs.back();
    std::span<const uint32_t> before;  // the row's lit runs before this call: none on a cleared image
    if (update) {
      before = {oldRuns.data() + 2 * std::size_t{oldRowRuns[2 * r]}, 2 * std::size_t{oldRowRuns[2 * r + 1]}};
      oldRowRuns[2 * r + 1] = 0;  // done with
    }
    changeRowRuns(row, before, {runs.data() + first, runs.size() - first});
  }
  if (update) {  // rows lit before and dark now
    for (uint32_t r = 0; r < height; ++r)
      if (oldRowRuns[2 * r + 1] != 0)
        clearRowRuns(out.pixels.data() + static_cast<std::size_t>(r) * width, oldRuns, oldRowRuns, r);
  }
}

void rasterizeCoverage(std::span<const ContourSet> sets, const PixelGrid& grid, MaskImage& out,
                       RasterScratch& scratch, uint64_t* valueSum, const CoverageTransfer* transfer) {
  assert(usableGrid(grid));
  if (valueSum) *valueSum = 0;
  const uint32_t width = grid.width, height = grid.height;
  prepareImage(grid, out);
  if (width == 0 || height == 0 || !usableGrid(grid)) return;

  buildCoverageTable(sets, grid, scratch);
  scratch.cells.assign(static_cast<std::size_t>(width) + 2, 0.0);
  double* cells = scratch.cells.data();
  std::vector<CellSpan>& spans = scratch.spans;
  const CoverageCurve* curve = transfer ? transfer->curve : nullptr;
  const auto rounded = [](double a) { return static_cast<uint8_t>(std::clamp(a, 0.0, 1.0) * 255.0 + 0.5); };
  const auto valueOf = [curve, rounded](double a) { return curve ? curve->value(a) : rounded(a); };
  // What a pixel of value v and coverage a adds to valueSum: round(255 a), before the curve.
  const auto areaOf = [curve, rounded](uint8_t v, double a) { return curve ? rounded(a) : v; };

  // Active edges: those overlapping row j, as u at the row's bottom and their index in coverageBucketed,
  // sorted by u (nearly sorted from the row below), so that the chains are too.
  const CoverageEdge* edges = scratch.coverageBucketed.data();
  std::vector<ActiveKey>& active = scratch.activeKeys;
  active.clear();
  // The constant stretches between edge pixels, for the coders (MaskImage::fills), unless a row hook
  // may change the values after they are written.
  const LightMap* light = transfer ? transfer->lightMap : nullptr;
  const bool keepFills = !(transfer && transfer->row);
  if (keepFills) {
    out.rowFills.assign(std::size_t{2} * height, 0);
    scratch.rowFills.resize(rowFillCapacity(width));
  }
  for (uint32_t j = 0; j < height; ++j) {
    std::size_t kept = 0;
    for (std::size_t i = 0; i < active.size(); ++i)
      if (edges[active[i].index].endRow > j) active[kept++] = active[i];
    active.resize(kept);
    for (uint32_t i = scratch.coverageRowStart[j]; i < scratch.coverageRowStart[j + 1]; ++i)
      active.push_back({0.0, i});
    if (active.empty()) continue;
    bool sorted = true;
    for (std::size_t i = 0; i < active.size(); ++i) {
      active[i].x = edgeU(edges[active[i].index], j);
      if (i > 0 && active[i].x < active[i - 1].x) sorted = false;
    }
    if (!sorted) sortNearlySorted(active, [](const ActiveKey& k) { return k.x; });

    spans.clear();
    const double y0 = j, y1 = j + 1.0;
    if (!scratch.alwaysBanded) {
      ++(coverRowByClusters(edges, active, y0, y1, width, scratch) ? scratch.clusteredRows
                                                                   : scratch.bandedRows);
    } else {
      ++scratch.bandedRows;
      std::vector<CoverageEdge>& rowEdges = scratch.coverageActive;
      rowEdges.resize(active.size());
      for (std::size_t i = 0; i < active.size(); ++i) rowEdges[i] = edges[active[i].index];
      coverRow(rowEdges, y0, y1, width, scratch, 0);
    }
    if (spans.empty()) continue;

    // The row: prefix sums over the touched cells, constant runs between them.
    const uint32_t r = grid.mirrorY ? height - 1 - j : j;
    uint8_t* row = out.pixels.data() + static_cast<std::size_t>(r) * width;
    const uint8_t* lightRow = light ? light->pixels.data() + static_cast<std::size_t>(r) * width : nullptr;
    // The map's next row, fetched at this row's edge pixels while they are written: a row's edges lie
    // near those of the row below, and the map (megabytes) is read a few bytes a row.
    const uint8_t* nextLightRow =
        lightRow && j + 1 < height ? (grid.mirrorY ? lightRow - width : lightRow + width) : nullptr;
    uint32_t lo = width, hi = 0;  // lit extent, unmirrored
    uint64_t sum = 0;
    uint32_t* const rowFills = scratch.rowFills.data();
    FillSink sink{rowFills};
    FillSink* fills = keepFills ? &sink : nullptr;  // in the pass's order: reversed below
    // The unmirrored pixels [from, to) at one value before the light map.
    const auto fill = [&](uint32_t from, uint32_t to, double a) {
      if (from >= to) return;
      const uint8_t value = valueOf(a);
      sum += static_cast<uint64_t>(areaOf(value, a)) * (to - from);
      const uint32_t at = grid.mirrorX ? width - to : from, end = at + (to - from);
      if (value == 0 || !lightRow) {
        putStretch(row, at, end, value, fills);
        if (value == 0) return;
      } else {
        dimByStretches(*light, r, at, end, value, grid.mirrorX, fills, row);
      }
      lo = std::min(lo, from);
      hi = to;
    };
    double covered = 0.0;
    uint32_t next = 0;  // first pixel not yet written
    std::size_t s = 0;
    while (s < spans.size()) {
      const uint32_t begin = spans[s].begin;
      uint32_t end = spans[s].end;
      for (++s; s < spans.size() && spans[s].begin <= end + 1; ++s) end = std::max(end, spans[s].end);
      fill(next, begin, covered);
      for (uint32_t i = begin; i <= end; ++i) {
        covered += cells[i];
        cells[i] = 0.0;
        if (i >= width) break;
        const uint8_t v = valueOf(covered);
        sum += areaOf(v, covered);
        if (v == 0) continue;
        const uint32_t at = grid.mirrorX ? width - 1 - i : i;
        if (lightRow) {
          if (nextLightRow) prefetch(nextLightRow + at);
          row[at] = lightValue(v, lightRow[at]);
        } else {
          row[at] = v;
        }
        lo = std::min(lo, i);
        hi = i + 1;
      }
      cells[width] = 0.0;
      next = std::min(end + 1, width);
    }
    fill(next, width, covered);
    if (keepFills && sink.at != rowFills) {
      const auto count = static_cast<std::size_t>(sink.at - rowFills);
      assert(count <= scratch.rowFills.size());
      if (grid.mirrorX) {
        for (std::size_t a = 0, b = count - 3; a < b; a += 3, b -= 3)
          std::swap_ranges(rowFills + a, rowFills + a + 3, rowFills + b);
      }
      out.rowFills[2 * r] = static_cast<uint32_t>(out.fills.size() / 3);
      out.rowFills[2 * r + 1] = static_cast<uint32_t>(count / 3);
      out.fills.insert(out.fills.end(), rowFills, sink.at);
    }
    if (lo >= hi) {  // dark, though a curve may have darkened some covered pixels
      if (valueSum) *valueSum += sum;
      continue;
    }
    uint32_t begin = grid.mirrorX ? width - hi : lo, end = grid.mirrorX ? width - lo : hi;
    const bool hook = transfer && transfer->row;
    if (hook) transfer->row(transfer->context, r, begin, end, row);
    if (hook || lightRow) {  // values may have become 0 at the ends
      while (begin < end && row[begin] == 0) ++begin;
      while (end > begin && row[end - 1] == 0) --end;
    }
    if (hook) {  // the light map and the curve keep the sum before them (the part's area)
      sum = 0;
      for (uint32_t i = begin; i < end; ++i) sum += row[i];
    }
    if (begin < end) {
      out.litBegin[r] = begin;
      out.litEnd[r] = end;
    }
    if (valueSum) *valueSum += sum;
  }
}

CoverageCurve coverageCurve(const std::array<double, 256>& thresholds) {
  CoverageCurve curve;
  std::copy(thresholds.begin(), thresholds.end(), curve.thresholds.begin());
  curve.thresholds[256] = std::numeric_limits<double>::infinity();
  unsigned v = 0;
  for (uint32_t k = 0; k <= CoverageCurve::kSteps; ++k) {
    const double a = static_cast<double>(k) / CoverageCurve::kSteps;
    while (v < 255 && a >= thresholds[v + 1]) ++v;
    curve.start[k] = static_cast<uint8_t>(v);
  }
  return curve;
}

LightMap lightMapOf(const MaskImage& map) {
  LightMap light;
  light.width = map.width;
  light.height = map.height;
  light.pixels = map.pixels;
  light.rowFirst.reserve(std::size_t{map.height} + 1);
  for (uint32_t r = 0; r < map.height; ++r) {
    light.rowFirst.push_back(static_cast<uint32_t>(light.starts.size()));
    const uint8_t* row = map.pixels.data() + std::size_t{r} * map.width;
    for (uint32_t i = 0; i < map.width; ++i)
      if (i == 0 || row[i] != row[i - 1]) light.starts.push_back(i);
  }
  light.rowFirst.push_back(static_cast<uint32_t>(light.starts.size()));
  return light;
}

std::size_t countSkippedLoops(std::span<const ContourSet> sets) {
  std::size_t skipped = 0;
  for (const ContourSet& set : sets) {
    const LayerContours& layer = *set.layer;
    for (std::size_t l = 0; l < layer.loopCount(); ++l) {
      if (layer.loopClosed[l] == 0 || !allFinite(layer.loopPoints(l))) ++skipped;
    }
  }
  return skipped;
}

std::size_t countLitPixels(const MaskImage& mask) {
  return static_cast<std::size_t>(
      std::count_if(mask.pixels.begin(), mask.pixels.end(), [](uint8_t v) { return v != 0; }));
}

double maskArea(const MaskImage& mask, double pixel) {
  // Blocks small enough for a 32-bit partial sum (255 * 65536 < 2^32), which the compiler vectorizes.
  constexpr std::size_t kBlock = 65536;
  const uint8_t* p = mask.pixels.data();
  const std::size_t n = mask.pixels.size();
  uint64_t sum = 0;
  for (std::size_t at = 0; at < n; at += kBlock) {
    const std::size_t end = std::min(n, at + kBlock);
    uint32_t partial = 0;
    for (std::size_t i = at; i < end; ++i) partial += p[i];
    sum += partial;
  }
  return static_cast<double>(sum) / 255.0 * pixel * pixel;
}

}  // namespace toposlice
