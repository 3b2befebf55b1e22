// OpenVDB mask stack: one .vdb file holding one grid per slab of layers (docs/FORMATS.md, "VDB").
//
// Grids: a MaskGrid for binary jobs (active = lit), a FloatGrid for anti-aliased ones (value pixel/255,
// active where > 0, background 0, class fog volume). Index coordinates (i, j, k) are (pixel i, pixel j,
// layer k) with k the absolute layer index in every grid; the linear transform maps voxel centres to
// model mm: x = x0 + (i + 1/2) p, y = y0 + (j + 1/2) p (mirrored images use a negative scale, so world
// positions stay the model's), z = z_0 + k h with z_0 the first layer's cut plane, so voxel k spans that
// layer's slab. With an explicit, uneven list of planes the z of the transform is only approximate.
//
// Slabs: grid "mask_<first layer, 5+ digits>" covers layers [first, last] (metadata first_layer,
// last_layer, layer_height, pixel_size); slabs start at multiples of 8 (the leaf depth, so no leaf node is
// split between grids) and hold kVdbSlabLayers layers, fewer when their leaf nodes pass
// kVdbSlabLeafBytes (fine detail in anti-aliased masks). A full 8 x 8 x 8 block becomes a tile, not a leaf.
// Memory: one band of 8 layers (8 * width * height bytes) plus one slab's tree.
//
// Streaming into one file: io::File::write needs all grids at once, so the writer derives from
// io::Archive and uses its protected writeHeader/writeGrid to append each slab's grid as it completes,
// then patches the grid count at the front (the file is seekable) - the same byte layout as
// io::File::write, so `vdb_print`, io::File and every VDB reader read it. The file is written under an
// OutputFile temporary and renamed at finish(). Each write carries a fresh random UUID in the header, so
// VDB files are never byte-identical between runs.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "core/mask_image.h"
#include "io/masks/mask_sink.h"

namespace toposlice {

inline constexpr uint32_t kVdbSlabLayers = 64;
inline constexpr std::size_t kVdbSlabLeafBytes = std::size_t{192} << 20;

std::unique_ptr<MaskSink> makeVdbSink(const std::filesystem::path& path, const MaskJob& job, bool overwrite);

// One grid of a mask VDB, read back (for tests and checks).
struct VdbSlab {
  std::string name;
  std::string valueType;  // "mask" or "float"
  uint64_t activeVoxels = 0;
  int firstLayer = -1, lastLayer = -1;
  std::array<double, 3> voxelSize{};    // world size of one voxel
  std::array<double, 3> voxelOrigin{};  // world position of the centre of voxel (0, 0, 0)
};

// Lists the grids of a mask VDB in file order. Throws InputError naming the file.
std::vector<VdbSlab> readVdbSlabs(const std::filesystem::path& file);

// Rebuilds layer `layer` as a width x height image: 255 where a mask grid is active, round(255 v) for a
// float grid. Throws InputError when no grid covers the layer.
MaskImage readVdbLayer(const std::filesystem::path& file, uint32_t layer, uint32_t width, uint32_t height);

}  // namespace toposlice
