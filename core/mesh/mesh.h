// Flat mesh arrays shared by every part of toposlice.
//
// A facet soup is what an STL file holds: facet i owns corners 3i, 3i+1, 3i+2, counter-clockwise seen
// from outside (outward normal by the right-hand rule). An indexed mesh is the welded form: vertices plus
// three uint32 vertex indices per facet, in the same facet order and the same corner order.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace toposlice {

struct Point3f {
  float x, y, z;
};

struct FacetSoup {
  std::vector<Point3f> corners;  // 3 per facet
  std::size_t facetCount() const { return corners.size() / 3; }
};

struct IndexedMesh {
  std::vector<Point3f> vertices;
  std::vector<uint32_t> facetVertices;  // 3 per facet, same corner order as the soup
  std::size_t facetCount() const { return facetVertices.size() / 3; }
};

struct BoundingBox {
  Point3f min{0, 0, 0};
  Point3f max{0, 0, 0};
};

}  // namespace toposlice
