#include "core/mesh/adjacency.h"

#include <gtest/gtest.h>

#include <algorithm>

#include "core/mesh/mesh_info.h"
#include "core/mesh/weld.h"
#include "tests/fixtures/shapes.h"

namespace toposlice {
namespace {

struct Built {
  IndexedMesh mesh;
  std::vector<int32_t> table;
  EdgeStats stats;
};

Built build(const FacetSoup& soup) {
  Built b{weldCorners(soup.corners), std::vector<int32_t>(soup.corners.size()), {}};
  b.stats = buildAdjacency(b.mesh.facetVertices, b.mesh.vertices.size(), b.table);
  return b;
}

// Every entry names a facet sharing the edge's two vertices in reverse order, and the table is symmetric.
void expectConsistent(const Built& b) {
  const auto& fv = b.mesh.facetVertices;
  const std::size_t t = fv.size() / 3;
  for (std::size_t i = 0; i < t; ++i) {
    for (unsigned j = 0; j < 3; ++j) {
      const int32_t k = b.table[3 * i + j];
      if (k < 0) continue;
      const uint32_t from = fv[3 * i + (j + 1) % 3], to = fv[3 * i + (j + 2) % 3];
      int found = 0;
      for (unsigned m = 0; m < 3; ++m) {
        if (fv[3 * k + (m + 1) % 3] == to && fv[3 * k + (m + 2) % 3] == from) {
          ++found;
          EXPECT_EQ(b.table[3 * k + m], static_cast<int32_t>(i))
              << "asymmetric at facet " << i << " edge " << j;
        }
      }
      EXPECT_EQ(found, 1) << "facet " << i << " edge " << j;
    }
  }
}

TEST(Adjacency, ClosedShapesHaveNoMissingEntries) {
  for (const FacetSoup& soup : {fixtures::box(0, 0, 0, 1, 1, 1), fixtures::sphere(2, 40, 20),
                                fixtures::torus(3, 1, 48, 24), fixtures::squareFrame(3, 1, 0, 1)}) {
    const Built b = build(soup);
    EXPECT_EQ(b.stats.boundary, 0u);
    EXPECT_EQ(b.stats.nonManifold, 0u);
    EXPECT_EQ(b.stats.inconsistent, 0u);
    EXPECT_EQ(b.stats.edges, soup.facetCount() * 3 / 2);
    for (const int32_t e : b.table) EXPECT_GE(e, 0);
    expectConsistent(b);
  }
}

TEST(Adjacency, RemovedFacetLeavesBoundaryEdges) {
  FacetSoup soup = fixtures::sphere(1, 16, 8);
  soup.corners.erase(soup.corners.begin() + 30, soup.corners.begin() + 33);  // drop facet 10
  const Built b = build(soup);
  EXPECT_EQ(b.stats.boundary, 3u);
  EXPECT_EQ(std::count(b.table.begin(), b.table.end(), -1), 3);
  expectConsistent(b);
}

TEST(Adjacency, ThreeFacetsOnOneEdgeAreNonManifold) {
  FacetSoup soup;
  const Point3f a{0, 0, 0}, b{1, 0, 0};
  soup.corners = {a, b, {0, 1, 0}, b, a, {0, -1, 0}, a, b, {0, 0, 1}};
  const Built built = build(soup);
  EXPECT_EQ(built.stats.nonManifold, 1u);
  EXPECT_EQ(built.table[2], -1);
  EXPECT_EQ(built.table[5], -1);
}

TEST(Adjacency, SameDirectionIsInconsistent) {
  FacetSoup soup;
  const Point3f a{0, 0, 0}, b{1, 0, 0};
  soup.corners = {a, b, {0, 1, 0}, a, b, {0, -1, 0}};
  const Built built = build(soup);
  EXPECT_EQ(built.stats.inconsistent, 1u);
  EXPECT_EQ(built.table[2], -1);
}

TEST(MeshInfo, VolumeAreaShells) {
  FacetSoup soup = fixtures::box(0, 0, 0, 2, 3, 4);
  EXPECT_NEAR(signedVolume(soup.corners), 24.0, 1e-9);
  EXPECT_NEAR(surfaceArea(soup.corners), 2 * (6 + 8 + 12), 1e-9);
  fixtures::append(soup, fixtures::box(10, 0, 0, 11, 1, 1));
  const IndexedMesh mesh = weldCorners(soup.corners);
  EXPECT_EQ(countShells(mesh.facetVertices, mesh.vertices.size()), 2u);
  // Inside-out: reversing every facet negates the volume.
  for (std::size_t c = 0; c < soup.corners.size(); c += 3)
    std::swap(soup.corners[c + 1], soup.corners[c + 2]);
  EXPECT_NEAR(signedVolume(soup.corners), -25.0, 1e-9);
}

}  // namespace
}  // namespace toposlice
