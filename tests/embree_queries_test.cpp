// FacetBvh (parallel/embree_queries.h) against brute-force scans: slab and plane queries on analytic
// shapes and a real model, planes exactly at vertex heights included; band starts equal to the
// marching kernel's linear scan; ray crossings complete and watertight (rays through vertices included).
#include "parallel/embree_queries.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <set>
#include <vector>

#include "core/slicing/crossing.h"
#include "core/slicing/layer_ranges.h"
#include "core/slicing/march_mesh.h"
#include "io/readers/stl_reader.h"
#include "parallel/parallel.h"
#include "tests/fixtures/models.h"
#include "tests/fixtures/shapes.h"

namespace toposlice {
namespace {

struct ZRange {
  double lo, hi;
};

ZRange facetZ(std::span<const Point3f> corners, std::size_t f) {
  const Point3f* c = &corners[3 * f];
  return {std::min({c[0].z, c[1].z, c[2].z}), std::max({c[0].z, c[1].z, c[2].z})};
}

std::vector<uint32_t> scanCrossing(std::span<const Point3f> corners, double z) {
  std::vector<uint32_t> out;
  for (std::size_t f = 0; f < corners.size() / 3; ++f) {
    const ZRange r = facetZ(corners, f);
    if (r.lo < z && z <= r.hi) out.push_back(static_cast<uint32_t>(f));
  }
  return out;
}

std::vector<uint32_t> scanSlab(std::span<const Point3f> corners, double zlo, double zhi) {
  std::vector<uint32_t> out;
  for (std::size_t f = 0; f < corners.size() / 3; ++f) {
    const ZRange r = facetZ(corners, f);
    if (r.lo <= zhi && r.hi >= zlo) out.push_back(static_cast<uint32_t>(f));
  }
  return out;
}

// Every distinct vertex height, the float just below and above each, midpoints and values outside.
std::vector<double> testPlanes(std::span<const Point3f> corners, std::size_t maxHeights, uint32_t seed) {
  std::vector<float> heights;
  for (const Point3f& p : corners) heights.push_back(p.z);
  std::sort(heights.begin(), heights.end());
  heights.erase(std::unique(heights.begin(), heights.end()), heights.end());
  std::vector<double> planes;
  const std::size_t stride = std::max<std::size_t>(1, heights.size() / maxHeights);
  for (std::size_t i = 0; i < heights.size(); i += stride) {
    const float h = heights[i];
    planes.push_back(h);
    planes.push_back(std::nextafter(h, -std::numeric_limits<float>::infinity()));
    planes.push_back(std::nextafter(h, std::numeric_limits<float>::infinity()));
    if (i + 1 < heights.size()) planes.push_back(0.5 * (double{h} + heights[i + 1]));
  }
  planes.push_back(double{heights.front()} - 1);
  planes.push_back(double{heights.back()} + 1);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uniform(heights.front(), heights.back());
  for (int i = 0; i < 100; ++i) planes.push_back(uniform(rng));
  return planes;
}

void expectCrossingMatchesScan(const FacetSoup& soup, std::size_t maxHeights) {
  const FacetBvh bvh(soup.corners, FacetBvh::kSlabQueries);
  std::vector<uint32_t> got;
  for (const double z : testPlanes(soup.corners, maxHeights, 7)) {
    bvh.facetsCrossingPlane(z, got);
    ASSERT_EQ(got, scanCrossing(soup.corners, z)) << "plane z = " << z;
  }
}

FacetSoup loadFemur() {
  return readStl(fixtures::modelPath("knee_femur_ssm_S001.stl"));
}

TEST(EmbreeQueries, EmptySoupAnswersNothing) {
  const FacetSoup empty;
  const FacetBvh bvh(empty.corners);
  std::vector<uint32_t> facets{1, 2, 3};
  bvh.facetsCrossingPlane(0, facets);
  EXPECT_TRUE(facets.empty());
  bvh.facetsInSlab(-1e30, 1e30, facets);
  EXPECT_TRUE(facets.empty());
  std::vector<RayCrossing> crossings(2);
  bvh.rayCrossings(0, 0, crossings);
  EXPECT_TRUE(crossings.empty());
  EXPECT_EQ(bvh.facetCount(), 0u);
}

TEST(EmbreeQueries, CrossingPlaneMatchesScanOnAnalyticShapes) {
  expectCrossingMatchesScan(fixtures::box(0, 0, 0, 1, 2, 3), 100);
  expectCrossingMatchesScan(fixtures::squareFrame(5, 3, -1, 2), 100);
  expectCrossingMatchesScan(fixtures::sphere(10, 48, 24, 1, 2, 3), 100);
  expectCrossingMatchesScan(fixtures::torus(8, 3, 64, 32, 5), 100);
  expectCrossingMatchesScan(fixtures::examplePart(), 300);
  // One facet, and a soup of one facet lying in a plane.
  FacetSoup one;
  one.corners = {{0, 0, 0}, {1, 0, 1}, {0, 1, 2}};
  expectCrossingMatchesScan(one, 10);
  one.corners = {{0, 0, 1}, {1, 0, 1}, {0, 1, 1}};
  expectCrossingMatchesScan(one, 10);
}

TEST(EmbreeQueries, CrossingPlaneMatchesScanOnFemur) {
  expectCrossingMatchesScan(loadFemur(), 600);
}

TEST(EmbreeQueries, SlabMatchesScan) {
  for (const FacetSoup& soup : {loadFemur(), fixtures::examplePart()}) {
    const FacetBvh bvh(soup.corners, FacetBvh::kSlabQueries);
    const std::vector<double> planes = testPlanes(soup.corners, 60, 11);
    std::mt19937 rng(5);
    std::uniform_int_distribution<std::size_t> pick(0, planes.size() - 1);
    std::vector<uint32_t> got, any;
    for (int i = 0; i < 400; ++i) {
      double lo = planes[pick(rng)], hi = planes[pick(rng)];
      if (i % 4 == 0) hi = lo;                       // zero thickness
      if (i % 4 == 1 && lo < hi) std::swap(lo, hi);  // inverted: empty
      bvh.facetsInSlab(lo, hi, got);
      ASSERT_EQ(got, scanSlab(soup.corners, lo, hi)) << "slab [" << lo << ", " << hi << "]";
      bvh.facetsInSlab(lo, hi, any, FacetOrder::Any);
      std::sort(any.begin(), any.end());
      ASSERT_EQ(any, got);
    }
    bvh.facetsInSlab(-1e30, 1e30, got);
    EXPECT_EQ(got.size(), soup.facetCount());
  }
}

TEST(EmbreeQueries, StartRecordsMatchActiveRecords) {
  FacetSoup soup = loadFemur();
  // A degenerate facet (two equal corners) spanning the model: no record, skipped by both.
  const Point3f a{0, 0, -200}, b{1, 0, 200};
  soup.corners.insert(soup.corners.end(), {a, a, b});
  double zmin = 1e30, zmax = -1e30;
  for (const Point3f& p : soup.corners) {
    if (p.z > 150 || p.z < -150) continue;
    zmin = std::min<double>(zmin, p.z);
    zmax = std::max<double>(zmax, p.z);
  }
  const double h = 0.05;
  std::vector<double> planes;
  for (uint32_t k = 0; zmin + k * h < zmax; ++k) planes.push_back(zmin + (k + 0.5) * h);
  const FacetLayers layers = computeFacetLayers(soup.corners, planes);
  MarchMesh mesh;
  prepareMarchMesh(layers, soup.facetCount(), mesh);
  const FacetBvh bvh(soup.corners, FacetBvh::kSlabQueries);
  ActiveRecords active;
  std::vector<uint32_t> records;
  for (uint32_t k = 0; k < planes.size(); k += 37) {
    active.start(mesh, k);
    std::vector<uint32_t> expected(active.records().begin(), active.records().end());
    std::sort(expected.begin(), expected.end());
    startRecordsFromBvh(bvh, mesh, planes[k], k, records);
    std::sort(records.begin(), records.end());
    ASSERT_EQ(records, expected) << "layer " << k;
  }
}

// ---- rays ----

TEST(EmbreeQueries, RayThroughBoxEdgesAndDiagonals) {
  // [0,2]^3: each face is two facets split along a diagonal; the line y = z = 1 runs along the diagonals
  // of the -x and +x faces, so it meets one facet of each, never both or neither.
  const FacetSoup cube = fixtures::box(0, 0, 0, 2, 2, 2);
  const FacetBvh bvh(cube.corners, FacetBvh::kRayQueries);
  std::vector<RayCrossing> hits;
  bvh.rayCrossings(1, 1, hits);
  ASSERT_EQ(hits.size(), 2u);
  EXPECT_EQ(hits[0].x, 0.0);
  EXPECT_EQ(hits[0].step, 1);
  EXPECT_EQ(hits[1].x, 2.0);
  EXPECT_EQ(hits[1].step, -1);
  // Boundaries follow the perturbation: the line sits just below its z and just above its y.
  bvh.rayCrossings(0.5, 2, hits);  // top face plane: just below it, inside
  EXPECT_EQ(hits.size(), 2u);
  bvh.rayCrossings(0.5, 0, hits);  // bottom face plane: just below it, outside
  EXPECT_EQ(hits.size(), 0u);
  bvh.rayCrossings(0, 0.5, hits);  // -y face plane: just above it, inside
  EXPECT_EQ(hits.size(), 2u);
  bvh.rayCrossings(2, 0.5, hits);  // +y face plane: just above it, outside
  EXPECT_EQ(hits.size(), 0u);
  bvh.rayCrossings(0, 2, hits);  // a box edge: inside in y, inside in z
  EXPECT_EQ(hits.size(), 2u);
  bvh.rayCrossings(5, 1, hits);
  EXPECT_EQ(hits.size(), 0u);
}

// Plain double-precision test for rays in general position (no tie can occur).
std::vector<uint32_t> bruteForceRay(std::span<const Point3f> corners, double y, double z) {
  std::vector<uint32_t> out;
  for (std::size_t f = 0; f < corners.size() / 3; ++f) {
    const Point3f* c = &corners[3 * f];
    double e[3];
    for (int i = 0; i < 3; ++i) {
      const Point3f& p = c[(i + 1) % 3];
      const Point3f& q = c[(i + 2) % 3];
      e[i] = (double{q.y} - p.y) * (z - p.z) - (double{q.z} - p.z) * (y - p.y);
    }
    if ((e[0] > 0 && e[1] > 0 && e[2] > 0) || (e[0] < 0 && e[1] < 0 && e[2] < 0))
      out.push_back(static_cast<uint32_t>(f));
  }
  return out;
}

// Along the line, the winding of a closed, outward, self-intersection-free mesh is 0 or 1 between
// crossings (steps at equal x summed first: a line through a vertex may enter and leave there) and ends
// at 0.
void expectWatertight(const std::vector<RayCrossing>& hits, double y, double z) {
  int winding = 0;
  for (std::size_t i = 0; i < hits.size(); ++i) {
    winding += hits[i].step;
    if (i + 1 < hits.size() && hits[i + 1].x == hits[i].x) continue;
    ASSERT_TRUE(winding == 0 || winding == 1) << "line y=" << y << " z=" << z << " at x=" << hits[i].x;
  }
  ASSERT_EQ(winding, 0) << "line y=" << y << " z=" << z;
}

TEST(EmbreeQueries, RayCrossingsMatchBruteForceAndAreWatertight) {
  for (const FacetSoup& soup : {loadFemur(), fixtures::sphere(10, 48, 24, 1, 2, 3)}) {
    const FacetBvh bvh(soup.corners, FacetBvh::kRayQueries);
    float ylo = 1e30f, yhi = -1e30f, zlo = 1e30f, zhi = -1e30f;
    for (const Point3f& p : soup.corners) {
      ylo = std::min(ylo, p.y), yhi = std::max(yhi, p.y), zlo = std::min(zlo, p.z), zhi = std::max(zhi, p.z);
    }
    std::mt19937 rng(3);
    std::uniform_real_distribution<double> ys(ylo - 1, yhi + 1), zs(zlo - 1, zhi + 1);
    std::vector<RayCrossing> hits;
    std::size_t crossed = 0;
    for (int i = 0; i < 300; ++i) {
      const double y = ys(rng), z = zs(rng);
      bvh.rayCrossings(y, z, hits);
      std::vector<uint32_t> facets;
      for (const RayCrossing& h : hits) facets.push_back(h.facet);
      std::sort(facets.begin(), facets.end());
      ASSERT_EQ(facets, bruteForceRay(soup.corners, y, z)) << "line y=" << y << " z=" << z;
      expectWatertight(hits, y, z);
      ASSERT_TRUE(std::is_sorted(hits.begin(), hits.end(), [](auto& a, auto& b) { return a.x < b.x; }));
      crossed += hits.empty() ? 0 : 1;
    }
    EXPECT_GT(crossed, 100u);
    // Lines exactly through vertices (fans of 4 to 24 facets meet there, the sphere's poles included).
    for (std::size_t v = 0; v < soup.corners.size(); v += 7) {
      const Point3f& p = soup.corners[v];
      bvh.rayCrossings(p.y, p.z, hits);
      expectWatertight(hits, p.y, p.z);
    }
  }
}

TEST(EmbreeQueries, ConcurrentQueriesAgreeWithSerial) {
  const FacetSoup soup = loadFemur();
  const FacetBvh bvh(soup.corners);
  const std::vector<double> planes = testPlanes(soup.corners, 200, 9);
  std::vector<std::vector<uint32_t>> serial(planes.size()), parallel(planes.size());
  std::vector<std::vector<RayCrossing>> serialRays(planes.size()), parallelRays(planes.size());
  for (std::size_t i = 0; i < planes.size(); ++i) {
    bvh.facetsCrossingPlane(planes[i], serial[i]);
    bvh.rayCrossings(0.37 * static_cast<double>(i % 50), planes[i], serialRays[i]);
  }
  parallelForChunks(planes.size(), 8, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      bvh.facetsCrossingPlane(planes[i], parallel[i]);
      bvh.rayCrossings(0.37 * static_cast<double>(i % 50), planes[i], parallelRays[i]);
    }
  });
  EXPECT_EQ(serial, parallel);
  EXPECT_EQ(serialRays, parallelRays);
}

}  // namespace
}  // namespace toposlice
