// An independent oracle for the whole mask path (weld, adjacency, marching, canonical loops, scanline
// rasterizer): every pixel of a binary mask is decided again by casting a line along +x through the
// pixel row's centre (y_j, z_k) against the mesh facets with Embree (FacetBvh::rayCrossings, which finds
// every crossing and decides each one exactly) and summing the winding steps of the crossings left of
// (or at) the pixel centre.
//
// Sign convention: a facet whose outward normal has a negative x component is where the line enters the
// solid (+1), a positive one where it leaves (-1); so the winding of an outward-oriented closed mesh is
// positive exactly inside, as the rasterizer's positive rule has it. Features add their winding times
// their sign (+1 add-on, -1 removal). A pixel is lit when the sum is > 0.
//
// Masks and oracle must agree on every pixel whose centre is more than 1e-6 mm from every contour edge of
// the layer (where the two differ only by rounding of the same crossing). Distances are computed only for
// the pixels where they disagree.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "core/mesh/mesh.h"
#include "core/mesh/mesh_info.h"
#include "core/raster/mask_image.h"
#include "core/raster/rasterize.h"
#include "core/slicing/contours.h"
#include "io/readers/stl_reader.h"
#include "parallel/embree_queries.h"
#include "tests/fixtures/exact_coverage.h"
#include "tests/fixtures/models.h"
#include "tests/fixtures/shapes.h"

namespace toposlice {
namespace {

constexpr double kEdgeTolerance = 1e-6;  // mm

// One contour source of a layer stack: a mesh, its ray BVH, its sliced layers and its sign.
struct Feature {
  const FacetSoup* soup;
  const FacetBvh* bvh;
  const std::vector<LayerContours>* layers;
  int sign;
};

double segmentDistance(Point2d p, Point2d a, Point2d b) {
  const double dx = b.x - a.x, dy = b.y - a.y;
  const double len2 = dx * dx + dy * dy;
  double t = len2 > 0 ? ((p.x - a.x) * dx + (p.y - a.y) * dy) / len2 : 0;
  t = std::clamp(t, 0.0, 1.0);
  const double ex = a.x + t * dx - p.x, ey = a.y + t * dy - p.y;
  return std::sqrt(ex * ex + ey * ey);
}

double distanceToContours(Point2d p, std::span<const ContourSet> sets) {
  double best = INFINITY;
  for (const ContourSet& set : sets) {
    const LayerContours& layer = *set.layer;
    for (std::size_t l = 0; l < layer.loopCount(); ++l) {
      const std::span<const Point2d> loop = layer.loopPoints(l);
      const std::size_t n = loop.size();
      const std::size_t segments = layer.loopClosed[l] ? n : (n > 0 ? n - 1 : 0);
      for (std::size_t i = 0; i < segments; ++i)
        best = std::min(best, segmentDistance(p, loop[i], loop[(i + 1) % n]));
    }
  }
  return best;
}

BoundingBox boundsOfAll(std::span<const Feature> features) {
  BoundingBox b = boundsOf(features[0].soup->corners);
  for (const Feature& f : features.subspan(1)) {
    const BoundingBox c = boundsOf(f.soup->corners);
    b.min = {std::min(b.min.x, c.min.x), std::min(b.min.y, c.min.y), std::min(b.min.z, c.min.z)};
    b.max = {std::max(b.max.x, c.max.x), std::max(b.max.y, c.max.y), std::max(b.max.z, c.max.z)};
  }
  return b;
}

// A grid of `pixel` covering the box with two pixels of margin, its origin on a multiple of the pixel.
PixelGrid gridAround(const BoundingBox& b, double pixel) {
  PixelGrid grid;
  grid.pixel = pixel;
  grid.x0 = (std::floor(b.min.x / pixel) - 2) * pixel;
  grid.y0 = (std::floor(b.min.y / pixel) - 2) * pixel;
  grid.width = static_cast<uint32_t>(std::ceil((b.max.x - grid.x0) / pixel)) + 2;
  grid.height = static_cast<uint32_t>(std::ceil((b.max.y - grid.y0) / pixel)) + 2;
  return grid;
}

std::vector<double> evenPlanes(double zmin, double zmax, uint32_t count) {
  std::vector<double> planes(count);
  const double h = (zmax - zmin) / count;
  for (uint32_t k = 0; k < count; ++k) planes[k] = zmin + (k + 0.5) * h;
  return planes;
}

struct OracleCount {
  std::size_t pixels = 0, lit = 0, disagree = 0, unexplained = 0;
  std::vector<std::string> firstUnexplained;  // up to 5 descriptions
};

// Pixel (i, j) of the layer as the oracle sees it: per feature its own winding, and the sum.
struct PixelWinding {
  std::vector<int> feature;
  int total = 0;
};

// Rasterizes `sets` and compares every pixel with the ray oracle of `features` at height z (the
// features' signs weight their windings). `inspect` is called for every pixel with its centre, the mask's
// value and the oracle's windings.
template <class Inspect>
void compareLayer(std::span<const ContourSet> sets, std::span<const Feature> features, double z,
                  const PixelGrid& grid, OracleCount& count, Inspect inspect) {
  MaskImage mask;
  RasterScratch scratch;
  rasterizeBinary(sets, grid, mask, scratch);
  ASSERT_EQ(mask.pixels.size(), std::size_t{grid.width} * grid.height);

  struct Step {
    double x;
    uint32_t feature;
    int step;
  };
  std::vector<Step> steps;
  std::vector<RayCrossing> hits;
  PixelWinding w;
  for (uint32_t j = 0; j < grid.height; ++j) {
    const double y = grid.y0 + (j + 0.5) * grid.pixel;  // the rasterizer's sample position
    steps.clear();
    for (uint32_t f = 0; f < features.size(); ++f) {
      features[f].bvh->rayCrossings(y, z, hits);
      for (const RayCrossing& h : hits) steps.push_back({h.x, f, h.step});
    }
    std::sort(steps.begin(), steps.end(), [](const Step& a, const Step& b) { return a.x < b.x; });
    w.feature.assign(features.size(), 0);
    w.total = 0;
    std::size_t next = 0;
    for (uint32_t i = 0; i < grid.width; ++i) {
      const double x = grid.x0 + (i + 0.5) * grid.pixel;
      for (; next < steps.size() && steps[next].x <= x; ++next) {
        w.feature[steps[next].feature] += steps[next].step;
        w.total += steps[next].step * features[steps[next].feature].sign;
      }
      const uint8_t value = mask.pixels[std::size_t{j} * grid.width + i];
      ASSERT_TRUE(value == 0 || value == 255);
      const bool maskLit = value == 255, oracleLit = w.total > 0;
      ++count.pixels;
      count.lit += maskLit ? 1 : 0;
      if (maskLit != oracleLit) {
        ++count.disagree;
        const double d = distanceToContours({x, y}, sets);
        if (d > kEdgeTolerance) {
          ++count.unexplained;
          if (count.firstUnexplained.size() < 5)
            count.firstUnexplained.push_back(
                "z=" + std::to_string(z) + " pixel (" + std::to_string(i) + ", " + std::to_string(j) +
                "): mask " + (maskLit ? "lit" : "dark") + ", ray winding " + std::to_string(w.total) +
                ", nearest contour edge " + std::to_string(d) + " mm");
        }
      }
      inspect(Point2d{x, y}, maskLit, w);
    }
  }
}

// Layer k of every feature, with its sign.
std::vector<ContourSet> layerSets(std::span<const Feature> features, uint32_t k) {
  std::vector<ContourSet> sets;
  for (const Feature& f : features) sets.push_back({&(*f.layers)[k], f.sign});
  return sets;
}

void expectNoUnexplained(const OracleCount& count) {
  EXPECT_EQ(count.unexplained, 0u);
  for (const std::string& s : count.firstUnexplained) ADD_FAILURE() << s;
}

struct OracleModel {
  const char* file;
  double pixel;  // about 1/200 of the model's larger horizontal extent
};

void checkModelAgainstOracle(const OracleModel& model) {
  SCOPED_TRACE(model.file);
  const FacetSoup soup = readStl(fixtures::modelPath(model.file));
  const BoundingBox b = boundsOf(soup.corners);
  const std::vector<double> planes = evenPlanes(b.min.z, b.max.z, 10);
  const std::vector<LayerContours> layers = fixtures::sliceToVector(soup, planes, SliceMethod::SelfReuse);
  const FacetBvh bvh(soup.corners, FacetBvh::kRayQueries);
  const Feature features[] = {{&soup, &bvh, &layers, 1}};
  const PixelGrid grid = gridAround(b, model.pixel);
  EXPECT_GE(std::max(grid.width, grid.height), 150u);
  EXPECT_LE(std::max(grid.width, grid.height), 260u);
  OracleCount count;
  for (uint32_t k = 0; k < planes.size(); ++k)
    compareLayer(layerSets(features, k), features, planes[k], grid, count,
                 [](Point2d, bool, const PixelWinding&) {});
  EXPECT_GT(count.lit, count.pixels / 50) << "the layers should hold material";
  expectNoUnexplained(count);
  std::printf("[ oracle   ] %s: %zu pixels, %zu lit, %zu disagreements within %g mm of an edge\n", model.file,
              count.pixels, count.lit, count.disagree, kEdgeTolerance);
}

// The oracle itself must see wrong masks: a mask of another layer, and a layer with one loop missing.
TEST(MaskOracle, DetectsWrongMasks) {
  const FacetSoup soup = readStl(fixtures::modelPath("knee_femur_ssm_S001.stl"));
  const BoundingBox b = boundsOf(soup.corners);
  const std::vector<double> planes = evenPlanes(b.min.z, b.max.z, 10);
  std::vector<LayerContours> layers = fixtures::sliceToVector(soup, planes, SliceMethod::SelfReuse);
  const FacetBvh bvh(soup.corners, FacetBvh::kRayQueries);
  const Feature features[] = {{&soup, &bvh, &layers, 1}};
  const PixelGrid grid = gridAround(b, 0.5);
  const auto nothing = [](Point2d, bool, const PixelWinding&) {};
  OracleCount shifted;
  compareLayer(layerSets(features, 4), features, planes[4] + 2.0, grid, shifted, nothing);
  EXPECT_GT(shifted.unexplained, 10u);
  // A layer with two or more loops (islands or holes); drop all but its first loop.
  uint32_t k = 0;
  while (k < layers.size() && layers[k].loopCount() < 2) ++k;
  ASSERT_LT(k, layers.size());
  LayerContours oneLoop;
  for (const Point2d& p : layers[k].loopPoints(0)) oneLoop.addPoint(p, 0);
  oneLoop.endLoop(true);
  const ContourSet partial[] = {{&oneLoop, 1}};
  OracleCount missing;
  compareLayer(partial, features, planes[k], grid, missing, nothing);
  EXPECT_GT(missing.unexplained, 10u);
  OracleCount intact;
  compareLayer(layerSets(features, k), features, planes[k], grid, intact, nothing);
  EXPECT_EQ(intact.unexplained, 0u);
}

// Axis-aligned solids whose faces, edges and vertices lie exactly on planes, pixel-centre rows and
// pixel-centre columns: the oracle's perturbation (a vertex at the plane's z counts above, at the row's
// y below; a crossing at the centre's x counts) is the slicer's and rasterizer's rule, so here the two
// must agree on every pixel, those on contour edges included.
TEST(MaskOracle, AgreesExactlyOnDegenerateAxisAlignedCase) {
  const FacetSoup frame = fixtures::squareFrame(5, 3, 0, 2);
  const FacetSoup addOn = fixtures::box(3, -1, 0.5f, 7, 1, 1.5f);   // its left face on the frame's hole wall
  const FacetSoup removal = fixtures::box(-7, -2, 0, -3.5f, 2, 2);  // cuts into the frame's left wall
  const std::vector<double> planes = {0, 0.25, 0.5, 1, 1.5, 1.75, 2};  // vertex heights included
  const std::vector<LayerContours> frameLayers =
      fixtures::sliceToVector(frame, planes, SliceMethod::SelfReuse);
  const std::vector<LayerContours> addOnLayers =
      fixtures::sliceToVector(addOn, planes, SliceMethod::SelfReuse);
  const std::vector<LayerContours> removalLayers =
      fixtures::sliceToVector(removal, planes, SliceMethod::SelfReuse);
  const FacetBvh frameBvh(frame.corners, FacetBvh::kRayQueries);
  const FacetBvh addOnBvh(addOn.corners, FacetBvh::kRayQueries);
  const FacetBvh removalBvh(removal.corners, FacetBvh::kRayQueries);
  const Feature features[] = {{&frame, &frameBvh, &frameLayers, 1},
                              {&addOn, &addOnBvh, &addOnLayers, 1},
                              {&removal, &removalBvh, &removalLayers, -1}};
  PixelGrid grid;  // pixel centres on every multiple of 0.5 from -8 to 8
  grid.pixel = 0.5;
  grid.x0 = grid.y0 = -8.25;
  grid.width = grid.height = 33;
  OracleCount count;
  for (uint32_t k = 0; k < planes.size(); ++k)
    compareLayer(layerSets(features, k), features, planes[k], grid, count,
                 [](Point2d, bool, const PixelWinding&) {});
  EXPECT_EQ(count.disagree, 0u);
  expectNoUnexplained(count);
  EXPECT_GT(count.lit, 300u);
}

TEST(MaskOracle, KneeFemurMatchesRayCasting) {
  checkModelAgainstOracle({"knee_femur_ssm_S001.stl", 0.5});
}
TEST(MaskOracle, FemurSubdividedMatchesRayCasting) {
  checkModelAgainstOracle({"derived/femur_S001_sub2.stl.gz", 0.5});
}
TEST(MaskOracle, HumanBodyMatchesRayCasting) {
  checkModelAgainstOracle({"human_body_smpl_male.stl", 0.01});
}
TEST(MaskOracle, GearwheelMatchesRayCasting) {
  checkModelAgainstOracle({"gearwheel_ascii.stl", 0.25});
}
TEST(MaskOracle, BunnyMatchesRayCasting) {
  checkModelAgainstOracle({"bunny_closed.stl", 0.008});
}

// Volume of the mask stack against the mesh volume. Bound: the mask is the voxelization that lights a
// voxel (pixel x layer) when its centre is inside; a point of a voxel is misjudged only if the
// axis-parallel path from it to the centre crosses the surface, and the points whose leg along axis a
// crosses the surface fill at most (half the voxel's extent along a) x (the surface's area projected
// along a). So |V_mask - V| <= (p/2)(A_x + A_y) + (h/2) A_z with A_a = sum over facets of |n_a| area
// (projected areas). The brief's perimeter bound, sum over layers of perimeter x p/2 x h, is printed
// beside it; in practice both are generous because the errors cancel.
void checkVolume(const char* file, double pixel, uint32_t layerCount) {
  SCOPED_TRACE(file);
  const FacetSoup soup = readStl(fixtures::modelPath(file));
  const BoundingBox b = boundsOf(soup.corners);
  const std::vector<double> planes = evenPlanes(b.min.z, b.max.z, layerCount);
  const double h = (double{b.max.z} - b.min.z) / layerCount;
  const std::vector<LayerContours> layers = fixtures::sliceToVector(soup, planes, SliceMethod::SelfReuse);
  const PixelGrid grid = gridAround(b, pixel);
  MaskImage mask;
  RasterScratch scratch;
  double maskVolume = 0, perimeterBound = 0;
  for (const LayerContours& layer : layers) {
    const ContourSet set{&layer, 1};
    rasterizeBinary(std::span(&set, 1), grid, mask, scratch);
    maskVolume += maskArea(mask, pixel) * h;
    for (std::size_t l = 0; l < layer.loopCount(); ++l) {
      const std::span<const Point2d> loop = layer.loopPoints(l);
      for (std::size_t i = 0; i < loop.size(); ++i) {
        const Point2d a = loop[i], c = loop[(i + 1) % loop.size()];
        perimeterBound += std::hypot(c.x - a.x, c.y - a.y) * pixel / 2 * h;
      }
    }
  }
  double ax = 0, ay = 0, az = 0;
  for (std::size_t f = 0; f < soup.facetCount(); ++f) {
    const Point3f* c = &soup.corners[3 * f];
    const double ux = double{c[1].x} - c[0].x, uy = double{c[1].y} - c[0].y, uz = double{c[1].z} - c[0].z;
    const double vx = double{c[2].x} - c[0].x, vy = double{c[2].y} - c[0].y, vz = double{c[2].z} - c[0].z;
    ax += std::abs(uy * vz - uz * vy) / 2;
    ay += std::abs(uz * vx - ux * vz) / 2;
    az += std::abs(ux * vy - uy * vx) / 2;
  }
  const double volume = signedVolume(soup.corners);
  const double bound = pixel / 2 * (ax + ay) + h / 2 * az;
  const double error = std::abs(maskVolume - volume);
  EXPECT_LE(error, bound) << "mask volume " << maskVolume << ", mesh volume " << volume;
  std::printf(
      "[ volume   ] %s: mesh %.6g, masks %.6g, |error| %.3g (%.3g%%), bound %.3g, perimeter bound %.3g\n",
      file, volume, maskVolume, error, 100 * error / volume, bound, perimeterBound);
}

TEST(MaskOracle, MaskVolumeMatchesMeshVolume) {
  checkVolume("knee_femur_ssm_S001.stl", 0.5, 200);
  checkVolume("gearwheel_ascii.stl", 0.25, 200);
  checkVolume("human_body_smpl_male.stl", 0.01, 200);
}

// Inter-model reuse at the mask stage: the femur plus a box add-on overlapping it, minus a box removal
// overlapping it elsewhere, each sliced on its own. Against the oracle's femur + add-on - removal winding;
// and directly: inside the add-on every pixel is lit (winding 2 where it overlaps the femur), inside the
// removal none is (femur 1 - removal 1 = 0, outside the femur -1).
TEST(MaskOracle, AddOnAndRemovalFeatures) {
  const FacetSoup femur = readStl(fixtures::modelPath("knee_femur_ssm_S001.stl"));
  const BoundingBox b = boundsOf(femur.corners);
  const float cx = 0.5f * (b.min.x + b.max.x), cy = 0.5f * (b.min.y + b.max.y), height = b.max.z - b.min.z;
  const float az0 = b.min.z + 0.30f * height, az1 = b.min.z + 0.60f * height;
  const float rz0 = b.min.z + 0.32f * height, rz1 = b.min.z + 0.58f * height;
  const float ax0 = cx, ax1 = b.max.x + 10, ay0 = cy - 8, ay1 = cy + 8;
  const float rx0 = b.min.x - 10, rx1 = cx - 2, ry0 = cy - 6, ry1 = cy + 6;
  const FacetSoup addOn = fixtures::box(ax0, ay0, az0, ax1, ay1, az1);
  const FacetSoup removal = fixtures::box(rx0, ry0, rz0, rx1, ry1, rz1);
  const std::vector<double> planes = evenPlanes(b.min.z + 0.34 * height, b.min.z + 0.56 * height, 10);
  const std::vector<LayerContours> femurLayers =
      fixtures::sliceToVector(femur, planes, SliceMethod::SelfReuse);
  const std::vector<LayerContours> addOnLayers =
      fixtures::sliceToVector(addOn, planes, SliceMethod::SelfReuse);
  const std::vector<LayerContours> removalLayers =
      fixtures::sliceToVector(removal, planes, SliceMethod::SelfReuse);
  const FacetBvh femurBvh(femur.corners, FacetBvh::kRayQueries);
  const FacetBvh addOnBvh(addOn.corners, FacetBvh::kRayQueries);
  const FacetBvh removalBvh(removal.corners, FacetBvh::kRayQueries);
  const Feature features[] = {{&femur, &femurBvh, &femurLayers, 1},
                              {&addOn, &addOnBvh, &addOnLayers, 1},
                              {&removal, &removalBvh, &removalLayers, -1}};
  const PixelGrid grid = gridAround(boundsOfAll(features), 0.5);
  const auto strictlyInside = [](Point2d p, float x0, float y0, float x1, float y1) {
    return p.x > x0 + kEdgeTolerance && p.x < x1 - kEdgeTolerance && p.y > y0 + kEdgeTolerance &&
           p.y < y1 - kEdgeTolerance;
  };
  OracleCount count;
  std::size_t inAddOn = 0, inAddOnAndFemur = 0, inRemoval = 0, inRemovalAndFemur = 0;
  for (uint32_t k = 0; k < planes.size(); ++k) {
    compareLayer(layerSets(features, k), features, planes[k], grid, count,
                 [&](Point2d p, bool lit, const PixelWinding& w) {
                   if (strictlyInside(p, ax0, ay0, ax1, ay1)) {
                     ++inAddOn;
                     EXPECT_TRUE(lit) << "add-on pixel at (" << p.x << ", " << p.y << ")";
                     EXPECT_EQ(w.feature[1], 1);
                     if (w.feature[0] > 0) {
                       ++inAddOnAndFemur;
                       EXPECT_EQ(w.total, 2);
                     }
                   }
                   if (strictlyInside(p, rx0, ry0, rx1, ry1)) {
                     ++inRemoval;
                     EXPECT_FALSE(lit) << "removal pixel at (" << p.x << ", " << p.y << ")";
                     EXPECT_EQ(w.feature[2], 1);
                     if (w.feature[0] > 0) {
                       ++inRemovalAndFemur;
                       EXPECT_EQ(w.total, 0);
                     }
                   }
                 });
    if (::testing::Test::HasFailure()) return;
  }
  expectNoUnexplained(count);
  EXPECT_GT(inAddOnAndFemur, 20u) << "the add-on should overlap the femur";
  EXPECT_GT(inAddOn, inAddOnAndFemur) << "the add-on should reach outside the femur";
  EXPECT_GT(inRemovalAndFemur, 20u) << "the removal should cut into the femur";
  EXPECT_GT(inRemoval, inRemovalAndFemur) << "the removal should reach outside the femur";
}

// Anti-aliased masks of real layers against exact polygon clipping (tests/fixtures/exact_coverage.h):
// every pixel within half a grey level (plus 1e-6) of 255 x the exact covered fraction of the
// positive-winding region. Femur + box add-on - box removal (winding 2 in the overlap, -1 outside the
// femur, box edges through femur pixels), and the bunny alone on a fine grid, both mirrored.
void checkCoverageAgainstClipping(std::span<const std::vector<LayerContours>> stacks,
                                  std::span<const int> signs, const PixelGrid& grid) {
  RasterScratch scratch;
  MaskImage mask;
  std::size_t partial = 0;
  for (std::size_t k = 0; k < stacks[0].size(); ++k) {
    std::vector<ContourSet> sets;
    for (std::size_t f = 0; f < stacks.size(); ++f) sets.push_back({&stacks[f][k], signs[f]});
    uint64_t sum = 0;
    rasterizeCoverage(sets, grid, mask, scratch, &sum);
    const std::vector<double> area = fixtures::exactCoverage(sets, grid);
    uint64_t expectedSum = 0;
    for (uint32_t j = 0; j < grid.height; ++j) {
      for (uint32_t i = 0; i < grid.width; ++i) {
        const uint32_t mi = grid.mirrorX ? grid.width - 1 - i : i,
                       mj = grid.mirrorY ? grid.height - 1 - j : j;
        const uint8_t v = mask.pixels[std::size_t{mj} * grid.width + mi];
        const double expected = 255.0 * area[std::size_t{j} * grid.width + i];
        ASSERT_LE(std::abs(v - expected), 0.5 + 1e-6) << "layer " << k << " pixel " << i << "," << j;
        partial += v != 0 && v != 255 ? 1 : 0;
        expectedSum += v;
      }
    }
    ASSERT_EQ(sum, expectedSum) << "layer " << k;
  }
  EXPECT_GT(partial, 100u) << "the layers should have edge pixels";
}

TEST(MaskOracle, AlignerRowsByClustersEqualTheBandedPath) {
  // The aligner at 1 um on the SL1 pixel (0.04725 mm): its outlines turn up and down inside pixel rows
  // (a local extreme every few vertices). 300 consecutive layers, every row by the clusters where they
  // apply against every row by the banded path: the same bytes.
  const FacetSoup aligner = readStl(fixtures::modelPath("derived/aligner_upper_case0.stl.gz"));
  const BoundingBox b = boundsOf(aligner.corners);
  const double z0 = b.min.z + 0.25 * (b.max.z - b.min.z);
  std::vector<double> planes(300);
  for (std::size_t k = 0; k < planes.size(); ++k) planes[k] = z0 + 0.001 * static_cast<double>(k);
  const std::vector<LayerContours> layers = fixtures::sliceToVector(aligner, planes, SliceMethod::SelfReuse);
  const PixelGrid grid = gridAround(b, 0.04725);
  RasterScratch clustered, banded;
  banded.alwaysBanded = true;
  MaskImage a, c;
  std::size_t rows = 0;
  for (std::size_t k = 0; k < layers.size(); ++k) {
    const ContourSet sets[] = {{&layers[k], 1}};
    uint64_t sumA = 0, sumC = 0;
    rasterizeCoverage(sets, grid, a, clustered, &sumA);
    rasterizeCoverage(sets, grid, c, banded, &sumC);
    ASSERT_EQ(a.pixels, c.pixels) << "layer " << k;
    ASSERT_EQ(sumA, sumC) << "layer " << k;
    rows = banded.bandedRows;
  }
  EXPECT_GT(clustered.clusteredRows, 9 * rows / 10);  // most rows by clusters,
  EXPECT_GT(clustered.extremeRows, rows / 20);        // many with local extremes inside the row
  EXPECT_GT(clustered.bandedRows, 0u);
}

TEST(MaskOracle, AntiAliasedMatchesExactClipping) {
  const FacetSoup femur = readStl(fixtures::modelPath("knee_femur_ssm_S001.stl"));
  const BoundingBox b = boundsOf(femur.corners);
  const float cx = 0.5f * (b.min.x + b.max.x), cy = 0.5f * (b.min.y + b.max.y), height = b.max.z - b.min.z;
  const FacetSoup addOn =
      fixtures::box(cx, cy - 8, b.min.z + 0.3f * height, b.max.x + 10, cy + 8, b.min.z + 0.6f * height);
  const FacetSoup removal =
      fixtures::box(b.min.x - 10, cy - 6, b.min.z + 0.32f * height, cx - 2, cy + 6, b.min.z + 0.58f * height);
  const std::vector<double> planes = evenPlanes(b.min.z + 0.34 * height, b.min.z + 0.56 * height, 4);
  const std::vector<LayerContours> stacks[] = {
      fixtures::sliceToVector(femur, planes, SliceMethod::SelfReuse),
      fixtures::sliceToVector(addOn, planes, SliceMethod::SelfReuse),
      fixtures::sliceToVector(removal, planes, SliceMethod::SelfReuse)};
  const int signs[] = {1, 1, -1};
  BoundingBox all = b;
  all.min.x -= 10;
  all.max.x += 10;
  PixelGrid grid = gridAround(all, 0.37);
  grid.mirrorX = true;
  checkCoverageAgainstClipping(stacks, signs, grid);

  const FacetSoup bunny = readStl(fixtures::modelPath("bunny_closed.stl"));
  const BoundingBox bb = boundsOf(bunny.corners);
  const std::vector<LayerContours> bunnyStack[] = {
      fixtures::sliceToVector(bunny, evenPlanes(bb.min.z, bb.max.z, 5), SliceMethod::SelfReuse)};
  const int plus[] = {1};
  PixelGrid fine = gridAround(bb, 0.0013);
  fine.mirrorY = true;
  checkCoverageAgainstClipping(bunnyStack, plus, fine);
}

}  // namespace
}  // namespace toposlice
