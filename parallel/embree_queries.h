// Spatial queries on a facet soup, answered by Embree BVHs (the only place Embree is reached through).
//
// Two structures, each built only when asked for (FacetBvh::Queries):
// - Slab queries (which facets a z range or a plane touches): Embree's SAH builder (rtcBuildBVH) builds a
//   4-wide tree over the facets' bounding boxes; it is flattened into index arrays (per child the z range,
//   per leaf entry the facet and its exact float z range), so a query is a short serial walk with no
//   Embree call, and every answer is filtered exactly against the facet's own z range.
// - Ray queries (every facet a line parallel to x meets): an Embree scene of one user geometry whose
//   primitives are the facets' boxes; rtcIntersect1 walks Embree's BVH and calls back for every box the
//   ray touches; the callback decides the crossing exactly (below) and records it without ending the
//   ray, so all crossings are found.
//
// Crossing rule of rayCrossings, settled once (symbolic perturbation, consistent with the slicer's
// on-plane rule and the rasterizer's half-open sampling): the line {(t, y, z)} is treated as lying at
// (y + d, z - e) with e >> d > 0 infinitesimal. So a vertex with z >= the line's z counts as above it,
// then a vertex with y <= the line's y counts as below it; the line meets a facet when this perturbed
// point lies strictly inside the facet's projection onto the yz plane. Every crossing is therefore
// strict; a facet whose projection has no area (normal with zero x component, degenerate facets) is never
// crossed; and a closed 2-manifold is crossed an even number of times, with no double counts or gaps at
// shared edges and vertices: each mesh edge's side test is computed from its two end points in one
// canonical order, so the two facets sharing the edge see the same bits with opposite signs.
// Each crossing carries the winding step of the facet: +1 where the line enters an outward-oriented
// solid (facet normal's x component < 0), -1 where it leaves (> 0). The winding number of a point
// (x, y, z) is the sum of the steps of the crossings with crossing x <= point x (the rasterizer's
// half-open runs: a point on a left boundary is inside, on a right boundary outside).
//
// The soup's memory is referenced, not copied (Embree's ray scene reads the corners through the bounds
// callback): the span must outlive the FacetBvh. Coordinates must be finite. All queries are const and
// thread-safe; each call writes only its output vector.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "core/mesh/mesh.h"
#include "core/slicing/march_mesh.h"

namespace toposlice {

// One crossing of a line parallel to x with a facet (see the crossing rule above).
struct RayCrossing {
  double x;        // where the line meets the facet (double barycentric interpolation)
  uint32_t facet;  // facet index in the soup
  int32_t step;    // winding change when passing it in +x: +1 entering (normal x < 0), -1 leaving
  friend bool operator==(const RayCrossing&, const RayCrossing&) = default;
};

// Whether a facet list must come out in ascending facet order (sorted after the walk) or in any order.
enum class FacetOrder { Ascending, Any };

class FacetBvh {
 public:
  enum Queries : unsigned { kSlabQueries = 1, kRayQueries = 2, kAllQueries = 3 };

  // Builds the structures for `queries` over `corners` (3 per facet, fewer than 2^32 facets, finite).
  // Throws std::runtime_error when Embree fails (out of memory, unsupported CPU).
  explicit FacetBvh(std::span<const Point3f> corners, unsigned queries = kAllQueries);
  ~FacetBvh();
  FacetBvh(FacetBvh&&) noexcept;
  FacetBvh& operator=(FacetBvh&&) noexcept;
  FacetBvh(const FacetBvh&) = delete;
  FacetBvh& operator=(const FacetBvh&) = delete;

  std::size_t facetCount() const;

  // Every facet whose z range [zmin, zmax] meets [zlo, zhi] (zmin <= zhi and zmax >= zlo; nothing when
  // zlo > zhi). Needs kSlabQueries. `out` is overwritten.
  void facetsInSlab(double zlo, double zhi, std::vector<uint32_t>& out,
                    FacetOrder order = FacetOrder::Ascending) const;

  // Exactly the facets with zmin < z <= zmax (the on-plane rule, crossing.h), degenerate facets
  // included (the slicer skips those; startRecordsFromBvh does too). Needs kSlabQueries.
  void facetsCrossingPlane(double z, std::vector<uint32_t>& out,
                           FacetOrder order = FacetOrder::Ascending) const;

  // Every crossing of the line {(t, y, z): t real} with the facets, ordered by x, then facet index.
  // Needs kRayQueries. `out` is overwritten.
  void rayCrossings(double y, double z, std::vector<RayCrossing>& out) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The band start of the marching kernel from the BVH instead of ActiveRecords::start's linear scan:
// `records` is overwritten with mesh.position[f] for every non-degenerate facet f crossing plane `z`,
// which must be the plane of layer `layer` of the planes `mesh` was built for. The set equals
// ActiveRecords::start(mesh, layer).records(); the order is unspecified (marchRecordsLayer
// canonicalizes). Needs a FacetBvh with kSlabQueries over the soup `mesh` was built from.
void startRecordsFromBvh(const FacetBvh& bvh, const MarchMesh& mesh, double z, uint32_t layer,
                         std::vector<uint32_t>& records);

}  // namespace toposlice
