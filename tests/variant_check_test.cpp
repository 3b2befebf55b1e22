// Variant check: instances of one shape model pass against each other's tables; other models, reordered
// facets and moved corners fail with a report naming the facet and edge.
#include "core/mesh/variant_check.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <utility>
#include <vector>

#include "core/mesh/adjacency.h"
#include "core/mesh/weld.h"
#include "io/jobs/template_file.h"
#include "io/readers/stl_reader.h"
#include "parallel/variant_screen.h"

namespace toposlice {
namespace {

namespace fs = std::filesystem;

// The shared meshes through the project's STL reader (io/readers/stl_reader.h).
FacetSoup loadBinaryStl(const fs::path& path) {
  return readStl(path);
}

FacetSoup load(const char* name) {
  return loadBinaryStl(fs::path(TOPOSLICE_MODELS_DIR) / name);
}

std::vector<int32_t> adjacencyOf(const FacetSoup& soup) {
  const IndexedMesh mesh = weldCorners(soup.corners);
  std::vector<int32_t> adjacency(mesh.facetVertices.size());
  buildAdjacency(mesh.facetVertices, mesh.vertices.size(), adjacency);
  return adjacency;
}

void expectSameConnectivity(const char* templateName, std::initializer_list<const char*> variants) {
  const std::vector<int32_t> table = adjacencyOf(load(templateName));
  for (const char* name : variants) {
    const FacetSoup variant = load(name);
    const auto mismatch = checkVariantConnectivity(variant.corners, table);
    EXPECT_FALSE(mismatch.has_value()) << name << " vs " << templateName << ": " << mismatch->reason;
  }
}

// First facet f (from `start`) whose neighbours across the edges at corner 0 (edges 1 and 2) both have
// higher indices, so that a mismatch there is reported from f's side.
std::size_t facetBelowItsNeighbours(std::span<const int32_t> table, std::size_t start) {
  for (std::size_t f = start; f < table.size() / 3; ++f) {
    if (table[3 * f + 1] > static_cast<int32_t>(f) && table[3 * f + 2] > static_cast<int32_t>(f)) return f;
  }
  return table.size();
}

TEST(VariantCheck, FemurInstancesShareTheTemplateConnectivity) {
  expectSameConnectivity("knee_femur_ssm_S001.stl", {"knee_femur_ssm_S001.stl", "knee_femur_ssm_S002.stl",
                                                     "knee_femur_ssm_S003.stl", "knee_femur_ssm_mean.stl"});
}

TEST(VariantCheck, TibiaInstancesShareTheTemplateConnectivity) {
  expectSameConnectivity("knee_tibia_ssm_S001.stl", {"knee_tibia_ssm_S002.stl"});
}

TEST(VariantCheck, SmplBodiesShareConnectivity) {
  expectSameConnectivity("human_body_smpl_male.stl", {"human_body_smpl_female.stl"});
  expectSameConnectivity("human_body_smpl_female.stl", {"human_body_smpl_male.stl"});
}

TEST(VariantCheck, OtherModelFailsOnFacetCount) {
  const std::vector<int32_t> tibiaTable = adjacencyOf(load("knee_tibia_ssm_S001.stl"));
  const FacetSoup femur = load("knee_femur_ssm_S001.stl");
  const auto mismatch = checkVariantConnectivity(femur.corners, tibiaTable);
  ASSERT_TRUE(mismatch.has_value());
  EXPECT_EQ(mismatch->facet, kNoIndex);
  EXPECT_EQ(mismatch->edge, kNoIndex);
  EXPECT_NE(mismatch->reason.find("14622 facets"), std::string::npos) << mismatch->reason;
  EXPECT_NE(mismatch->reason.find("11756"), std::string::npos) << mismatch->reason;

  std::vector<Point3f> ragged = femur.corners;
  ragged.resize(3 * 11756 + 1);
  EXPECT_TRUE(checkVariantConnectivity(ragged, tibiaTable).has_value());
}

TEST(VariantCheck, SwappedFacetsFailNamingAFacet) {
  const FacetSoup s001 = load("knee_femur_ssm_S001.stl");
  const std::vector<int32_t> table = adjacencyOf(s001);
  FacetSoup s002 = load("knee_femur_ssm_S002.stl");
  const std::size_t a = 1000, b = 9000;
  std::swap_ranges(s002.corners.begin() + 3 * a, s002.corners.begin() + 3 * a + 3,
                   s002.corners.begin() + 3 * b);
  const auto mismatch = checkVariantConnectivity(s002.corners, table);
  ASSERT_TRUE(mismatch.has_value());
  const bool namesSwapped =
      mismatch->facet == a || mismatch->facet == b || mismatch->neighbour == a || mismatch->neighbour == b;
  EXPECT_TRUE(namesSwapped) << mismatch->facet << " " << mismatch->neighbour << ": " << mismatch->reason;
  EXPECT_NE(mismatch->reason.find("facet " + std::to_string(mismatch->facet) + " edge"), std::string::npos)
      << mismatch->reason;
}

TEST(VariantCheck, RotatedCornersFail) {
  FacetSoup s003 = load("knee_femur_ssm_S003.stl");
  const std::vector<int32_t> table = adjacencyOf(load("knee_femur_ssm_S001.stl"));
  const std::size_t f = 4321;  // same triangle, corners rotated: edge j now names another neighbour
  std::rotate(s003.corners.begin() + 3 * f, s003.corners.begin() + 3 * f + 1,
              s003.corners.begin() + 3 * f + 3);
  const auto mismatch = checkVariantConnectivity(s003.corners, table);
  ASSERT_TRUE(mismatch.has_value());
  EXPECT_TRUE(mismatch->facet == f || mismatch->neighbour == f) << mismatch->reason;
}

TEST(VariantCheck, MovedCornerFailsNamingFacetAndEdge) {
  const std::vector<int32_t> table = adjacencyOf(load("knee_femur_ssm_S001.stl"));
  FacetSoup s002 = load("knee_femur_ssm_S002.stl");
  ASSERT_FALSE(checkVariantConnectivity(s002.corners, table).has_value());

  // Corner 0 of facet f lies on edges 1 (corner 2 -> 0) and 2 (corner 0 -> 1); both neighbours have
  // higher indices, so the first failing entry is f's edge 1.
  const std::size_t f = facetBelowItsNeighbours(table, 5000);
  ASSERT_LT(f, table.size());
  FacetSoup moved = s002;
  moved.corners[3 * f].x = std::nextafter(moved.corners[3 * f].x, 1e9f);  // one ulp is enough
  const auto mismatch = checkVariantConnectivity(moved.corners, table);
  ASSERT_TRUE(mismatch.has_value());
  EXPECT_EQ(mismatch->facet, f);
  EXPECT_EQ(mismatch->edge, 1u);
  EXPECT_EQ(mismatch->neighbour, static_cast<uint32_t>(table[3 * f + 1]));
  EXPECT_NE(mismatch->reason.find("facet " + std::to_string(f) + " edge 1"), std::string::npos)
      << mismatch->reason;

  // Seen from a lower-indexed neighbour, the same kind of defect names the facet as the neighbour.
  std::size_t g = table.size();
  for (std::size_t i = 100; i < table.size() / 3 && g == table.size(); ++i) {
    if (table[3 * i + 1] >= 0 && table[3 * i + 1] < static_cast<int32_t>(i) && table[3 * i + 2] >= 0 &&
        table[3 * i + 2] < static_cast<int32_t>(i)) {
      g = i;
    }
  }
  ASSERT_LT(g, table.size());
  moved = s002;
  moved.corners[3 * g].z += 0.25f;
  const auto fromBelow = checkVariantConnectivity(moved.corners, table);
  ASSERT_TRUE(fromBelow.has_value());
  EXPECT_EQ(fromBelow->neighbour, g) << fromBelow->reason;
  EXPECT_LT(fromBelow->facet, g);
}

TEST(VariantCheck, NegativeZeroEqualsPositiveZero) {
  // Two facets sharing the edge (0,0,0)-(1,0,0); the second writes it with negative zeros.
  const FacetSoup pair{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, -0.0f, -0.0f}, {-0.0f, 0, 0}, {0, -1, 0}}};
  const std::vector<int32_t> table = adjacencyOf(pair);
  ASSERT_EQ(table[2], 1);
  EXPECT_FALSE(checkVariantConnectivity(pair.corners, table).has_value());
  FacetSoup flipped = pair;
  flipped.corners[0].x = -0.0f;
  flipped.corners[3].y = 0.0f;
  EXPECT_FALSE(checkVariantConnectivity(flipped.corners, table).has_value());
}

// An open entry (-1) claims that no single facet lies across the edge: a variant with exactly two facets
// on it, in opposite directions, contradicts it (a table of another model with more open edges, or all
// -1, passed before). Boundary, non-manifold and inconsistent edges of defective meshes stay open and pass.
TEST(VariantCheck, OpenEntriesTheVariantContradictsFail) {
  const FacetSoup pair{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, -0.0f, 0}, {0, 0, 0}, {0, -1, 0}}};
  const std::vector<int32_t> open(6, -1);
  for (const auto& m :
       {checkVariantConnectivity(pair.corners, open), checkVariantConnectivityParallel(pair.corners, open)}) {
    ASSERT_TRUE(m.has_value());
    EXPECT_EQ(m->facet, 0u);
    EXPECT_EQ(m->edge, 2u);
    EXPECT_NE(m->reason.find("is open in the template's table (-1), but the variant has one facet across it"),
              std::string::npos)
        << m->reason;
  }
  // The same edge used in one direction twice (inconsistent), or by three facets (non-manifold): open.
  const FacetSoup same{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 0}, {1, 0, 0}, {0, -1, 0}}};
  EXPECT_EQ(adjacencyOf(same), open);
  EXPECT_FALSE(checkVariantConnectivity(same.corners, open).has_value());
  const FacetSoup three{
      {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 0, 0}, {0, 0, 0}, {0, -1, 0}, {1, 0, 0}, {0, 0, 0}, {0, 0, 1}}};
  EXPECT_EQ(adjacencyOf(three), std::vector<int32_t>(9, -1));
  EXPECT_FALSE(checkVariantConnectivity(three.corners, std::vector<int32_t>(9, -1)).has_value());
  for (const char* name :
       {"defect_pig_cracks.stl", "defect_diplodocus_nonmanifold.stl", "defect_elephant_with_holes.stl"}) {
    const FacetSoup soup = load(name);
    const std::vector<int32_t> table = adjacencyOf(soup);
    ASSERT_NE(std::count(table.begin(), table.end(), -1), 0) << name;
    const auto m = checkVariantConnectivityParallel(soup.corners, table);
    EXPECT_FALSE(m.has_value()) << name << ": " << m->reason;
  }
}

TEST(VariantCheck, InvalidTablesAreReportedNotRead) {
  const FacetSoup pair{{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 0, 0}, {0, 0, 0}, {0, -1, 0}}};
  std::vector<int32_t> table = adjacencyOf(pair);
  ASSERT_EQ(table, (std::vector<int32_t>{-1, -1, 1, -1, -1, 0}));
  const auto check = [&](std::vector<int32_t> t, const char* what) {
    const auto m = checkVariantConnectivity(pair.corners, t);
    ASSERT_TRUE(m.has_value()) << what;
    EXPECT_NE(m->reason.find(what), std::string::npos) << m->reason;
  };
  check({-1, -1, 2, -1, -1, 0}, "outside");
  check({-1, -1, -7, -1, -1, 0}, "outside");
  check({-1, -1, 0, -1, -1, 0}, "its own facet");
  check({-1, -1, 1, -1, -1, -1}, "not symmetric");
  check({-1, -1, 1, 0, -1, -1}, "reverse");  // the back entry names the wrong edge of facet 1
}

TEST(VariantCheck, AlignerStageAgainstSavedTemplate) {
  const FacetSoup stage0 = load("derived/aligner_upper_case0.stl.gz");
  const FacetSoup stage2 = load("derived/aligner_upper_case0_stage2.stl.gz");
  ASSERT_EQ(stage0.facetCount(), 544774u);
  const TemplateTable built = buildTemplateTable(weldCorners(stage0.corners));
  const fs::path file = fs::temp_directory_path() /
                        ("toposlice_variant_aligner_" +
                         std::to_string(::testing::UnitTest::GetInstance()->random_seed()) + ".topo");
  writeTemplateFile(file, built, true);
  const TemplateTable table = readTemplateFile(file);
  fs::remove(file);
  ASSERT_EQ(table, built);

  const auto start = std::chrono::steady_clock::now();
  const auto mismatch = checkVariantConnectivity(stage2.corners, table.adjacency);
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  EXPECT_FALSE(mismatch.has_value()) << mismatch->reason;
  RecordProperty("check_ms", std::to_string(ms));
  EXPECT_FALSE(checkVariantConnectivity(stage0.corners, table.adjacency).has_value());

  FacetSoup moved = stage2;
  moved.corners[3 * 300000 + 2].y += 0.01f;
  const auto bad = checkVariantConnectivity(moved.corners, table.adjacency);
  ASSERT_TRUE(bad.has_value());
  EXPECT_TRUE(bad->facet == 300000 || bad->neighbour == 300000) << bad->reason;
}

TEST(VariantCheck, ParallelScreeningGivesTheSameAnswer) {
  // The aligner (545k facets) spans many screening chunks; defects far into the mesh and near its end.
  const std::vector<int32_t> table = adjacencyOf(load("derived/aligner_upper_case0.stl.gz"));
  const FacetSoup stage2 = load("derived/aligner_upper_case0_stage2.stl.gz");
  auto same = [&](const FacetSoup& variant, std::span<const int32_t> t) {
    const auto serial = checkVariantConnectivity(variant.corners, t);
    const auto parallel = checkVariantConnectivityParallel(variant.corners, t);
    ASSERT_EQ(serial.has_value(), parallel.has_value());
    if (!serial) return;
    EXPECT_EQ(serial->facet, parallel->facet);
    EXPECT_EQ(serial->edge, parallel->edge);
    EXPECT_EQ(serial->neighbour, parallel->neighbour);
    EXPECT_EQ(serial->reason, parallel->reason);
  };
  same(stage2, table);
  EXPECT_FALSE(checkVariantConnectivityParallel(stage2.corners, table).has_value());
  for (const std::size_t f : {std::size_t{400000}, stage2.facetCount() - 2}) {
    FacetSoup moved = stage2;
    moved.corners[3 * f + 1].y += 0.01f;
    same(moved, table);
    EXPECT_TRUE(checkVariantConnectivityParallel(moved.corners, table).has_value()) << f;
  }
  same(load("knee_femur_ssm_S001.stl"), table);  // another facet count
}

}  // namespace
}  // namespace toposlice
