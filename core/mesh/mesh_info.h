// Whole-mesh measures reported by `toposlice info` and the slice summary.
#pragma once

#include <algorithm>
#include <cstdint>
#include <span>

#include "core/mesh/adjacency.h"
#include "core/mesh/mesh.h"

namespace toposlice {

struct MeshInfo {
  uint64_t facets = 0;
  uint64_t vertices = 0;  // after welding
  BoundingBox bounds;
  double volume = 0;  // signed; negative for an inside-out mesh
  double surfaceArea = 0;
  uint64_t shells = 0;  // connected components (facets sharing a vertex are connected)
  EdgeStats edges;
};

BoundingBox boundsOf(std::span<const Point3f> points);

// The smallest box holding both.
inline BoundingBox unite(const BoundingBox& a, const BoundingBox& b) {
  return {{std::min(a.min.x, b.min.x), std::min(a.min.y, b.min.y), std::min(a.min.z, b.min.z)},
          {std::max(a.max.x, b.max.x), std::max(a.max.y, b.max.y), std::max(a.max.z, b.max.z)}};
}

// `box` grown to hold every corner of `soups` (a model's box and its add-ons, say).
inline BoundingBox unite(BoundingBox box, std::span<const FacetSoup> soups) {
  for (const FacetSoup& soup : soups) box = unite(box, boundsOf(soup.corners));
  return box;
}

// Signed volume of the soup (divergence theorem, tetrahedra against the bounding-box centre), in double.
double signedVolume(std::span<const Point3f> corners);

// Six times the signed volume of facets [beginFacet, endFacet) against the centre of `bounds` (the whole
// soup's): the terms of signedVolume, for callers that sum fixed blocks in parallel (and add them in
// block order).
double signedVolumeTerms(std::span<const Point3f> corners, const BoundingBox& bounds, std::size_t beginFacet,
                         std::size_t endFacet);

double surfaceArea(std::span<const Point3f> corners);

// Connected components of the welded mesh (union-find over vertices, linear time).
uint64_t countShells(std::span<const uint32_t> facetVertices, std::size_t vertexCount);

}  // namespace toposlice
