// 3MF reader (3MF Core Specification 1.x) into a facet soup (core/mesh/mesh.h), through lib3mf 1.8 (Debian
// lib3mf-dev), reading the package from memory (lib3mf_reader_readfrombuffer).
//
// Contract (every bad input throws InputError("<name>: <what is wrong>"); nothing is repaired):
// - What lib3mf refuses (not a 3MF package, malformed XML, missing parts, ...) -> "not a valid 3MF
//   file: <lib3mf's message> (lib3mf error 0x...)".
// - Every <build> item is placed: its object's mesh, or for a components object every component's
//   object resolved recursively (at most 32 levels), each with its component transform, then the build
//   item's transform. Transforms are applied in double; a transform with a negative determinant
//   (a mirror) has its facets' corner order reversed so that they still face outwards.
// - Objects of type "support" and "solidsupport" are skipped (printer supports, not the part);
//   "model", "surface" and "other" are read. Beam lattices, slices, colours and materials are ignored.
// - Coordinates are converted from the model's unit (micron, millimeter, centimeter, inch, foot, meter)
//   to mm, then multiplied by `factor` (the user's scale), and must stay finite within float's range
//   ("object 'N' vertex V: ...").
// - Zero facets (no build item, only supports, empty meshes) -> "contains no facets".
#pragma once

#include <cstddef>
#include <span>
#include <string>

#include "core/mesh/mesh.h"

namespace toposlice {

struct ThreeMfSource {
  std::string objectName;  // the first build item's object name (may be empty)
  std::string unit;        // the model's unit as the file states it: "millimeter", "inch", ...
  double unitMm = 1.0;     // the length of that unit in mm
  uint64_t supportsSkipped = 0;
};

// Parses a 3MF package; `name` starts every error message. Coordinates come out in mm times `factor`.
FacetSoup parseThreeMf(std::span<const std::byte> bytes, const std::string& name, double factor = 1.0,
                       ThreeMfSource* source = nullptr);

}  // namespace toposlice
