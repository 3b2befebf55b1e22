// Preview pictures (core/raster/preview.h) as PNG files: 8-bit RGB, encoded by libspng (sub filter, zlib
// level 1: these are small pictures drawn before a job's first layer), no time or text chunks, so the
// same picture gives the same bytes.
#pragma once

#include <cstdint>
#include <filesystem>
#include <vector>

#include "core/raster/preview.h"

namespace toposlice {

// Encodes `image` (width, height >= 1) into `out` (replaced). Throws OutputError if libspng fails.
void encodeRgbPng(const RgbImage& image, std::vector<uint8_t>& out);

// Renders `corners` at width x height and returns the PNG bytes.
std::vector<uint8_t> previewPng(std::span<const Point3f> corners, uint32_t width, uint32_t height,
                                const ChunkRunner& runner = serialChunkRunner());

}  // namespace toposlice
