// Deflate for run-structured streams (RFC 1951; zlib's Adler-32, RFC 1950): tokens, then one block that
// codes them with a dynamic Huffman code (3.2.7) or, when that is not smaller, the fixed code (3.2.6).
#include "io/coders/deflate_runs.h"

#include <algorithm>
#include <bit>
#include <cassert>
#include <cstring>
#include <span>

namespace toposlice {
namespace {

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
// (3..258) at distance 1 (a run); kRowMatch + (L - 3) one at the copy distance (e.g. the row above).
constexpr uint32_t kRunMatch = 256;
constexpr uint32_t kRowMatch = kRunMatch + kMaxMatch - 2;
constexpr uint32_t kTokenKinds = kRowMatch + kMaxMatch - 2;
// A long run or copy is mostly matches of 258 bytes: kRepeatRun + (q - 1) stands for q of them at
// distance 1, kRepeatRow + (q - 1) for q at the copy distance (q <= kMaxRepeat), so that pushing and
// writing them costs one token, not one per 258 bytes.
constexpr uint32_t kRepeatRun = kTokenKinds;
constexpr uint32_t kMaxRepeat = 32000;
constexpr uint32_t kRepeatRow = kRepeatRun + kMaxRepeat;
static_assert(kRepeatRow + kMaxRepeat - 1 <= 0xFFFF, "tokens are 16-bit");

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

struct BlockTables {
  std::array<uint32_t, kFixedLitLenSymbols> litLenCodes;
  std::array<uint32_t, kCodeLengthSymbols> codeLengthCodes;
  std::array<TokenCode, kTokenKinds> tokens;
};

// Picks the smaller of the dynamic code built from the token counts and the fixed code (the fixed one
// on a tie, or always when `choice` says so). rowIndex: distance symbol of the kRowMatch tokens.
// `blocks` blocks share the code (each with its own header and end of block): the choice weighs the
// header once per block.
void planBlock(const std::array<uint32_t, kTokenKinds>& counts, uint32_t rowIndex, DeflateCode choice,
               BlockCode& code, uint32_t blocks = 1) {
  std::array<uint32_t, kLitLenSymbols> litLenFreq{};
  std::array<uint32_t, kDistanceSymbols> distanceFreq{};
  uint64_t extraBits = 0;  // length and distance extra bits: the same under either code
  for (uint32_t v = 0; v < 256; ++v) litLenFreq[v] = counts[v];
  litLenFreq[kEndOfBlock] = blocks;
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

  uint64_t fixedBits = 3 * uint64_t{blocks} + extraBits + (runs + rowCopies) * 5;
  for (uint32_t s = 0; s < kLitLenSymbols; ++s) {
    fixedBits += uint64_t{litLenFreq[s]} * (s < 144 ? 8 : s < 256 ? 9 : s < 280 ? 7 : 8);
  }

  code.dynamic = false;
  code.bits = fixedBits;
  if (choice == DeflateCode::smallest) {
    // Both codes get two symbols at least (a stream's first literal and the end of block are two
    // literal/length symbols already; HDIST counts one distance code even when no match occurs).
    useAtLeastTwoSymbols(litLenFreq);
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
    uint64_t headerBits = 3 + 5 + 5 + 4 + 3 * code.codeLengthCount;
    for (size_t i = 0; i < code.itemCount; ++i) {
      const uint32_t symbol = code.items[i].symbol;
      headerBits += code.codeLength[symbol] + kCodeLengthExtraBits[symbol];
    }
    uint64_t dynamicBits = blocks * headerBits + extraBits;
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
// The canonical codes of a planned block and the bits of every token under them.
void prepareTables(const BlockCode& code, uint32_t rowIndex, uint32_t rowDistance, BlockTables& t) {
  std::array<uint32_t, kFixedLitLenSymbols>& litLenCodes = t.litLenCodes;
  std::array<uint32_t, kFixedDistanceSymbols> distanceCodes;
  canonicalCodes(code.litLen, litLenCodes);
  canonicalCodes(code.distance, distanceCodes);
  canonicalCodes(code.codeLength, t.codeLengthCodes);
  // Every token as one put: literal code, or length code + extra bits + distance code + extra bits
  // (at most 15 + 5 + 15 + 13 = 48 bits).
  std::array<TokenCode, kTokenKinds>& table = t.tokens;
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
}

// Writes one final block of `tokens` with the planned code at the start of `out`, which has room for
// it plus 8 bytes of slack; returns its size in bytes.
size_t writeCodedBlock(const BlockCode& code, const BlockTables& tables, std::span<const uint16_t> tokens,
                       uint8_t* out) {
  BitWriter w(out);
  if (code.dynamic) {
    w.put(0b101, 3);  // BFINAL = 1, BTYPE = 10 (dynamic Huffman)
    w.put(code.litLenCount - 257, 5);
    w.put(code.distanceCount - 1, 5);
    w.put(code.codeLengthCount - 4, 4);
    for (uint32_t i = 0; i < code.codeLengthCount; ++i) w.put(code.codeLength[kCodeLengthOrder[i]], 3);
    const auto& codeLengthCodes = tables.codeLengthCodes;
    for (size_t i = 0; i < code.itemCount; ++i) {
      const CodeLengthItem item = code.items[i];
      w.put(codeLengthCodes[item.symbol], code.codeLength[item.symbol]);
      w.put(item.extra, kCodeLengthExtraBits[item.symbol]);
    }
  } else {
    w.put(0b011, 3);  // BFINAL = 1, BTYPE = 01 (fixed Huffman)
  }
  for (const uint16_t t : tokens) {
    if (t < kTokenKinds) [[likely]] {
      w.put(tables.tokens[t].bits, tables.tokens[t].count);
      continue;
    }
    // q matches of 258 bytes: as many codes per put as fit in 56 bits.
    const bool row = t >= kRepeatRow;
    uint32_t q = t - (row ? kRepeatRow : kRepeatRun) + 1;
    const TokenCode one = tables.tokens[(row ? kRowMatch : kRunMatch) + kMaxMatch - 3];
    const uint32_t perPut = 56 / one.count;
    uint64_t bits = 0;
    for (uint32_t i = 0; i < std::min(perPut, q); ++i) bits |= one.bits << (i * one.count);
    for (; q >= perPut; q -= perPut) w.put(bits, perPut * one.count);
    if (q > 0) w.put(bits & ((uint64_t{1} << (q * one.count)) - 1), q * one.count);
  }
  w.put(tables.litLenCodes[kEndOfBlock], code.litLen[kEndOfBlock]);
  return w.finish();
}

}  // namespace

// The code shared by a deflater's streams, planned at the first write.
struct RunDeflater::Plan {
  BlockCode code;
  BlockTables tables;
};

RunDeflater::RunDeflater(DeflateScratch& scratch, uint32_t copyDistance)
    : tokens_(scratch.tokens), copyDistance_(copyDistance) {
  assert(copyDistance >= 1 && copyDistance <= kMaxDistance);
}

RunDeflater::~RunDeflater() = default;

void RunDeflater::grow(size_t more) {
  tokens_.resize(std::max({size_t{4096}, 2 * tokens_.size(), size_ + more}));
}

// q matches of 258 bytes of `kind` (kRunMatch, kRowMatch), as repeat tokens.
void RunDeflater::pushLongest(uint64_t q, uint32_t kind) {
  const uint32_t longest = kind + kMaxMatch - 3;
  const uint32_t repeat = kind == kRunMatch ? kRepeatRun : kRepeatRow;
  while (q > 0) {
    const auto take = static_cast<uint32_t>(std::min<uint64_t>(q, kMaxRepeat));
    if (take == 1) {
      push(longest);
    } else {
      append(repeat + take - 1);
      counts_[longest] += take;
      expanded_ += take;
    }
    q -= take;
  }
}

// `n` bytes that repeat the stream at the distance of `kind` (kRunMatch, kRowMatch), as matches of at
// most 258 bytes; a remainder of 1 or 2 bytes (only when n < 3 to begin with) goes out as literals of
// the last byte (only runs have one).
void RunDeflater::putMatches(uint64_t n, uint32_t kind) {
  // All but the last one or two matches are of 258 bytes.
  uint64_t longest = n / kMaxMatch;
  if (longest > 0 && (n % kMaxMatch == 1 || n % kMaxMatch == 2)) --longest;
  pushLongest(longest, kind);
  n -= longest * kMaxMatch;
  while (n >= 3) {
    uint64_t take = std::min<uint64_t>(n, kMaxMatch);
    if (n - take == 1 || n - take == 2) take = n - 3;  // leave a remainder a match can still take
    push(kind + static_cast<uint32_t>(take) - 3);
    n -= take;
  }
  assert(n == 0 || kind == kRunMatch);
  for (; n > 0; --n) push(static_cast<uint32_t>(last_));
}

// Runs go out when the next value differs, so a run carries on across calls (and rows) and never ends
// on a short remainder just because a row did.
void RunDeflater::flush() {
  if (pending_ == 0) return;  // most anti-aliased edge pixels: a literal after a literal
  putMatches(pending_, kRunMatch);
  pending_ = 0;
}

void RunDeflater::putByteString(const uint8_t* bytes, size_t count) {
  size_t i = 0;
  while (i < count) {
    const uint8_t v = bytes[i];
    if (v == last_) {  // a run goes on
      const size_t e = runEnd(bytes, i + 1, count, v);
      pending_ += e - i;
      i = e;
      continue;
    }
    if (pending_ != 0) flush();
    // Literals up to the first byte that repeats the one before it (no run pending among them).
    if (size_ + (count - i) > tokens_.size()) grow(count - i);
    uint16_t* const out = tokens_.data() + size_;
    size_t k = 0;
    uint8_t last = v;
    for (;;) {
      out[k++] = last;
      ++counts_[last];
      if (++i == count || bytes[i] == last) break;
      last = bytes[i];
    }
    size_ += k;
    expanded_ += k;
    last_ = last;
  }
}

void RunDeflater::putCopy(uint64_t count, uint8_t lastByte) {
  assert(count >= 3 && copyDistance_ > 1);
  flush();
  putMatches(count, kRowMatch);
  last_ = lastByte;
}

size_t RunDeflater::endStream() {
  flush();
  last_ = -1;
  streamEnds_.push_back(size_);
  streamMatches_.push_back(expanded_);
  return streamEnds_.size() - 1;
}

size_t RunDeflater::streamBound(size_t stream) const {
  const uint64_t begin = stream == 0 ? 0 : streamMatches_[stream - 1];
  // Dynamic header: 17 bits, 19 x 3 bits, at most 316 code-length items of 7 + 7 bits. Literals and
  // matches: at most 15 + 5 + 15 + 13 bits each.
  return (17 + 57 + 316 * 14 + (streamMatches_[stream] - begin + 1) * 48 + 7) / 8 + 8;
}

size_t RunDeflater::writeStream(size_t stream, std::vector<uint8_t>& out, size_t at, DeflateCode code) {
  assert(stream < streamEnds_.size());
  if (!plan_) {
    plan_ = std::make_unique<Plan>();
    const uint32_t rowIndex = distanceIndex(copyDistance_);
    planBlock(counts_, rowIndex, code, plan_->code, static_cast<uint32_t>(streamEnds_.size()));
    prepareTables(plan_->code, rowIndex, copyDistance_, plan_->tables);
  }
  // One stream: its planned size is exact (plus the coder's 8 bytes of slack), so `out` is not grown and
  // zero-filled to the worst case, about 5x larger, for every image.
  const size_t room =
      streamEnds_.size() == 1 ? static_cast<size_t>((plan_->code.bits + 7) / 8) + 8 : streamBound(stream);
  out.resize(at + room);
  const size_t begin = stream == 0 ? 0 : streamEnds_[stream - 1];
  return writeCodedBlock(plan_->code, plan_->tables, {tokens_.data() + begin, streamEnds_[stream] - begin},
                         out.data() + at);
}

size_t RunDeflater::writeBlock(std::vector<uint8_t>& out, size_t at, DeflateCode code) {
  const size_t stream = endStream();
  assert(stream == 0);
  const size_t bytes = writeStream(stream, out, at, code);
  assert(bytes == (plan_->code.bits + 7) / 8);
  return bytes;
}

namespace {
constexpr uint64_t kAdlerModulus = 65521;
}  // namespace

// A and B are reduced lazily: while A < 2^33 and a run is shorter than 2^24, count A + v count
// (count + 1) / 2 stays below 2^58, so B only needs reducing past 2^61.
void RunAdler32::add(uint8_t value, uint64_t count) {
  constexpr uint64_t kPiece = uint64_t{1} << 23;
  for (; count > kPiece; count -= kPiece) add(value, kPiece);
  b_ += count * a_ + value * (count * (count + 1) / 2);
  a_ += value * count;
  if (a_ >= (uint64_t{1} << 32)) a_ %= kAdlerModulus;
  if (b_ >= (uint64_t{1} << 61)) b_ %= kAdlerModulus;
}

void RunAdler32::addRun(uint8_t first, uint8_t rest, uint64_t count) {
  constexpr uint64_t kPiece = uint64_t{1} << 23;
  if (count > kPiece) {  // the lazy reduction's bounds hold for runs shorter than 2^24
    add(first, 1);
    add(rest, count - 1);
    return;
  }
  // A += first, B += A; then count - 1 bytes of rest (as add), with one reduction check.
  a_ += first;
  b_ += a_;
  const uint64_t m = count - 1;
  b_ += m * a_ + rest * (m * (m + 1) / 2);
  a_ += rest * m;
  if (a_ >= (uint64_t{1} << 32)) a_ %= kAdlerModulus;
  if (b_ >= (uint64_t{1} << 61)) b_ %= kAdlerModulus;
}

uint32_t RunAdler32::value() const {
  return static_cast<uint32_t>((b_ % kAdlerModulus) << 16 | (a_ % kAdlerModulus));
}

size_t runEnd(const uint8_t* row, size_t p, size_t end, uint8_t v) {
  const uint64_t pattern = 0x0101010101010101ull * v;
  while (p + 8 <= end) {
    uint64_t word;
    std::memcpy(&word, row + p, 8);
    word ^= pattern;
    if (word != 0) {
      if constexpr (std::endian::native == std::endian::little) return p + std::countr_zero(word) / 8;
      return p + std::countl_zero(word) / 8;
    }
    p += 8;
  }
  while (p < end && row[p] == v) ++p;
  return p;
}

}  // namespace toposlice
