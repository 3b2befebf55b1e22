// NanoDLP plate archives read back with libzip (not the minizip that writes them): every layer PNG equals
// the PNG-directory layer of the same job, the JSON files parse and agree with the layers, the bytes do
// not depend on the thread count; and the per-layer figures on masks whose islands are known.
#include <gtest/gtest.h>
#include <zip.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "io/coders/mask_png.h"
#include "io/masks/nanodlp_writer.h"
#include "io/readers/stl_writer.h"
#include "tests/fixtures/shapes.h"
#include "tests/tool_runner.h"

namespace toposlice {
namespace {

namespace fs = std::filesystem;

std::map<std::string, std::string> zipEntries(const fs::path& file) {
  std::map<std::string, std::string> entries;
  int err = 0;
  zip_t* zip = zip_open(file.c_str(), ZIP_RDONLY | ZIP_CHECKCONS, &err);
  EXPECT_NE(zip, nullptr) << "libzip error " << err;
  if (zip == nullptr) return entries;
  for (zip_int64_t i = 0; i < zip_get_num_entries(zip, 0); ++i) {
    zip_stat_t st;
    zip_stat_init(&st);
    if (zip_stat_index(zip, static_cast<zip_uint64_t>(i), 0, &st) != 0) continue;
    std::string data(st.size, '\0');
    zip_file_t* f = zip_fopen_index(zip, static_cast<zip_uint64_t>(i), 0);
    EXPECT_NE(f, nullptr) << st.name;
    if (f == nullptr) continue;
    EXPECT_EQ(zip_fread(f, data.data(), st.size), static_cast<zip_int64_t>(st.size)) << st.name;
    zip_fclose(f);
    entries[st.name] = data;
  }
  zip_close(zip);
  return entries;
}

uint32_t be32(const std::string& b, std::size_t at) {
  uint32_t v = 0;
  for (std::size_t i = 0; i < 4; ++i) v = v << 8 | static_cast<uint8_t>(b[at + i]);
  return v;
}

MaskImage maskOf(const std::vector<std::string>& rowsTopDown) {
  MaskImage m;
  m.height = static_cast<uint32_t>(rowsTopDown.size());
  m.width = static_cast<uint32_t>(rowsTopDown[0].size());
  for (uint32_t r = m.height; r-- > 0;)
    for (char c : rowsTopDown[r]) m.pixels.push_back(c == '#' ? 255 : c == '+' ? 51 : 0);
  return m;
}

TEST(NanoDlpInfo, IslandsAreasAndBoundsOfKnownMasks) {
  // Three islands: a 2 x 2 block, a U shape whose arms join at the bottom, a grey pixel touching the
  // block only diagonally (4-connected: separate).
  const MaskImage m = maskOf({
      "........",
      ".##.#.#.",
      ".##.#.#.",
      "+...###.",
      "........",
  });
  const NanoDlpLayerInfo info = nanoDlpLayerInfo(m, 0.5);
  EXPECT_EQ(info.areaCount, 3u);
  EXPECT_DOUBLE_EQ(info.totalSolidArea, (4 + 7 + 0.2) * 0.25);
  EXPECT_DOUBLE_EQ(info.largestArea, 7 * 0.25);
  EXPECT_DOUBLE_EQ(info.smallestArea, 0.2 * 0.25);
  EXPECT_EQ(info.minX, 0u);
  EXPECT_EQ(info.maxX, 6u);
  EXPECT_EQ(info.minY, 1u);  // picture rows, top first
  EXPECT_EQ(info.maxY, 3u);
  const NanoDlpLayerInfo dark = nanoDlpLayerInfo(maskOf({"....", "...."}), 0.5);
  EXPECT_EQ(dark.areaCount, 0u);
  EXPECT_EQ(dark.totalSolidArea, 0.0);
}

using NanoDlpCli = tool_test::CliToolBase;

TEST_F(NanoDlpCli, LayersEqualThePngLayersOfTheSameJob) {
  // The PNG folder in the NanoDLP file's landscape frame (the sl1 preset's display is portrait).
  const std::vector<std::string> args{"slice",     tool_test::examplePart().string(),
                                      "-H",        "0.1",
                                      "--printer", "sl1",
                                      "--set",     "display_orientation=landscape",
                                      "--set",     "display_mirror_x=0",
                                      "-q"};
  auto a = args, b = args, png = args;
  a.insert(a.end(), {"--masks", "p.nanodlp", "--threads", "2"});
  b.insert(b.end(), {"--masks", "p1.nanodlp", "--threads", "1"});
  png.insert(png.end(), {"--masks", "png"});
  for (const auto* cmd : {&a, &b, &png}) {
    const tool_test::RunResult r = run(*cmd);
    ASSERT_EQ(r.code(), 0) << r.describe();
  }
  EXPECT_TRUE(tool_test::readBytes(path("p.nanodlp")) == tool_test::readBytes(path("p1.nanodlp")))
      << "1 and 2 threads differ";
  const auto entries = zipEntries(path("p.nanodlp"));
  const auto folder = tool_test::directoryContents(path("png"));
  ASSERT_EQ(folder.size(), 62u);  // ceil(6.2 / 0.1)
  for (const char* name :
       {"meta.json", "plate.json", "profile.json", "info.json", "options.json", "slicer.json", "3d.png"})
    EXPECT_EQ(entries.count(name), 1u) << name;
  EXPECT_EQ(entries.size(), folder.size() + 7);
  std::size_t k = 0;
  for (const auto& [name, bytes] : folder) {  // names sort in layer order
    const auto it = entries.find(std::to_string(k + 1) + ".png");
    ASSERT_NE(it, entries.end()) << k;
    EXPECT_TRUE(it->second == bytes) << "layer " << k + 1 << " differs from " << name;
    ++k;
  }
  const auto meta = nlohmann::json::parse(entries.at("meta.json"));
  EXPECT_EQ(meta["FormatVersion"], 1);
  EXPECT_EQ(meta["Program"], "toposlice");
  const auto plate = nlohmann::json::parse(entries.at("plate.json"));
  EXPECT_EQ(plate["LayersCount"], 62);
  const auto info = nlohmann::json::parse(entries.at("info.json"));
  ASSERT_EQ(info.size(), 62u);
  double total = 0;
  for (const auto& layer : info) {
    // Nothing in the part floats, so no layer is dark (a dark layer's info: NanoDlpLayerInfo above).
    EXPECT_GT(layer["AreaCount"].get<int>(), 0);
    EXPECT_GT(layer["TotalSolidArea"].get<double>(), 0);
    EXPECT_LE(layer["SmallestArea"].get<double>(), layer["LargestArea"].get<double>());
    total += layer["TotalSolidArea"].get<double>();
  }
  EXPECT_DOUBLE_EQ(plate["TotalSolidArea"].get<double>(), total);
  const std::string preview = entries.at("3d.png");
  EXPECT_TRUE(preview.starts_with("\x89PNG\r\n\x1a\n"));
  EXPECT_EQ(be32(preview, 16), 200u);  // IHDR width, height
  EXPECT_EQ(be32(preview, 20), 100u);
  const auto profile = nlohmann::json::parse(entries.at("profile.json"));
  EXPECT_EQ(profile["TransitionalLayer"], 8);  // the sl1 preset's 10 faded layers - 2
  EXPECT_EQ(profile["BottomLiftDistance"], 5.0);
  EXPECT_EQ(profile["BottomLiftSpeed"], 65.0);
  // NanoDLP's own names, as UVtools and mslicer read them (mslicer: whole numbers without a point).
  EXPECT_EQ(profile.at("Depth").dump(), "100");
  EXPECT_EQ(profile.at("SupportDepth").dump(), "100");
  EXPECT_EQ(profile.at("WaitHeight").dump(), "5");
  EXPECT_EQ(profile.at("SupportWaitHeight").dump(), "5");
  EXPECT_EQ(profile.at("SupportLayerNumber").dump(), "1");
  // The options readers take the display from: UVtools reads slicer.json, NanoDLP options.json.
  EXPECT_EQ(entries.at("options.json"), entries.at("slicer.json"));
  const auto options = nlohmann::json::parse(entries.at("slicer.json"));
  EXPECT_EQ(options.at("PWidth"), 2560);  // the sl1 preset's display, landscape
  EXPECT_EQ(options.at("PHeight"), 1440);
  EXPECT_NEAR(options.at("XPixelSize").get<double>(), 0.04725, 1e-12);
  EXPECT_NEAR(options.at("YPixelSize").get<double>(), 0.04725, 1e-12);
  EXPECT_EQ(options.at("Thickness"), 100);
  EXPECT_EQ(options.at("LayerCount"), 62);
  EXPECT_EQ(options.at("ImageMirror"), 0);
  EXPECT_EQ(options.at("Boundary"), (nlohmann::json{{"XMin", plate["XMin"]},
                                                    {"XMax", plate["XMax"]},
                                                    {"YMin", plate["YMin"]},
                                                    {"YMax", plate["YMax"]},
                                                    {"ZMin", plate["ZMin"]},
                                                    {"ZMax", plate["ZMax"]}}));
  // The plate's bounds: mm from the display's centre (y down the picture), the union of the layers'
  // pixel bounds, as UVtools computes them from the pictures.
  uint32_t minX = UINT32_MAX, minY = UINT32_MAX, maxX = 0, maxY = 0;
  for (const auto& layer : info) {
    minX = std::min(minX, layer["MinX"].get<uint32_t>());
    minY = std::min(minY, layer["MinY"].get<uint32_t>());
    maxX = std::max(maxX, layer["MaxX"].get<uint32_t>());
    maxY = std::max(maxY, layer["MaxY"].get<uint32_t>());
  }
  const double p = 0.04725, halfWidth = 2560 * p / 2, halfHeight = 1440 * p / 2;
  EXPECT_NEAR(plate["XMin"].get<double>(), minX * p - halfWidth, 1e-9);
  EXPECT_NEAR(plate["XMax"].get<double>(), (maxX + 1) * p - halfWidth, 1e-9);
  EXPECT_NEAR(plate["YMin"].get<double>(), minY * p - halfHeight, 1e-9);
  EXPECT_NEAR(plate["YMax"].get<double>(), (maxY + 1) * p - halfHeight, 1e-9);
  EXPECT_LT(plate["XMin"].get<double>(), 0);  // the part sits about the display's centre
  EXPECT_GT(plate["XMax"].get<double>(), 0);
  EXPECT_NEAR(plate["ZMax"].get<double>(), 6.2, 1e-9);
  expectNoTemporaries();
  // A stack shorter than the fade: as many transition layers as there are after the bottom one.
  auto one = args;
  one.insert(one.end(), {"--layers", "1", "--masks", "one.nanodlp"});
  one.erase(one.begin() + 2, one.begin() + 4);  // -H 0.1
  ASSERT_EQ(run(one).code(), 0);
  EXPECT_EQ(nlohmann::json::parse(zipEntries(path("one.nanodlp")).at("profile.json"))["TransitionalLayer"],
            0);
}

// The preview shows what is printed: the model and its add-ons (it drew the model alone).
TEST_F(NanoDlpCli, ThePreviewShowsTheAddOns) {
  writeBinaryStl(path("tab.stl"), fixtures::box(-3, -3, 6, 3, 3, 12), "tab", false);  // on top of the part
  const auto preview = [&](const std::string& name, bool addOn) {
    std::vector<std::string> args{
        "slice", tool_test::examplePart().string(), "-H", "0.5", "--printer", "sl1", "--masks", name, "-q"};
    if (addOn) args.insert(args.end(), {"--add", "tab.stl"});
    const tool_test::RunResult r = run(args);
    EXPECT_EQ(r.code(), 0) << r.describe();
    return zipEntries(path(name)).at("3d.png");
  };
  EXPECT_NE(preview("with.nanodlp", true), preview("without.nanodlp", false));
}

}  // namespace
}  // namespace toposlice
