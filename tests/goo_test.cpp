// GOO files read back by a decoder written here from Elegoo's "GOO format specification" v1.2 alone
// (header table, layer definition, chunk types and lengths, delimiters, ending string), sharing no code
// with io/masks/goo_writer.cpp. Multi-byte fields are read big-endian, the checksum as the complement of
// the 8-bit sum of the chunk bytes (what the format's public readers check).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "io/coders/mask_png.h"
#include "io/masks/goo_writer.h"
#include "io/masks/mask_sink.h"
#include "tests/fixtures/scratch_dir.h"
#include "tests/fixtures/shapes.h"
#include "tests/tool_runner.h"

namespace toposlice {
namespace {

namespace fs = std::filesystem;

// ---------------------------------------------------------------------------------------------------
// The decoder

class Reader {
 public:
  explicit Reader(const std::string& bytes) : b_(bytes) {}
  bool ok() const { return ok_; }
  std::size_t at() const { return at_; }
  uint64_t be(int n) {
    if (!has(n)) return 0;
    uint64_t v = 0;
    for (int i = 0; i < n; ++i) v = v << 8 | static_cast<uint8_t>(b_[at_++]);
    return v;
  }
  float f32() {
    const uint32_t v = static_cast<uint32_t>(be(4));
    float f;
    std::memcpy(&f, &v, 4);
    return f;
  }
  std::string raw(std::size_t n) {
    if (!has(n)) return {};
    std::string s = b_.substr(at_, n);
    at_ += n;
    return s;
  }
  std::string text(std::size_t n) {  // a zero-terminated string in a fixed field
    const std::string s = raw(n);
    return s.substr(0, s.find('\0'));
  }

 private:
  bool has(std::size_t n) {
    if (at_ + n > b_.size()) ok_ = false;
    return ok_;
  }
  const std::string& b_;
  std::size_t at_ = 0;
  bool ok_ = true;
};

struct GooHeader {
  std::string version, magic, software, softwareVersion, fileTime, printerName, printerType, profile;
  uint64_t antiAliasing = 0, greyLevel = 0, blurLevel = 0;
  std::string smallPreview, bigPreview, delimiter1, delimiter2;
  uint64_t layers = 0, resX = 0, resY = 0, mirrorX = 0, mirrorY = 0;
  float sizeX = 0, sizeY = 0, sizeZ = 0, layerThickness = 0, exposure = 0;
  uint64_t delayMode = 0;
  float turnOff = 0, bottomBeforeLift = 0, bottomAfterLift = 0, bottomAfterRetract = 0, beforeLift = 0,
        afterLift = 0, afterRetract = 0, bottomExposure = 0;
  uint64_t bottomLayers = 0;
  float motion[16] = {};  // fields 35-50: bottom lift distance ... second retract speed
  uint64_t bottomPwm = 0, pwm = 0, advanceMode = 0, printTime = 0;
  float volume = 0, weight = 0, price = 0;
  std::string priceUnit;
  uint64_t layerContentOffset = 0, grayScaleLevel = 0, transitionLayers = 0;
};

struct GooLayer {
  uint64_t pause = 0;
  float pauseZ = 0, z = 0, exposure = 0, offTime = 0, beforeLift = 0, afterLift = 0, afterRetract = 0;
  float liftDistance = 0, liftSpeed = 0, lift2Distance = 0, lift2Speed = 0;
  float retractDistance = 0, retractSpeed = 0, retract2Distance = 0, retract2Speed = 0;
  uint64_t pwm = 0;
  std::vector<uint8_t> pixels;  // top row first, as the chunks run
};

// Decodes the chunks of one layer (after the 0x55, before the checksum) into exactly `count` pixels.
std::string decodeChunks(const std::string& data, uint64_t count, std::vector<uint8_t>& pixels) {
  pixels.clear();
  pixels.reserve(count);
  uint8_t previous = 0;
  std::size_t i = 0;
  const auto next = [&](uint8_t& v) {
    if (i >= data.size()) return false;
    v = static_cast<uint8_t>(data[i++]);
    return true;
  };
  while (i < data.size()) {
    uint8_t b0 = 0, b = 0;
    next(b0);
    const int type = b0 >> 6, form = (b0 >> 4) & 3;
    uint8_t value = 0;
    uint64_t length = 0;
    if (type == 2) {  // difference from the previous pixel
      const int diff = b0 & 0xF;
      value = static_cast<uint8_t>(form & 2 ? previous - diff : previous + diff);
      length = 1;
      if (form & 1) {
        if (!next(b)) return "truncated diff chunk";
        length = b;
      }
    } else {
      if (type == 0) value = 0;
      if (type == 3) value = 0xFF;
      if (type == 1 && !next(value)) return "truncated grey chunk";
      if (type == 1 && (value == 0 || value == 0xFF)) return "grey chunk holds 0 or 255";
      for (int k = 0; k < form; ++k) {
        if (!next(b)) return "truncated run length";
        length = length << 8 | b;
      }
      length = length << 4 | (b0 & 0xF);
    }
    if (length == 0) return "empty run at byte " + std::to_string(i);
    if (pixels.size() + length > count) return "runs exceed the image";
    pixels.insert(pixels.end(), length, value);
    previous = value;
  }
  if (pixels.size() != count)
    return "runs cover " + std::to_string(pixels.size()) + " of " + std::to_string(count);
  return {};
}

const std::string kDelimiter("\x0D\x0A", 2);
const std::string kEnding("\x00\x00\x00\x07\x00\x00\x00\x44\x4C\x50\x00", 11);

// Reads a whole file; returns an error text, empty when every field, checksum and delimiter is right.
std::string decodeGoo(const std::string& bytes, GooHeader& h, std::vector<GooLayer>& layers) {
  Reader r(bytes);
  h.version = r.raw(4);
  h.magic = r.raw(8);
  h.software = r.text(32);
  h.softwareVersion = r.text(24);
  h.fileTime = r.text(24);
  h.printerName = r.text(32);
  h.printerType = r.text(32);
  h.profile = r.text(32);
  h.antiAliasing = r.be(2);
  h.greyLevel = r.be(2);
  h.blurLevel = r.be(2);
  h.smallPreview = r.raw(2 * 116 * 116);
  h.delimiter1 = r.raw(2);
  h.bigPreview = r.raw(2 * 290 * 290);
  h.delimiter2 = r.raw(2);
  h.layers = r.be(4);
  h.resX = r.be(2);
  h.resY = r.be(2);
  h.mirrorX = r.be(1);
  h.mirrorY = r.be(1);
  h.sizeX = r.f32();
  h.sizeY = r.f32();
  h.sizeZ = r.f32();
  h.layerThickness = r.f32();
  h.exposure = r.f32();
  h.delayMode = r.be(1);
  h.turnOff = r.f32();
  h.bottomBeforeLift = r.f32();
  h.bottomAfterLift = r.f32();
  h.bottomAfterRetract = r.f32();
  h.beforeLift = r.f32();
  h.afterLift = r.f32();
  h.afterRetract = r.f32();
  h.bottomExposure = r.f32();
  h.bottomLayers = r.be(4);
  for (float& m : h.motion) m = r.f32();
  h.bottomPwm = r.be(2);
  h.pwm = r.be(2);
  h.advanceMode = r.be(1);
  h.printTime = r.be(4);
  h.volume = r.f32();
  h.weight = r.f32();
  h.price = r.f32();
  h.priceUnit = r.text(8);
  h.layerContentOffset = r.be(4);
  h.grayScaleLevel = r.be(1);
  h.transitionLayers = r.be(2);
  if (!r.ok()) return "header truncated";
  if (h.delimiter1 != kDelimiter || h.delimiter2 != kDelimiter) return "preview delimiter";
  if (r.at() != h.layerContentOffset) return "layer content offset " + std::to_string(h.layerContentOffset);
  layers.clear();
  for (uint64_t k = 0; k < h.layers; ++k) {
    GooLayer l;
    l.pause = r.be(2);
    l.pauseZ = r.f32();
    l.z = r.f32();
    l.exposure = r.f32();
    l.offTime = r.f32();
    l.beforeLift = r.f32();
    l.afterLift = r.f32();
    l.afterRetract = r.f32();
    l.liftDistance = r.f32();
    l.liftSpeed = r.f32();
    l.lift2Distance = r.f32();
    l.lift2Speed = r.f32();
    l.retractDistance = r.f32();
    l.retractSpeed = r.f32();
    l.retract2Distance = r.f32();
    l.retract2Speed = r.f32();
    l.pwm = r.be(2);
    if (r.raw(2) != kDelimiter) return "layer " + std::to_string(k) + ": definition delimiter";
    const uint64_t size = r.be(4);
    if (!r.ok() || size < 2) return "layer " + std::to_string(k) + ": data size";
    const std::string data = r.raw(size);
    if (!r.ok()) return "layer " + std::to_string(k) + ": data truncated";
    if (static_cast<uint8_t>(data[0]) != 0x55) return "layer " + std::to_string(k) + ": no 0x55";
    const std::string chunks = data.substr(1, size - 2);
    uint8_t sum = 0;
    for (char c : chunks) sum = static_cast<uint8_t>(sum + static_cast<uint8_t>(c));
    if (static_cast<uint8_t>(data.back()) != static_cast<uint8_t>(~sum))
      return "layer " + std::to_string(k) + ": checksum";
    if (r.raw(2) != kDelimiter) return "layer " + std::to_string(k) + ": data delimiter";
    const std::string error = decodeChunks(chunks, h.resX * h.resY, l.pixels);
    if (!error.empty()) return "layer " + std::to_string(k) + ": " + error;
    layers.push_back(std::move(l));
  }
  if (r.raw(11) != kEnding) return "ending string";
  if (r.at() != bytes.size()) return "bytes after the ending string";
  return {};
}

std::string readFile(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

// The mask's rows top-down, as the layer's chunks run.
std::vector<uint8_t> topDown(const MaskImage& m) {
  std::vector<uint8_t> out;
  for (uint32_t r = m.height; r-- > 0;)
    out.insert(out.end(), m.pixels.begin() + std::size_t{r} * m.width,
               m.pixels.begin() + std::size_t{r + 1} * m.width);
  return out;
}

// ---------------------------------------------------------------------------------------------------
// The specification's examples

std::vector<uint8_t> run(uint8_t value, uint32_t length) {
  std::vector<uint8_t> out;
  appendGooRun(out, value, length);
  return out;
}

TEST(GooSpec, EncoderWritesTheSpecificationsExampleChunks) {
  // "pixel value is 0x0; run-length is 0x555657f": 00 11 1111, 0x55 0x56 0x57
  EXPECT_EQ(run(0, 0x555657F), (std::vector<uint8_t>{0x3F, 0x55, 0x56, 0x57}));
  // "pixel value is 0xaa; run-length is 0xbbcc155": 01 11 0101, 0xaa 0xbb 0xcc 0x15
  EXPECT_EQ(run(0xAA, 0xBBCC155), (std::vector<uint8_t>{0x75, 0xAA, 0xBB, 0xCC, 0x15}));
  // "pixel value is 0x0; run-length is 0x5": 00 00 0101
  EXPECT_EQ(run(0, 5), (std::vector<uint8_t>{0x05}));
  // 0xff chunks with the 1-byte length form (the specification's own 0xff example lists a fourth length
  // byte and a 36-bit length, which its 4 + 24-bit form cannot hold).
  EXPECT_EQ(run(0xFF, 0xCCB), (std::vector<uint8_t>{0xDB, 0xCC}));
  EXPECT_EQ(run(0xFF, 0xCCBBAA1), (std::vector<uint8_t>{0xF1, 0xCC, 0xBB, 0xAA}));
  // Longer than 28 bits: split.
  const std::vector<uint8_t> split = run(0, kGooMaxRun + 3);
  EXPECT_EQ(split, (std::vector<uint8_t>{0x3F, 0xFF, 0xFF, 0xFF, 0x03}));
  // Checksum: complement of the 8-bit sum.
  const uint8_t chunk[] = {0x3F, 0x55, 0x56, 0x57};
  EXPECT_EQ(gooChecksum(chunk, 4), static_cast<uint8_t>(~static_cast<uint8_t>(0x3F + 0x55 + 0x56 + 0x57)));
}

TEST(GooSpec, DecoderReadsTheSpecificationsExampleChunks) {
  std::vector<uint8_t> px;
  // 0xaa x 3 (grey, 4-bit length), then "positive diff value is 1; run-length is 1" (0xab), "positive
  // diff value is 2; run-length is 0xff" (0xad x 255), "negative diff 1, run 1" (0xac), "negative diff 2;
  // run-length is 0xee" (0xaa x 238), 0 x 5.
  const std::string chunks("\x43\xAA\x81\x92\xFF\xA1\xB2\xEE\x05", 9);
  ASSERT_EQ(decodeChunks(chunks, 3 + 1 + 255 + 1 + 238 + 5, px), "");
  EXPECT_EQ(px[0], 0xAA);
  EXPECT_EQ(px[3], 0xAB);
  EXPECT_EQ(px[4], 0xAD);
  EXPECT_EQ(px[258], 0xAD);
  EXPECT_EQ(px[259], 0xAC);
  EXPECT_EQ(px[260], 0xAA);
  EXPECT_EQ(px[497], 0xAA);
  EXPECT_EQ(px[498], 0);
  EXPECT_NE(decodeChunks(chunks, 600, px), "");  // the runs must cover the image exactly
}

// ---------------------------------------------------------------------------------------------------
// Field by field

TEST(GooWriter, HeaderFieldsLayerDefinitionsAndImagesReadBack) {
  fixtures::ScratchDir dir;
  const FacetSoup cube = fixtures::box(0, 0, 0, 10, 10, 10);
  MaskJob job;
  job.name = "part";
  job.grid.pixel = 0.05;
  job.grid.width = 3300;  // 165.00 mm, the specification's example X size
  job.grid.height = 1426;
  job.grid.mirrorX = true;
  job.layerHeight = 0.05;
  job.layerCount = 3;
  job.exposureTime = 2.5;
  job.initialExposureTime = 30;
  job.fadeLayers = 4;
  job.printerModel = "Saturn";
  job.created = 1700000000;
  job.previewModel = cube.corners;
  // Three layers: dark, binary with long and short runs, and every grey level.
  std::vector<MaskImage> masks(3);
  std::mt19937 rng(7);
  for (uint32_t k = 0; k < 3; ++k) {
    MaskImage& m = masks[k];
    m.width = job.grid.width;
    m.height = job.grid.height;
    m.pixels.assign(std::size_t{m.width} * m.height, 0);
    for (std::size_t i = 0; i < m.pixels.size(); ++i) {
      if (k == 1) m.pixels[i] = (i / 37) % 5 == 0 || (i > 1000000 && i < 1100000) ? 255 : 0;
      if (k == 2 && i % 7 != 0) m.pixels[i] = static_cast<uint8_t>(rng() % 3 == 0 ? i % 256 : 255);
    }
  }
  {
    auto sink = makeMaskSink(dir / "part.goo", job, false);
    for (uint32_t k = 0; k < 3; ++k) sink->writeLayer(k, (k + 0.5) * 0.05, masks[k]);
    MaskJob final = job;
    final.previewModel = {};
    final.volumeMl = 1.25;
    sink->finish(final);
  }
  const std::string bytes = readFile(dir / "part.goo");
  GooHeader h;
  std::vector<GooLayer> layers;
  ASSERT_EQ(decodeGoo(bytes, h, layers), "");

  EXPECT_EQ(h.version, "V3.0");
  EXPECT_EQ(h.magic, std::string("\x07\x00\x00\x00\x44\x4C\x50\x00", 8));
  EXPECT_EQ(h.software, "toposlice");
  EXPECT_FALSE(h.softwareVersion.empty());
  EXPECT_EQ(h.fileTime, "2023-11-14 22:13:20");
  EXPECT_EQ(h.printerName, "Saturn");
  EXPECT_EQ(h.layerContentOffset, 195477u);  // the sum of the table's field lengths
  EXPECT_EQ(h.layers, 3u);
  EXPECT_EQ(h.resX, 3300u);
  EXPECT_EQ(h.resY, 1426u);
  EXPECT_EQ(h.mirrorX, 1u);
  EXPECT_EQ(h.mirrorY, 0u);
  EXPECT_EQ(h.sizeX, 165.0f);
  EXPECT_EQ(h.sizeY, static_cast<float>(1426 * 0.05));
  EXPECT_EQ(h.sizeZ, 150.0f);
  EXPECT_EQ(h.layerThickness, 0.05f);
  EXPECT_EQ(h.exposure, 2.5f);
  EXPECT_EQ(h.bottomExposure, 30.0f);
  EXPECT_EQ(h.bottomLayers, 1u);
  EXPECT_EQ(h.transitionLayers, 2u);  // fadeLayers - 2
  EXPECT_EQ(h.delayMode, 1u);
  EXPECT_EQ(h.afterRetract, 1.0f);
  EXPECT_EQ(h.motion[0], 5.0f);    // bottom lift distance
  EXPECT_EQ(h.motion[1], 65.0f);   // bottom lift speed
  EXPECT_EQ(h.motion[2], 5.0f);    // lift distance
  EXPECT_EQ(h.motion[3], 65.0f);   // lift speed
  EXPECT_EQ(h.motion[7], 150.0f);  // retract speed
  for (int i = 8; i < 16; ++i) EXPECT_EQ(h.motion[i], 0.0f) << "second stage field " << 35 + i;
  EXPECT_EQ(h.bottomPwm, 255u);
  EXPECT_EQ(h.pwm, 255u);
  EXPECT_EQ(h.advanceMode, 0u);
  EXPECT_EQ(h.volume, 1250.0f);
  EXPECT_EQ(h.weight, static_cast<float>(1.25 * 1.1));
  EXPECT_EQ(h.priceUnit, "$");
  EXPECT_EQ(h.grayScaleLevel, 1u);
  // Print time: exposures 30, 30 - 27.5/3, 30 - 2 x 27.5/3, 1 s wait and 5 mm up at 65, down at 150 mm/min.
  const double exposures = 30 + (30 - 27.5 / 3) + (30 - 2 * 27.5 / 3);
  EXPECT_EQ(h.printTime, static_cast<uint64_t>(std::lround(exposures + 3 * (1 + 300.0 / 65 + 300.0 / 150))));
  // The previews show the cube: some pixels are not the background.
  const auto shown = [](const std::string& p) {
    for (std::size_t i = 2; i < p.size(); i += 2)
      if (p[i] != p[0] || p[i + 1] != p[1]) return true;
    return false;
  };
  EXPECT_TRUE(shown(h.smallPreview));
  EXPECT_TRUE(shown(h.bigPreview));

  ASSERT_EQ(layers.size(), 3u);
  const float expectedExposure[3] = {30.0f, static_cast<float>(30 - 27.5 / 3),
                                     static_cast<float>(30 - 2 * (27.5 / 3))};
  for (uint32_t k = 0; k < 3; ++k) {
    const GooLayer& l = layers[k];
    EXPECT_EQ(l.pause, 0u);
    EXPECT_EQ(l.z, static_cast<float>((k + 1) * 0.05)) << k;
    EXPECT_EQ(l.exposure, expectedExposure[k]) << k;
    EXPECT_EQ(l.liftDistance, 5.0f);
    EXPECT_EQ(l.retractDistance, 5.0f);
    EXPECT_EQ(l.retractSpeed, 150.0f);
    EXPECT_EQ(l.afterRetract, 1.0f);
    EXPECT_EQ(l.pwm, 255u);
    EXPECT_TRUE(l.pixels == topDown(masks[k])) << "layer " << k;
  }
}

// ---------------------------------------------------------------------------------------------------
// End to end: every layer equals the PNG layer of the same job, for binary and anti-aliased masks, and
// the file is the same for 1 and 2 threads.

using GooCli = tool_test::CliToolBase;

TEST_F(GooCli, LayersEqualThePngLayersOfTheSameJob) {
  for (const bool antialias : {false, true}) {
    // The PNG folder in the GOO's landscape frame (the sl1 preset's display is portrait).
    std::vector<std::string> args{"slice",     tool_test::examplePart().string(),
                                  "-H",        "0.1",
                                  "--printer", "sl1",
                                  "--set",     "display_orientation=landscape",
                                  "--set",     "display_mirror_x=0",
                                  "-q"};
    if (antialias) args.push_back("--antialias");
    const std::string tag = antialias ? "aa" : "bin";
    auto gooArgs = args, pngArgs = args, oneThread = args;
    gooArgs.insert(gooArgs.end(), {"--masks", tag + ".goo", "--threads", "2"});
    oneThread.insert(oneThread.end(), {"--masks", tag + "1.goo", "--threads", "1"});
    pngArgs.insert(pngArgs.end(), {"--masks", tag + "_png"});
    for (const auto* a : {&gooArgs, &oneThread, &pngArgs}) {
      const tool_test::RunResult r = run(*a);
      ASSERT_EQ(r.code(), 0) << r.describe();
    }
    const std::string bytes = readFile(path(tag + ".goo"));
    EXPECT_TRUE(bytes == readFile(path(tag + "1.goo"))) << tag << ": 1 and 2 threads differ";
    GooHeader h;
    std::vector<GooLayer> layers;
    ASSERT_EQ(decodeGoo(bytes, h, layers), "") << tag;
    std::map<std::string, fs::path> pngs;
    for (const auto& e : fs::directory_iterator(path(tag + "_png")))
      pngs[e.path().filename().string()] = e.path();
    ASSERT_EQ(layers.size(), pngs.size()) << tag;
    ASSERT_EQ(h.layers, 62u);  // ceil(6.2 / 0.1)
    EXPECT_EQ(h.antiAliasing, antialias ? 8u : 1u);
    std::size_t k = 0;
    bool grey = false;
    for (const auto& [name, file] : pngs) {
      const std::string png = readFile(file);
      MaskImage m;
      ASSERT_TRUE(decodeMaskPng({reinterpret_cast<const uint8_t*>(png.data()), png.size()}, m)) << name;
      EXPECT_TRUE(layers[k].pixels == topDown(m)) << tag << " layer " << k << " differs from " << name;
      for (uint8_t v : layers[k].pixels) grey |= v != 0 && v != 255;
      EXPECT_EQ(layers[k].z, static_cast<float>(static_cast<double>(k + 1) * 0.1)) << k;
      ++k;
    }
    EXPECT_EQ(grey, antialias) << tag;
  }
  expectNoTemporaries();
}

// The header carries the printer and material settings the job was given (exposure, fade, lift).
TEST_F(GooCli, HeaderCarriesTheProfileSettings) {
  const tool_test::RunResult r =
      run({"slice", tool_test::examplePart().string(), "-H", "0.1", "--printer", "sl1", "-q", "--masks",
           "s.goo", "--exposure-time", "3.5", "--initial-exposure-time", "20", "--set", "lift_distance=7",
           "--set", "lift_speed=80"});
  ASSERT_EQ(r.code(), 0) << r.describe();
  GooHeader h;
  std::vector<GooLayer> layers;
  ASSERT_EQ(decodeGoo(readFile(path("s.goo")), h, layers), "");
  EXPECT_EQ(h.exposure, 3.5f);
  ASSERT_FALSE(layers.empty());
  EXPECT_EQ(layers.front().exposure, 20.0f);
  EXPECT_EQ(layers.back().exposure, 3.5f);
  EXPECT_EQ(layers.back().liftDistance, 7.0f);
  EXPECT_EQ(layers.back().liftSpeed, 80.0f);
  EXPECT_EQ(h.transitionLayers, 8u);  // the sl1 preset's 10 faded layers - 2
  EXPECT_EQ(h.printerName, "SL1");

  // The printer's name: a generic preset's, not the SL1 model its SL1 archives carry; one the user
  // gives, as given.
  ASSERT_EQ(run({"slice", tool_test::examplePart().string(), "-H", "0.5", "--printer", "generic-8k", "-q",
                 "--masks", "g.goo"})
                .code(),
            0);
  ASSERT_EQ(decodeGoo(readFile(path("g.goo")), h, layers), "");
  EXPECT_EQ(h.printerName, "generic-8k");
  ASSERT_EQ(run({"slice", tool_test::examplePart().string(), "-H", "0.5", "--printer", "generic-8k", "-q",
                 "--masks", "n.goo", "--printer-model", "Saturn"})
                .code(),
            0);
  ASSERT_EQ(decodeGoo(readFile(path("n.goo")), h, layers), "");
  EXPECT_EQ(h.printerName, "Saturn");

  // A stack shorter than the fade: as many transition layers as there are after the bottom one (a
  // one-layer file said 8).
  for (const auto& [count, transitions] : {std::pair<const char*, uint64_t>{"1", 0}, {"4", 3}}) {
    ASSERT_EQ(run({"slice", tool_test::examplePart().string(), "--layers", count, "--printer", "sl1", "-q",
                   "--masks", "short.goo", "--force"})
                  .code(),
              0);
    ASSERT_EQ(decodeGoo(readFile(path("short.goo")), h, layers), "");
    EXPECT_EQ(h.transitionLayers, transitions) << count << " layers";
  }

  // A printer name longer than the header's 31 bytes was cut off silently: refused, naming the file.
  const tool_test::RunResult longName =
      run({"slice", tool_test::examplePart().string(), "-H", "0.1", "--printer", "sl1", "-q", "--masks",
           "l.goo", "--printer-model", std::string(32, 'M')});
  EXPECT_NE(longName.code(), 0);
  EXPECT_NE(longName.err.find("l.goo: printer_model '"), std::string::npos) << longName.err;
  EXPECT_NE(longName.err.find("31 at most"), std::string::npos) << longName.err;
  EXPECT_FALSE(fs::exists(path("l.goo")));
  EXPECT_EQ(run({"slice", tool_test::examplePart().string(), "-H", "0.1", "--printer", "sl1", "-q", "--masks",
                 "m.goo", "--printer-model", std::string(31, 'M')})
                .code(),
            0);
}

}  // namespace
}  // namespace toposlice
