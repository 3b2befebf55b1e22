// PNG encoding for masks (PNG 1.2 spec; deflate RFC 1951; zlib stream RFC 1950), the PNG-directory sink,
// the sink factory and StagedDirectory.
#include "io/mask_png.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cassert>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>
#include <system_error>

#include <fcntl.h>
#include <spng.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include "io/errors.h"
#include "io/output_file.h"
#include "io/exr_writer.h"
#include "io/sl1_writer.h"
#include "io/vdb_writer.h"

namespace toposlice {
namespace {

// ---------------------------------------------------------------------------------------------------
// Deflate with the fixed Huffman code.

struct BitCode {
  uint32_t bits;   // already in stream order (Huffman code bit-reversed, extra bits above it)
  uint32_t count;  // number of bits
};

constexpr uint32_t reverseBits(uint32_t v, uint32_t n) {
  uint32_t r = 0;
  for (uint32_t i = 0; i < n; ++i) r |= ((v >> i) & 1u) << (n - 1 - i);
  return r;
}

// Fixed literal/length code (RFC 1951 3.2.6) of symbol s in 0..287.
constexpr BitCode fixedSymbol(uint32_t s) {
  if (s < 144) return {reverseBits(0x30 + s, 8), 8};
  if (s < 256) return {reverseBits(0x190 + s - 144, 9), 9};
  if (s < 280) return {reverseBits(s - 256, 7), 7};
  return {reverseBits(0xC0 + s - 280, 8), 8};
}

constexpr std::array<uint32_t, 29> kLengthBase = {3,  4,  5,  6,   7,   8,   9,   10,  11, 13,
                                                  15, 17, 19, 23,  27,  31,  35,  43,  51, 59,
                                                  67, 83, 99, 115, 131, 163, 195, 227, 258};
constexpr std::array<uint32_t, 29> kLengthExtra = {0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2,
                                                   2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0};
constexpr std::array<uint32_t, 30> kDistanceBase = {
    1,   2,   3,   4,   5,   7,    9,    13,   17,   25,   33,   49,   65,    97,    129,
    193, 257, 385, 513, 769, 1025, 1537, 2049, 3073, 4097, 6145, 8193, 12289, 16385, 24577};
constexpr std::array<uint32_t, 30> kDistanceExtra = {0, 0, 0, 0, 1, 1, 2, 2,  3,  3,  4,  4,  5,  5,  6,
                                                     6, 7, 7, 8, 8, 9, 9, 10, 10, 11, 11, 12, 12, 13, 13};
constexpr uint32_t kMaxMatch = 258;
constexpr uint32_t kMaxDistance = 32768;

struct FixedCode {
  std::array<BitCode, 256> literal{};
  std::array<BitCode, kMaxMatch + 1> length{};  // index = match length 3..258, symbol and extra bits merged
  BitCode endOfBlock{};
};

constexpr FixedCode makeFixedCode() {
  FixedCode code;
  for (uint32_t v = 0; v < 256; ++v) code.literal[v] = fixedSymbol(v);
  code.endOfBlock = fixedSymbol(256);
  for (uint32_t len = 3; len <= kMaxMatch; ++len) {
    uint32_t i = 0;
    while (i + 1 < kLengthBase.size() && kLengthBase[i + 1] <= len) ++i;
    const BitCode sym = fixedSymbol(257 + i);
    code.length[len] = {sym.bits | ((len - kLengthBase[i]) << sym.count), sym.count + kLengthExtra[i]};
  }
  return code;
}

constexpr FixedCode kFixed = makeFixedCode();

BitCode distanceCode(uint32_t distance) {
  assert(distance >= 1 && distance <= kMaxDistance);
  uint32_t i = 0;
  while (i + 1 < kDistanceBase.size() && kDistanceBase[i + 1] <= distance) ++i;
  return {reverseBits(i, 5) | ((distance - kDistanceBase[i]) << 5), 5 + kDistanceExtra[i]};
}

// LSB-first bit packing (RFC 1951 3.1.1) into a byte vector that grows on demand.
class BitWriter {
 public:
  BitWriter(std::vector<uint8_t>& out, size_t pos) : out_(out), pos_(pos) {}

  // Makes room for `bytes` more whole bytes of output (plus the accumulator).
  void reserve(size_t bytes) {
    const size_t need = pos_ + bytes + 16;
    if (out_.size() < need) out_.resize(std::max(need, out_.size() * 2));
  }
  void put(BitCode c) {
    assert(c.count <= 32 && count_ < 32);
    acc_ |= uint64_t{c.bits} << count_;
    count_ += c.count;
    if (count_ >= 32) {
      for (int i = 0; i < 4; ++i) out_[pos_++] = static_cast<uint8_t>(acc_ >> (8 * i));
      acc_ >>= 32;
      count_ -= 32;
    }
  }
  size_t finish() {  // pads the last byte with zero bits; returns the end position
    while (count_ > 0) {
      out_[pos_++] = static_cast<uint8_t>(acc_);
      acc_ >>= 8;
      count_ = count_ > 8 ? count_ - 8 : 0;
    }
    return pos_;
  }

 private:
  std::vector<uint8_t>& out_;
  size_t pos_;
  uint64_t acc_ = 0;
  uint32_t count_ = 0;
};

// `n` bytes that repeat the stream `distance` bytes back, as matches of at most 258 bytes; a remainder
// of 1 or 2 bytes (only when n < 3 to begin with) is returned for the caller to send as literals.
uint32_t putCopies(BitWriter& w, uint32_t n, BitCode distance) {
  while (n >= 3) {
    uint32_t take = std::min(n, kMaxMatch);
    if (n - take == 1 || n - take == 2) take = n - 3;  // leave a remainder a match can still take
    w.put(kFixed.length[take]);
    w.put(distance);
    n -= take;
  }
  return n;
}

// First position >= p in row[0..width) whose byte differs from v.
size_t runEnd(const uint8_t* row, size_t p, size_t width, uint8_t v) {
  const uint64_t pattern = 0x0101010101010101ull * v;
  while (p + 8 <= width) {
    uint64_t word;
    std::memcpy(&word, row + p, 8);
    word ^= pattern;
    if (word != 0) {
      if constexpr (std::endian::native == std::endian::little) return p + std::countr_zero(word) / 8;
      return p + std::countl_zero(word) / 8;
    }
    p += 8;
  }
  while (p < width && row[p] == v) ++p;
  return p;
}

constexpr uint32_t kAdlerModulus = 65521;

// Contribution of one filtered row (n bytes) to Adler-32: a += S, b += n * a + T, with
// S = sum x_i and T = sum (n - i) x_i over the row's bytes x_0..x_{n-1}.
struct RowSums {
  uint64_t s = 0, t = 0;
  void addRun(uint64_t n, uint64_t offset, uint64_t length, uint64_t value) {
    s += value * length;
    t += value * (length * (n - offset) - length * (length - 1) / 2);
  }
};

void putBigEndian32(uint8_t* p, uint32_t v) {
  p[0] = static_cast<uint8_t>(v >> 24);
  p[1] = static_cast<uint8_t>(v >> 16);
  p[2] = static_cast<uint8_t>(v >> 8);
  p[3] = static_cast<uint8_t>(v);
}

void appendChunk(std::vector<uint8_t>& out, const char type[4], std::span<const uint8_t> data) {
  const size_t at = out.size();
  out.resize(at + 12 + data.size());
  putBigEndian32(&out[at], static_cast<uint32_t>(data.size()));
  std::memcpy(&out[at + 4], type, 4);
  if (!data.empty()) std::memcpy(&out[at + 8], data.data(), data.size());
  const uLong crc = crc32_z(0, &out[at + 4], 4 + data.size());
  putBigEndian32(&out[at + 8 + data.size()], static_cast<uint32_t>(crc));
}

// ---------------------------------------------------------------------------------------------------
// Files and directories.

std::string reason(int err) {
  return std::generic_category().message(err);
}

std::atomic<uint64_t> gStagedCounter{0};

std::filesystem::path siblingName(const std::filesystem::path& finalPath, const char* tag) {
  std::filesystem::path p = finalPath;
  p += std::string(tag) + std::to_string(::getpid()) + "-d" +
       std::to_string(gStagedCounter.fetch_add(1, std::memory_order_relaxed));
  return p;
}

// Writes a whole new file; `context` names the output in the error message.
void writeNewFile(const std::filesystem::path& file, std::span<const uint8_t> data,
                  const std::filesystem::path& context) {
  const int fd = ::open(file.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
  if (fd < 0) throw OutputError(context.string() + ": cannot create " + file.string() + ": " + reason(errno));
  const uint8_t* p = data.data();
  size_t left = data.size();
  while (left > 0) {
    const ssize_t n = ::write(fd, p, left);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int err = n < 0 ? errno : EIO;
      ::close(fd);
      throw OutputError(context.string() + ": cannot write " + file.string() + ": " + reason(err));
    }
    p += n;
    left -= static_cast<size_t>(n);
  }
  if (::close(fd) != 0) {
    throw OutputError(context.string() + ": cannot write " + file.string() + ": " + reason(errno));
  }
}

class PngDirectorySink final : public MaskSink {
 public:
  PngDirectorySink(const std::filesystem::path& path, const MaskJob& job, bool overwrite)
      : dir_(path, overwrite), job_(job) {}

  bool wantsPng() const override { return true; }

  void writeLayer(uint32_t index, double /*z*/, const MaskImage& mask,
                  std::span<const uint8_t> png) override {
    if (index != next_) {
      throw OutputError(dir_.finalPath().string() + ": layer " + std::to_string(index) +
                        " arrived, expected " + std::to_string(next_));
    }
    if (png.empty()) {
      if (mask.width != job_.grid.width || mask.height != job_.grid.height) {
        throw OutputError(dir_.finalPath().string() + ": layer " + std::to_string(index) +
                          " does not match the job's image size");
      }
      encodeMaskPng(mask, scratch_);
      png = scratch_;
    }
    writeNewFile(dir_.tempPath() / maskLayerFileName(job_.name, index, job_.layerCount, "png"), png,
                 dir_.finalPath());
    ++next_;
  }

  void finish(const MaskJob& /*finalJob*/) override { dir_.commit(); }

 private:
  StagedDirectory dir_;
  MaskJob job_;
  std::vector<uint8_t> scratch_;
  uint32_t next_ = 0;
};

}  // namespace

// -----------------------------------------------------------------------------------------------------

void encodeMaskPng(const MaskImage& mask, std::vector<uint8_t>& out) {
  const size_t width = mask.width, height = mask.height;
  assert(width >= 1 && height >= 1 && mask.pixels.size() == width * height);
  const uint64_t n = width + 1;  // filtered row: filter byte 0, then the pixels

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

  const size_t idat = out.size();  // length, type, then the zlib stream
  out.resize(idat + 8 + 2);
  std::memcpy(&out[idat + 4], "IDAT", 4);
  out[idat + 8] = 0x78;  // CMF: deflate, 32 KiB window
  out[idat + 9] = 0x01;  // FLG: no dictionary, check bits ((0x78 << 8) | 0x01) % 31 == 0

  BitWriter w(out, out.size());
  w.reserve(1);
  w.put({0b011, 3});  // BFINAL = 1, BTYPE = 01 (fixed Huffman)
  const bool rowCopies = width >= 2 && n <= kMaxDistance;
  const BitCode runDistance = distanceCode(1);
  const BitCode rowDistance = rowCopies ? distanceCode(static_cast<uint32_t>(n)) : runDistance;
  const size_t worstRowBytes = (n * 9 + 7) / 8 + 8;
  uint64_t adlerA = 1, adlerB = 0;
  RowSums sums;
  int last = -1;  // last byte sent, -1 before the first
  const uint8_t* previous = nullptr;
  // With known extents (mask_image.h) dark pixels are never read: rows compare on their lit spans and
  // zero runs outside them are known without scanning.
  const bool extents = mask.hasExtents();
  size_t previousBegin = 0, previousEnd = width;
  for (size_t r = 0; r < height; ++r) {
    const size_t stored = height - 1 - r;
    const uint8_t* row = mask.pixels.data() + stored * width;
    size_t litBegin = 0, litEnd = width;
    if (extents) {
      litBegin = mask.litBegin[stored];
      litEnd = mask.litEnd[stored];
      if (litBegin >= litEnd) litBegin = litEnd = width;
    }
    w.reserve(worstRowBytes);
    const bool sameAsPrevious =
        previous != nullptr &&
        (extents ? litBegin == previousBegin && litEnd == previousEnd &&
                       std::memcmp(row + litBegin, previous + litBegin, litEnd - litBegin) == 0
                 : std::memcmp(row, previous, width) == 0);
    previousBegin = litBegin;
    previousEnd = litEnd;
    // First position >= p whose byte differs from v, using the extents where they settle it.
    auto runFrom = [&](size_t p, uint8_t v) {
      if (!extents) return runEnd(row, p, width, v);
      if (p >= litEnd) return v == 0 ? width : p;  // dark to the end
      if (v == 0 && p < litBegin) return litBegin;  // dark up to the first lit pixel
      const size_t e = runEnd(row, p, litEnd, v);
      return e == litEnd && v == 0 ? width : e;
    };
    if (rowCopies && sameAsPrevious) {
      const uint32_t left = putCopies(w, static_cast<uint32_t>(n), rowDistance);
      assert(left == 0);
      (void)left;
    } else {
      sums = RowSums{};
      // The filter byte 0 joins a run of zeros at the start of the row.
      size_t p = runFrom(0, 0);
      uint32_t length = static_cast<uint32_t>(p) + 1;
      uint8_t value = 0;
      uint64_t offset = 0;  // of the run in the filtered row
      for (;;) {
        sums.addRun(n, offset, length, value);
        uint32_t repeat = length;
        if (last != value) {
          w.put(kFixed.literal[value]);
          --repeat;
        }
        for (uint32_t left = putCopies(w, repeat, runDistance); left > 0; --left)
          w.put(kFixed.literal[value]);
        last = value;
        if (p == width) break;
        offset = p + 1;
        value = row[p];
        const size_t end = runFrom(p + 1, value);
        length = static_cast<uint32_t>(end - p);
        p = end;
      }
    }
    adlerB = (adlerB + n * adlerA + sums.t) % kAdlerModulus;
    adlerA = (adlerA + sums.s) % kAdlerModulus;
    previous = row;
  }
  w.reserve(8);
  w.put(kFixed.endOfBlock);
  size_t end = w.finish();
  out.resize(end + 4);
  putBigEndian32(&out[end], static_cast<uint32_t>((adlerB << 16) | adlerA));
  end += 4;

  const size_t dataSize = end - (idat + 8);
  if (dataSize > 0x7FFFFFFFu) throw OutputError("mask image too large for one PNG IDAT chunk");
  putBigEndian32(&out[idat], static_cast<uint32_t>(dataSize));
  out.resize(end + 4);
  putBigEndian32(&out[end], static_cast<uint32_t>(crc32_z(0, &out[idat + 4], 4 + dataSize)));
  appendChunk(out, "IEND", {});
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

std::unique_ptr<MaskSink> makePngDirectorySink(const std::filesystem::path& path, const MaskJob& job,
                                               bool overwrite) {
  return std::make_unique<PngDirectorySink>(path, job, overwrite);
}

std::unique_ptr<MaskSink> makeMaskSink(const std::filesystem::path& path, const MaskJob& job,
                                       bool overwrite) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](char c) { return static_cast<char>(c >= 'A' && c <= 'Z' ? c - 'A' + 'a' : c); });
  if (ext == ".sl1" || ext == ".sl1s") return makeSl1Sink(path, job, overwrite);
  if (ext == ".exr") return makeExrSink(path, job, overwrite);
  if (ext == ".vdb") return makeVdbSink(path, job, overwrite);
  return makePngDirectorySink(path, job, overwrite);
}

std::string maskFilePrefix(const std::string& name) {
  if (name.empty()) return "layer";
  std::string prefix = name;
  for (char& c : prefix) {
    if (c == '/' || c == '\\' || static_cast<unsigned char>(c) < 0x20 || c == 0x7F) c = '_';
  }
  return prefix;
}

std::string maskLayerFileName(const std::string& name, uint32_t index, uint32_t layerCount, const char* ext) {
  int digits = 5;
  for (uint64_t limit = 100000; layerCount > limit; limit *= 10) ++digits;
  char number[16];
  std::snprintf(number, sizeof number, "%0*u", digits, index);
  return maskFilePrefix(name) + number + "." + ext;
}

// -----------------------------------------------------------------------------------------------------

StagedDirectory::StagedDirectory(std::filesystem::path finalPath, bool overwrite)
    : finalPath_(std::move(finalPath)), overwrite_(overwrite) {
  if (!overwrite_ && outputPathExists(finalPath_)) throw OutputError(outputExistsMessage(finalPath_));
  tempPath_ = siblingName(finalPath_, ".tmp-");
  if (::mkdir(tempPath_.c_str(), 0777) != 0) {
    throw OutputError(finalPath_.string() + ": cannot create " + tempPath_.string() + ": " + reason(errno));
  }
}

StagedDirectory::~StagedDirectory() {
  if (committed_) return;
  std::error_code ec;
  std::filesystem::remove_all(tempPath_, ec);
}

void StagedDirectory::commit() {
  assert(!committed_);
  const std::string temp = tempPath_.string(), final = finalPath_.string();
  if (!overwrite_) {
    if (::renameat2(AT_FDCWD, temp.c_str(), AT_FDCWD, final.c_str(), RENAME_NOREPLACE) == 0) {
      committed_ = true;
      return;
    }
    const int err = errno;
    if (err == EEXIST || ((err == EINVAL || err == ENOSYS) && outputPathExists(finalPath_))) {
      throw OutputError(outputExistsMessage(finalPath_));
    }
    if (err != EINVAL && err != ENOSYS) {
      throw OutputError(final + ": cannot rename " + temp + ": " + reason(err));
    }
  }
  if (::rename(temp.c_str(), final.c_str()) == 0) {  // no final entry yet, or an empty directory
    committed_ = true;
    return;
  }
  if (!overwrite_ || !outputPathExists(finalPath_)) {
    throw OutputError(final + ": cannot rename " + temp + ": " + reason(errno));
  }
  // Replace an existing entry: move it aside, move ours in, then delete the old one.
  const std::filesystem::path old = siblingName(finalPath_, ".old-");
  if (::rename(final.c_str(), old.c_str()) != 0) {
    throw OutputError(final + ": cannot replace the existing entry: " + reason(errno));
  }
  if (::rename(temp.c_str(), final.c_str()) != 0) {
    const int err = errno;
    ::rename(old.c_str(), final.c_str());
    throw OutputError(final + ": cannot rename " + temp + ": " + reason(err));
  }
  committed_ = true;
  std::error_code ec;
  std::filesystem::remove_all(old, ec);
}

}  // namespace toposlice
