#include "core/slicing/slice_lazy.h"

#include <limits>

#include "core/slicing/crossing.h"

namespace toposlice {

LazySlicer::LazySlicer(std::span<const Point3f> corners, std::span<int32_t> table, double joinTolerance)
    : corners_(corners), table_(table), tolerance2_(joinTolerance * joinTolerance) {
  scratch_.prepare(corners.size() / 3);
}

uint32_t LazySlicer::sliceLayer(std::span<const uint32_t> active, double z, uint32_t layer,
                                LayerContours& out) {
  // Two marks per layer: one for the first march, one for the march after joining.
  const uint32_t firstMark = 2 * layer + 1;
  uint32_t open = marchLayer(corners_, table_, active, z, firstMark, scratch_, out);
  if (open == 0) return 0;

  open_.clear();
  for (std::size_t l = 0; l < out.loopCount(); ++l) {
    if (out.loopClosed[l]) continue;
    const uint32_t b = out.loopOffsets[l], e = out.loopOffsets[l + 1] - 1;
    open_.push_back({out.facets[b], out.facets[e], out.points[b], out.points[e]});
  }
  taken_.assign(open_.size(), 0);
  ++stats_.joinedLayers;
  const Point3f* soup = corners_.data();
  bool joined = false;
  // Closest-point rule: each open end is joined to the nearest free polyline start whose entry edge is
  // the same edge (a start merely touching the point, as at a vertex lying in the plane, never wins).
  for (const OpenEnd& from : open_) {
    const Point3f* a = soup + 3 * std::size_t{from.last};
    const unsigned upA = kUpEdge[aboveMask(a, z)];
    double best = std::numeric_limits<double>::infinity();
    std::size_t bestIndex = open_.size();
    for (std::size_t j = 0; j < open_.size(); ++j) {
      if (taken_[j]) continue;
      const double d = squaredDistance(from.end, open_[j].start);
      if (d > tolerance2_ || d >= best) continue;
      const Point3f* b = soup + 3 * std::size_t{open_[j].first};
      if (!sharesEdge(a, upA, b, kDownEdge[aboveMask(b, z)], tolerance2_)) continue;
      best = d;
      bestIndex = j;
    }
    if (bestIndex == open_.size()) {
      ++stats_.unjoined;
      continue;
    }
    taken_[bestIndex] = 1;
    const uint32_t g = open_[bestIndex].first;
    const Point3f* b = soup + 3 * std::size_t{g};
    table_[3 * std::size_t{from.last} + upA] = static_cast<int32_t>(g);
    table_[3 * std::size_t{g} + kDownEdge[aboveMask(b, z)]] = static_cast<int32_t>(from.last);
    ++stats_.joins;
    joined = true;
  }
  if (joined) open = marchLayer(corners_, table_, active, z, firstMark + 1, scratch_, out);
  return open;
}

}  // namespace toposlice
