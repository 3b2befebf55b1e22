// How one facet meets one plane: the degenerate cases, settled once.
//
// On-plane rule (DESIGN.md, symbolic perturbation): a vertex with z >= plane counts as ABOVE the plane.
// So a facet crosses plane z exactly when zmin < z <= zmax, every crossed facet has exactly one edge
// traversed from above to below (its "down" edge) and one from below to above (its "up" edge), and no
// epsilon or special case is needed for vertices, edges or whole facets lying in the plane.
//
// Edge numbering follows the adjacency table: edge j of a facet is the edge opposite corner j, running
// corner j+1 -> corner j+2 in the facet's counter-clockwise order.
//
// Orientation: for an outward-facing facet, the segment that keeps material on its left (so outer loops
// are counter-clockwise seen from +z) runs from the crossing on the down edge to the crossing on the up
// edge. Marching therefore leaves a facet through its up edge, and enters the neighbour through the
// neighbour's down edge (the same geometric edge, traversed the other way).
//
// Crossing point: computed from the edge's below end `a` and above end `b` as a + (z - a.z) s, with the
// slope s = (b - a) / (b.z - a.z), in double. Both facets sharing an edge see the same (a, b), so every
// path computes bit-identical points; a path that keeps (a, s) for many layers (slice_follow.h) gets the
// same bits as one that derives them afresh. (The build disables floating-point contraction, so no
// compiler turns one of these into a fused multiply-add and another not.)
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>

#include "core/mesh/mesh.h"
#include "core/slicing/contours.h"

namespace toposlice {

// Bit i set when corner i is above (or on) the plane. Codes 1..6 cross the plane; 0 and 7 do not.
inline unsigned aboveMask(const Point3f* corners, double z) {
  return (static_cast<double>(corners[0].z) >= z ? 1u : 0u) |
         (static_cast<double>(corners[1].z) >= z ? 2u : 0u) |
         (static_cast<double>(corners[2].z) >= z ? 4u : 0u);
}

inline bool crossesPlane(unsigned mask) {
  return mask != 0 && mask != 7;
}

// A facet with two equal corners (bitwise, -0.0 == +0.0) has no area and no direction: it is skipped by
// every slicing path and by the adjacency table, and counted. (After welding, these are exactly the
// facets with a repeated vertex index.)
inline bool isDegenerateFacet(const Point3f* c) {
  auto same = [](const Point3f& a, const Point3f& b) { return a.x == b.x && a.y == b.y && a.z == b.z; };
  return same(c[0], c[1]) || same(c[1], c[2]) || same(c[0], c[2]);
}

// Down edge (above -> below) and up edge (below -> above) for each crossing mask; index 0 and 7 unused.
inline constexpr uint8_t kDownEdge[8] = {0, 2, 0, 0, 1, 2, 1, 0};
inline constexpr uint8_t kUpEdge[8] = {0, 1, 2, 1, 0, 0, 2, 0};

// The line along which the crossing of one edge moves with the plane: its below end and slope.
struct EdgeLine {
  double sx, sy;     // (b - a) / (b.z - a.z) for x and y
  float ax, ay, az;  // the below end a
  Point2d at(double z) const {
    const double d = z - static_cast<double>(az);
    return {static_cast<double>(ax) + d * sx, static_cast<double>(ay) + d * sy};
  }
};

// Line of edge `edge` (opposite corner `edge`) of a facet crossed by plane z. Works for either direction
// of traversal: the below end is always the base.
inline EdgeLine edgeLine(const Point3f* corners, unsigned edge, double z) {
  const Point3f& p = corners[edge == 2 ? 0 : edge + 1];
  const Point3f& q = corners[edge == 0 ? 2 : edge - 1];
  const bool pBelow = static_cast<double>(p.z) < z;
  const Point3f& a = pBelow ? p : q;
  const Point3f& b = pBelow ? q : p;
  const double dz = static_cast<double>(b.z) - a.z;
  return {(static_cast<double>(b.x) - a.x) / dz, (static_cast<double>(b.y) - a.y) / dz, a.x, a.y, a.z};
}

// Crossing of edge `edge` of a crossed facet with plane z.
inline Point2d edgeCrossing(const Point3f* corners, unsigned edge, double z) {
  return edgeLine(corners, edge, z).at(z);
}

}  // namespace toposlice

namespace toposlice {

inline double squaredDistance(Point2d a, Point2d b) {
  const double dx = a.x - b.x, dy = a.y - b.y;
  return dx * dx + dy * dy;
}

inline double squaredDistance(const Point3f& a, const Point3f& b) {
  const double dx = double{a.x} - b.x, dy = double{a.y} - b.y, dz = double{a.z} - b.z;
  return dx * dx + dy * dy + dz * dz;
}

// True when edge `ea` of facet a and edge `eb` of facet b join the same two corner positions in opposite
// directions (each pair within sqrt(tolerance2)): the test that two facets really are neighbours across
// those edges, used where adjacency is discovered from geometry (sr-lazy, closest point).
inline bool sharesEdge(const Point3f* a, unsigned ea, const Point3f* b, unsigned eb, double tolerance2) {
  const unsigned a1 = (ea + 1) % 3, a2 = (ea + 2) % 3, b1 = (eb + 1) % 3, b2 = (eb + 2) % 3;
  return squaredDistance(a[a1], b[b2]) <= tolerance2 && squaredDistance(a[a2], b[b1]) <= tolerance2;
}

}  // namespace toposlice

namespace toposlice {

// The smallest float >= z. For a float coordinate v, (v >= z) == (v >= planeAsFloat(z)), so the on-plane
// rule can be applied with float compares and still match the double-precision rule exactly.
inline float planeAsFloat(double z) {
  float f = static_cast<float>(z);
  if (static_cast<double>(f) < z) f = std::nextafter(f, std::numeric_limits<float>::infinity());
  return f;
}

inline unsigned aboveMaskF(const Point3f* corners, float zf) {
  return (corners[0].z >= zf ? 1u : 0u) | (corners[1].z >= zf ? 2u : 0u) | (corners[2].z >= zf ? 4u : 0u);
}

}  // namespace toposlice
