// OpenEXR mask stack: a directory of single-part scanline files, one per layer (docs/FORMATS.md, "EXR").
//
// "<path>/<name>00000.exr", ...: one HALF channel "Y" holding the mask as 0..1 (pixel / 255), ZIP
// compression (16 scanlines per block), rows top-down like the PNGs (mask row height-1 first, so +y is up
// in the picture), data and display window (0, 0) - (width-1, height-1). Attributes per file:
//   z            float  the layer's cut plane, mm
//   layer        int    the layer index, 0-based
//   layerCount   int    layers announced by the job
//   layerHeight  float  mm
//   pixelSize    float  pixel edge, mm
//   origin       v2f    (x0, y0): lower-left corner of pixel (0, 0) in model mm, before mirroring
//   mirrorX, mirrorY int 1 where the rasterizer mirrored the image (pixel i shows column width-1-i)
// Why not one multi-part file: OpenEXR's MultiPartOutputFile needs every part's header when it is opened
// and keeps each part's header, offset table and writer until it is closed, so its memory grows with the
// layer count (and tools list 100,000 parts poorly). One file per layer keeps memory at one layer, and
// every file is a plain image that `exrheader`, viewers and compositors read. The directory is written
// under a temporary name (StagedDirectory) and renamed at finish().
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "io/masks/mask_sink.h"

namespace toposlice {

inline constexpr int kExrZipLevel = 1;  // zlib level of the ZIP blocks: speed over size, as for the PNGs

std::unique_ptr<MaskSink> makeExrSink(const std::filesystem::path& path, const MaskJob& job, bool overwrite);

// Sets the size of OpenEXR's process-wide thread pool (Imf::setGlobalThreadCount), which compresses the
// 16-line ZIP blocks of one file in parallel; 0 (OpenEXR's default) compresses on the calling thread.
// Writing a 2560 x 1440 layer takes about 45 ms on one core, mostly OpenEXR's block preparation and zlib.
void setExrThreadCount(int threads);

// One layer file read back (for tests and checks).
struct ExrMaskLayer {
  uint32_t width = 0, height = 0;
  std::vector<float> values;  // width * height, rows bottom-up as in MaskImage
  std::string channel;        // name of the file's only channel
  float z = 0;
  int layer = -1;
  float pixelSize = 0;
  float layerHeight = 0;
};

// Reads a single-channel EXR written by the EXR sink. Throws InputError naming the file when it cannot
// be read or lacks the channel or the z / layer attributes.
ExrMaskLayer readExrMaskLayer(const std::filesystem::path& file);

}  // namespace toposlice
