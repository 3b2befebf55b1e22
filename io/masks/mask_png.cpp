// PNG encoding for masks (PNG 1.2 spec; deflate RFC 1951; zlib stream RFC 1950), the PNG-directory sink,
// the sink factory.
#include "io/masks/mask_png.h"

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
#include "io/masks/exr_writer.h"
#include "io/masks/sl1_writer.h"
#include "io/masks/vdb_writer.h"
#include "io/output_file.h"
#include "io/staged_directory.h"

namespace toposlice {
namespace {

// ---------------------------------------------------------------------------------------------------
// Deflate (RFC 1951): the image as a stream of tokens (literals, runs, row copies), then one block that
// codes them with a dynamic Huffman code (3.2.7) or, when that is not smaller, the fixed code (3.2.6).

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

constexpr uint32_t kEndOfBlock = 256;
constexpr uint32_t kLitLenSymbols = 286;  // 0..255 literals, 256 end of block, 257..285 lengths
constexpr uint32_t kDistanceSymbols = 30;
// The fixed code also assigns codes to literal/length symbols 286, 287 and distance symbols 30, 31
// (never sent); its canonical construction needs them.
constexpr uint32_t kFixedLitLenSymbols = 288, kFixedDistanceSymbols = 32;
constexpr uint32_t kCodeLengthSymbols = 19;
constexpr uint32_t kMaxCodeBits = 15;       // literal/length and distance codes
constexpr uint32_t kMaxCodeLengthBits = 7;  // the code-length code
constexpr std::array<uint8_t, kCodeLengthSymbols> kCodeLengthOrder = {16, 17, 18, 0, 8,  7, 9,  6, 10, 5,
                                                                      11, 4,  12, 3, 13, 2, 14, 1, 15};

// Tokens, one uint16_t each: t < 256 is the literal byte t; kRunMatch + (L - 3) is a match of L bytes
// (3..258) at distance 1 (a run); kRowMatch + (L - 3) one at distance width + 1 (the row above).
constexpr uint32_t kRunMatch = 256;
constexpr uint32_t kRowMatch = kRunMatch + kMaxMatch - 2;
constexpr uint32_t kTokenKinds = kRowMatch + kMaxMatch - 2;

// Length symbol index (0..28, symbol 257 + index) of every match length 0..258 (meaningful from 3).
constexpr std::array<uint8_t, kMaxMatch + 1> kLengthIndex = [] {
  std::array<uint8_t, kMaxMatch + 1> index{};
  size_t i = 0;
  for (uint32_t len = 3; len <= kMaxMatch; ++len) {
    while (i + 1 < kLengthBase.size() && kLengthBase[i + 1] <= len) ++i;
    index[len] = static_cast<uint8_t>(i);
  }
  return index;
}();

uint32_t distanceIndex(uint32_t distance) {
  assert(distance >= 1 && distance <= kMaxDistance);
  uint32_t i = 0;
  while (i + 1 < kDistanceBase.size() && kDistanceBase[i + 1] <= distance) ++i;
  return i;
}

constexpr uint32_t reverseBits(uint32_t v, uint32_t n) {
  uint32_t r = 0;
  for (uint32_t i = 0; i < n; ++i) r |= ((v >> i) & 1u) << (n - 1 - i);
  return r;
}

// The token stream of one image and how often each token occurs. `tokens` is the caller's buffer,
// grown on demand and never shrunk.
class TokenStream {
 public:
  explicit TokenStream(std::vector<uint16_t>& tokens) : tokens_(tokens) {}

  void push(uint32_t token) {
    assert(token < kTokenKinds);
    if (size_ == tokens_.size()) [[unlikely]]
      tokens_.resize(std::max<size_t>(4096, 2 * size_));
    tokens_[size_++] = static_cast<uint16_t>(token);
    ++counts_[token];
  }
  std::span<const uint16_t> tokens() const { return {tokens_.data(), size_}; }
  const std::array<uint32_t, kTokenKinds>& counts() const { return counts_; }

 private:
  std::vector<uint16_t>& tokens_;
  size_t size_ = 0;
  std::array<uint32_t, kTokenKinds> counts_{};
};

// `n` bytes that repeat the stream at the distance of `kind` (kRunMatch, kRowMatch), as match tokens of
// at most 258 bytes; a remainder of 1 or 2 bytes (only when n < 3 to begin with) is returned for the
// caller to send as literals.
uint32_t putCopies(TokenStream& tokens, uint64_t n, uint32_t kind) {
  while (n >= 3) {
    uint64_t take = std::min<uint64_t>(n, kMaxMatch);
    if (n - take == 1 || n - take == 2) take = n - 3;  // leave a remainder a match can still take
    tokens.push(kind + static_cast<uint32_t>(take) - 3);
    n -= take;
  }
  return static_cast<uint32_t>(n);
}

// Optimal prefix-code lengths of at most maxBits bits for the symbols with freq > 0, 0 for the others,
// by package-merge (L. L. Larmore, D. S. Hirschberg, "A fast algorithm for optimal length-limited
// Huffman codes", JACM 37(3), 1990). Needs 2 <= used symbols <= 2^maxBits; the code is then complete
// (Kraft sum exactly 1), as zlib's inflate requires of every code but a lone distance code. Ties are
// broken by symbol, so the lengths are a function of the frequencies.
void limitedCodeLengths(std::span<const uint32_t> freq, uint32_t maxBits, std::span<uint8_t> lengths) {
  constexpr size_t kMaxItems = 2 * kLitLenSymbols;
  assert(freq.size() <= kLitLenSymbols && lengths.size() == freq.size());
  assert(maxBits >= 1 && maxBits <= kMaxCodeBits);
  std::array<uint64_t, kLitLenSymbols> leaves;  // freq << 16 | symbol, ascending
  size_t n = 0;
  for (size_t s = 0; s < freq.size(); ++s) {
    if (freq[s] > 0) leaves[n++] = (uint64_t{freq[s]} << 16) | s;
  }
  assert(n >= 2 && n <= (size_t{1} << maxBits));
  std::sort(leaves.begin(), leaves.begin() + n);
  // List d (d = 0 .. maxBits-1, coin width 2^(d - maxBits)) merges the leaves with the pairs of list
  // d-1 by weight (list 0: the leaves alone), keeping its 2n - 2 lightest items, the most ever taken.
  const size_t keep = 2 * n - 2;
  std::array<uint64_t, kMaxItems> weightsA, weightsB;
  std::array<std::array<bool, kMaxItems>, kMaxCodeBits> isLeaf;
  std::array<size_t, kMaxCodeBits> listSize;
  uint64_t* previous = weightsA.data();
  uint64_t* current = weightsB.data();
  for (size_t i = 0; i < n; ++i) previous[i] = leaves[i] >> 16;
  size_t previousSize = n;
  listSize[0] = n;
  for (uint32_t d = 1; d < maxBits; ++d) {
    const size_t pairs = previousSize / 2;
    size_t leaf = 0, pair = 0, size = 0;
    while (size < keep && (leaf < n || pair < pairs)) {
      const uint64_t pairWeight = pair < pairs ? previous[2 * pair] + previous[2 * pair + 1] : ~uint64_t{0};
      const bool takeLeaf = leaf < n && (leaves[leaf] >> 16) <= pairWeight;
      current[size] = takeLeaf ? leaves[leaf++] >> 16 : (++pair, pairWeight);
      isLeaf[d][size++] = takeLeaf;
    }
    std::swap(previous, current);
    previousSize = listSize[d] = size;
  }
  // Take the 2n - 2 lightest items of the top list; a pair taken from list d takes two items of list
  // d-1. Every leaf taken adds one bit to its symbol's code, and leaves are taken lightest first.
  std::fill(lengths.begin(), lengths.end(), uint8_t{0});
  size_t take = keep;
  for (uint32_t d = maxBits; d-- > 0;) {
    assert(take <= listSize[d]);
    size_t leafCount = take;
    if (d > 0) leafCount = static_cast<size_t>(std::count(isLeaf[d].begin(), isLeaf[d].begin() + take, true));
    for (size_t i = 0; i < leafCount; ++i) ++lengths[leaves[i] & 0xFFFF];
    take = 2 * (take - leafCount);
  }
  assert(take == 0);
}

// Gives frequency 1 to the lowest unused symbols until at least two are used: then limitedCodeLengths
// yields a complete code, which every inflater accepts (a lone code of length 1 is legal only for
// distances, and a code-length code must be complete).
void useAtLeastTwoSymbols(std::span<uint32_t> freq) {
  size_t used =
      static_cast<size_t>(std::count_if(freq.begin(), freq.end(), [](uint32_t f) { return f > 0; }));
  for (size_t s = 0; used < 2 && s < freq.size(); ++s) {
    if (freq[s] == 0) {
      freq[s] = 1;
      ++used;
    }
  }
}

// Canonical codes (RFC 1951 3.2.2) of code lengths <= 15, bit-reversed for LSB-first output.
void canonicalCodes(std::span<const uint8_t> lengths, std::span<uint32_t> codes) {
  std::array<uint32_t, kMaxCodeBits + 1> count{}, next{};
  for (uint8_t len : lengths) ++count[len];
  count[0] = 0;
  uint32_t code = 0;
  for (uint32_t bits = 1; bits <= kMaxCodeBits; ++bits) {
    code = (code + count[bits - 1]) << 1;
    next[bits] = code;
  }
  for (size_t s = 0; s < lengths.size(); ++s) {
    codes[s] = lengths[s] == 0 ? 0 : reverseBits(next[lengths[s]]++, lengths[s]);
  }
}

// The code lengths of both alphabets as one sequence (RFC 1951 3.2.7) in code-length symbols: 0..15
// literally, 16 = repeat the previous length 3..6 times, 17 = 3..10 zeros, 18 = 11..138 zeros.
struct CodeLengthItem {
  uint8_t symbol;
  uint8_t extra;  // value of the extra bits (repeat count - 3 or - 11)
};
constexpr std::array<uint32_t, kCodeLengthSymbols> kCodeLengthExtraBits = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
                                                                           0, 0, 0, 0, 0, 0, 2, 3, 7};

size_t runLengthCodeLengths(std::span<const uint8_t> lengths, std::span<CodeLengthItem> items) {
  size_t count = 0;
  auto push = [&](size_t symbol, size_t extra) {
    items[count++] = {static_cast<uint8_t>(symbol), static_cast<uint8_t>(extra)};
  };
  for (size_t i = 0; i < lengths.size();) {
    const uint8_t v = lengths[i];
    size_t run = 1;
    while (i + run < lengths.size() && lengths[i + run] == v) ++run;
    i += run;
    if (v == 0) {
      for (; run >= 11; run -= std::min<size_t>(run, 138)) push(18, std::min<size_t>(run, 138) - 11);
      if (run >= 3) {
        push(17, run - 3);
        run = 0;
      }
    } else {
      push(v, 0);
      --run;
      for (; run >= 3; run -= std::min<size_t>(run, 6)) push(16, std::min<size_t>(run, 6) - 3);
    }
    for (; run > 0; --run) push(v, 0);
  }
  return count;
}

// LSB-first bit packing (RFC 1951 3.1.1) into a buffer that the caller sized: each put stores 8 bytes
// at the current byte, so 8 bytes of slack must follow the end of the stream.
class BitWriter {
 public:
  explicit BitWriter(uint8_t* out) : out_(out) {}

  void put(uint64_t bits, uint32_t count) {  // count <= 56, bits above count zero
    assert(count <= 56 && bits >> count == 0);
    acc_ |= bits << count_;
    count_ += count;
    uint64_t bytes = acc_;
    if constexpr (std::endian::native == std::endian::big) bytes = __builtin_bswap64(bytes);
    std::memcpy(out_ + pos_, &bytes, 8);
    const uint32_t whole = count_ >> 3;
    pos_ += whole;
    acc_ >>= 8 * whole;
    count_ &= 7;
  }
  size_t finish() const { return pos_ + (count_ > 0 ? 1 : 0); }  // bytes written, last one zero-padded

 private:
  uint8_t* out_;
  size_t pos_ = 0;
  uint64_t acc_ = 0;
  uint32_t count_ = 0;
};

// The bits of one token in stream order: its Huffman code, then length extra bits, distance code and
// distance extra bits for a match.
struct TokenCode {
  uint64_t bits;
  uint32_t count;
};

// The Huffman code of one block and its exact size. Only the lengths are kept: codes are canonical.
struct BlockCode {
  bool dynamic = false;
  uint64_t bits = 0;  // the whole block: header, tokens, end of block
  // Code lengths; a dynamic code uses the first kLitLenSymbols and kDistanceSymbols of them.
  std::array<uint8_t, kFixedLitLenSymbols> litLen{};
  std::array<uint8_t, kFixedDistanceSymbols> distance{};
  // Dynamic header: HLIT + 257 literal/length and HDIST + 1 distance code lengths, as run-length items
  // in the code-length code, whose HCLEN + 4 lengths are sent in kCodeLengthOrder.
  uint32_t litLenCount = 0, distanceCount = 0, codeLengthCount = 0;
  std::array<uint8_t, kCodeLengthSymbols> codeLength{};
  std::array<CodeLengthItem, kLitLenSymbols + kDistanceSymbols> items{};
  size_t itemCount = 0;
};

// Picks the smaller of the dynamic code built from the token counts and the fixed code (the fixed one
// on a tie, or always when `choice` says so). rowIndex: distance symbol of the kRowMatch tokens.
void planBlock(const std::array<uint32_t, kTokenKinds>& counts, uint32_t rowIndex, MaskPngCode choice,
               BlockCode& code) {
  std::array<uint32_t, kLitLenSymbols> litLenFreq{};
  std::array<uint32_t, kDistanceSymbols> distanceFreq{};
  uint64_t extraBits = 0;  // length and distance extra bits: the same under either code
  for (uint32_t v = 0; v < 256; ++v) litLenFreq[v] = counts[v];
  litLenFreq[kEndOfBlock] = 1;
  uint64_t runs = 0, rowCopies = 0;
  for (uint32_t len = 3; len <= kMaxMatch; ++len) {
    const uint32_t run = counts[kRunMatch + len - 3], row = counts[kRowMatch + len - 3];
    const uint32_t index = kLengthIndex[len];
    litLenFreq[257 + index] += run + row;
    extraBits += uint64_t{run + row} * kLengthExtra[index];
    runs += run;
    rowCopies += row;
  }
  distanceFreq[0] += static_cast<uint32_t>(runs);
  distanceFreq[rowIndex] += static_cast<uint32_t>(rowCopies);
  extraBits += rowCopies * kDistanceExtra[rowIndex];

  uint64_t fixedBits = 3 + extraBits + (runs + rowCopies) * 5;
  for (uint32_t s = 0; s < kLitLenSymbols; ++s) {
    fixedBits += uint64_t{litLenFreq[s]} * (s < 144 ? 8 : s < 256 ? 9 : s < 280 ? 7 : 8);
  }

  code.dynamic = false;
  code.bits = fixedBits;
  if (choice == MaskPngCode::smallest) {
    // Literal 0 (the first filter byte) and end of block: two literal/length symbols at least. The
    // distance code gets two as well, even when no match occurs (HDIST counts one code at least).
    assert(litLenFreq[0] > 0);
    useAtLeastTwoSymbols(distanceFreq);
    code.litLen.fill(0);
    code.distance.fill(0);
    limitedCodeLengths(litLenFreq, kMaxCodeBits, std::span(code.litLen).first<kLitLenSymbols>());
    limitedCodeLengths(distanceFreq, kMaxCodeBits, std::span(code.distance).first<kDistanceSymbols>());
    code.litLenCount = kLitLenSymbols;
    while (code.litLen[code.litLenCount - 1] == 0) --code.litLenCount;
    code.distanceCount = kDistanceSymbols;
    while (code.distance[code.distanceCount - 1] == 0) --code.distanceCount;
    std::array<uint8_t, kLitLenSymbols + kDistanceSymbols> sequence;
    std::copy_n(code.litLen.begin(), code.litLenCount, sequence.begin());
    std::copy_n(code.distance.begin(), code.distanceCount, sequence.begin() + code.litLenCount);
    code.itemCount =
        runLengthCodeLengths({sequence.data(), code.litLenCount + code.distanceCount}, code.items);
    std::array<uint32_t, kCodeLengthSymbols> codeLengthFreq{};
    for (size_t i = 0; i < code.itemCount; ++i) ++codeLengthFreq[code.items[i].symbol];
    useAtLeastTwoSymbols(codeLengthFreq);
    limitedCodeLengths(codeLengthFreq, kMaxCodeLengthBits, code.codeLength);
    code.codeLengthCount = kCodeLengthSymbols;
    while (code.codeLengthCount > 4 && code.codeLength[kCodeLengthOrder[code.codeLengthCount - 1]] == 0) {
      --code.codeLengthCount;
    }
    // Padding symbols (useAtLeastTwoSymbols) get codes but never occur: count only what is sent.
    uint64_t dynamicBits = 3 + 5 + 5 + 4 + 3 * code.codeLengthCount + extraBits;
    for (size_t i = 0; i < code.itemCount; ++i) {
      const uint32_t symbol = code.items[i].symbol;
      dynamicBits += code.codeLength[symbol] + kCodeLengthExtraBits[symbol];
    }
    for (uint32_t s = 0; s < kLitLenSymbols; ++s) dynamicBits += uint64_t{litLenFreq[s]} * code.litLen[s];
    dynamicBits += runs * code.distance[0] + rowCopies * code.distance[rowIndex];
    if (dynamicBits < fixedBits) {
      code.dynamic = true;
      code.bits = dynamicBits;
      return;
    }
  }
  for (uint32_t s = 0; s < kFixedLitLenSymbols; ++s)
    code.litLen[s] = s < 144 ? 8 : s < 256 ? 9 : s < 280 ? 7 : 8;
  code.distance.fill(5);
}
// Writes the block planned by planBlock (BFINAL set) for `tokens` at the start of `out`, which has room
// for code.bits plus 8 bytes of slack; returns its size in bytes. rowIndex as for planBlock, rowDistance
// the distance it stands for.
size_t writeBlock(const BlockCode& code, std::span<const uint16_t> tokens, uint32_t rowIndex,
                  uint32_t rowDistance, uint8_t* out) {
  BitWriter w(out);
  std::array<uint32_t, kFixedLitLenSymbols> litLenCodes;
  std::array<uint32_t, kFixedDistanceSymbols> distanceCodes;
  canonicalCodes(code.litLen, litLenCodes);
  canonicalCodes(code.distance, distanceCodes);
  if (code.dynamic) {
    w.put(0b101, 3);  // BFINAL = 1, BTYPE = 10 (dynamic Huffman)
    w.put(code.litLenCount - 257, 5);
    w.put(code.distanceCount - 1, 5);
    w.put(code.codeLengthCount - 4, 4);
    for (uint32_t i = 0; i < code.codeLengthCount; ++i) w.put(code.codeLength[kCodeLengthOrder[i]], 3);
    std::array<uint32_t, kCodeLengthSymbols> codeLengthCodes;
    canonicalCodes(code.codeLength, codeLengthCodes);
    for (size_t i = 0; i < code.itemCount; ++i) {
      const CodeLengthItem item = code.items[i];
      w.put(codeLengthCodes[item.symbol], code.codeLength[item.symbol]);
      w.put(item.extra, kCodeLengthExtraBits[item.symbol]);
    }
  } else {
    w.put(0b011, 3);  // BFINAL = 1, BTYPE = 01 (fixed Huffman)
  }
  // Every token as one put: literal code, or length code + extra bits + distance code + extra bits
  // (at most 15 + 5 + 15 + 13 = 48 bits).
  std::array<TokenCode, kTokenKinds> table;
  for (uint32_t v = 0; v < 256; ++v) table[v] = {litLenCodes[v], code.litLen[v]};
  const TokenCode run = {distanceCodes[0], code.distance[0]};
  const TokenCode row = {
      distanceCodes[rowIndex] | uint64_t{rowDistance - kDistanceBase[rowIndex]} << code.distance[rowIndex],
      code.distance[rowIndex] + kDistanceExtra[rowIndex]};
  for (uint32_t len = 3; len <= kMaxMatch; ++len) {
    const uint32_t index = kLengthIndex[len], symbol = 257 + index;
    const TokenCode length = {litLenCodes[symbol] | uint64_t{len - kLengthBase[index]} << code.litLen[symbol],
                              code.litLen[symbol] + kLengthExtra[index]};
    table[kRunMatch + len - 3] = {length.bits | run.bits << length.count, length.count + run.count};
    table[kRowMatch + len - 3] = {length.bits | row.bits << length.count, length.count + row.count};
  }
  for (const uint16_t t : tokens) w.put(table[t].bits, table[t].count);
  w.put(litLenCodes[kEndOfBlock], code.litLen[kEndOfBlock]);
  const size_t bytes = w.finish();
  assert(bytes == (code.bits + 7) / 8);
  return bytes;
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
      : dir_(path, overwrite, ".png"), job_(job) {}

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
      encodeMaskPng(mask, scratch_, pngScratch_);
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
  MaskPngScratch pngScratch_;
  uint32_t next_ = 0;
};

}  // namespace

// -----------------------------------------------------------------------------------------------------

void encodeMaskPng(const MaskImage& mask, std::vector<uint8_t>& out, MaskPngScratch& scratch,
                   MaskPngCode code) {
  const size_t width = mask.width, height = mask.height;
  assert(width >= 1 && height >= 1 && mask.pixels.size() == width * height);
  const uint64_t n = width + 1;  // filtered row: filter byte 0, then the pixels
  // Token counts are 32-bit, and so is an IDAT chunk's length.
  if (n * height > 0xFFFFFFFFu) throw OutputError("mask image too large for one PNG IDAT chunk");

  // Pass 1: the filtered rows as tokens, and the Adler-32 of the bytes they stand for.
  TokenStream tokens(scratch.tokens);
  const bool rowCopies = width >= 2 && n <= kMaxDistance;
  const auto rowDistance = static_cast<uint32_t>(rowCopies ? n : 1);
  uint64_t adlerA = 1, adlerB = 0;
  RowSums sums;
  int last = -1;         // last byte of the stream so far, -1 before the first
  uint64_t pending = 0;  // bytes equal to `last` at the end of the stream, not yet sent as tokens
  // Runs go out when the next value differs, so a run carries on across the end of a row (a stack of
  // dark rows is one run) and never ends on a short remainder just because the row did.
  auto flush = [&] {
    for (uint32_t left = putCopies(tokens, pending, kRunMatch); left > 0; --left) tokens.push(last);
    pending = 0;
  };
  const uint8_t* previous = nullptr;
  bool previousDark = false;  // the row above is all zeros
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
      if (p >= litEnd) return v == 0 ? width : p;   // dark to the end
      if (v == 0 && p < litBegin) return litBegin;  // dark up to the first lit pixel
      const size_t e = runEnd(row, p, litEnd, v);
      return e == litEnd && v == 0 ? width : e;
    };
    // A dark row is one run of zeros that continues the zeros before it: run matches cost the same
    // number of tokens as row copies, without the row distance's extra bits, so only lit rows are copied.
    if (rowCopies && sameAsPrevious && !previousDark) {
      flush();
      const uint32_t left = putCopies(tokens, n, kRowMatch);
      assert(left == 0);
      (void)left;
    } else {
      sums = RowSums{};
      // The filter byte 0 joins a run of zeros at the start of the row.
      size_t p = sameAsPrevious && previousDark ? width : runFrom(0, 0);
      previousDark = p == width;
      uint32_t length = static_cast<uint32_t>(p) + 1;
      uint8_t value = 0;
      uint64_t offset = 0;  // of the run in the filtered row
      for (;;) {
        sums.addRun(n, offset, length, value);
        if (last == value) {
          pending += length;
        } else {
          flush();
          tokens.push(value);
          last = value;
          pending = length - 1;
        }
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
  flush();

  // Pass 2: the code, then the file around the block.
  const uint32_t rowIndex = distanceIndex(rowDistance);
  BlockCode block;
  planBlock(tokens.counts(), rowIndex, code, block);

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
  const uint64_t blockBytes = (block.bits + 7) / 8;
  const uint64_t dataSize = 2 + blockBytes + 4;
  if (dataSize > 0x7FFFFFFFu) throw OutputError("mask image too large for one PNG IDAT chunk");
  out.resize(idat + 8 + dataSize + 8);  // + 8: slack for the bit writer, then the CRC
  putBigEndian32(&out[idat], static_cast<uint32_t>(dataSize));
  std::memcpy(&out[idat + 4], "IDAT", 4);
  out[idat + 8] = 0x78;  // CMF: deflate, 32 KiB window
  out[idat + 9] = 0x01;  // FLG: no dictionary, check bits ((0x78 << 8) | 0x01) % 31 == 0
  const size_t written = writeBlock(block, tokens.tokens(), rowIndex, rowDistance, &out[idat + 10]);
  assert(written == blockBytes);
  (void)written;
  size_t end = idat + 10 + blockBytes;
  putBigEndian32(&out[end], static_cast<uint32_t>((adlerB << 16) | adlerA));
  end += 4;
  putBigEndian32(&out[end], static_cast<uint32_t>(crc32_z(0, &out[idat + 4], 4 + dataSize)));
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

}  // namespace toposlice
