// The preview renderer (core/raster/preview.h) on analytic models: a cube's silhouette, its three visible
// faces in the expected shading order and places; a sphere's round silhouette and the side its light comes
// from; the PNG encoding and the `toposlice preview` command.
#include <gtest/gtest.h>
#include <spng.h>

#include <cmath>
#include <map>
#include <memory>
#include <numbers>
#include <string>
#include <vector>

#include "core/raster/preview.h"
#include "io/preview_png.h"
#include "parallel/parallel.h"
#include "tests/fixtures/runners.h"
#include "tests/fixtures/shapes.h"
#include "tests/tool_runner.h"

namespace toposlice {
namespace {

bool isBackground(const RgbImage& im, uint32_t x, uint32_t y) {
  const uint8_t* p = &im.rgb[(std::size_t{y} * im.width + x) * 3];
  return p[0] == kPreviewBackground[0] && p[1] == kPreviewBackground[1] && p[2] == kPreviewBackground[2];
}

// The shade of a fully covered model pixel, from its green channel (the model colour times the shade).
double shadeOf(const RgbImage& im, uint32_t x, uint32_t y) {
  return im.rgb[(std::size_t{y} * im.width + x) * 3 + 1] / double{kPreviewModel[1]};
}

struct Extent {
  uint32_t minX = UINT32_MAX, minY = UINT32_MAX, maxX = 0, maxY = 0;
  std::size_t count = 0;
};

Extent modelExtent(const RgbImage& im) {
  Extent e;
  for (uint32_t y = 0; y < im.height; ++y)
    for (uint32_t x = 0; x < im.width; ++x)
      if (!isBackground(im, x, y)) {
        e.minX = std::min(e.minX, x);
        e.maxX = std::max(e.maxX, x);
        e.minY = std::min(e.minY, y);
        e.maxY = std::max(e.maxY, y);
        ++e.count;
      }
  return e;
}

// Expected flat shade of a face with outward normal n (facing the camera): ambient 0.25 + 0.75 Lambert.
double expectedShade(double nx, double ny, double nz) {
  const Point3f l = previewLightDirection();
  return 0.25 + 0.75 * std::max(0.0, nx * l.x + ny * l.y + nz * l.z);
}

TEST(Preview, CubeShowsThreeFacesInShadingOrderCentredInThePicture) {
  const FacetSoup cube = fixtures::box(-5, -5, 0, 5, 5, 10);
  RgbImage im;
  renderPreview(cube.corners, 300, 200, im);
  ASSERT_EQ(im.rgb.size(), 300u * 200 * 3);
  for (uint32_t x : {0u, 299u})
    for (uint32_t y : {0u, 199u}) EXPECT_TRUE(isBackground(im, x, y)) << x << "," << y;
  const Extent e = modelExtent(im);
  ASSERT_GT(e.count, 0u);
  // Fitted with a margin and centred: equal margins left/right and top/bottom (to a pixel or two), and
  // the limiting direction (height here: the cube is taller than wide in this view) fills the picture.
  EXPECT_NEAR(static_cast<double>(e.minX), 299.0 - e.maxX, 2.0);
  EXPECT_NEAR(static_cast<double>(e.minY), 199.0 - e.maxY, 2.0);
  EXPECT_GT(e.maxY - e.minY, 160u);

  // The three faces seen from the front right: top (+z), front (-y), right (+x).
  const double top = expectedShade(0, 0, 1), front = expectedShade(0, -1, 0), right = expectedShade(1, 0, 0);
  EXPECT_GT(top, front);
  EXPECT_GT(front, right);
  struct Face {
    double shade;
    double sumX = 0, sumY = 0;
    std::size_t count = 0;
  };
  Face faces[3] = {{top}, {front}, {right}};
  std::size_t other = 0;
  for (uint32_t y = 0; y < im.height; ++y)
    for (uint32_t x = 0; x < im.width; ++x) {
      if (isBackground(im, x, y)) continue;
      bool matched = false;
      for (Face& f : faces)
        if (std::abs(shadeOf(im, x, y) - f.shade) < 1.5 / kPreviewModel[1]) {
          f.sumX += x;
          f.sumY += y;
          ++f.count;
          matched = true;
        }
      other += matched ? 0 : 1;
    }
  for (const Face& f : faces) EXPECT_GT(f.count, 2000u) << "shade " << f.shade;
  EXPECT_LT(other, e.count / 20) << "pixels of no face shade (edges only)";
  const auto cx = [](const Face& f) { return f.sumX / static_cast<double>(f.count); };
  const auto cy = [](const Face& f) { return f.sumY / static_cast<double>(f.count); };
  EXPECT_LT(cy(faces[0]), cy(faces[1]));  // the top above the side faces
  EXPECT_LT(cy(faces[0]), cy(faces[2]));
  EXPECT_LT(cx(faces[1]), cx(faces[2]));  // the front face left of the right face
}

TEST(Preview, SphereIsRoundAndLitFromTheUpperLeft) {
  const FacetSoup ball = fixtures::sphere(10, 96, 48);
  RgbImage im;
  renderPreview(ball.corners, 240, 240, im);
  const Extent e = modelExtent(im);
  const double w = e.maxX - e.minX + 1.0, h = e.maxY - e.minY + 1.0;
  EXPECT_NEAR(w, h, 2.0);
  EXPECT_NEAR(static_cast<double>(e.count) / (w * h), std::numbers::pi / 4, 0.02);  // a disc fills pi/4
  const double centreX = (e.minX + e.maxX) / 2.0, centreY = (e.minY + e.maxY) / 2.0;
  // The brightest pixels lie up and left of the centre (towards the light), the darkest down and right.
  double best = 0, worst = 2;
  for (uint32_t y = 0; y < im.height; ++y)
    for (uint32_t x = 0; x < im.width; ++x)
      if (!isBackground(im, x, y)) {
        best = std::max(best, shadeOf(im, x, y));
        worst = std::min(worst, shadeOf(im, x, y));
      }
  double bx = 0, by = 0, dx = 0, dy = 0, bn = 0, dn = 0;
  for (uint32_t y = e.minY + 2; y + 2 <= e.maxY; ++y)
    for (uint32_t x = e.minX + 2; x + 2 <= e.maxX; ++x) {
      if (isBackground(im, x, y)) continue;
      const double s = shadeOf(im, x, y);
      if (s > best - 0.03) bx += x, by += y, ++bn;
      if (s < worst + 0.03) dx += x, dy += y, ++dn;
    }
  ASSERT_GT(bn, 0);
  ASSERT_GT(dn, 0);
  EXPECT_LT(bx / bn, centreX - 10);
  EXPECT_LT(by / bn, centreY - 10);
  EXPECT_GT(dx / dn, centreX);
  EXPECT_GT(dy / dn, centreY);
  EXPECT_NEAR(worst, 0.25, 0.03);  // ambient only where the light does not reach
}

TEST(Preview, PiecesGiveTheSerialPicture) {
  // Two interpenetrating spheres of 262,144 facets each: eight pieces of the facets, drawn one by one in
  // reverse order or on the thread pool, merge into the serial picture byte for byte.
  FacetSoup soup = fixtures::sphere(10, 512, 256);
  const FacetSoup second = fixtures::sphere(7, 512, 256);
  for (Point3f c : second.corners) soup.corners.push_back({c.x + 9.0f, c.y - 4.0f, c.z + 3.0f});
  const ChunkRunner reversed = fixtures::shuffledRunner(true, 8);
  RgbImage serial, pieces, pooled;
  renderPreview(soup.corners, 800, 480, serial);
  renderPreview(soup.corners, 800, 480, pieces, reversed);
  renderPreview(soup.corners, 800, 480, pooled, parallelChunkRunner());
  EXPECT_EQ(pieces.rgb, serial.rgb);
  EXPECT_EQ(pooled.rgb, serial.rgb);
  EXPECT_GT(modelExtent(serial).count, 800u * 480 / 10);
}

TEST(Preview, SeveralSizesInOnePassAreEachSizeDrawnAlone) {
  // Printer files draw two sizes in one pass over the facets: each picture is the one drawn alone, on
  // one thread or on the pool, including a size whose samples the small facets miss.
  FacetSoup soup = fixtures::sphere(10, 256, 128);
  const FacetSoup second = fixtures::sphere(7, 256, 128);
  for (Point3f c : second.corners) soup.corners.push_back({c.x + 9.0f, c.y - 4.0f, c.z + 3.0f});
  const PreviewSize sizes[3] = {{400, 400}, {800, 480}, {24, 16}};
  RgbImage alone[3], together[3], pooled[3];
  for (int i = 0; i < 3; ++i) renderPreview(soup.corners, sizes[i].width, sizes[i].height, alone[i]);
  renderPreviews(soup.corners, sizes, together);
  renderPreviews(soup.corners, sizes, pooled, parallelChunkRunner());
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(together[i].width, sizes[i].width);
    EXPECT_EQ(together[i].height, sizes[i].height);
    EXPECT_EQ(together[i].rgb, alone[i].rgb) << i;
    EXPECT_EQ(pooled[i].rgb, alone[i].rgb) << i;
    EXPECT_GT(modelExtent(alone[i]).count, sizes[i].width * sizes[i].height / 10) << i;
  }
}

TEST(Preview, EmptyMeshIsBackgroundAndPngDecodesToThePixels) {
  RgbImage im;
  renderPreview({}, 16, 8, im);
  EXPECT_EQ(modelExtent(im).count, 0u);
  const FacetSoup cube = fixtures::box(0, 0, 0, 1, 1, 1);
  renderPreview(cube.corners, 64, 48, im);
  RgbImage again;
  renderPreview(cube.corners, 64, 48, again);
  EXPECT_TRUE(im.rgb == again.rgb);
  std::vector<uint8_t> png;
  encodeRgbPng(im, png);
  std::unique_ptr<spng_ctx, decltype(&spng_ctx_free)> ctx(spng_ctx_new(0), &spng_ctx_free);
  ASSERT_EQ(spng_set_png_buffer(ctx.get(), png.data(), png.size()), 0);
  std::size_t size = 0;
  ASSERT_EQ(spng_decoded_image_size(ctx.get(), SPNG_FMT_RGB8, &size), 0);
  std::vector<uint8_t> rgb(size);
  ASSERT_EQ(spng_decode_image(ctx.get(), rgb.data(), size, SPNG_FMT_RGB8, 0), 0);
  EXPECT_TRUE(rgb == im.rgb);
}

using PreviewCli = tool_test::CliToolBase;

TEST_F(PreviewCli, WritesAPngOfTheGivenSize) {
  const tool_test::RunResult r =
      run({"preview", tool_test::examplePart().string(), "-o", "p.png", "--size", "320x200", "-q"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  const std::string png = tool_test::readBytes(path("p.png"));
  ASSERT_TRUE(png.starts_with("\x89PNG\r\n\x1a\n"));
  const auto be32 = [&](std::size_t at) {
    uint32_t v = 0;
    for (std::size_t i = 0; i < 4; ++i) v = v << 8 | static_cast<uint8_t>(png[at + i]);
    return v;
  };
  EXPECT_EQ(be32(16), 320u);
  EXPECT_EQ(be32(20), 200u);
  const tool_test::RunResult again = run({"preview", tool_test::examplePart().string(), "-o", "p.png", "-q"});
  EXPECT_EQ(again.code(), 1) << again.describe();  // exists: --force needed
  const tool_test::RunResult bad =
      run({"preview", tool_test::examplePart().string(), "-o", "q.png", "--size", "0x5", "-q"});
  EXPECT_EQ(bad.code(), 1) << bad.describe();
  expectNoTemporaries();
}

}  // namespace
}  // namespace toposlice
