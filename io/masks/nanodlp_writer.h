// NanoDLP plate archive writer (`.nanodlp`, docs/FORMATS.md), after NanoDLP's manual page "ZIP File
// Format": a zip of meta.json, plate.json, profile.json, info.json (one object per layer), 3d.png (a
// 200 x 100 preview) and the layers as 8-bit grayscale PNGs named 1.png, 2.png, ... (1-based, as
// mslicer writes them). Layers are encoded in the parallel stage (the PNG coder of mask_png.h, the
// CRC-32 and the layer's info.json object) and streamed into the zip in order (ZipStream); the JSON
// files are added at finish(). Memory: the zip directory and the info.json text, about 250 bytes per
// layer.
#pragma once

#include <filesystem>
#include <memory>

#include "io/masks/mask_sink.h"

namespace toposlice {

std::unique_ptr<MaskSink> makeNanoDlpSink(const std::filesystem::path& path, const MaskJob& job,
                                          bool overwrite);

// NanoDLP's per-layer figures, from the layer's pixels: lit area (grey pixels count by their value / 255),
// islands (4-connected groups of lit pixels) and the pixel bounds of the lit area, x from the left,
// y from the top row of the picture.
struct NanoDlpLayerInfo {
  double totalSolidArea = 0, largestArea = 0, smallestArea = 0;  // mm^2
  uint32_t minX = 0, minY = 0, maxX = 0, maxY = 0;               // pixels; all 0 for a dark layer
  uint64_t areaCount = 0;
};
NanoDlpLayerInfo nanoDlpLayerInfo(const MaskImage& mask, double pixel);

}  // namespace toposlice
