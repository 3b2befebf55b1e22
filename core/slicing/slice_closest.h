// The closest-point baseline (the paper's classic method): per layer, intersect every crossing facet
// with the plane, then connect the segments by repeatedly searching all unexplored segments for the
// start point nearest to the current end point: O(s^2) in the segments of a layer. It is the reference
// every other path is compared with, and the benchmark baseline.
//
// Crossing facets come from the same layer sweep as the other paths (the paper scans every facet per
// layer; that part is not what the method is measured on). Ties at equal distance (a vertex lying in
// the plane makes several segments meet at one point) go to the segment entering through the same edge.
// A loop starts at the lowest unexplored facet, so the output is canonical without sorting.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/mesh/mesh.h"
#include "core/slicing/contours.h"

namespace toposlice {

struct ClosestScratch {
  struct Segment {
    Point2d start, end;
    uint32_t facet;
    uint8_t downEdge, upEdge;
  };
  std::vector<Segment> segments;
  std::vector<uint32_t> unexplored;  // indices into segments, compacted as they are used
};

// Slices plane z; `active` lists the crossing facets in ascending order. Segment ends farther apart
// than sqrt(tolerance2) are not joined (the polyline is emitted open). Returns the open polyline count.
uint32_t closestPointLayer(std::span<const Point3f> corners, std::span<const uint32_t> active, double z,
                           double tolerance2, ClosestScratch& scratch, LayerContours& out);

}  // namespace toposlice
