// Deflate (RFC 1951) and zlib (RFC 1950) for byte streams made of runs: the shared coder of the mask
// writers (the IDAT stream of the PNG coder, mask_png.h; the ZIP chunks of the EXR writer, exr_writer.h).
//
// A stream is given as runs (`count` bytes of one value) and copies (bytes repeating those a fixed
// distance back, e.g. the row above). The only deflate matches are runs (distance 1) and copies at that
// distance, collected as tokens (2 bytes each, in a DeflateScratch; one token stands for a series of
// 258-byte matches, so a long run costs one token, not one per 258 bytes) with their counts; writeBlock then
// builds length-limited canonical Huffman codes from the counts (package-merge) and writes one final
// block with this dynamic code (RFC 1951 3.2.7), or with the fixed code (3.2.6) when that is not larger.
// Output is a pure function of the runs and copies given: same calls, same bytes.
#pragma once

#include <array>
#include <cassert>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "core/raster/mask_image.h"

namespace toposlice {

// Which Huffman code writeBlock may use: `smallest` (dynamic or fixed, whichever gives fewer bits; the
// fixed one on a tie) or always `fixed` (for tests and comparisons).
enum class DeflateCode { smallest, fixed };

// Reusable token buffer (one per thread), grown to the largest stream so far and never shrunk.
struct DeflateScratch {
  std::vector<uint16_t> tokens;
};

inline constexpr uint32_t kDeflateMaxDistance = 32768;

class RunDeflater {
 public:
  // copyDistance: the distance of putCopy, 1..kDeflateMaxDistance. `scratch` must outlive the deflater.
  RunDeflater(DeflateScratch& scratch, uint32_t copyDistance);
  ~RunDeflater();

  // Appends `count` >= 1 bytes of `value`. Runs of one value across calls join into one run. Inline: an
  // anti-aliased mask puts most of its edge pixels one literal at a time.
  void putBytes(uint8_t value, uint64_t count) {
    assert(count >= 1);
    if (last_ == value) {
      pending_ += count;
      return;
    }
    if (pending_ != 0) flush();
    push(value);
    last_ = value;
    pending_ = count - 1;
  }
  // Appends the `count` bytes at `bytes`, the same as putBytes(bytes[i], 1) for each in turn: the edge
  // pixels of an anti-aliased row, mostly one literal each, in one loop.
  void putByteString(const uint8_t* bytes, size_t count);
  // Appends `count` >= 3 bytes repeating those copyDistance back (the stream already holds that many);
  // the last of them is `lastByte`.
  void putCopy(uint64_t count, uint8_t lastByte);

  // One stream: ends it and writes it as one final block at out[at ..], growing `out` as needed (it is
  // left larger: the caller trims it); returns the block's size in bytes.
  size_t writeBlock(std::vector<uint8_t>& out, size_t at, DeflateCode code);

  // Several streams with one code (e.g. the chunks of one image, each its own zlib stream): endStream()
  // closes the stream so far (the next one starts without history) and returns its number; after the
  // last, writeStream(i) writes stream i as one final block, all with the code planned from the counts
  // of all streams at the first writeStream (one plan instead of one per stream). Same growth of `out`.
  size_t endStream();
  size_t writeStream(size_t stream, std::vector<uint8_t>& out, size_t at, DeflateCode code);

  static constexpr uint32_t kTokenKinds = 256 + 2 * 256;  // literals, runs of 3..258, copies of 3..258

 private:
  struct Plan;
  void grow(size_t more);  // the token buffer, to hold `more` tokens beyond size_ (at least doubled)
  // Into the buffer, grown as needed; counts are the caller's.
  void append(uint32_t token) {
    if (size_ == tokens_.size()) [[unlikely]]
      grow(1);
    tokens_[size_++] = static_cast<uint16_t>(token);
  }
  // A literal or one match, counted.
  void push(uint32_t token) {
    assert(token < kTokenKinds && !plan_);
    append(token);
    ++counts_[token];
    ++expanded_;
  }
  void flush();
  void putMatches(uint64_t n, uint32_t kind);
  void pushLongest(uint64_t q, uint32_t kind);
  size_t streamBound(size_t stream) const;

  std::vector<uint16_t>& tokens_;
  size_t size_ = 0;
  std::array<uint32_t, kTokenKinds> counts_{};
  uint32_t copyDistance_;
  int last_ = -1;                   // last byte of the stream so far, -1 before the first
  uint64_t pending_ = 0;            // bytes equal to last_ at the end of the stream, not yet sent as tokens
  uint64_t expanded_ = 0;           // literals and matches so far (a repeat token stands for many)
  std::vector<size_t> streamEnds_;  // token count at the end of each stream
  std::vector<uint64_t> streamMatches_;  // expanded_ at the end of each stream
  std::unique_ptr<Plan> plan_;
};

// Adler-32 (RFC 1950 8.2) of a stream given as runs: a run of `count` bytes of value v adds v count to
// A and count A + v count (count + 1) / 2 to B, so no byte is visited.
class RunAdler32 {
 public:
  void add(uint8_t value, uint64_t count);
  // One byte `first`, then count - 1 bytes of `rest` (count >= 1): the delta bytes of one run.
  void addRun(uint8_t first, uint8_t rest, uint64_t count);
  uint32_t value() const;

 private:
  uint64_t a_ = 1, b_ = 0;
};

// First position >= p in row[0..end) whose byte differs from v, scanned 8 bytes at a time.
size_t runEnd(const uint8_t* row, size_t p, size_t end, uint8_t v);

}  // namespace toposlice
