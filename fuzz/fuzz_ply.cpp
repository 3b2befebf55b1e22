// libFuzzer harness for the PLY reader (io/readers/ply_reader.h): ASCII and binary PLY bytes go through
// parsePly. InputError is the expected answer to bad input; any other exception, a sanitizer report or a
// broken invariant of a loaded soup is a crash:
// - at least one facet, 3 corners per facet, every coordinate finite;
// - PlySource::binary only when the header names a binary encoding, else it names ascii.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <span>
#include <string_view>

#include "io/errors.h"
#include "io/readers/ply_reader.h"

namespace {

void require(bool condition, const char* what) {
  if (condition) return;
  std::fprintf(stderr, "fuzz_ply: invariant broken: %s\n", what);
  std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const std::span<const std::byte> bytes(reinterpret_cast<const std::byte*>(data), size);
  toposlice::PlySource source;
  try {
    const toposlice::FacetSoup soup = toposlice::parsePly(bytes, "fuzz.ply", &source);
    require(!soup.corners.empty(), "a loaded PLY has at least one facet");
    require(soup.corners.size() % 3 == 0, "corners.size() is a multiple of 3");
    for (const toposlice::Point3f& p : soup.corners) {
      require(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z), "every coordinate is finite");
    }
    const std::string_view text(reinterpret_cast<const char*>(data), size);
    const std::string_view header = text.substr(0, text.find("end_header"));
    require(header.find(source.binary ? "binary_" : "ascii") != std::string_view::npos,
            "PlySource::binary agrees with the header's format");
  } catch (const toposlice::InputError&) {
    // Bad input, reported as the reader's contract says.
  }
  return 0;
}
