// Template files (.topo): a template's adjacency table saved once, loaded before slicing each customized
// variant, so that variants are sliced without welding or rebuilding topology (the paper's section 4,
// DESIGN.md "intra-model reuse"). Byte layout and load checks: docs/FORMATS.md.
//
// Layout (little-endian): 32-byte header {magic "TOPOSLC\0", uint32 version = 1, uint32 facet count t,
// uint32 vertex count, uint32 flags = 0, uint64 connectivity fingerprint}, then t*3 int32 adjacency
// entries (core/mesh/adjacency.h order), then a uint64 checksum (templateChecksum) of header + entries.
// File size is exactly 40 + 12 t bytes.
//
// Loading never yields a wrong table: every malformed file is an InputError("<name>: <what>") — not a
// template (magic), unsupported version or flags, size not matching the facet count (truncated or
// trailing bytes), checksum mismatch ("corrupt"), and table entries out of [-1, t), pointing at their own
// facet or not symmetric. Cost: one read straight into the table, one hash pass, one linear validation pass.
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

inline constexpr uint32_t kTemplateFormatVersion = 1;
inline constexpr std::size_t kTemplateHeaderSize = 32;
inline constexpr std::size_t kTemplateChecksumSize = 8;

struct TemplateTable {
  uint32_t facetCount = 0;
  uint32_t vertexCount = 0;        // of the welded template the table was built from
  uint64_t fingerprint = 0;        // connectivityFingerprint of the welded template's facet-vertex indices
  std::vector<int32_t> adjacency;  // 3 per facet; adjacency[3i+j] = facet across edge j of i, or -1
  friend bool operator==(const TemplateTable&, const TemplateTable&) = default;
};

// 64-bit fingerprint of a welded mesh's connectivity: the format's hash (docs/FORMATS.md) of the index
// array as little-endian uint32 bytes. Two meshes welded from soups with the same facet order, corner
// order and vertex sharing get the same value whatever their positions. Linear time, no allocation.
uint64_t connectivityFingerprint(std::span<const uint32_t> facetVertices);

// The checksum stored at the end of a template file: the format's 64-bit hash of the header and the
// entries (the file without its last 8 bytes). Exposed for tools and tests that build or patch files.
uint64_t templateChecksum(std::span<const std::byte> headerAndEntries);

// Builds the table of a welded template: buildAdjacency plus the fingerprint and counts. Entries are -1
// at boundary, non-manifold, inconsistently oriented and degenerate edges (core/mesh/adjacency.h).
// Precondition: mesh.facetCount() < 2^31 (entries are int32).
TemplateTable buildTemplateTable(const IndexedMesh& mesh, const ChunkRunner& runner = serialChunkRunner());

// Writes `table` to `path` through a temporary beside it, renamed into place when complete
// (io/output_file.h), so a reader never sees a partial file. Throws OutputError when `path` exists and
// !overwrite, or on any write failure. Precondition: adjacency.size() == 3 * facetCount. The table is written
// as given (not validated), so a file written from a broken table is rejected when loaded.
void writeTemplateFile(const std::filesystem::path& path, const TemplateTable& table, bool overwrite);

// Reads and fully validates a template file (see the checks above). The header is checked before the
// rest is read, so a wrong or huge file fails without reading it all. Throws InputError("<path>: <what>")
// on a missing, unreadable or malformed file.
TemplateTable readTemplateFile(const std::filesystem::path& path);

// Same checks on bytes already in memory (the whole file); `name` starts every error message. Any byte
// sequence either yields a table that passes every check or throws InputError (fuzzing entry point).
TemplateTable parseTemplate(std::span<const std::byte> bytes, const std::string& name);

}  // namespace toposlice
