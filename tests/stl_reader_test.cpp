// STL reader: one decision per file of ../shared/models/stl_parser_edge_cases (the table below), real
// models in binary, ASCII and gzip form, and malformed bytes made here (truncations, NaN, corrupt gzip).
#include "io/readers/stl_reader.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "io/errors.h"

namespace toposlice {
namespace {

namespace fs = std::filesystem;
using Bytes = std::vector<std::byte>;

fs::path modelsDir() {
  return fs::path(TOPOSLICE_MODELS_DIR);
}
fs::path edgeCase(const std::string& file) {
  return modelsDir() / "stl_parser_edge_cases" / file;
}

Bytes bytesOf(std::string_view text) {
  Bytes bytes(text.size());
  if (!text.empty()) std::memcpy(bytes.data(), text.data(), text.size());
  return bytes;
}

Bytes readBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  EXPECT_TRUE(in.good()) << path;
  std::vector<char> chars((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  return bytesOf(std::string_view(chars.data(), chars.size()));
}

void putLe32(Bytes& out, uint32_t v) {
  for (int i = 0; i < 4; ++i) out.push_back(static_cast<std::byte>((v >> (8 * i)) & 0xFFu));
}

// A binary STL of the given corners (3 per facet); `count` overrides the facet count in the header.
Bytes makeBinary(const std::vector<Point3f>& corners, std::string_view header = "test", int64_t count = -1) {
  Bytes out(80, std::byte{0});
  std::memcpy(out.data(), header.data(), std::min<std::size_t>(header.size(), 80));
  putLe32(out, static_cast<uint32_t>(count >= 0 ? count : static_cast<int64_t>(corners.size() / 3)));
  for (std::size_t f = 0; f < corners.size() / 3; ++f) {
    for (int k = 0; k < 3; ++k) putLe32(out, 0);  // normal, ignored
    for (int c = 0; c < 3; ++c) {
      const Point3f& p = corners[3 * f + c];
      putLe32(out, std::bit_cast<uint32_t>(p.x));
      putLe32(out, std::bit_cast<uint32_t>(p.y));
      putLe32(out, std::bit_cast<uint32_t>(p.z));
    }
    out.push_back(std::byte{0});
    out.push_back(std::byte{0});
  }
  return out;
}

std::vector<Point3f> someCorners(std::size_t facets) {
  std::vector<Point3f> corners;
  for (std::size_t i = 0; i < facets * 3; ++i) {
    const auto v = static_cast<float>(i);
    corners.push_back({v, -0.5f * v, 0.25f * v + 1.0f});
  }
  return corners;
}

uint32_t crc32(const Bytes& data) {
  static const std::array<uint32_t, 256> table = [] {
    std::array<uint32_t, 256> t{};
    for (uint32_t n = 0; n < 256; ++n) {
      uint32_t c = n;
      for (int k = 0; k < 8; ++k) c = (c & 1u) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[n] = c;
    }
    return t;
  }();
  uint32_t crc = 0xFFFFFFFFu;
  for (std::byte b : data) crc = table[(crc ^ std::to_integer<uint32_t>(b)) & 0xFFu] ^ (crc >> 8);
  return crc ^ 0xFFFFFFFFu;
}

// A gzip member (RFC 1952) holding `data` in stored (uncompressed) deflate blocks (RFC 1951 3.2.4).
Bytes gzipStored(const Bytes& data) {
  Bytes out = {std::byte{0x1F}, std::byte{0x8B}, std::byte{8}, std::byte{0}, std::byte{0},
               std::byte{0},    std::byte{0},    std::byte{0}, std::byte{0}, std::byte{0xFF}};
  std::size_t at = 0;
  do {
    const std::size_t len = std::min<std::size_t>(data.size() - at, 65535);
    const bool last = at + len == data.size();
    out.push_back(std::byte{last ? uint8_t{1} : uint8_t{0}});
    const auto len16 = static_cast<uint16_t>(len);
    const auto nlen16 = static_cast<uint16_t>(~len16);
    out.push_back(static_cast<std::byte>(len16 & 0xFFu));
    out.push_back(static_cast<std::byte>(len16 >> 8));
    out.push_back(static_cast<std::byte>(nlen16 & 0xFFu));
    out.push_back(static_cast<std::byte>(nlen16 >> 8));
    out.insert(out.end(), data.begin() + static_cast<std::ptrdiff_t>(at),
               data.begin() + static_cast<std::ptrdiff_t>(at + len));
    at += len;
  } while (at < data.size());
  putLe32(out, crc32(data));
  putLe32(out, static_cast<uint32_t>(data.size()));
  return out;
}

// The message of the InputError that `parse` throws; fails the test when it throws nothing or another type.
template <class Parse>
std::string inputErrorOf(Parse parse) {
  try {
    parse();
  } catch (const InputError& error) {
    return error.what();
  } catch (const std::exception& other) {
    ADD_FAILURE() << "not an InputError: " << other.what();
    return {};
  }
  ADD_FAILURE() << "no InputError thrown";
  return {};
}

std::string parseError(const Bytes& bytes, const std::string& name = "mem.stl") {
  return inputErrorOf([&] { parseStl(bytes, name); });
}

bool samePoint(const Point3f& a, const Point3f& b) {
  return a.x == b.x && a.y == b.y && a.z == b.z;
}

// ---------------------------------------------------------------------------------------------------
// Edge-case files: one decision each.

struct EdgeCase {
  const char* file;
  std::size_t facets;  // 0: the file is rejected
  const char* phrase;  // for a rejected file: part of the message (after "<path>: ")
};

const EdgeCase kEdgeCases[] = {
    // 0 bytes.
    {"empty.stl", 0, "empty file"},
    // "solid empty" / "endsolid empty" and nothing between: a valid frame holding no mesh.
    {"faceless.ascii.stl", 0, "contains no facets"},
    // First facet has a 4th vertex: polygons are not triangulated; the message names facet and line.
    {"fourVertices.ascii.stl", 0, "facet 0 (line 2): 4 vertices, expected 3"},
    // Binary, header count 66 but data for 4 facets: the count is wrong, the data is not trusted.
    {"incorrectFaceCounter.bin.stl", 0,
     "truncated: expected 66 facets (3384 bytes), file has 284 bytes (binary facet count does not match"},
    // Ends after the last endfacet without endsolid: all 4 facets are complete, so it loads.
    {"missingEndsolid.ascii.stl", 4, ""},
    // A tetrahedron with one facet left out: an open surface is still a valid soup.
    {"missingFace.ascii.stl", 3, ""},
    // Last facet has "facet normal" with no values: the grammar needs 3 numbers there.
    {"missingNormal.ascii.stl", 0, "facet 3 (line 24): 'facet normal' needs 3 numbers, found 'outer'"},
    // Solid name of several words: kept whole in StlSource::solidName.
    {"multiWordName.ascii.stl", 4, ""},
    // Binary whose bytes went through a UTF-8 conversion (EF BF BD inserted): 333 bytes for 4 facets.
    {"multiWordName.bin.stl", 0,
     "binary facet count does not match the file length: expected 4 facets (284 bytes), file has 333 bytes"},
    // "solid" with no name, "endsolid" with no name.
    {"namelessSolid.ascii.stl", 4, ""},
    // Facet normal "NaN NaN NaN": normals are ignored, and NaN lexes as a number.
    {"notANumberNormal.ascii.stl", 4, ""},
    // A 4-vertex facet (a quad): rejected like fourVertices.
    {"quad.ascii.stl", 0, "facet 0 (line 2): 4 vertices, expected 3"},
    // One facet: a valid (open) soup.
    {"singleFace.ascii.stl", 1, ""},
    // "endsolid anything but tetrahedron": the endsolid name is ignored.
    {"solidNameMismatch.ascii.stl", 4, ""},
    // No indentation at all.
    {"tetrahedron.min.ascii.stl", 4, ""},
    // Binary tetrahedron whose normals hold -0.0: loads; values are kept bit for bit (welding merges
    // -0.0 with +0.0), see MinusZeroCoordinatesKept.
    {"tetrahedronMinusZero.bin.stl", 4, ""},
    // First facet has only 2 vertices.
    {"twoVertices.ascii.stl", 0, "facet 0 (line 2): 2 vertices, expected 3"},
    // Binary whose header starts with "solid": the length 84 + 50*12 decides binary.
    {"wrongHeader.bin.stl", 12, ""},
    // Last facet's normal disagrees with its winding: ignored, the corner order is kept.
    {"wrongNormal.ascii.stl", 4, ""},
    // All normals 0 0 0: ignored.
    {"wrongNormals.ascii.stl", 4, ""},
};

TEST(StlEdgeCases, EveryFileHasItsDecision) {
  for (const EdgeCase& c : kEdgeCases) {
    SCOPED_TRACE(c.file);
    const fs::path path = edgeCase(c.file);
    if (c.facets > 0) {
      StlSource source;
      FacetSoup soup;
      ASSERT_NO_THROW(soup = readStl(path, &source));
      EXPECT_EQ(soup.facetCount(), c.facets);
      EXPECT_EQ(soup.corners.size(), 3 * c.facets);
      EXPECT_EQ(source.binary, std::string_view(c.file).ends_with(".bin.stl"));
      EXPECT_FALSE(source.gzip);
    } else {
      const std::string message = inputErrorOf([&] { readStl(path); });
      EXPECT_NE(message.find(c.file), std::string::npos) << message;
      EXPECT_NE(message.find(c.phrase), std::string::npos) << message;
      EXPECT_EQ(message.rfind(path.string() + ": ", 0), 0u) << message;
    }
  }
}

TEST(StlEdgeCases, TableCoversEveryFileInTheFolder) {
  std::set<std::string> inTable;
  for (const EdgeCase& c : kEdgeCases) inTable.insert(c.file);
  std::set<std::string> inFolder;
  for (const auto& entry : fs::directory_iterator(edgeCase("")))
    inFolder.insert(entry.path().filename().string());
  EXPECT_EQ(inTable, inFolder);
}

TEST(StlEdgeCases, SolidNames) {
  StlSource source;
  readStl(edgeCase("multiWordName.ascii.stl"), &source);
  EXPECT_EQ(source.solidName, "Model with a multi word name");
  readStl(edgeCase("namelessSolid.ascii.stl"), &source);
  EXPECT_EQ(source.solidName, "");
  readStl(edgeCase("solidNameMismatch.ascii.stl"), &source);
  EXPECT_EQ(source.solidName, "tetrahedron");
  readStl(edgeCase("wrongHeader.bin.stl"), &source);
  EXPECT_TRUE(source.binary);
  EXPECT_EQ(source.solidName, "solid");
}

TEST(StlEdgeCases, CornersInFileOrderAsciiEqualsBinary) {
  const FacetSoup ascii = readStl(edgeCase("tetrahedron.min.ascii.stl"));
  const FacetSoup binary = readStl(edgeCase("tetrahedronMinusZero.bin.stl"));
  ASSERT_EQ(ascii.corners.size(), 12u);
  ASSERT_EQ(binary.corners.size(), 12u);
  EXPECT_TRUE(samePoint(ascii.corners[0], {1, 0, 0}));
  EXPECT_TRUE(samePoint(ascii.corners[1], {0, 1, 0}));
  EXPECT_TRUE(samePoint(ascii.corners[2], {0, 0, 1}));
  for (std::size_t i = 0; i < 12; ++i) EXPECT_TRUE(samePoint(ascii.corners[i], binary.corners[i])) << i;
}

// tetrahedronMinusZero.bin.stl holds its -0.0 values in the (ignored) normals only, so -0.0 corners are
// checked on bytes made here: kept bit for bit, in binary and in ASCII.
TEST(StlEdgeCases, MinusZeroCoordinatesKept) {
  const FacetSoup binary = parseStl(makeBinary({{-0.0f, 1, 0}, {0, -0.0f, 1}, {1, 0, -0.0f}}), "mem.stl");
  const FacetSoup ascii =
      parseStl(bytesOf("solid\nfacet normal 0 0 0 outer loop vertex -0 1 0 vertex 0 -0.0 1 vertex 1 0 -0e0 "
                       "endloop endfacet\n"),
               "mem.stl");
  for (const FacetSoup* soup : {&binary, &ascii}) {
    ASSERT_EQ(soup->corners.size(), 3u);
    EXPECT_TRUE(std::signbit(soup->corners[0].x));
    EXPECT_TRUE(std::signbit(soup->corners[1].y));
    EXPECT_TRUE(std::signbit(soup->corners[2].z));
    EXPECT_FALSE(std::signbit(soup->corners[1].x));
  }
}

// ---------------------------------------------------------------------------------------------------
// Real models.

TEST(StlModels, BunnyBinaryAndAsciiAgree) {
  StlSource binarySource, asciiSource;
  const FacetSoup binary = readStl(modelsDir() / "bunny_stanford_original.stl", &binarySource);
  const FacetSoup ascii = readStl(modelsDir() / "bunny_stanford_ascii.stl.gz", &asciiSource);
  EXPECT_TRUE(binarySource.binary);
  EXPECT_FALSE(binarySource.gzip);
  EXPECT_FALSE(asciiSource.binary);
  EXPECT_TRUE(asciiSource.gzip);
  EXPECT_EQ(asciiSource.solidName, "bunny");
  ASSERT_EQ(binary.facetCount(), 69451u);
  ASSERT_EQ(ascii.facetCount(), 69451u);
  // The ASCII file prints 7 significant digits: equal to the binary floats within half a unit there.
  std::size_t mismatches = 0;
  for (std::size_t i = 0; i < binary.corners.size(); ++i) {
    const Point3f& a = binary.corners[i];
    const Point3f& b = ascii.corners[i];
    const float pa[3] = {a.x, a.y, a.z};
    const float pb[3] = {b.x, b.y, b.z};
    for (int k = 0; k < 3; ++k) {
      if (std::abs(pa[k] - pb[k]) > 1e-6f * std::abs(pa[k]) + 1e-30f) ++mismatches;
    }
  }
  EXPECT_EQ(mismatches, 0u);
}

TEST(StlModels, GzipAlignerLoads) {
  StlSource source;
  const auto start = std::chrono::steady_clock::now();
  const FacetSoup soup = readStl(modelsDir() / "derived" / "aligner_upper_case0.stl.gz", &source);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  RecordProperty("load_seconds", std::to_string(seconds));
  std::printf("aligner_upper_case0.stl.gz: %zu facets in %.3f s\n", soup.facetCount(), seconds);
  EXPECT_EQ(soup.facetCount(), 544774u);
  EXPECT_TRUE(source.gzip);
  EXPECT_TRUE(source.binary);
  float minZ = std::numeric_limits<float>::max(), maxZ = -minZ;
  for (const Point3f& p : soup.corners) minZ = std::min(minZ, p.z), maxZ = std::max(maxZ, p.z);
  EXPECT_NEAR(minZ, -3.54f, 0.01f);
  EXPECT_NEAR(maxZ, 7.34f, 0.01f);
}

TEST(StlModels, GzipOfABinaryGivesTheSameSoup) {
  const Bytes plain = readBytes(modelsDir() / "bunny_stanford_original.stl");
  const FacetSoup expected = parseStl(plain, "plain");
  Bytes twoMembers = gzipStored(Bytes(plain.begin(), plain.begin() + 1000));
  const Bytes second = gzipStored(Bytes(plain.begin() + 1000, plain.end()));
  twoMembers.insert(twoMembers.end(), second.begin(), second.end());
  for (const Bytes& gz : {gzipStored(plain), twoMembers}) {
    StlSource source;
    const FacetSoup soup = parseStl(gz, "bunny.gz", &source);
    EXPECT_TRUE(source.gzip);
    EXPECT_TRUE(source.binary);
    ASSERT_EQ(soup.corners.size(), expected.corners.size());
    EXPECT_EQ(
        std::memcmp(soup.corners.data(), expected.corners.data(), soup.corners.size() * sizeof(Point3f)), 0);
  }
}

// ---------------------------------------------------------------------------------------------------
// Binary made here.

TEST(StlBinary, RoundTripAndHeaderName) {
  const std::vector<Point3f> corners = someCorners(5);
  StlSource source;
  const FacetSoup soup = parseStl(makeBinary(corners, "  part 7  "), "mem.stl", &source);
  EXPECT_TRUE(source.binary);
  EXPECT_EQ(source.solidName, "part 7");
  ASSERT_EQ(soup.corners.size(), corners.size());
  for (std::size_t i = 0; i < corners.size(); ++i) EXPECT_TRUE(samePoint(soup.corners[i], corners[i])) << i;
}

TEST(StlBinary, SolidHeaderWithBinaryLengthIsBinary) {
  const std::vector<Point3f> corners = someCorners(3);
  StlSource source;
  const FacetSoup soup = parseStl(makeBinary(corners, "solid looks like ascii"), "mem.stl", &source);
  EXPECT_TRUE(source.binary);
  EXPECT_EQ(soup.facetCount(), 3u);
}

TEST(StlBinary, ZeroFacetsIsAnError) {
  EXPECT_NE(parseError(makeBinary({})).find("mem.stl: contains no facets"), std::string::npos);
}

TEST(StlBinary, TruncatedAtSeveralOffsetsFails) {
  const Bytes full = makeBinary(someCorners(4), "test header");
  ASSERT_EQ(full.size(), 284u);
  for (std::size_t length : {1u, 2u, 50u, 80u, 83u, 84u, 85u, 100u, 133u, 134u, 200u, 234u, 283u}) {
    SCOPED_TRACE(length);
    const std::string message =
        parseError(Bytes(full.begin(), full.begin() + static_cast<std::ptrdiff_t>(length)));
    EXPECT_EQ(message.rfind("mem.stl: ", 0), 0u) << message;
    if (length >= 84) {
      const std::string expected =
          "truncated: expected 4 facets (284 bytes), file has " + std::to_string(length) + " bytes";
      EXPECT_NE(message.find(expected), std::string::npos) << message;
    } else {
      EXPECT_NE(message.find("not an STL file"), std::string::npos) << message;
    }
  }
  // Truncating a "solid"-headed binary: NUL bytes in the header still say binary, not ASCII.
  const Bytes solidHeaded = makeBinary(someCorners(4), "solid x");
  const std::string message = parseError(Bytes(solidHeaded.begin(), solidHeaded.begin() + 200));
  EXPECT_NE(message.find("truncated: expected 4 facets"), std::string::npos) << message;
}

TEST(StlBinary, LongerThanItsCountFails) {
  Bytes bytes = makeBinary(someCorners(2));
  bytes.push_back(std::byte{0});
  const std::string message = parseError(bytes);
  EXPECT_NE(
      message.find("facet count does not match the file length: expected 2 facets (184 bytes), file has "
                   "185 bytes"),
      std::string::npos)
      << message;
}

TEST(StlBinary, NonFiniteCoordinateNamesTheFacet) {
  for (float bad : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
                    -std::numeric_limits<float>::infinity()}) {
    std::vector<Point3f> corners = someCorners(6);
    corners[3 * 4 + 2].y = bad;  // facet 4
    const Bytes binary = makeBinary(corners);
    for (const Bytes& bytes : {binary, gzipStored(binary)}) {
      const std::string message = parseError(bytes);
      EXPECT_NE(message.find("mem.stl: facet 4: non-finite coordinate"), std::string::npos) << message;
    }
  }
}

// ---------------------------------------------------------------------------------------------------
// ASCII made here.

const char* const kTwoFacets =
    "solid two\n"
    "facet normal 0 0 1\n outer loop\n  vertex 0 0 0\n  vertex 1 0 0\n  vertex 0 1 0\n endloop\nendfacet\n"
    "facet normal 0 0 1\n outer loop\n  vertex 1 0 0\n  vertex 1 1 0\n  vertex 0 1 0\n endloop\nendfacet\n"
    "endsolid two\n";

TEST(StlAscii, ToleratesCaseWhitespaceSignsAndLineBreaks) {
  const std::string text =
      "\xEF\xBB\xBF  \r\nSOLID  Part  One \r\n"
      "FACET NORMAL +0 -0 1E+0\r\n\tOUTER LOOP\r\n"
      "\t\tVERTEX +1.5e+0 -2.25 3\r\n\t\tvertex 4. .5 -6e-1\r\n\t\tVertex\n7\n8\n9\r\n"
      "\tENDLOOP\r\nENDFACET\r\n"
      "facet normal 0 0 0 outer loop vertex 1e-50 0 0 vertex 0 1 0 vertex 0 0 1 endloop endfacet"
      "\r\nendsolid\r\n"
      "solid second\nfacet normal 0 0 1 outer loop vertex 1 1 1 vertex 2 2 2 vertex 3 3 3 endloop endfacet\n"
      "endsolid second";
  StlSource source;
  const FacetSoup soup = parseStl(bytesOf(text), "mem.stl", &source);
  EXPECT_FALSE(source.binary);
  EXPECT_EQ(source.solidName, "Part  One");
  ASSERT_EQ(soup.facetCount(), 3u);
  EXPECT_TRUE(samePoint(soup.corners[0], {1.5f, -2.25f, 3.0f}));
  EXPECT_TRUE(samePoint(soup.corners[1], {4.0f, 0.5f, -0.6f}));
  EXPECT_TRUE(samePoint(soup.corners[2], {7.0f, 8.0f, 9.0f}));
  EXPECT_EQ(soup.corners[3].x, 0.0f);  // below float's range
  EXPECT_TRUE(samePoint(soup.corners[8], {3.0f, 3.0f, 3.0f}));
}

TEST(StlAscii, FourVertexFacetFails) {
  std::string text = kTwoFacets;
  const std::string extra = "  vertex 1 1 1\n";
  text.insert(text.find(" endloop", text.find("vertex 1 1 0")), extra);
  EXPECT_NE(parseError(bytesOf(text)).find("mem.stl: facet 1 (line 9): 4 vertices, expected 3"),
            std::string::npos);
}

TEST(StlAscii, NonFiniteCoordinateNamesTheFacet) {
  for (const char* bad : {"nan", "NaN", "inf", "-Infinity"}) {
    std::string text = kTwoFacets;
    text.replace(text.find("vertex 1 1 0") + 7, 1, bad);
    const std::string message = parseError(bytesOf(text));
    EXPECT_NE(message.find("mem.stl: facet 1 (line 12): non-finite coordinate"), std::string::npos)
        << message;
  }
}

TEST(StlAscii, BadNumbersFail) {
  for (const char* bad : {"1,5", "0x10", "++1", "+-1", "1e", "abc", "1e39"}) {
    std::string text = kTwoFacets;
    text.replace(text.find("vertex 1 1 0") + 9, 1, bad);
    const std::string message = parseError(bytesOf(text));
    EXPECT_NE(message.find("mem.stl: facet 1 (line 12): "), std::string::npos) << bad << ": " << message;
  }
}

TEST(StlAscii, TruncatedInsideAFacetFailsAtAFacetBoundaryLoads) {
  const std::string text = kTwoFacets;
  const std::size_t secondFacet = text.find("facet", text.find("endfacet") + 8);
  for (std::size_t length :
       {secondFacet + 3, secondFacet + 12, secondFacet + 40, text.find("endsolid") - 2}) {
    SCOPED_TRACE(length);
    const std::string message = parseError(bytesOf(text.substr(0, length)));
    EXPECT_NE(message.find("mem.stl: facet 1 (line "), std::string::npos) << message;
  }
  EXPECT_EQ(parseStl(bytesOf(text.substr(0, secondFacet)), "mem.stl").facetCount(), 1u);
}

TEST(StlAscii, GarbageAfterEndsolidFails) {
  const std::string message = parseError(bytesOf(std::string(kTwoFacets) + "trailing words\n"));
  EXPECT_NE(message.find("mem.stl: line 17: expected 'solid', found 'trailing'"), std::string::npos)
      << message;
}

TEST(StlAscii, NotAnStlFails) {
  EXPECT_NE(parseError(bytesOf("hello")).find("mem.stl: not an STL file"), std::string::npos);
  EXPECT_NE(parseError(bytesOf(" \r\n\t ")).find("mem.stl: empty file"), std::string::npos);
  EXPECT_NE(parseError(bytesOf("solid x\nfacet normal 0 0 1\nouter loop\nendloop\nendfacet\n"))
                .find("facet 0 (line 2): 0 vertices, expected 3"),
            std::string::npos);
  EXPECT_NE(
      parseError(bytesOf("solid x\nvertex 0 0 0\n")).find("facet 0 (line 2): expected 'facet' or 'endsolid'"),
      std::string::npos);
  EXPECT_NE(parseError(Bytes{}).find("mem.stl: empty file"), std::string::npos);
  EXPECT_NE(parseError(bytesOf("\xEF\xBB\xBF\r\n\n solid x\nfacet normal 1 2\n"))
                .find("mem.stl: facet 0 (line 5): 'facet normal' needs 3 numbers, found end of file"),
            std::string::npos);
}

// ---------------------------------------------------------------------------------------------------
// gzip and files.

TEST(StlGzip, CorruptOrTruncatedStreamFails) {
  const Bytes stl = bytesOf(kTwoFacets);
  const Bytes gz = gzipStored(stl);
  ASSERT_EQ(parseStl(gz, "mem.stl.gz").facetCount(), 2u);

  Bytes flipped = gz;
  flipped[40] ^= std::byte{0x01};  // a data byte: the CRC no longer matches
  EXPECT_NE(parseError(flipped).find("mem.stl: corrupt gzip stream"), std::string::npos);
  Bytes badMethod = gz;
  badMethod[2] = std::byte{7};
  EXPECT_NE(parseError(badMethod).find("mem.stl: corrupt gzip stream"), std::string::npos);
  Bytes trailing = gz;
  trailing.push_back(std::byte{'x'});
  EXPECT_NE(parseError(trailing).find("corrupt gzip stream: 1 unexpected bytes"), std::string::npos);
  for (std::size_t length : {2u, 5u, 10u, 30u}) {
    EXPECT_NE(parseError(Bytes(gz.begin(), gz.begin() + static_cast<std::ptrdiff_t>(length)))
                  .find("mem.stl: truncated gzip stream"),
              std::string::npos);
  }
  EXPECT_NE(parseError(Bytes(gz.begin(), gz.end() - 1)).find("mem.stl: truncated gzip stream"),
            std::string::npos);
  EXPECT_NE(parseError(gzipStored({})).find("mem.stl: empty file"), std::string::npos);

  // A real deflate stream: cut in half, and with bytes changed in the middle.
  const Bytes real = readBytes(modelsDir() / "bunny_stanford_ascii.stl.gz");
  EXPECT_NE(parseError(Bytes(real.begin(), real.begin() + static_cast<std::ptrdiff_t>(real.size() / 2)))
                .find("truncated gzip stream"),
            std::string::npos);
  Bytes damaged = real;
  for (std::size_t i = 0; i < 64; ++i) damaged[real.size() / 2 + i] ^= std::byte{0x5A};
  EXPECT_NE(parseError(damaged).find("corrupt gzip stream"), std::string::npos);
}

// A gzip'd binary is streamed when the trailer's size says binary. The trailer only gives the last
// member's size, so two members can claim 84 + 50*4 bytes and hold more: the general rules then apply.
TEST(StlGzip, TrailerSizeThatLiesFallsBackToTheLengthRule) {
  Bytes data = makeBinary(someCorners(4));
  data.insert(data.end(), 10, std::byte{0});
  Bytes gz = gzipStored(Bytes(data.begin(), data.begin() + 10));
  const Bytes last = gzipStored(Bytes(data.begin() + 10, data.end()));
  ASSERT_EQ(last.size() > 4 ? std::to_integer<int>(last[last.size() - 4]) : 0, 284 - 256);
  gz.insert(gz.end(), last.begin(), last.end());
  const std::string message = parseError(gz);
  EXPECT_NE(message.find("expected 4 facets (284 bytes), file has 294 bytes"), std::string::npos) << message;
}

TEST(StlFiles, UnreadablePathsAreInputErrors) {
  const fs::path missing = edgeCase("no such file.stl");
  const std::string message = inputErrorOf([&] { readStl(missing); });
  EXPECT_EQ(message.rfind(missing.string() + ": cannot open", 0), 0u) << message;
  EXPECT_NE(inputErrorOf([&] { readStl(edgeCase("")); }).find("is a directory"), std::string::npos);
}

// Every prefix and many byte flips of small files either load or throw InputError, never anything else.
TEST(StlFuzz, PrefixesAndFlipsLoadOrThrowInputError) {
  std::vector<Bytes> seeds;
  for (const EdgeCase& c : kEdgeCases) seeds.push_back(readBytes(edgeCase(c.file)));
  seeds.push_back(gzipStored(seeds.back()));                                         // ASCII
  seeds.push_back(gzipStored(readBytes(edgeCase("tetrahedronMinusZero.bin.stl"))));  // binary
  std::mt19937 random(12345);
  std::size_t loaded = 0, rejected = 0;
  auto attempt = [&](const Bytes& bytes) {
    try {
      const FacetSoup soup = parseStl(bytes, "fuzz");
      EXPECT_GT(soup.facetCount(), 0u);
      ++loaded;
    } catch (const InputError&) {
      ++rejected;
    }
  };
  for (const Bytes& seed : seeds) {
    for (std::size_t length = 0; length <= seed.size(); ++length) {
      attempt(Bytes(seed.begin(), seed.begin() + static_cast<std::ptrdiff_t>(length)));
    }
    for (int trial = 0; trial < 200 && !seed.empty(); ++trial) {
      Bytes mutated = seed;
      for (int k = 0; k < 3; ++k) {
        mutated[random() % mutated.size()] = static_cast<std::byte>(random() & 0xFFu);
      }
      attempt(mutated);
    }
  }
  EXPECT_GT(loaded, 0u);
  EXPECT_GT(rejected, 0u);
}

}  // namespace
}  // namespace toposlice
