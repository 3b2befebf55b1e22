// Closing open polylines of defective meshes (boundary and non-manifold edges end the marching walk).
//
// Within one layer, every open polyline's end may be joined to an open polyline's start (its own
// included, which closes it) when the two points are at most `maxGap` apart. Candidate joins are taken
// nearest first (ties by polyline order, so the result is deterministic), each end and each start at
// most once. Chains that come back to themselves become closed loops, the gap bridged by a straight
// edge. With `closeRest` the chains still open are then matched the same way with no distance limit,
// so every chain closes (a loop broken by several holes is rejoined piece to piece; a single open
// curve, such as the section of an open base, closes on itself with a chord); without it they stay
// open. Every kind is counted. The layer is then put back in canonical form.
#pragma once

#include <cstdint>
#include <vector>

#include "core/slicing/contours.h"

namespace toposlice {

struct GapStats {
  uint64_t joins = 0;             // gaps bridged
  uint64_t closedLoops = 0;       // loops closed by bridges alone
  uint64_t selfClosed = 0;        // joins wider than the gap limit, made to close every chain (closeRest)
  uint64_t closedLoopsWider = 0;  // loops whose closing took a join wider than the limit
  uint64_t leftOpen = 0;          // polylines still open
  GapStats& operator+=(const GapStats& o) {
    joins += o.joins;
    closedLoops += o.closedLoops;
    selfClosed += o.selfClosed;
    closedLoopsWider += o.closedLoopsWider;
    leftOpen += o.leftOpen;
    return *this;
  }
};

struct GapScratch {
  struct Candidate {
    double distance2;
    uint32_t from, to;  // open polyline indices: end of `from` to start of `to`
  };
  std::vector<uint32_t> open;  // loop index of each open polyline
  std::vector<Candidate> candidates;
  std::vector<int32_t> next, prev;
  std::vector<uint8_t> used, wide;
  LayerContours rebuilt;
  CanonicalScratch canonical;
};

// Bridges gaps of at most maxGap (mm) between open polylines of `layer`, then closes what is still open
// when closeRest; returns this layer's counts.
GapStats closeGaps(LayerContours& layer, double maxGap, bool closeRest, GapScratch& scratch);

}  // namespace toposlice
