// Mask-stack writers: PNG encoding, PNG directories, SL1 archives, OpenEXR stacks, OpenVDB slabs, and the
// staging rules shared by every sink (docs/FORMATS.md).
#include <gtest/gtest.h>
#include <spng.h>
#include <unistd.h>
#include <zip.h>  // libzip, to read archives back independently of the writer's minizip
#include <zlib.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "io/coders/mask_png.h"
#include "io/errors.h"
#include "io/masks/exr_writer.h"
#include "io/masks/mask_sink.h"
#include "io/masks/sl1_writer.h"
#include "io/masks/vdb_writer.h"
#include "io/output_file.h"
#include "tests/fixtures/archives.h"
#include "tests/fixtures/scratch_dir.h"
#include "tests/fixtures/shapes.h"
#include "tests/tinyexr_read.h"
#include "tests/tool_runner.h"

namespace toposlice {
namespace {

namespace fs = std::filesystem;

MaskImage blankMask(uint32_t width, uint32_t height) {
  MaskImage m;
  m.width = width;
  m.height = height;
  m.pixels.assign(size_t{width} * height, 0);
  return m;
}

// Rows of runs of random length (1..maxRun) and value (0/255 when levels is 2, else 0..levels-1); a
// third of the rows copy the row above and, with darkRows, a quarter of the others stay dark. `below(n)`
// draws from 0..n-1.
template <class Below>
MaskImage randomRunMask(uint32_t width, uint32_t height, uint32_t levels, uint32_t maxRun, bool darkRows,
                        Below& below) {
  MaskImage m = blankMask(width, height);
  for (uint32_t j = 0; j < height; ++j) {
    uint8_t* row = m.pixels.data() + size_t{j} * width;
    if (j > 0 && below(3) == 0) {
      std::copy_n(row - width, width, row);
      continue;
    }
    if (darkRows && below(4) == 0) continue;
    for (uint32_t i = 0; i < width;) {
      const uint32_t run = std::min(width - i, 1 + below(maxRun));
      const auto value = static_cast<uint8_t>(levels == 2 ? below(2) * 255 : below(levels));
      std::fill_n(row + i, run, value);
      i += run;
    }
  }
  return m;
}

// A disc of radius r at (cx, cy): binary, or with a soft edge (coverage-like values) when antiAliased.
MaskImage discMask(uint32_t width, uint32_t height, double cx, double cy, double r, bool antiAliased) {
  MaskImage m = blankMask(width, height);
  for (uint32_t j = 0; j < height; ++j) {
    for (uint32_t i = 0; i < width; ++i) {
      const double d = std::hypot(i + 0.5 - cx, j + 0.5 - cy) - r;
      double v = 0;
      if (antiAliased) {
        v = std::clamp(0.5 - d, 0.0, 1.0);
      } else {
        v = d < 0 ? 1 : 0;
      }
      m.pixels[size_t{j} * width + i] = static_cast<uint8_t>(std::lround(255 * v));
    }
  }
  return m;
}

MaskImage noiseMask(uint32_t width, uint32_t height, uint32_t seed, bool binary) {
  std::mt19937 rng(seed);
  MaskImage m = blankMask(width, height);
  for (uint8_t& p : m.pixels) {
    const auto r = static_cast<uint32_t>(rng());
    p = binary ? ((r & 1) ? 255 : 0) : static_cast<uint8_t>(r);
  }
  return m;
}

uint64_t litPixels(const MaskImage& m) {
  uint64_t n = 0;
  for (uint8_t p : m.pixels) n += p != 0;
  return n;
}

// Decodes with libspng directly, rows top-down as stored in the file.
bool decodeTopDown(const std::vector<uint8_t>& png, uint32_t& width, uint32_t& height,
                   std::vector<uint8_t>& rows) {
  spng_ctx* ctx = spng_ctx_new(0);
  bool ok = spng_set_png_buffer(ctx, png.data(), png.size()) == 0;
  spng_ihdr ihdr{};
  ok = ok && spng_get_ihdr(ctx, &ihdr) == 0 && ihdr.bit_depth == 8 &&
       ihdr.color_type == SPNG_COLOR_TYPE_GRAYSCALE;
  size_t size = 0;
  ok = ok && spng_decoded_image_size(ctx, SPNG_FMT_PNG, &size) == 0;
  if (ok) {
    rows.resize(size);
    ok = spng_decode_image(ctx, rows.data(), size, SPNG_FMT_PNG, 0) == 0;
    width = ihdr.width;
    height = ihdr.height;
  }
  spng_ctx_free(ctx);
  return ok;
}

void expectPngRoundTrip(const MaskImage& mask) {
  std::vector<uint8_t> png;
  encodeMaskPng(mask, png);
  MaskImage back;
  ASSERT_TRUE(decodeMaskPng(png, back)) << mask.width << "x" << mask.height;
  EXPECT_EQ(back.width, mask.width);
  EXPECT_EQ(back.height, mask.height);
  EXPECT_TRUE(back.pixels == mask.pixels) << mask.width << "x" << mask.height;
}

std::map<std::string, std::string> parseIni(const std::string& text) {
  std::map<std::string, std::string> m;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    const size_t eq = line.find(" = ");
    if (eq != std::string::npos) m[line.substr(0, eq)] = line.substr(eq + 3);
  }
  return m;
}

MaskJob smallJob(uint32_t width, uint32_t height, uint32_t layers, bool antiAliased) {
  MaskJob job;
  job.name = "part";
  job.grid.width = width;
  job.grid.height = height;
  job.grid.pixel = 0.05;
  job.grid.x0 = -1.0;
  job.grid.y0 = 2.0;
  job.layerHeight = 0.025;
  job.layerCount = layers;
  job.antiAliased = antiAliased;
  return job;
}

// smallJob with a fixed creation time and `model` (kept alive by the caller) for its previews.
MaskJob previewJob(const FacetSoup& model, uint32_t width, uint32_t height, uint32_t layers,
                   bool antiAliased) {
  MaskJob job = smallJob(width, height, layers, antiAliased);
  job.created = 1700000000;
  job.previewModel = model.corners;
  return job;
}

// A fresh, empty directory per test, removed afterwards.
class TempDirTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() / ("toposlice-masks-" + std::to_string(::getpid()) + "-" +
                                        info->test_suite_name() + "-" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  // Entries of the test directory other than `keep`.
  std::vector<std::string> strayEntries(const fs::path& keep = {}) const {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(dir_)) {
      if (e.path() != keep) names.push_back(e.path().filename().string());
    }
    return names;
  }

  fs::path dir_;
};

// ---------------------------------------------------------------------------------------------------
// PNG

TEST(PngEncode, RoundTripsBinaryAndGrayImages) {
  expectPngRoundTrip(blankMask(1, 1));
  expectPngRoundTrip(noiseMask(1, 7, 1, true));
  expectPngRoundTrip(noiseMask(2, 3, 2, false));
  expectPngRoundTrip(noiseMask(17, 13, 3, true));
  expectPngRoundTrip(noiseMask(64, 9, 4, false));
  expectPngRoundTrip(discMask(301, 203, 150, 100, 80, false));
  expectPngRoundTrip(discMask(301, 203, 150, 100, 80, true));
  expectPngRoundTrip(discMask(2560, 1440, 1280.3, 700.7, 600, false));
  expectPngRoundTrip(discMask(2560, 1440, 1280.3, 700.7, 600, true));
  MaskImage full = blankMask(259, 4);  // runs of 259/260 bytes: the match-splitting remainders
  std::fill(full.pixels.begin(), full.pixels.end(), 255);
  expectPngRoundTrip(full);
  expectPngRoundTrip(blankMask(258, 3));
  expectPngRoundTrip(blankMask(257, 3));
  // Rows wider than the 32 KiB deflate window: no copies of the row above.
  MaskImage wide = discMask(40000, 3, 20000, 1.5, 15000, false);
  expectPngRoundTrip(wide);
}

TEST(PngEncode, RandomRunImagesRoundTrip) {
  // Runs of every length around the 258-byte match limit, repeated rows, few and many grey levels.
  std::mt19937 rng(12345);
  const auto below = [&rng](uint32_t n) { return static_cast<uint32_t>(rng() % n); };
  for (uint32_t trial = 0; trial < 200; ++trial) {
    const uint32_t width = 1 + below(700), height = 1 + below(40);
    const uint32_t levels = trial % 3 == 0 ? 2 : 1 + below(256);
    expectPngRoundTrip(randomRunMask(width, height, levels, 600, false, below));
    if (HasFailure()) break;
  }
}

TEST(PngEncode, RepeatedRowsAndLongRuns) {
  MaskImage m = blankMask(1000, 50);
  for (uint32_t j = 10; j < 40; ++j) {
    for (uint32_t i = 100; i < 900; ++i) m.pixels[size_t{j} * 1000 + i] = 255;
  }
  m.pixels[size_t{25} * 1000 + 500] = 7;  // one row differs from its neighbours
  expectPngRoundTrip(m);
}

TEST(PngEncode, RowZeroIsTheLastPngRow) {
  MaskImage m = blankMask(5, 4);
  m.pixels[0 * 5 + 2] = 255;  // pixel (2, 0): lowest y
  std::vector<uint8_t> png;
  encodeMaskPng(m, png);
  uint32_t width = 0, height = 0;
  std::vector<uint8_t> rows;
  ASSERT_TRUE(decodeTopDown(png, width, height, rows));
  ASSERT_EQ(width, 5u);
  ASSERT_EQ(height, 4u);
  for (uint32_t r = 0; r < height; ++r) {
    for (uint32_t i = 0; i < width; ++i) {
      EXPECT_EQ(rows[size_t{r} * width + i], (r == 3 && i == 2) ? 255 : 0) << "png row " << r << " col " << i;
    }
  }
}

TEST(PngEncode, SameImageSameBytesAndSmallForMasks) {
  const MaskImage m = discMask(2560, 1440, 1280, 720, 500, false);
  std::vector<uint8_t> a, b;
  encodeMaskPng(m, a);
  encodeMaskPng(m, b);
  EXPECT_EQ(a, b);
  EXPECT_LT(a.size(), 100000u);  // a disc: about 2 runs per row
}

TEST(PngEncode, Speed2560x1440Binary) {
  // Twelve discs, 41 % lit: a typical busy layer.
  MaskImage m = blankMask(2560, 1440);
  for (int c = 0; c < 12; ++c) {
    const MaskImage d =
        discMask(2560, 1440, 200 + (c % 4) * 600, 250 + (c / 4) * 450, 120 + (c * 37) % 150, false);
    for (size_t p = 0; p < m.pixels.size(); ++p) m.pixels[p] |= d.pixels[p];
  }
  std::vector<uint8_t> png;
  double best = 1e9;
  for (int it = 0; it < 20; ++it) {
    const auto t0 = std::chrono::steady_clock::now();
    encodeMaskPng(m, png);
    best = std::min(best,
                    std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  RecordProperty("encode_ms", std::to_string(best));
  RecordProperty("png_bytes", std::to_string(png.size()));
  std::printf("[ info     ] 2560x1440 binary mask: %.3f ms, %zu bytes\n", best, png.size());
  EXPECT_LT(best, 50.0);  // about 0.5 ms optimised; loose for sanitizer and debug builds
}

// ---------------------------------------------------------------------------------------------------
// PNG, checked byte by byte with zlib's inflate (an implementation independent of the encoder's).

// Tight lit extents of every row, as the binary rasterizer keeps them (mask_image.h).
MaskImage withExtents(MaskImage m) {
  m.litBegin.assign(m.height, m.width);
  m.litEnd.assign(m.height, 0);
  for (uint32_t r = 0; r < m.height; ++r) {
    for (uint32_t i = 0; i < m.width; ++i) {
      if (m.pixels[size_t{r} * m.width + i] != 0) {
        m.litBegin[r] = std::min(m.litBegin[r], i);
        m.litEnd[r] = i + 1;
      }
    }
  }
  return m;
}

// A binary mask (0 and 255) with its extents and maximal lit runs, as the binary rasterizer keeps them.
MaskImage withRuns(MaskImage m) {
  m = withExtents(std::move(m));
  m.runs.clear();
  m.rowRuns.assign(2 * size_t{m.height}, 0);
  for (uint32_t r = 0; r < m.height; ++r) {
    const uint8_t* row = m.pixels.data() + size_t{r} * m.width;
    m.rowRuns[2 * r] = static_cast<uint32_t>(m.runs.size() / 2);
    for (uint32_t i = 0; i < m.width;) {
      if (row[i] == 0) {
        ++i;
        continue;
      }
      uint32_t e = i;
      while (e < m.width && row[e] != 0) ++e;
      m.runs.push_back(i);
      m.runs.push_back(e);
      i = e;
    }
    m.rowRuns[2 * r + 1] = static_cast<uint32_t>(m.runs.size() / 2 - m.rowRuns[2 * r]);
  }
  return m;
}

uint32_t bigEndian32(const uint8_t* p) {
  return (uint32_t{p[0]} << 24) | (uint32_t{p[1]} << 16) | (uint32_t{p[2]} << 8) | p[3];
}

// What a PNG of encodeMaskPng holds, read without libspng: the zlib stream of its one IDAT, inflated.
struct InflatedPng {
  uint32_t width = 0, height = 0;
  std::vector<uint8_t> zlibStream;  // the IDAT data
  std::vector<uint8_t> filtered;    // inflated: per row a filter byte, then the pixels
  int blockType = -1;               // BTYPE of the first deflate block: 1 fixed, 2 dynamic
  bool onlyBlock = false;           // BFINAL of the first block
};

// Checks the signature, the chunk sequence IHDR IDAT IEND and every chunk CRC, then inflates the IDAT
// with zlib (which checks the Adler-32). Failures are reported; returns false after one.
bool inflatePng(const std::vector<uint8_t>& png, InflatedPng& result) {
  static constexpr uint8_t kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  if (png.size() < 8 || std::memcmp(png.data(), kSignature, 8) != 0) {
    ADD_FAILURE() << "no PNG signature";
    return false;
  }
  std::vector<std::string> types;
  for (size_t at = 8; at < png.size();) {
    if (png.size() - at < 12) {
      ADD_FAILURE() << "truncated chunk at " << at;
      return false;
    }
    const uint32_t length = bigEndian32(&png[at]);
    if (png.size() - at - 12 < length) {
      ADD_FAILURE() << "chunk length past the end at " << at;
      return false;
    }
    const std::string type(reinterpret_cast<const char*>(&png[at + 4]), 4);
    const uint8_t* data = &png[at + 8];
    if (crc32_z(0, &png[at + 4], 4 + length) != bigEndian32(data + length)) {
      ADD_FAILURE() << type << ": bad CRC";
      return false;
    }
    if (type == "IHDR") {
      result.width = bigEndian32(data);
      result.height = bigEndian32(data + 4);
      if (length != 13 || data[8] != 8 || data[9] != 0 || data[10] != 0 || data[11] != 0 || data[12] != 0) {
        ADD_FAILURE() << "IHDR is not 8-bit grayscale, deflate, filter method 0, no interlace";
        return false;
      }
    }
    if (type == "IDAT") result.zlibStream.assign(data, data + length);
    if (type == "tEXt" &&
        std::string(reinterpret_cast<const char*>(data), length) != std::string("Software\0toposlice", 18)) {
      ADD_FAILURE() << "the tEXt chunk is not Software: toposlice";
      return false;
    }
    types.push_back(type);
    at += 12 + length;
  }
  if (types != std::vector<std::string>{"IHDR", "tEXt", "IDAT", "IEND"}) {
    ADD_FAILURE() << "chunks are not IHDR tEXt IDAT IEND";
    return false;
  }
  if (result.zlibStream.size() < 3) {
    ADD_FAILURE() << "IDAT too short";
    return false;
  }
  result.blockType = (result.zlibStream[2] >> 1) & 3;
  result.onlyBlock = (result.zlibStream[2] & 1) != 0;
  const size_t rawSize = (size_t{result.width} + 1) * result.height;
  result.filtered.assign(rawSize + 1, 0xEE);  // one spare byte: inflating more than rawSize is an error
  z_stream z{};
  if (inflateInit(&z) != Z_OK) {
    ADD_FAILURE() << "inflateInit";
    return false;
  }
  z.next_in = result.zlibStream.data();
  z.avail_in = static_cast<uInt>(result.zlibStream.size());
  z.next_out = result.filtered.data();
  z.avail_out = static_cast<uInt>(result.filtered.size());
  const int rc = inflate(&z, Z_FINISH);
  const size_t produced = result.filtered.size() - z.avail_out, leftIn = z.avail_in;
  const std::string message = z.msg ? z.msg : "";
  inflateEnd(&z);
  if (rc != Z_STREAM_END || produced != rawSize || leftIn != 0) {
    ADD_FAILURE() << "inflate: rc " << rc << " (" << message << "), " << produced << " of " << rawSize
                  << " bytes, " << leftIn << " input bytes left";
    return false;
  }
  result.filtered.resize(rawSize);
  return true;
}

// Encodes with the given code, inflates with zlib and compares every byte (filter type 0, the pixels,
// rows top-down). Returns the PNG's first block type (-1 on failure).
int expectInflatesExactly(const MaskImage& mask, MaskPngCode code = MaskPngCode::smallest,
                          std::vector<uint8_t>* pngOut = nullptr) {
  std::vector<uint8_t> png;
  MaskPngScratch scratch;
  encodeMaskPng(mask, png, scratch, code);
  if (pngOut) *pngOut = png;
  InflatedPng in;
  if (!inflatePng(png, in)) return -1;
  EXPECT_EQ(in.width, mask.width);
  EXPECT_EQ(in.height, mask.height);
  EXPECT_TRUE(in.onlyBlock);
  for (uint32_t r = 0; r < mask.height; ++r) {
    const uint8_t* row = &in.filtered[size_t{r} * (mask.width + 1)];
    const uint8_t* expected = &mask.pixels[size_t{mask.height - 1 - r} * mask.width];
    if (row[0] != 0 || std::memcmp(row + 1, expected, mask.width) != 0) {
      ADD_FAILURE() << mask.width << "x" << mask.height << ": PNG row " << r << " differs";
      return -1;
    }
  }
  return in.blockType;
}

// The literal/length and distance code lengths of a dynamic block (RFC 1951 3.2.7), read back bit by bit.
struct DynamicHeader {
  std::vector<uint8_t> litLen, distance;
};

bool readDynamicHeader(const std::vector<uint8_t>& zlibStream, DynamicHeader& header) {
  size_t bit = 16;  // after CMF and FLG
  auto bits = [&](uint32_t n) {
    uint32_t v = 0;
    for (uint32_t i = 0; i < n; ++i, ++bit) v |= ((zlibStream[bit / 8] >> (bit % 8)) & 1u) << i;
    return v;
  };
  if (bits(3) != 0b101) return false;  // BFINAL, BTYPE = 10
  const uint32_t hlit = bits(5) + 257, hdist = bits(5) + 1, hclen = bits(4) + 4;
  static constexpr uint8_t kOrder[19] = {16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15};
  uint8_t codeLength[19] = {};
  for (uint32_t i = 0; i < hclen; ++i) codeLength[kOrder[i]] = static_cast<uint8_t>(bits(3));
  // Decode with the canonical code: try lengths 1..7, matching the MSB-first code read so far.
  auto symbol = [&]() -> int {
    uint32_t code = 0, first = 0, index = 0;
    for (uint32_t len = 1; len <= 7; ++len) {
      code |= bits(1);
      uint32_t count = 0;
      for (uint8_t l : codeLength) count += l == len;
      if (code - first < count) {
        uint32_t k = code - first;
        for (int s = 0; s < 19; ++s) {
          if (codeLength[s] == len && k-- == 0) return s;
        }
      }
      index += count;
      first = (first + count) << 1;
      code <<= 1;
    }
    return -1;
  };
  std::vector<uint8_t> lengths;
  while (lengths.size() < hlit + hdist) {
    const int s = symbol();
    if (s < 0) return false;
    if (s < 16) {
      lengths.push_back(static_cast<uint8_t>(s));
    } else if (s == 16) {
      if (lengths.empty()) return false;
      lengths.insert(lengths.end(), 3 + bits(2), lengths.back());
    } else {
      lengths.insert(lengths.end(), s == 17 ? 3 + bits(3) : 11 + bits(7), 0);
    }
  }
  if (lengths.size() != hlit + hdist) return false;
  header.litLen.assign(lengths.begin(), lengths.begin() + hlit);
  header.distance.assign(lengths.begin() + hlit, lengths.end());
  return true;
}

// Kraft sum of a code in units of 2^-15 (32768: complete).
uint32_t kraftSum(const std::vector<uint8_t>& lengths) {
  uint32_t sum = 0;
  for (uint8_t l : lengths) sum += l == 0 ? 0 : 1u << (15 - l);
  return sum;
}

MaskImage filledMask(uint32_t width, uint32_t height, uint8_t value) {
  MaskImage m = blankMask(width, height);
  std::fill(m.pixels.begin(), m.pixels.end(), value);
  return m;
}

TEST(PngEncode, ZlibInflatesEdgeCasesWithEitherCode) {
  std::vector<MaskImage> masks;
  for (const auto& [w, h] : std::vector<std::pair<uint32_t, uint32_t>>{
           {1, 1}, {1, 2}, {2, 1}, {1, 300}, {3, 3}, {7, 5}, {257, 3}, {258, 2}, {259, 4}, {2560, 1440}}) {
    masks.push_back(blankMask(w, h));        // all black: one literal, one distance
    masks.push_back(filledMask(w, h, 255));  // all white
    masks.push_back(filledMask(w, h, 7));    // a single grey level
    MaskImage one = blankMask(w, h);         // a single lit pixel, in each corner
    for (int corner = 0; corner < 4; ++corner) {
      const uint32_t i = corner % 2 ? w - 1 : 0, j = corner / 2 ? h - 1 : 0;
      MaskImage c = one;
      c.pixels[size_t{j} * w + i] = 255;
      masks.push_back(c);
    }
  }
  // Lit spans touching both image borders, the right border only, the left border only.
  MaskImage borders = blankMask(101, 40);
  for (uint32_t j = 0; j < 40; ++j) {
    const uint32_t from = j % 3 == 1 ? 50 : 0, to = j % 3 == 2 ? 60 : 101;
    std::fill_n(borders.pixels.begin() + size_t{j} * 101 + from, to - from, 255);
  }
  masks.push_back(borders);
  // Every grey value, many times, in several patterns (anti-aliased edges at their worst).
  MaskImage ramp = blankMask(256, 64);
  for (uint32_t j = 0; j < 64; ++j) {
    for (uint32_t i = 0; i < 256; ++i)
      ramp.pixels[size_t{j} * 256 + i] = static_cast<uint8_t>((i * (j + 1)) & 255);
  }
  masks.push_back(ramp);
  masks.push_back(noiseMask(255, 77, 9, false));
  masks.push_back(noiseMask(1, 999, 10, false));
  masks.push_back(discMask(1001, 333, 500, 160, 150, true));
  // One run of 8.4 MB: longer than a repeat token holds (32,000 matches of 258 bytes).
  masks.push_back(blankMask(4000, 2100));
  for (size_t k = 0; k < masks.size(); ++k) {
    for (const MaskImage& m : {masks[k], withExtents(masks[k])}) {
      for (const MaskPngCode code : {MaskPngCode::smallest, MaskPngCode::fixed}) {
        const int type = expectInflatesExactly(m, code);
        ASSERT_NE(type, -1) << "mask " << k << " (" << m.width << "x" << m.height << ")";
        if (code == MaskPngCode::fixed) {
          EXPECT_EQ(type, 1) << "mask " << k;
        }
      }
    }
  }
}

TEST(PngEncode, ZlibInflatesRandomRunImages) {
  // Runs of every length around the 258-byte match limit, repeated lit and dark rows, few and many
  // grey levels, with and without extents, under both codes.
  std::mt19937 rng(4242);
  const auto below = [&rng](uint32_t n) { return static_cast<uint32_t>(rng() % n); };
  for (uint32_t trial = 0; trial < 300; ++trial) {
    const uint32_t width = 1 + below(trial % 5 == 0 ? 3 : 900), height = 1 + below(60);
    const uint32_t levels = trial % 3 == 0 ? 2 : 1 + below(256);
    const uint32_t maxRun = 1 + below(trial % 2 ? 8 : 700);
    const MaskImage m = randomRunMask(width, height, levels, maxRun, true, below);
    const MaskImage& mask = trial % 2 ? m : withExtents(m);
    const MaskPngCode code = trial % 4 == 3 ? MaskPngCode::fixed : MaskPngCode::smallest;
    ASSERT_NE(expectInflatesExactly(mask, code), -1) << "trial " << trial << ", " << width << "x" << height;
  }
}

TEST(RunDeflater, ByteStringsCodeAsTheirBytesOneByOne) {
  // putByteString (the edge pixels of anti-aliased rows) gives the tokens of putBytes(byte, 1) for each
  // byte: literals, runs that start inside a string, continue the bytes before it or go on into the
  // next call, strings longer than the token buffer of a fresh scratch; and zlib inflates the stream.
  std::mt19937 rng(2027);
  for (int trial = 0; trial < 200; ++trial) {
    DeflateScratch oneScratch, stringScratch;
    RunDeflater one(oneScratch, 1), strings(stringScratch, 1);
    std::vector<uint8_t> expected;
    const int pieces = 1 + static_cast<int>(rng() % 12);
    for (int k = 0; k < pieces; ++k) {
      if (rng() % 3 == 0) {  // a run by putBytes, on both
        const uint8_t v =
            static_cast<uint8_t>(rng() % 4 == 0 ? expected.empty() ? 7 : expected.back() : rng() % 6);
        const uint64_t count = 1 + rng() % 700;
        one.putBytes(v, count);
        strings.putBytes(v, count);
        expected.insert(expected.end(), count, v);
        continue;
      }
      const std::size_t size = trial % 10 == 0 ? 5000 + rng() % 20000 : rng() % 300;
      std::vector<uint8_t> bytes(size);
      for (std::size_t i = 0; i < size; ++i)  // few values: runs of every length, literals between them
        bytes[i] =
            static_cast<uint8_t>(i > 0 && rng() % 3 == 0 ? bytes[i - 1] : rng() % (trial % 2 ? 4 : 256));
      for (uint8_t b : bytes) one.putBytes(b, 1);
      strings.putByteString(bytes.data(), bytes.size());
      expected.insert(expected.end(), bytes.begin(), bytes.end());
    }
    if (expected.empty()) continue;
    std::vector<uint8_t> a, b;
    a.resize(one.writeBlock(a, 0, DeflateCode::smallest));
    b.resize(strings.writeBlock(b, 0, DeflateCode::smallest));
    ASSERT_EQ(a, b) << "trial " << trial;
    std::vector<uint8_t> inflated(expected.size() + 1);
    z_stream z{};
    ASSERT_EQ(inflateInit2(&z, -15), Z_OK);
    z.next_in = b.data();
    z.avail_in = static_cast<uInt>(b.size());
    z.next_out = inflated.data();
    z.avail_out = static_cast<uInt>(inflated.size());
    const int rc = inflate(&z, Z_FINISH);
    inflateEnd(&z);
    ASSERT_EQ(rc, Z_STREAM_END) << "trial " << trial;
    inflated.resize(inflated.size() - z.avail_out);
    ASSERT_EQ(inflated, expected) << "trial " << trial;
  }
}

TEST(PngEncode, BinaryMasksFromRunsGiveTheSameBytes) {
  // The coder reads a binary mask from its rows' runs when it has them (mask_image.h): the same PNG as
  // from the pixels, with or without extents, under both codes; repeated, dark and full rows, runs
  // around the 258-byte match limit, rows wider than the deflate window.
  std::mt19937 rng(777);
  const auto below = [&rng](uint32_t n) { return static_cast<uint32_t>(rng() % n); };
  for (uint32_t trial = 0; trial < 300; ++trial) {
    const uint32_t width = trial == 0 ? 40000 : 1 + below(trial % 5 == 0 ? 3 : 900), height = 1 + below(60);
    MaskImage m = randomRunMask(width, height, 2, 1 + below(trial % 2 ? 8 : 700), true, below);
    if (trial % 7 == 0) std::fill(m.pixels.begin(), m.pixels.end(), uint8_t{255});
    const MaskPngCode code = trial % 4 == 3 ? MaskPngCode::fixed : MaskPngCode::smallest;
    std::vector<uint8_t> plain, extents, runs;
    MaskPngScratch scratch;
    encodeMaskPng(m, plain, scratch, code);
    encodeMaskPng(withExtents(m), extents, scratch, code);
    const MaskImage fromRuns = withRuns(m);
    ASSERT_TRUE(fromRuns.hasRuns());
    ASSERT_NE(expectInflatesExactly(fromRuns, code, &runs), -1) << "trial " << trial;
    ASSERT_EQ(runs, plain) << "trial " << trial << ", " << width << "x" << height;
    ASSERT_EQ(extents, plain) << "trial " << trial;
  }
}

// Twelve discs, 41 % lit: a typical busy binary layer.
MaskImage twelveDiscs(bool antiAliased) {
  MaskImage m = blankMask(2560, 1440);
  for (int c = 0; c < 12; ++c) {
    const MaskImage d =
        discMask(2560, 1440, 200 + (c % 4) * 600, 250 + (c / 4) * 450, 120 + (c * 37) % 150, antiAliased);
    for (size_t p = 0; p < m.pixels.size(); ++p) m.pixels[p] = std::max(m.pixels[p], d.pixels[p]);
  }
  return m;
}

TEST(PngEncode, RealisticMasksTakeTheDynamicCode) {
  for (const bool antiAliased : {false, true}) {
    const MaskImage m = antiAliased ? twelveDiscs(true) : withExtents(twelveDiscs(false));
    std::vector<uint8_t> dynamicPng, fixedPng;
    ASSERT_EQ(expectInflatesExactly(m, MaskPngCode::smallest, &dynamicPng), 2);
    ASSERT_EQ(expectInflatesExactly(m, MaskPngCode::fixed, &fixedPng), 1);
    EXPECT_LT(dynamicPng.size(), fixedPng.size());
    if (!antiAliased) {
      EXPECT_LT(dynamicPng.size() * 2, fixedPng.size());
    }
    std::printf("[ info     ] 2560x1440 twelve discs%s: dynamic %zu bytes, fixed %zu bytes\n",
                antiAliased ? ", anti-aliased" : "", dynamicPng.size(), fixedPng.size());
    InflatedPng in;
    ASSERT_TRUE(inflatePng(dynamicPng, in));
    DynamicHeader header;
    ASSERT_TRUE(readDynamicHeader(in.zlibStream, header));
    EXPECT_EQ(kraftSum(header.litLen), 32768u);
    EXPECT_EQ(kraftSum(header.distance), 32768u);
  }
  // All black: one literal, runs at one distance. The distance code still needs (and gets) a valid code.
  std::vector<uint8_t> png;
  ASSERT_EQ(expectInflatesExactly(blankMask(2560, 1440), MaskPngCode::smallest, &png), 2);
  EXPECT_LT(png.size(), 4000u);
  InflatedPng in;
  ASSERT_TRUE(inflatePng(png, in));
  DynamicHeader header;
  ASSERT_TRUE(readDynamicHeader(in.zlibStream, header));
  EXPECT_EQ(kraftSum(header.distance), 32768u);
}

TEST(PngEncode, TinyImagesFallBackToTheFixedCode) {
  // A dynamic header costs more than the whole fixed-code block here.
  std::vector<uint8_t> smallest, fixed;
  const MaskImage m = noiseMask(3, 2, 5, true);
  EXPECT_EQ(expectInflatesExactly(m, MaskPngCode::smallest, &smallest), 1);
  EXPECT_EQ(expectInflatesExactly(m, MaskPngCode::fixed, &fixed), 1);
  EXPECT_EQ(smallest, fixed);
}

TEST(PngEncode, CodeLengthsAreLimitedTo15Bits) {
  // Grey values with Fibonacci frequencies: an unlimited Huffman code would be 24 bits deep.
  std::vector<uint8_t> values;
  uint32_t a = 1, b = 1;
  for (uint8_t v = 1; v <= 25; ++v) {
    values.insert(values.end(), a, v);
    const uint32_t next = a + b;
    a = b;
    b = next;
  }
  std::mt19937 rng(99);
  std::shuffle(values.begin(), values.end(), rng);
  const uint32_t width = 1000, height = static_cast<uint32_t>((values.size() + width - 1) / width);
  MaskImage m = blankMask(width, height);
  std::copy(values.begin(), values.end(), m.pixels.begin());
  std::vector<uint8_t> png;
  ASSERT_EQ(expectInflatesExactly(m, MaskPngCode::smallest, &png), 2);
  InflatedPng in;
  ASSERT_TRUE(inflatePng(png, in));
  DynamicHeader header;
  ASSERT_TRUE(readDynamicHeader(in.zlibStream, header));
  EXPECT_EQ(*std::max_element(header.litLen.begin(), header.litLen.end()), 15);
  EXPECT_EQ(kraftSum(header.litLen), 32768u);
}

TEST(PngEncode, ScratchReuseGivesTheSameBytes) {
  const std::vector<MaskImage> masks = {twelveDiscs(false), noiseMask(300, 200, 3, false), blankMask(5, 5),
                                        withExtents(twelveDiscs(false)), twelveDiscs(true)};
  MaskPngScratch shared;
  std::vector<uint8_t> reused;
  for (int pass = 0; pass < 2; ++pass) {
    for (size_t k = 0; k < masks.size(); ++k) {
      std::vector<uint8_t> fresh;
      MaskPngScratch own;
      encodeMaskPng(masks[k], fresh, own);
      encodeMaskPng(masks[k], reused, shared);
      EXPECT_EQ(reused, fresh) << "mask " << k;
    }
  }
  std::vector<uint8_t> plain;  // the overload without a scratch
  encodeMaskPng(masks[0], plain);
  encodeMaskPng(masks[0], reused, shared);
  EXPECT_EQ(plain, reused);
}

TEST(PngDecode, RejectsGarbage) {
  MaskImage m;
  const std::vector<uint8_t> junk = {1, 2, 3, 4, 5};
  EXPECT_FALSE(decodeMaskPng(junk, m));
  std::vector<uint8_t> png;
  encodeMaskPng(discMask(30, 20, 15, 10, 6, false), png);
  png.resize(png.size() / 2);
  EXPECT_FALSE(decodeMaskPng(png, m));
}

TEST(MaskNames, PadToFiveDigitsOrMore) {
  EXPECT_EQ(maskLayerFileName("part", 7, 100, "png"), "part00007.png");
  EXPECT_EQ(maskLayerFileName("part", 99999, 100000, "png"), "part99999.png");
  EXPECT_EQ(maskLayerFileName("part", 7, 100001, "exr"), "part000007.exr");
  EXPECT_EQ(maskLayerFileName("a/b\\c", 0, 1, "png"), "a_b_c00000.png");
  EXPECT_EQ(maskLayerFileName("", 1, 1, "png"), "layer00001.png");
}

// ---------------------------------------------------------------------------------------------------
// PNG directory

using PngDirectory = TempDirTest;

TEST_F(PngDirectory, WritesOneFilePerLayer) {
  const MaskJob job = smallJob(31, 17, 3, false);
  const fs::path out = dir_ / "stack";
  std::vector<MaskImage> masks;
  for (uint32_t k = 0; k < 3; ++k) masks.push_back(discMask(31, 17, 15, 8, 3.0 + 2 * k, false));
  auto sink = makeMaskSink(out, job, false);
  std::vector<uint8_t> png;
  for (uint32_t k = 0; k < 3; ++k) {
    encodeMaskPng(masks[k], png);
    if (k == 1) {
      sink->writeLayer(k, 0.0125 + k * 0.025, masks[k]);
    } else {  // the two-step path gives the same files
      EncodedMaskLayer encoded;
      MaskEncodeScratch scratch;
      sink->encodeLayer(k, 0.0125 + k * 0.025, masks[k], encoded, scratch);
      EXPECT_TRUE(encoded.bytes == png) << k;
      sink->writeEncodedLayer(k, 0.0125 + k * 0.025, encoded);
    }
    EXPECT_FALSE(fs::exists(out));
  }
  sink->finish(job);
  ASSERT_TRUE(fs::is_directory(out));
  EXPECT_EQ(strayEntries(out).size(), 0u);
  size_t files = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(out)) ++files;
  EXPECT_EQ(files, 3u);
  for (uint32_t k = 0; k < 3; ++k) {
    std::ifstream in(out / maskLayerFileName("part", k, 3, "png"), std::ios::binary);
    const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    MaskImage back;
    ASSERT_TRUE(decodeMaskPng(bytes, back)) << k;
    EXPECT_TRUE(back.pixels == masks[k].pixels) << k;
  }
}

// ---------------------------------------------------------------------------------------------------
// SL1

using Sl1Archive = TempDirTest;

struct ZipContents {
  std::map<std::string, std::vector<uint8_t>> entries;
  std::vector<std::string> order;
  bool allStored = true;
};

ZipContents readZip(const fs::path& path) {
  ZipContents z;
  int err = 0;
  zip_t* zip = zip_open(path.c_str(), ZIP_RDONLY | ZIP_CHECKCONS, &err);
  EXPECT_NE(zip, nullptr) << "libzip error " << err;
  if (zip == nullptr) return z;
  const zip_int64_t n = zip_get_num_entries(zip, 0);
  for (zip_int64_t i = 0; i < n; ++i) {
    zip_stat_t st;
    zip_stat_init(&st);
    EXPECT_EQ(zip_stat_index(zip, static_cast<zip_uint64_t>(i), 0, &st), 0);
    z.allStored = z.allStored && st.comp_method == ZIP_CM_STORE;
    std::vector<uint8_t> data(st.size);
    zip_file_t* f = zip_fopen_index(zip, static_cast<zip_uint64_t>(i), 0);
    EXPECT_NE(f, nullptr);
    if (f != nullptr) {
      EXPECT_EQ(zip_fread(f, data.data(), st.size), static_cast<zip_int64_t>(st.size));  // checks the CRC too
      zip_fclose(f);
    }
    z.order.push_back(st.name);
    z.entries[st.name] = std::move(data);
  }
  zip_close(zip);
  return z;
}

std::string asText(const std::vector<uint8_t>& bytes) {
  return std::string(bytes.begin(), bytes.end());
}

TEST_F(Sl1Archive, HoldsLayersAndBothIniFiles) {
  MaskJob job = smallJob(40, 30, 3, true);
  job.printerModel = "SL1S";
  const fs::path out = dir_ / "part.sl1";
  std::vector<MaskImage> masks;
  for (uint32_t k = 0; k < 3; ++k) masks.push_back(discMask(40, 30, 20, 15, 5.0 + 3 * k, true));
  auto sink = makeMaskSink(out, job, false);
  std::vector<uint8_t> png;
  for (uint32_t k = 0; k < 3; ++k) {
    encodeMaskPng(masks[k], png);
    sink->writeLayer(k, 0.0125 + k * 0.025, masks[k]);
  }
  EXPECT_FALSE(fs::exists(out));
  job.volumeMl = 1.23456;
  sink->finish(job);
  ASSERT_TRUE(fs::is_regular_file(out));
  EXPECT_EQ(strayEntries(out).size(), 0u);

  const ZipContents z = readZip(out);
  EXPECT_TRUE(z.allStored);
  ASSERT_EQ(z.entries.size(), 5u);
  for (uint32_t k = 0; k < 3; ++k) {
    const std::string name = "part0000" + std::to_string(k) + ".png";
    ASSERT_EQ(z.entries.count(name), 1u) << name;
    MaskImage back;
    ASSERT_TRUE(decodeMaskPng(z.entries.at(name), back)) << name;
    EXPECT_EQ(back.width, 40u);
    EXPECT_EQ(back.height, 30u);
    EXPECT_TRUE(back.pixels == masks[k].pixels) << name;
  }
  ASSERT_EQ(z.entries.count("config.ini"), 1u);
  ASSERT_EQ(z.entries.count("prusaslicer.ini"), 1u);
  const auto config = parseIni(asText(z.entries.at("config.ini")));
  EXPECT_EQ(config.at("jobDir"), "part");
  EXPECT_EQ(config.at("action"), "print");
  EXPECT_EQ(config.at("numFast"), "3");
  EXPECT_EQ(config.at("numSlow"), "0");
  EXPECT_EQ(config.at("numFade"), "10");
  EXPECT_EQ(config.at("layerHeight"), "0.025");
  EXPECT_EQ(config.at("layerHeightFirst"), "0.025");
  EXPECT_EQ(config.at("expTime"), "8");
  EXPECT_EQ(config.at("expTimeFirst"), "35");
  EXPECT_EQ(config.at("usedMaterial"), "1.235");
  EXPECT_EQ(config.at("printerModel"), "SL1S");
  EXPECT_EQ(config.at("printerVariant"), "default");
  for (const char* key : {"printTime", "fileCreationTimestamp", "materialName", "printProfile",
                          "printerProfile", "prusaSlicerVersion", "expUserProfile", "hollow"}) {
    EXPECT_EQ(config.count(key), 1u) << key;
  }
  const auto profile = parseIni(asText(z.entries.at("prusaslicer.ini")));
  EXPECT_EQ(profile.at("display_pixels_x"), "40");
  EXPECT_EQ(profile.at("display_pixels_y"), "30");
  EXPECT_EQ(profile.at("display_width"), "2");
  EXPECT_EQ(profile.at("display_height"), "1.5");
  EXPECT_EQ(profile.at("display_orientation"), "landscape");
  EXPECT_EQ(profile.at("display_mirror_x"), "0");
  EXPECT_EQ(profile.at("display_mirror_y"), "0");
  EXPECT_EQ(profile.at("printer_technology"), "SLA");
  EXPECT_EQ(profile.at("printer_model"), "SL1S");
  EXPECT_EQ(profile.at("layer_height"), "0.025");
  EXPECT_EQ(profile.at("initial_layer_height"), "0.025");
  EXPECT_EQ(profile.at("gamma_correction"), "1");
  EXPECT_EQ(profile.at("exposure_time"), "8");
  EXPECT_EQ(profile.at("initial_exposure_time"), "35");
  EXPECT_EQ(profile.at("faded_layers"), "10");
}

TEST_F(Sl1Archive, EncodesItselfWithoutPngAndIsReproducible) {
  const MaskJob job = smallJob(20, 12, 2, false);
  ::setenv("SOURCE_DATE_EPOCH", "1700000000", 1);
  std::vector<std::vector<uint8_t>> files;
  for (const char* name : {"a.SL1", "b.sl1s"}) {
    auto sink = makeMaskSink(dir_ / name, job, false);
    for (uint32_t k = 0; k < 2; ++k) sink->writeLayer(k, 0.1 * k, discMask(20, 12, 10, 6, 2 + k, false));
    sink->finish(job);
    std::ifstream in(dir_ / name, std::ios::binary);
    files.emplace_back((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  }
  ::unsetenv("SOURCE_DATE_EPOCH");
  EXPECT_EQ(files[0], files[1]);
  const ZipContents z = readZip(dir_ / "a.SL1");
  EXPECT_EQ(z.entries.size(), 4u);
  const auto config = parseIni(asText(z.entries.at("config.ini")));
  EXPECT_EQ(config.at("fileCreationTimestamp"), "2023-11-14 at 22:13:20 UTC");
  EXPECT_EQ(config.at("printerModel"), "SL1");
  MaskImage back;
  ASSERT_TRUE(decodeMaskPng(z.entries.at("part00001.png"), back));
  EXPECT_TRUE(back.pixels == discMask(20, 12, 10, 6, 3, false).pixels);
}

// Thumbnails drawn when the sink is made, drawn later by drawPreviews() on another thread while layers
// are encoded, or drawn as the first layer is written (deferred, never asked): the same archive, with the
// thumbnails first. Layers larger than the writer's 1 MiB buffer go out around it.
TEST_F(Sl1Archive, DeferredThumbnailsGiveTheSameArchive) {
  const FacetSoup model = fixtures::sphere(4.0, 48, 24);
  const MaskJob job = previewJob(model, 1200, 900, 3, true);
  std::vector<MaskImage> masks;
  std::mt19937 random(3);
  for (uint32_t k = 0; k < 3; ++k) {
    MaskImage m = discMask(1200, 900, 600, 450, 100.0 + 50 * k, true);
    if (k == 1)  // noise: a PNG of about 1 MB, past the buffer
      for (uint8_t& p : m.pixels) p = static_cast<uint8_t>(random());
    masks.push_back(std::move(m));
  }
  std::vector<std::string> files;
  for (int way = 0; way < 3; ++way) {
    MaskJob j = job;
    j.deferPreviews = way > 0;
    const fs::path out = dir_ / ("part" + std::to_string(way) + ".sl1");
    auto sink = makeMaskSink(out, j, false);
    std::vector<EncodedMaskLayer> encoded(3);
    MaskEncodeScratch scratch;
    std::thread previews;
    if (way == 1) previews = std::thread([&sink] { sink->drawPreviews(); });
    for (uint32_t k = 0; k < 3; ++k) sink->encodeLayer(k, 0.1 * k, masks[k], encoded[k], scratch);
    if (previews.joinable()) previews.join();
    for (uint32_t k = 0; k < 3; ++k) sink->writeEncodedLayer(k, 0.1 * k, encoded[k]);
    sink->finish(j);
    files.push_back(fixtures::readFile(out));
    const ZipContents z = readZip(out);
    ASSERT_EQ(z.order.size(), 7u);
    EXPECT_EQ(z.order[0], "thumbnail/thumbnail400x400.png");
    EXPECT_EQ(z.order[1], "thumbnail/thumbnail800x480.png");
    MaskImage back;
    ASSERT_TRUE(decodeMaskPng(z.entries.at("part00001.png"), back));
    EXPECT_TRUE(back.pixels == masks[1].pixels);
  }
  EXPECT_GT(files[0].size(), std::size_t{1} << 20);
  EXPECT_TRUE(files[1] == files[0]);
  EXPECT_TRUE(files[2] == files[0]);
}

// GOO and NanoDLP store their previews at finish (the GOO header is rewritten then, NanoDLP's 3d.png
// added then): deferred, drawn by drawPreviews() on another thread while the layers are written, or
// never asked for (drawn at finish), the file is the one whose previews were drawn when the sink was
// made, byte for byte.
TEST_F(Sl1Archive, DeferredPreviewsOfGooAndNanoDlpGiveTheSameFile) {
  const FacetSoup model = fixtures::sphere(4.0, 48, 24);
  const MaskJob job = previewJob(model, 120, 90, 3, false);
  std::vector<MaskImage> masks;
  for (uint32_t k = 0; k < 3; ++k) masks.push_back(discMask(120, 90, 60, 45, 10.0 + 5 * k, false));
  for (const std::string ext : {".goo", ".nanodlp"}) {
    std::vector<std::string> files;
    for (int way = 0; way < 3; ++way) {
      MaskJob j = job;
      j.deferPreviews = way > 0;
      const fs::path out = dir_ / ("part" + std::to_string(way) + ext);
      auto sink = makeMaskSink(out, j, false);
      EXPECT_FALSE(sink->previewsBeforeLayers()) << ext;
      std::thread previews;
      if (way == 1) previews = std::thread([&sink] { sink->drawPreviews(); });
      for (uint32_t k = 0; k < 3; ++k) sink->writeLayer(k, 0.1 * k, masks[k]);
      if (previews.joinable()) previews.join();
      sink->finish(j);
      files.push_back(fixtures::readFile(out));
    }
    EXPECT_GT(files[0].size(), 1000u) << ext;
    EXPECT_TRUE(files[1] == files[0]) << ext << ": drawn beside the layers";
    EXPECT_TRUE(files[2] == files[0]) << ext << ": drawn at finish";
  }
}

TEST_F(Sl1Archive, Zip64PastSixtyFiveThousandEntries) {
  const uint32_t layers = 70000;
  const MaskJob job = smallJob(8, 8, layers, false);
  MaskImage m = blankMask(8, 8);
  m.pixels[9] = 255;
  std::vector<uint8_t> png;
  encodeMaskPng(m, png);
  auto sink = makeMaskSink(dir_ / "many.sl1", job, false);
  for (uint32_t k = 0; k < layers; ++k) sink->writeLayer(k, 0.025 * k, m);
  sink->finish(job);
  int err = 0;
  zip_t* zip = zip_open((dir_ / "many.sl1").c_str(), ZIP_RDONLY | ZIP_CHECKCONS, &err);
  ASSERT_NE(zip, nullptr) << "libzip error " << err;
  EXPECT_EQ(zip_get_num_entries(zip, 0), layers + 2);
  EXPECT_GE(zip_name_locate(zip, "part69999.png", 0), 0);
  EXPECT_GE(zip_name_locate(zip, "prusaslicer.ini", 0), 0);
  zip_close(zip);
}

TEST_F(Sl1Archive, RefusesMoreLayersThanFiveDigitNames) {
  const MaskJob job = smallJob(4, 4, kSl1MaxLayers + 1, false);
  EXPECT_THROW(makeMaskSink(dir_ / "big.sl1", job, false), OutputError);
  EXPECT_TRUE(strayEntries().empty());
}

TEST(Sl1Ini, FadeAndPrintTime) {
  MaskJob job = smallJob(10, 10, 20, false);
  job.fadeLayers = 1;  // the firmware divides by numFade - 1
  const auto config = parseIni(sl1ConfigIni(job, 20, 0));
  EXPECT_EQ(config.at("numFade"), "2");
  EXPECT_EQ(config.at("fileCreationTimestamp"), "1970-01-01 at 00:00:00 UTC");
  // First layer 35 s, the other 19 at 8 s, plus the per-layer overhead.
  EXPECT_EQ(config.at("printTime"), std::to_string(static_cast<int>(35 + 19 * 8 + 20 * kSl1LayerOverheadS)));
}

// ---------------------------------------------------------------------------------------------------
// EXR

using ExrStack = TempDirTest;

TEST_F(ExrStack, OneHalfFilePerLayerWithZAndLayer) {
  const MaskJob job = smallJob(33, 21, 3, true);
  const fs::path out = dir_ / "part.exr";
  std::vector<MaskImage> masks;
  for (uint32_t k = 0; k < 3; ++k) masks.push_back(discMask(33, 21, 16, 10, 4.0 + 2.5 * k, true));
  masks[2].pixels[0] = 255;  // pixel (0, 0): bottom-left
  auto sink = makeMaskSink(out, job, false);
  for (uint32_t k = 0; k < 3; ++k) sink->writeLayer(k, 0.0125 + k * 0.025, masks[k]);
  EXPECT_FALSE(fs::exists(out));
  sink->finish(job);
  ASSERT_TRUE(fs::is_directory(out));
  EXPECT_EQ(strayEntries(out).size(), 0u);
  for (uint32_t k = 0; k < 3; ++k) {
    const ExrMaskLayer layer = readExrMaskLayer(out / exrLayerFileName("part", k, 3));
    EXPECT_EQ(layer.channel, "Y");
    EXPECT_EQ(layer.width, 33u);
    EXPECT_EQ(layer.height, 21u);
    EXPECT_EQ(layer.layer, static_cast<int>(k));
    EXPECT_FLOAT_EQ(layer.z, static_cast<float>(0.0125 + k * 0.025));
    EXPECT_FLOAT_EQ(layer.pixelSize, 0.05f);
    EXPECT_FLOAT_EQ(layer.layerHeight, 0.025f);
    ASSERT_EQ(layer.values.size(), masks[k].pixels.size());
    for (size_t p = 0; p < layer.values.size(); ++p) {
      ASSERT_NEAR(layer.values[p], masks[k].pixels[p] / 255.0f, 1e-3f) << "layer " << k << " pixel " << p;
    }
  }
  if (!fs::exists("/usr/bin/exrheader")) GTEST_SKIP() << "exrheader not installed (Debian package openexr)";
  int rc = -1;
  const std::string text =
      tool_test::runTool("/usr/bin/exrheader '" + (out / "part.00001.exr").string() + "'", rc);
  EXPECT_EQ(rc, 0) << text;
  EXPECT_NE(text.find("z (type float): 0.0375"), std::string::npos) << text;
  EXPECT_NE(text.find("layer (type int): 1"), std::string::npos) << text;
  EXPECT_NE(text.find("Y, 16-bit floating-point"), std::string::npos) << text;
  EXPECT_NE(text.find("zip"), std::string::npos) << text;
}

// Tight row extents, as the binary rasterizer keeps them.
void addExtents(MaskImage& m) {
  m.litBegin.assign(m.height, m.width);
  m.litEnd.assign(m.height, 0);
  for (uint32_t j = 0; j < m.height; ++j) {
    for (uint32_t i = 0; i < m.width; ++i) {
      if (m.pixels[size_t{j} * m.width + i] == 0) continue;
      m.litBegin[j] = std::min(m.litBegin[j], i);
      m.litEnd[j] = i + 1;
    }
  }
}

// Masks that reach every path of the EXR chunk coder: rows equal to the row above (copies), dark rows,
// noise (chunks stored raw), widths below 4 (no copies) and over 32768 (no copies), heights that end
// on a partial 16-line chunk, and binary masks with the rasterizer's lit extents.
std::vector<MaskImage> exrTestMasks(bool antiAliased) {
  std::vector<MaskImage> masks;
  std::mt19937 rng(antiAliased ? 7 : 3);
  auto below = [&rng](uint32_t n) { return static_cast<uint32_t>(rng() % n); };
  const uint32_t levels = antiAliased ? 256 : 2;
  for (const auto& [w, h] : std::vector<std::pair<uint32_t, uint32_t>>{
           {1, 1}, {1, 17}, {2, 5}, {3, 33}, {4, 16}, {37, 50}, {300, 41}, {40000, 3}}) {
    masks.push_back(randomRunMask(w, h, levels, 1 + w / 3, true, below));
    masks.push_back(noiseMask(w, h, w + h, !antiAliased));
    masks.push_back(blankMask(w, h));
  }
  masks.push_back(discMask(200, 90, 100, 45, 30, antiAliased));
  MaskImage lit = blankMask(64, 40);
  std::fill(lit.pixels.begin(), lit.pixels.end(), antiAliased ? 200 : 255);
  masks.push_back(lit);
  if (!antiAliased) {  // the same disc with tight lit extents, as the binary rasterizer leaves them
    MaskImage m = discMask(200, 90, 100, 45, 30, false);
    addExtents(m);
    masks.push_back(m);
  }
  return masks;
}

TEST_F(ExrStack, IndependentReadersGetTheSl1PixelsBack) {
  for (const bool antiAliased : {false, true}) {
    const std::vector<MaskImage> masks = exrTestMasks(antiAliased);
    for (size_t n = 0; n < masks.size(); ++n) {
      const MaskImage& m = masks[n];
      const MaskJob job = smallJob(m.width, m.height, 2, antiAliased);
      const std::string tag = std::to_string(n) + (antiAliased ? "aa" : "bin");
      auto exr = makeMaskSink(dir_ / (tag + ".exr"), job, false);
      auto sl1 = makeMaskSink(dir_ / (tag + ".sl1"), job, false);
      for (uint32_t k = 0; k < 2; ++k) {
        exr->writeLayer(k, 0.5 + k, m);
        sl1->writeLayer(k, 0.5 + k, m);
      }
      exr->finish(job);
      sl1->finish(job);
      const ZipContents z = readZip(dir_ / (tag + ".sl1"));
      for (uint32_t k = 0; k < 2; ++k) {
        MaskImage png;
        ASSERT_TRUE(decodeMaskPng(z.entries.at(maskLayerFileName("part", k, kSl1MaxLayers, "png")), png));
        const fs::path file = dir_ / (tag + ".exr") / exrLayerFileName("part", k, 2);
        const TinyExrLayer t = readExrWithTinyExr(file);
        ASSERT_EQ(t.error, "") << tag;
        EXPECT_EQ(t.compression, "zip") << tag;
        EXPECT_EQ(t.layer, static_cast<int>(k)) << tag;
        EXPECT_FLOAT_EQ(t.z, static_cast<float>(0.5 + k)) << tag;
        EXPECT_TRUE(t.exact) << tag;
        EXPECT_TRUE(t.mask.pixels == png.pixels) << tag << " " << m.width << "x" << m.height;
        const ExrMaskLayer o = readExrMaskLayer(file);  // OpenEXR's own reader agrees
        ASSERT_EQ(o.values.size(), png.pixels.size()) << tag;
        for (size_t p = 0; p < o.values.size(); ++p) {
          ASSERT_EQ(std::lround(o.values[p] * 255.0f), png.pixels[p]) << tag << " pixel " << p;
        }
      }
    }
  }
}

TEST_F(ExrStack, TwoStepEncodingGivesTheSameFiles) {
  const MaskImage m = discMask(300, 70, 150, 35, 25, true);
  const MaskJob job = smallJob(300, 70, 1, true);
  auto a = makeMaskSink(dir_ / "a.exr", job, false);
  auto b = makeMaskSink(dir_ / "b.exr", job, false);
  a->writeLayer(0, 0.25, m);
  EncodedMaskLayer encoded;
  MaskEncodeScratch scratch;
  b->encodeLayer(0, 0.25, m, encoded, scratch);
  b->writeEncodedLayer(0, 0.25, encoded);
  a->finish(job);
  b->finish(job);
  std::ifstream fa(dir_ / "a.exr" / "part.00000.exr", std::ios::binary);
  std::ifstream fb(dir_ / "b.exr" / "part.00000.exr", std::ios::binary);
  const std::string sa((std::istreambuf_iterator<char>(fa)), {}),
      sb((std::istreambuf_iterator<char>(fb)), {});
  EXPECT_FALSE(sa.empty());
  EXPECT_TRUE(sa == sb);
  EXPECT_TRUE(std::string(encoded.bytes.begin(), encoded.bytes.end()) == sa);
}

TEST(ExrNames, SequenceReadersFindTheFrameNumber) {
  EXPECT_EQ(exrLayerFileName("case0", 7, 3), "case0.00007.exr");
  EXPECT_EQ(exrLayerFileName("", 12, 200000), "layer.000012.exr");
}

// ---------------------------------------------------------------------------------------------------
// VDB

using VdbGrid = TempDirTest;
using VdbSlabs = TempDirTest;

// Layers with full 8x8x8 blocks (tiles), partial blocks at the image edges and sparse noise.
std::vector<MaskImage> vdbLayers(uint32_t width, uint32_t height, uint32_t count, bool antiAliased) {
  std::vector<MaskImage> layers;
  for (uint32_t k = 0; k < count; ++k) {
    MaskImage m = discMask(width, height, width / 2.0, height / 2.0, width / 3.0 + (k % 5), antiAliased);
    if (k % 7 == 3) m.pixels[size_t{height - 1} * width + (width - 1)] = 200;  // top-right corner
    layers.push_back(std::move(m));
  }
  return layers;
}

void writeAll(MaskSink& sink, const std::vector<MaskImage>& layers, double z0, double h) {
  for (uint32_t k = 0; k < layers.size(); ++k) sink.writeLayer(k, z0 + k * h, layers[k]);
}

// What a layer reads back as: binary grids hold lit (255) or dark.
MaskImage asRead(MaskImage m, bool antiAliased) {
  if (!antiAliased)
    for (uint8_t& p : m.pixels) p = p ? 255 : 0;
  return m;
}

TEST_F(VdbGrid, BinaryStackIsOneMaskGridWithTransformAndMetadata) {
  const uint32_t width = 45, height = 29, count = 20;
  const MaskJob job = smallJob(width, height, count, false);
  const fs::path out = dir_ / "part.vdb";
  const auto layers = vdbLayers(width, height, count, false);
  auto sink = makeMaskSink(out, job, false);
  writeAll(*sink, layers, 0.0125, 0.025);
  EXPECT_FALSE(fs::exists(out));
  sink->finish(job);
  ASSERT_TRUE(fs::is_regular_file(out));
  EXPECT_EQ(strayEntries(out).size(), 0u);

  const auto grids = readVdbSlabs(out);
  ASSERT_EQ(grids.size(), 1u);
  uint64_t lit = 0;
  for (const auto& m : layers) lit += litPixels(m);
  EXPECT_EQ(grids[0].name, "density");
  EXPECT_EQ(grids[0].valueType, "mask");
  EXPECT_EQ(grids[0].activeVoxels, lit);
  EXPECT_EQ(grids[0].firstLayer, 0);
  EXPECT_EQ(grids[0].lastLayer, 19);
  EXPECT_NEAR(grids[0].voxelSize[0], 0.05, 1e-12);
  EXPECT_NEAR(grids[0].voxelSize[1], 0.05, 1e-12);
  EXPECT_NEAR(grids[0].voxelSize[2], 0.025, 1e-12);
  EXPECT_NEAR(grids[0].voxelOrigin[0], -1.0 + 0.025, 1e-12);  // x0 + p/2
  EXPECT_NEAR(grids[0].voxelOrigin[1], 2.0 + 0.025, 1e-12);
  EXPECT_NEAR(grids[0].voxelOrigin[2], 0.0125, 1e-12);  // the first layer's plane
  for (uint32_t k = 0; k < count; ++k)
    EXPECT_TRUE(readVdbLayer(out, k, width, height).pixels == asRead(layers[k], false).pixels)
        << "layer " << k;
  EXPECT_THROW(readVdbLayer(out, count, width, height), InputError);

  if (!fs::exists("/usr/bin/vdb_print"))
    GTEST_SKIP() << "vdb_print not installed (Debian package libopenvdb-tools)";
  int rc = -1;
  const std::string text = tool_test::runTool("/usr/bin/vdb_print -l '" + out.string() + "'", rc);
  EXPECT_EQ(rc, 0) << text;
  for (const char* expected : {"density", "first_z", "mirror_x", "origin_y", "layout: single"})
    EXPECT_NE(text.find(expected), std::string::npos) << expected << "\n" << text;
}

// 150 layers (more than one old slab, not a multiple of 8), fully lit 8^3 blocks (tiles) in the middle,
// anti-aliased values on the rims, every layer back exactly.
TEST_F(VdbGrid, AntiAliasedStackIsOneFloatGrid) {
  const uint32_t width = 24, height = 17, count = 150;
  const MaskJob job = smallJob(width, height, count, true);
  const fs::path out = dir_ / "part.vdb";
  const auto layers = vdbLayers(width, height, count, true);
  auto sink = makeMaskSink(out, job, false);
  writeAll(*sink, layers, 0.5, 0.025);
  sink->finish(job);

  const auto grids = readVdbSlabs(out);
  ASSERT_EQ(grids.size(), 1u);
  uint64_t lit = 0;
  for (const auto& m : layers) lit += litPixels(m);
  EXPECT_EQ(grids[0].name, "density");
  EXPECT_EQ(grids[0].valueType, "float");
  EXPECT_EQ(grids[0].activeVoxels, lit);
  EXPECT_EQ(grids[0].lastLayer, 149);
  EXPECT_NEAR(grids[0].voxelOrigin[2], 0.5, 1e-12);
  for (uint32_t k = 0; k < count; ++k)
    EXPECT_TRUE(readVdbLayer(out, k, width, height).pixels == layers[k].pixels) << "layer " << k;
}

// The parallel path (encodeLayer anywhere, writeEncodedLayer in order) writes the same voxels as
// writeLayer, with and without row extents (the binary rasterizer keeps them), for images whose sides
// are not multiples of 8.
TEST_F(VdbGrid, EncodedLayersGiveTheSameVoxels) {
  for (const bool antiAliased : {false, true}) {
    const uint32_t width = 37, height = 21, count = 19;
    const MaskJob job = smallJob(width, height, count, antiAliased);
    auto layers = vdbLayers(width, height, count, antiAliased);
    for (uint32_t k = 0; k < count; ++k) {
      const MaskImage noise = noiseMask(width, height, k, !antiAliased);
      for (size_t p = 0; p < noise.pixels.size(); p += 5) layers[k].pixels[p] = noise.pixels[p];
      if (k == 4) std::fill(layers[k].pixels.begin(), layers[k].pixels.end(), 0);  // a dark layer
      if (k % 2 == 0) addExtents(layers[k]);
    }
    const fs::path out = dir_ / (antiAliased ? "aa.vdb" : "bin.vdb");
    auto sink = makeMaskSink(out, job, false);
    std::vector<EncodedMaskLayer> encoded(count);
    MaskEncodeScratch scratch;
    for (uint32_t k = count; k-- > 0;)  // any order
      sink->encodeLayer(k, 0.1 + k * 0.025, layers[k], encoded[k], scratch);
    for (uint32_t k = 0; k < count; ++k) sink->writeEncodedLayer(k, 0.1 + k * 0.025, encoded[k]);
    sink->finish(job);
    for (uint32_t k = 0; k < count; ++k) {
      EXPECT_TRUE(readVdbLayer(out, k, width, height).pixels == asRead(layers[k], antiAliased).pixels)
          << (antiAliased ? "anti-aliased" : "binary") << " layer " << k;
    }
  }
}

TEST_F(VdbGrid, MirroredImagesKeepWorldPositions) {
  MaskJob job = smallJob(10, 6, 1, false);
  job.grid.mirrorX = true;
  const fs::path out = dir_ / "m.vdb";
  auto sink = makeMaskSink(out, job, false);
  sink->writeLayer(0, 1.0, discMask(10, 6, 5, 3, 2, false));
  sink->finish(job);
  const auto grids = readVdbSlabs(out);
  ASSERT_EQ(grids.size(), 1u);
  EXPECT_NEAR(grids[0].voxelOrigin[0], -1.0 + 9.5 * 0.05, 1e-12);  // pixel 0 shows column width-1
  EXPECT_NEAR(grids[0].voxelOrigin[1], 2.0 + 0.025, 1e-12);
  EXPECT_NEAR(grids[0].voxelSize[0], 0.05, 1e-12);
}

TEST_F(VdbSlabs, SlabLayoutWritesOneGridPer64Layers) {
  for (const bool antiAliased : {false, true}) {
    const uint32_t width = 24, height = 17, count = 150;
    MaskJob job = smallJob(width, height, count, antiAliased);
    job.vdbSlabs = true;
    const fs::path out = dir_ / (antiAliased ? "aa.vdb" : "bin.vdb");
    const auto layers = vdbLayers(width, height, count, antiAliased);
    auto sink = makeMaskSink(out, job, false);
    writeAll(*sink, layers, 0.5, 0.025);
    sink->finish(job);

    const auto slabs = readVdbSlabs(out);
    ASSERT_EQ(slabs.size(), 3u);  // layers 0-63, 64-127, 128-149
    const int first[] = {0, 64, 128}, last[] = {63, 127, 149};
    for (size_t s = 0; s < 3; ++s) {
      EXPECT_EQ(slabs[s].valueType, antiAliased ? "float" : "mask");
      EXPECT_EQ(slabs[s].firstLayer, first[s]);
      EXPECT_EQ(slabs[s].lastLayer, last[s]);
      uint64_t lit = 0;
      for (int k = first[s]; k <= last[s]; ++k) lit += litPixels(layers[static_cast<size_t>(k)]);
      EXPECT_EQ(slabs[s].activeVoxels, lit) << slabs[s].name;
      EXPECT_NEAR(slabs[s].voxelOrigin[2], 0.5, 1e-12);  // one transform for all slabs: k is absolute
    }
    EXPECT_EQ(slabs[0].name, "mask_00000");
    EXPECT_EQ(slabs[1].name, "mask_00064");
    for (uint32_t k : {0u, 63u, 64u, 100u, 149u}) {
      EXPECT_TRUE(readVdbLayer(out, k, width, height).pixels == asRead(layers[k], antiAliased).pixels)
          << "layer " << k;
    }
    EXPECT_THROW(readVdbLayer(out, 150, width, height), InputError);
  }
}

// ---------------------------------------------------------------------------------------------------
// Staging rules shared by every sink

using MaskStaging = TempDirTest;

const char* const kOutputs[] = {"stack", "part.sl1", "part.exr", "part.vdb"};

TEST_F(MaskStaging, InterruptedWritesLeaveNothing) {
  const MaskJob job = smallJob(16, 16, 4, false);
  const MaskImage m = discMask(16, 16, 8, 8, 5, false);
  for (const char* name : kOutputs) {
    {
      auto sink = makeMaskSink(dir_ / name, job, false);
      sink->writeLayer(0, 0.0125, m);
      sink->writeLayer(1, 0.0375, m);
      EXPECT_FALSE(strayEntries().empty()) << name << ": the temporary should exist while writing";
    }  // destroyed without finish()
    EXPECT_FALSE(fs::exists(dir_ / name)) << name;
    EXPECT_TRUE(strayEntries().empty()) << name << ": " << (strayEntries().empty() ? "" : strayEntries()[0]);
  }
}

// What a batch re-run takes as a finished output (outputLooksWhole): every sink's complete output, but
// not an empty one, a PNG or GOO cut short, or a folder with a layer missing between others.
TEST_F(MaskStaging, WholeOutputsAndBrokenOnes) {
  const MaskJob job = smallJob(16, 16, 4, false);
  const MaskImage m = discMask(16, 16, 8, 8, 5, false);
  for (const char* name : {"stack", "part.sl1", "part.exr", "part.vdb", "part.goo", "part.nanodlp"}) {
    auto sink = makeMaskSink(dir_ / name, job, false);
    for (uint32_t k = 0; k < 4; ++k) sink->writeLayer(k, 0.0125 + 0.025 * k, m);
    sink->finish(job);
    const std::string ext = lowerExtension(dir_ / name);
    EXPECT_TRUE(outputLooksWhole(dir_ / name, ext.empty() ? ".png" : ext)) << name;
  }
  const auto cut = [&](const fs::path& path) {
    std::string bytes = tool_test::readBytes(path);
    tool_test::writeBytes(path, bytes.substr(0, bytes.size() - 5));
  };
  cut(dir_ / "part.goo");
  EXPECT_FALSE(outputLooksWhole(dir_ / "part.goo"));
  cut(dir_ / "part.sl1");
  EXPECT_FALSE(outputLooksWhole(dir_ / "part.sl1"));
  tool_test::writeBytes(dir_ / "part.vdb", "");
  EXPECT_FALSE(outputLooksWhole(dir_ / "part.vdb"));
  std::vector<fs::path> layers;
  for (const auto& e : fs::directory_iterator(dir_ / "stack")) layers.push_back(e.path());
  std::sort(layers.begin(), layers.end());
  ASSERT_EQ(layers.size(), 4u);
  cut(layers[3]);
  EXPECT_FALSE(outputLooksWhole(dir_ / "stack", ".png"));
  fs::remove(layers[3]);  // the last layer gone: the layers left are whole and without a gap
  EXPECT_TRUE(outputLooksWhole(dir_ / "stack", ".png"));
  fs::remove(layers[1]);  // one between others gone
  EXPECT_FALSE(outputLooksWhole(dir_ / "stack", ".png"));
  fs::remove(layers[0]);  // from 1: the first is missing
  EXPECT_FALSE(outputLooksWhole(dir_ / "stack", ".png"));
  // An EXR layer cut short ends before its last chunk; a stack short of its last layer has fewer layers
  // than each one's layerCount says.
  std::vector<fs::path> exr;
  for (const auto& e : fs::directory_iterator(dir_ / "part.exr")) exr.push_back(e.path());
  std::sort(exr.begin(), exr.end());
  const std::string layer = tool_test::readBytes(exr[1]);
  cut(exr[1]);
  EXPECT_FALSE(outputLooksWhole(dir_ / "part.exr", ".exr"));
  tool_test::writeBytes(exr[1], layer);
  EXPECT_TRUE(outputLooksWhole(dir_ / "part.exr", ".exr"));
  fs::remove(exr[3]);
  EXPECT_FALSE(outputLooksWhole(dir_ / "part.exr", ".exr"));
}

// OpenVDB's transform refuses a tiny scale with its own words ("ArithmeticError: Non-zero scale values
// required"): said in ours, naming the sizes, before anything is written.
TEST_F(MaskStaging, VdbVoxelTooSmallForOpenVdbIsNamed) {
  MaskJob job = smallJob(16, 16, 2, false);
  job.grid.pixel = 1e-9;
  try {
    makeMaskSink(dir_ / "tiny.vdb", job, false);
    ADD_FAILURE() << "accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("a VDB voxel of 1e-09 x 1e-09 x"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(strayEntries().empty());
}

TEST_F(MaskStaging, ExistingOutputNeedsOverwrite) {
  const MaskJob job = smallJob(16, 16, 1, false);
  const MaskImage m = discMask(16, 16, 8, 8, 5, false);
  // What an earlier toposlice run left: an archive or grid file that starts as its format does, or a
  // folder of layer files. Only such outputs are replaced, and only with overwrite.
  auto makeOld = [](const fs::path& out) {
    const std::string ext = out.extension().string();
    if (ext.empty() || ext == ".exr") {
      fs::create_directory(out);
      const std::string layer = ext.empty() ? ".png" : ".exr";
      std::ofstream(out / ("old00000" + layer)) << fixtures::fileToposliceWrote(layer, "old");
    } else {
      std::ofstream(out) << fixtures::fileToposliceWrote(ext, "old");
    }
  };
  for (size_t n = 0; n < std::size(kOutputs); ++n) {
    const char* name = kOutputs[n];
    const fs::path out = dir_ / name;
    makeOld(out);
    const auto before = fs::is_directory(out) ? std::uintmax_t{0} : fs::file_size(out);
    EXPECT_THROW(makeMaskSink(out, job, false), OutputError) << name;
    EXPECT_EQ(fs::is_directory(out) ? std::uintmax_t{0} : fs::file_size(out), before) << name;
    auto sink = makeMaskSink(out, job, true);
    sink->writeLayer(0, 0.0125, m);
    sink->finish(job);
    EXPECT_TRUE(fs::exists(out)) << name;
    EXPECT_FALSE(fs::exists(out / "old00000.png") || fs::exists(out / "old00000.exr")) << name;
    EXPECT_FALSE(fs::is_regular_file(out) && fs::file_size(out) == before) << name << " was not replaced";
    EXPECT_EQ(strayEntries(out).size(), n) << name;  // the outputs of the previous rounds
  }
  // A second run over directory outputs replaces them too.
  auto sink = makeMaskSink(dir_ / "stack", job, true);
  sink->writeLayer(0, 0.0125, m);
  sink->finish(job);
  EXPECT_TRUE(fs::is_regular_file(dir_ / "stack" / "part00000.png"));
}

// Overwrite replaces only what toposlice writes: a folder holding anything but layer files, a file at a
// folder output's path, or a file of another format is refused, and left exactly as it was.
TEST_F(MaskStaging, OverwriteNeverReplacesForeignContent) {
  const MaskJob job = smallJob(16, 16, 1, false);
  fs::create_directory(dir_ / "stack");
  std::ofstream(dir_ / "stack" / "part00000.png") << fixtures::fileToposliceWrote(".png", "png");
  std::ofstream(dir_ / "stack" / "notes.txt") << "mine";
  fs::create_directory(dir_ / "stack2");
  fs::create_directory(dir_ / "stack2" / "sub");
  // Layer files named as toposlice names them, of their format, but written by another program: a PNG
  // without toposlice's tEXt chunk, an EXR without its "software" attribute.
  fs::create_directory(dir_ / "stack3");
  std::ofstream(dir_ / "stack3" / "photo00001.png") << std::string("\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR", 16);
  fs::create_directory(dir_ / "part.exr");
  std::ofstream(dir_ / "part.exr" / "render0001.exr") << std::string("v/1\x01\2\0\0\0channels\0chlist\0", 24);
  std::ofstream(dir_ / "plain") << "a file where a folder would go";
  std::ofstream(dir_ / "part.sl1") << "not a zip";
  // A grid file of another program: the VDB magic without toposlice's "creator".
  std::ofstream(dir_ / "part.vdb") << std::string(" BDV\0\0\0\0\xe0\0\0\0", 12) << "houdini";
  const std::pair<const char*, const char*> cases[] = {
      {"stack", "notes.txt"},     {"stack2", "sub"},         {"stack3", "photo00001.png"},
      {"part.exr", "render0001"}, {"plain", "not a folder"}, {"part.sl1", "not a sl1"},
      {"part.vdb", "not a vdb"}};
  for (const auto& [name, named] : cases) {
    try {
      makeMaskSink(dir_ / name, job, true);
      ADD_FAILURE() << name << ": replaced";
    } catch (const OutputError& e) {
      EXPECT_NE(std::string(e.what()).find(named), std::string::npos) << e.what();
    }
  }
  EXPECT_TRUE(fs::exists(dir_ / "stack" / "notes.txt"));
  EXPECT_TRUE(fs::exists(dir_ / "stack2" / "sub"));
  EXPECT_TRUE(fs::exists(dir_ / "stack3" / "photo00001.png"));
  EXPECT_TRUE(fs::exists(dir_ / "part.exr" / "render0001.exr"));
  EXPECT_EQ(fs::file_size(dir_ / "part.sl1"), 9u);
  EXPECT_EQ(fs::file_size(dir_ / "part.vdb"), 19u);
}

TEST_F(MaskStaging, OutputCreatedMeanwhileIsNotReplaced) {
  const MaskJob job = smallJob(8, 8, 1, false);
  const MaskImage m = blankMask(8, 8);
  for (const char* name : kOutputs) {
    auto sink = makeMaskSink(dir_ / name, job, false);
    sink->writeLayer(0, 0.0125, m);
    {
      std::ofstream other(dir_ / name);
      other << "other";
    }
    EXPECT_THROW(sink->finish(job), OutputError) << name;
    sink.reset();
    EXPECT_EQ(fs::file_size(dir_ / name), 5u) << name;
    fs::remove(dir_ / name);
    EXPECT_TRUE(strayEntries().empty()) << name;
  }
}

TEST_F(MaskStaging, LayersMustArriveInOrderAtTheJobSize) {
  const MaskJob job = smallJob(8, 8, 3, false);
  for (const char* name : kOutputs) {
    auto sink = makeMaskSink(dir_ / name, job, false);
    EXPECT_THROW(sink->writeLayer(1, 0.0, blankMask(8, 8)), OutputError) << name;
    EXPECT_THROW(sink->writeLayer(0, 0.0, blankMask(9, 8)), OutputError) << name;
  }
  EXPECT_TRUE(strayEntries().empty());
}

}  // namespace
}  // namespace toposlice
