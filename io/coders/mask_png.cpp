// PNG encoding for masks (PNG 1.2 spec; zlib stream RFC 1950) on the shared run deflater
// (deflate_runs.h).
#include "io/coders/mask_png.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cstring>
#include <memory>
#include <span>

#include <libdeflate.h>
#include <spng.h>

#include "core/prefetch.h"
#include "io/errors.h"
#include "io/output_file.h"

namespace toposlice {
namespace {

constexpr uint32_t kAdlerModulus = 65521;

// Contribution of one filtered row (n bytes) to Adler-32: a += S, b += n * a + T, with
// S = sum x_i and T = sum (n - i) x_i over the row's bytes x_0..x_{n-1}.
struct RowSums {
  uint64_t s = 0, t = 0;
  void addRun(uint64_t n, uint64_t offset, uint64_t length, uint64_t value) {
    s += value * length;
    t += value * (length * (n - offset) - length * (length - 1) / 2);
  }
  // The bytes [offset, offset + count) of the filtered row, read.
  void addBytes(uint64_t n, uint64_t offset, const uint8_t* bytes, size_t count) {
    uint64_t sum = 0, weighted = 0;  // sum of x_k, sum of k x_k
    for (size_t k = 0; k < count; ++k) {
      sum += bytes[k];
      weighted += k * bytes[k];
    }
    s += sum;
    t += (n - offset) * sum - weighted;
  }
};

void putBigEndian32(uint8_t* p, uint32_t v) {
  p[0] = static_cast<uint8_t>(v >> 24);
  p[1] = static_cast<uint8_t>(v >> 16);
  p[2] = static_cast<uint8_t>(v >> 8);
  p[3] = static_cast<uint8_t>(v);
}

// The tEXt chunk's keyword "Software", a zero byte, then the program's name (kSoftwareName).
constexpr auto kSoftwareText = [] {
  std::array<uint8_t, 9 + kSoftwareName.size()> text{};
  constexpr std::string_view keyword("Software", 9);  // with its terminating zero
  for (std::size_t i = 0; i < keyword.size(); ++i) text[i] = static_cast<uint8_t>(keyword[i]);
  for (std::size_t i = 0; i < kSoftwareName.size(); ++i) text[9 + i] = static_cast<uint8_t>(kSoftwareName[i]);
  return text;
}();

void appendChunk(std::vector<uint8_t>& out, const char type[4], std::span<const uint8_t> data) {
  const size_t at = out.size();
  out.resize(at + 12 + data.size());
  putBigEndian32(&out[at], static_cast<uint32_t>(data.size()));
  std::memcpy(&out[at + 4], type, 4);
  if (!data.empty()) std::memcpy(&out[at + 8], data.data(), data.size());
  putBigEndian32(&out[at + 8 + data.size()], libdeflate_crc32(0, &out[at + 4], 4 + data.size()));
}

}  // namespace

void encodeMaskPng(const MaskImage& mask, std::vector<uint8_t>& out, MaskPngScratch& scratch,
                   MaskPngCode code) {
  const size_t width = mask.width, height = mask.height;
  assert(width >= 1 && height >= 1 && mask.pixels.size() == width * height);
  const uint64_t n = width + 1;  // filtered row: filter byte 0, then the pixels
  // Token counts are 32-bit, and so is an IDAT chunk's length.
  if (n * height > 0xFFFFFFFFu) throw OutputError("mask image too large for one PNG IDAT chunk");

  // Pass 1: the filtered rows as tokens, and the Adler-32 of the bytes they stand for.
  const bool rowCopies = width >= 2 && n <= kDeflateMaxDistance;
  const auto rowDistance = static_cast<uint32_t>(rowCopies ? n : 1);
  RunDeflater tokens(scratch, rowDistance);
  uint64_t adlerA = 1, adlerB = 0;
  RowSums sums;
  // `length` bytes of `value` at `offset` in the filtered row.
  const auto put = [&](uint64_t offset, uint64_t length, uint8_t value) {
    sums.addRun(n, offset, length, value);
    tokens.putBytes(value, length);
  };
  const uint8_t* previous = nullptr;
  bool previousDark = false;  // the row above is all zeros
  // With known extents (mask_image.h) dark pixels are never read: rows compare on their lit spans and
  // zero runs outside them are known without scanning.
  const bool extents = mask.hasExtents();
  // With runs (a binary mask from the rasterizer), rows are coded and compared from their runs: lit
  // pixels are not even read.
  const bool runs = mask.hasRuns();
  size_t previousBegin = 0, previousEnd = width;
  std::span<const uint32_t> previousRuns;
  for (size_t r = 0; r < height; ++r) {
    const size_t stored = height - 1 - r;
    const uint8_t* row = mask.pixels.data() + stored * width;
    if (runs) {
      const std::span<const uint32_t> rowRuns(mask.runs.data() + 2 * size_t{mask.rowRuns[2 * stored]},
                                              2 * size_t{mask.rowRuns[2 * stored + 1]});
      const bool same = r > 0 && rowRuns.size() == previousRuns.size() &&
                        std::equal(rowRuns.begin(), rowRuns.end(), previousRuns.begin());
      previousRuns = rowRuns;
      if (rowCopies && same && !previousDark) {
        tokens.putCopy(n, row[width - 1]);
      } else {
        // Zeros (after the filter byte 0) up to the first run, then each run of 255 and the zeros after it.
        sums = RowSums{};
        size_t p = rowRuns.empty() ? width : rowRuns[0];
        put(0, p + 1, 0);
        for (size_t k = 0; k < rowRuns.size(); k += 2) {
          assert(row[rowRuns[k]] == 255);
          put(rowRuns[k] + 1, rowRuns[k + 1] - rowRuns[k], 255);
          p = k + 2 < rowRuns.size() ? rowRuns[k + 2] : width;
          if (p > rowRuns[k + 1]) put(rowRuns[k + 1] + 1, p - rowRuns[k + 1], 0);
        }
        previousDark = rowRuns.empty();
      }
      adlerB = (adlerB + n * adlerA + sums.t) % kAdlerModulus;
      adlerA = (adlerA + sums.s) % kAdlerModulus;
      continue;
    }
    // The row's non-zero pixels lie in [litBegin, litEnd): from the extents, else from a scan for the
    // first one (the rest of the row is then read as it is coded).
    size_t litBegin = width, litEnd = width;
    if (extents) {
      litBegin = mask.litBegin[stored];
      litEnd = mask.litEnd[stored];
      if (litBegin >= litEnd) litBegin = litEnd = width;
    } else {
      litBegin = runEnd(row, 0, width, 0);
    }
    const bool sameAsPrevious =
        previous != nullptr &&
        (extents ? litBegin == previousBegin && litEnd == previousEnd &&
                       std::memcmp(row + litBegin, previous + litBegin, litEnd - litBegin) == 0
                 : std::memcmp(row, previous, width) == 0);
    previousBegin = litBegin;
    previousEnd = litEnd;
    // A dark row is one run of zeros that continues the zeros before it: run matches cost the same
    // number of tokens as row copies, without the row distance's extra bits, so only lit rows are copied.
    if (rowCopies && sameAsPrevious && !previousDark) {
      tokens.putCopy(n, row[width - 1]);
    } else {
      sums = RowSums{};
      previousDark = litBegin == width;
      // The filter byte 0 and the zeros up to the first lit pixel; then the listed stretches of one
      // value as runs without reading them, and the pixels between them (most of them edge pixels, one
      // literal each) read as a byte string; then the zeros to the row's end.
      put(0, litBegin + 1, 0);
      const uint8_t* ahead = rowAhead(mask, stored);  // where each stretch read is prefetched
      forEachRowStretch(
          mask, stored, litBegin, litEnd,
          [&](size_t a, size_t b, uint8_t value) { put(a + 1, b - a, value); },
          [&](size_t a, size_t b) {
            prefetch(ahead + a);
            sums.addBytes(n, a + 1, row + a, b - a);
            tokens.putByteString(row + a, b - a);
          });
      if (litEnd < width) put(litEnd + 1, width - litEnd, 0);
    }
    adlerB = (adlerB + n * adlerA + sums.t) % kAdlerModulus;
    adlerA = (adlerA + sums.s) % kAdlerModulus;
    previous = row;
  }

  // Pass 2: the code, then the file around the block.

  static constexpr uint8_t kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  out.resize(8);
  std::memcpy(out.data(), kSignature, 8);
  uint8_t ihdr[13];
  putBigEndian32(ihdr, mask.width);
  putBigEndian32(ihdr + 4, mask.height);
  ihdr[8] = 8;   // bit depth
  ihdr[9] = 0;   // grayscale
  ihdr[10] = 0;  // deflate
  ihdr[11] = 0;  // adaptive filtering (every row uses type 0)
  ihdr[12] = 0;  // no interlace
  appendChunk(out, "IHDR", ihdr);
  appendChunk(out, "tEXt", kSoftwareText);  // how --force knows the file (checkReplaceable)

  const size_t idat = out.size();  // length, type, then the zlib stream
  out.resize(idat + 10);
  std::memcpy(&out[idat + 4], "IDAT", 4);
  out[idat + 8] = 0x78;  // CMF: deflate, 32 KiB window
  out[idat + 9] = 0x01;  // FLG: no dictionary, check bits ((0x78 << 8) | 0x01) % 31 == 0
  const size_t blockBytes = tokens.writeBlock(out, idat + 10, code);
  const uint64_t dataSize = 2 + uint64_t{blockBytes} + 4;
  if (dataSize > 0x7FFFFFFFu) throw OutputError("mask image too large for one PNG IDAT chunk");
  putBigEndian32(&out[idat], static_cast<uint32_t>(dataSize));
  size_t end = idat + 10 + blockBytes;
  out.resize(end + 8);  // the Adler-32, then the CRC
  putBigEndian32(&out[end], static_cast<uint32_t>((adlerB << 16) | adlerA));
  end += 4;
  putBigEndian32(&out[end], libdeflate_crc32(0, &out[idat + 4], 4 + dataSize));
  out.resize(end + 4);
  appendChunk(out, "IEND", {});
}

void encodeMaskPng(const MaskImage& mask, std::vector<uint8_t>& out) {
  MaskPngScratch scratch;
  encodeMaskPng(mask, out, scratch);
}

bool decodeMaskPng(std::span<const uint8_t> png, MaskImage& mask) {
  std::unique_ptr<spng_ctx, decltype(&spng_ctx_free)> ctx(spng_ctx_new(0), &spng_ctx_free);
  if (!ctx || spng_set_png_buffer(ctx.get(), png.data(), png.size()) != 0) return false;
  spng_ihdr ihdr{};
  if (spng_get_ihdr(ctx.get(), &ihdr) != 0) return false;
  if (ihdr.color_type != SPNG_COLOR_TYPE_GRAYSCALE || ihdr.bit_depth > 8) return false;
  size_t size = 0;
  if (spng_decoded_image_size(ctx.get(), SPNG_FMT_G8, &size) != 0) return false;
  if (size != size_t{ihdr.width} * ihdr.height) return false;
  std::vector<uint8_t> topDown(size);
  if (spng_decode_image(ctx.get(), topDown.data(), size, SPNG_FMT_G8, 0) != 0) return false;
  mask.width = ihdr.width;
  mask.height = ihdr.height;
  mask.pixels.resize(size);
  for (size_t r = 0; r < ihdr.height; ++r) {
    std::memcpy(&mask.pixels[(ihdr.height - 1 - r) * ihdr.width], &topDown[r * ihdr.width], ihdr.width);
  }
  return true;
}

}  // namespace toposlice
