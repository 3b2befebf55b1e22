// The split weld and adjacency (core/chunk_runner.h) against their serial forms: the same vertices,
// numbering, table and counts, bit for bit, on real meshes (closed, with holes, non-manifold, with
// degenerate facets) under runners that take the chunks in any order and on every thread count.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <string>
#include <vector>

#include "core/mesh/adjacency.h"
#include "core/mesh/weld.h"
#include "io/readers/mesh_reader.h"
#include "parallel/parallel.h"
#include "tests/fixtures/models.h"
#include "tests/fixtures/shapes.h"

namespace toposlice {
namespace {

// Runs the chunks one at a time, but in the order given: last first, or odd chunks before even ones.
// A kernel whose result depended on the chunk order would differ from its serial form here.
ChunkRunner shuffledRunner(bool reverse) {
  return ChunkRunner{[reverse](std::size_t count, std::size_t, const ChunkBody& body) {
                       std::vector<std::size_t> order(count);
                       for (std::size_t i = 0; i < count; ++i) order[i] = i;
                       if (reverse)
                         std::reverse(order.begin(), order.end());
                       else
                         std::stable_partition(order.begin(), order.end(),
                                               [](std::size_t i) { return i % 2 == 1; });
                       for (const std::size_t c : order) body(c, c + 1);
                     },
                     4};
}

struct Topology {
  IndexedMesh mesh;
  std::vector<int32_t> table;
  EdgeStats stats;
};

Topology topologyOf(const FacetSoup& soup, const ChunkRunner& runner) {
  Topology t;
  t.mesh = weldCorners(soup.corners, runner);
  t.table.assign(soup.corners.size(), 7);  // every entry must be written
  t.stats = buildAdjacency(t.mesh.facetVertices, t.mesh.vertices.size(), t.table, runner);
  return t;
}

void expectSame(const Topology& a, const Topology& b, const std::string& what) {
  ASSERT_EQ(a.mesh.vertices.size(), b.mesh.vertices.size()) << what;
  for (std::size_t v = 0; v < a.mesh.vertices.size(); ++v) {
    const Point3f &p = a.mesh.vertices[v], &q = b.mesh.vertices[v];
    ASSERT_TRUE(std::memcmp(&p, &q, sizeof p) == 0) << what << ": vertex " << v;
  }
  ASSERT_EQ(a.mesh.facetVertices, b.mesh.facetVertices) << what;
  ASSERT_EQ(a.table, b.table) << what;
  EXPECT_EQ(a.stats.edges, b.stats.edges) << what;
  EXPECT_EQ(a.stats.boundary, b.stats.boundary) << what;
  EXPECT_EQ(a.stats.nonManifold, b.stats.nonManifold) << what;
  EXPECT_EQ(a.stats.inconsistent, b.stats.inconsistent) << what;
  EXPECT_EQ(a.stats.degenerateFacets, b.stats.degenerateFacets) << what;
}

void checkModel(const FacetSoup& soup, const std::string& name) {
  const Topology serial = topologyOf(soup, serialChunkRunner());
  expectSame(serial, topologyOf(soup, shuffledRunner(true)), name + ", chunks last first");
  expectSame(serial, topologyOf(soup, shuffledRunner(false)), name + ", odd chunks first");
  for (const unsigned threads : {2u, 3u, 8u}) {
    ThreadLimit limit(threads);
    expectSame(serial, topologyOf(soup, parallelChunkRunner()),
               name + ", " + std::to_string(threads) + " threads");
  }
}

TEST(SplitTopology, SameAsSerialOnSharedModels) {
  for (const char* model :
       {"derived/aligner_upper_case0.stl.gz", "knee_femur_ssm_S001.stl", "defect_diplodocus_nonmanifold.stl",
        "defect_elephant_with_holes.stl", "bunny_stanford_original.stl"}) {
    SCOPED_TRACE(model);
    checkModel(readMesh(fixtures::modelPath(model), MeshReadOptions{}), model);
  }
}

// A soup built to hit every case at once, large enough to be split: many copies of a sphere (shared
// corners across copies' seams are distinct), a degenerate facet, a flipped facet and a fin.
TEST(SplitTopology, SameAsSerialOnEveryEdgeCase) {
  FacetSoup soup;
  for (int i = 0; i < 24; ++i) {
    const FacetSoup s = fixtures::sphere(1.0 + (i % 3), 96, 48);
    for (Point3f p : s.corners) {
      p.x += static_cast<float>(i / 3) * 0.5f;  // overlapping copies share some corners exactly
      soup.corners.push_back(p);
    }
  }
  const std::size_t n = soup.corners.size();
  soup.corners.push_back(soup.corners[0]);  // degenerate: a repeated corner
  soup.corners.push_back(soup.corners[0]);
  soup.corners.push_back(soup.corners[1]);
  for (int c : {0, 2, 1})
    soup.corners.push_back(soup.corners[static_cast<std::size_t>(c)]);  // a flipped copy
  soup.corners.push_back(soup.corners[n / 2]);                          // a fin on an edge of a middle facet
  soup.corners.push_back(soup.corners[n / 2 + 1]);
  soup.corners.push_back(Point3f{-0.0f, 9.0f, 9.0f});
  ASSERT_GT(soup.corners.size(), std::size_t{1} << 18);
  checkModel(soup, "spheres");
}

}  // namespace
}  // namespace toposlice
