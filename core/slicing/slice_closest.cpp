#include "core/slicing/slice_closest.h"

#include <limits>

#include "core/slicing/crossing.h"

namespace toposlice {

uint32_t closestPointLayer(std::span<const Point3f> corners, std::span<const uint32_t> active, double z,
                           double tolerance2, ClosestScratch& scratch, LayerContours& out) {
  out.clear(z);
  auto& segments = scratch.segments;
  segments.clear();
  for (const uint32_t f : active) {
    const Point3f* c = &corners[3 * std::size_t{f}];
    const unsigned mask = aboveMask(c, z);
    segments.push_back({edgeCrossing(c, kDownEdge[mask], z), edgeCrossing(c, kUpEdge[mask], z), f,
                        kDownEdge[mask], kUpEdge[mask]});
  }
  // Unexplored segments in ascending facet order; removal keeps the order (erase by shifting), so the
  // next loop always starts at the lowest unexplored facet.
  auto& unexplored = scratch.unexplored;
  unexplored.resize(segments.size());
  for (std::size_t i = 0; i < segments.size(); ++i) unexplored[i] = static_cast<uint32_t>(i);

  uint32_t openCount = 0;
  while (!unexplored.empty()) {
    const uint32_t first = unexplored.front();
    unexplored.erase(unexplored.begin());
    uint32_t current = first;
    bool closed = false;
    for (;;) {
      const auto& seg = segments[current];
      out.addPoint(seg.start, seg.facet);
      const Point3f* a = &corners[3 * std::size_t{seg.facet}];
      auto better = [&](uint32_t candidate, double d, double best, bool bestShares) {
        if (d > tolerance2 || d > best) return std::pair{false, false};
        const auto& s = segments[candidate];
        const bool shares =
            sharesEdge(a, seg.upEdge, &corners[3 * std::size_t{s.facet}], s.downEdge, tolerance2);
        return std::pair{d < best || (shares && !bestShares), shares};
      };
      double best = std::numeric_limits<double>::infinity();
      bool bestShares = false;
      std::size_t bestPos = SIZE_MAX;  // position in unexplored; SIZE_MAX - 1 = close the loop
      {
        const auto [take, shares] =
            better(first, squaredDistance(seg.end, segments[first].start), best, bestShares);
        if (take && current != first) {
          best = squaredDistance(seg.end, segments[first].start);
          bestShares = shares;
          bestPos = SIZE_MAX - 1;
        }
      }
      for (std::size_t p = 0; p < unexplored.size(); ++p) {
        const double d = squaredDistance(seg.end, segments[unexplored[p]].start);
        if (d > best) continue;
        const auto [take, shares] = better(unexplored[p], d, best, bestShares);
        if (take) {
          best = d;
          bestShares = shares;
          bestPos = p;
        }
      }
      if (bestPos == SIZE_MAX - 1) {
        closed = true;
        break;
      }
      if (bestPos == SIZE_MAX) {  // no start within the tolerance: an open polyline
        out.addPoint(seg.end, seg.facet);
        break;
      }
      current = unexplored[bestPos];
      unexplored.erase(unexplored.begin() + static_cast<std::ptrdiff_t>(bestPos));
    }
    if (!closed) ++openCount;
    out.endLoop(closed);
  }
  return openCount;
}

}  // namespace toposlice
