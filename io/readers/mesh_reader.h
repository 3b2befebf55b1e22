// Mesh input: the one entry point for meshes, whatever their format (STL, PLY, OBJ, 3MF), into a facet
// soup (core/mesh/mesh.h) in mm.
//
// Contract (every bad input throws InputError("<name>: <what is wrong>"), one line; nothing is repaired):
// - Container: bytes starting with 1f 8b are gzip, inflated first (io/readers/byte_input.h), whatever
//   the format inside. The format is then decided by content, never by the file name, in this order:
//   1. no bytes -> STL ("empty file");
//   2. "ply" alone on the first line -> PLY (io/readers/ply_reader.h);
//   3. a zip local header "PK\3\4" -> 3MF (io/readers/threemf_reader.h);
//   4. length 84 + 50 n, n the little-endian uint32 at offset 80 -> binary STL;
//   5. only whitespace, or text starting with "solid" (after whitespace and a UTF-8 byte-order mark) ->
//      STL, which reports or reads it exactly as readStl does (io/readers/stl_reader.h);
//   6. text (the first 64 KiB hold no NUL and at most 1% other control bytes) whose first meaningful
//      lines (blank lines and # comments skipped, up to 16 of them) are all OBJ statements (v vt vn vp
//      f l p o g s usemtl mtllib and the free-form geometry keywords) -> OBJ (io/readers/obj_reader.h);
//   7. other text -> "not a mesh file (toposlice reads STL, PLY, OBJ and 3MF, recognised by content)";
//   8. anything else is binary: the STL reader's messages for a binary STL whose count does not match
//      its length ("truncated: expected N facets ...", "not an STL file: ...").
// - Polygons (PLY, OBJ) are fanned from their first corner, (0, i, i+1), keeping the orientation;
//   MeshSource::polygonsTriangulated counts them.
// - Units: STL, PLY and OBJ carry none; a coordinate is multiplied by options.unitMm (the user's
//   --units, default 1: the file is in mm). A 3MF states its unit and is always converted to mm; a
//   unitMm given for a 3MF is an error ("3MF files state their unit (...); --units does not apply").
//   Then every coordinate is multiplied by options.scale. Both are applied in double and rounded to
//   float once; a result beyond float's range is an error naming the facet. unitMm and scale must be
//   finite and positive.
// - NaN or infinite coordinates are errors naming the vertex (PLY, OBJ, 3MF) or facet (STL); zero
//   facets -> "contains no facets".
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>

#include "core/chunk_runner.h"
#include "core/mesh/mesh.h"

namespace toposlice {

enum class MeshFormat { Stl, Ply, Obj, ThreeMf };

struct MeshSource {
  MeshFormat format = MeshFormat::Stl;
  bool binary = false;                // binary STL or binary PLY (false for ASCII STL/PLY, OBJ and 3MF)
  bool gzip = false;                  // the bytes were gzip-compressed
  std::string name;                   // STL solid name / 3MF object name, may be empty
  std::string fileUnit;               // 3MF: the unit the file states ("millimeter", ...); else empty
  uint64_t polygonsTriangulated = 0;  // polygons with >3 corners fan-triangulated
};

struct MeshReadOptions {
  std::optional<double> unitMm;              // user's --units: the length of one file unit in mm
  double scale = 1.0;                        // user's --scale: multiplies every coordinate after units
  ChunkRunner runner = serialChunkRunner();  // STL parsing in parallel chunks (stl_reader.h) when parallel
  // Where a gzip'd binary STL is parsed while it inflates (a runner of width 2, units and scale 1), its
  // corners are also welded as they arrive into *weld (core/mesh/weld.h: weldCorners' result, bit for
  // bit), hidden behind the inflate. *weld is left empty otherwise: its facetVertices then do not
  // match the soup's corners, and the caller welds.
  IndexedMesh* weld = nullptr;
};

// Reads a mesh file of any supported format, optionally gzip-compressed (see the contract above).
FacetSoup readMesh(const std::filesystem::path& path, const MeshReadOptions& options = {},
                   MeshSource* source = nullptr);

// Same, from bytes already in memory (used by fuzzers); `name` starts every error message.
FacetSoup parseMesh(std::span<const std::byte> bytes, const std::string& name,
                    const MeshReadOptions& options = {}, MeshSource* source = nullptr);

// "STL", "PLY", "OBJ", "3MF".
const char* meshFormatName(MeshFormat format);

// The length of one unit in mm: "mm" -> 1, "cm" -> 10, "m" -> 1000, "in" -> 25.4. Anything else throws
// InputError("--units 'x': expected mm, cm, m or in").
double parseUnits(const std::string& text);

}  // namespace toposlice
