// Exact polygon offsets of one layer's solid region (issue "Production print settings": absolute XY
// correction and elephant-foot compensation), through Clipper 6 (Debian's libpolyclipping, the library
// PrusaSlicer uses for the same corrections).
//
// Contract, settled once:
// - The input region is the one the rasterizer lights (core/raster/rasterize.h): every closed loop of every
// set
//   adds its winding number times the set's sign; solid where the count is > 0 (the paper's positive
//   rule). Open polylines and loops with a non-finite coordinate take no part. Loops that touch, overlap
//   or self-intersect are therefore fine: the region is first rebuilt as clean polygons (a union under
//   the positive rule), so an offset never sees a self-intersecting input.
// - Coordinates are rounded to integer nanometres (kOffsetUnitsPerMm) for Clipper; the result has no
//   self-intersections, outer loops counter-clockwise (positive area), holes clockwise, no two loops
//   overlapping. Parts that an inward offset removes (walls thinner than twice the distance) vanish.
// - Before an offset, vertices closer than 0.5 um to their neighbours or to the line through them are
//   dropped (ClipperLib::CleanPolygons' rule, re-derived, with one more condition: a vertex near the
//   line of its neighbours goes only when every vertex dropped between them is near that line too,
//   and at most 256 go between two kept ones): the outline moves by at most 0.5 um, far below a pixel,
//   and the offset of a dense mesh's outline costs about a third less. (Clipper's rule alone lets drop
//   after drop wander: a 4,000-sided circle of 5 mm lost up to 30 um.)
// - Corners use mitred joins with a miter limit of 3 (PrusaSlicer's default for offset_ex): a box grown
//   by d stays a box, (a + 2d) x (b + 2d); corners sharper than about 39 degrees are squared off.
// - Offsets use raw offset loops: ClipperOffset's points (re-derived: outline cleaning, orientation
//   fix, normals, joins and rounding to integer nanometres), with each corner where the moved edges
//   cross (a concave corner when growing, a convex one when shrinking) trimmed where it fits: the
//   detour through the corner is replaced by the crossing of its two moved edges (rounded to a
//   nanometre), which leaves the positive-winding region as it was (docs/DESIGN.md, "Growing by trimmed
//   raw loops"; shrinking a clean region is growing its complement). Where a corner's trims do not fit
//   (short edges), the trim still goes where the small loop it removes lies in the bands that the edges
//   on both sides sweep (with their mitred joins and next edges), and a short edge swallowed by its
//   neighbours' moved edges goes with it (the same section). The union of loops that no longer
//   cross at every such corner costs a fraction of ClipperOffset's. The region is ClipperOffset's
//   wherever the input's count is never negative (its points can differ where Clipper rounds a
//   crossing of its own); where it is negative somewhere, the positive part grows alone, which
//   ClipperOffset's detours did not give. A shrink starts from the union of the input, as
//   ClipperOffset's needs, so its input is always clean.
// - The output layer holds closed loops only; its `facets` entries are kCorrectedFacet (a corrected
//   point lies on no single facet).
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "core/raster/rasterize.h"
#include "core/slicing/contours.h"

namespace toposlice {

inline constexpr double kOffsetUnitsPerMm = 1e6;
inline constexpr uint32_t kCorrectedFacet = 0xffffffffu;

struct LayerCorrection {
  double absolute = 0;      // mm: every solid grown (+) or shrunk (-) by this distance
  double elephantFoot = 0;  // mm >= 0: shrink applied after `absolute`, sparing thin features
  double minWidth = 0;      // mm >= 0: features narrower than this are not shrunk by elephantFoot
  bool any() const { return absolute != 0 || elephantFoot > 0; }
};

// The sets' solid region, corrected, into `out` (cleared first; out.z = z). Steps, in order:
// 1. S = the region of `sets` under the positive rule, grown by `absolute` (shrunk when negative).
// 2. With elephantFoot e > 0 and minWidth w > 0: S shrunk by e, but no feature made narrower than w
//    by it (PrusaSlicer's elefant_foot_min_width): a wall narrower than w keeps its width, one of width
//    d between w and w + 2e ends w wide (to within 2 steps above), a wider one d - 2e. In n = ceil(e /
//    12.5 um) steps of s = e / n: each takes the thin part T of the region R (R minus its opening by
//    w/2 + s: the points that no disc of diameter w + 2s inside R covers, cleaned of slivers thinner
//    than a micrometre) and makes R (R shrunk by s) united with ((T grown by s) within R), so thin
//    features stay joined to the shrunk body by their root. With w = 0, S shrunk by e.
// Returns the number of closed loops written.
std::size_t correctLayer(std::span<const ContourSet> sets, const LayerCorrection& correction, double z,
                         LayerContours& out);

// The corrected region as loops for a rasterizer, without the union that correctLayer's offset ends
// with. Only when `correction` is an absolute correction alone (no elephant foot) that grows a single
// positive set, or that shrinks any sets (returns false otherwise, `out` untouched): the trimmed raw
// offset loops (above; of the sets' union when shrinking), whose positive-winding union (unitePositive)
// is exactly correctLayer's result, so masks of either are the same region. The rasterizers apply the
// positive rule themselves, so masks need no union. Where a corner's detour stays (its trims do
// not fit), the loop crosses itself there.
bool rawCorrectedLoops(std::span<const ContourSet> sets, const LayerCorrection& correction, double z,
                       LayerContours& out);

// The outline cleaning every offset starts with (ClipperLib::CleanPolygon's): the points of `loop`, in
// offset units (kOffsetUnitsPerMm), that it keeps within `distance` units, in the order it returns
// them; none when fewer than three are left.
std::vector<std::array<int64_t, 2>> cleanedOutline(std::span<const std::array<int64_t, 2>> loop,
                                                   double distance);

// The positive-winding region of `loops` (all closed) as clean polygons into `out` (cleared first; out.z =
// z): Clipper's union, as correctLayer's offset ends. Returns the number of loops written.
std::size_t unitePositive(const LayerContours& loops, double z, LayerContours& out);

}  // namespace toposlice
