// Wavefront OBJ reader into a facet soup (core/mesh/mesh.h), through tinyobjloader (Debian
// libtinyobjloader-dev, its streaming callback interface: tinyobjloader lexes the lines, this reader
// resolves indices and triangulates, so the face order and numbering are the file's).
//
// Contract (every bad input throws InputError("<name>: <what is wrong>"); nothing is repaired):
// - The bytes are not compressed (io/readers/mesh_reader.h inflates gzip first); they are read from
//   memory. Materials are never loaded: mtllib names no file that is opened, usemtl is ignored.
// - "v x y z [w]": the position; w and any trailing colour values are ignored. A missing y or z reads
//   as 0 (tinyobjloader's rule). Each value present must be a finite number (checked by this reader:
//   tinyobjloader would read "nan" or "abc" as 0) -> "vertex V (line L): coordinate 'nan' is not a
//   finite number"; beyond float's range -> "vertex V: ..." (V counted from 1, as f lines count them).
// - "f" with corners "v", "v/vt", "v//vn" or "v/vt/vn": only v is used. Positive indices count from 1,
//   negative ones back from the last vertex defined before the face (-1 is the latest). A face of n >= 3
//   corners becomes n - 2 facets fanned from its first corner, (0, i, i+1), keeping the file's
//   orientation. Fewer than 3 corners, index 0 (or a corner that is not a number) or an index outside
//   the file's vertices -> "face F: ..." (F counted from 0 over every f line of the file).
// - Objects (o) and groups (g) are merged into one soup in file order; vt, vn, s, l, p and unknown
//   statements are ignored.
// - Zero facets -> "contains no facets".
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "core/mesh/mesh.h"

namespace toposlice {

struct ObjSource {
  uint64_t polygonsTriangulated = 0;  // faces with more than 3 corners
};

// Parses OBJ text; `name` starts every error message.
FacetSoup parseObj(std::span<const std::byte> bytes, const std::string& name, ObjSource* source = nullptr);

}  // namespace toposlice
