#include "core/mesh/weld.h"

#include <gtest/gtest.h>

#include <cmath>

#include "tests/fixtures/shapes.h"

namespace toposlice {
namespace {

TEST(Weld, CubeCornersBecomeEightVertices) {
  const FacetSoup cube = fixtures::box(0, 0, 0, 1, 2, 3);
  const IndexedMesh mesh = weldCorners(cube.corners);
  EXPECT_EQ(mesh.vertices.size(), 8u);
  ASSERT_EQ(mesh.facetVertices.size(), 36u);
  for (std::size_t c = 0; c < 36; ++c) {
    const Point3f& p = mesh.vertices[mesh.facetVertices[c]];
    EXPECT_EQ(p.x, cube.corners[c].x);
    EXPECT_EQ(p.y, cube.corners[c].y);
    EXPECT_EQ(p.z, cube.corners[c].z);
  }
}

TEST(Weld, NegativeZeroWeldsWithPositiveZero) {
  const std::vector<Point3f> corners = {{0.0f, 1, 2}, {-0.0f, 1, 2}, {1, -0.0f, 0.0f}, {1, 0.0f, -0.0f}};
  const IndexedMesh mesh = weldCorners(corners);
  EXPECT_EQ(mesh.vertices.size(), 2u);
  EXPECT_EQ(mesh.facetVertices[0], mesh.facetVertices[1]);
  EXPECT_EQ(mesh.facetVertices[2], mesh.facetVertices[3]);
}

TEST(Weld, NearlyEqualCornersStayApart) {
  const float a = 1.0f;
  const float b = std::nextafter(a, 2.0f);
  const std::vector<Point3f> corners = {{a, 0, 0}, {b, 0, 0}, {a, 0, 0}};
  const IndexedMesh mesh = weldCorners(corners);
  EXPECT_EQ(mesh.vertices.size(), 2u);
  EXPECT_EQ(mesh.facetVertices[0], 0u);
  EXPECT_EQ(mesh.facetVertices[1], 1u);
  EXPECT_EQ(mesh.facetVertices[2], 0u);
}

TEST(Weld, SphereHasEulerVertexCount) {
  const FacetSoup s = fixtures::sphere(1.0, 32, 16);
  const IndexedMesh mesh = weldCorners(s.corners);
  // V - E + F = 2 with E = 3F/2.
  const std::size_t f = s.facetCount();
  EXPECT_EQ(mesh.vertices.size(), 2 + f / 2);
}

}  // namespace
}  // namespace toposlice
