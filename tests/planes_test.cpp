#include "core/slicing/planes.h"

#include <gtest/gtest.h>

#include <algorithm>

#include "core/slicing/layer_ranges.h"
#include "tests/fixtures/shapes.h"

namespace toposlice {
namespace {

TEST(Planes, LayerHeightGivesMidLayerPlanes) {
  PlaneSpec spec;
  spec.layerHeight = 0.25;
  std::string error;
  const auto planes = makePlanes(spec, 1.0, 2.0, error);
  ASSERT_TRUE(error.empty());
  ASSERT_EQ(planes.size(), 4u);
  EXPECT_DOUBLE_EQ(planes[0], 1.125);
  EXPECT_DOUBLE_EQ(planes[3], 1.875);
}

TEST(Planes, CountRoundsUpAndZ0Moves) {
  PlaneSpec spec;
  spec.layerHeight = 0.3;
  spec.z0 = 0.5;
  std::string error;
  const auto planes = makePlanes(spec, 0.0, 1.0, error);
  ASSERT_EQ(planes.size(), 2u);  // ceil(0.5 / 0.3)
  EXPECT_DOUBLE_EQ(planes[0], 0.65);
}

TEST(Planes, LayerCountAloneDividesHeight) {
  PlaneSpec spec;
  spec.layers = 10;
  std::string error;
  const auto planes = makePlanes(spec, -1.0, 1.0, error);
  ASSERT_EQ(planes.size(), 10u);
  EXPECT_DOUBLE_EQ(planes[0], -0.9);
}

TEST(Planes, BadSpecificationsAreErrors) {
  std::string error;
  PlaneSpec zero;
  zero.layerHeight = 0.0;
  EXPECT_TRUE(makePlanes(zero, 0, 1, error).empty());
  EXPECT_NE(error.find("positive"), std::string::npos);
  PlaneSpec unsorted;
  unsorted.explicitZ = {0.5, 0.2};
  EXPECT_TRUE(makePlanes(unsorted, 0, 1, error).empty());
  EXPECT_NE(error.find("increasing"), std::string::npos);
  EXPECT_TRUE(makePlanes(PlaneSpec{}, 0, 1, error).empty());
}

TEST(Planes, ParseZList) {
  std::vector<double> z;
  EXPECT_TRUE(parseZList("0.1, 0.2 0.35", z));
  EXPECT_EQ(z, (std::vector<double>{0.1, 0.2, 0.35}));
  EXPECT_FALSE(parseZList("0.1,abc", z));
}

TEST(LayerRanges, OnPlaneVertexCountsAbove) {
  // One facet spanning z 1..2; planes at exactly 1 and 2 and between.
  const std::vector<Point3f> corners = {{0, 0, 1}, {1, 0, 1}, {0, 0, 2}};
  const std::vector<double> planes = {0.5, 1.0, 1.5, 2.0, 2.5};
  const FacetLayers layers = computeFacetLayers(corners, planes);
  // Crosses z when zmin < z <= zmax: 1.5 and 2.0, not 1.0 (all above) and not 2.5.
  EXPECT_EQ(layers.first[0], 2u);
  EXPECT_EQ(layers.last[0], 3u);
}

TEST(LayerRanges, SweepMatchesBruteForce) {
  const FacetSoup soup = fixtures::torus(3, 1, 40, 20);
  std::vector<double> planes;
  for (int k = 0; k < 50; ++k) planes.push_back(-1.2 + 0.05 * k);
  const FacetLayers layers = computeFacetLayers(soup.corners, planes);
  ActiveFacets sweep;
  for (uint32_t k = 0; k < planes.size(); ++k) {
    if (k == 0)
      sweep.start(layers, 0);
    else
      sweep.advance(layers);
    std::vector<uint32_t> expected;
    for (uint32_t f = 0; f < soup.facetCount(); ++f) {
      const float a = soup.corners[3 * f].z, b = soup.corners[3 * f + 1].z, c = soup.corners[3 * f + 2].z;
      if (std::min({a, b, c}) < planes[k] && planes[k] <= std::max({a, b, c})) expected.push_back(f);
    }
    const auto got = sweep.facets();
    EXPECT_EQ(std::vector<uint32_t>(got.begin(), got.end()), expected) << "layer " << k;
  }
}

}  // namespace
}  // namespace toposlice
