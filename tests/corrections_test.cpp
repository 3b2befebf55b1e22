// Corrections (offset/polygon_offset.h, core/print/corrections.h) against analytic areas, and through the
// program: every correction alone and combined on a box with thin pins and on a cylinder.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <numbers>
#include <polyclipping/clipper.hpp>
#include <random>
#include <sstream>

#include "core/mesh/mesh_info.h"
#include "core/print/corrections.h"
#include "core/raster/rasterize.h"
#include "core/slicing/planes.h"
#include "io/masks/exr_writer.h"
#include "io/readers/stl_reader.h"
#include "io/readers/stl_writer.h"
#include "offset/polygon_offset.h"
#include "tests/fixtures/models.h"
#include "tests/fixtures/shapes.h"
#include "tests/tinyexr_read.h"
#include "tests/tool_runner.h"

namespace toposlice {
namespace {

using tool_test::CliToolBase;
using tool_test::examplePart;
using tool_test::readBytes;
using tool_test::RunResult;
namespace fs = std::filesystem;

void addLoop(LayerContours& layer, std::vector<Point2d> points) {
  for (const Point2d& p : points) layer.addPoint(p, 0);
  layer.endLoop(true);
}

void addRect(LayerContours& layer, double x0, double y0, double x1, double y1) {
  addLoop(layer, {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}});
}

// Regular n-gon of circumradius r about (cx, cy), counter-clockwise.
void addPolygon(LayerContours& layer, double cx, double cy, double r, int n) {
  std::vector<Point2d> points;
  for (int i = 0; i < n; ++i) {
    const double a = 2 * std::numbers::pi * i / n;
    points.push_back({cx + r * std::cos(a), cy + r * std::sin(a)});
  }
  addLoop(layer, points);
}

double correctedArea(const LayerContours& layer, const LayerCorrection& c, int sign = 1) {
  const ContourSet set{&layer, sign};
  LayerContours out;
  correctLayer({&set, 1}, c, 0.0, out);
  return layerSignedArea(out);
}

TEST(PolygonOffset, BoxGrowsAndShrinksByTheDistance) {
  LayerContours box;
  addRect(box, 0, 0, 10, 6);
  EXPECT_NEAR(correctedArea(box, {0.05, 0, 0}), 10.1 * 6.1, 1e-5);
  EXPECT_NEAR(correctedArea(box, {-0.05, 0, 0}), 9.9 * 5.9, 1e-5);
  EXPECT_NEAR(correctedArea(box, {0, 0, 0}), 60.0, 1e-6);
}

TEST(PolygonOffset, PolygonalCylinderKeepsItsShape) {
  // A regular n-gon offset by d with mitred corners is the n-gon with apothem a + d: area n (a+d)^2
  // tan(pi/n).
  const int n = 360;
  const double r = 3, apothem = r * std::cos(std::numbers::pi / n);
  LayerContours disc;
  addPolygon(disc, 1, 2, r, n);
  for (const double d : {0.05, -0.05, 0.2}) {
    const double expected = n * (apothem + d) * (apothem + d) * std::tan(std::numbers::pi / n);
    // Outline cleaning before the offset moves the outline by at most 0.5 um (polygon_offset.h): here
    // it drops every other vertex of the 360-gon (its sagitta over two edges is 0.46 um).
    EXPECT_NEAR(correctedArea(disc, {d, 0, 0}), expected, 2 * std::numbers::pi * (r + d) * 0.0005) << d;
  }
}

// A finely drawn circle (a scanned or CAD part's smooth wall): the cleaning dropped each vertex against
// its neighbours as they were then, so that drop after drop the outline cut up to 30 um inside a 4,000-sided
// circle of 5 mm (80 um with 20,000 sides), by different amounts in identical layers. Every corrected
// point stays within the cleaning's 0.5 um of the exact offset polygon, whose vertices lie between its
// apothem and its circumradius from the centre.
TEST(PolygonOffset, FinelyDrawnCirclesKeepTheirShape) {
  for (const int n : {4000, 20000}) {
    const double r = 5, apothem = r * std::cos(std::numbers::pi / n);
    LayerContours disc;
    addPolygon(disc, 10, 20, r, n);
    for (const double d : {-0.07, 0.07}) {
      const ContourSet set{&disc, 1};
      LayerContours out;
      correctLayer({&set, 1}, {d, 0, 0}, 0.0, out);
      ASSERT_EQ(out.loopCount(), 1u) << n << " " << d;
      double nearest = INFINITY, farthest = 0;
      for (const Point2d& p : out.points) {
        const double distance = std::hypot(p.x - 10, p.y - 20);
        nearest = std::min(nearest, distance);
        farthest = std::max(farthest, distance);
      }
      const double circumradius = (apothem + d) / std::cos(std::numbers::pi / n);
      EXPECT_GT(nearest, apothem + d - 0.0006) << n << " sides, offset " << d;
      EXPECT_LT(farthest, circumradius + 0.0006) << n << " sides, offset " << d;
      const double exact = n * (apothem + d) * (apothem + d) * std::tan(std::numbers::pi / n);
      EXPECT_NEAR(layerSignedArea(out), exact, 2 * std::numbers::pi * (r + d) * 0.0005) << n << " " << d;
    }
  }
}

TEST(PolygonOffset, OverlappingAndRemovedLoopsFollowThePositiveRule) {
  // The same square twice (count 2) shrinks as one square.
  LayerContours twice;
  addRect(twice, 0, 0, 4, 4);
  addRect(twice, 0, 0, 4, 4);
  EXPECT_NEAR(correctedArea(twice, {-0.1, 0, 0}), 3.8 * 3.8, 1e-5);
  // Two overlapping squares shrink as their union (an L-shaped outline grows no inner edge).
  LayerContours overlap;
  addRect(overlap, 0, 0, 4, 4);
  addRect(overlap, 2, 0, 6, 4);
  EXPECT_NEAR(correctedArea(overlap, {-0.1, 0, 0}), 5.8 * 3.8, 1e-5);
  // A removal set (sign -1) punches a hole, which grows when the solid shrinks.
  LayerContours model, removal;
  addRect(model, 0, 0, 10, 10);
  addRect(removal, 4, 4, 6, 6);
  const ContourSet sets[] = {{&model, 1}, {&removal, -1}};
  LayerContours out;
  correctLayer(sets, {-0.1, 0, 0}, 0.0, out);
  EXPECT_NEAR(layerSignedArea(out), 9.8 * 9.8 - 2.2 * 2.2, 1e-5);
  EXPECT_EQ(out.loopCount(), 2u);
}

TEST(PolygonOffset, SelfIntersectingAndVanishingLoops) {
  // A bow tie: its clockwise half has winding -1 and is not solid; the solid triangle grows alone.
  LayerContours bow;
  addLoop(bow, {{0, 0}, {2, 2}, {2, 0}, {0, 2}});  // left triangle CW, right triangle CCW
  const double triangle = correctedArea(bow, {0, 0, 0});
  EXPECT_NEAR(triangle, 1.0, 1e-6);
  // A wall thinner than twice the deflation vanishes; a wider one stays.
  LayerContours wall;
  addRect(wall, 0, 0, 0.08, 5);
  EXPECT_EQ(correctedArea(wall, {-0.05, 0, 0}), 0.0);
  addRect(wall, 1, 0, 1.3, 5);
  EXPECT_NEAR(correctedArea(wall, {-0.05, 0, 0}), 0.2 * 4.9, 1e-5);
  // Two squares that touch at an edge grow as one rectangle.
  LayerContours touching;
  addRect(touching, 0, 0, 1, 1);
  addRect(touching, 1, 0, 2, 1);
  EXPECT_NEAR(correctedArea(touching, {0.1, 0, 0}), 2.2 * 1.2, 1e-5);
}

// Shapes that reach every join of the raw offset: straight runs (nearly collinear points), mitred and
// squared-off convex corners, concave corners, an inside-out loop (the orientation fix), loops that
// overlap, touch or cross themselves.
std::vector<LayerContours> rawOffsetShapes() {
  std::vector<LayerContours> shapes(10);
  addRect(shapes[0], 0, 0, 10, 6);
  addPolygon(shapes[1], 1, 2, 3, 360);
  std::vector<Point2d> star;  // sharp tips (squared off) and concave notches
  for (int i = 0; i < 10; ++i) {
    const double a = 2 * std::numbers::pi * i / 10, r = i % 2 ? 0.6 : 3.0;
    star.push_back({r * std::cos(a), r * std::sin(a)});
  }
  addLoop(shapes[2], star);
  addLoop(shapes[3], {{0, 0}, {0, 4}, {4, 4}, {4, 0}});  // clockwise: inside out
  addRect(shapes[4], 0, 0, 4, 4);
  addRect(shapes[4], 2, 1, 6, 5);
  addRect(shapes[5], 0, 0, 1, 1);
  addRect(shapes[5], 1, 0, 2, 1);
  addLoop(shapes[6], {{0, 0}, {2, 2}, {2, 0}, {0, 2}});  // a bow tie
  std::vector<Point2d> wavy;  // a dense, jagged outline: points a fraction of a micrometre off a line
  for (int i = 0; i <= 400; ++i) wavy.push_back({0.01 * i, 0.0000003 * (i % 3)});
  wavy.push_back({4, 1});
  wavy.push_back({0, 1.3});
  addLoop(shapes[7], wavy);
  addRect(shapes[8], 0, 0, 8, 8);  // a frame: an outer loop and a clockwise hole
  addLoop(shapes[8], {{2, 2}, {2, 6}, {6, 6}, {6, 2}});
  addLoop(shapes[9], {{0, 0}, {4, 0}, {0, 4}});  // 45 degree corners: mitred within limit 3, not 2
  // A comb: notches 0.04 wide and deep between teeth, so that at the larger distances the concave
  // corners' trims no longer fit their short edges and their detours stay.
  std::vector<Point2d> comb{{0, 0}, {3, 0}, {3, 1}};
  for (int i = 0; i < 20; ++i) {
    const double x = 3 - 0.08 * i;
    comb.insert(comb.end(), {{x - 0.04, 1}, {x - 0.04, 0.96}, {x - 0.08, 0.96}, {x - 0.08, 1}});
  }
  comb.push_back({0, 1});
  addLoop(shapes.emplace_back(), comb);
  return shapes;
}

// The reference for growing: ClipperOffset itself (Clipper 6, Debian's libpolyclipping), on the outline
// cleaned as correctLayer cleans it, with mitred joins and a miter limit of 3.
ClipperLib::Paths toPaths(const LayerContours& layer) {
  ClipperLib::Paths paths;
  for (std::size_t l = 0; l < layer.loopCount(); ++l) {
    ClipperLib::Path& path = paths.emplace_back();
    for (const Point2d& p : layer.loopPoints(l))
      path.push_back(
          ClipperLib::IntPoint(std::llround(p.x * kOffsetUnitsPerMm), std::llround(p.y * kOffsetUnitsPerMm)));
  }
  return paths;
}

LayerContours toLayer(const ClipperLib::Paths& paths) {
  LayerContours layer;
  for (const ClipperLib::Path& path : paths) {
    for (const ClipperLib::IntPoint& p : path)
      layer.addPoint(
          {static_cast<double>(p.X) / kOffsetUnitsPerMm, static_cast<double>(p.Y) / kOffsetUnitsPerMm}, 0);
    layer.endLoop(true);
  }
  return layer;
}

// The outline cleaning polygon_offset.h promises, written here on its own: ClipperLib::CleanPolygon's
// walk (Clipper 6.4.2: a point close to the one before goes; a spike, the point and the next, goes when
// the points around it are close; a point near the line of its neighbours goes), where a point near
// the line goes only when every point dropped between its neighbours (it too) is near their line, so
// that the outline moves by at most the distance, and at most 256 such points go between two kept ones.
ClipperLib::Path referenceClean(const ClipperLib::Path& in, double distance) {
  struct Node {
    std::size_t index, prev, next;
    bool done;
  };
  const std::size_t n = in.size();
  if (n == 0) return {};
  std::vector<Node> nodes(n);
  for (std::size_t i = 0; i < n; ++i) nodes[i] = {i, (i + n - 1) % n, (i + 1) % n, false};
  const double d2 = distance * distance;
  const auto closeTo = [&](std::size_t a, std::size_t b) {
    const double dx = double(in[a].X) - double(in[b].X), dy = double(in[a].Y) - double(in[b].Y);
    return dx * dx + dy * dy <= d2;
  };
  const auto lineDistance2 = [&](std::size_t p, std::size_t a, std::size_t b) {  // from the line a b
    const double ux = double(in[b].X) - double(in[a].X), uy = double(in[b].Y) - double(in[a].Y);
    const double cross = ux * (double(in[p].Y) - double(in[a].Y)) - uy * (double(in[p].X) - double(in[a].X));
    return cross * cross / (ux * ux + uy * uy);
  };
  const auto between = [&](std::size_t a, std::size_t b, std::size_t c) {  // b between a and c
    const bool alongX = std::abs(in[a].X - in[b].X) > std::abs(in[a].Y - in[b].Y);
    return alongX ? (in[b].X > in[a].X) == (in[b].X < in[c].X) : (in[b].Y > in[a].Y) == (in[b].Y < in[c].Y);
  };
  const auto nearlyCollinear = [&](std::size_t a, std::size_t b, std::size_t c) {
    const bool alongX = std::abs(in[a].X - in[b].X) > std::abs(in[a].Y - in[b].Y);
    const bool aMiddle =
        alongX ? (in[a].X > in[b].X) == (in[a].X < in[c].X) : (in[a].Y > in[b].Y) == (in[a].Y < in[c].Y);
    if (aMiddle) return lineDistance2(a, b, c) < d2;
    if (between(a, b, c)) return lineDistance2(b, a, c) < d2;
    return lineDistance2(c, a, b) < d2;
  };
  const auto droppedNear = [&](std::size_t from, std::size_t to) {
    std::size_t count = 0;
    for (std::size_t i = (from + 1) % n; i != to; i = (i + 1) % n)
      if (++count > 256 || !(lineDistance2(i, from, to) < d2)) return false;
    return true;
  };
  const auto exclude = [&](std::size_t op) {
    const std::size_t result = nodes[op].prev;
    nodes[result].next = nodes[op].next;
    nodes[nodes[op].next].prev = result;
    nodes[result].done = false;
    return result;
  };
  std::size_t size = n, op = 0;
  while (!nodes[op].done && nodes[op].next != nodes[op].prev) {
    const std::size_t before = nodes[op].prev, after = nodes[op].next;
    if (closeTo(op, before)) {
      op = exclude(op);
      --size;
    } else if (closeTo(before, after)) {
      exclude(after);
      op = exclude(op);
      size -= 2;
    } else if (nearlyCollinear(before, op, after) && droppedNear(before, after)) {
      op = exclude(op);
      --size;
    } else {
      nodes[op].done = true;
      op = after;
    }
  }
  ClipperLib::Path out;
  if (size < 3) return out;
  for (std::size_t i = 0; i < size; ++i, op = nodes[op].next) out.push_back(in[op]);
  return out;
}

LayerContours clipperGrown(const LayerContours& layer, double d) {
  ClipperLib::Paths cleaned, out;
  for (const ClipperLib::Path& path : toPaths(layer))
    if (ClipperLib::Path kept = referenceClean(path, 0.0005 * kOffsetUnitsPerMm); !kept.empty())
      cleaned.push_back(std::move(kept));
  ClipperLib::ClipperOffset offsetter(3.0);
  offsetter.AddPaths(cleaned, ClipperLib::jtMiter, ClipperLib::etClosedPolygon);
  offsetter.Execute(out, static_cast<double>(std::llround(d * kOffsetUnitsPerMm)));
  return toLayer(out);
}

// The reference for shrinking: ClipperOffset's shrink of the region (Clipper's union first, as
// correctLayer unites it), cleaned alike.
LayerContours clipperShrunk(const LayerContours& layer, double d) {
  ClipperLib::Paths united;
  ClipperLib::Clipper clipper;
  clipper.AddPaths(toPaths(layer), ClipperLib::ptSubject, true);
  clipper.Execute(ClipperLib::ctUnion, united, ClipperLib::pftPositive, ClipperLib::pftPositive);
  return clipperGrown(toLayer(united), -d);
}

// ClipperOffset's region for an absolute correction d of either sign.
LayerContours clipperOffset(const LayerContours& layer, double d) {
  return d > 0 ? clipperGrown(layer, d) : clipperShrunk(layer, -d);
}

// The area, in mm^2, of the points in one of the two regions and not in the other: the signed sum over
// the XOR's polygons (outer loops positive, holes negative; where the two regions hold the same small
// island, Clipper may return it as a loop and an equal hole, which cancel).
double differenceArea(const LayerContours& a, const LayerContours& b) {
  ClipperLib::Clipper clipper;
  clipper.AddPaths(toPaths(a), ClipperLib::ptSubject, true);
  clipper.AddPaths(toPaths(b), ClipperLib::ptClip, true);
  ClipperLib::Paths out;
  clipper.Execute(ClipperLib::ctXor, out, ClipperLib::pftPositive, ClipperLib::pftPositive);
  double area = 0;
  for (const ClipperLib::Path& p : out) area += ClipperLib::Area(p);
  return std::fabs(area) / (kOffsetUnitsPerMm * kOffsetUnitsPerMm);
}

double perimeter(const LayerContours& layer) {
  double length = 0;
  for (std::size_t l = 0; l < layer.loopCount(); ++l) {
    const std::span<const Point2d> loop = layer.loopPoints(l);
    for (std::size_t i = 0, j = loop.size() - 1; i < loop.size(); j = i++)
      length += std::hypot(loop[i].x - loop[j].x, loop[i].y - loop[j].y);
  }
  return length;
}

// Growing by trimmed raw loops gives ClipperOffset's region: the two differ by no more than a band of
// a nanometre or two along the outline (each rounds its crossing points to whole nanometres). The one
// exception is a loop whose count goes negative somewhere: the bow tie's left triangle counts +1 and
// its right one -1, so its region is the left triangle. Grown by trimmed loops, that is what grows;
// ClipperOffset's detours add to the count over the negative triangle and it grows too large (by 0.43
// mm^2 of 2.97 at d = 0.3). The reference there is the left triangle grown alone, for distances at
// which the right triangle's corners are trimmed too (it then shrinks exactly, and no point within d of
// the left triangle lies in what is left of it). At 1.5 the right triangle vanishes (its inradius is
// 0.41), its detours stay, and nothing is promised for a negative count.
//
// Shrinking (a negative d) starts from the union of the input, which is clean (count 0 or 1), and gives
// ClipperOffset's shrink of that union, bow tie included (its union is the left triangle), down to
// nothing where d exceeds a shape's inradius.
TEST(PolygonOffset, GrowingOrShrinkingGivesClipperOffsetsRegion) {
  const std::vector<LayerContours> shapes = rawOffsetShapes();
  LayerContours leftOfBowTie;
  addLoop(leftOfBowTie, {{0, 0}, {1, 1}, {0, 2}});
  for (std::size_t s = 0; s < shapes.size(); ++s) {
    for (const double d : {0.0005, 0.05, 0.3, 1.5, -0.0005, -0.05, -0.3, -1.5}) {
      if (s == 6 && d > 1) continue;
      const ContourSet set{&shapes[s], 1};
      LayerContours offset;
      correctLayer({&set, 1}, {d, 0, 0}, 0.0, offset);
      const LayerContours reference = clipperOffset(s == 6 && d > 0 ? leftOfBowTie : shapes[s], d);
      const double band = 2e-6 * std::max(perimeter(reference), 1e-3);
      EXPECT_NEAR(layerSignedArea(offset), layerSignedArea(reference), band) << "shape " << s << ", d " << d;
      EXPECT_LE(differenceArea(offset, reference), band) << "shape " << s << ", d " << d;
    }
  }
}

// Real layers: the aligner (dense, nearly straight outlines with many concave corners, overlapping
// shells) and the femur, 40 layers each. The grown or shrunk region is ClipperOffset's within a
// nanometre band, and binary masks of the raw loops (what a masks-only job rasterizes) are those of
// Clipper's polygons.
TEST(PolygonOffset, GrowingOrShrinkingRealLayersGivesClipperOffsetsRegionAndMasks) {
  RasterScratch scratch;
  std::size_t pixelsCompared = 0, pixelsDiffering = 0, layersCompared = 0, levelsDiffering = 0,
              edgePixels = 0;
  for (const char* file : {"derived/aligner_upper_case0.stl.gz", "knee_femur_ssm_S001.stl"}) {
    const FacetSoup soup = readStl(fixtures::modelPath(file));
    const BoundingBox box = boundsOf(soup.corners);
    PlaneSpec spec;
    spec.layers = 40;
    std::string error;
    const std::vector<double> planes = makePlanes(spec, box.min.z, box.max.z, error);
    ASSERT_TRUE(error.empty()) << error;
    const std::vector<LayerContours> layers = fixtures::sliceToVector(soup, planes, SliceMethod::SelfReuse);
    const PixelGrid grid = fixtures::gridAround(box, 0.04725, 1, 0.013, 0.007);
    for (const double d : {0.05, 0.2, -0.05, -0.2}) {
      for (std::size_t k = 0; k < layers.size(); ++k) {
        if (layers[k].loopCount() == 0) continue;
        const ContourSet set{&layers[k], 1};
        LayerContours offset, raw;
        correctLayer({&set, 1}, {d, 0, 0}, 0.0, offset);
        ASSERT_TRUE(rawCorrectedLoops({&set, 1}, {d, 0, 0}, 0.0, raw));
        const LayerContours reference = clipperOffset(layers[k], d);
        EXPECT_LE(differenceArea(offset, reference), 2e-6 * std::max(perimeter(reference), 1e-3))
            << file << " layer " << k << ", d " << d;
        const ContourSet a{&reference, 1}, b{&raw, 1}, c{&offset, 1};
        MaskImage ma, mb;
        rasterizeBinary({&a, 1}, grid, ma, scratch);
        rasterizeBinary({&b, 1}, grid, mb, scratch);
        for (std::size_t p = 0; p < ma.pixels.size(); ++p)
          pixelsDiffering += ma.pixels[p] != mb.pixels[p] ? 1 : 0;
        pixelsCompared += ma.pixels.size();
        ++layersCompared;
        // Anti-aliased: the raw loops (crossing themselves where a detour stays) and their union cover
        // the same area of every pixel; a value may differ by one level at a rounding tie.
        rasterizeCoverage({&c, 1}, grid, ma, scratch);
        rasterizeCoverage({&b, 1}, grid, mb, scratch);
        for (std::size_t p = 0; p < ma.pixels.size(); ++p) {
          ASSERT_LE(std::abs(ma.pixels[p] - mb.pixels[p]), 1) << file << " layer " << k << ", d " << d;
          levelsDiffering += ma.pixels[p] != mb.pixels[p] ? 1 : 0;
          edgePixels += ma.pixels[p] != 0 && ma.pixels[p] != 255 ? 1 : 0;
        }
      }
    }
  }
  EXPECT_GT(layersCompared, 240u);
  // A pixel centre within a nanometre of the outline may fall either way: at most one in ten million.
  EXPECT_LE(pixelsDiffering * 10'000'000, pixelsCompared) << pixelsDiffering << " of " << pixelsCompared;
  EXPECT_GT(edgePixels, 100'000u);
  EXPECT_LE(levelsDiffering * 10'000, edgePixels) << levelsDiffering << " of " << edgePixels;
}

// Random outlines, 4,000 of them: stars of 5 to 84 points at random radii, half with a jitter point
// beside every vertex (short edges, sharp concave corners, spikes, small self-crossings), grown and
// shrunk by 0.005 to 0.6. Grown, wherever the count never goes negative, the region is
// ClipperOffset's. (With a negative count somewhere, ClipperOffset itself is not the grown positive
// region: see the bow tie.) Shrunk, it is ClipperOffset's shrink of the union, always.
TEST(PolygonOffset, GrowingOrShrinkingRandomOutlinesGivesClipperOffsetsRegion) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> uniform(0, 1);
  std::size_t compared = 0, shrinks = 0;
  for (int trial = 0; trial < 4000; ++trial) {
    std::vector<Point2d> points;
    const int n = 5 + trial % 80;
    for (int i = 0; i < n; ++i) {
      const double a = 2 * std::numbers::pi * (i + 0.8 * uniform(rng)) / n;
      const double r = (trial % 3 == 0 ? 0.05 : 0.5) + uniform(rng);
      points.push_back({r * std::cos(a), r * std::sin(a)});
      if (trial % 2) {
        const double e = 0.02 * uniform(rng), b = 2 * std::numbers::pi * uniform(rng);
        points.push_back({r * std::cos(a) + e * std::cos(b), r * std::sin(a) + e * std::sin(b)});
      }
    }
    LayerContours shape;
    addLoop(shape, points);
    const double d = 0.005 + (trial % 4 == 0 ? 0.6 : 0.1) * uniform(rng);
    {
      const ContourSet set{&shape, 1};
      LayerContours shrunk;
      correctLayer({&set, 1}, {-d, 0, 0}, 0.0, shrunk);
      const LayerContours reference = clipperShrunk(shape, d);
      ASSERT_LE(differenceArea(shrunk, reference), 2e-6 * std::max(perimeter(reference), 1e-3))
          << "trial " << trial << ", shrunk by " << d;
      ++shrinks;
    }
    ClipperLib::Paths negative;
    ClipperLib::Clipper clipper;
    clipper.AddPaths(toPaths(shape), ClipperLib::ptSubject, true);
    clipper.Execute(ClipperLib::ctUnion, negative, ClipperLib::pftNegative, ClipperLib::pftNegative);
    if (!negative.empty()) continue;
    const ContourSet set{&shape, 1};
    LayerContours grown;
    correctLayer({&set, 1}, {d, 0, 0}, 0.0, grown);
    const LayerContours reference = clipperGrown(shape, d);
    ASSERT_LE(differenceArea(grown, reference), 2e-6 * perimeter(reference))
        << "trial " << trial << ", d " << d;
    ++compared;
  }
  EXPECT_GT(compared, 2000u);
  EXPECT_EQ(shrinks, 4000u);
}

// Jagged outlines, 3,000 of them: circles of 40 to 400 vertices whose radii and angular steps jitter by
// about the offset distance, so that edges are as short as the distance and concave and convex corners
// alternate (as on a dense mesh's layers, where most trims do not fit their edges and are decided by the
// edges' swept bands). Grown or shrunk, the region is ClipperOffset's wherever the count is never
// negative.
TEST(PolygonOffset, JaggedOutlinesGiveClipperOffsetsRegion) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uniform(0, 1);
  std::size_t compared = 0;
  for (int trial = 0; trial < 3000; ++trial) {
    const int n = 40 + (trial * 37) % 360;
    const double d = (trial % 5 == 0 ? 0.002 : 0.01) + (trial % 3 == 0 ? 0.3 : 0.05) * uniform(rng);
    const double jitter = d * (0.2 + 2 * uniform(rng));
    std::vector<Point2d> points;
    for (int i = 0; i < n; ++i) {
      const double a = 2 * std::numbers::pi * (i + 0.9 * uniform(rng)) / n;
      const double r = 1 + jitter * (uniform(rng) - 0.5);
      points.push_back({r * std::cos(a), r * std::sin(a)});
    }
    LayerContours shape;
    if (trial % 2) {  // as a hole in a box
      addRect(shape, -3, -3, 3, 3);
      std::reverse(points.begin(), points.end());
    }
    addLoop(shape, points);
    ClipperLib::Paths negative;
    ClipperLib::Clipper clipper;
    clipper.AddPaths(toPaths(shape), ClipperLib::ptSubject, true);
    clipper.Execute(ClipperLib::ctUnion, negative, ClipperLib::pftNegative, ClipperLib::pftNegative);
    if (!negative.empty()) continue;
    for (const double sd : {d, -d}) {
      const ContourSet set{&shape, 1};
      LayerContours offset;
      correctLayer({&set, 1}, {sd, 0, 0}, 0.0, offset);
      const LayerContours reference = clipperOffset(shape, sd);
      ASSERT_LE(differenceArea(offset, reference), 2e-6 * std::max(perimeter(reference), 1e-3))
          << "trial " << trial << ", d " << sd;
      ++compared;
    }
  }
  EXPECT_GT(compared, 5000u);
}

// Concave corners are trimmed where their trims fit: an L grown by 0.1 is the grown L, six points, not
// a loop with a detour through its inner corner. Where the trims do not fit (the comb's notches at
// 0.3), the detour stays.
TEST(PolygonOffset, ConcaveCornersAreTrimmedWhereTheTrimsFit) {
  LayerContours shape;
  addLoop(shape, {{0, 0}, {4, 0}, {4, 1}, {1, 1}, {1, 4}, {0, 4}});
  const ContourSet set{&shape, 1};
  LayerContours raw;
  ASSERT_TRUE(rawCorrectedLoops({&set, 1}, {0.1, 0, 0}, 0.0, raw));
  const std::vector<Point2d> expected{{-0.1, -0.1}, {4.1, -0.1}, {4.1, 1.1},
                                      {1.1, 1.1},   {1.1, 4.1},  {-0.1, 4.1}};
  ASSERT_EQ(raw.points.size(), expected.size());
  for (std::size_t i = 0; i < expected.size(); ++i) {
    EXPECT_NEAR(raw.points[i].x, expected[i].x, 1e-9) << i;
    EXPECT_NEAR(raw.points[i].y, expected[i].y, 1e-9) << i;
  }
  const LayerContours comb = rawOffsetShapes().back();
  const ContourSet combSet{&comb, 1};
  ASSERT_TRUE(rawCorrectedLoops({&combSet, 1}, {0.01, 0, 0}, 0.0, raw));
  EXPECT_EQ(raw.points.size(), comb.points.size()) << "every corner trimmed";
  ASSERT_TRUE(rawCorrectedLoops({&combSet, 1}, {0.3, 0, 0}, 0.0, raw));
  EXPECT_GT(raw.points.size(), comb.points.size() + 20) << "the notches' detours stay";
}

// A concave corner whose next edge is shorter than the corner's reach is still trimmed where the bands
// swept by the edges on either side (with the convex join after the short edge and the edge after it)
// hold the small loop the trim removes; and where the short edge is swallowed (the moved edges before and
// after the corner do not meet on it), the edge before meets the one after the short edge, and the loop
// through the corner and the swallowed edge goes. Both regions are ClipperOffset's.
TEST(PolygonOffset, ShortEdgesAfterConcaveCornersAreTrimmedWhereTheSweptBandsHoldTheLoop) {
  const double t = 10 * std::numbers::pi / 180;
  const std::vector<std::vector<Point2d>> outlines{
      {{0, 0}, {4, 0}, {4, 1}, {1.2, 1}, {1.2, 1.05}, {1, 1.05}, {1, 4}, {0, 4}},  // a 0.05 step
      {{0, 0},
       {4, 0},
       {4, 1},
       {1.2, 1},
       {1.2, 1.01},
       {1.2 - 3 * std::sin(t), 1.01 + 3 * std::cos(t)},
       {0, 1.01 + 3 * std::cos(t)}}};  // a 0.01 edge, then a slight left turn: swallowed (and gone) at 0.1
  for (std::size_t o = 0; o < outlines.size(); ++o) {
    LayerContours shape;
    addLoop(shape, outlines[o]);
    const ContourSet set{&shape, 1};
    LayerContours raw, grown;
    ASSERT_TRUE(rawCorrectedLoops({&set, 1}, {0.1, 0, 0}, 0.0, raw));
    EXPECT_EQ(raw.points.size(), outlines[o].size() - o) << "outline " << o << ": no detour left";
    correctLayer({&set, 1}, {0.1, 0, 0}, 0.0, grown);
    const LayerContours reference = clipperGrown(shape, 0.1);
    EXPECT_LE(differenceArea(grown, reference), 2e-6 * perimeter(reference)) << "outline " << o;
    EXPECT_LE(differenceArea(raw, reference), 2e-6 * perimeter(reference)) << "outline " << o;
  }
}

// The outline cleaning before every offset keeps the points the reference cleaning keeps (Clipper's
// CleanPolygon, with every dropped point near the line of its kept neighbours), in its order: random loops of
// 3 to 60 points with runs of points closer than the distance, points nearly on the line of their neighbours,
// spikes and collapsing loops (where the cleaning walks back past the first point), and a few long straight
// stretches at large coordinates.
TEST(PolygonOffset, OutlineCleaningIsTheReferenceCleaning) {
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> pick(0, 9);
  std::normal_distribution<double> jitter(0, 1);
  const double distance = 500;
  std::size_t removed = 0, empty = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    const int n = 3 + trial % 58;
    const double scale = trial % 10 == 0 ? 1e3 : trial % 10 == 1 ? 1e8 : 1e5;
    std::vector<std::array<int64_t, 2>> loop;
    ClipperLib::Path path;
    double x = 0, y = 0;
    for (int i = 0; i < n; ++i) {
      const int kind = pick(rng);
      if (kind < 3) {  // close to the point before
        x += 300 * jitter(rng);
        y += 300 * jitter(rng);
      } else if (kind < 6 && i >= 2) {  // nearly on the line of the two before
        x += (x - static_cast<double>(loop[i - 2][0])) + 200 * jitter(rng);
        y += (y - static_cast<double>(loop[i - 2][1])) + 200 * jitter(rng);
      } else {
        x += scale * jitter(rng);
        y += scale * jitter(rng);
      }
      loop.push_back({std::llround(x), std::llround(y)});
      path.push_back(ClipperLib::IntPoint(loop.back()[0], loop.back()[1]));
    }
    const ClipperLib::Path expected = referenceClean(path, distance);
    const std::vector<std::array<int64_t, 2>> kept = cleanedOutline(loop, distance);
    ASSERT_EQ(kept.size(), expected.size()) << "trial " << trial;
    for (std::size_t i = 0; i < kept.size(); ++i) {
      ASSERT_EQ(kept[i][0], expected[i].X) << "trial " << trial << ", point " << i;
      ASSERT_EQ(kept[i][1], expected[i].Y) << "trial " << trial << ", point " << i;
    }
    removed += loop.size() - kept.size();
    empty += kept.empty() ? 1 : 0;
  }
  EXPECT_GT(removed, 50000u);
  EXPECT_GT(empty, 100u);
}

// Runs of concave corners whose edges are shorter than the distance times their turn (the rounded
// bottom of a groove narrower than the distance, cut into short edges as a dense mesh's layers have
// it): the moved edges of the run are replaced by their envelope, and no detour is left where the run
// turns by less than a half turn and its end edges hold the envelope's ends. Random grooves (jittered,
// some turning more than a half turn, with short or long sides), grown and shrunk (shrinking the box
// with the groove is growing it: its convex corners turn concave): the region is ClipperOffset's.
TEST(PolygonOffset, RunsOfConcaveCornersGoByTheirEnvelope) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> uniform(0, 1);
  std::size_t compared = 0, noDetour = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    const int edges = 2 + trial % 40;
    const double alpha = 0.15 + (trial % 9 == 0 ? 1.7 : 1.3) * uniform(rng);  // half the groove's turn
    const double radius = 0.005 + 0.3 * uniform(rng), d = 0.01 + 0.5 * uniform(rng);
    const double side = 0.02 + (trial % 2 ? 2.0 : 0.3) * uniform(rng);
    const double jitter = trial % 3 == 0 ? 0.4 * radius * alpha / edges * uniform(rng) : 0;
    // The groove's bottom: an arc about (0, c) from angle alpha to -alpha, and its sides, tangent to it,
    // `side` long, up to y = top; the box around it.
    const double c = 0;
    const double top = c - radius * std::cos(alpha) + side * std::sin(alpha);
    const double xTop = radius * std::sin(alpha) + side * std::cos(alpha);
    const double wide = std::max(4.0, xTop + 2);
    std::vector<Point2d> points{{-wide, top - 6}, {wide, top - 6}, {wide, top}, {xTop, top}};
    for (int i = 0; i <= edges; ++i) {
      const double a =
          alpha - 2 * alpha * i / edges + (i > 0 && i < edges ? jitter * (uniform(rng) - 0.5) : 0);
      points.push_back({radius * std::sin(a), c - radius * std::cos(a)});
    }
    points.push_back({-xTop, top});
    points.push_back({-wide, top});
    LayerContours shape;
    addLoop(shape, points);
    for (const double sd : {d, -d}) {
      const ContourSet set{&shape, 1};
      LayerContours offset, raw;
      correctLayer({&set, 1}, {sd, 0, 0}, 0.0, offset);
      const LayerContours reference = clipperOffset(shape, sd);
      ASSERT_LE(differenceArea(offset, reference), 2e-6 * std::max(perimeter(reference), 1e-3))
          << "trial " << trial << ", d " << sd;
      ASSERT_TRUE(rawCorrectedLoops({&set, 1}, {sd, 0, 0}, 0.0, raw));
      ASSERT_LE(differenceArea(raw, reference), 2e-6 * std::max(perimeter(reference), 1e-3))
          << "raw, trial " << trial << ", d " << sd;
      ++compared;
      if (sd > 0 && raw.points.size() <= points.size()) ++noDetour;
    }
  }
  EXPECT_EQ(compared, 4000u);
  EXPECT_GT(noDetour, 300u);
}

// The masks' raw loops (built straight from the layer's points) united are correctLayer's polygons
// (built through its Paths), point for point: masks-only and contour jobs see one region.
TEST(PolygonOffset, RawLoopsUniteToTheCorrectedLayerPointForPoint) {
  std::vector<LayerContours> shapes = rawOffsetShapes();
  // An arc of radius 2 m in 2 mm steps: turns of 1 mrad, which outline cleaning keeps (the middle point
  // is 1 um off its neighbours' line) and a 0.5 um offset takes as straight on.
  LayerContours& arc = shapes.emplace_back();
  std::vector<Point2d> points;
  for (int i = 0; i <= 20; ++i)
    points.push_back({2000 * std::sin(0.001 * i), 2000 * (1 - std::cos(0.001 * i))});
  points.push_back({0, 5});
  addLoop(arc, points);
  for (std::size_t s = 0; s < shapes.size(); ++s) {
    for (const double d : {0.0005, 0.05, 0.3, 1.5, -0.0005, -0.05, -0.3}) {
      const ContourSet set{&shapes[s], 1};
      LayerContours expected, raw, united;
      correctLayer({&set, 1}, {d, 0, 0}, 1.0, expected);
      ASSERT_TRUE(rawCorrectedLoops({&set, 1}, {d, 0, 0}, 1.0, raw)) << s;
      EXPECT_EQ(raw.z, 1.0);
      unitePositive(raw, 1.0, united);
      ASSERT_EQ(united.loopCount(), expected.loopCount()) << "shape " << s << ", d " << d;
      EXPECT_TRUE(united.points == expected.points) << "shape " << s << ", d " << d;
      EXPECT_TRUE(united.loopOffsets == expected.loopOffsets) << "shape " << s << ", d " << d;
    }
  }
}

// Raw loops for an absolute correction alone: growing one positive set (growth distributes over the
// union), or shrinking any sets (from their union). Not with an elephant foot, nor for growing sets
// that a union would have to merge first.
TEST(PolygonOffset, RawLoopsForAnAbsoluteCorrectionAlone) {
  LayerContours box, hole;
  addRect(box, 0, 0, 10, 6);
  addRect(hole, 4, 2, 6, 4);
  const ContourSet one{&box, 1}, removed[] = {{&box, 1}, {&hole, -1}}, added[] = {{&box, 1}, {&hole, 1}};
  LayerContours out;
  EXPECT_FALSE(rawCorrectedLoops({&one, 1}, {0.05, 0.1, 0.2}, 0, out));   // the elephant foot
  EXPECT_FALSE(rawCorrectedLoops({&one, 1}, {-0.05, 0.1, 0.2}, 0, out));  // shrinking or not
  EXPECT_FALSE(rawCorrectedLoops({&one, 1}, {0, 0, 0}, 0, out));
  EXPECT_FALSE(rawCorrectedLoops(removed, {0.05, 0, 0}, 0, out));
  EXPECT_FALSE(rawCorrectedLoops(added, {0.05, 0, 0}, 0, out));
  EXPECT_EQ(out.loopCount(), 0u);
  EXPECT_TRUE(rawCorrectedLoops({&one, 1}, {0.05, 0, 0}, 0, out));
  EXPECT_TRUE(rawCorrectedLoops({&one, 1}, {-0.05, 0, 0}, 0, out));
  EXPECT_EQ(out.points.size(), 4u);  // the box's convex corners trimmed: no detour through them
  // The box with its hole removed, shrunk: the frame 9.9 x 5.9 minus the hole grown to 2.1 x 2.1.
  ASSERT_TRUE(rawCorrectedLoops(removed, {-0.05, 0, 0}, 0, out));
  EXPECT_NEAR(layerSignedArea(out), 9.9 * 5.9 - 2.1 * 2.1, 1e-9);
}

TEST(PolygonOffset, RawLoopsRasterizeToTheOffsetsMasks) {
  // The rasterizers' positive rule does the union: the same binary pixels, and anti-aliased values
  // within one level (the united outline's crossing points are rounded to integer nanometres).
  const std::vector<LayerContours> shapes = rawOffsetShapes();
  PixelGrid grid;
  grid.x0 = -5.013;
  grid.y0 = -5.007;
  grid.pixel = 0.0473;
  grid.width = 360;
  grid.height = 330;
  RasterScratch scratch;
  for (std::size_t s = 0; s < shapes.size(); ++s) {
    for (const double d : {0.05, 0.3, -0.05, -0.3}) {
      const ContourSet set{&shapes[s], 1};
      LayerContours polygons, raw;
      correctLayer({&set, 1}, {d, 0, 0}, 0.0, polygons);
      ASSERT_TRUE(rawCorrectedLoops({&set, 1}, {d, 0, 0}, 0.0, raw));
      const ContourSet a{&polygons, 1}, b{&raw, 1};
      MaskImage ma, mb;
      uint64_t litA = 0, litB = 0;
      rasterizeBinary({&a, 1}, grid, ma, scratch, &litA);
      rasterizeBinary({&b, 1}, grid, mb, scratch, &litB);
      EXPECT_TRUE(litA > 0 || d < 0) << s;  // a shrink may leave nothing of a small shape
      EXPECT_TRUE(ma.pixels == mb.pixels) << "binary, shape " << s << ", d " << d;
      rasterizeCoverage({&a, 1}, grid, ma, scratch);
      rasterizeCoverage({&b, 1}, grid, mb, scratch);
      int worst = 0;
      for (std::size_t p = 0; p < ma.pixels.size(); ++p)
        worst = std::max(worst, std::abs(ma.pixels[p] - mb.pixels[p]));
      EXPECT_LE(worst, 1) << "anti-aliased, shape " << s << ", d " << d;
    }
  }
}

TEST(ElephantFoot, ThinPinsSurviveAndTheBodyShrinks) {
  // A 10 x 10 box with two pins 0.1 mm wide and 1 mm long on its right side.
  LayerContours part;
  addLoop(part, {{0, 0},
                 {10, 0},
                 {10, 2.95},
                 {11, 2.95},
                 {11, 3.05},
                 {10, 3.05},
                 {10, 6.95},
                 {11, 6.95},
                 {11, 7.05},
                 {10, 7.05},
                 {10, 10},
                 {0, 10}});
  const double e = 0.2, width = 0.2;
  const ContourSet set{&part, 1};
  LayerContours out;
  correctLayer({&set, 1}, {0, e, width}, 0.0, out);
  // Body shrunk by e; each pin kept whole, joined to the body by its root: in 16 steps of s = 12.5 um
  // the root grows a step wider on each side per step inward while it is thinner than the minimum
  // width (5 steps: 0.125, 0.15, ..., 0.225 wide, each s long), then goes on as a neck 0.25 wide to the
  // shrunk body's edge (10 - e - 0.0625 = 0.1375 long).
  const double s = e / 16, root = s * (0.125 + 0.15 + 0.175 + 0.2 + 0.225) + 0.25 * (e - 5 * s);
  const double expected = (10 - 2 * e) * (10 - 2 * e) + 2 * (0.1 * 1.0 + root);
  EXPECT_NEAR(layerSignedArea(out), expected, 1e-5);
  EXPECT_EQ(out.loopCount(), 1u);  // the pins stay joined to the body
  // The pin tips are lit on a 10 um grid.
  PixelGrid grid{-0.5, -0.5, 0.01, 1200, 1200};
  MaskImage mask;
  RasterScratch scratch;
  const ContourSet corrected{&out, 1};
  rasterizeBinary({&corrected, 1}, grid, mask, scratch);
  const auto lit = [&](double x, double y) {
    const auto i = static_cast<uint32_t>((x - grid.x0) / grid.pixel),
               j = static_cast<uint32_t>((y - grid.y0) / grid.pixel);
    return mask.pixels[j * grid.width + i] != 0;
  };
  EXPECT_TRUE(lit(10.955, 3.005));
  EXPECT_TRUE(lit(10.955, 7.005));
  EXPECT_FALSE(lit(9.905, 5.005));  // the body's edge moved in by e
  // Without a minimum width the pins go with the rest.
  correctLayer({&set, 1}, {0, e, 0}, 0.0, out);
  EXPECT_NEAR(layerSignedArea(out), (10 - 2 * e) * (10 - 2 * e), 1e-5);
}

// PrusaSlicer's elefant_foot_min_width: no wall made narrower than the minimum width by the shrink. A
// wall thinner than it keeps its width, one between w and w + 2e ends w wide (within two steps of
// 12.5 um above), a wider one loses e on each side. Before, walls 0.25-0.4 mm wide vanished while a
// 0.15 mm wall stayed, and a 0.5 mm wall ended 0.1 mm wide.
TEST(ElephantFoot, NoWallEndsNarrowerThanTheMinimumWidth) {
  const double e = 0.2, w = 0.2;
  const std::vector<double> widths = {0.15, 0.25, 0.3, 0.4, 0.5, 0.6, 0.8};
  LayerContours walls;
  for (std::size_t i = 0; i < widths.size(); ++i) {
    const double y = 2.0 * static_cast<double>(i);
    addLoop(walls, {{0, y}, {10, y}, {10, y + widths[i]}, {0, y + widths[i]}});
  }
  const ContourSet set{&walls, 1};
  LayerContours out;
  correctLayer({&set, 1}, {0, e, w}, 0.0, out);
  ASSERT_EQ(out.loopCount(), widths.size());
  for (std::size_t l = 0; l < out.loopCount(); ++l) {
    double lo = 1e9, hi = -1e9;
    for (const Point2d& p : out.loopPoints(l)) lo = std::min(lo, p.y), hi = std::max(hi, p.y);
    const std::size_t i = static_cast<std::size_t>(std::lround(lo / 2.0));
    const double d = widths[i], width = hi - lo;
    if (d < w) {
      EXPECT_NEAR(width, d, 1e-6) << "wall " << d;
    } else if (d <= w + 2 * e) {
      EXPECT_GE(width, w - 1e-6) << "wall " << d;
      EXPECT_LE(width, w + 2 * 0.0125 + 1e-6) << "wall " << d;
    } else {
      EXPECT_NEAR(width, d - 2 * e, 1e-6) << "wall " << d;
    }
    // Centred on the wall.
    EXPECT_NEAR(0.5 * (lo + hi), 2.0 * static_cast<double>(i) + 0.5 * d, 1e-6) << "wall " << d;
  }
  // A finely drawn pin thinner than w keeps its outline: 256 sides, 0.15 mm across (the steps' final
  // closing wore it down to 0.145 mm).
  LayerContours pin;
  std::vector<Point2d> circle;
  for (int k = 0; k < 256; ++k) {
    const double a = 2 * std::numbers::pi * k / 256;
    circle.push_back({0.075 * std::cos(a), 0.075 * std::sin(a)});
  }
  addLoop(pin, circle);
  const ContourSet pinSet{&pin, 1};
  correctLayer({&pinSet, 1}, {0, e, w}, 0.0, out);
  EXPECT_NEAR(layerSignedArea(out), layerSignedArea(pin), 1e-6);  // nanometre rounding; 6 % was 1e-3
}

TEST(ElephantFoot, FadesLinearlyOverItsLayers) {
  // PrusaSlicer's fade (SLAPrint printer corrections): n = max(1, layers - 1), layer k gets e (n - k) / n.
  EXPECT_DOUBLE_EQ(elephantFootAt(0, 0.2, 1), 0.2);
  EXPECT_DOUBLE_EQ(elephantFootAt(1, 0.2, 1), 0.0);
  EXPECT_DOUBLE_EQ(elephantFootAt(0, 0.2, 2), 0.2);
  EXPECT_DOUBLE_EQ(elephantFootAt(1, 0.2, 2), 0.0);
  EXPECT_DOUBLE_EQ(elephantFootAt(0, 0.2, 4), 0.2);
  EXPECT_DOUBLE_EQ(elephantFootAt(1, 0.2, 4), 0.2 * 2 / 3);
  EXPECT_DOUBLE_EQ(elephantFootAt(2, 0.2, 4), 0.2 / 3);
  EXPECT_DOUBLE_EQ(elephantFootAt(3, 0.2, 4), 0.0);
  EXPECT_DOUBLE_EQ(elephantFootAt(4, 0.2, 4), 0.0);
  EXPECT_DOUBLE_EQ(elephantFootAt(9, 0.2, 10), 0.0);
  EXPECT_DOUBLE_EQ(elephantFootAt(8, 0.2, 10), 0.2 / 9);
}

// The gamma applies to the exact coverage: round(255 a^gamma) for any a, not to a rounded to 8 bits
// first (a pixel 0.000655 covered was 0 at every gamma; at 0.45 it is 9).
TEST(MaskCorrections, GammaAndLightMap) {
  std::mt19937_64 random(7);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (const double gamma : {1.0, 2.0, 0.45, 2.2, 0.8}) {
    const CoverageCurve curve = gammaCurve(gamma);
    EXPECT_EQ(curve.value(0), 0);
    EXPECT_EQ(curve.value(-1e-12), 0);
    EXPECT_EQ(curve.value(1), 255);
    EXPECT_EQ(curve.value(1 + 1e-12), 255);
    for (int k = 0; k < 20000; ++k) {
      // Uniform, and many near 0 where a gamma under 1 is steep.
      const double a = k % 2 == 0 ? unit(random) : std::pow(unit(random), 8.0);
      const double exact = 255.0 * std::pow(a, gamma) + 0.5;
      const int v = curve.value(a);
      // Exact away from ties (a rounding step of pow may move a value sitting on a half).
      if (std::abs(exact - std::round(exact)) > 1e-9) {
        ASSERT_EQ(v, static_cast<int>(std::floor(exact))) << "gamma " << gamma << ", a " << a;
      }
    }
  }
  EXPECT_EQ(gammaCurve(0.45).value(0.000655), 9);     // 255 * 0.000655^0.45 = 9.41
  EXPECT_EQ(gammaCurve(2.0).value(128 / 255.0), 64);  // 255 * (128/255)^2 = 64.25
  EXPECT_EQ(gammaCurve(2.2).value(0.02), 0);          // 255 * 0.02^2.2 = 0.047
  EXPECT_EQ(lightValue(255, 128), 128);
  EXPECT_EQ(lightValue(128, 255), 128);
}

TEST(ScaleCorrection, AboutTheBottomCentre) {
  FacetSoup soup = fixtures::box(0, 0, 1, 10, 4, 3);
  const BoundingBox before = boundsOf(soup.corners);
  scaleCorners(soup.corners, {1.02, 0.5, 2.0}, scaleCentre(before));
  const BoundingBox after = boundsOf(soup.corners);
  EXPECT_NEAR(after.min.x, -0.1, 1e-6);
  EXPECT_NEAR(after.max.x, 10.1, 1e-6);
  EXPECT_NEAR(after.min.y, 1, 1e-6);
  EXPECT_NEAR(after.max.y, 3, 1e-6);
  EXPECT_NEAR(after.min.z, 1, 1e-6);
  EXPECT_NEAR(after.max.z, 5, 1e-6);
}

// Through the program: the per-layer report's areas (lit pixels x pixel^2) against the analytic area
// of each corrected layer, within one pixel row along the outline (perimeter x pixel).
class CorrectionsCli : public CliToolBase {
 protected:
  std::vector<double> reportAreas(const fs::path& csv) {
    std::ifstream in(csv);
    std::string line;
    std::getline(in, line);
    std::vector<double> areas;
    while (std::getline(in, line)) {
      std::stringstream s(line);
      std::string field;
      for (int i = 0; i < 3; ++i) std::getline(s, field, ',');
      areas.push_back(std::stod(field));
    }
    return areas;
  }
};

// The contours' extent (a CLI's $$DIMENSION, an SVG's view box) holds every contour written: a growing
// absolute correction and an add-on reaching out of the model widen it (the header said -2.65 .. 12.65
// where the polylines ran -2.75 .. 12.75, and an SVG's view box cut the add-on off).
TEST_F(CorrectionsCli, TheContoursExtentHoldsTheCorrectedContours) {
  writeBinaryStl(path("box.stl"), fixtures::box(0, 0, 0, 10, 10, 2), "box", false);
  writeBinaryStl(path("tab.stl"), fixtures::box(9, 4, 0, 14, 6, 2), "tab", false);
  const auto run1 = run({"slice", "box.stl", "-H", "0.5", "-o", "c.cli", "-o", "c.svg", "--add", "tab.stl",
                         "--absolute-correction", "0.1", "--relative-correction-x", "1.02", "-q"});
  ASSERT_EQ(run1.code(), 0) << run1.describe();
  double dims[6] = {};
  double lo[2] = {INFINITY, INFINITY}, hi[2] = {-INFINITY, -INFINITY};
  std::istringstream in(tool_test::readBytes(path("c.cli")));
  for (std::string line; std::getline(in, line);) {
    if (line.starts_with("$$DIMENSION/")) {
      ASSERT_EQ(std::sscanf(line.c_str() + 12, "%lf,%lf,%lf,%lf,%lf,%lf", &dims[0], &dims[1], &dims[2],
                            &dims[3], &dims[4], &dims[5]),
                6);
    }
    if (!line.starts_with("$$POLYLINE/")) continue;
    std::vector<double> v;
    std::stringstream fields(line.substr(11));
    for (std::string f; std::getline(fields, f, ',');) v.push_back(std::stod(f));
    for (std::size_t k = 3; k + 1 < v.size(); k += 2)
      for (int a = 0; a < 2; ++a) lo[a] = std::min(lo[a], v[k + a]), hi[a] = std::max(hi[a], v[k + a]);
  }
  ASSERT_TRUE(std::isfinite(lo[0])) << "no polyline";
  EXPECT_NEAR(hi[0], 14.28, 1e-3);  // the tab's end, scaled about the model's centre (x 5), grown by 0.1
  for (int a = 0; a < 2; ++a) {
    EXPECT_LE(dims[a], lo[a] + 1e-6) << "axis " << a;
    EXPECT_GE(dims[3 + a], hi[a] - 1e-6) << "axis " << a;
  }
  // The SVG's first panel: its frame is the extent; every point of its paths lies inside it.
  const std::string svg = tool_test::readBytes(path("c.svg"));
  const std::size_t frame = svg.find("<rect class=\"frame\"");
  ASSERT_NE(frame, std::string::npos);
  double fx = 0, fy = 0, fw = 0, fh = 0;
  ASSERT_EQ(std::sscanf(svg.c_str() + frame,
                        "<rect class=\"frame\" x=\"%lf\" y=\"%lf\" width=\"%lf\" height=\"%lf\"", &fx, &fy,
                        &fw, &fh),
            4)
      << svg.substr(frame, 100);
  const std::size_t end = svg.find("</g>", frame);
  std::size_t points = 0;
  for (std::size_t d = svg.find(" d=\"", frame); d < end; d = svg.find(" d=\"", d + 1)) {
    const std::size_t close = svg.find('"', d + 4);
    std::string text = svg.substr(d + 4, close - d - 4);
    for (char& c : text)
      if (c == 'M' || c == 'L' || c == 'Z' || c == ',') c = ' ';
    std::istringstream numbers(text);
    for (double x = 0, y = 0; numbers >> x >> y; ++points) {
      EXPECT_GE(x, fx - 2e-4);
      EXPECT_LE(x, fx + fw + 2e-4);
      EXPECT_GE(y, fy - 2e-4);
      EXPECT_LE(y, fy + fh + 2e-4);
    }
  }
  EXPECT_GT(points, 4u);
}

TEST_F(CorrectionsCli, CylinderEachCorrectionAloneAndCombined) {
  const double r = 4, h = 2, layer = 0.1, pixel = 0.01;
  writeBinaryStl(path("cyl.stl"), fixtures::cylinder(0, 0, r, 720, 0, static_cast<float>(h)), "cylinder",
                 true);
  struct Case {
    std::vector<std::string> args;
    double sx, sy, sz, absolute, foot;
  };
  const std::vector<Case> cases = {
      {{}, 1, 1, 1, 0, 0},
      {{"--absolute-correction", "0.05"}, 1, 1, 1, 0.05, 0},
      {{"--absolute-correction", "-0.05"}, 1, 1, 1, -0.05, 0},
      {{"--relative-correction-x", "1.02", "--relative-correction-y", "1.02"}, 1.02, 1.02, 1, 0, 0},
      {{"--relative-correction-z", "1.5"}, 1, 1, 1.5, 0, 0},
      {{"--material-correction-z", "0.5", "--relative-correction-z", "1.2"}, 1, 1, 0.6, 0, 0},
      {{"--elefant-foot-compensation", "0.2"}, 1, 1, 1, 0, 0.2},
      {{"--relative-correction-x", "1.02", "--relative-correction-y", "1.02", "--absolute-correction", "0.05",
        "--elefant-foot-compensation", "0.2", "--material-correction-z", "1.1"},
       1.02,
       1.02,
       1.1,
       0.05,
       0.2},
  };
  for (const Case& c : cases) {
    std::vector<std::string> args{"slice",        path("cyl.stl").string(),
                                  "-H",           "0.1",
                                  "--resolution", "1000x1000",
                                  "--pixel",      "0.01",
                                  "--masks",      path("m").string(),
                                  "--report",     path("r.csv").string(),
                                  "-f",           "-q"};
    args.insert(args.end(), c.args.begin(), c.args.end());
    const RunResult run = this->run(args);
    ASSERT_EQ(run.code(), 0) << run.describe();
    const std::vector<double> areas = reportAreas(path("r.csv"));
    // z scaling changes the layer count: ceil(height / layer) of the scaled (float) model height; a
    // plane above the top (the float height a hair over 1.2) is empty.
    const double top = static_cast<float>(h * c.sz);
    EXPECT_EQ(areas.size(), static_cast<std::size_t>(std::ceil(top / layer))) << c.args.size();
    for (std::size_t k = 0; k < areas.size() && (static_cast<double>(k) + 0.5) * layer < top; ++k) {
      // The 720-gon scaled by (sx, sy) is an ellipse to within 1e-4 of its area; the offset adds
      // perimeter x d (+ pi d^2 for a disc).
      const double a = r * c.sx, b = r * c.sy;
      // The elephant foot fades over the default faded_layers (10) as PrusaSlicer fades it: layer k
      // gets foot (n - k) / n, n = 9.
      const double n = 9;
      double d = c.absolute - (k < 10 ? c.foot * (n - static_cast<double>(k)) / n : 0);
      const double perimeter = std::numbers::pi * (3 * (a + b) - std::sqrt((3 * a + b) * (a + 3 * b)));
      const double expected = std::numbers::pi * a * b + perimeter * d + std::numbers::pi * d * d;
      EXPECT_NEAR(areas[k], expected, perimeter * pixel + 0.01)
          << "layer " << k << " of case " << c.args.size();
    }
  }
}

TEST_F(CorrectionsCli, ProfileFileSettingsReachTheSl1) {
  {
    std::ofstream profile(path("lab.json"));
    profile << R"({"printers": {"lab-sl1": {"inherits": "sl1", "absolute_correction": -0.02,
                    "relative_correction_x": 1.01}},
                  "materials": {"dental": {"exposure_time": 6.5, "initial_exposure_time": 30,
                    "faded_layers": 8, "material_density": 1.2, "material_correction_z": 1.002}}})";
  }
  const RunResult run = this->run({"slice", examplePart().string(), "-H", "0.05", "--profile",
                                   path("lab.json").string(), "--masks", path("a.sl1").string(),
                                   "--exposure-time", "7", "--summary", path("s.json").string(), "-q"});
  ASSERT_EQ(run.code(), 0) << run.describe();
  const std::string zip = readBytes(path("a.sl1"));
  (void)zip;
  const RunResult ini = this->run({"slice", examplePart().string(), "--profile", path("lab.json").string(),
                                   "--masks", path("b.sl1").string(), "--explain"});
  ASSERT_EQ(ini.code(), 0) << ini.describe();
  EXPECT_NE(ini.out.find("exposure_time              = 6.5"), std::string::npos) << ini.out;
  EXPECT_NE(ini.out.find("absolute_correction        = -0.02        (profile lab.json printer lab-sl1)"),
            std::string::npos)
      << ini.out;
  EXPECT_FALSE(fs::exists(path("b.sl1")));  // --explain writes nothing
  // What the run would refuse without reading a mesh, --explain refuses too (it said the settings and
  // exit 0): a model that cannot be opened, a light map missing or of another size than the display.
  for (const auto& [args, said] : std::vector<std::pair<std::vector<std::string>, std::string>>{
           {{"missing.stl"}, "missing.stl: cannot open: No such file or directory"},
           {{examplePart().string(), "--add", "missing-tab.stl"}, "missing-tab.stl: cannot open"},
           {{examplePart().string(), "--antialias", "--light-map", "missing.png"},
            "missing.png: cannot read"},
           {{examplePart().string(), "--antialias", "--light-map", path("lab.json").string()},
            "lab.json: the light map must be an 8-bit (or less) grayscale PNG"}}) {
    std::vector<std::string> command{"slice"};
    command.insert(command.end(), args.begin(), args.end());
    command.insert(command.end(), {"--printer", "sl1", "--masks", path("x.sl1").string(), "--explain"});
    const RunResult refused = this->run(command);
    EXPECT_EQ(refused.code(), 1) << refused.describe();
    EXPECT_NE(refused.err.find(said), std::string::npos) << refused.err;
  }
  // The display the masks have: --resolution (with the printer's pitch) and --mirror-y.
  const RunResult display =
      this->run({"slice", examplePart().string(), "--printer", "sl1", "--resolution", "2000x1000",
                 "--mirror-y", "--masks", path("c.sl1").string(), "--explain"});
  ASSERT_EQ(display.code(), 0) << display.describe();
  for (const char* line : {"display_pixels_x           = 2000         (--resolution)",
                           "display_width              = 94.5         (--resolution)",
                           "display_height             = 47.25        (--resolution)",
                           "display_mirror_y           = 1            (command line)"})
    EXPECT_NE(display.out.find(line), std::string::npos) << line << "\n" << display.out;
  // A batch job's settings: its profile, material and print_settings, shown by batch --explain.
  tool_test::writeBytes(path("job.json"),
                        R"({"template": {"model": "m.stl"}, "settings": {"layer_height": 0.05,
      "profile": "lab.json", "printer": "lab-sl1", "material": "dental", "print_settings": {"faded_layers": 3}},
      "variants": [{"name": "a", "model": "m.stl", "masks": "a2.sl1"}, {"name": "b", "model": "m.stl",
      "contours": "b.cli"}]})");
  const RunResult batch = this->run({"batch", path("job.json").string(), "--explain"});
  ASSERT_EQ(batch.code(), 0) << batch.describe();
  for (const char* line : {"batch job  : ", "(2 variants)\n", "printer    : lab-sl1\n",
                           "  faded_layers               = 3            (batch job print_settings)\n",
                           "masks      : each variant's (1 of 2 variants), binary",
                           "exposure   : 6.5 s, first layer 30 s, faded over 3 layers\n"})
    EXPECT_NE(batch.out.find(line), std::string::npos) << line << batch.out;
  EXPECT_FALSE(fs::exists(path("a2.sl1")));
  const std::string summary = readBytes(path("s.json"));
  EXPECT_NE(summary.find("\"exposure_time\": \"7\""), std::string::npos) << summary;
  EXPECT_NE(summary.find("\"material\": \"dental\""), std::string::npos) << summary;
  EXPECT_NE(summary.find("\"resin_mass_g\""), std::string::npos) << summary;
}

// The settings a job uses also go into each EXR layer's header (docs/FORMATS.md: "ts:" + the key), read
// back here with tinyexr, a decoder that is not the one that writes them.
TEST_F(CorrectionsCli, SettingsReachTheExrLayersHeaders) {
  const RunResult run = this->run({"slice", examplePart().string(), "-H", "1", "--printer", "sl1", "--masks",
                                   path("a.exr").string(), "--exposure-time", "6.5", "--absolute-correction",
                                   "0.02", "--set", "faded_layers=7", "-q"});
  ASSERT_EQ(run.code(), 0) << run.describe();
  const TinyExrLayer layer = readExrWithTinyExr(path("a.exr") / exrLayerFileName("example_part", 0, 7));
  ASSERT_EQ(layer.error, "");
  for (const auto& [key, value] :
       std::vector<std::pair<std::string, std::string>>{{"ts:exposure_time", "6.5"},
                                                        {"ts:absolute_correction", "0.02"},
                                                        {"ts:faded_layers", "7"},
                                                        {"ts:initial_exposure_time", "35"},
                                                        {"ts:printer_model", "SL1"},
                                                        {"ts:gamma_correction", "0"},
                                                        // The SL1's portrait display and its mirror are not
                                                        // applied to a volume: the headers say what is.
                                                        {"ts:display_orientation", "landscape"},
                                                        {"ts:display_mirror_x", "0"}}) {
    const auto found = layer.strings.find(key);
    ASSERT_NE(found, layer.strings.end()) << key;
    EXPECT_EQ(found->second, value) << key;
  }
  // Left to --antialias, the gamma the headers give is the one the masks have (as the SL1's ini says).
  const RunResult aa = this->run({"slice", examplePart().string(), "-H", "1", "--printer", "sl1", "--masks",
                                  path("aa.exr").string(), "--antialias", "-q"});
  ASSERT_EQ(aa.code(), 0) << aa.describe();
  const TinyExrLayer aaLayer = readExrWithTinyExr(path("aa.exr") / exrLayerFileName("example_part", 0, 7));
  ASSERT_EQ(aaLayer.error, "");
  EXPECT_EQ(aaLayer.strings.count("ts:gamma_correction") ? aaLayer.strings.at("ts:gamma_correction") : "none",
            "1");
  // The display as the images have it: generic-4k has no pixel pitch of its own (display_width 0), --pixel
  // gives it one, --resolution another size.
  const RunResult g =
      this->run({"slice", examplePart().string(), "-H", "1", "--printer", "generic-4k", "--pixel", "0.05",
                 "--resolution", "1000x800", "--masks", path("g.exr").string(), "--mirror-x", "--summary",
                 path("g.json").string(), "-q"});
  ASSERT_EQ(g.code(), 0) << g.describe();
  const TinyExrLayer gLayer = readExrWithTinyExr(path("g.exr") / exrLayerFileName("example_part", 0, 7));
  ASSERT_EQ(gLayer.error, "");
  for (const auto& [key, value] :
       std::vector<std::pair<std::string, std::string>>{{"ts:display_pixels_x", "1000"},
                                                        {"ts:display_pixels_y", "800"},
                                                        {"ts:display_width", "50"},
                                                        {"ts:display_height", "40"},
                                                        {"ts:display_mirror_x", "1"},  // --mirror-x
                                                        {"ts:display_mirror_y", "0"}})
    EXPECT_EQ(gLayer.strings.count(key) ? gLayer.strings.at(key) : "none", value) << key;
  const std::string summary = readBytes(path("g.json"));
  EXPECT_NE(summary.find("\"display_mirror_x\": \"1\""), std::string::npos) << summary;
}

// The same settings in a VDB file's metadata, as Debian's vdb_print (OpenVDB's own tool) lists them.
TEST_F(CorrectionsCli, SettingsReachTheVdbFilesMetadata) {
  if (!fs::exists("/usr/bin/vdb_print"))
    GTEST_SKIP() << "vdb_print not installed (Debian package libopenvdb-tools)";
  for (const bool antialias : {false, true}) {
    const fs::path vdb = path(antialias ? "aa.vdb" : "b.vdb");
    std::vector<std::string> args{
        "slice", examplePart().string(), "-H", "1", "--printer", "sl1", "--masks", vdb.string()};
    args.insert(args.end(), {"--exposure-time", "6.5", "--elefant-foot-compensation", "0.1", "--set",
                             "material_correction_z=1.01", "-q"});
    if (antialias) args.push_back("--antialias");
    const RunResult run = this->run(args);
    ASSERT_EQ(run.code(), 0) << run.describe();
    int rc = -1;
    const std::string text = tool_test::runTool("/usr/bin/vdb_print -m '" + vdb.string() + "'", rc);
    ASSERT_EQ(rc, 0) << text;
    for (const std::string& expected : std::vector<std::string>{
             "toposlice:exposure_time: 6.5\n", "toposlice:elefant_foot_compensation: 0.1\n",
             "toposlice:material_correction_z: 1.01\n", "toposlice:printer_model: SL1\n",
             std::string("toposlice:gamma_correction: ") + (antialias ? "1" : "0") + "\n"})
      EXPECT_NE(text.find(expected), std::string::npos) << expected << text;
  }
}

TEST_F(CorrectionsCli, GrowingMasksAreTheSameWithOrWithoutContourOutputs) {
  // Masks rasterize the raw offset loops; with a contour output or a report the polygons are made too.
  // The archive must not depend on it (byte for byte, binary and anti-aliased).
  for (const char* correction : {"0.05", "0.3", "-0.05", "0.05a", "-0.05a"}) {
    const std::string distance(correction, std::strcspn(correction, "a"));
    std::vector<std::string> common{"slice", examplePart().string(),  "-H",     "0.1", "--printer",
                                    "sl1",   "--absolute-correction", distance, "-f",  "-q"};
    if (distance.size() < std::strlen(correction)) common.push_back("--antialias");
    std::vector<std::string> alone = common, withContours = common;
    alone.insert(alone.end(), {"--masks", path("alone.sl1").string()});
    withContours.insert(withContours.end(), {"--masks", path("with.sl1").string(), "-o",
                                             path("c.cli").string(), "--report", path("r.csv").string()});
    const RunResult a = this->run(alone), b = this->run(withContours);
    ASSERT_EQ(a.code(), 0) << a.describe();
    ASSERT_EQ(b.code(), 0) << b.describe();
    EXPECT_TRUE(readBytes(path("alone.sl1")) == readBytes(path("with.sl1"))) << correction;
  }
}

// The elephant foot fades over faded_layers (10 by default: layers 0-8 shrink). Above it the correction
// is nil, and those layers are the layers of the same job without it, byte for byte: masks (each layer's
// PNG in the SL1), contours (each layer of the ASCII CLI) and the report's areas -- on a part alone and
// on a plate.
TEST_F(CorrectionsCli, LayersAboveTheElephantFootAreTheUncorrectedLayers) {
  const auto cliLayers = [](const std::string& text) {
    std::vector<std::string> layers;
    for (std::size_t at = text.find("$$LAYER/"); at != std::string::npos;) {
      const std::size_t next = text.find("$$LAYER/", at + 1);
      layers.push_back(text.substr(at, next == std::string::npos ? std::string::npos : next - at));
      at = next;
    }
    return layers;
  };
  std::vector<std::string> png[2], cli[2], report[2];
  for (int foot = 0; foot < 2; ++foot) {
    const std::string tag = foot ? "foot" : "plain";
    std::vector<std::string> args{"slice",     examplePart().string(),
                                  "-H",        "0.1",
                                  "--printer", "sl1",
                                  "--masks",   path(tag + ".sl1").string(),
                                  "-o",        path(tag + ".cli").string(),
                                  "--report",  path(tag + ".csv").string(),
                                  "-q"};
    if (foot) args.insert(args.end(), {"--elefant-foot-compensation", "0.2"});
    const RunResult r = this->run(args);
    ASSERT_EQ(r.code(), 0) << r.describe();
    for (const std::string& name : tool_test::zipEntryNames(readBytes(path(tag + ".sl1"))))
      if (name.ends_with(".png") && name.find("thumbnail") == std::string::npos)
        png[foot].push_back(tool_test::zipEntry(path(tag + ".sl1"), name.c_str()));
    cli[foot] = cliLayers(readBytes(path(tag + ".cli")));
    std::istringstream lines(readBytes(path(tag + ".csv")));
    for (std::string line; std::getline(lines, line);) report[foot].push_back(line);
  }
  ASSERT_EQ(png[0].size(), png[1].size());
  ASSERT_GT(png[0].size(), 20u);
  ASSERT_EQ(cli[0].size(), png[0].size());
  ASSERT_EQ(report[0].size(), report[1].size());
  EXPECT_NE(png[0][0], png[1][0]);  // the first layer shrinks
  EXPECT_NE(cli[0][8], cli[1][8]);  // and the ninth, by a ninth of the foot
  for (std::size_t k = 9; k < png[0].size(); ++k) {
    EXPECT_TRUE(png[0][k] == png[1][k]) << "mask of layer " << k;
    EXPECT_EQ(cli[0][k], cli[1][k]) << "contours of layer " << k;
    EXPECT_EQ(report[0][k + 1], report[1][k + 1]) << "report row of layer " << k;  // after the header
  }
}

TEST_F(CorrectionsCli, BadSettingsAreNamed) {
  const RunResult typo = this->run(
      {"slice", examplePart().string(), "-o", path("a.cli").string(), "--set", "absolute_corection=0.1"});
  expectOneErrorLine(typo);
  EXPECT_NE(typo.err.find("did you mean 'absolute_correction'"), std::string::npos) << typo.err;
  const RunResult range = this->run(
      {"slice", examplePart().string(), "-o", path("a.cli").string(), "--relative-correction-x", "-1"});
  expectOneErrorLine(range);
  const RunResult masksOnly =
      this->run({"slice", examplePart().string(), "-o", path("a.cli").string(), "--exposure-time", "5"});
  expectOneErrorLine(masksOnly);
  EXPECT_NE(masksOnly.err.find("does nothing"), std::string::npos) << masksOnly.err;
  const RunResult material =
      this->run({"slice", examplePart().string(), "-o", path("a.cli").string(), "--material", "nope"});
  expectOneErrorLine(material);
  EXPECT_NE(material.err.find("--material: unknown material 'nope' (known: default)"), std::string::npos)
      << material.err;
}

// A line break in a setting or a profile's name went into config.ini and prusaslicer.ini as it was, so a
// value could add a line of its own ("SL1S\nexpTime = 77"): refused, in one message line.
TEST_F(CorrectionsCli, ControlCharactersInSettingsAndNamesAreRefused) {
  const std::string part = examplePart().string();
  const std::vector<std::string> sl1{"slice", part, "-H", "0.5", "--masks", path("m.sl1").string(), "-q"};
  const auto refused = [&](std::vector<std::string> extra, const std::string& message) {
    std::vector<std::string> args = sl1;
    args.insert(args.end(), extra.begin(), extra.end());
    const RunResult r = this->run(args);
    expectOneErrorLine(r);
    EXPECT_NE(r.err.find(message), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(path("m.sl1")));
  };
  refused({"--printer", "sl1", "--printer-model", "SL1S\nexpTime = 77"},
          "printer_model 'SL1S\\nexpTime = 77'");
  refused({"--printer", "sl1", "--set", "printer_model=SL1\rx"}, "control characters");
  refused({"--printer", "sl1", "--material", "x\ny"}, "--material: 'x\\ny'");
  tool_test::writeBytes(path("p.json"), "{\"printers\": {\"lab\\nexpTime = 77\": {\"inherits\": \"sl1\"}}}");
  refused({"--profile", path("p.json").string()}, "p.json: printers: the name 'lab\\nexpTime = 77'");
}

// A profile is as strict as a job file: a repeated key was kept silently (the last one), and true was
// taken as the number 1 (exposure_time: true gave 1 s); true/false are for flags.
TEST_F(CorrectionsCli, ProfilesRefuseRepeatedKeysAndTrueForANumber) {
  const std::vector<std::pair<std::string, std::string>> cases{
      {R"({"printers": {"p": {"inherits": "sl1", "light_pwm": 1}, "p": {"light_pwm": 7}}})",
       "p.json: printers.p: duplicate key"},
      {R"({"printers": {"p": {"inherits": "sl1", "light_pwm": 1, "light_pwm": 7}}})",
       "p.json: printers.p.light_pwm: duplicate key"},
      {R"({"printers": {"p": {"inherits": "sl1"}}, "materials": {"m": {"exposure_time": true}}})",
       "exposure_time 'true': expected a number"},
      // A chain of 18 levels is no circle, and a circle is one.
      {[] {
         std::string chain = R"({"printers": {"p": {"inherits": "c1"})";
         for (int i = 1; i < 18; ++i)
           chain += ", \"c" + std::to_string(i) + "\": {\"inherits\": \"c" + std::to_string(i + 1) + "\"}";
         return chain + R"(, "c18": {"inherits": "sl1"}}})";
       }(),
       "'inherits' goes more than 16 levels deep"},
      {R"({"printers": {"p": {"inherits": "q"}, "q": {"inherits": "p"}}})",
       "'inherits' goes round in a circle"},
  };
  for (const auto& [profile, message] : cases) {
    tool_test::writeBytes(path("p.json"), profile);
    const RunResult r = this->run({"slice", examplePart().string(), "--profile", path("p.json").string(),
                                   "--printer", "p", "--masks", path("m.sl1").string(), "-q"});
    expectOneErrorLine(r);
    EXPECT_NE(r.err.find(message), std::string::npos) << r.err;
  }
  tool_test::writeBytes(path("p.json"),
                        R"({"printers": {"p": {"inherits": "sl1", "display_mirror_x": false}}})");
  EXPECT_EQ(this->run({"slice", examplePart().string(), "--profile", path("p.json").string(), "--masks",
                       path("m.sl1").string(), "-q"})
                .code(),
            0);
}

// A batch job's unknown printer or material is refused before its template table is built and saved
// (every variant failed on it afterwards, the table left behind), naming the job file and the key; a
// plate job's likewise.
TEST_F(CorrectionsCli, JobsNameTheirUnknownPrinterOrMaterialBeforeAnyWork) {
  const std::string part = examplePart().string();
  for (const std::string settings : {R"("printer": "sl1x")", R"("printer": "sl1", "material": "resinA")"}) {
    tool_test::writeBytes(path("job.json"),
                          R"({"version": 1, "template": {"model": ")" + part +
                              R"(", "table": "out/t.topo"}, "settings": {"layer_height": 0.5, )" + settings +
                              R"(}, "variants": [{"name": "a", "model": ")" + part +
                              R"(", "masks": "out/a.sl1"}]})");
    const RunResult r = this->run({"batch", path("job.json").string()});
    expectOneErrorLine(r);
    const std::string key = tool_test::contains(settings, "sl1x")
                                ? "settings.printer: unknown printer 'sl1x'"
                                : "settings.material: unknown material 'resinA'";
    EXPECT_NE(r.err.find("job.json: " + key), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(path("out/t.topo"))) << "the table was built and saved first";
  }
  tool_test::writeBytes(path("plate.json"),
                        R"({"version": 1, "printer": "sl9", "settings": {"layer_height": 0.5},
      "parts": [{"name": "p", "model": ")" +
                            part + R"(", "placement": "auto"}], "outputs": {"masks": "p.sl1"}})");
  const RunResult plate = this->run({"plate", path("plate.json").string()});
  expectOneErrorLine(plate);
  EXPECT_NE(plate.err.find("plate.json: printer: unknown printer 'sl9'"), std::string::npos) << plate.err;
}

}  // namespace
}  // namespace toposlice
