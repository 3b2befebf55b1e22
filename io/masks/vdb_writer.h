// OpenVDB mask stack: one .vdb file holding one grid for the whole stack (default), or one grid per slab
// of layers (MaskJob::vdbSlabs, `--vdb-layout slabs`; docs/FORMATS.md, "VDB").
//
// Grids: a MaskGrid for binary jobs (active = lit), a FloatGrid for anti-aliased ones (value pixel/255,
// active where > 0, background 0, class fog volume). Index coordinates (i, j, k) are (pixel i, pixel j,
// layer k) with k the absolute layer index in every grid; the linear transform maps voxel centres to
// model mm: x = x0 + (i + 1/2) p, y = y0 + (j + 1/2) p (mirrored images use a negative scale, so world
// positions stay the model's), z = z_0 + k h with z_0 the first layer's cut plane, so voxel k spans that
// layer's slab. With an explicit, uneven list of planes the z of the transform is only approximate.
// Grid metadata: first_layer, last_layer, layer_height, pixel_size, first_z, origin_x, origin_y,
// mirror_x, mirror_y.
//
// Single grid: named kVdbGridName ("density", the grid Blender's and Houdini's volume shading read by
// default). Its tree is built band by band and written at finish(), so memory follows the tree: leaves
// along every lit edge of every 8 layers, tiles for fully lit 8 x 8 x 8 blocks.
// Slabs: grid "mask_<first layer, 5+ digits>" covers layers [first, last]; slabs start at multiples of 8
// (the leaf depth, so no leaf node is split between grids) and hold kVdbSlabLayers layers, fewer when
// their leaf nodes pass kVdbSlabLeafBytes (fine detail in anti-aliased masks). Memory: one slab's tree.
//
// Work split: encodeLayer (the caller's parallel stage) reduces a layer to its lit 8 x 8 pixel blocks,
// each with a bit per lit pixel (and its values when anti-aliased); writeEncodedLayer (in order) keeps a
// band of 8 layers of these records and merges them block by block into tiles and leaves, whose masks
// are assembled a column byte at a time, so the in-order work is per lit block, not per pixel.
//
// Streaming into one file: io::File::write needs all grids at once, so the writer derives from
// io::Archive and uses its protected writeHeader/writeGrid to append each grid as it completes, then
// patches the grid count at the front (the file is seekable) - the same byte layout as io::File::write,
// so `vdb_print`, io::File and every VDB reader read it. The file is written under an OutputFile
// temporary and renamed at finish(). Each write carries a fresh random UUID in the header, so VDB files
// are never byte-identical between runs.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "core/raster/mask_image.h"
#include "io/masks/mask_sink.h"

namespace toposlice {

inline constexpr const char* kVdbGridName = "density";  // the single grid's name
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
