// Slicing analytic shapes: per-layer area, loop count, orientation and closedness, for every method,
// including planes through vertices and horizontal facets (the on-plane rule).
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "core/slicing/contours.h"
#include "core/slicing/planes.h"
#include "tests/fixtures/models.h"
#include "tests/fixtures/shapes.h"

namespace toposlice {
namespace {

const SliceMethod kMethods[] = {SliceMethod::ClosestPoint, SliceMethod::SelfReuseLazy,
                                SliceMethod::SelfReuse};

std::vector<double> uniformPlanes(double zmin, double zmax, double h) {
  PlaneSpec spec;
  spec.layerHeight = h;
  std::string error;
  return makePlanes(spec, zmin, zmax, error);
}

// Slices with every method, checks closedness and the facet-wise area, and that all methods agree.
std::vector<LayerContours> sliceAllMethods(const FacetSoup& soup, const std::vector<double>& planes) {
  std::vector<LayerContours> reference;
  for (const SliceMethod method : kMethods) {
    const auto layers = fixtures::sliceToVector(soup, planes, method);
    for (std::size_t k = 0; k < layers.size(); ++k) {
      for (const uint8_t closed : layers[k].loopClosed)
        EXPECT_EQ(closed, 1) << sliceMethodName(method) << " layer " << k;
      EXPECT_NEAR(layerSignedArea(layers[k]), fixtures::facetwiseArea(soup.corners, planes[k]), 1e-9)
          << sliceMethodName(method) << " layer " << k;
    }
    if (reference.empty())
      reference = layers;
    else
      EXPECT_TRUE(layers == reference) << sliceMethodName(method) << " differs from cp";
  }
  return reference;
}

// Outer loops whose boxes overlap (intersecting shells, or an island inside another's hole) may count a
// region twice in the signed area; disjoint islands and an outer loop with its hole do not.
TEST(SliceAnalytic, OuterLoopsMayOverlapOnlyWhenTheirBoxesDo) {
  const auto square = [](LayerContours& layer, double x0, double y0, double size, bool hole) {
    const Point2d corners[4] = {{x0, y0}, {x0 + size, y0}, {x0 + size, y0 + size}, {x0, y0 + size}};
    for (int i = 0; i < 4; ++i) layer.addPoint(corners[hole ? 3 - i : i], 0);
    layer.endLoop(true);
  };
  LayerContours layer;
  square(layer, 0, 0, 10, false);
  EXPECT_FALSE(outerLoopsMayOverlap(layer));
  square(layer, 2, 2, 6, true);     // its hole
  square(layer, 20, 0, 10, false);  // an island beside it, touching no box
  square(layer, 0, 20, 10, false);  // above it
  EXPECT_FALSE(outerLoopsMayOverlap(layer));
  square(layer, 25, 5, 10, false);  // into the island beside
  EXPECT_TRUE(outerLoopsMayOverlap(layer));
  layer.clear(0);
  square(layer, 0, 0, 10, false);
  square(layer, 2, 2, 6, true);
  square(layer, 3, 3, 4, false);  // an island in the hole: its box overlaps the outer loop's
  EXPECT_TRUE(outerLoopsMayOverlap(layer));
}

TEST(SliceAnalytic, BoxLayersAreOneCounterClockwiseRectangle) {
  const FacetSoup soup = fixtures::box(0, 0, 0, 1, 2, 3);
  const auto layers = sliceAllMethods(soup, uniformPlanes(0, 3, 0.25));
  ASSERT_EQ(layers.size(), 12u);
  for (const auto& layer : layers) {
    ASSERT_EQ(layer.loopCount(), 1u);
    EXPECT_NEAR(layerSignedArea(layer), 2.0, 1e-12);
    EXPECT_EQ(layer.loopPoints(0).size(), 8u);  // each side quad is cut across its diagonal: 2 segments
  }
}

TEST(SliceAnalytic, PlanesThroughVerticesFollowTheOnPlaneRule) {
  const FacetSoup soup = fixtures::box(0, 0, 0, 1, 2, 3);
  // z = 0: every vertex counts as above, nothing crosses. z = 3: the top vertices are above, the bottom
  // ones below, so the plane sees the full section (as if it lay just below the top).
  const auto layers = sliceAllMethods(soup, {0.0, 1.0, 3.0});
  EXPECT_EQ(layers[0].loopCount(), 0u);
  ASSERT_EQ(layers[2].loopCount(), 1u);
  EXPECT_NEAR(layerSignedArea(layers[2]), 2.0, 1e-12);
}

TEST(SliceAnalytic, SpherePlanesThroughRingVertices) {
  const FacetSoup soup = fixtures::sphere(2.0, 36, 18);
  std::vector<double> planes;
  for (const Point3f& c : soup.corners) planes.push_back(c.z);  // every ring height, exactly
  std::sort(planes.begin(), planes.end());
  planes.erase(std::unique(planes.begin(), planes.end()), planes.end());
  const auto layers = sliceAllMethods(soup, planes);
  for (std::size_t k = 0; k < layers.size(); ++k) {
    if (k == 0) {
      EXPECT_EQ(layers[k].loopCount(), 0u);  // the south pole: everything above
      continue;
    }
    ASSERT_EQ(layers[k].loopCount(), 1u) << "layer " << k;
    if (k + 1 == layers.size()) {
      // The north pole lies in the plane and counts as above: its fan meets the plane in one point.
      EXPECT_EQ(layerSignedArea(layers[k]), 0.0);
      continue;
    }
    EXPECT_GT(layerSignedArea(layers[k]), 0.0);
  }
}

TEST(SliceAnalytic, SphereAreaApproachesCircle) {
  const double r = 5.0;
  const FacetSoup soup = fixtures::sphere(r, 256, 128);
  const auto planes = uniformPlanes(-r, r, 0.37);
  const auto layers = sliceAllMethods(soup, planes);
  for (std::size_t k = 0; k < layers.size(); ++k) {
    const double z = planes[k];
    if (z >= r) {
      EXPECT_EQ(layers[k].loopCount(), 0u);  // the last plane lies above the pole
      continue;
    }
    const double circle = std::numbers::pi * (r * r - z * z);
    ASSERT_EQ(layers[k].loopCount(), 1u);
    EXPECT_NEAR(layerSignedArea(layers[k]), circle, 0.01 * circle + 0.02) << "z = " << z;
  }
}

TEST(SliceAnalytic, TorusHasOuterLoopAndHole) {
  const double R = 4, r = 1;
  const FacetSoup soup = fixtures::torus(R, r, 128, 64);
  const auto planes = uniformPlanes(-r, r, 0.1);
  const auto layers = sliceAllMethods(soup, planes);
  for (std::size_t k = 0; k < layers.size(); ++k) {
    const auto& layer = layers[k];
    ASSERT_EQ(layer.loopCount(), 2u) << "layer " << k;
    const double a0 = signedArea(layer.loopPoints(0)), a1 = signedArea(layer.loopPoints(1));
    EXPECT_GT(std::max(a0, a1), 0.0);
    EXPECT_LT(std::min(a0, a1), 0.0);  // the hole runs clockwise
    const double w = std::sqrt(r * r - planes[k] * planes[k]);
    const double ring = std::numbers::pi * ((R + w) * (R + w) - (R - w) * (R - w));
    EXPECT_NEAR(a0 + a1, ring, 0.02 * ring);
  }
}

TEST(SliceAnalytic, HorizontalFacetsInThePlane) {
  // The frame's top and bottom rings are horizontal; planes exactly at z0 and z1.
  const FacetSoup soup = fixtures::squareFrame(3.0f, 1.0f, 0.0f, 2.0f);
  const auto layers = sliceAllMethods(soup, {0.0, 1.0, 2.0});
  EXPECT_EQ(layers[0].loopCount(), 0u);
  for (const std::size_t k : {1u, 2u}) {
    ASSERT_EQ(layers[k].loopCount(), 2u);
    EXPECT_NEAR(layerSignedArea(layers[k]), 36.0 - 4.0, 1e-12);
  }
}

TEST(SliceAnalytic, CanonicalLoopsStartAtLowestFacet) {
  const FacetSoup soup = fixtures::examplePart();
  const auto planes = uniformPlanes(0, 6.2, 0.1);
  const auto layers = sliceAllMethods(soup, planes);
  for (const auto& layer : layers) {
    uint32_t previous = 0;
    for (std::size_t l = 0; l < layer.loopCount(); ++l) {
      const auto facets = layer.loopFacets(l);
      EXPECT_EQ(*std::min_element(facets.begin(), facets.end()), facets[0]);
      if (l > 0) {
        EXPECT_GT(facets[0], previous);
      }
      previous = facets[0];
    }
  }
}

TEST(SliceAnalytic, BandSizesGiveIdenticalLayers) {
  const FacetSoup soup = fixtures::examplePart();
  const auto planes = uniformPlanes(0, 6.2, 0.05);
  const auto reference = fixtures::sliceToVector(soup, planes, SliceMethod::SelfReuse, 1000);
  for (const uint32_t band : {1u, 3u, 7u, 64u})
    EXPECT_TRUE(fixtures::sliceToVector(soup, planes, SliceMethod::SelfReuse, band) == reference) << band;
}

TEST(SliceAnalytic, EmbreeCandidatesGiveIdenticalLayers) {
  FacetSoup soup = fixtures::examplePart();
  soup.corners.push_back({1, 1, 1});  // plus a degenerate facet, which both searches must skip
  soup.corners.push_back({1, 1, 1});
  soup.corners.push_back({2, 1, 3});
  const auto planes = uniformPlanes(0, 6.2, 0.05);
  for (const SliceMethod method : {SliceMethod::SelfReuse, SliceMethod::ClosestPoint}) {
    SliceSettings sweep;
    sweep.method = method;
    sweep.bandLayers = 5;
    SliceSettings embree = sweep;
    embree.candidates = CandidateSearch::Embree;
    EXPECT_TRUE(fixtures::sliceToVector(soup, planes, embree) == fixtures::sliceToVector(soup, planes, sweep))
        << sliceMethodName(method);
  }
}

TEST(SliceAnalytic, OpenMeshGivesOpenPolylines) {
  FacetSoup soup = fixtures::sphere(1, 16, 8);
  soup.corners.erase(soup.corners.begin() + 3 * 40, soup.corners.begin() + 3 * 41);
  const auto planes = uniformPlanes(-1, 1, 0.05);
  SliceStats stats;
  const auto layers = fixtures::sliceToVector(soup, planes, SliceMethod::SelfReuse, 0, &stats);
  EXPECT_GT(stats.openPolylines, 0u);
  for (const auto& layer : layers)
    for (std::size_t l = 0; l < layer.loopCount(); ++l)
      if (!layer.loopClosed[l]) {
        EXPECT_GE(layer.loopPoints(l).size(), 2u);
      }
}

}  // namespace
}  // namespace toposlice
