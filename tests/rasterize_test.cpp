#include "core/raster/rasterize.h"
#include "core/print/corrections.h"
#include "io/coders/mask_png.h"
#include "io/masks/exr_writer.h"
#include "tests/fixtures/exact_coverage.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <numbers>
#include <numeric>
#include <random>
#include <string>
#include <vector>

namespace toposlice {
namespace {

using Loop = std::vector<Point2d>;

// Counter-clockwise rectangle [x0, x1] x [y0, y1] (an outer loop).
Loop rect(double x0, double y0, double x1, double y1) {
  return {{x0, y0}, {x1, y0}, {x1, y1}, {x0, y1}};
}

Loop reversed(Loop loop) {
  return Loop(loop.rbegin(), loop.rend());
}

// Counter-clockwise regular polygon with n vertices on a circle.
Loop circle(double cx, double cy, double r, int n) {
  Loop loop;
  for (int k = 0; k < n; ++k) {
    const double a = 2.0 * std::numbers::pi * k / n;
    loop.push_back({cx + r * std::cos(a), cy + r * std::sin(a)});
  }
  return loop;
}

LayerContours makeLayer(const std::vector<Loop>& loops, bool closed = true) {
  LayerContours layer;
  uint32_t facet = 0;
  for (const Loop& loop : loops) {
    for (const Point2d& p : loop) layer.addPoint(p, facet++);
    layer.endLoop(closed);
  }
  return layer;
}

PixelGrid makeGrid(double x0, double y0, double pixel, uint32_t width, uint32_t height) {
  PixelGrid grid;
  grid.x0 = x0;
  grid.y0 = y0;
  grid.pixel = pixel;
  grid.width = width;
  grid.height = height;
  return grid;
}

PixelGrid unitGrid(uint32_t width, uint32_t height) {
  return makeGrid(0, 0, 1, width, height);
}

MaskImage binary(std::vector<ContourSet> sets, const PixelGrid& grid) {
  MaskImage out;
  RasterScratch scratch;
  rasterizeBinary(sets, grid, out, scratch);
  return out;
}

MaskImage coverage(std::vector<ContourSet> sets, const PixelGrid& grid) {
  MaskImage out;
  RasterScratch scratch;
  rasterizeCoverage(sets, grid, out, scratch);
  return out;
}

// Every pixel of m is the rounding of 255 * the exact covered fraction (oracle: exact_coverage.h), up to
// floating-point rounding at a half; also checks the lit extents and the value sum.
void expectExactCoverage(const std::vector<ContourSet>& sets, const PixelGrid& grid, const MaskImage& m,
                         const std::string& what) {
  const std::vector<double> area = fixtures::exactCoverage(sets, grid);
  for (uint32_t j = 0; j < grid.height; ++j) {
    for (uint32_t i = 0; i < grid.width; ++i) {
      const double expected = 255.0 * area[std::size_t{j} * grid.width + i];
      const uint32_t mi = grid.mirrorX ? grid.width - 1 - i : i, mj = grid.mirrorY ? grid.height - 1 - j : j;
      ASSERT_LE(std::abs(m.pixels[std::size_t{mj} * grid.width + mi] - expected), 0.5 + 1e-6)
          << what << " pixel " << i << "," << j;
    }
  }
}

uint8_t at(const MaskImage& m, uint32_t i, uint32_t j) {
  return m.pixels[static_cast<std::size_t>(j) * m.width + i];
}

// Every pixel is 255 where `lit(i, j)` and 0 elsewhere.
void expectPattern(const MaskImage& m, const std::function<bool(uint32_t, uint32_t)>& lit) {
  for (uint32_t j = 0; j < m.height; ++j) {
    for (uint32_t i = 0; i < m.width; ++i) {
      ASSERT_EQ(at(m, i, j), lit(i, j) ? 255 : 0) << "pixel (" << i << ", " << j << ")";
    }
  }
}

// The binary rasterizer's runs (mask_image.h) describe its pixels exactly: in increasing x, maximal,
// 255 inside and 0 elsewhere; the extents are the first and last run's ends.
void expectRunsDescribePixels(const MaskImage& m) {
  ASSERT_TRUE(m.hasRuns());
  for (uint32_t r = 0; r < m.height; ++r) {
    std::vector<uint8_t> expected(m.width, 0);
    const uint32_t first = m.rowRuns[2 * r], count = m.rowRuns[2 * r + 1];
    for (uint32_t k = first; k < first + count; ++k) {
      const uint32_t a = m.runs[2 * k], b = m.runs[2 * k + 1];
      ASSERT_LT(a, b) << "row " << r;
      ASSERT_LE(b, m.width) << "row " << r;
      if (k > first) {
        ASSERT_GT(a, m.runs[2 * k - 1]) << "row " << r << ": runs touch or are out of order";
      }
      std::fill(expected.begin() + a, expected.begin() + b, uint8_t{255});
    }
    ASSERT_TRUE(std::equal(expected.begin(), expected.end(), m.pixels.begin() + size_t{r} * m.width))
        << "row " << r;
    if (count > 0) {
      EXPECT_EQ(m.litBegin[r], m.runs[2 * first]) << "row " << r;
      EXPECT_EQ(m.litEnd[r], m.runs[2 * (first + count) - 1]) << "row " << r;
    } else {
      EXPECT_GE(m.litBegin[r], m.litEnd[r]) << "row " << r;
    }
  }
}

std::size_t litInRow(const MaskImage& m, uint32_t j) {
  std::size_t n = 0;
  for (uint32_t i = 0; i < m.width; ++i) n += at(m, i, j) != 0 ? 1 : 0;
  return n;
}

TEST(RasterBinary, SquareLightsExactlyThePixelCentresInside) {
  const LayerContours layer = makeLayer({rect(2.2, 3.1, 7.8, 5.9)});
  const MaskImage m = binary({{&layer, 1}}, unitGrid(10, 10));
  ASSERT_EQ(m.width, 10u);
  ASSERT_EQ(m.height, 10u);
  ASSERT_EQ(m.pixels.size(), 100u);
  EXPECT_EQ(countLitPixels(m), 18u);  // centres 2.5..7.5 x 3.5..5.5
  expectPattern(m, [](uint32_t i, uint32_t j) { return i >= 2 && i <= 7 && j >= 3 && j <= 5; });
  EXPECT_DOUBLE_EQ(maskArea(m, 1.0), 18.0);
}

TEST(RasterBinary, OffsetGridWithSmallPixels) {
  // Centres x = 10 + (i + 1/2) 0.25, y = -5 + (j + 1/2) 0.25: i = 1..3 and j = 2..3 are inside.
  const LayerContours layer = makeLayer({rect(10.3, -4.6, 11.1, -4.0)});
  const MaskImage m = binary({{&layer, 1}}, makeGrid(10, -5, 0.25, 8, 8));
  EXPECT_EQ(countLitPixels(m), 6u);
  expectPattern(m, [](uint32_t i, uint32_t j) { return i >= 1 && i <= 3 && j >= 2 && j <= 3; });
  EXPECT_DOUBLE_EQ(maskArea(m, 0.25), 6 * 0.0625);
}

TEST(RasterBinary, ClockwiseHoleIsEmpty) {
  const LayerContours layer = makeLayer({rect(0, 0, 10, 10), reversed(rect(3, 3, 6, 6))});
  const MaskImage m = binary({{&layer, 1}}, unitGrid(12, 12));
  EXPECT_EQ(countLitPixels(m), 91u);
  expectPattern(m, [](uint32_t i, uint32_t j) {
    const bool outer = i < 10 && j < 10;
    const bool hole = i >= 3 && i < 6 && j >= 3 && j < 6;
    return outer && !hole;
  });
}

TEST(RasterBinary, OverlappingOuterLoopsStaySolid) {
  const LayerContours both = makeLayer({rect(1, 1, 6, 6), rect(4, 4, 9, 9)});
  const MaskImage m = binary({{&both, 1}}, unitGrid(10, 10));
  EXPECT_EQ(countLitPixels(m), 46u);  // 25 + 25 - 4: the union
  EXPECT_EQ(at(m, 4, 4), 255);        // winding 2
  EXPECT_EQ(at(m, 5, 5), 255);
  EXPECT_EQ(at(m, 2, 7), 0);

  // The same squares as two sets (model and add-on) give the same bytes.
  const LayerContours a = makeLayer({rect(1, 1, 6, 6)});
  const LayerContours b = makeLayer({rect(4, 4, 9, 9)});
  EXPECT_EQ(binary({{&a, 1}, {&b, 1}}, unitGrid(10, 10)).pixels, m.pixels);
}

TEST(RasterBinary, RemovalSetPunchesHole) {
  const LayerContours model = makeLayer({rect(0, 0, 10, 10)});
  const LayerContours removal = makeLayer({rect(3, 3, 6, 6)});  // a feature mesh's CCW contour
  const MaskImage m = binary({{&model, 1}, {&removal, -1}}, unitGrid(12, 12));
  EXPECT_EQ(countLitPixels(m), 91u);
  const LayerContours holed = makeLayer({rect(0, 0, 10, 10), reversed(rect(3, 3, 6, 6))});
  EXPECT_EQ(m.pixels, binary({{&holed, 1}}, unitGrid(12, 12)).pixels);
}

TEST(RasterBinary, RemovalOutsideModelDoesNothing) {
  const LayerContours model = makeLayer({rect(0, 0, 5, 5)});
  const LayerContours away = makeLayer({rect(6, 6, 9, 9)});
  const MaskImage m = binary({{&model, 1}, {&away, -1}}, unitGrid(10, 10));
  EXPECT_EQ(countLitPixels(m), 25u);  // winding -1 is not solid
  EXPECT_EQ(at(m, 7, 7), 0);

  // Abutting on the left: the count jumps from -1 to +1 at x = 2 (both crossings at once).
  const LayerContours small = makeLayer({rect(2, 1, 6, 5)});
  const LayerContours beside = makeLayer({rect(-3, 1, 2, 5)});
  const MaskImage smallAlone = binary({{&small, 1}}, unitGrid(10, 10));
  EXPECT_EQ(countLitPixels(smallAlone), 16u);
  EXPECT_EQ(binary({{&small, 1}, {&beside, -1}}, unitGrid(10, 10)).pixels, smallAlone.pixels);
  EXPECT_EQ(coverage({{&small, 1}, {&beside, -1}}, unitGrid(10, 10)).pixels, smallAlone.pixels);

  // Partly overlapping: only the inside part is subtracted, the outside part stays empty.
  const LayerContours straddling = makeLayer({rect(3, 3, 9, 9)});
  const MaskImage p = binary({{&model, 1}, {&straddling, -1}}, unitGrid(10, 10));
  EXPECT_EQ(countLitPixels(p), 21u);
  expectPattern(p, [](uint32_t i, uint32_t j) { return i < 5 && j < 5 && !(i >= 3 && j >= 3); });
}

TEST(RasterBinary, RemovalBelowAddOnOverlapLeavesWindingOne) {
  // Model x in [0,6], add-on [3,9], removal [2,8]: counts 1, 0, 1 (=1+1-1), 0, 1 along x.
  const LayerContours model = makeLayer({rect(0, 0, 6, 6)});
  const LayerContours addOn = makeLayer({rect(3, 0, 9, 6)});
  const LayerContours removal = makeLayer({rect(2, 0, 8, 6)});
  const MaskImage m = binary({{&model, 1}, {&addOn, 1}, {&removal, -1}}, unitGrid(10, 6));
  EXPECT_EQ(countLitPixels(m), 36u);
  expectPattern(m, [](uint32_t i, uint32_t) { return i < 2 || (i >= 3 && i < 6) || i == 8; });
}

TEST(RasterBinary, RemovalEqualToModelCancelsExactly) {
  // Slanted edges: crossings are interpolated from each edge's lower end, so reversed edges match.
  const LayerContours model = makeLayer({circle(4.37, 5.11, 3.3, 37)});
  const MaskImage alone = binary({{&model, 1}}, makeGrid(0, 0, 0.1, 100, 100));
  EXPECT_GT(countLitPixels(alone), 3000u);
  EXPECT_EQ(countLitPixels(binary({{&model, 1}, {&model, -1}}, makeGrid(0, 0, 0.1, 100, 100))), 0u);
  EXPECT_EQ(countLitPixels(coverage({{&model, 1}, {&model, -1}}, makeGrid(0, 0, 0.1, 100, 100))), 0u);
}

TEST(RasterBinary, ClockwiseOnlyLoopIsEmpty) {
  const LayerContours layer = makeLayer({reversed(rect(1, 1, 8, 8)), reversed(circle(5, 5, 2, 20))});
  EXPECT_EQ(countLitPixels(binary({{&layer, 1}}, unitGrid(10, 10))), 0u);
  EXPECT_EQ(countLitPixels(coverage({{&layer, 1}}, unitGrid(10, 10))), 0u);
}

TEST(RasterBinary, OpenAndNonFiniteLoopsAreSkippedAndCounted) {
  const LayerContours open = makeLayer({rect(1, 1, 8, 8)}, false);
  EXPECT_EQ(countLitPixels(binary({{&open, 1}}, unitGrid(10, 10))), 0u);

  LayerContours mixed =
      makeLayer({rect(1, 1, 3, 3), {{4, 4}, {9, 4}, {9, std::numeric_limits<double>::quiet_NaN()}}});
  mixed.addPoint({5, 5}, 99);
  mixed.addPoint({6, 5}, 100);
  mixed.endLoop(false);
  const std::vector<ContourSet> sets = {{&open, 1}, {&mixed, 1}};
  EXPECT_EQ(countSkippedLoops(sets), 3u);
  const MaskImage m = binary(sets, unitGrid(10, 10));
  EXPECT_EQ(countLitPixels(m), 4u);  // only the valid square
  expectPattern(m, [](uint32_t i, uint32_t j) { return i >= 1 && i < 3 && j >= 1 && j < 3; });
}

TEST(RasterBinary, PixelCentresOnEdgesFollowHalfOpenRule) {
  // Left and bottom boundaries include a centre lying on them, right and top boundaries exclude it.
  const LayerContours square = makeLayer({rect(0.5, 0.5, 3.5, 2.5)});
  const MaskImage m = binary({{&square, 1}}, unitGrid(6, 5));
  EXPECT_EQ(countLitPixels(m), 6u);
  expectPattern(m, [](uint32_t i, uint32_t j) { return i <= 2 && j <= 1; });

  // Two solids sharing an edge through pixel centres light each of those centres exactly once.
  const LayerContours left = makeLayer({rect(0.5, 0.5, 2.5, 2.5)});
  const LayerContours right = makeLayer({rect(2.5, 0.5, 4.5, 2.5)});
  EXPECT_EQ(countLitPixels(binary({{&left, 1}}, unitGrid(6, 5))), 4u);
  EXPECT_EQ(countLitPixels(binary({{&right, 1}}, unitGrid(6, 5))), 4u);
  const LayerContours whole = makeLayer({rect(0.5, 0.5, 4.5, 2.5)});
  EXPECT_EQ(binary({{&left, 1}, {&right, 1}}, unitGrid(6, 5)).pixels,
            binary({{&whole, 1}}, unitGrid(6, 5)).pixels);

  // A slanted right boundary x + y = 5 through centres (i + j = 4): those centres are outside.
  const LayerContours triangle = makeLayer({{{0.5, 0.5}, {4.5, 0.5}, {0.5, 4.5}}});
  const MaskImage t = binary({{&triangle, 1}}, unitGrid(6, 6));
  EXPECT_EQ(countLitPixels(t), 10u);  // 4 + 3 + 2 + 1
  expectPattern(t, [](uint32_t i, uint32_t j) { return i + j < 4; });
}

TEST(RasterBinary, VertexOnRowCentreCountedOnce) {
  // Diamond with all four vertices on pixel centres: the side vertices are passed through (counted
  // once), the bottom one is a minimum (two crossings at the same x, empty run), the top one a maximum.
  const LayerContours diamond = makeLayer({{{5.5, 1.5}, {9.5, 5.5}, {5.5, 9.5}, {1.5, 5.5}}});
  const MaskImage m = binary({{&diamond, 1}}, unitGrid(11, 11));
  const std::size_t expected[11] = {0, 0, 2, 4, 6, 8, 6, 4, 2, 0, 0};
  for (uint32_t j = 0; j < 11; ++j) EXPECT_EQ(litInRow(m, j), expected[j]) << "row " << j;
  EXPECT_EQ(countLitPixels(m), 32u);  // the diamond's area
  EXPECT_EQ(at(m, 1, 5), 255);        // centre on the left vertex: inside
  EXPECT_EQ(at(m, 9, 5), 0);          // centre on the right vertex: outside

  // A notch whose lowest vertex (5, 5.5) lies on a row centre: the two edges meeting there cancel
  // and row 5 stays whole. Area = 8 x 7 - 10 = 46.
  const LayerContours notch = makeLayer({{{1, 1}, {9, 1}, {9, 8}, {5, 5.5}, {1, 8}}});
  const MaskImage n = binary({{&notch, 1}}, unitGrid(10, 10));
  const std::size_t notchRows[10] = {0, 8, 8, 8, 8, 8, 4, 2, 0, 0};
  for (uint32_t j = 0; j < 10; ++j) EXPECT_EQ(litInRow(n, j), notchRows[j]) << "row " << j;
  EXPECT_EQ(countLitPixels(n), 46u);
}

TEST(RasterBinary, ContoursOutsideGridAreClipped) {
  const PixelGrid grid = unitGrid(10, 10);
  const LayerContours huge = makeLayer({rect(-100, -100, 100, 100)});
  EXPECT_EQ(countLitPixels(binary({{&huge, 1}}, grid)), 100u);
  const LayerContours partly = makeLayer({rect(-3, -2, 4, 30)});
  const MaskImage p = binary({{&partly, 1}}, grid);
  EXPECT_EQ(countLitPixels(p), 40u);
  expectPattern(p, [](uint32_t i, uint32_t) { return i < 4; });
  const LayerContours away = makeLayer({rect(20, 20, 30, 30), rect(-30, 2, -20, 5)});
  EXPECT_EQ(countLitPixels(binary({{&away, 1}}, grid)), 0u);
  const LayerContours band = makeLayer({rect(-1e30, 2, 1e30, 3)});
  const MaskImage b = binary({{&band, 1}}, grid);
  EXPECT_EQ(countLitPixels(b), 10u);
  expectPattern(b, [](uint32_t, uint32_t j) { return j == 2; });
  // A hole larger than the grid around a model larger than the grid: nothing.
  const LayerContours frame = makeLayer({rect(-50, -50, 50, 50), reversed(rect(-20, -20, 20, 20))});
  EXPECT_EQ(countLitPixels(binary({{&frame, 1}}, grid)), 0u);
  EXPECT_EQ(countLitPixels(coverage({{&frame, 1}}, grid)), 0u);
}

TEST(RasterBinary, MirrorFlipsAtWriteTime) {
  // An L shape in a non-square grid, off the pixel edges: no symmetry to hide a wrong flip, and the
  // coverage mask has fractional pixels on every side.
  const LayerContours l =
      makeLayer({{{0.2, 0.1}, {3.3, 0.1}, {3.3, 1.4}, {1.2, 1.4}, {1.2, 4.3}, {0.2, 4.3}}});
  for (bool anti : {false, true}) {
    PixelGrid grid = makeGrid(0, 0, 1, 7, 5);
    const std::vector<ContourSet> sets = {{&l, 1}};
    const MaskImage plain = anti ? coverage(sets, grid) : binary(sets, grid);
    EXPECT_EQ(countLitPixels(plain), anti ? 14u : 6u);
    for (int mode = 1; mode < 4; ++mode) {
      grid.mirrorX = (mode & 1) != 0;
      grid.mirrorY = (mode & 2) != 0;
      const MaskImage m = anti ? coverage(sets, grid) : binary(sets, grid);
      ASSERT_EQ(m.width, 7u);
      ASSERT_EQ(m.height, 5u);
      for (uint32_t j = 0; j < 5; ++j) {
        for (uint32_t i = 0; i < 7; ++i) {
          const uint32_t mi = grid.mirrorX ? 6 - i : i, mj = grid.mirrorY ? 4 - j : j;
          ASSERT_EQ(at(m, mi, mj), at(plain, i, j)) << "mode " << mode << " pixel " << i << "," << j;
        }
      }
    }
  }
}

TEST(RasterBinary, ScratchReuseGivesSameBytes) {
  const LayerContours a = makeLayer({circle(3.2, 2.9, 2.1, 300), reversed(circle(3.0, 3.1, 0.7, 50))});
  const LayerContours b = makeLayer({rect(0.3, 0.2, 5.7, 1.9), circle(1, 5, 0.9, 40)});
  const PixelGrid grid = makeGrid(0, 0, 0.05, 130, 140);
  RasterScratch scratch;
  MaskImage first, other, again;
  rasterizeBinary(std::vector<ContourSet>{{&a, 1}}, grid, first, scratch);
  rasterizeBinary(std::vector<ContourSet>{{&b, 1}}, grid, other, scratch);
  again = other;  // reused output buffer, fully overwritten
  rasterizeBinary(std::vector<ContourSet>{{&a, 1}}, grid, again, scratch);
  EXPECT_EQ(again.pixels, first.pixels);
  EXPECT_NE(other.pixels, first.pixels);

  rasterizeCoverage(std::vector<ContourSet>{{&a, 1}}, grid, first, scratch);
  rasterizeCoverage(std::vector<ContourSet>{{&b, 1}}, grid, other, scratch);
  again = other;
  rasterizeCoverage(std::vector<ContourSet>{{&a, 1}}, grid, again, scratch);
  EXPECT_EQ(again.pixels, first.pixels);
}

TEST(RasterBinary, EmptyGridAndEmptySets) {
  const LayerContours layer = makeLayer({rect(0, 0, 5, 5)});
  MaskImage m;
  m.pixels.assign(7, 1);
  RasterScratch scratch;
  rasterizeBinary(std::vector<ContourSet>{{&layer, 1}}, unitGrid(0, 4), m, scratch);
  EXPECT_EQ(m.width, 0u);
  EXPECT_EQ(m.height, 4u);
  EXPECT_TRUE(m.pixels.empty());
  rasterizeBinary(std::span<const ContourSet>(), unitGrid(3, 4), m, scratch);
  EXPECT_EQ(m.pixels, std::vector<uint8_t>(12, 0));
}

// Reference: the winding count at (x, y) from every edge of every set, with the same half-open rule in y,
// the same crossing interpolation (from the lower end) and a crossing at x counted as passed (x <= px).
int bruteWinding(const std::vector<ContourSet>& sets, double px, double py) {
  int w = 0;
  for (const ContourSet& set : sets) {
    for (std::size_t l = 0; l < set.layer->loopCount(); ++l) {
      const std::span<const Point2d> loop = set.layer->loopPoints(l);
      for (std::size_t i = 0; i < loop.size(); ++i) {
        const Point2d a = loop[i], b = loop[(i + 1) % loop.size()];
        if ((a.y <= py) == (b.y <= py)) continue;
        const Point2d lo = a.y < b.y ? a : b, hi = a.y < b.y ? b : a;
        const double x = lo.x + (py - lo.y) * ((hi.x - lo.x) / (hi.y - lo.y));
        if (x <= px) w += (a.y < b.y ? -1 : 1) * set.sign;
      }
    }
  }
  return w;
}

// Random self-intersecting loops on a quarter-pixel lattice (many vertices and crossings exactly on
// pixel centres), in three sets with signs +1, +1, -1, some loops reaching outside the grid.
std::vector<LayerContours> randomLayers(std::mt19937& rng) {
  std::uniform_int_distribution<int> coord(-8, 4 * 26 + 8), count(3, 9);
  std::vector<LayerContours> layers(3);
  for (LayerContours& layer : layers) {
    const int loops = count(rng) / 3;
    std::vector<Loop> ls;
    for (int l = 0; l < loops; ++l) {
      Loop loop;
      const int n = count(rng);
      for (int k = 0; k < n; ++k) loop.push_back({0.25 * coord(rng), 0.25 * coord(rng)});
      ls.push_back(loop);
    }
    layer = makeLayer(ls);
  }
  return layers;
}

// Every pixel of the binary mask m of `sets` on a unit grid is the brute-force winding's, and m's runs
// describe its pixels.
void expectBruteForcePixels(const std::vector<ContourSet>& sets, const PixelGrid& grid, const MaskImage& m,
                            int trial) {
  for (uint32_t j = 0; j < grid.height; ++j) {
    for (uint32_t i = 0; i < grid.width; ++i) {
      const bool solid = bruteWinding(sets, i + 0.5, j + 0.5) > 0;
      ASSERT_EQ(at(m, i, j), solid ? 255 : 0) << "trial " << trial << " pixel " << i << "," << j;
    }
  }
  expectRunsDescribePixels(m);
}

TEST(RasterBinary, MatchesBruteForceWindingOnRandomLoops) {
  std::mt19937 rng(12345);
  const PixelGrid grid = unitGrid(24, 22);
  RasterScratch scratch;
  MaskImage m;
  std::size_t litTotal = 0;
  for (int trial = 0; trial < 200; ++trial) {
    const std::vector<LayerContours> layers = randomLayers(rng);
    const std::vector<ContourSet> sets = {{&layers[0], 1}, {&layers[1], 1}, {&layers[2], -1}};
    rasterizeBinary(sets, grid, m, scratch);
    expectBruteForcePixels(sets, grid, m, trial);
    if (HasFatalFailure()) return;
    litTotal += countLitPixels(m);
  }
  EXPECT_GT(litTotal, 200u * 24 * 22 / 10);  // the fixtures are not trivially empty
}

TEST(RasterBinary, ManyEdgesStartingOnOneLineMatchBruteForce) {
  // Rows where more than 32 edges start at once (the parts of a plate): they are sorted apart and
  // merged into the active list. Slanted, overlapping, reversed and coincident triangles, starting on
  // three sample lines, against the brute-force winding at every pixel centre.
  std::mt19937 rng(314);
  std::uniform_real_distribution<double> x(0.0, 60.0), dx(-3.0, 3.0), top(4.0, 19.0);
  const PixelGrid grid = unitGrid(60, 20);
  RasterScratch scratch;
  MaskImage m;
  for (int trial = 0; trial < 20; ++trial) {
    std::vector<Loop> loops;
    for (int t = 0; t < 60; ++t) {
      const double y0 = 0.2 + (t % 3) * 1.0, x0 = x(rng), w = 0.3 + 2.0 * (t % 5) / 4.0;
      Loop tri{{x0, y0}, {x0 + w, y0}, {x0 + dx(rng), top(rng)}};
      loops.push_back(t % 7 == 3 ? reversed(tri) : tri);
      if (t % 11 == 5) loops.push_back(tri);  // coincident edges
    }
    const LayerContours layer = makeLayer(loops);
    const std::vector<ContourSet> sets = {{&layer, 1}};
    rasterizeBinary(sets, grid, m, scratch);
    expectBruteForcePixels(sets, grid, m, trial);
    if (HasFatalFailure()) return;
  }
}

TEST(RasterBinary, LongChainsOfShortEdgesMatchBruteForce) {
  // Finely sampled outlines like the slices of a mesh at 1 um: hundreds of edges per loop, each
  // crossing at most a line or two, so that an edge ending on a sample line hands its place in the
  // active list to the next edge of its chain. Wobbly rings (outer loop and reversed hole), with
  // zig-zags whose teeth start and end between and on sample lines, some vertices exactly on sample
  // lines, and rings overlapping each other, against the brute-force winding at every pixel centre.
  std::mt19937 rng(2718);
  std::uniform_real_distribution<double> wobble(-0.9, 0.9), centre(12.0, 28.0);
  const PixelGrid grid = unitGrid(40, 36);
  RasterScratch scratch;
  MaskImage m;
  for (int trial = 0; trial < 40; ++trial) {
    std::vector<Loop> loops;
    for (int ring = 0; ring < 3; ++ring) {
      const double cx = centre(rng), cy = centre(rng), r = 6.0 + 3.0 * ring;
      const int n = 200 + 150 * ring;
      Loop outer, inner;
      for (int k = 0; k < n; ++k) {
        const double t = 2.0 * std::numbers::pi * k / n;
        const double tooth = (k % 2 == 0 ? 0.35 : -0.35) * (trial % 3);  // zig-zag across the lines
        Point2d p{cx + (r + wobble(rng) * 0.3 + tooth) * std::cos(t),
                  cy + (r + wobble(rng) * 0.3) * std::sin(t)};
        if (k % 9 == 0) p.y = std::round(p.y - 0.5) + 0.5;  // on a sample line
        outer.push_back(p);
        inner.push_back({cx + 0.5 * (p.x - cx), cy + 0.5 * (p.y - cy)});
      }
      loops.push_back(outer);
      if (ring != 1) loops.push_back(reversed(inner));
    }
    const LayerContours layer = makeLayer(loops);
    const std::vector<ContourSet> sets = {{&layer, 1}};
    rasterizeBinary(sets, grid, m, scratch);
    expectBruteForcePixels(sets, grid, m, trial);
    if (HasFatalFailure()) return;
  }
}
TEST(RasterBinary, RunsOfMirroredAndPortraitGridsDescribeTheirPixels) {
  // Rows of several runs (random self-intersecting loops), mirrored and transposed grids, one image and
  // scratch reused throughout (the next layer is cleared from the previous layer's runs): every mask is
  // the flip of the plain one, pixel for pixel, and its runs describe it.
  std::mt19937 rng(99);
  RasterScratch scratch;
  MaskImage m;
  std::size_t multiRunRows = 0;
  for (int trial = 0; trial < 200; ++trial) {
    const std::vector<LayerContours> layers = randomLayers(rng);
    const std::vector<ContourSet> sets = {{&layers[0], 1}, {&layers[1], 1}, {&layers[2], -1}};
    PixelGrid grid = makeGrid(0.1, -0.2, 0.9, 26, 23);
    grid.transposed = trial % 2 == 1;
    const MaskImage plain = binary(sets, grid);
    grid.mirrorX = trial % 3 != 0;
    grid.mirrorY = trial % 4 >= 2;
    rasterizeBinary(sets, grid, m, scratch);
    expectRunsDescribePixels(m);
    for (uint32_t j = 0; j < grid.height; ++j) {
      multiRunRows += m.rowRuns[2 * j + 1] > 1 ? 1 : 0;
      for (uint32_t i = 0; i < grid.width; ++i) {
        const uint32_t mi = grid.mirrorX ? grid.width - 1 - i : i,
                       mj = grid.mirrorY ? grid.height - 1 - j : j;
        ASSERT_EQ(at(m, mi, mj), at(plain, i, j)) << "trial " << trial << " pixel " << i << "," << j;
      }
    }
  }
  EXPECT_GT(multiRunRows, 500u);
}

// Layer k of a slowly changing stack, for the tests of layers drawn into the previous layer's image: a
// disc drifting in x and shrinking, with a hole, and a bar that comes and goes (turned round, a hole
// alone, from layer 56 on); every 17th layer empty.
LayerContours driftingLayer(int k) {
  const double t = 0.013 * k;
  std::vector<Loop> loops = {circle(3.0 + t, 3.1, 1.9 - 0.5 * t, 120), reversed(circle(3.1, 3.0, 0.6, 40))};
  if (k % 9 < 5) loops.push_back(rect(0.4, 4.6 + 0.02 * k, 2.2 + t, 5.7));
  return makeLayer(k % 17 == 16 ? std::vector<Loop>{} : loops);
}

// The grid of layer k of that stack: portrait for layers 40-79, mirrored in x and in y by stretches.
PixelGrid driftingGrid(int k, double pixel, uint32_t width, uint32_t height) {
  PixelGrid grid = makeGrid(0.05, -0.03, pixel, width, height);
  grid.transposed = k / 40 == 1;
  grid.mirrorX = k / 20 % 2 == 1;
  grid.mirrorY = k / 30 % 2 == 1;
  return grid;
}

TEST(RasterBinary, ConsecutiveLayersInOneImageEqualFreshImages) {
  // A binary mask rasterized into the image that holds the previous layer's mask rewrites only the rows
  // whose runs changed. Slowly moving shapes (most rows repeat, some change, some go dark, whole layers
  // go empty), mirrored and portrait grids, an anti-aliased layer and a grid of another size between
  // them: every mask equals the same layer rasterized into a fresh image, pixel for pixel, with the same
  // runs.
  RasterScratch scratch;
  MaskImage m;
  std::size_t repeatedRows = 0, changedRows = 0;
  MaskImage previous;  // the last binary mask, for counting repeated rows
  for (int k = 0; k < 120; ++k) {
    const LayerContours layer = driftingLayer(k);
    const std::vector<ContourSet> sets = {{&layer, 1}};
    const PixelGrid grid = driftingGrid(k, 0.1, 66, 62);
    if (k % 23 == 22) {  // something else in between: coverage, then a smaller grid
      MaskImage fresh;
      rasterizeCoverage(sets, grid, m, scratch);
      rasterizeCoverage(sets, grid, fresh, scratch);
      ASSERT_EQ(m.pixels, fresh.pixels) << "layer " << k;
      rasterizeBinary(sets, makeGrid(0, 0, 0.2, 33, 31), m, scratch);
      previous = MaskImage{};
      continue;
    }
    rasterizeBinary(sets, grid, m, scratch);
    const MaskImage fresh = binary(sets, grid);
    ASSERT_EQ(m.pixels, fresh.pixels) << "layer " << k;
    ASSERT_EQ(m.runs, fresh.runs) << "layer " << k;
    ASSERT_EQ(m.rowRuns, fresh.rowRuns) << "layer " << k;
    ASSERT_EQ(m.litBegin, fresh.litBegin) << "layer " << k;
    ASSERT_EQ(m.litEnd, fresh.litEnd) << "layer " << k;
    expectRunsDescribePixels(m);
    if (previous.rowRuns.size() == m.rowRuns.size()) {
      for (uint32_t r = 0; r < grid.height; ++r) {
        if (m.rowRuns[2 * r + 1] == 0) continue;
        const auto runsOf = [r](const MaskImage& image) {
          const auto begin = image.runs.begin() + 2 * std::ptrdiff_t{image.rowRuns[2 * r]};
          return std::vector<uint32_t>(begin, begin + 2 * std::ptrdiff_t{image.rowRuns[2 * r + 1]});
        };
        (runsOf(m) == runsOf(previous) ? repeatedRows : changedRows) += 1;
      }
    }
    previous = m;
  }
  EXPECT_GT(repeatedRows, 1000u);  // the fixture exercises both kinds of rows
  EXPECT_GT(changedRows, 100u);
}

TEST(RasterCoverage, MatchesExactClippingOnRandomLoops) {
  // Self-intersecting loops in three sets (+1, +1, -1): vertices inside and on pixel borders, crossings,
  // coincident edges, winding counts from -2 to 3; mirrored and not, on a reused image and scratch.
  std::mt19937 rng(777);
  RasterScratch scratch;
  MaskImage m;
  for (int trial = 0; trial < 60; ++trial) {
    PixelGrid grid = unitGrid(24, 22);
    grid.mirrorX = trial % 2 == 1;
    grid.mirrorY = trial % 3 == 1;
    const std::vector<LayerContours> layers = randomLayers(rng);
    const std::vector<ContourSet> sets = {{&layers[0], 1}, {&layers[1], 1}, {&layers[2], -1}};
    uint64_t sum = 0;
    rasterizeCoverage(sets, grid, m, scratch, &sum);
    expectExactCoverage(sets, grid, m, "trial " + std::to_string(trial));
    uint64_t expectedSum = 0;
    for (uint8_t v : m.pixels) expectedSum += v;
    ASSERT_EQ(sum, expectedSum) << "trial " << trial;
  }
}

TEST(RasterCoverage, RandomOffGridLoopsMatchExactClipping) {
  // Vertices anywhere (not on a lattice), small pixels: slanted edges crossing many pixels.
  std::mt19937 rng(4242);
  std::uniform_real_distribution<double> coord(-0.3, 2.3);
  RasterScratch scratch;
  MaskImage m;
  for (int trial = 0; trial < 60; ++trial) {
    const PixelGrid grid = makeGrid(0.013, -0.021, 0.07, 30, 29);
    std::vector<Loop> loops(1 + trial % 3);
    for (Loop& loop : loops)
      for (int k = 0; k < 3 + trial % 7; ++k) loop.push_back({coord(rng), coord(rng)});
    const LayerContours layer = makeLayer(loops);
    const std::vector<ContourSet> sets = {{&layer, 1}};
    rasterizeCoverage(sets, grid, m, scratch);
    expectExactCoverage(sets, grid, m, "trial " + std::to_string(trial));
  }
}

// Rasterizes `sets` twice, by clusters where they apply and with every row on the banded path, and
// expects the same bytes, extents and value sums, except that a pixel whose exact 255 * area is a half
// (to 1e-9) may round either way (the two paths add the same areas in a different order where a row's
// cluster is not one chain); both must match the exact oracle. Returns the clustered scratch's row
// counts.
RasterScratch expectClustersEqualBanded(const std::vector<ContourSet>& sets, const PixelGrid& grid,
                                        const std::string& what) {
  RasterScratch clustered, banded;
  banded.alwaysBanded = true;
  MaskImage a, b;
  uint64_t sumA = 0, sumB = 0;
  rasterizeCoverage(sets, grid, a, clustered, &sumA);
  rasterizeCoverage(sets, grid, b, banded, &sumB);
  EXPECT_EQ(banded.clusteredRows, 0u) << what;
  const std::vector<double> area = fixtures::exactCoverage(sets, grid);
  std::size_t ties = 0;
  for (uint32_t j = 0; j < grid.height; ++j) {
    for (uint32_t i = 0; i < grid.width; ++i) {
      const uint32_t mi = grid.mirrorX ? grid.width - 1 - i : i, mj = grid.mirrorY ? grid.height - 1 - j : j;
      const std::size_t at = std::size_t{mj} * grid.width + mi;
      if (a.pixels[at] == b.pixels[at]) continue;
      const double scaled = 255.0 * area[std::size_t{j} * grid.width + i];
      EXPECT_NEAR(std::abs(scaled - std::floor(scaled) - 0.5), 0.0, 1e-9)
          << what << " pixel " << i << "," << j;
      EXPECT_EQ(std::abs(a.pixels[at] - b.pixels[at]), 1) << what << " pixel " << i << "," << j;
      ++ties;
    }
  }
  if (ties == 0) {
    EXPECT_EQ(a.litBegin, b.litBegin) << what;
    EXPECT_EQ(a.litEnd, b.litEnd) << what;
    EXPECT_EQ(sumA, sumB) << what;
  }
  EXPECT_EQ(sumA, std::accumulate(a.pixels.begin(), a.pixels.end(), uint64_t{0})) << what;
  expectExactCoverage(sets, grid, a, what);
  return clustered;
}

// A star-shaped loop around (cx, cy): n vertices at increasing angles, radius r plus a wiggle of
// amplitude `wiggle` (random per vertex), so the outline turns up and down inside pixel rows as the
// aligner's 1 um slices do. Counter-clockwise.
Loop wigglyLoop(std::mt19937& rng, double cx, double cy, double r, double wiggle, int n) {
  std::uniform_real_distribution<double> noise(-wiggle, wiggle);
  Loop loop;
  for (int k = 0; k < n; ++k) {
    const double a = 2.0 * std::numbers::pi * k / n, radius = r + noise(rng);
    loop.push_back({cx + radius * std::cos(a), cy + radius * std::sin(a)});
  }
  return loop;
}

TEST(RasterCoverage, ClusteredRowsEqualBandedRowsOnWigglyOutlines) {
  // Simple outlines whose boundary turns up and down inside rows (clusters with local extremes), with
  // holes, on a mirrored grid; every row decided by clusters must give the banded path's bytes.
  std::mt19937 rng(2026);
  std::size_t clustered = 0, extremes = 0;
  for (int trial = 0; trial < 40; ++trial) {
    PixelGrid grid = makeGrid(-0.013, 0.021, 0.5 + 0.05 * (trial % 5), 40, 38);
    grid.mirrorX = trial % 2 == 0;
    const double w = 0.02 + 0.04 * (trial % 4);
    std::vector<Loop> loops = {wigglyLoop(rng, 10, 9.5, 8, w, 300 + 40 * trial)};
    if (trial % 3 != 0) loops.push_back(reversed(wigglyLoop(rng, 10.2, 9.3, 4, w, 200)));  // a hole
    if (trial % 4 == 1) loops.push_back(wigglyLoop(rng, 10.1, 9.4, 2, w, 150));            // an island in it
    const LayerContours layer = makeLayer(loops);
    const RasterScratch s = expectClustersEqualBanded({{&layer, 1}}, grid, "trial " + std::to_string(trial));
    clustered += s.clusteredRows;
    extremes += s.extremeRows;
  }
  EXPECT_GT(clustered, 1000u);  // the fixture exercises clusters, and clusters with local extremes
  EXPECT_GT(extremes, 200u);
}

TEST(RasterCoverage, ClusteredRowsEqualBandedRowsOnOverlappingWigglyLoops) {
  // Pairs and triples of wiggly outlines of both orientations crossing one another at random: counts
  // from -2 to 3, crossings inside rows, caps crossing chains; a quarter of them on a lattice.
  std::mt19937 rng(31337);
  std::uniform_real_distribution<double> centre(5, 11), radius(1.5, 5), wiggle(0.01, 0.4);
  std::size_t banded = 0, small = 0;
  for (int trial = 0; trial < 150; ++trial) {
    std::vector<Loop> loops;
    for (int l = 0; l < 2 + trial % 2; ++l) {
      Loop loop = wigglyLoop(rng, centre(rng), centre(rng), radius(rng), wiggle(rng), 20 + 7 * (trial % 11));
      if (trial % 4 == 3) {  // on a quarter-pixel lattice: vertices on row lines, touching loops
        for (Point2d& p : loop) p = {0.25 * std::round(4 * p.x), 0.25 * std::round(4 * p.y)};
      }
      loops.push_back(l == 1 && trial % 3 == 0 ? reversed(loop) : loop);
    }
    const LayerContours layer = makeLayer(loops);
    const PixelGrid grid =
        makeGrid(trial % 4 == 3 ? 0 : 0.1, trial % 4 == 3 ? 0 : -0.07, trial % 2 == 0 ? 1.0 : 0.5, 18, 18);
    const RasterScratch s = expectClustersEqualBanded({{&layer, 1}}, grid, "trial " + std::to_string(trial));
    banded += s.bandedRows;
    small += s.smallClusters;
  }
  EXPECT_GT(banded, 100u);
  EXPECT_GT(small, 1000u);  // clusters the proof rejects, decided part by part
}

// Raw offsets of jagged loops, built as Clipper builds them before its union (as a grown layer's loops
// are where a detour stays): every edge moved out by d, a mitre at each convex corner (a bevel where
// it would be long) and a detour b -> v -> a through each concave one. The detours make small loops
// where the count is 2 and edges that cross inside rows; the clusters holding them are decided part by
// part, or, where the count is at least 1 all round them, add nothing, and must give the exact
// coverage and the banded path's bytes (a rounding tie aside), on grids offset, mirrored, and with
// vertices on the row lines (a lattice).
TEST(RasterCoverage, RawOffsetDetoursAreDecidedPartByPartExactly) {
  std::mt19937 rng(99);
  std::uniform_real_distribution<double> uniform(0, 1);
  std::size_t small = 0, interior = 0;
  for (int trial = 0; trial < 60; ++trial) {
    const int n = 30 + 3 * trial;
    const double d = 0.2 + 0.8 * uniform(rng);
    Loop loop;
    for (int i = 0; i < n; ++i) {
      const double a = 2 * std::numbers::pi * (i + 0.8 * uniform(rng)) / n,
                   r = 7 + 1.5 * (uniform(rng) - 0.5);
      loop.push_back({10 + r * std::cos(a), 10 + r * std::sin(a)});
      if (trial % 3 == 2)
        loop.back() = {0.25 * std::round(4 * loop.back().x), 0.25 * std::round(4 * loop.back().y)};
    }
    const auto normal = [](Point2d p, Point2d q) {  // outward for a counter-clockwise loop
      const double dx = q.x - p.x, dy = q.y - p.y, l = std::hypot(dx, dy);
      return Point2d{dy / l, -dx / l};
    };
    Loop raw;
    for (int i = 0; i < n; ++i) {
      const Point2d p = loop[(i + n - 1) % n], v = loop[i], q = loop[(i + 1) % n];
      if (p.x == v.x && p.y == v.y) continue;
      if (q.x == v.x && q.y == v.y) continue;
      const Point2d n1 = normal(p, v), n2 = normal(v, q);
      const double turn = (v.x - p.x) * (q.y - v.y) - (v.y - p.y) * (q.x - v.x),
                   r = 1 + n1.x * n2.x + n1.y * n2.y;
      if (turn < 0) {  // concave: the detour through the vertex
        raw.insert(raw.end(), {{v.x + d * n1.x, v.y + d * n1.y}, v, {v.x + d * n2.x, v.y + d * n2.y}});
      } else if (r > 0.3) {
        raw.push_back({v.x + d * (n1.x + n2.x) / r, v.y + d * (n1.y + n2.y) / r});
      } else {
        raw.insert(raw.end(), {{v.x + d * n1.x, v.y + d * n1.y}, {v.x + d * n2.x, v.y + d * n2.y}});
      }
    }
    const LayerContours layer = makeLayer({raw});
    PixelGrid grid = makeGrid(trial % 3 == 2 ? 0 : 0.13, trial % 3 == 2 ? 0 : -0.05,
                              trial % 2 == 0 ? 1.0 : 0.5, trial % 2 == 0 ? 21 : 42, trial % 2 == 0 ? 21 : 42);
    grid.mirrorY = trial % 4 == 1;
    const RasterScratch s = expectClustersEqualBanded({{&layer, 1}}, grid, "trial " + std::to_string(trial));
    small += s.smallClusters;
    interior += s.interiorClusters;
  }
  EXPECT_GT(small, 2000u);
  EXPECT_GT(interior, 1000u);  // a detour's tip inside the grown region: the count 1 or 2 all round
}

TEST(RasterCoverage, OverlappingPartsSideBySideKeepTheirPixelsAlone) {
  // Two parts in the same rows, each made of two dense outlines that cross each other all along (rows
  // with crossings and counts of 2, more edges than a band is cut exactly for, so their clusters take the
  // banded path and are sampled): every pixel of the pair is the pixel of the part alone, as a part on a
  // plate must be the part sliced alone. (When a banded row was cut and sampled over all of its edges,
  // the other part's vertices changed the part's sub-bands and so its sample lines.)
  std::mt19937 rng(4242);
  std::size_t banded = 0;
  for (int trial = 0; trial < 6; ++trial) {
    const PixelGrid grid = makeGrid(0, 0, 0.5, 90, 30);
    const int n = 1500 + 300 * trial;
    const LayerContours left =
        makeLayer({wigglyLoop(rng, 11, 15, 9, 0.3, n), wigglyLoop(rng, 11, 15, 9, 0.3, n)});
    const LayerContours right =
        makeLayer({wigglyLoop(rng, 34, 15, 9, 0.3, n), wigglyLoop(rng, 34, 15, 9, 0.3, n),
                   reversed(wigglyLoop(rng, 34, 15, 4, 0.1, n / 4))});
    RasterScratch scratch;
    MaskImage both, a, b;
    const std::vector<ContourSet> pair = {{&left, 1}, {&right, 1}};
    rasterizeCoverage(pair, grid, both, scratch);
    banded += scratch.bandedRows;
    const ContourSet leftAlone{&left, 1}, rightAlone{&right, 1};
    rasterizeCoverage({&leftAlone, 1}, grid, a, scratch);
    rasterizeCoverage({&rightAlone, 1}, grid, b, scratch);
    std::size_t lit = 0;
    for (std::size_t p = 0; p < both.pixels.size(); ++p) {
      ASSERT_EQ(std::min(a.pixels[p], b.pixels[p]), 0) << "trial " << trial << ": the parts overlap";
      ASSERT_EQ(both.pixels[p], std::max(a.pixels[p], b.pixels[p])) << "trial " << trial << " pixel " << p;
      lit += both.pixels[p] != 0;
    }
    EXPECT_GT(lit, 1000u);
  }
  EXPECT_GT(banded, 100u);
}

TEST(RasterCoverage, OverlapsAndTouchingLoopsLeaveTheClusters) {
  // Configurations whose count leaves {0, 1} or whose loops meet, each next to plain rows: they must be
  // exact (the oracle) and equal to the banded path whichever path takes them.
  std::mt19937 rng(99);
  struct Case {
    std::string what;
    std::vector<Loop> loops;
    std::vector<Loop> removal;
  };
  const std::vector<Case> cases = {
      {"overlapping outlines (count 2)",
       {wigglyLoop(rng, 8, 8, 5, 0.05, 400), wigglyLoop(rng, 11, 9, 5, 0.05, 400)},
       {}},
      {"island of the same orientation inside an outline",
       {wigglyLoop(rng, 10, 10, 7, 0.05, 400), wigglyLoop(rng, 10, 10, 3, 0.05, 300)},
       {}},
      {"a loop inside one row, inside an outline",
       {rect(2, 2.5, 15, 15), {{5.2, 7.2}, {6.7, 7.4}, {5.9, 7.8}}},
       {}},
      {"a hole inside one row", {rect(2, 2.5, 15, 15), reversed({{5.2, 7.2}, {6.7, 7.4}, {5.9, 7.8}})}, {}},
      {"a loop inside one row, alone", {{{5.2, 7.2}, {6.7, 7.4}, {5.9, 7.8}}}, {}},
      {"squares touching at a vertex", {rect(2, 2, 6.5, 6.5), rect(6.5, 6.5, 11, 11)}, {}},
      {"squares sharing an edge", {rect(2, 2.25, 6.5, 9.75), rect(6.5, 3.5, 11, 8.25)}, {}},
      {"an edge through another loop's vertex",
       {{{2, 2}, {8, 5}, {2, 8}}, {{8, 2.5}, {8, 7.5}, {5, 5.0}, {3, 5}, {3, 4.5}}},
       {}},
      {"crossing wiggly outlines, one reversed",
       {wigglyLoop(rng, 8, 8, 5, 0.05, 400), reversed(wigglyLoop(rng, 10, 8, 5, 0.05, 400))},
       {}},
      {"removal over the outline's edge",
       {wigglyLoop(rng, 8, 8, 6, 0.05, 400)},
       {rect(11.3, 5.2, 16.6, 10.9)}},
      {"removal equal to the outline", {rect(3.25, 3.5, 9.75, 12.25)}, {rect(3.25, 3.5, 9.75, 12.25)}},
      {"local minimum on a row line", {{{5, 4}, {9, 7.5}, {9, 10}, {1, 10}, {1, 7.5}}}, {}},
      // Counts outside {0, 1} inside partially covered pixels (where a wrong count would show):
      {"a clockwise loop inside one row, left of an outline's edge in the same pixel",
       {rect(5.8, 2.5, 15, 15), reversed({{5.1, 7.2}, {5.6, 7.3}, {5.3, 7.8}})},
       {}},
      {"a loop inside one row, inside an outline's edge pixel",
       {rect(5.3, 2.5, 15, 15), {{5.5, 7.2}, {5.9, 7.3}, {5.6, 7.8}}},
       {}},
      {"a peak inside a row, inside an outline's edge pixel",
       {rect(2, 2, 6.4, 15), {{5.8, 3}, {6.3, 3}, {6.05, 7.5}}},
       {}},
      {"a valley inside a row, inside an outline's edge pixel",
       {rect(2, 2, 6.4, 15), {{6.05, 7.5}, {6.3, 12}, {5.8, 12}}},
       {}},
      {"a clockwise peak crossing into an outline's edge pixel",
       {rect(6.2, 2, 12, 15), reversed({{5.7, 3}, {6.6, 3}, {6.1, 7.5}})},
       {}},
  };
  std::size_t clustered = 0, banded = 0;
  for (const Case& c : cases) {
    const LayerContours layer = makeLayer(c.loops), removal = makeLayer(c.removal);
    std::vector<ContourSet> sets = {{&layer, 1}};
    if (!c.removal.empty()) sets.push_back({&removal, -1});
    for (const double pixel : {1.0, 0.37}) {
      const PixelGrid grid =
          makeGrid(0, 0, pixel, static_cast<uint32_t>(20 / pixel), static_cast<uint32_t>(18 / pixel));
      const RasterScratch s = expectClustersEqualBanded(sets, grid, c.what);
      clustered += s.clusteredRows;
      banded += s.bandedRows;
    }
  }
  EXPECT_GT(clustered, 100u);
  EXPECT_GT(banded, 50u);
}

TEST(RasterCoverage, ManyCrossingEdgesAreSampledWithinTheMidpointBound) {
  // A self-intersecting loop of 400 random vertices: most rows hold far more than 64 crossing edges, so
  // their crossing bands are sampled (16 lines per pixel, exact in x; rasterize.h) instead of cut at
  // every crossing. Against exact clipping: the total within 0.1 %, pixels within a few levels on
  // average; and fast (the exact cuts took seconds at 2000 vertices).
  std::mt19937 rng(99);
  std::uniform_real_distribution<double> coord(0.0, 24.0);
  Loop loop;
  for (int k = 0; k < 400; ++k) loop.push_back({coord(rng), coord(rng)});
  const LayerContours layer = makeLayer({loop});
  const std::vector<ContourSet> sets = {{&layer, 1}};
  const PixelGrid grid = unitGrid(24, 24);
  uint64_t sum = 0;
  MaskImage m;
  RasterScratch scratch;
  rasterizeCoverage(sets, grid, m, scratch, &sum);
  const std::vector<double> area = fixtures::exactCoverage(sets, grid);
  double exact = 0, absError = 0;
  for (std::size_t p = 0; p < area.size(); ++p) {
    exact += 255.0 * area[p];
    absError += std::abs(m.pixels[p] - 255.0 * area[p]);
  }
  EXPECT_GT(exact, 100.0 * 255);
  EXPECT_NEAR(static_cast<double>(sum), exact, 1e-3 * exact);
  EXPECT_LT(absError / static_cast<double>(area.size()), 3.0);
}

// Regular 1000-gon of radius 2 mm at 0.05 mm pixels (about 250 boundary pixels).
struct CircleCase {
  LayerContours layer = makeLayer({circle(3.013, 2.971, 2.0, 1000)});
  PixelGrid grid = makeGrid(0, 0, 0.05, 120, 120);
  double area = layerSignedArea(layer);
  double perimeter = 2 * std::numbers::pi * 2.0;
};

TEST(RasterBinary, CircleAreaWithinPixelError) {
  const CircleCase c;
  EXPECT_NEAR(c.area, std::numbers::pi * 4.0, 1e-3);
  const MaskImage m = binary({{&c.layer, 1}}, c.grid);
  const double p2 = c.grid.pixel * c.grid.pixel;
  // Only pixels within half a diagonal of the boundary can be misclassified; the errors are signed and
  // mostly cancel. Bound: 5% of the boundary pixel count (about 13 pixels).
  const double boundaryPixels = c.perimeter / c.grid.pixel;
  EXPECT_NEAR(static_cast<double>(countLitPixels(m)) * p2, c.area, 0.05 * boundaryPixels * p2);
  EXPECT_DOUBLE_EQ(maskArea(m, c.grid.pixel), static_cast<double>(countLitPixels(m)) * p2);
}

TEST(RasterCoverage, CircleAreaWithinRoundingError) {
  const CircleCase c;
  const MaskImage m = coverage({{&c.layer, 1}}, c.grid);
  std::size_t partial = 0;
  for (uint8_t v : m.pixels) partial += (v != 0 && v != 255) ? 1 : 0;
  EXPECT_GT(partial, 250u);
  EXPECT_LT(partial, 2 * 260u);
  const double p2 = c.grid.pixel * c.grid.pixel;
  // Each partial pixel rounds by at most 0.5/255 of a pixel; the vertical sampling of a smooth convex
  // boundary adds far less. The bound is 1/8 of the worst rounding case (signed errors cancel).
  const double bound = 0.125 * static_cast<double>(partial) * 0.5 / 255.0 * p2;
  EXPECT_NEAR(maskArea(m, c.grid.pixel), c.area, bound);
  EXPECT_LT(bound, 0.01 * p2 * c.perimeter / c.grid.pixel);  // much tighter than the binary bound
}

TEST(RasterCoverage, AxisAlignedFractionsAreExact) {
  // x: column 2 covered 0.75, columns 3-4 fully, column 5 half. y: rows 1-2 fully, row 3 a quarter.
  const LayerContours layer = makeLayer({rect(2.25, 1.0, 5.5, 3.25)});
  const MaskImage m = coverage({{&layer, 1}}, unitGrid(8, 5));
  const double fx[8] = {0, 0, 0.75, 1, 1, 0.5, 0, 0};
  const double fy[5] = {0, 1, 1, 0.25, 0};
  for (uint32_t j = 0; j < 5; ++j) {
    for (uint32_t i = 0; i < 8; ++i) {
      EXPECT_EQ(at(m, i, j), static_cast<int>(std::floor(255.0 * fx[i] * fy[j] + 0.5))) << i << "," << j;
    }
  }
  EXPECT_EQ(at(m, 2, 1), 191);
  EXPECT_EQ(at(m, 5, 1), 128);  // 127.5 rounds up
  EXPECT_EQ(at(m, 2, 3), 48);
}

TEST(RasterCoverage, DiagonalCutsPixelInHalf) {
  const LayerContours layer = makeLayer({{{0, 0}, {1, 0}, {0, 1}}});
  const MaskImage m = coverage({{&layer, 1}}, unitGrid(2, 2));
  EXPECT_EQ(m.pixels, (std::vector<uint8_t>{128, 0, 0, 0}));
}

TEST(RasterCoverage, ThinSliversAreExact) {
  // A strip 0.31 pixel high (the old 16 sub-scanlines saw 5/16 = 0.3125: 80) and one 0.02 wide: 0.02 of
  // each pixel it crosses (5.1 -> 5); a sliver this thin is lost by any sampling at pixel centres.
  const LayerContours strip = makeLayer({rect(0, 0, 1, 0.31)});
  EXPECT_EQ(coverage({{&strip, 1}}, unitGrid(1, 1)).pixels[0], 79);  // 79.05
  const LayerContours sliver = makeLayer({rect(1.3, -2, 1.32, 9)});
  const MaskImage m = coverage({{&sliver, 1}}, unitGrid(3, 4));
  for (uint32_t j = 0; j < 4; ++j) {
    EXPECT_EQ(at(m, 0, j), 0);
    EXPECT_EQ(at(m, 1, j), 5);
    EXPECT_EQ(at(m, 2, j), 0);
    EXPECT_EQ(m.litBegin[j], 1u);
    EXPECT_EQ(m.litEnd[j], 2u);
  }
  // A slanted sliver: a parallelogram 0.05 wide along x leaning 1 pixel per 4 rows, area 0.05 per row.
  const LayerContours slanted = makeLayer({{{0.5, 0}, {0.55, 0}, {1.55, 4}, {1.5, 4}}});
  const MaskImage s = coverage({{&slanted, 1}}, unitGrid(3, 4));
  for (uint32_t j = 0; j < 4; ++j) {
    int rowSum = 0;
    for (uint32_t i = 0; i < 3; ++i) rowSum += at(s, i, j);
    EXPECT_NEAR(rowSum, 255 * 0.05, 1.0) << "row " << j;
  }
}

TEST(RasterCoverage, SlantedEdgeKnownFractions) {
  // Right triangle (0,0), (4,0), (0,2): the hypotenuse x = 4 - 2y crosses both rows. Row 0: columns
  // 0-1 full, column 2 covers 0.75, column 3 0.25; row 1: column 0 0.75, column 1 0.25.
  const LayerContours layer = makeLayer({{{0, 0}, {4, 0}, {0, 2}}});
  const MaskImage m = coverage({{&layer, 1}}, unitGrid(5, 3));
  EXPECT_EQ(m.pixels, (std::vector<uint8_t>{255, 255, 191, 64, 0, 191, 64, 0, 0, 0, 0, 0, 0, 0, 0}));
  // The same with the grid shifted by a quarter pixel: vertices inside pixels.
  const PixelGrid shifted = makeGrid(-0.25, -0.25, 1, 5, 3);
  const MaskImage t = coverage({{&layer, 1}}, shifted);
  expectExactCoverage({{&layer, 1}}, shifted, t, "shifted");
  EXPECT_EQ(at(t, 0, 0), 143);  // 0.5625: [0, 0.75] x [0, 0.75] of the pixel
}

TEST(RasterCoverage, VerticesInsidePixels) {
  // A triangle inside one pixel: its area exactly (shoelace: 0.5 * (0.6 * 0.7 - 0.1 * 0.2) = 0.2).
  const LayerContours tri = makeLayer({{{1.2, 1.2}, {1.8, 1.3}, {1.4, 1.9}}});
  const MaskImage m = coverage({{&tri, 1}}, unitGrid(3, 3));
  EXPECT_EQ(at(m, 1, 1), 51);  // 255 * 0.2
  EXPECT_EQ(countLitPixels(m), 1u);
  // A diamond with its four vertices in four different pixels.
  const LayerContours diamond = makeLayer({{{1.5, 0.3}, {2.7, 1.5}, {1.5, 2.7}, {0.3, 1.5}}});
  expectExactCoverage({{&diamond, 1}}, unitGrid(4, 4), coverage({{&diamond, 1}}, unitGrid(4, 4)), "diamond");
}

TEST(RasterCoverage, CoincidentRemovalEdgesCancelExactly) {
  // Model: a leaning parallelogram; removal: its right part, sharing the slanted right edge and the
  // horizontal edges. Where only the two overlap the value is exactly 0 (no residue of the shared edge).
  const LayerContours model = makeLayer({{{0, 0}, {3, 0}, {4, 4}, {1, 4}}});
  const LayerContours removal = makeLayer({{{1.5, 0}, {3, 0}, {4, 4}, {2.5, 4}}});
  const std::vector<ContourSet> sets = {{&model, 1}, {&removal, -1}};
  const MaskImage m = coverage(sets, unitGrid(5, 4));
  expectExactCoverage(sets, unitGrid(5, 4), m, "removal");
  for (uint32_t j = 0; j < 4; ++j) {
    for (uint32_t i = 3; i < 5; ++i) EXPECT_EQ(at(m, i, j), 0) << i << "," << j;
    // The left edge x = y / 4 leaves 1 - (j + 1/2) / 4 of pixel (0, j): 223, 159, 96, 32.
    EXPECT_EQ(at(m, 0, j), static_cast<int>(std::floor(255 * (1 - (j + 0.5) / 4) + 0.5))) << "row " << j;
  }
}

// The transfer curve is applied as values are written (here a threshold at half coverage), the row hook
// on each lit row's span; extents follow what they leave, the value sum is the area before the curve.
TEST(RasterCoverage, TransferCurveAndRowHook) {
  const LayerContours layer = makeLayer({circle(3.2, 2.9, 2.1, 300)});
  const std::vector<ContourSet> sets = {{&layer, 1}};
  PixelGrid grid = makeGrid(0, 0, 0.1, 70, 60);
  grid.mirrorX = true;
  const MaskImage plain = coverage(sets, grid);
  uint8_t threshold[256];
  for (int v = 0; v < 256; ++v) threshold[v] = v >= 128 ? 255 : 0;
  // round(255 a) >= 128 where a >= 127.5 / 255: a curve of one step there.
  std::array<double, 256> steps;
  steps.fill(127.5 / 255.0);
  const CoverageCurve curve = coverageCurve(steps);
  CoverageTransfer transfer;
  transfer.curve = &curve;
  RasterScratch scratch;
  MaskImage m;
  uint64_t sum = 0;
  rasterizeCoverage(sets, grid, m, scratch, &sum, &transfer);
  uint64_t expectedSum = 0;
  for (std::size_t p = 0; p < m.pixels.size(); ++p) {
    ASSERT_EQ(m.pixels[p], threshold[plain.pixels[p]]) << p;
    expectedSum += plain.pixels[p];  // the area, before the curve
  }
  EXPECT_EQ(sum, expectedSum);
  // A hook that darkens the first lit pixel of every row: the extent starts one later (or further).
  transfer.curve = nullptr;
  transfer.row = [](void* context, uint32_t, uint32_t begin, uint32_t, uint8_t* row) {
    ++*static_cast<int*>(context);
    row[begin] = 0;
  };
  int calls = 0;
  transfer.context = &calls;
  rasterizeCoverage(sets, grid, m, scratch, &sum, &transfer);
  uint64_t litRows = 0;
  expectedSum = 0;
  for (uint32_t r = 0; r < grid.height; ++r) {
    if (plain.litBegin[r] >= plain.litEnd[r]) continue;
    ++litRows;
    const uint8_t* row = m.pixels.data() + std::size_t{r} * grid.width;
    EXPECT_EQ(row[plain.litBegin[r]], 0) << r;
    EXPECT_GT(m.litBegin[r], plain.litBegin[r]) << r;
    if (m.litBegin[r] < m.litEnd[r]) {
      EXPECT_NE(row[m.litBegin[r]], 0) << r;
    }
    for (uint32_t i = 0; i < grid.width; ++i) expectedSum += row[i];
  }
  EXPECT_EQ(static_cast<uint64_t>(calls), litRows);
  EXPECT_EQ(sum, expectedSum);
}

// Every fill of m (MaskImage::fills) is a stretch of its row holding its value, in increasing x, none
// overlapping.
void expectFillsDescribePixels(const MaskImage& m) {
  ASSERT_TRUE(m.hasFills());
  for (uint32_t r = 0; r < m.height; ++r) {
    const uint32_t first = m.rowFills[2 * r], count = m.rowFills[2 * r + 1];
    const uint8_t* row = m.pixels.data() + std::size_t{r} * m.width;
    for (uint32_t k = first; k < first + count; ++k) {
      const uint32_t a = m.fills[3 * k], b = m.fills[3 * k + 1], value = m.fills[3 * k + 2];
      ASSERT_LT(a, b) << "row " << r;
      ASSERT_LE(b, m.width) << "row " << r;
      if (k > first) {
        ASSERT_GE(a, m.fills[3 * k - 2]) << "row " << r << ": fills overlap or are out of order";
      }
      for (uint32_t i = a; i < b; ++i) ASSERT_EQ(row[i], value) << "row " << r << " pixel " << i;
    }
  }
}

// A light map applied as the values are written equals the map applied to every pixel of the finished
// image, round(v * m / 255), with a gamma curve, mirrored or not, on a reused image: the same pixels, tight
// extents (pixels dimmed to 0 at a row's ends leave it), the value sum taken before the map, and the
// stretches of one value (the map's, within the runs between edge pixels) listed as fills. Maps: one
// that changes at every pixel, and one of stretches (some dark) as a display's smooth map has.
TEST(RasterCoverage, LightMapAsTheValuesAreWritten) {
  const LayerContours layer =
      makeLayer({circle(3.2, 2.9, 2.1, 300), reversed(circle(3.0, 3.0, 1.0, 200)), rect(4.6, 0.3, 6.6, 5.5)});
  const std::vector<ContourSet> sets = {{&layer, 1}};
  const CoverageCurve gamma = gammaCurve(0.8);
  RasterScratch scratch;
  MaskImage m;
  for (int variant = 0; variant < 4; ++variant) {
    const bool mirror = variant % 2 == 1, stretches = variant >= 2;
    PixelGrid grid = makeGrid(0, 0, 0.1, 70, 60);
    grid.mirrorX = mirror;
    grid.mirrorY = mirror;
    MaskImage image;
    image.width = grid.width;
    image.height = grid.height;
    image.pixels.resize(std::size_t{grid.width} * grid.height);
    for (std::size_t p = 0; p < image.pixels.size(); ++p) {
      const std::size_t x = p % grid.width, y = p / grid.width;
      image.pixels[p] = static_cast<uint8_t>(stretches ? ((x / 11 + y) % 5 == 0 ? 0 : 120 + 9 * (x / 11) + y)
                                                       : (p % 7 == 0 ? 0 : 90 + (p * 37) % 166));
    }
    const LightMap map = lightMapOf(image);
    CoverageTransfer transfer;
    transfer.curve = &gamma;
    uint64_t before = 0, after = 0;
    rasterizeCoverage(sets, grid, m, scratch, &before, &transfer);
    const MaskImage unlit = m;
    MaskImage expected = m;
    for (std::size_t p = 0; p < expected.pixels.size(); ++p)
      expected.pixels[p] = static_cast<uint8_t>(std::lround(expected.pixels[p] * image.pixels[p] / 255.0));
    transfer.lightMap = &map;
    rasterizeCoverage(sets, grid, m, scratch, &after, &transfer);
    ASSERT_EQ(m.pixels, expected.pixels) << "variant " << variant;
    EXPECT_EQ(after, before);
    expectFillsDescribePixels(m);
    std::size_t litFills = 0;
    for (std::size_t f = 0; f < m.fills.size(); f += 3) litFills += m.fills[f + 2] != 0 ? 1 : 0;
    if (stretches) {
      EXPECT_GT(litFills, 30u);
    } else {
      EXPECT_EQ(litFills, 0u);
    }
    std::size_t dimmedEnds = 0;
    for (uint32_t r = 0; r < grid.height; ++r) {
      const uint8_t* row = m.pixels.data() + std::size_t{r} * grid.width;
      uint32_t first = grid.width, last = 0;
      for (uint32_t i = 0; i < grid.width; ++i)
        if (row[i] != 0) first = std::min(first, i), last = i + 1;
      if (first >= last) {
        EXPECT_GE(m.litBegin[r], m.litEnd[r]) << r;
        continue;
      }
      EXPECT_EQ(m.litBegin[r], first) << r;
      EXPECT_EQ(m.litEnd[r], last) << r;
      dimmedEnds += m.litBegin[r] != unlit.litBegin[r] || m.litEnd[r] != unlit.litEnd[r] ? 1 : 0;
    }
    EXPECT_GT(dimmedEnds, 0u);
  }
}

TEST(RasterCoverage, PixelAlignedShapesMatchBinary) {
  const LayerContours layer = makeLayer({rect(2, 3, 7, 9), reversed(rect(4, 5, 5, 6))});
  const LayerContours removal = makeLayer({rect(6, 0, 8, 4)});
  const std::vector<ContourSet> sets = {{&layer, 1}, {&removal, -1}};
  const MaskImage c = coverage(sets, unitGrid(10, 10));
  EXPECT_EQ(c.pixels, binary(sets, unitGrid(10, 10)).pixels);
  EXPECT_EQ(countLitPixels(c), 28u);  // 30 - 1 (hole) - 1 (removal)
}

TEST(RasterCoverage, RemovalRunEndsAreFractional) {
  const LayerContours model = makeLayer({rect(0, 0, 4, 4)});
  const LayerContours removal = makeLayer({rect(1.5, -1, 2.5, 5)});
  const MaskImage m = coverage({{&model, 1}, {&removal, -1}}, unitGrid(5, 4));
  for (uint32_t j = 0; j < 4; ++j) {
    EXPECT_EQ(at(m, 0, j), 255);
    EXPECT_EQ(at(m, 1, j), 128);
    EXPECT_EQ(at(m, 2, j), 128);
    EXPECT_EQ(at(m, 3, j), 255);
    EXPECT_EQ(at(m, 4, j), 0);
  }
}

TEST(RasterCoverage, ClippedAtGridBorder) {
  const LayerContours layer = makeLayer({rect(-5, -5, 2.5, 100)});
  const MaskImage m = coverage({{&layer, 1}}, unitGrid(4, 4));
  for (uint32_t j = 0; j < 4; ++j) {
    EXPECT_EQ(at(m, 0, j), 255);
    EXPECT_EQ(at(m, 1, j), 255);
    EXPECT_EQ(at(m, 2, j), 128);
    EXPECT_EQ(at(m, 3, j), 0);
  }
}

}  // namespace
}  // namespace toposlice

namespace toposlice {
namespace {

// The lit extents the binary rasterizer keeps are tight and exact, survive reuse of the image across
// layers (with mirroring), and the PNG encoder's extent path gives the same image as the full scan.
std::vector<uint8_t> pngOf(const MaskImage& m) {
  std::vector<uint8_t> png;
  encodeMaskPng(m, png);
  return png;
}

TEST(MaskImageRows, StretchesCoverTheRangeInOrder) {
  // forEachRowStretch over random fills (some before, across or after the range, some touching) and
  // random ranges: fills and gaps alternate as they lie, none empty, together exactly the range; a fill
  // is reported where it lies inside the range, with its value; without fills, one gap.
  std::mt19937 rng(31);  // 32-bit results
  for (int trial = 0; trial < 2000; ++trial) {
    MaskImage m;
    m.width = 1 + static_cast<uint32_t>(rng() % 80);
    m.height = 3;
    m.pixels.assign(std::size_t{m.width} * m.height, 0);
    m.litBegin.assign(m.height, 0);
    m.litEnd.assign(m.height, m.width);
    const bool withFills = trial % 5 != 0;
    std::vector<std::array<uint32_t, 3>> listed;  // of row 1
    if (withFills) {
      m.rowFills.assign(2 * std::size_t{m.height}, 0);
      for (uint32_t r = 0; r < m.height; ++r) {
        m.rowFills[2 * r] = static_cast<uint32_t>(m.fills.size() / 3);
        for (uint32_t x = rng() % 4; x < m.width;) {
          const uint32_t end = std::min(m.width, x + 1 + static_cast<uint32_t>(rng() % 12));
          const uint32_t value = rng() % 3 == 0 ? 0 : static_cast<uint32_t>(rng() % 256);
          m.fills.insert(m.fills.end(), {x, end, value});
          if (r == 1) listed.push_back({x, end, value});
          x = end + static_cast<uint32_t>(rng() % 3);  // touching, or a gap of one or two
        }
        m.rowFills[2 * r + 1] = static_cast<uint32_t>(m.fills.size() / 3) - m.rowFills[2 * r];
      }
      ASSERT_TRUE(m.hasFills());
    }
    const std::size_t begin = rng() % (m.width + 1), end = begin + rng() % (m.width + 1 - begin);
    std::vector<std::array<std::size_t, 4>> seen;  // begin, end, kind (0 gap, 1 fill), value
    forEachRowStretch(
        m, 1, begin, end,
        [&](std::size_t a, std::size_t b, uint8_t value) {
          seen.push_back({a, b, 1, value});
        },
        [&](std::size_t a, std::size_t b) {
          seen.push_back({a, b, 0, 0});
        });
    std::size_t at = begin;
    for (const auto& [a, b, kind, value] : seen) {
      ASSERT_EQ(a, at) << "trial " << trial;
      ASSERT_LT(a, b) << "trial " << trial;
      at = b;
      if (kind == 1) {
        const auto f = std::find_if(listed.begin(), listed.end(),
                                    [&](const std::array<uint32_t, 3>& g) { return g[0] <= a && b <= g[1]; });
        ASSERT_NE(f, listed.end()) << "trial " << trial << ": a fill where none is listed";
        EXPECT_EQ(value, (*f)[2]) << "trial " << trial;
        EXPECT_TRUE(a == std::max<std::size_t>((*f)[0], begin) && b == std::min<std::size_t>((*f)[1], end));
      } else {  // no listed fill meets a gap
        for (const auto& g : listed) ASSERT_TRUE(g[1] <= a || g[0] >= b) << "trial " << trial;
      }
    }
    ASSERT_EQ(at, end) << "trial " << trial;
    if (!withFills) {
      EXPECT_LE(seen.size(), 1u);
    }
  }
}

TEST(RasterCoverage, ConsecutiveLayersInOneImageEqualFreshImages) {
  // An anti-aliased layer drawn into the image that holds the previous layer (only that layer's lit
  // stretches are cleared, its dark fills skipped). Slowly moving shapes with a hole and a second part
  // that comes and goes (dark stretches between parts), whole layers empty, mirrored and portrait grids,
  // with a gamma curve, a light map or a row hook, and a binary layer or a grid of another size in
  // between: every image equals the same layer drawn into a fresh image, with the same extents, fills
  // and value sum.
  RasterScratch scratch;
  MaskImage m;
  const CoverageCurve gamma = gammaCurve(0.8);
  constexpr uint32_t kWidth = 126, kHeight = 121;  // every layer's grid, portrait or not
  MaskImage lightImage;                            // a light map of stretches, some of them dark
  lightImage.width = kWidth;
  lightImage.height = kHeight;
  lightImage.pixels.resize(std::size_t{kWidth} * kHeight);
  for (std::size_t p = 0; p < lightImage.pixels.size(); ++p) {
    const std::size_t x = p % kWidth, y = p / kWidth;
    lightImage.pixels[p] = static_cast<uint8_t>((x / 17 + y / 5) % 7 == 0 ? 0 : 170 + x / 3);
  }
  const LightMap map = lightMapOf(lightImage);
  std::size_t keptFills = 0;  // lit fills overlapping a lit fill of the same value in the layer below
  MaskImage previous;
  for (int k = 0; k < 120; ++k) {
    const LayerContours layer = driftingLayer(k);
    const std::vector<ContourSet> sets = {{&layer, 1}};
    const PixelGrid grid = driftingGrid(k, 0.05, kWidth, kHeight);
    CoverageTransfer transfer;
    transfer.curve = k % 4 == 1 ? &gamma : nullptr;
    transfer.lightMap = k % 4 == 2 ? &map : nullptr;
    if (k % 4 == 3 && k % 3 == 0) {
      transfer.row = [](void*, uint32_t, uint32_t begin, uint32_t end, uint8_t* row) {
        for (uint32_t i = begin; i < end; ++i) row[i] = static_cast<uint8_t>(row[i] > 200 ? 0 : row[i]);
      };
    }
    if (k % 29 == 28) {  // something else in between: a binary layer, then a grid of another size
      rasterizeBinary(sets, grid, m, scratch);
      rasterizeCoverage(sets, makeGrid(0, 0, 0.2, 33, 31), m, scratch);
      previous = MaskImage{};
      continue;
    }
    uint64_t sum = 0, freshSum = 0;
    rasterizeCoverage(sets, grid, m, scratch, &sum, &transfer);
    MaskImage fresh;
    RasterScratch freshScratch;
    rasterizeCoverage(sets, grid, fresh, freshScratch, &freshSum, &transfer);
    ASSERT_EQ(m.pixels, fresh.pixels) << "layer " << k;
    ASSERT_EQ(m.litBegin, fresh.litBegin) << "layer " << k;
    ASSERT_EQ(m.litEnd, fresh.litEnd) << "layer " << k;
    ASSERT_EQ(m.fills, fresh.fills) << "layer " << k;
    ASSERT_EQ(m.rowFills, fresh.rowFills) << "layer " << k;
    ASSERT_EQ(sum, freshSum) << "layer " << k;
    if (previous.hasFills() && m.hasFills()) {
      for (uint32_t r = 0; r < grid.height; ++r) {
        for (uint32_t f = m.rowFills[2 * r]; f < m.rowFills[2 * r] + m.rowFills[2 * r + 1]; ++f) {
          for (uint32_t g = previous.rowFills[2 * r];
               g < previous.rowFills[2 * r] + previous.rowFills[2 * r + 1]; ++g) {
            keptFills += m.fills[3 * f + 2] != 0 && m.fills[3 * f + 2] == previous.fills[3 * g + 2] &&
                                 m.fills[3 * f] < previous.fills[3 * g + 1] &&
                                 previous.fills[3 * g] < m.fills[3 * f + 1]
                             ? 1
                             : 0;
          }
        }
      }
    }
    previous = m;
  }
  EXPECT_GT(keptFills, 1000u);  // consecutive layers overlap: the fixture moves slowly
}

TEST(RasterCoverage, FillsDescribePixelsAndLeaveThePngAsItWas) {
  // Anti-aliased images of wiggly outlines and random loops, mirrored or not, reused from layer to
  // layer, with a gamma curve or a light map: their fills hold what the pixels hold, and the PNG and EXR
  // coders, which jump over them, write the bytes they write without them. A row hook may change values, so
  // it leaves no fills.
  std::mt19937 rng(4711);
  RasterScratch scratch;
  MaskImage m;
  std::size_t fills = 0;
  const CoverageCurve gamma = gammaCurve(0.7);
  for (int trial = 0; trial < 40; ++trial) {
    PixelGrid grid = makeGrid(-0.013, 0.021, 0.25, 90, 80);
    grid.mirrorX = trial % 2 == 1;
    grid.mirrorY = trial % 3 == 1;
    const std::vector<LayerContours> random = randomLayers(rng);
    const LayerContours wiggly =
        makeLayer({wigglyLoop(rng, 10, 9.5, 8, 0.1, 300), reversed(wigglyLoop(rng, 10, 9.5, 4, 0.1, 200))});
    std::vector<ContourSet> sets = {{&wiggly, 1}};
    if (trial % 4 == 3) sets = {{&random[0], 1}, {&random[1], 1}, {&random[2], -1}};
    MaskImage image;  // a light map of stretches
    image.width = grid.width;
    image.height = grid.height;
    image.pixels.resize(std::size_t{grid.width} * grid.height);
    for (std::size_t p = 0; p < image.pixels.size(); ++p)
      image.pixels[p] = static_cast<uint8_t>(150 + (p % grid.width) / 13 + (p / grid.width) % 3);
    const LightMap map = lightMapOf(image);
    CoverageTransfer transfer;
    transfer.curve = &gamma;
    transfer.lightMap = trial % 5 == 4 ? &map : nullptr;
    rasterizeCoverage(sets, grid, m, scratch, nullptr,
                      trial % 5 == 2 || trial % 5 == 4 ? &transfer : nullptr);
    expectFillsDescribePixels(m);
    for (uint32_t r = 0; r < m.height; ++r) fills += m.rowFills[2 * r + 1];
    MaskImage plain = m;
    plain.fills.clear();
    plain.rowFills.clear();
    std::vector<uint8_t> withFills = pngOf(m), withoutFills = pngOf(plain);
    EXPECT_EQ(withFills, withoutFills) << "trial " << trial;
    MaskJob job;
    job.grid = grid;
    job.layerCount = 1;
    job.antiAliased = true;
    MaskEncodeScratch exrScratch;
    encodeExrMaskLayer(m, job, 0, 0.1, withFills, exrScratch);
    encodeExrMaskLayer(plain, job, 0, 0.1, withoutFills, exrScratch);
    EXPECT_EQ(withFills, withoutFills) << "EXR, trial " << trial;
  }
  EXPECT_GT(fills, 1000u);
  CoverageTransfer hook;
  hook.row = [](void*, uint32_t, uint32_t begin, uint32_t end, uint8_t* row) {
    for (uint32_t i = begin; i < end; ++i) row[i] = static_cast<uint8_t>(row[i] / 2);
  };
  const LayerContours layer = makeLayer({rect(2, 2, 15, 15)});
  const std::vector<ContourSet> square = {{&layer, 1}};
  rasterizeCoverage(square, makeGrid(0, 0, 0.5, 40, 40), m, scratch, nullptr, &hook);
  EXPECT_FALSE(m.hasFills());
}

TEST(RasterBinary, LitExtentsAreTightAndPngRoundTrips) {
  std::mt19937 rng(777);
  RasterScratch scratch;
  MaskImage reused;
  for (int trial = 0; trial < 60; ++trial) {
    PixelGrid grid = unitGrid(40, 33);
    grid.mirrorX = trial % 2 == 1;
    grid.mirrorY = trial % 3 == 1;
    const std::vector<LayerContours> layers = randomLayers(rng);
    const std::vector<ContourSet> sets = {{&layers[0], 1}, {&layers[1], 1}, {&layers[2], -1}};
    uint64_t lit = 0;
    rasterizeBinary(sets, grid, reused, scratch, &lit);
    const MaskImage fresh = binary(sets, grid);
    ASSERT_EQ(reused.pixels, fresh.pixels) << "trial " << trial;
    ASSERT_EQ(lit, countLitPixels(fresh));
    ASSERT_TRUE(reused.hasExtents());
    for (uint32_t r = 0; r < grid.height; ++r) {
      const uint8_t* row = reused.pixels.data() + std::size_t{r} * grid.width;
      uint32_t lo = grid.width, hi = 0;
      for (uint32_t i = 0; i < grid.width; ++i)
        if (row[i]) {
          lo = std::min(lo, i);
          hi = i + 1;
        }
      if (lo >= hi) {
        EXPECT_GE(reused.litBegin[r], reused.litEnd[r]) << "row " << r;
      } else {
        EXPECT_EQ(reused.litBegin[r], lo) << "row " << r;
        EXPECT_EQ(reused.litEnd[r], hi) << "row " << r;
      }
    }
    MaskImage plain = reused;
    plain.litBegin.clear();
    plain.litEnd.clear();
    const std::vector<uint8_t> withExtents = pngOf(reused);
    EXPECT_EQ(withExtents, pngOf(plain)) << "trial " << trial;
    MaskImage decoded;
    ASSERT_TRUE(decodeMaskPng(withExtents, decoded));
    EXPECT_EQ(decoded.pixels, fresh.pixels);
  }
}

}  // namespace
}  // namespace toposlice
