// Mask layers as 8-bit grayscale PNG, and the PNG-directory sink (docs/FORMATS.md).
//
// The encoder is specialised for masks, where speed matters far more than size: filter type 0 on every
// row, one deflate block with the fixed Huffman code (RFC 1951 3.2.6), whose only matches are runs
// (distance 1) and rows equal to the row above (distance width + 1); the zlib Adler-32 is computed from
// the runs in closed form instead of byte by byte. A 2560 x 1440 binary mask encodes in well under a
// millisecond (libspng or zlib at level 1 take about 5.5 ms, libdeflate 5.5-9 ms); the file is larger
// than a level-9 PNG but still small (tens of kB for typical binary layers), and any PNG reader decodes
// it. Output is a pure function of the image: same pixels, same bytes.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <vector>

#include "core/mask_image.h"
#include "io/mask_sink.h"

namespace toposlice {

// Encodes `mask` (width, height >= 1, pixels.size() == width * height) as an 8-bit grayscale PNG into
// `out` (replaced; its capacity is reused, so pass the same vector for every layer). PNG rows are
// top-down: mask row height-1 comes first, so +y is up in the picture.
void encodeMaskPng(const MaskImage& mask, std::vector<uint8_t>& out);

// Decodes a PNG of any grayscale bit depth <= 8 into `mask` (rows bottom-up again, as MaskImage stores
// them). Returns false for a malformed file or a colour / 16-bit image. Meant for tests and checks.
bool decodeMaskPng(std::span<const uint8_t> png, MaskImage& mask);

// Directory "<path>/" of "<name>00000.png", ... (maskLayerFileName). The directory is written under a
// temporary name (StagedDirectory) and renamed at finish().
std::unique_ptr<MaskSink> makePngDirectorySink(const std::filesystem::path& path, const MaskJob& job,
                                               bool overwrite);

}  // namespace toposlice
