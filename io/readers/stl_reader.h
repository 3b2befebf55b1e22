// STL reader: binary or ASCII STL, optionally gzip-compressed, into a facet soup (core/mesh/mesh.h).
//
// Contract (every bad input throws InputError("<name>: <what is wrong>"); nothing is repaired):
// - Container: bytes starting with 1f 8b are a gzip stream (detected by content, never by the file name),
//   inflated in memory; several concatenated members are read as one stream. A corrupt, truncated or
//   trailing-garbage gzip stream is an error ("corrupt gzip stream ...", "truncated gzip stream").
// - Format, decided by content (after gunzip) in this order:
//   1. no bytes -> "empty file";
//   2. binary when length == 84 + 50*n, n the little-endian uint32 at offset 80, even when the 80-byte
//      header starts with "solid";
//   3. only whitespace -> "empty file (only whitespace)";
//   4. ASCII when the text starts, after optional whitespace and a UTF-8 byte-order mark, with "solid"
//      (any case) and its first 84 bytes hold no NUL (ASCII STL never does; a NUL-padded "solid"
//      header is a binary file whose count is wrong, reported as in 5);
//   5. otherwise, at least 84 bytes: the count disagrees with the length. Shorter than 84 + 50*n ->
//      "truncated: expected N facets (X bytes), file has Y bytes (binary facet count does not match the
//      file length)"; longer -> "binary facet count does not match the file length: expected N facets
//      (X bytes), file has Y bytes". Shorter than 84 bytes -> "not an STL file: ...".
// - Facet normals are ignored; orientation comes from the corner order, kept as in the file.
//   Coordinates are kept bit for bit (-0.0 stays -0.0; welding merges it with +0.0).
// - A NaN or infinite coordinate is an error naming the facet index (0-based): "facet F ...".
// - Zero facets (binary n == 0, or an ASCII solid without facets) -> "contains no facets".
// - Geometrically odd facet lists (open surface, a single facet, degenerate facets) load as they are.
// - ASCII grammar, tokens separated by any whitespace (spaces, tabs, CR, LF: line breaks may fall
//   anywhere between tokens), keywords in any case:
//     solid [name to end of line]
//       facet normal <num> <num> <num>  outer loop  (vertex <x> <y> <z>)*  endloop  endfacet  ...
//     endsolid [name to end of line]
//   * The name is the rest of the "solid" line, trimmed; it may have several words or be absent.
//     The endsolid name is ignored, so a mismatch is accepted.
//   * A missing endsolid at the end of the text is accepted; the end inside a facet is an error.
//   * The three normal values must be present and lex as numbers (nan and inf included: they are
//     ignored).
//   * A facet with other than 3 vertices is an error naming the facet and the line of its "facet"
//     keyword: "facet F (line L): V vertices, expected 3". Polygons are not triangulated.
//   * Numbers are float text as std::from_chars reads it, plus an optional leading '+'. Values too
//     small for float become 0 or subnormal; values too large are an error.
//   * Several solids one after another are read as one soup (solidName is the first one's name);
//     anything else after the last endsolid is an error.
//   * Errors give the 1-based line, and inside a solid the facet index: "facet F (line L): ...".
// Decisions for ../shared/models/stl_parser_edge_cases (checked by tests/stl_reader_test.cpp):
//   load: missingEndsolid (4 facets), missingFace (3), multiWordName.ascii (4, the whole name),
//     namelessSolid (4, name ""), notANumberNormal (4), singleFace (1), solidNameMismatch (4),
//     tetrahedron.min (4), tetrahedronMinusZero.bin (4), wrongHeader.bin (12, binary by its length),
//     wrongNormal (4), wrongNormals (4);
//   fail: empty ("empty file"), faceless ("contains no facets"), fourVertices and quad ("facet 0
//     (line 2): 4 vertices"), twoVertices ("facet 0 (line 2): 2 vertices"), missingNormal ("'facet
//     normal' needs 3 numbers"), incorrectFaceCounter.bin (count 66, data for 4: "truncated ... binary
//     facet count does not match the file length"), multiWordName.bin (a binary file mangled by a text
//     conversion, 333 bytes for 4 facets: "binary facet count does not match the file length").
// Cost: one read of the file and one pass over its bytes, no allocation per facet. A gzip'd binary STL
// (the trailer's size is 84 + 50*n) is inflated in cache-sized chunks straight into the soup; any other
// gzip'd content is inflated into one buffer sized from the trailer first.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "core/chunk_runner.h"
#include "core/mesh/mesh.h"

namespace toposlice {

struct StlSource {
  bool binary = false;     // binary STL (else ASCII)
  bool gzip = false;       // the bytes were gzip-compressed
  std::string solidName;   // ASCII: first solid's name; binary: the header up to its first NUL, trimmed
  std::size_t pieces = 1;  // how many pieces were read side by side (a parallel runner, a large file)
};

// Reads a binary or ASCII STL, optionally gzip-compressed. Throws InputError("<path>: <what is wrong>")
// on a file that cannot be read or is not a valid STL (see the contract above).
// For readers that receive a binary STL's bytes in order (the streamed gzip read, mesh_reader.cpp): the
// corners of `count` 50-byte facet records appended to `corners` (true when a coordinate is NaN or
// infinite), the solid name that StlSource gives for an 80-byte header, and the facet count an 84-byte
// prefix gives (little-endian, after the header).
bool appendBinaryStlRecords(const std::byte* records, std::size_t count, std::vector<Point3f>& corners);
std::string binaryStlHeaderName(const std::byte* header);
uint32_t binaryStlFacetCount(const std::byte* prefix);

FacetSoup readStl(const std::filesystem::path& path, StlSource* source = nullptr);

// Same, from bytes already in memory (used by fuzzers); `name` starts every error message.
FacetSoup parseStl(std::span<const std::byte> bytes, const std::string& name, StlSource* source = nullptr);

// Same, for bytes already inflated (the mesh reader, io/readers/mesh_reader.h): no gzip detection, and
// StlSource::gzip stays false.
// With a parallel runner (core/chunk_runner.h), a large binary file is converted in parallel chunks and a
// large ASCII file of one solid read in parallel pieces cut before "facet" keywords; anything a piece
// does not accept is read again serially, so results and error messages are the serial ones.
FacetSoup parseStlUncompressed(std::span<const std::byte> bytes, const std::string& name,
                               StlSource* source = nullptr, const ChunkRunner& runner = serialChunkRunner());

}  // namespace toposlice
