// libFuzzer harness for the STL reader (io/readers/stl_reader.h): binary, ASCII and gzip-compressed bytes all
// go through parseStl, which tells them apart by content. InputError is the expected answer to bad input; any
// other exception, a sanitizer report or a broken invariant of a loaded soup is a crash:
// - at least one facet, 3 corners per facet, every coordinate finite;
// - StlSource::gzip exactly when the bytes start with the gzip magic 1f 8b;
// - an uncompressed binary file is exactly 84 + 50 n bytes for its n facets, and its corners are the
//   file's floats bit for bit (the reader keeps -0.0 and subnormals).
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <span>

#include "io/errors.h"
#include "io/readers/stl_reader.h"

namespace {

void require(bool condition, const char* what) {
  if (condition) return;
  std::fprintf(stderr, "fuzz_stl: invariant broken: %s\n", what);
  std::abort();
}

void checkSoup(std::span<const std::byte> bytes, const toposlice::FacetSoup& soup,
               const toposlice::StlSource& source) {
  require(!soup.corners.empty(), "a loaded STL has at least one facet");
  require(soup.corners.size() % 3 == 0, "corners.size() is a multiple of 3");
  for (const toposlice::Point3f& p : soup.corners) {
    require(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z), "every coordinate is finite");
  }
  const bool gzipMagic = bytes.size() >= 2 && bytes[0] == std::byte{0x1F} && bytes[1] == std::byte{0x8B};
  require(source.gzip == gzipMagic, "StlSource::gzip matches the 1f 8b magic");
  if (!source.binary || source.gzip) return;

  constexpr std::size_t kPrefix = 84, kRecord = 50;
  require(bytes.size() == kPrefix + kRecord * soup.facetCount(), "binary STL length is 84 + 50 n");
  for (std::size_t f = 0; f < soup.facetCount(); ++f) {
    const std::byte* record = bytes.data() + kPrefix + kRecord * f;
    require(std::memcmp(&soup.corners[3 * f], record + 12, 36) == 0, "binary corners are kept bit for bit");
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const std::span<const std::byte> bytes(reinterpret_cast<const std::byte*>(data), size);
  toposlice::StlSource source;
  try {
    const toposlice::FacetSoup soup = toposlice::parseStl(bytes, "fuzz.stl", &source);
    checkSoup(bytes, soup, source);
  } catch (const toposlice::InputError&) {
    // Bad input, reported as the reader's contract says.
  }
  return 0;
}
