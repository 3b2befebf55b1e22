// The loop follower (core/slicing/slice_follow.h) against the marching kernel, layer after layer: thin layers
// (long runs carried over, a few changed facets each layer), planes through vertices (the on-plane rule at
// every event), coarse layers (nearly every facet changes) and loops that split and merge (torus,
// real scans). Every layer must be identical bit for bit.
#include <gtest/gtest.h>

#include <algorithm>

#include "core/mesh/adjacency.h"
#include "core/mesh/weld.h"
#include "core/slicing/layer_ranges.h"
#include "core/slicing/march_mesh.h"
#include "core/slicing/slice_follow.h"
#include "core/slicing/slice_march.h"
#include "io/readers/stl_reader.h"
#include "tests/fixtures/models.h"
#include "tests/fixtures/shapes.h"

namespace toposlice {
namespace {

struct Prepared {
  std::vector<int32_t> table;
  FacetLayers layers;
  MarchMesh march;
};

Prepared prepare(const FacetSoup& soup, std::span<const double> planes) {
  Prepared p;
  const IndexedMesh mesh = weldCorners(soup.corners);
  p.table.resize(soup.corners.size());
  buildAdjacency(mesh.facetVertices, mesh.vertices.size(), p.table);
  p.layers = computeFacetLayers(soup.corners, planes);
  prepareMarchMesh(p.layers, soup.facetCount(), p.march);
  p.march.missingNeighbours =
      fillMarchFacets(soup.corners, p.table, p.layers, planes, 0, p.march.facets.size(), p.march);
  return p;
}

// Follows layers [0, planes.size()) and compares each with the marching kernel. Returns how many layers
// were followed (not restarted).
std::size_t expectFollowMatchesMarch(const FacetSoup& soup, std::span<const double> planes) {
  Prepared p = prepare(soup, planes);
  EXPECT_EQ(p.march.missingNeighbours, 0u);
  LoopFollower follower;
  MarchScratch scratch;
  scratch.prepare(p.march.facets.size());
  ActiveRecords active;
  LayerContours followed, marched;
  std::size_t advanced = 0;
  for (uint32_t k = 0; k < planes.size(); ++k) {
    if (k == 0)
      active.start(p.march, 0);
    else
      active.advance(p.march);
    if (k > 0 && follower.advance(p.march, k, planes[k], followed)) {
      ++advanced;
    } else {
      EXPECT_TRUE(follower.start(p.march, active.records(), k, planes[k], followed)) << "layer " << k;
    }
    marchRecordsLayer(p.march.facets, active.records(), planes[k], k + 1, scratch, marched);
    if (!(followed == marched)) {
      ADD_FAILURE() << "layer " << k << " (z " << planes[k] << "): " << followed.loopCount() << " loops / "
                    << followed.points.size() << " points followed, " << marched.loopCount() << " / "
                    << marched.points.size() << " marched";
      return advanced;
    }
  }
  return advanced;
}

std::vector<double> evenPlanes(double zmin, double zmax, std::size_t count) {
  std::vector<double> planes(count);
  const double h = (zmax - zmin) / static_cast<double>(count);
  for (std::size_t k = 0; k < count; ++k) planes[k] = zmin + (static_cast<double>(k) + 0.5) * h;
  return planes;
}

// Every distinct vertex height as a plane: each layer has vertices exactly on it.
std::vector<double> vertexPlanes(const FacetSoup& soup) {
  std::vector<double> planes;
  for (const Point3f& c : soup.corners) planes.push_back(c.z);
  std::sort(planes.begin(), planes.end());
  planes.erase(std::unique(planes.begin(), planes.end()), planes.end());
  return planes;
}

TEST(SliceFollow, TorusThinAndCoarse) {
  // Two loops born together at the bottom circle and dying together at the top.
  const FacetSoup soup = fixtures::torus(10, 3, 96, 48);
  for (const std::size_t count : {7u, 100u, 3000u}) {
    SCOPED_TRACE(count);
    const std::size_t advanced = expectFollowMatchesMarch(soup, evenPlanes(-3, 3, count));
    EXPECT_EQ(advanced, count - 1);  // every layer after the first was followed, none restarted
  }
}

TEST(SliceFollow, PlanesThroughEveryVertex) {
  for (const FacetSoup& soup : {fixtures::torus(10, 3, 40, 20), fixtures::sphere(5, 32, 16),
                                fixtures::box(0, 0, 0, 1, 2, 3), fixtures::squareFrame(4, 2, 0, 1)}) {
    const std::vector<double> planes = vertexPlanes(soup);
    expectFollowMatchesMarch(soup, planes);
  }
}

TEST(SliceFollow, RealMeshesThinLayers) {
  // Loops split and merge here (ears, fingers, teeth, gear teeth).
  for (const char* name : {"bunny_closed.stl", "knee_femur_ssm_S001.stl", "gearwheel_ascii.stl",
                           "dental_teeth_upper_case0.stl", "hand_smpl_closed.stl"}) {
    SCOPED_TRACE(name);
    const FacetSoup soup = readStl(fixtures::modelPath(name));
    float zmin = soup.corners[0].z, zmax = zmin;
    for (const Point3f& c : soup.corners) {
      zmin = std::min(zmin, c.z);
      zmax = std::max(zmax, c.z);
    }
    const std::size_t advanced = expectFollowMatchesMarch(soup, evenPlanes(zmin, zmax, 2500));
    EXPECT_EQ(advanced, 2499u);
    expectFollowMatchesMarch(soup, evenPlanes(zmin, zmax, 40));
  }
}

TEST(SliceFollow, AlignerAtOneMicronMidHeight) {
  // 1,500 layers of 1 um through the middle of the aligner, where loops are many and long.
  const FacetSoup soup = readStl(fixtures::modelPath("derived/aligner_upper_case0.stl.gz"));
  std::vector<double> planes(1500);
  for (std::size_t k = 0; k < planes.size(); ++k) planes[k] = 1.0 + 0.001 * (static_cast<double>(k) + 0.5);
  EXPECT_EQ(expectFollowMatchesMarch(soup, planes), planes.size() - 1);
}

TEST(SliceFollow, InconsistentTableIsReportedNotSliced) {
  // A cube whose table sends one walk into a facet that does not cross the plane: start() must fail
  // (the band slicer then marches the layer) instead of producing a wrong loop.
  const FacetSoup soup = fixtures::box(0, 0, 0, 1, 1, 1);
  const std::vector<double> planes{0.5};
  Prepared p = prepare(soup, planes);
  ActiveRecords active;
  active.start(p.march, 0);
  ASSERT_FALSE(active.records().empty());
  LayerContours out;
  LoopFollower good;
  ASSERT_TRUE(good.start(p.march, active.records(), 0, 0.5, out));
  EXPECT_EQ(out.loopCount(), 1u);
  for (MarchFacet& f : p.march.facets)
    for (int32_t& n : f.next)
      n = static_cast<int32_t>(active.records()[0]);  // every exit leads back to one facet
  LoopFollower bad;
  EXPECT_FALSE(bad.start(p.march, active.records(), 0, 0.5, out));
  EXPECT_FALSE(bad.advance(p.march, 1, 0.6, out));  // nothing to follow after a failed layer
}

}  // namespace
}  // namespace toposlice
