// Per-layer contours: the output of every slicing path.
//
// A layer holds loops as a flat point array with offsets (CSR). Point i of a loop is where the loop
// enters facet facets[i] (the crossing on that facet's "down" edge, see crossing.h); the loop runs
// through the points in order and returns to its first point (the first point is not repeated).
// Canonical form (DESIGN.md): each loop starts at its lowest facet index and loops are ordered by that
// index. An outer boundary is counter-clockwise seen from +z (positive signed area), a hole clockwise.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

namespace toposlice {

struct Point2d {
  double x, y;
  friend bool operator==(const Point2d&, const Point2d&) = default;
};

struct LayerContours {
  double z = 0;
  std::vector<Point2d> points;
  std::vector<uint32_t> facets;          // facet of each point (the segment's facet)
  std::vector<uint32_t> loopOffsets{0};  // loop l is [loopOffsets[l], loopOffsets[l+1])
  std::vector<uint8_t> loopClosed;       // 1 for a closed loop, 0 for an open polyline (defects)

  std::size_t loopCount() const { return loopOffsets.size() - 1; }
  std::span<const Point2d> loopPoints(std::size_t l) const {
    return std::span<const Point2d>(points).subspan(loopOffsets[l], loopOffsets[l + 1] - loopOffsets[l]);
  }
  std::span<const uint32_t> loopFacets(std::size_t l) const {
    return std::span<const uint32_t>(facets).subspan(loopOffsets[l], loopOffsets[l + 1] - loopOffsets[l]);
  }
  // Empties the layer and keeps the capacity for reuse.
  void clear(double newZ) {
    z = newZ;
    points.clear();
    facets.clear();
    loopOffsets.assign(1, 0);
    loopClosed.clear();
  }
  // Appends one point of the loop being built.
  void addPoint(Point2d p, uint32_t facet) {
    points.push_back(p);
    facets.push_back(facet);
  }
  // Ends the loop made of the points added since the previous endLoop.
  void endLoop(bool closed) {
    loopOffsets.push_back(static_cast<uint32_t>(points.size()));
    loopClosed.push_back(closed ? 1 : 0);
  }
  friend bool operator==(const LayerContours&, const LayerContours&) = default;
};

// Scratch for canonicalizeLayer (kept between layers to avoid allocations).
struct CanonicalScratch {
  std::vector<uint32_t> loopMin, order;
  LayerContours sorted;
};

// Puts a layer's loops into canonical form: each closed loop rotated to start at its lowest facet index
// (first occurrence), open polylines left as they run, and loops ordered by their lowest facet index.
void canonicalizeLayer(LayerContours& layer, CanonicalScratch& scratch);

// Signed area of a closed polygon (shoelace); positive for counter-clockwise seen from +z.
double signedArea(std::span<const Point2d> loop);

// Sum of the signed areas of all loops of a layer (solid area under the even/positive rule for
// properly nested, non-overlapping loops).
double layerSignedArea(const LayerContours& layer);

// Whether two of the layer's counter-clockwise (outer) loops have overlapping bounding boxes. Only then
// can the signed area count a region twice (shells of one model that intersect: overlapping teeth, or
// two parts joined by placing one into the other), so only then does the solid area need the union
// under the positive rule. False for disjoint islands and for a single outer loop with its holes.
bool outerLoopsMayOverlap(const LayerContours& layer);

}  // namespace toposlice
