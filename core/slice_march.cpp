#include "core/slice_march.h"

#include <algorithm>

#include "core/crossing.h"

namespace toposlice {

uint32_t marchLayer(std::span<const Point3f> corners, std::span<const int32_t> adjacency,
                    std::span<const uint32_t> active, double z, uint32_t mark, MarchScratch& scratch,
                    LayerContours& out) {
  out.clear(z);
  uint32_t* stamp = scratch.stamp.data();
  const Point3f* soup = corners.data();
  const int32_t* table = adjacency.data();
  uint32_t openCount = 0;

  for (const uint32_t start : active) {
    if (stamp[start] == mark) continue;
    const std::size_t loopBegin = out.points.size();
    uint32_t f = start;
    bool closed = false;
    for (;;) {
      stamp[f] = mark;
      const Point3f* c = soup + 3 * std::size_t{f};
      const unsigned mask = aboveMask(c, z);
      out.addPoint(edgeCrossing(c, kDownEdge[mask], z), f);
      const int32_t next = table[3 * std::size_t{f} + kUpEdge[mask]];
      if (next == static_cast<int32_t>(start)) {
        closed = true;
        break;
      }
      if (next < 0 || stamp[next] == mark) break;
      f = static_cast<uint32_t>(next);
    }
    if (!closed) {
      // Open polyline: append the exit point, then prepend what lies behind `start`.
      const Point3f* c = soup + 3 * std::size_t{f};
      out.addPoint(edgeCrossing(c, kUpEdge[aboveMask(c, z)], z), f);
      scratch.backward.clear();
      uint32_t g = start;
      for (;;) {
        const Point3f* cg = soup + 3 * std::size_t{g};
        const int32_t prev = table[3 * std::size_t{g} + kDownEdge[aboveMask(cg, z)]];
        if (prev < 0 || stamp[prev] == mark) break;
        g = static_cast<uint32_t>(prev);
        stamp[g] = mark;
        scratch.backward.push_back(g);
      }
      if (!scratch.backward.empty()) {
        const std::size_t n = scratch.backward.size();
        std::vector<Point2d> pts(n);
        for (std::size_t i = 0; i < n; ++i) {
          const uint32_t b = scratch.backward[n - 1 - i];
          const Point3f* cb = soup + 3 * std::size_t{b};
          pts[i] = edgeCrossing(cb, kDownEdge[aboveMask(cb, z)], z);
        }
        out.points.insert(out.points.begin() + static_cast<std::ptrdiff_t>(loopBegin), pts.begin(), pts.end());
        out.facets.insert(out.facets.begin() + static_cast<std::ptrdiff_t>(loopBegin), scratch.backward.rbegin(),
                          scratch.backward.rend());
      }
      ++openCount;
    }
    out.endLoop(closed);
  }
  return openCount;
}

}  // namespace toposlice
