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

// One read of the bytes: true with the soup and source, or false; `what` gets the soup's bytes and
// source, or the error message, to compare reads by.
bool readOnce(std::span<const std::byte> bytes, const toposlice::MeshReadOptions& options,
              toposlice::FacetSoup& soup, toposlice::MeshSource& source, std::string& what) {
  try {
    soup = toposlice::parseMesh(bytes, "fuzz.mesh", options, &source);
  } catch (const toposlice::InputError& e) {
    // Bad input, reported as the readers' contracts say.
    what = std::string("error: ") + e.what();
    return false;
  }
  what.assign(reinterpret_cast<const char*>(soup.corners.data()), soup.corners.size() * 12);
  what += std::string("|") + toposlice::meshFormatName(source.format) + (source.binary ? " b " : " t ") +
          (source.gzip ? "gz " : "") + source.name;
  return true;
}

// The streamed gzip read (a runner of width 2, whose chunks run one after another here) against the
// serial read's outcome, and its weld against the serial weld of the soup.
void requireStreamedAsSerial(std::span<const std::byte> bytes, const std::string& serial) {
  toposlice::MeshReadOptions streamed;
  streamed.runner = toposlice::serialChunkRunner();
  streamed.runner.width = 2;
  toposlice::IndexedMesh weld;
  streamed.weld = &weld;
  toposlice::FacetSoup soup;
  toposlice::MeshSource source;
  std::string what;
  readOnce(bytes, streamed, soup, source, what);
  require(what == serial, "the streamed gzip read is the serial one");
  if (weld.facetVertices.empty()) return;
  const toposlice::IndexedMesh serialWeld = toposlice::weldCorners(soup.corners);
  require(
      weld.facetVertices == serialWeld.facetVertices && weld.vertices.size() == serialWeld.vertices.size(),
      "the streamed read's weld is the serial weld");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const std::span<const std::byte> bytes(reinterpret_cast<const std::byte*>(data), size);
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  toposlice::FacetSoup soup;
  toposlice::MeshSource source;
  std::string serial;
  if (readOnce(bytes, {}, soup, source, serial)) {
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
  }
  if (text.starts_with("\x1f\x8b")) requireStreamedAsSerial(bytes, serial);
  return 0;
}
