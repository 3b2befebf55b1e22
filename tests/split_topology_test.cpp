// The split weld, adjacency and STL parse (core/chunk_runner.h) against their serial forms: the same
// vertices, numbering, table and counts, bit for bit, on real meshes (closed, with holes, non-manifold,
// with degenerate facets), and the same soup or error message from STL text and binary, under runners
// that take the chunks in any order and on several thread counts.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "core/mesh/adjacency.h"
#include "core/mesh/weld.h"
#include "io/errors.h"
#include "io/readers/mesh_reader.h"
#include "io/readers/stl_reader.h"
#include "parallel/parallel.h"
#include "tests/fixtures/models.h"
#include "tests/fixtures/runners.h"
#include "tests/fixtures/shapes.h"

namespace toposlice {
namespace {

using fixtures::shuffledRunner;

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
  expectSame(serial, topologyOf(soup, shuffledRunner(true, 2)), name + ", width 2, chunks last first");
  expectSame(serial, topologyOf(soup, shuffledRunner(false, 32)), name + ", width 32, odd chunks first");
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

// ---------------------------------------------------------------------------------------------------
// STL parsed in parallel pieces (stl_reader.h): the serial soup, or the serial error message.

std::string asciiStl(std::span<const Point3f> corners, const char* name, int firstFacetCase = 0) {
  std::string text = std::string("solid ") + name + "\n";
  char line[160];
  for (std::size_t c = 0; c < corners.size(); c += 3) {
    text += (c / 3) % 7 == 3 && firstFacetCase ? "  FACET normal 0 0 1\n" : "  facet normal 0 0 1\n";
    text += "    outer loop\n";
    for (int k = 0; k < 3; ++k) {
      const Point3f& p = corners[c + static_cast<std::size_t>(k)];
      std::snprintf(line, sizeof line, "      vertex %.9g %.9g %.9g\n", double{p.x}, double{p.y},
                    double{p.z});
      text += line;
    }
    text += "    endloop\n  endfacet\n";
  }
  return text + "endsolid " + name + "\n";
}

std::span<const std::byte> bytesOf(const std::string& text) {
  return {reinterpret_cast<const std::byte*>(text.data()), text.size()};
}

// The serial result: the soup's bits, or the error message.
std::string parseOutcome(const std::string& text, const ChunkRunner& runner, StlSource* source = nullptr) {
  try {
    const FacetSoup soup = parseStlUncompressed(bytesOf(text), "t.stl", source, runner);
    return std::string(reinterpret_cast<const char*>(soup.corners.data()),
                       soup.corners.size() * sizeof(Point3f));
  } catch (const InputError& e) {
    return std::string("error: ") + e.what();
  }
}

// The parse outcome under every runner; returns how many pieces the shuffled runner read.
std::size_t expectSameParse(const std::string& text, const std::string& what, bool expectError) {
  StlSource serialSource;
  const std::string serial = parseOutcome(text, serialChunkRunner(), &serialSource);
  EXPECT_EQ(serial.starts_with("error: "), expectError) << what << ": " << serial.substr(0, 200);
  EXPECT_EQ(serialSource.pieces, 1u);
  std::size_t pieces = 0;
  for (const bool reverse : {true, false}) {
    StlSource source;
    EXPECT_EQ(parseOutcome(text, shuffledRunner(reverse), &source), serial) << what;
    EXPECT_EQ(source.solidName, serialSource.solidName) << what;
    pieces = source.pieces;
  }
  ThreadLimit limit(3);
  EXPECT_EQ(parseOutcome(text, parallelChunkRunner()), serial) << what;
  return pieces;
}

TEST(SplitStl, AsciiAndBinaryPiecesGiveTheSerialSoupOrError) {
  const FacetSoup aligner =
      readMesh(fixtures::modelPath("derived/aligner_upper_case0.stl.gz"), MeshReadOptions{});
  const std::span<const Point3f> some = std::span<const Point3f>(aligner.corners).first(3 * 60000);
  const std::string text = asciiStl(some, "facet maker 2", 1);  // a name with the keyword, mixed case
  ASSERT_GT(text.size(), std::size_t{8} << 20);
  EXPECT_GT(expectSameParse(text, "one solid", false), 4u);  // read in pieces, not by the fallback
  expectSameParse(text + "solid second\n" + asciiStl(some.first(30), "x").substr(9), "two solids", false);
  EXPECT_GT(expectSameParse(text.substr(0, text.size() - 14), "no endsolid", false), 4u);
  expectSameParse(text + "trailing", "text after endsolid", true);
  std::string broken = text;
  broken.replace(broken.find("vertex", broken.size() / 2), 6, "vertx");
  expectSameParse(broken, "a misspelt keyword in the middle", true);
  std::string fourth = text;
  const std::size_t endloop = fourth.find("endloop", fourth.size() / 3);
  fourth.insert(endloop, "vertex 1 2 3\n      ");
  expectSameParse(fourth, "a facet with 4 vertices", true);
  std::string huge = text;
  huge.replace(huge.find("vertex", huge.size() / 4) + 7, 1, "1e99 ");
  expectSameParse(huge, "a coordinate out of range", true);
  std::string cut = text.substr(0, text.size() / 2);
  expectSameParse(cut, "ends inside a facet", true);

  // Binary: the whole aligner, and one NaN in the middle.
  std::string binary(80, '\0');
  const auto facets = static_cast<uint32_t>(aligner.facetCount());
  binary.append(reinterpret_cast<const char*>(&facets), 4);
  for (std::size_t f = 0; f < aligner.facetCount(); ++f) {
    char record[50] = {};
    std::memcpy(record + 12, &aligner.corners[3 * f], 36);
    binary.append(record, 50);
  }
  EXPECT_GT(expectSameParse(binary, "binary", false), 4u);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(binary.data() + 84 + 50 * 300000 + 16, &nan, 4);
  expectSameParse(binary, "binary with a NaN", true);
}

}  // namespace
}  // namespace toposlice
