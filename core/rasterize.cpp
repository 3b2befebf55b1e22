#include "core/rasterize.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstring>
#include <limits>

// Scanline conversion with an active edge table: edges are bucketed by the first sample line they cross
// (count, prefix sum, fill), the active list is kept sorted by x from one sample line to the next
// (insertion sort on nearly sorted data) and swept left to right accumulating the winding count.

namespace toposlice {
namespace {

double samplePosition(double origin, double pitch, uint32_t k) {
  return origin + (static_cast<double>(k) + 0.5) * pitch;
}

// Smallest k in [0, count] with samplePosition(k) >= v (count when there is none). The division only
// guesses; the answer is settled with the same expression every caller uses for the sample position.
uint32_t firstSampleAtOrAbove(double v, double origin, double pitch, uint32_t count) {
  const double guess = std::ceil((v - origin) / pitch - 0.5);
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

// Collects the edges of all closed, finite loops that cross at least one of `count` sample lines
// origin + (k + 1/2) pitch, then groups them by first line into scratch.bucketed / bucketStart.
void buildEdgeTable(std::span<const ContourSet> sets, double origin, double pitch, uint32_t count,
                    RasterScratch& scratch) {
  std::vector<RasterEdge>& edges = scratch.edges;
  edges.clear();
  for (const ContourSet& set : sets) {
    assert(set.layer != nullptr && (set.sign == 1 || set.sign == -1));
    const LayerContours& layer = *set.layer;
    for (std::size_t l = 0; l < layer.loopCount(); ++l) {
      if (layer.loopClosed[l] == 0) continue;
      const std::span<const Point2d> loop = layer.loopPoints(l);
      if (!allFinite(loop)) continue;
      const std::size_t n = loop.size();
      for (std::size_t i = 0; i < n; ++i) {
        const Point2d a = loop[i];
        const Point2d b = loop[i + 1 == n ? 0 : i + 1];
        if (a.y == b.y) continue;  // horizontal: crosses no sample line under the half-open rule
        const bool upward = a.y < b.y;
        const Point2d lo = upward ? a : b;
        const Point2d hi = upward ? b : a;
        const uint32_t first = firstSampleAtOrAbove(lo.y, origin, pitch, count);
        const uint32_t end = firstSampleAtOrAbove(hi.y, origin, pitch, count);
        if (first >= end) continue;
        double slope = (hi.x - lo.x) / (hi.y - lo.y);
        if (!std::isfinite(slope)) slope = 0.0;  // dy is so small that any x of the edge is as good
        // A CCW outer loop runs downwards on its left side: crossing it left to right enters the solid.
        const int32_t winding = upward ? -set.sign : set.sign;
        edges.push_back(RasterEdge{0.0, lo.x, lo.y, slope, first, end, winding});
      }
    }
  }

  std::vector<uint32_t>& start = scratch.bucketStart;
  start.assign(static_cast<std::size_t>(count) + 1, 0);
  for (const RasterEdge& e : edges) ++start[e.first + 1];
  for (uint32_t k = 0; k < count; ++k) start[k + 1] += start[k];
  scratch.bucketed.resize(edges.size());
  for (const RasterEdge& e : edges) scratch.bucketed[start[e.first]++] = e;  // start[k] becomes start[k+1]
  for (uint32_t k = count; k > 0; --k) start[k] = start[k - 1];
  start[0] = 0;

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

// Moves the active edge table to sample line k at height y: drops edges that ended, adds the edges whose
// first line is k, computes every crossing and sorts by x.
void advanceTo(uint32_t k, double y, RasterScratch& scratch) {
  std::vector<RasterEdge>& active = scratch.active;
  std::size_t kept = 0;
  for (std::size_t i = 0; i < active.size(); ++i) {
    if (active[i].end <= k) continue;
    RasterEdge e = active[i];
    e.x = e.xLow + (y - e.yLow) * e.slope;
    active[kept++] = e;
  }
  active.resize(kept);
  for (uint32_t b = scratch.bucketStart[k]; b < scratch.bucketStart[k + 1]; ++b) {
    RasterEdge e = scratch.bucketed[b];
    e.x = e.xLow + (y - e.yLow) * e.slope;
    active.push_back(e);
  }
  sortByX(active);
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

}  // namespace

void rasterizeBinary(std::span<const ContourSet> sets, const PixelGrid& grid, MaskImage& out,
                     RasterScratch& scratch, uint64_t* litPixels) {
  assert(usableGrid(grid));
  if (litPixels) *litPixels = 0;
  const uint32_t width = grid.width, height = grid.height;
  // Reuse of the previous image: with known extents only its lit spans need clearing.
  const bool reuse = out.width == width && out.height == height && out.hasExtents() &&
                     out.pixels.size() == static_cast<std::size_t>(width) * height;
  out.width = width;
  out.height = height;
  out.pixels.resize(static_cast<std::size_t>(width) * height);
  if (!reuse) std::fill(out.pixels.begin(), out.pixels.end(), uint8_t{0});
  out.litBegin.resize(height);
  out.litEnd.resize(height);
  if (width == 0 || height == 0) return;
  for (uint32_t r = 0; r < height; ++r) {
    if (reuse && out.litBegin[r] < out.litEnd[r])
      std::memset(out.pixels.data() + static_cast<std::size_t>(r) * width + out.litBegin[r], 0,
                  out.litEnd[r] - out.litBegin[r]);
    out.litBegin[r] = width;
    out.litEnd[r] = 0;
  }
  if (!usableGrid(grid)) return;

  buildEdgeTable(sets, grid.y0, grid.pixel, height, scratch);
  for (uint32_t j = 0; j < height; ++j) {
    if (!hasWork(j, scratch)) continue;
    const uint32_t r = grid.mirrorY ? height - 1 - j : j;
    uint8_t* row = out.pixels.data() + static_cast<std::size_t>(r) * width;
    advanceTo(j, samplePosition(grid.y0, grid.pixel, j), scratch);
    uint32_t lo = width, hi = 0;
    forEachSolidRun(scratch.active, [&](double xa, double xb) {
      const uint32_t ia = firstSampleAtOrAbove(xa, grid.x0, grid.pixel, width);
      const uint32_t ib = firstSampleAtOrAbove(xb, grid.x0, grid.pixel, width);
      if (ia >= ib) return;
      const uint32_t a = grid.mirrorX ? width - ib : ia, b = grid.mirrorX ? width - ia : ib;
      std::memset(row + a, 255, b - a);
      lo = std::min(lo, a);
      hi = std::max(hi, b);
      if (litPixels) *litPixels += ib - ia;
    });
    out.litBegin[r] = lo;
    out.litEnd[r] = hi;
  }
}

void rasterizeCoverage(std::span<const ContourSet> sets, const PixelGrid& grid, MaskImage& out,
                       RasterScratch& scratch, uint32_t subScanlines) {
  assert(usableGrid(grid));
  assert(subScanlines >= 1 && subScanlines <= 256);
  const uint32_t width = grid.width, height = grid.height;
  out.width = width;
  out.height = height;
  out.pixels.resize(static_cast<std::size_t>(width) * height);
  out.litBegin.clear();  // every pixel is rewritten; extents are not tracked for coverage masks
  out.litEnd.clear();
  if (width == 0 || height == 0) return;
  if (!usableGrid(grid)) {
    std::fill(out.pixels.begin(), out.pixels.end(), uint8_t{0});
    return;
  }
  // Sample lines are numbered in 32 bits: very tall grids get fewer sub-scanlines.
  const uint32_t sub = std::min(std::clamp<uint32_t>(subScanlines, 1, 256),
                                std::max<uint32_t>(1, (std::numeric_limits<uint32_t>::max() - 1) / height));
  const uint32_t lines = height * sub;
  const double subPitch = grid.pixel / sub;
  const double widthD = static_cast<double>(width);
  const double scale = 255.0 / sub;

  buildEdgeTable(sets, grid.y0, subPitch, lines, scratch);
  std::vector<double>& partial = scratch.partial;
  std::vector<int32_t>& fullDelta = scratch.fullDelta;
  std::vector<uint32_t>& stamp = scratch.pixelStamp;
  std::vector<uint32_t>& events = scratch.events;
  partial.assign(width, 0.0);
  fullDelta.assign(static_cast<std::size_t>(width) + 1, 0);
  stamp.assign(width, 0);
  uint8_t fullValue[257];  // value of a pixel with no fractional part, by whole sub-scanline count
  for (uint32_t c = 0; c <= sub; ++c) fullValue[c] = static_cast<uint8_t>(std::min(c * scale + 0.5, 255.0));

  for (uint32_t j = 0; j < height; ++j) {
    uint8_t* row = out.pixels.data() + static_cast<std::size_t>(grid.mirrorY ? height - 1 - j : j) * width;
    // Event pixels: where a fractional part was added or the whole-pixel count changes. Between two
    // events every pixel has the same value, so it is filled, not computed.
    events.clear();
    const auto touch = [&](uint32_t i) {
      if (stamp[i] != j + 1) {
        stamp[i] = j + 1;
        events.push_back(i);
      }
    };
    for (uint32_t s = 0; s < sub; ++s) {
      const uint32_t k = j * sub + s;
      if (!hasWork(k, scratch)) continue;
      advanceTo(k, samplePosition(grid.y0, subPitch, k), scratch);
      forEachSolidRun(scratch.active, [&](double xa, double xb) {
        const double ua = std::clamp((xa - grid.x0) / grid.pixel, 0.0, widthD);
        const double ub = std::clamp((xb - grid.x0) / grid.pixel, 0.0, widthD);
        if (!(ua < ub)) return;
        const uint32_t ia = static_cast<uint32_t>(ua);  // < width since ua < ub <= width
        const uint32_t ib = static_cast<uint32_t>(ub);  // <= width
        touch(ia);
        if (ia == ib) {
          partial[ia] += ub - ua;
          return;
        }
        partial[ia] += static_cast<double>(ia + 1) - ua;
        ++fullDelta[ia + 1];
        --fullDelta[ib];
        if (ia + 1 < width) touch(ia + 1);
        if (ib < width) {
          partial[ib] += ub - static_cast<double>(ib);
          touch(ib);
        }
      });
    }
    if (events.empty()) {
      std::memset(row, 0, width);
      continue;
    }
    std::sort(events.begin(), events.end());
    const auto fill = [&](uint32_t from, uint32_t to, uint8_t value) {
      if (from < to) std::memset(row + (grid.mirrorX ? width - to : from), value, to - from);
    };
    uint32_t full = 0, next = 0;  // whole sub-scanlines covering pixels [next, event)
    for (const uint32_t i : events) {
      fill(next, i, fullValue[full]);
      full = static_cast<uint32_t>(static_cast<int32_t>(full) + fullDelta[i]);
      const double value = (partial[i] + full) * scale + 0.5;
      row[grid.mirrorX ? width - 1 - i : i] = static_cast<uint8_t>(std::min(value, 255.0));
      partial[i] = 0.0;
      fullDelta[i] = 0;
      next = i + 1;
    }
    fill(next, width, fullValue[full]);
    fullDelta[width] = 0;
  }
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
