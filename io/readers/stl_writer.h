// Binary STL writer (for generated test parts and for tools that hand meshes on): 80-byte header,
// little-endian facet count, 50 bytes per facet with the facet's unit normal computed from its corners.
#pragma once

#include <filesystem>
#include <string>

#include "core/mesh/mesh.h"

namespace toposlice {

// Writes through a temporary name and renames when complete; throws OutputError.
void writeBinaryStl(const std::filesystem::path& path, const FacetSoup& soup, const std::string& header,
                    bool overwrite);

}  // namespace toposlice
