// SVG writer (panels, styles, y flip, file policy) and the layer-list parser.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include <unistd.h>

#include "core/slicing/contours.h"
#include "io/contours/svg_writer.h"
#include "io/errors.h"
#include "tests/fixtures/scratch_dir.h"

namespace toposlice {
namespace {

namespace fs = std::filesystem;

using fixtures::readFile;
using fixtures::ScratchDir;

std::size_t countOf(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (std::size_t pos = text.find(what); pos != std::string::npos; pos = text.find(what, pos + 1)) ++n;
  return n;
}

// Every layer: CCW square 0..10, CW square hole 3..7, an open polyline.
LayerContours sampleLayer(double z) {
  LayerContours layer;
  layer.clear(z);
  layer.addPoint({0, 0}, 0);
  layer.addPoint({10, 0}, 1);
  layer.addPoint({10, 10}, 2);
  layer.addPoint({0, 10}, 3);
  layer.endLoop(true);
  layer.addPoint({3, 3}, 4);
  layer.addPoint({3, 7}, 5);
  layer.addPoint({7, 7}, 6);
  layer.addPoint({7, 3}, 7);
  layer.endLoop(true);
  layer.addPoint({1, 1}, 8);
  layer.addPoint({2, 2}, 9);
  layer.endLoop(false);
  return layer;
}

ContourJob sampleJob(uint32_t layerCount) {
  ContourJob job;
  job.name = "demo <part>";
  job.bounds.min = {0, 0, 0};
  job.bounds.max = {10, 10, 1};
  job.layerCount = layerCount;
  return job;
}

void writeSample(const fs::path& path, std::vector<uint32_t> chosen, bool overwrite = false) {
  auto sink = makeSvgWriter(path, sampleJob(5), std::move(chosen), overwrite);
  for (uint32_t k = 0; k < 5; ++k) sink->writeLayer(k, sampleLayer(0.1 * k + 0.05));
  sink->finish();
}

// The text between `open` and the next `close` after it; empty when `open` is missing.
std::string between(const std::string& text, const std::string& open, const std::string& close) {
  const std::size_t from = text.find(open);
  if (from == std::string::npos) return {};
  const std::size_t begin = from + open.size();
  return text.substr(begin, text.find(close, begin) - begin);
}

TEST(SvgWriter, FeaturesGetPartGroupsAndTheSolidPathSubtractsRemovals) {
  ScratchDir dir;
  ContourJob job = sampleJob(1);
  job.features = {{"knob", PartRole::Add}, {"slot", PartRole::Remove}};
  std::vector<LayerContours> parts(3);
  parts[0] = sampleLayer(0.05);
  parts[1].clear(0.05);
  for (const Point2d p : {Point2d{10, 0}, Point2d{12, 0}, Point2d{12, 2}, Point2d{10, 2}})
    parts[1].addPoint(p, 0);
  parts[1].endLoop(true);
  parts[2].clear(0.05);
  for (const Point2d p : {Point2d{1, 4}, Point2d{2, 4}, Point2d{2, 6}, Point2d{1, 6}})
    parts[2].addPoint(p, 0);
  parts[2].endLoop(true);
  auto sink = makeSvgWriter(dir / "f.svg", job, {0}, false);
  sink->writeLayer(0, parts);
  sink->finish();
  const std::string svg = readFile(dir / "f.svg");

  EXPECT_EQ(
      countOf(svg, "<g id=\"layer-0-part-1\" class=\"part model\"><title>model demo &lt;part&gt;</title>"),
      1u);
  EXPECT_EQ(countOf(svg, "<g id=\"layer-0-part-2\" class=\"part add\"><title>add knob</title>"), 1u);
  EXPECT_EQ(countOf(svg, "<g id=\"layer-0-part-3\" class=\"part remove\"><title>remove slot</title>"), 1u);
  // The model's hole and open polyline stay in the model's group; each feature loop is an outline.
  const std::string model = between(svg, "class=\"part model\">", "</g>");
  EXPECT_EQ(countOf(model, "class=\"hole\""), 1u);
  EXPECT_EQ(countOf(model, "class=\"open\""), 1u);
  EXPECT_EQ(countOf(between(svg, "class=\"part add\">", "</g>"), "<polygon class=\"add\""), 1u);
  const std::string removal = between(svg, "class=\"part remove\">", "</g>");
  EXPECT_EQ(countOf(removal, "<polygon class=\"remove\""), 1u);
  EXPECT_EQ(countOf(removal, "stroke-dasharray"), 1u);

  // Panel origin (0.5, 1.22) with +y up: the removal (1,4) (2,4) (2,6) (1,6) is drawn reversed from its
  // first point, in its outline and in the solid path, which holds all three parts.
  const std::string reversed = "1.5,7.22 1.5,5.22 2.5,5.22 2.5,7.22";
  EXPECT_EQ(between(removal, "points=\"", "\""), reversed);
  const std::string solid = between(svg, "<path class=\"solid\"", "/>");
  EXPECT_EQ(countOf(solid, " clip-path=\"url(#clip-layer-0)\""), 1u);
  EXPECT_EQ(countOf(solid, " fill-rule=\"nonzero\""), 1u);
  EXPECT_EQ(countOf(solid, "M1.5,7.22 L1.5,5.22 2.5,5.22 2.5,7.22 Z"), 1u);
  EXPECT_EQ(countOf(solid, "M"), 4u);  // outer, hole, add-on, removal
  // The clip is the model and add-ons only, so negative winding (a removal beyond them) stays empty.
  const std::string clip =
      between(svg, "<clipPath id=\"clip-layer-0\"><path clip-rule=\"nonzero\" d=\"", "\"");
  EXPECT_EQ(countOf(clip, "M"), 3u);
  EXPECT_EQ(countOf(clip, "M1.5,7.22"), 0u);
}

TEST(SvgWriter, WithoutFeaturesNoPartGroupsOrClip) {
  ScratchDir dir;
  writeSample(dir / "s.svg", {0, 1});
  const std::string svg = readFile(dir / "s.svg");
  EXPECT_EQ(countOf(svg, "class=\"part"), 0u);
  EXPECT_EQ(countOf(svg, "clip"), 0u);
}

TEST(SvgWriter, OnePanelPerChosenLayer) {
  ScratchDir dir;
  writeSample(dir / "s.svg", {4, 0, 2, 2, 9});  // unsorted, a duplicate, one out of range
  const std::string svg = readFile(dir / "s.svg");
  EXPECT_EQ(svg.rfind("<?xml", 0), 0u);
  EXPECT_NE(svg.find("<title>demo &lt;part&gt;</title>"), std::string::npos);
  EXPECT_EQ(svg.substr(svg.size() - 7), "</svg>\n");
  EXPECT_EQ(countOf(svg, "<path "), 3u);
  EXPECT_EQ(countOf(svg, "<g id=\"layer-"), 3u);
  // Panels in layer order with their captions.
  const std::size_t p0 = svg.find(">layer 0, z = 0.05<");
  const std::size_t p2 = svg.find(">layer 2, z = 0.25<");
  const std::size_t p4 = svg.find(">layer 4, z = 0.45<");
  ASSERT_NE(p0, std::string::npos);
  ASSERT_NE(p2, std::string::npos);
  ASSERT_NE(p4, std::string::npos);
  EXPECT_LT(p0, p2);
  EXPECT_LT(p2, p4);
  EXPECT_EQ(svg.find("layer 1,"), std::string::npos);
  EXPECT_EQ(svg.find("layer 3,"), std::string::npos);
}

TEST(SvgWriter, HolesAndOpenLinesStyledApart) {
  ScratchDir dir;
  writeSample(dir / "s.svg", {1});
  const std::string svg = readFile(dir / "s.svg");
  // One filled path per panel holding both closed loops, nonzero so the hole stays empty.
  ASSERT_EQ(countOf(svg, "<path "), 1u);
  const std::size_t path = svg.find("<path ");
  const std::string pathElement = svg.substr(path, svg.find("/>", path) - path);
  EXPECT_NE(pathElement.find("fill-rule=\"nonzero\""), std::string::npos);
  EXPECT_NE(pathElement.find("class=\"solid\""), std::string::npos);
  EXPECT_EQ(countOf(pathElement, "M"), 2u);
  EXPECT_EQ(countOf(pathElement, "Z"), 2u);
  // The hole outline: its own element, dashed red, unfilled; the open polyline orange, unfilled.
  ASSERT_EQ(countOf(svg, "class=\"hole\""), 1u);
  const std::size_t hole = svg.find("class=\"hole\"");
  const std::string holeElement = svg.substr(hole, svg.find("/>", hole) - hole);
  EXPECT_NE(holeElement.find("stroke-dasharray"), std::string::npos);
  EXPECT_NE(holeElement.find("fill=\"none\""), std::string::npos);
  EXPECT_EQ(pathElement.find("stroke-dasharray"), std::string::npos);
  ASSERT_EQ(countOf(svg, "<polyline class=\"open\""), 1u);
  EXPECT_NE(svg.find("<polyline class=\"open\" fill=\"none\" stroke=\"#ff7f0e\""), std::string::npos);
  // +y is up: with margin 0.5 and caption 0.72 (size 10), model (0,0) is the panel's bottom-left corner
  // at (0.5, 1.22 + 10) and (0,10) its top-left corner.
  EXPECT_NE(pathElement.find("d=\"M0.5,11.22 L10.5,11.22 10.5,1.22 0.5,1.22 Z"), std::string::npos)
      << pathElement;
}

TEST(SvgWriter, EmptySelectionAndEmptyLayer) {
  ScratchDir dir;
  {
    auto sink = makeSvgWriter(dir / "none.svg", sampleJob(2), {}, false);
    sink->writeLayer(0, sampleLayer(0.05));
    sink->writeLayer(1, sampleLayer(0.15));
    sink->finish();
  }
  EXPECT_EQ(countOf(readFile(dir / "none.svg"), "<path "), 0u);
  {
    auto sink = makeSvgWriter(dir / "empty.svg", sampleJob(1), {0}, false);
    LayerContours empty;
    empty.clear(0.05);
    sink->writeLayer(0, empty);
    sink->finish();
  }
  const std::string svg = readFile(dir / "empty.svg");
  EXPECT_EQ(countOf(svg, "<path "), 1u);
  EXPECT_NE(svg.find("d=\"\""), std::string::npos);
}

TEST(SvgWriter, DeterministicAndAtomic) {
  ScratchDir dir;
  writeSample(dir / "a.svg", {0, 2});
  writeSample(dir / "b.svg", {2, 0});
  EXPECT_EQ(readFile(dir / "a.svg"), readFile(dir / "b.svg"));
  {
    auto sink = makeSvgWriter(dir / "c.svg", sampleJob(5), {0}, false);
    sink->writeLayer(0, sampleLayer(0.05));
    EXPECT_FALSE(fs::exists(dir / "c.svg"));
    EXPECT_EQ(dir.count(), 3u);  // a.svg, b.svg and the temporary
  }
  EXPECT_FALSE(fs::exists(dir / "c.svg"));
  EXPECT_EQ(dir.count(), 2u);
}

TEST(SvgWriter, ExistingFileNeedsOverwrite) {
  ScratchDir dir;
  writeSample(dir / "a.svg", {0});
  try {
    writeSample(dir / "a.svg", {1});
    FAIL() << "no OutputError";
  } catch (const OutputError& e) {
    EXPECT_EQ(std::string(e.what()),
              (dir / "a.svg").string() + ": already exists (use --force to overwrite)");
  }
  EXPECT_NE(readFile(dir / "a.svg").find(">layer 0,"), std::string::npos);
  writeSample(dir / "a.svg", {1}, true);
  EXPECT_NE(readFile(dir / "a.svg").find(">layer 1,"), std::string::npos);
  EXPECT_EQ(dir.count(), 1u);
}

std::vector<uint32_t> range(uint32_t first, uint32_t last) {
  std::vector<uint32_t> v;
  for (uint32_t k = first; k <= last; ++k) v.push_back(k);
  return v;
}

TEST(SvgLayerList, ParsesIndicesRangesAndNames) {
  std::vector<uint32_t> out;
  std::string error;
  ASSERT_TRUE(parseLayerList("0,10,20-30,last", 100, out, error)) << error;
  std::vector<uint32_t> expected = {0, 10};
  for (uint32_t k : range(20, 30)) expected.push_back(k);
  expected.push_back(99);
  EXPECT_EQ(out, expected);

  ASSERT_TRUE(parseLayerList("mid", 100, out, error));
  EXPECT_EQ(out, std::vector<uint32_t>{50});
  ASSERT_TRUE(parseLayerList("mid,last", 1, out, error));
  EXPECT_EQ(out, std::vector<uint32_t>{0});
  ASSERT_TRUE(parseLayerList(" 7 , 3 ,7, 5-5 ", 10, out, error));
  EXPECT_EQ(out, (std::vector<uint32_t>{3, 5, 7}));
  ASSERT_TRUE(parseLayerList("mid-last", 6, out, error));
  EXPECT_EQ(out, range(3, 5));
  ASSERT_TRUE(parseLayerList("0 - 2", 6, out, error));
  EXPECT_EQ(out, range(0, 2));
}

TEST(SvgLayerList, RejectsBadLists) {
  struct Case {
    const char* text;
    uint32_t layerCount;
    const char* reason;
  };
  const Case cases[] = {
      {"", 10, "no layers given"},
      {"  ", 10, "no layers given"},
      {"1,,2", 10, "item 2 is empty"},
      {"1,", 10, "item 2 is empty"},
      {"abc", 10, "\"abc\" is not a layer number, \"last\" or \"mid\""},
      {"-3", 10, "\"-3\" is not a range \"a-b\""},
      {"3-", 10, "\"3-\" is not a range"},
      {"1-2-3", 10, "\"1-2-3\" is not a range"},
      {"1-x", 10, "\"x\" is not a layer number"},
      {"1-10", 10, "layer 10 is out of range (layers 0-9)"},
      {"+1", 10, "\"+1\" is not a layer number"},
      {"1.5", 10, "\"1.5\" is not a layer number"},
      {"8-3", 10, "range \"8-3\" runs backwards"},
      {"10", 10, "layer 10 is out of range (layers 0-9)"},
      {"99999999999999999999999", 10, "is out of range (layers 0-9)"},
      {"0", 0, "the model has no layers"},
  };
  for (const Case& c : cases) {
    std::vector<uint32_t> out = {42};
    std::string error;
    EXPECT_FALSE(parseLayerList(c.text, c.layerCount, out, error)) << c.text;
    EXPECT_TRUE(out.empty()) << c.text;
    EXPECT_NE(error.find(c.reason), std::string::npos) << c.text << " -> " << error;
  }
}

}  // namespace
}  // namespace toposlice
