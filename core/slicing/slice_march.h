// Marching slicer (the paper's section 3 with the table complete): one layer's contours by walking from
// facet to neighbouring facet through the adjacency table.
//
// Every crossed facet contributes one segment (crossing.h). Starting from the lowest unvisited crossing
// facet, the walk leaves each facet through its up edge into the neighbour across it, until it returns to
// the start (a closed loop). Because facets are taken in ascending order, each loop starts at its lowest
// facet index and loops come out ordered by it: the canonical form of DESIGN.md, with no sorting.
//
// Where the table has -1 (a boundary, non-manifold or inconsistent edge) the walk cannot go on: the
// polyline is extended backwards from its start through known down-edge neighbours and emitted open,
// with its final exit point appended (n segments, n + 1 points), so that nothing is silently dropped.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/mesh/mesh.h"
#include "core/slicing/contours.h"
#include "core/slicing/march_mesh.h"

namespace toposlice {

// Per-thread scratch of the marching kernels. `stamp` holds one entry per facet, initially 0; each call
// marks visited facets with its own non-zero `mark` (layer k uses k + 1), so it is never cleared.
struct MarchScratch {
  std::vector<uint32_t> stamp;
  std::vector<uint32_t> backward;              // facets found walking backwards from an open polyline's start
  CanonicalScratch canonical;                  // record kernel: putting loops in canonical order
  std::vector<uint32_t> visit, previousVisit;  // record kernel: walk order of this and the last layer
  // Call when the next layer is not the one after the last (a new band): drops the prefetch hints.
  void forgetWalk() { visit.clear(); }
  void prepare(std::size_t facetCount) {
    if (stamp.size() != facetCount) stamp.assign(facetCount, 0);
  }
};

// Slices the plane at height z. `active` lists the facets crossing z in ascending order (see
// ActiveFacets). corners: 3 per facet; adjacency: 3 per facet (-1 = unknown / none); `mark` is non-zero
// and differs from every earlier call's with the same scratch. `out` is cleared first and receives this
// layer's canonical loops. Returns the number of open polylines.
uint32_t marchLayer(std::span<const Point3f> corners, std::span<const int32_t> adjacency,
                    std::span<const uint32_t> active, double z, uint32_t mark, MarchScratch& scratch,
                    LayerContours& out);

// The same layer from the reordered mesh (march_mesh.h): `active` lists crossing records (any order);
// `stamp` entries are per record. Loops are walked from whichever record comes first and then put in
// canonical form (closed loops rotated to start at their lowest facet index, loops sorted by it), so the
// result equals marchLayer's bit for bit. Returns the number of open polylines.
uint32_t marchRecordsLayer(std::span<const MarchFacet> records, std::span<const uint32_t> active, double z,
                           uint32_t mark, MarchScratch& scratch, LayerContours& out);

}  // namespace toposlice
