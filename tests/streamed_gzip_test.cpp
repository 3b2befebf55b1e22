// The threaded gzip reads (mesh_reader.cpp): on two threads a gzip'd binary STL is parsed, and welded,
// while it inflates (io/readers/byte_input.h GzipChunks); on more, every thread inflates a part of the
// stream (io/readers/parallel_gunzip.h) before the parse. Against the serial read: the same soup, source
// and weld, or the same error message, for the shared models and for streams damaged in every way the
// stream can end early, run long or lie about its size.
#include <gtest/gtest.h>
#include <zlib.h>

#include <cmath>
#include <cstring>
#include <initializer_list>
#include <limits>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "core/mesh/weld.h"
#include "io/errors.h"
#include "io/readers/byte_input.h"
#include "io/readers/mesh_reader.h"
#include "parallel/parallel.h"
#include "tests/fixtures/gzip_bytes.h"
#include "tests/fixtures/models.h"

namespace toposlice {
namespace {

using Bytes = std::vector<std::byte>;

Bytes fileBytes(const std::string& model) {
  const ByteBuffer file = readWholeFile(fixtures::modelPath(model));
  return Bytes(file.data.get(), file.data.get() + file.size);
}

using fixtures::gzipped;

Bytes gunzipped(const Bytes& gz) {
  const ByteBuffer whole = gunzip(gz, "t");
  return Bytes(whole.data.get(), whole.data.get() + whole.size);
}

// A binary STL of `corners`.
Bytes binaryStl(const std::vector<Point3f>& corners, const char* header = "binary") {
  Bytes out(84, std::byte{0});
  std::memcpy(out.data(), header, std::strlen(header));
  const auto count = static_cast<uint32_t>(corners.size() / 3);
  std::memcpy(out.data() + 80, &count, 4);
  for (std::size_t f = 0; f < count; ++f) {
    std::byte record[50] = {};
    std::memcpy(record + 12, &corners[3 * f], 36);
    out.insert(out.end(), record, record + 50);
  }
  return out;
}

// What one read gives: the soup's bytes and its source, or the error message; and the weld it left.
struct Outcome {
  std::string result;
  IndexedMesh weld;
};

Outcome readWith(const Bytes& bytes, const ChunkRunner& runner, bool weld, double scale = 1.0) {
  Outcome o;
  MeshReadOptions options;
  options.runner = runner;
  options.scale = scale;
  if (weld) options.weld = &o.weld;
  try {
    MeshSource source;
    const FacetSoup soup = parseMesh(bytes, "t.stl.gz", options, &source);
    o.result = std::string(reinterpret_cast<const char*>(soup.corners.data()), soup.corners.size() * 12) +
               "|" + meshFormatName(source.format) + (source.binary ? " binary " : " text ") +
               (source.gzip ? "gzip " : "") + source.name;
  } catch (const InputError& e) {
    o.result = std::string("error: ") + e.what();
  }
  return o;
}

// The serial read and the threaded ones (2 and 3 threads, with and without the weld) agree; the weld is
// either left empty or is the serial weld of the soup. Returns whether the streamed read welded.
bool expectSameRead(const Bytes& bytes, const std::string& what, double scale = 1.0,
                    std::initializer_list<unsigned> threadCounts = {2, 3}) {
  const Outcome serial = readWith(bytes, serialChunkRunner(), true, scale);
  EXPECT_TRUE(serial.weld.facetVertices.empty()) << what << ": the serial read does not weld";
  bool welded = false;
  for (const unsigned threads : threadCounts)
    for (const bool weld : {false, true}) {
      ThreadLimit limit(threads);
      const Outcome streamed = readWith(bytes, parallelChunkRunner(), weld, scale);
      EXPECT_EQ(streamed.result.substr(0, 300), serial.result.substr(0, 300)) << what;
      EXPECT_TRUE(streamed.result == serial.result) << what << ", " << threads << " threads";
      if (streamed.weld.facetVertices.empty()) continue;
      welded = true;
      EXPECT_TRUE(weld) << what;
      FacetSoup soup;
      soup.corners.resize(streamed.weld.facetVertices.size());
      std::memcpy(soup.corners.data(), streamed.result.data(), soup.corners.size() * 12);
      const IndexedMesh expected = weldCorners(soup.corners);
      EXPECT_EQ(streamed.weld.facetVertices, expected.facetVertices) << what;
      EXPECT_TRUE(streamed.weld.vertices.size() == expected.vertices.size() &&
                  std::memcmp(streamed.weld.vertices.data(), expected.vertices.data(),
                              expected.vertices.size() * 12) == 0)
          << what;
    }
  return welded;
}

TEST(StreamedGzip, SharedModelsReadAsSerially) {
  for (const char* model : {"derived/aligner_upper_case0.stl.gz", "derived/femur_S001_sub2.stl.gz",
                            "derived/spine_L2-L5_sub1.stl.gz", "benchy_3dbenchy.stl.gz", "igea.stl.gz"}) {
    SCOPED_TRACE(model);
    EXPECT_TRUE(expectSameRead(fileBytes(model), model)) << "binary: parsed and welded while inflating";
  }
  // ASCII inside gzip: inflated by the stream, then read the general way; no weld.
  EXPECT_FALSE(expectSameRead(fileBytes("bunny_stanford_ascii.stl.gz"), "ascii"));
}

// Head and chunks joined, as GzipChunks gives them to a reader, and whether finish() said handled.
std::pair<Bytes, bool> inflatedByChunks(const Bytes& gz, std::size_t headBytes, std::size_t chunkBytes,
                                        std::size_t slots) {
  GzipChunks stream(gz, headBytes, chunkBytes, slots);
  const std::span<const std::byte> head = stream.head();
  Bytes got(head.begin(), head.end());
  for (std::span<const std::byte> chunk = stream.next(); !chunk.empty(); chunk = stream.next()) {
    EXPECT_LE(chunk.size(), chunkBytes);
    got.insert(got.end(), chunk.begin(), chunk.end());
  }
  EXPECT_TRUE(stream.next().empty()) << "the end stays the end";
  return {got, stream.finish()};
}

TEST(StreamedGzip, GzipChunksGiveTheInflatedBytes) {
  const Bytes gz = fileBytes("derived/femur_S001_sub2.stl.gz");
  const Bytes expected = gunzipped(gz);
  EXPECT_EQ(GzipChunks(gz, 84, 4096).expectedSize(), expected.size());
  // The ring's slots are reused many times over (the inflater keeps its own history), and chunks of every
  // size down to one byte come whole and in order.
  using Case = std::tuple<std::size_t, std::size_t, std::size_t>;  // head bytes, chunk bytes, slots
  for (const auto& [head, chunk, slots] :
       {Case{84, 204800, 8}, Case{0, 1000, 1}, Case{expected.size() + 5, 100, 2}}) {
    SCOPED_TRACE(std::to_string(head) + " " + std::to_string(chunk) + " " + std::to_string(slots));
    const auto [got, handled] = inflatedByChunks(gz, head, chunk, slots);
    EXPECT_TRUE(handled);
    EXPECT_TRUE(got == expected);
  }
  const Bytes part(expected.begin(), expected.begin() + 20000);
  for (const auto& [head, chunk, slots] : {Case{84, 50, 2}, Case{3, 1, 3}}) {
    SCOPED_TRACE(std::to_string(head) + " " + std::to_string(chunk) + " " + std::to_string(slots));
    const auto [got, handled] = inflatedByChunks(gzipped(part), head, chunk, slots);
    EXPECT_TRUE(handled);
    EXPECT_TRUE(got == part);
  }

  // Not handled: cut short, a byte flipped inside, another member after it, a trailer that lies about
  // the size. (What the chunks held is known good only when finish() says so: a flipped byte changes
  // what follows it before the CRC-32 at the end tells.) Cut short, the chunks given are the stream's.
  Bytes cut(gz.begin(), gz.end() - 1000), flipped = gz, twice = gz, lying = gz;
  flipped[gz.size() / 2] ^= std::byte{0x10};
  twice.insert(twice.end(), gz.begin(), gz.end());
  lying[lying.size() - 4] ^= std::byte{1};
  for (const Bytes* damaged : {&cut, &flipped, &twice, &lying}) {
    const auto [got, ok] = inflatedByChunks(*damaged, 84, 4096, 4);
    EXPECT_FALSE(ok);
    EXPECT_LE(got.size(), expected.size());
    if (damaged == &cut) {
      EXPECT_TRUE(std::equal(got.begin(), got.end(), expected.begin()));
    }
  }

  // Abandoned while inflating, before or after its head: it stops without being read to the end.
  { GzipChunks abandoned(gz, 84, 4096, 2); }
  {
    GzipChunks abandoned(gz, 84, 4096, 2);
    EXPECT_EQ(abandoned.head().size(), 84u);
    EXPECT_EQ(abandoned.next().size(), 4096u);
    EXPECT_FALSE(abandoned.finish());
  }
}

TEST(StreamedGzip, DamagedOrUnusualStreamsReadAsSerially) {
  const auto expectSameRead = [](const Bytes& bytes, const std::string& what, double scale = 1.0) {
    return toposlice::expectSameRead(bytes, what, scale, {2, 4});
  };
  const FacetSoup femur = readMesh(fixtures::modelPath("derived/femur_S001_sub2.stl.gz"));
  const Bytes stl = binaryStl(femur.corners, "femur");
  const Bytes gz = gzipped(stl);
  EXPECT_TRUE(expectSameRead(gz, "whole"));
  EXPECT_TRUE(expectSameRead(gzipped(stl, 0), "stored blocks"));
  EXPECT_TRUE(expectSameRead(gzipped(stl, 9), "level 9"));
  EXPECT_FALSE(expectSameRead(gz, "scaled", 2.0)) << "a scaled soup is not welded by the reader";

  // Cut anywhere: a truncated stream.
  for (const double at : {0.0001, 0.01, 0.3, 0.9, 0.9999})
    expectSameRead(
        Bytes(gz.begin(), gz.begin() + static_cast<std::ptrdiff_t>(at * static_cast<double>(gz.size()))),
        "cut at " + std::to_string(at));
  expectSameRead(Bytes(gz.begin(), gz.end() - 1), "trailer cut");
  // Bytes changed in the middle, and in the CRC.
  Bytes damaged = gz;
  for (std::size_t i = 0; i < 32; ++i) damaged[gz.size() / 2 + i] ^= std::byte{0x5A};
  expectSameRead(damaged, "damaged");
  Bytes badCrc = gz;
  badCrc[gz.size() - 6] ^= std::byte{1};
  expectSameRead(badCrc, "bad CRC");
  // Header fields the serial inflaters refuse (a reserved flag bit, another method) and ISA-L alone would
  // read past.
  Bytes reserved = gz, method = gz;
  reserved[3] |= std::byte{0x80};
  method[2] = std::byte{7};
  expectSameRead(reserved, "a reserved header flag");
  expectSameRead(method, "another method");
  // Something after the member: garbage, or a second member.
  Bytes trailing = gz;
  trailing.push_back(std::byte{'x'});
  expectSameRead(trailing, "trailing byte");
  const std::size_t half = 84 + 50 * (femur.facetCount() / 2);
  Bytes twoMembers = gzipped(Bytes(stl.begin(), stl.begin() + static_cast<std::ptrdiff_t>(half)));
  const Bytes second = gzipped(Bytes(stl.begin() + static_cast<std::ptrdiff_t>(half), stl.end()));
  twoMembers.insert(twoMembers.end(), second.begin(), second.end());
  expectSameRead(twoMembers, "two members");
  // A trailer whose size is not the stream's: larger, smaller, zero.
  for (const uint32_t size : {uint32_t(stl.size() + 50), uint32_t(stl.size() - 50), uint32_t{0}}) {
    Bytes lying = gz;
    std::memcpy(lying.data() + lying.size() - 4, &size, 4);
    expectSameRead(lying, "trailer says " + std::to_string(size));
  }

  // Content that is not a clean binary STL: a NaN, a count that does not match, no facets, a header
  // that makes it PLY, and ASCII.
  std::vector<Point3f> withNan = femur.corners;
  withNan[withNan.size() / 2].y = std::numeric_limits<float>::quiet_NaN();
  expectSameRead(gzipped(binaryStl(withNan)), "a NaN");
  Bytes wrongCount = stl;
  wrongCount[80] ^= std::byte{1};
  expectSameRead(gzipped(wrongCount), "a count that does not match");
  expectSameRead(gzipped(binaryStl({})), "no facets");
  expectSameRead(gzipped(binaryStl(femur.corners, "ply\nformat ascii 1.0\n")), "a header that says PLY");
  // Headers the streamed read leaves to detection on the whole (a binary STL all the same here).
  expectSameRead(gzipped(binaryStl(femur.corners, "plywood base plate")), "a header starting 'ply'");
  expectSameRead(gzipped(binaryStl(femur.corners, "PK\x03\x04 not an archive")), "a header starting 'PK'");
  const std::string ascii =
      "solid a\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
      "vertex 0 1 0\nendloop\nendfacet\nendsolid a\n";
  expectSameRead(gzipped(Bytes(reinterpret_cast<const std::byte*>(ascii.data()),
                               reinterpret_cast<const std::byte*>(ascii.data()) + ascii.size())),
                 "ascii");
}

}  // namespace
}  // namespace toposlice
