// OpenEXR mask stack: a directory of single-part scanline files, one per layer (docs/FORMATS.md, "EXR").
//
// "<path>/<name>.00000.exr", ... (exrLayerFileName): one HALF channel "Y" holding the mask as 0..1
// (pixel / 255), ZIP compression (16 scanlines per chunk), rows top-down like the PNGs (mask row height-1
// first, so +y is up in the picture), data and display window (0, 0) - (width-1, height-1). Attributes:
//   z            float  the layer's cut plane, mm
//   layer        int    the layer index, 0-based
//   layerCount   int    layers announced by the job
//   layerHeight  float  mm
//   pixelSize    float  pixel edge, mm
//   origin       v2f    (x0, y0): lower-left corner of pixel (0, 0) in model mm, before mirroring
//   mirrorX, mirrorY int 1 where the rasterizer mirrored the image (pixel i shows column width-1-i)
//
// Encoding: encodeExrMaskLayer builds a whole file in memory, in the parallel stage (MaskSink::
// encodeLayer). Each 16-line chunk is compressed straight from the mask's runs: OpenEXR's ZIP is zlib
// over the chunk's bytes split into low and high bytes of the halves and delta-coded (byte minus the
// previous byte plus 128), so a run of pixels becomes one delta byte and a run of 128s, which the run
// deflater (deflate_runs.h) codes without ever forming the 2 x width x 16 raw bytes; rows equal to the
// row above become copies. OpenEXR's core library (openexr_core) writes the header, the pre-compressed
// chunks (exr_write_scanline_chunk) and the offset table into that buffer; the sink only writes the
// buffer to its file, in order. The bytes depend only on the pixels and the attributes.
//
// Why not one multi-part file: OpenEXR's multi-part writer needs every part's header when it is opened
// and keeps each part's header and offset table until it is closed, so its memory grows with the layer
// count (and tools list 100,000 parts poorly). One file per layer keeps memory at one layer, and every
// file is a plain image that `exrheader`, viewers and compositors read. The directory is written under
// a temporary name (StagedDirectory) and renamed at finish().
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "io/masks/mask_sink.h"

namespace toposlice {

inline constexpr uint32_t kExrLinesPerChunk = 16;  // ZIP_COMPRESSION's chunk height (fixed by the format)

std::unique_ptr<MaskSink> makeExrSink(const std::filesystem::path& path, const MaskJob& job, bool overwrite);

// "<prefix>.<index>.exr": the prefix of maskFilePrefix, a dot, then the index padded as in
// maskLayerFileName, so that sequence readers (Blender, Nuke, OpenImageIO: "name.#####.exr") find the
// frame number even when the job name ends in digits.
std::string exrLayerFileName(const std::string& name, uint32_t index, uint32_t layerCount);

// Layer `index` cut at `z` of `job` as a complete EXR file, into `out` (replaced). `mask` is
// job.grid.width x job.grid.height (width <= 32768 keeps row copies; any width works). Thread-safe.
// Throws OutputError when OpenEXR refuses the header.
void encodeExrMaskLayer(const MaskImage& mask, const MaskJob& job, uint32_t index, double z,
                        std::vector<uint8_t>& out, MaskEncodeScratch& scratch);

// One layer file read back with OpenEXR's C++ API (for tests and checks).
struct ExrMaskLayer {
  uint32_t width = 0, height = 0;
  std::vector<float> values;  // width * height, rows bottom-up as in MaskImage
  std::string channel;        // name of the file's only channel
  std::string compression;    // "zip", "rle", ... as OpenEXR names it
  float z = 0;
  int layer = -1;
  float pixelSize = 0;
  float layerHeight = 0;
};

// Reads a single-channel EXR written by the EXR sink. Throws InputError naming the file when it cannot
// be read or lacks the channel or the z / layer attributes.
ExrMaskLayer readExrMaskLayer(const std::filesystem::path& file);

}  // namespace toposlice
