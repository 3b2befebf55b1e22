// Self reuse as the paper's section 3 describes it ("sr-lazy"): the adjacency table starts at -1 (or is
// loaded from a template), each layer is marched along the entries already known, the resulting open
// polylines are joined by the closest-point rule, and every join that is a real shared edge is written
// into the table, so later layers march through it without searching. Needs no welded vertices: facets
// are matched by geometry, so corners that differ by up to the join tolerance are still joined.
//
// The table is shared mutable state, so layers are sliced in order on one thread. Output is the same
// canonical form as every other path: after the joins the layer is marched again through the completed
// table (only on layers that needed joins).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/mesh/mesh.h"
#include "core/slicing/contours.h"
#include "core/slicing/slice_march.h"

namespace toposlice {

struct LazyStats {
  uint64_t joinedLayers = 0;  // layers that needed closest-point joins
  uint64_t joins = 0;         // polyline ends joined (each writes two table entries)
  uint64_t unjoined = 0;      // polyline ends left open (no neighbour within the tolerance)
};

class LazySlicer {
 public:
  // `table`: 3 entries per facet, -1 where unknown; updated in place. joinTolerance (mm): how far apart
  // the corners of a shared edge may be (0 for bit-identical corners).
  LazySlicer(std::span<const Point3f> corners, std::span<int32_t> table, double joinTolerance);

  // Slices plane z (`active`: crossing facets, ascending); `layer` indexes the plane and must increase
  // from call to call. Returns the number of open polylines left in `out`.
  uint32_t sliceLayer(std::span<const uint32_t> active, double z, uint32_t layer, LayerContours& out);

  const LazyStats& stats() const { return stats_; }

 private:
  struct OpenEnd {
    uint32_t first, last;  // first and last facet of an open polyline
    Point2d start, end;    // its first and last point
  };
  std::span<const Point3f> corners_;
  std::span<int32_t> table_;
  double tolerance2_;
  MarchScratch scratch_;
  std::vector<OpenEnd> open_;
  std::vector<uint8_t> taken_;
  LazyStats stats_;
};

}  // namespace toposlice
