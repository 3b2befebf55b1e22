// PLY reader (Stanford polygon format 1.0) into a facet soup (core/mesh/mesh.h). Debian has no maintained PLY
// library, so this is a small one of toposlice's own, written from the format description (Greg Turk,
// "The PLY Polygon File Format", 1994; the same grammar as RPly and the Stanford tools).
//
// Contract (every bad input throws InputError("<name>: <what is wrong>"); nothing is repaired):
// - The bytes are not compressed (io/readers/mesh_reader.h inflates gzip first).
// - Header: a "ply" line, one "format ascii|binary_little_endian|binary_big_endian 1.0" line before the
//   first element, "comment"/"obj_info" lines (ignored), "element <name> <count>", "property <type>
//   <name>", "property list <count type> <item type> <name>", and "end_header". Lines end in LF or CRLF.
//   Types: char uchar short ushort int uint float double and int8 uint8 int16 uint16 int32 uint32
//   float32 float64. Header errors name the 1-based header line: "PLY header line L: ...".
// - Element "vertex": scalar properties x, y and z of any type are the position (converted to float;
//   a value beyond float's range or NaN/infinity is an error "vertex V: ..."); its other properties
//   (normals, colours, ...) are skipped. At most 2^32 - 1 vertices.
// - Element "face": a list property "vertex_indices" (or "vertex_index") with integer count and index
//   types. A face of n >= 3 corners becomes n - 2 facets fanned from its first corner, (0, i, i+1),
//   keeping the file's orientation. Fewer than 3 corners or an index outside [0, vertex count) is an
//   error naming the 0-based face: "face F: ...". Other properties of the face element are skipped.
// - Every other element (edge, material, ...) and every other property is skipped with its exact size,
//   list properties included (their count types must be integers). Elements may come in any order.
// - Zero facets (no face element, or zero faces) -> "contains no facets".
// - Binary: records packed without padding, in the stated byte order. Data ending inside a record ->
//   "truncated: ...". ASCII: values are whitespace-separated tokens (line breaks anywhere); errors give
//   the 1-based line. Data after the last element (a record count that is too small) is an error:
//   "N bytes after the last element" (binary), "data after the last element, line L" (ASCII; blanks
//   are allowed there).
// - Hostile counts: no allocation is sized from a count before the count is checked against the bytes
//   left (each record needs at least its fixed bytes in binary, one token per property in ASCII).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "core/chunk_runner.h"
#include "core/mesh/mesh.h"

namespace toposlice {

struct PlySource {
  bool binary = false;                // binary_little_endian or binary_big_endian (else ascii)
  uint64_t polygonsTriangulated = 0;  // faces with more than 3 corners
};

// Parses PLY bytes; `name` starts every error message. The common binary file, whose records all have
// one size (every face a triangle, no list property but the faces' corners), is converted in chunks on
// `runner` (the result is the same for any runner); any other file, and any damage, is read record by
// record (parsePlyRecords), which gives the same soup or names the problem.
FacetSoup parsePly(std::span<const std::byte> bytes, const std::string& name, PlySource* source = nullptr,
                   const ChunkRunner& runner = serialChunkRunner());
// The record-by-record reader alone: every file the contract above admits (tests compare the two).
FacetSoup parsePlyRecords(std::span<const std::byte> bytes, const std::string& name,
                          PlySource* source = nullptr);

}  // namespace toposlice
