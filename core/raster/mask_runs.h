// A compact run-length form of a mask, to hold rasterized layers between the parallel stage and the
// in-order writer without keeping full images (a binary 2560 x 1440 layer of a part is a few KB of runs
// instead of 3.7 MB). Format: for each row, pairs (value: uint8, length: uint16 little-endian) covering
// the row exactly; rows follow one another.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/raster/mask_image.h"

namespace toposlice {

// Appends nothing but `out`'s new content: out is cleared first.
void encodeMaskRuns(const MaskImage& mask, std::vector<uint8_t>& out);

// Decodes into `mask`, which must already have the encoded width and height. Returns false on
// malformed runs (never produced by encodeMaskRuns).
bool decodeMaskRuns(std::span<const uint8_t> runs, MaskImage& mask);

}  // namespace toposlice
