// PNG mask stack: a directory of 8-bit grayscale PNGs, one per layer (docs/FORMATS.md), encoded by
// encodeMaskPng (mask_png.h) in encodeLayer.
#pragma once

#include <filesystem>
#include <memory>

#include "io/masks/mask_sink.h"

namespace toposlice {

// Directory "<path>/" of "<name>00000.png", ... (maskLayerFileName). The directory is written under a
// temporary name (StagedDirectory) and renamed at finish().
std::unique_ptr<MaskSink> makePngDirectorySink(const std::filesystem::path& path, const MaskJob& job,
                                               bool overwrite);

}  // namespace toposlice
