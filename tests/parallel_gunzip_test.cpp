// The parallel inflate (io/readers/parallel_gunzip.h) against zlib, an independent inflater: streams made
// by zlib with every strategy, level, block size and window, cut into parts from a few bytes up, on one
// thread and several; and damaged or unusual streams, which it must refuse unless zlib reads them to the
// same bytes.
#include "io/readers/parallel_gunzip.h"

#include <gtest/gtest.h>
#include <zlib.h>

#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "parallel/parallel.h"
#include "tests/fixtures/gzip_bytes.h"
#include "tests/fixtures/models.h"

namespace toposlice {
namespace {

using Bytes = std::vector<std::byte>;

struct Settings {
  int level = 6, strategy = Z_DEFAULT_STRATEGY, memLevel = 8, windowBits = 15;
};

Bytes deflated(const Bytes& in, const Settings& s) {
  return fixtures::gzipped(in, s.level, s.strategy, s.memLevel, s.windowBits);
}

// zlib's inflate of one member, nothing after it; false for anything else.
bool zlibInflated(const Bytes& gz, Bytes& out) {
  z_stream z{};
  if (inflateInit2(&z, 16 + MAX_WBITS) != Z_OK) return false;
  out.assign(std::max<std::size_t>(gz.size() * 8, 1 << 16), std::byte{0});
  z.next_in = const_cast<Bytef*>(reinterpret_cast<const Bytef*>(gz.data()));
  z.avail_in = static_cast<uInt>(gz.size());
  int rc = Z_OK;
  while (rc == Z_OK) {
    if (z.total_out == out.size()) out.resize(out.size() * 2);
    z.next_out = reinterpret_cast<Bytef*>(out.data() + z.total_out);
    z.avail_out = static_cast<uInt>(out.size() - z.total_out);
    rc = inflate(&z, Z_NO_FLUSH);
  }
  const bool ok = rc == Z_STREAM_END && z.avail_in == 0;
  out.resize(z.total_out);
  inflateEnd(&z);
  return ok;
}

// gunzipParallel's answer: whether it handled the stream, and the bytes when it did.
bool parallelInflated(const Bytes& gz, const ChunkRunner& runner, std::size_t partBytes, Bytes& out) {
  ByteBuffer buffer;
  if (!gunzipParallel(gz, runner, buffer, partBytes)) return false;
  out.assign(buffer.data.get(), buffer.data.get() + buffer.size);
  return true;
}

// Bytes of several kinds: a real binary STL's records (floats that repeat at many distances), random
// bytes (zlib stores them), text with long repeats, runs of one byte.
Bytes sample(const std::string& kind, std::size_t size, unsigned seed) {
  std::mt19937 random(seed);
  Bytes out(size);
  if (kind == "stl") {
    const Bytes file = [] {
      const auto buffer = readWholeFile(fixtures::modelPath("derived/femur_S001_sub2.stl.gz"));
      Bytes gz(buffer.data.get(), buffer.data.get() + buffer.size);
      Bytes whole;
      EXPECT_TRUE(zlibInflated(gz, whole));
      return whole;
    }();
    const std::size_t from = random() % (file.size() - size);
    std::memcpy(out.data(), file.data() + from, size);
  } else if (kind == "random") {
    for (std::byte& b : out) b = static_cast<std::byte>(random());
  } else if (kind == "text") {
    const std::string words[] = {"facet normal ", "vertex ",   "0.125 ",
                                 "-3.5e-2 ",      "endloop\n", "outer loop\n"};
    for (std::size_t i = 0; i < size;) {
      const std::string& w = words[random() % 6];
      for (std::size_t k = 0; k < w.size() && i < size; ++k) out[i++] = static_cast<std::byte>(w[k]);
    }
  } else {  // runs
    for (std::size_t i = 0; i < size;) {
      const std::size_t run = 1 + random() % 600;
      const auto value = static_cast<std::byte>(random() % 3);
      for (std::size_t k = 0; k < run && i < size; ++k) out[i++] = value;
    }
  }
  return out;
}

ChunkRunner runnerOf(unsigned threads) {
  return threads == 1 ? serialChunkRunner() : parallelChunkRunner();
}

TEST(ParallelGunzip, InflatesWhatZlibDeflated) {
  struct Case {
    std::string kind;
    Settings settings;
    std::size_t partBytes;
    bool mustHandle;  // dynamic blocks throughout: every part boundary can be found
  };
  const std::vector<Case> cases = {
      {"stl", {}, 0, true},
      {"stl", {}, 3000, true},
      {"stl", {9, Z_DEFAULT_STRATEGY, 9, 15}, 20000, true},
      {"stl", {1, Z_DEFAULT_STRATEGY, 1, 15}, 700, true},  // small blocks
      {"stl", {6, Z_FILTERED, 8, 15}, 5000, true},
      {"stl", {6, Z_HUFFMAN_ONLY, 8, 15}, 5000, true},
      {"stl", {6, Z_RLE, 8, 15}, 5000, true},
      {"stl", {6, Z_DEFAULT_STRATEGY, 8, 9}, 5000, true},  // a 512-byte window
      {"text", {9, Z_DEFAULT_STRATEGY, 8, 15}, 1000, true},
      {"runs", {6, Z_DEFAULT_STRATEGY, 8, 15}, 300, false},
      {"stl", {6, Z_FIXED, 8, 15}, 5000, false},                // fixed codes: no part start is found
      {"random", {6, Z_DEFAULT_STRATEGY, 8, 15}, 5000, false},  // stored blocks
      {"stl", {0, Z_DEFAULT_STRATEGY, 8, 15}, 5000, false},
  };
  unsigned seed = 1;
  for (const Case& c : cases) {
    const Bytes data = sample(c.kind, 400000, seed++);
    const Bytes gz = deflated(data, c.settings);
    for (const unsigned threads : {1u, 2u, 4u}) {
      SCOPED_TRACE(c.kind + " level " + std::to_string(c.settings.level) + " strategy " +
                   std::to_string(c.settings.strategy) + " memLevel " + std::to_string(c.settings.memLevel) +
                   " window " + std::to_string(c.settings.windowBits) + " parts of " +
                   std::to_string(c.partBytes) + ", " + std::to_string(threads) + " threads");
      ThreadLimit limit(threads);
      Bytes got;
      const bool handled = parallelInflated(gz, runnerOf(threads), c.partBytes, got);
      if (c.mustHandle) {
        EXPECT_TRUE(handled);
      }
      if (handled) {
        EXPECT_TRUE(got == data);
      }
    }
  }
}

TEST(ParallelGunzip, StreamsWithStoredStretchesAndTinyStreams) {
  // Compressible, then incompressible (stored blocks: no part can start inside), then compressible: the
  // parts that found no start are passed over, and the part before them decodes on through.
  Bytes data = sample("stl", 200000, 7);
  const Bytes noise = sample("random", 150000, 8), tail = sample("stl", 200000, 9);
  data.insert(data.end(), noise.begin(), noise.end());
  data.insert(data.end(), tail.begin(), tail.end());
  const Bytes gz = deflated(data, {});
  for (const std::size_t partBytes : {2000u, 30000u}) {
    Bytes got;
    EXPECT_TRUE(parallelInflated(gz, serialChunkRunner(), partBytes, got)) << partBytes;
    EXPECT_TRUE(got == data);
  }
  // One byte, and a stream smaller than a part.
  for (const std::size_t size : {1u, 100u}) {
    const Bytes small = sample("text", size, 3);
    Bytes got;
    EXPECT_TRUE(parallelInflated(deflated(small, {}), serialChunkRunner(), 0, got));
    EXPECT_TRUE(got == small);
  }
}

TEST(ParallelGunzip, SharedModelAsTheSerialInflate) {
  const auto buffer = readWholeFile(fixtures::modelPath("derived/aligner_upper_case0.stl.gz"));
  const Bytes gz(buffer.data.get(), buffer.data.get() + buffer.size);
  const ByteBuffer serial = gunzip(gz, "aligner");
  for (const unsigned threads : {2u, 4u}) {
    ThreadLimit limit(threads);
    ByteBuffer parallel;
    ASSERT_TRUE(gunzipParallel(gz, parallelChunkRunner(), parallel)) << threads;
    EXPECT_EQ(parallel.size, serial.size);
    EXPECT_EQ(std::memcmp(parallel.data.get(), serial.data.get(), serial.size), 0);
  }
}

// Damage of every kind: refused, unless zlib reads the damaged stream to the same bytes.
TEST(ParallelGunzip, DamagedStreamsRefusedOrReadAsZlibReadsThem) {
  const Bytes data = sample("stl", 300000, 11);
  const Bytes gz = deflated(data, {});
  auto expectRefusedOrAsZlib = [](const Bytes& damaged, const std::string& what) {
    Bytes ours, theirs;
    const bool handled = parallelInflated(damaged, serialChunkRunner(), 2000, ours);
    if (!handled) return;
    EXPECT_TRUE(zlibInflated(damaged, theirs)) << what << ": read what zlib refuses";
    EXPECT_TRUE(ours == theirs) << what;
  };
  std::mt19937 random(5);
  for (int i = 0; i < 300; ++i) {
    Bytes flipped = gz;
    const std::size_t at = random() % gz.size();
    flipped[at] ^= static_cast<std::byte>(1u << (random() % 8));
    expectRefusedOrAsZlib(flipped, "bit flipped at " + std::to_string(at));
  }
  for (const std::size_t cut :
       {std::size_t{1}, std::size_t{8}, std::size_t{9}, gz.size() / 2, gz.size() - 11})
    expectRefusedOrAsZlib(Bytes(gz.begin(), gz.end() - static_cast<std::ptrdiff_t>(cut)), "cut");
  Bytes twice = gz, trailing = gz, reserved = gz, method = gz;
  twice.insert(twice.end(), gz.begin(), gz.end());
  trailing.push_back(std::byte{0});
  reserved[3] |= std::byte{0x20};
  method[2] = std::byte{7};
  for (const Bytes* refused : {&twice, &trailing, &reserved, &method}) {
    Bytes got;
    EXPECT_FALSE(parallelInflated(*refused, serialChunkRunner(), 2000, got));
  }
  for (const uint32_t size : {uint32_t(data.size() + 1), uint32_t(data.size() - 1), uint32_t{0}}) {
    Bytes lying = gz;
    std::memcpy(lying.data() + lying.size() - 4, &size, 4);
    Bytes got;
    EXPECT_FALSE(parallelInflated(lying, serialChunkRunner(), 2000, got)) << size;
  }
}

}  // namespace
}  // namespace toposlice
