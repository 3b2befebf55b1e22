// libFuzzer harness for mesh input (io/readers/mesh_reader.h): the whole dispatch of parseMesh -- gzip,
// detection by content, and the STL, PLY, OBJ (tinyobjloader) and 3MF (lib3mf) readers behind it.
// InputError is the expected answer to bad input; any other exception, a sanitizer report or a broken
// invariant of a loaded soup is a crash:
// - at least one facet, 3 corners per facet, every coordinate finite;
// - MeshSource::gzip exactly when the bytes start with the gzip magic 1f 8b;
// - without gzip, PLY only when the bytes start with "ply", and 3MF exactly when they start "PK\3\4";
// - gzip'd input read as on more than one thread (a gzip'd binary STL inflated in chunks on a thread of
//   its own and parsed and welded as they come, GzipChunks) gives the serial read's soup, source and
//   weld, or its error message.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <span>
#include <string>
#include <string_view>

#include "core/mesh/weld.h"
#include "io/errors.h"
#include "io/readers/mesh_reader.h"

// lib3mf 1.8 opens zip entries with zip_fopen_index and never closes them (see
// tests/threemf_writer_test.cpp): leaks of libzip allocations are lib3mf's, not the reader's.
extern "C" const char* __lsan_default_suppressions() {
  return "leak:libzip.so\n";
}

namespace {

void require(bool condition, const char* what) {
  if (condition) return;
  std::fprintf(stderr, "fuzz_mesh: invariant broken: %s\n", what);
  std::abort();
}

// One read of the bytes: the soup's bytes and source, or the error message.
std::string outcome(std::span<const std::byte> bytes, const toposlice::MeshReadOptions& options,
                    toposlice::FacetSoup* soupOut = nullptr) {
  try {
    toposlice::MeshSource source;
    toposlice::FacetSoup soup = toposlice::parseMesh(bytes, "fuzz.mesh", options, &source);
    std::string text(reinterpret_cast<const char*>(soup.corners.data()), soup.corners.size() * 12);
    text += std::string("|") + toposlice::meshFormatName(source.format) + (source.binary ? " b " : " t ") +
            (source.gzip ? "gz " : "") + source.name;
    if (soupOut) *soupOut = std::move(soup);
    return text;
  } catch (const toposlice::InputError& e) {
    return std::string("error: ") + e.what();
  }
}

// The streamed gzip read (a runner of width 2, whose chunks run one after another here) against the
// serial read, and its weld against the serial weld of the soup.
void requireStreamedAsSerial(std::span<const std::byte> bytes) {
  toposlice::MeshReadOptions streamed;
  streamed.runner = toposlice::serialChunkRunner();
  streamed.runner.width = 2;
  toposlice::IndexedMesh weld;
  streamed.weld = &weld;
  toposlice::FacetSoup soup;
  require(outcome(bytes, streamed, &soup) == outcome(bytes, {}), "the streamed gzip read is the serial one");
  if (weld.facetVertices.empty()) return;
  const toposlice::IndexedMesh serial = toposlice::weldCorners(soup.corners);
  require(weld.facetVertices == serial.facetVertices && weld.vertices.size() == serial.vertices.size(),
          "the streamed read's weld is the serial weld");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const std::span<const std::byte> bytes(reinterpret_cast<const std::byte*>(data), size);
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  toposlice::MeshSource source;
  try {
    const toposlice::FacetSoup soup = toposlice::parseMesh(bytes, "fuzz.mesh", {}, &source);
    require(!soup.corners.empty(), "a loaded mesh has at least one facet");
    require(soup.corners.size() % 3 == 0, "corners.size() is a multiple of 3");
    for (const toposlice::Point3f& p : soup.corners) {
      require(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z), "every coordinate is finite");
    }
    const bool gzipMagic = text.starts_with("\x1f\x8b");
    require(source.gzip == gzipMagic, "MeshSource::gzip matches the 1f 8b magic");
    if (!gzipMagic) {
      require(source.format != toposlice::MeshFormat::Ply || text.starts_with("ply"),
              "PLY starts with 'ply'");
      require((source.format == toposlice::MeshFormat::ThreeMf) ==
                  text.starts_with(std::string_view("PK\3\4", 4)),
              "3MF exactly when the bytes start with a zip local header");
    }
  } catch (const toposlice::InputError&) {
    // Bad input, reported as the readers' contracts say.
  }
  if (text.starts_with("\x1f\x8b")) requireStreamedAsSerial(bytes);
  return 0;
}
