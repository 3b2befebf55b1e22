// Elegoo GOO writer (docs/FORMATS.md), after Elegoo's "GOO format specification" v1.2 (a copy is in
// the UVtools repository's documentation). Every multi-byte field is big-endian (the specification does
// not say so; its public readers, UVtools and mslicer, read them so).
//
// File: header (kGooHeaderSize bytes, with the two RGB565 previews), then per layer a definition, the
// size of the image data, the image data (0x55, the run-length chunks, a checksum) and 0x0D 0x0A, then
// the ending string. The chunks of a layer are encoded in the parallel stage (encodeLayer) straight from
// the mask's rows, top row first; the header is written with placeholders first and rewritten at the end
// with the layer count, volume and print time.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <vector>

#include "io/masks/mask_sink.h"

namespace toposlice {

inline constexpr std::size_t kGooHeaderSize = 195477;  // the sum of the header's field lengths
inline constexpr uint32_t kGooSmallPreview = 116, kGooBigPreview = 290;
inline constexpr uint32_t kGooMaxRun = (1u << 28) - 1;  // 4 + 3 x 8 bits of length

std::unique_ptr<MaskSink> makeGooSink(const std::filesystem::path& path, const MaskJob& job, bool overwrite);

// Appends the chunks for `length` >= 1 pixels of `value`: value 0 -> chunk type 00, 255 -> 11, others
// -> 01 followed by the value; the length in the fewest of the 4 length forms (low 4 bits in byte 0,
// higher bits in 0-3 following bytes, most significant first); runs longer than kGooMaxRun are split.
void appendGooRun(std::vector<uint8_t>& out, uint8_t value, uint32_t length);

// The image-data checksum: the bitwise complement of the 8-bit sum of the chunk bytes (not the 0x55).
uint8_t gooChecksum(const uint8_t* chunks, std::size_t size);

// Exposure time (s) of layer `index`: the SL1 firmware's fade (sl1_writer.h), which is GOO's one bottom
// layer followed by fadeLayers - 2 transition layers.
double gooLayerExposure(const MaskJob& job, uint32_t index);

}  // namespace toposlice
