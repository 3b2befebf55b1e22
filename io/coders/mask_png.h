// Mask layers as 8-bit grayscale PNG (docs/FORMATS.md), for the PNG directory and SL1 writers.
//
// The encoder is specialised for masks: filter type 0 on every row, and a deflate stream (RFC 1951,
// RunDeflater in deflate_runs.h) whose only matches are runs (distance 1) and rows equal to the row
// above (distance width + 1). A first pass turns the image into these tokens (2 bytes each, in
// MaskPngScratch) and counts them; the
// zlib Adler-32 comes from the runs in closed form instead of byte by byte. A second pass builds
// length-limited canonical Huffman codes from the counts (package-merge) and writes one block with this
// dynamic code (RFC 1951 3.2.7), or with the fixed code (3.2.6) when that is not larger, e.g. for tiny
// images. On 2560 x 1440 aligner layers this takes 0.1-0.7 ms and gives files 2.7-5.7x (binary) or
// 1.6-3.8x (anti-aliased) smaller than the fixed code alone: about the size of zlib's Z_RLE strategy,
// about 20x faster than zlib at level 1, whose files are larger. Any PNG reader decodes it. Output is a
// pure function of the image: same pixels, same bytes.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/raster/mask_image.h"
#include "io/coders/deflate_runs.h"

namespace toposlice {

// Reusable buffer of encodeMaskPng (one per thread): the deflate tokens of the largest image so far,
// 2 bytes per token; at most 2 (width + 1) height bytes (noise), a few hundred kB for busy mask layers.
using MaskPngScratch = DeflateScratch;

// Which Huffman code encodeMaskPng may use: `smallest` (dynamic or fixed, whichever gives fewer bits;
// the fixed one on a tie) or always `fixed` (for tests and comparisons).
using MaskPngCode = DeflateCode;

// Encodes `mask` (width, height >= 1, pixels.size() == width * height) as an 8-bit grayscale PNG into
// `out` (replaced; its capacity is reused, so pass the same vector and scratch for every layer). PNG
// rows are top-down: mask row height-1 comes first, so +y is up in the picture.
void encodeMaskPng(const MaskImage& mask, std::vector<uint8_t>& out, MaskPngScratch& scratch,
                   MaskPngCode code = MaskPngCode::smallest);

// The same with a scratch buffer of its own (allocated per call).
void encodeMaskPng(const MaskImage& mask, std::vector<uint8_t>& out);

// Decodes a PNG of any grayscale bit depth <= 8 into `mask` (rows bottom-up again, as MaskImage stores
// them). Returns false for a malformed file or a colour / 16-bit image. Meant for tests and checks.
bool decodeMaskPng(std::span<const uint8_t> png, MaskImage& mask);

}  // namespace toposlice
