#include "core/mesh/weld.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <span>
#include <vector>

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

// The weld fed in pieces of any size (as a reader feeds it) is the weld of the whole soup, also when
// nothing is shared and its table must grow many times over.
TEST(Weld, PiecesOfAnySizeGiveTheWholeWeld) {
  std::mt19937 random(11);
  std::vector<Point3f> corners;
  for (int i = 0; i < 150000; ++i) {  // unique corners, with every fifth one repeating an earlier one
    if (i % 5 == 4 && !corners.empty()) {
      corners.push_back(corners[random() % corners.size()]);
    } else {
      corners.push_back({static_cast<float>(random() % 100000), static_cast<float>(i), -0.0f});
    }
  }
  const IndexedMesh whole = weldCorners(corners);
  EXPECT_GT(whole.vertices.size(), 110000u);
  for (const std::size_t piece : {std::size_t{1}, std::size_t{7}, std::size_t{4096}, corners.size()}) {
    IncrementalWeld weld(piece == 1 ? 3 : corners.size());  // a wrong expectation only costs growth
    for (std::size_t at = 0; at < corners.size(); at += piece)
      weld.add(std::span<const Point3f>(corners).subspan(at, std::min(piece, corners.size() - at)));
    const IndexedMesh got = weld.take();
    EXPECT_EQ(got.facetVertices, whole.facetVertices) << piece;
    ASSERT_EQ(got.vertices.size(), whole.vertices.size()) << piece;
    EXPECT_EQ(
        std::memcmp(got.vertices.data(), whole.vertices.data(), whole.vertices.size() * sizeof(Point3f)), 0);
  }
}

}  // namespace
}  // namespace toposlice
