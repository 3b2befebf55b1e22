#include "io/readers/parallel_gunzip.h"

#include <libdeflate.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <bit>
#include <cstdint>
#include <cstring>
#include <deque>
#include <memory>
#include <vector>

#include "core/memory_advice.h"

namespace toposlice {
namespace {

// Deflate (RFC 1951) as zlib reads it. Where zlib and libdeflate differ on a malformed stream this
// decoder refuses it (the serial read then decides), so it never accepts what the serial read refuses.

constexpr std::size_t kWindow = 32768;
constexpr uint16_t kMarker = 256;        // a symbol kMarker + i stands for byte i of the window before a part
constexpr std::size_t kRoom = 258 + 16;  // output room before a symbol: the longest match and copy overrun

// ---- Huffman decode tables ----
// An entry: bits 0-7 the bits it takes (the code's and its extra bits), 8-11 the code's length (for a
// subtable pointer, the subtable's index bits), 12-14 its kind, 16-31 the value (a byte, a base length or
// distance, a subtable's start). A symbol's bits and its extra bits are dropped in one shift.
enum Kind : uint32_t { kLiteral = 0, kBase = 1, kEnd = 2, kSubtable = 3, kInvalid = 4 };
constexpr uint32_t makeEntry(uint32_t kind, uint32_t value = 0, uint32_t extra = 0) {
  return value << 16 | kind << 12 | extra;
}
inline uint32_t kindOf(uint32_t e) {
  return (e >> 12) & 7;
}
inline unsigned takenBits(uint32_t e) {
  return e & 0xFF;
}
inline unsigned codeBits(uint32_t e) {
  return (e >> 8) & 15;
}
inline unsigned valueOf(uint32_t e) {
  return e >> 16;
}
// The extra bits of entry e, from the bits as they were before e was decoded.
inline uint32_t extraValue(uint64_t before, uint32_t e) {
  return static_cast<uint32_t>((before & ((uint64_t{1} << takenBits(e)) - 1)) >> codeBits(e));
}

constexpr unsigned kLitRoot = 11, kDistRoot = 8, kPreRoot = 7;
constexpr std::size_t kLitTable = (1 << kLitRoot) + 288 * (1 << (15 - kLitRoot));
constexpr std::size_t kDistTable = (1 << kDistRoot) + 32 * (1 << (15 - kDistRoot));

struct Payloads {
  std::array<uint32_t, 288> lit{};
  std::array<uint32_t, 32> dist{};
  std::array<uint32_t, 19> pre{};
  Payloads() {
    static constexpr uint16_t kLenBase[29] = {3,  4,  5,  6,  7,  8,  9,  10, 11,  13,  15,  17,  19,  23, 27,
                                              31, 35, 43, 51, 59, 67, 83, 99, 115, 131, 163, 195, 227, 258};
    static constexpr uint8_t kLenExtra[29] = {0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2,
                                              2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0};
    static constexpr uint16_t kDistBase[30] = {1,    2,    3,    4,    5,    7,    9,    13,    17,    25,
                                               33,   49,   65,   97,   129,  193,  257,  385,   513,   769,
                                               1025, 1537, 2049, 3073, 4097, 6145, 8193, 12289, 16385, 24577};
    for (uint32_t s = 0; s < 256; ++s) lit[s] = makeEntry(kLiteral, s);
    lit[256] = makeEntry(kEnd);
    for (uint32_t s = 0; s < 29; ++s) lit[257 + s] = makeEntry(kBase, kLenBase[s], kLenExtra[s]);
    lit[286] = lit[287] = makeEntry(kInvalid);  // in the fixed code only, and invalid there
    for (uint32_t s = 0; s < 30; ++s) dist[s] = makeEntry(kBase, kDistBase[s], s < 4 ? 0 : s / 2 - 1);
    dist[30] = dist[31] = makeEntry(kInvalid);
    for (uint32_t s = 0; s < 19; ++s) pre[s] = makeEntry(kLiteral, s);
  }
};
const Payloads& payloads() {
  static const Payloads p;
  return p;
}

// For each four 3-bit code lengths (12 bits), the sum of 2^(7-len) over the nonzero ones.
const std::array<uint16_t, 4096>& kraftOfFourLengths() {
  static const std::array<uint16_t, 4096> table = [] {
    std::array<uint16_t, 4096> t{};
    for (unsigned q = 0; q < 4096; ++q) {
      for (unsigned i = 0; i < 4; ++i) {
        const unsigned len = (q >> (3 * i)) & 7;
        t[q] = static_cast<uint16_t>(t[q] + (len > 0 ? 128u >> len : 0));
      }
    }
    return t;
  }();
  return table;
}

// Every byte with its bits in reverse order.
const std::array<uint8_t, 256>& reversedByte() {
  static const std::array<uint8_t, 256> table = [] {
    std::array<uint8_t, 256> t{};
    for (unsigned b = 0; b < 256; ++b)
      for (unsigned i = 0; i < 8; ++i) t[b] = static_cast<uint8_t>(t[b] | ((b >> i) & 1) << (7 - i));
    return t;
  }();
  return table;
}

// The decode table of the canonical code with `lengths` (0: symbol unused) into `table`. False for an
// over-subscribed code, and for an incomplete one unless `incompleteOk` and it has no code or a single
// one-bit code (zlib's rule; the code-length code must be complete).
bool buildTable(const uint8_t* lengths, unsigned n, const uint32_t* payload, unsigned root, uint32_t* table,
                bool incompleteOk) {
  unsigned count[16] = {};
  for (unsigned s = 0; s < n; ++s) ++count[lengths[s]];
  count[0] = 0;
  unsigned maxLen = 0;
  int left = 1;
  for (unsigned len = 1; len <= 15; ++len) {
    left = left * 2 - static_cast<int>(count[len]);
    if (left < 0) return false;
    if (count[len] > 0) maxLen = len;
  }
  if (left > 0 && !(incompleteOk && (maxLen == 0 || (maxLen == 1 && count[1] == 1)))) return false;
  unsigned next[16] = {};
  for (unsigned len = 1, code = 0; len <= 15; ++len) {
    code = (code + count[len - 1]) << 1;
    next[len] = code;
  }
  // A complete code writes every entry; only an incomplete one leaves some to mark invalid.
  const uint32_t invalid = makeEntry(kInvalid);
  const bool complete = left == 0;
  if (!complete) std::fill(table, table + (std::size_t{1} << root), invalid);
  const unsigned subBits = maxLen > root ? maxLen - root : 0;
  uint32_t nextSub = 1u << root;
  auto reversedCode = [&](unsigned len) {  // deflate sends a code's bits from its first on
    const uint32_t code = next[len]++;
    return (reversedByte()[code & 255] << 8 | reversedByte()[code >> 8]) >> (16 - len);
  };
  if (complete && maxLen > root) {  // the entries that will point to subtables may hold an old table's
    const std::array<unsigned, 16> first = std::to_array(next);
    for (unsigned s = 0; s < n; ++s)
      if (lengths[s] > root) table[reversedCode(lengths[s]) & ((1u << root) - 1)] = invalid;
    std::copy(first.begin(), first.end(), next);
  }
  for (unsigned s = 0; s < n; ++s) {
    const unsigned len = lengths[s];
    if (len == 0) continue;
    const uint32_t reversed = reversedCode(len);
    const uint32_t e = payload[s] + len + (len << 8);
    if (len <= root) {
      for (uint32_t i = reversed; i < (1u << root); i += 1u << len) table[i] = e;
      continue;
    }
    uint32_t& pointer = table[reversed & ((1u << root) - 1)];
    if (kindOf(pointer) != kSubtable) {
      pointer = makeEntry(kSubtable, nextSub) | subBits << 8;
      if (!complete) std::fill(table + nextSub, table + nextSub + (std::size_t{1} << subBits), invalid);
      nextSub += 1u << subBits;
    }
    for (uint32_t i = reversed >> root; i < (1u << subBits); i += 1u << (len - root))
      table[valueOf(pointer) + i] = e;
  }
  return true;
}

// ---- Bits ----
// Bits in from the least significant end, 56 or more after each refill (zeros past the end, counted).
class BitReader {
 public:
  explicit BitReader(std::span<const uint8_t> data) : data_(data) {}

  void seek(uint64_t bit) {
    pos_ = static_cast<std::size_t>(bit / 8);
    buffer_ = 0;
    avail_ = 0;
    refill();
    drop(static_cast<unsigned>(bit % 8));
  }
  uint64_t position() const { return uint64_t{pos_} * 8 - avail_; }
  bool overrun() const { return position() > uint64_t{data_.size()} * 8; }

  void refill() {
    if (pos_ + 8 <= data_.size()) {
      buffer_ |= load64(data_.data() + pos_) << avail_;
      pos_ += (63 - avail_) >> 3;
      avail_ |= 56;
      return;
    }
    while (avail_ <= 56) {
      const uint64_t byte = pos_ < data_.size() ? data_[pos_] : 0;
      buffer_ |= byte << avail_;
      ++pos_;
      avail_ += 8;
    }
  }
  uint64_t bits() const { return buffer_; }
  void drop(unsigned n) {
    buffer_ >>= n;
    avail_ -= n;
  }
  uint32_t take(unsigned n) {
    const auto v = static_cast<uint32_t>(buffer_ & ((uint64_t{1} << n) - 1));
    drop(n);
    return v;
  }
  // The data from bit `bit` on (a byte boundary).
  const uint8_t* bytesAt(uint64_t bit) const { return data_.data() + bit / 8; }
  std::size_t size() const { return data_.size(); }

  static uint64_t load64(const uint8_t* p) {
    uint64_t v;
    std::memcpy(&v, p, 8);
    if constexpr (std::endian::native == std::endian::big) v = __builtin_bswap64(v);
    return v;
  }

 private:
  std::span<const uint8_t> data_;
  std::size_t pos_ = 0;  // the next byte to load (past the end once zeros are loaded)
  uint64_t buffer_ = 0;
  unsigned avail_ = 0;
};

// Entry of the code that starts at the low end of `bits`.
template <unsigned kRoot>
inline uint32_t lookup(const uint32_t* table, uint64_t bits) {
  const uint32_t e = table[bits & ((1u << kRoot) - 1)];
  if (kindOf(e) != kSubtable) return e;
  return table[valueOf(e) + ((bits >> kRoot) & ((1u << codeBits(e)) - 1))];
}

// One code's symbol from the reader (refilled by the caller), its bits dropped (a code with no extra bits).
template <unsigned kRoot>
inline uint32_t decodeSymbol(const uint32_t* table, BitReader& r) {
  const uint32_t e = lookup<kRoot>(table, r.bits());
  r.drop(takenBits(e));
  return e;
}

// ---- Output ----
// A growable array that is not zero-filled; or a fixed one over memory it does not own.
template <class T>
struct Output {
  std::unique_ptr<T[]> owned;
  T* data = nullptr;
  std::size_t size = 0, capacity = 0;
  bool fixed = false;

  void reserve(std::size_t n) {
    auto grown = std::make_unique_for_overwrite<T[]>(n);
    adviseHugePages(grown.get(), n * sizeof(T));
    if (size > 0) std::memcpy(grown.get(), data, size * sizeof(T));
    owned = std::move(grown);
    data = owned.get();
    capacity = n;
  }
  // Room for one more symbol; false when a fixed output is full or `limit` elements would be passed.
  bool room(std::size_t limit) {
    if (capacity - size >= kRoom) return true;
    if (fixed || size > limit) return false;
    reserve(std::max<std::size_t>(capacity + capacity / 2, size + 4 * kRoom));
    return true;
  }
  // room() for a loop that holds the pointer, size and capacity in locals (codedBytes): they are
  // refreshed where the array grew.
  bool room(std::size_t limit, T*& localData, std::size_t localSize, std::size_t& localCapacity) {
    if (localCapacity - localSize >= kRoom) return true;
    size = localSize;
    if (!room(limit)) return false;
    localData = data;
    localCapacity = capacity;
    return true;
  }
};

// ---- One part ----
struct Part {
  uint64_t beginBit = 0, endBit = 0;
  bool decoded = false;      // from beginBit to endBit, every block valid
  bool final = false;        // its last block is the stream's last
  Output<uint16_t> symbols;  // with markers, until 32 KiB in a row were free of them
  Output<uint8_t> bytes;     // then bytes, the first `seed` of them repeating the end of `symbols`
  std::size_t seed = 0;
  std::size_t size() const { return symbols.size + bytes.size - seed; }
};

class Inflater {
 public:
  // `limit`: no part is longer (the stream's size); `sizeHint`: a part's likely length.
  Inflater(std::span<const uint8_t> data, std::size_t limit, std::size_t sizeHint)
      : reader_(data), limit_(limit), sizeHint_(sizeHint) {}

  // Decodes blocks from `beginBit` until one ends at or after `stopBit`, or the last block ends; false
  // for invalid data. With `knownStart` the part starts the stream (no window: plain bytes into
  // part.bytes); otherwise symbols with markers first.
  bool decode(Part& part, uint64_t beginBit, uint64_t stopBit, bool knownStart) {
    begin(part, beginBit, knownStart);
    Step step = Step::kMore;
    while (step == Step::kMore) step = next(part, stopBit);
    return step == Step::kDone;
  }

  // decode() a block at a time: begin(), then next() until it is done or invalid.
  enum class Step { kMore, kDone, kInvalid };
  void begin(Part& part, uint64_t beginBit, bool knownStart) {
    part.beginBit = beginBit;
    part.decoded = part.final = false;
    part.symbols.size = part.bytes.size = part.seed = 0;
    if (!knownStart && part.symbols.capacity == 0) part.symbols.reserve(std::min(limit_, sizeHint_));
    bytesMode_ = knownStart;
    lastMarkerEnd_ = 0;
    reader_.seek(beginBit);
  }
  Step next(Part& part, uint64_t stopBit) {
    if (!block(part)) return Step::kInvalid;
    if (!bytesMode_ && part.symbols.size - lastMarkerEnd_ >= kWindow) switchToBytes(part);
    if (!part.final && reader_.position() < stopBit) return Step::kMore;
    if (reader_.overrun()) return Step::kInvalid;
    part.endBit = reader_.position();
    part.decoded = true;
    return Step::kDone;
  }

  // A dynamic block header that parses at `bit` into valid tables (the start of a part, if its blocks
  // then decode). Cheap tests first: most positions fail on the header bits or the code-length code.
  bool plausibleStart(uint64_t bit) {
    const uint8_t* data = reader_.bytesAt(0);
    const std::size_t at = static_cast<std::size_t>(bit / 8);
    if (at + 24 > reader_.size()) return false;
    const uint64_t w = BitReader::load64(data + at) >> (bit % 8);  // 57 or more valid bits
    if (((w >> 1) & 3) != 2) return false;                         // BTYPE: dynamic
    if (((w >> 3) & 31) > 29 || ((w >> 8) & 31) > 29) return false;
    const unsigned hclen = static_cast<unsigned>((w >> 13) & 15) + 4;
    // Complete: the lengths' 2^-len sum to 1, in units of 2^-7; four 3-bit lengths per lookup.
    const uint64_t lengthsAt = bit + 17;
    uint64_t lengths = BitReader::load64(data + lengthsAt / 8) >> (lengthsAt % 8);  // 18 lengths at least
    lengths &= (uint64_t{1} << (3 * std::min(hclen, 18u))) - 1;
    const auto& quad = kraftOfFourLengths();
    unsigned kraft = 0;
    for (unsigned shift = 0; shift < 60; shift += 12) kraft += quad[(lengths >> shift) & 0xFFF];
    if (hclen == 19) {
      const uint64_t lastAt = lengthsAt + 54;
      const auto len = static_cast<unsigned>((BitReader::load64(data + lastAt / 8) >> (lastAt % 8)) & 7);
      kraft += len > 0 ? 128u >> len : 0;
    }
    if (kraft != 128) return false;
    reader_.seek(bit);
    reader_.refill();
    reader_.drop(3);
    return dynamicTables();
  }

 private:
  bool block(Part& part) {
    reader_.refill();
    part.final = reader_.take(1) != 0;
    switch (reader_.take(2)) {
      case 0:
        return stored(part);
      case 1:
        fixedTables();
        break;
      case 2:
        if (!dynamicTables()) return false;
        break;
      default:
        return false;
    }
    return bytesMode_ ? codedBytes(part.bytes) : codedSymbols(part.symbols);
  }

  bool stored(Part& part) {
    const uint64_t aligned = (reader_.position() + 7) / 8 * 8;
    if (aligned / 8 + 4 > reader_.size()) return false;
    const uint8_t* p = reader_.bytesAt(aligned);
    const unsigned len = p[0] | p[1] << 8, nlen = p[2] | p[3] << 8;
    if ((len ^ nlen) != 0xFFFF || aligned / 8 + 4 + len > reader_.size()) return false;
    for (unsigned i = 0; i < len; ++i) {
      if (bytesMode_) {
        if (!part.bytes.room(limit_)) return false;
        part.bytes.data[part.bytes.size++] = p[4 + i];
      } else {
        if (!part.symbols.room(limit_)) return false;
        part.symbols.data[part.symbols.size++] = p[4 + i];
      }
    }
    reader_.seek(aligned + 8 * (4 + uint64_t{len}));
    return true;
  }

  void fixedTables() {
    if (fixedBuilt_) {
      lit_ = fixedLit_.data();
      dist_ = fixedDist_.data();
      return;
    }
    uint8_t lens[288 + 32];
    std::fill(lens, lens + 144, 8);
    std::fill(lens + 144, lens + 256, 9);
    std::fill(lens + 256, lens + 280, 7);
    std::fill(lens + 280, lens + 288, 8);
    std::fill(lens + 288, lens + 320, 5);
    buildTable(lens, 288, payloads().lit.data(), kLitRoot, fixedLit_.data(), false);
    buildTable(lens + 288, 32, payloads().dist.data(), kDistRoot, fixedDist_.data(), false);
    fixedBuilt_ = true;
    fixedTables();
  }

  bool dynamicTables() {
    static constexpr uint8_t kOrder[19] = {16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15};
    reader_.refill();
    const unsigned nlit = reader_.take(5) + 257, ndist = reader_.take(5) + 1, nclen = reader_.take(4) + 4;
    if (nlit > 286 || ndist > 30) return false;
    uint8_t clens[19] = {};
    for (unsigned i = 0; i < nclen; ++i) {
      reader_.refill();
      clens[kOrder[i]] = static_cast<uint8_t>(reader_.take(3));
    }
    if (!buildTable(clens, 19, payloads().pre.data(), kPreRoot, pre_.data(), false)) return false;
    uint8_t lens[286 + 30] = {};
    for (unsigned i = 0; i < nlit + ndist;) {
      reader_.refill();
      const uint32_t e = decodeSymbol<kPreRoot>(pre_.data(), reader_);
      if (kindOf(e) != kLiteral) return false;
      const unsigned sym = valueOf(e);
      if (sym < 16) {
        lens[i++] = static_cast<uint8_t>(sym);
        continue;
      }
      unsigned repeat;
      uint8_t value = 0;
      if (sym == 16) {
        if (i == 0) return false;
        value = lens[i - 1];
        repeat = 3 + reader_.take(2);
      } else {
        repeat = sym == 17 ? 3 + reader_.take(3) : 11 + reader_.take(7);
      }
      if (i + repeat > nlit + ndist) return false;
      std::fill(lens + i, lens + i + repeat, value);
      i += repeat;
    }
    if (reader_.overrun() || lens[256] == 0) return false;
    if (!buildTable(lens, nlit, payloads().lit.data(), kLitRoot, litDynamic_.data(), true)) return false;
    if (!buildTable(lens + nlit, ndist, payloads().dist.data(), kDistRoot, distDynamic_.data(), true))
      return false;
    lit_ = litDynamic_.data();
    dist_ = distDynamic_.data();
    return true;
  }

  // The distance of a match (the reader holding 28 bits or more); zero for an invalid distance code.
  static uint32_t matchDistance(BitReader& r, const uint32_t* dist) {
    const uint64_t before = r.bits();
    const uint32_t d = lookup<kDistRoot>(dist, before);
    r.drop(takenBits(d));
    return kindOf(d) == kBase ? valueOf(d) + extraValue(before, d) : 0;
  }

  // The block's coded data into bytes whose window is complete (everything before is in `out`). The
  // reader, tables and output live in locals here: byte stores may alias any member, which would keep
  // the compiler from holding them in registers.
  bool codedBytes(Output<uint8_t>& out) {
    BitReader r = reader_;
    const uint32_t* const lit = lit_;
    const uint32_t* const dist = dist_;
    uint8_t* data = out.data;
    std::size_t size = out.size, capacity = out.capacity;
    bool ok = false;
    for (;;) {
      if (!out.room(limit_, data, size, capacity)) break;
      r.refill();
      uint64_t before = r.bits();
      uint32_t e = lookup<kLitRoot>(lit, before);
      r.drop(takenBits(e));
      if (kindOf(e) == kLiteral) {
        data[size++] = static_cast<uint8_t>(valueOf(e));
        before = r.bits();  // 41 bits or more: a second symbol and its extra bits fit
        e = lookup<kLitRoot>(lit, before);
        r.drop(takenBits(e));
        if (kindOf(e) == kLiteral) {
          data[size++] = static_cast<uint8_t>(valueOf(e));
          continue;
        }
        r.refill();
      }
      if (kindOf(e) != kBase) {
        ok = kindOf(e) == kEnd && !r.overrun();
        break;
      }
      const unsigned length = valueOf(e) + extraValue(before, e);
      const uint32_t distance = matchDistance(r, dist);
      if (distance == 0 || distance > size) break;
      uint8_t* to = data + size;
      const uint8_t* from = to - distance;
      if (distance >= 8) {
        uint8_t* const end = to + length;
        do {
          std::memcpy(to, from, 8);
          to += 8;
          from += 8;
        } while (to < end);
      } else if (distance == 1) {
        std::memset(to, *from, length);
      } else {
        for (unsigned i = 0; i < length; ++i) to[i] = from[i];
      }
      size += length;
      if (r.overrun()) break;
    }
    out.size = size;
    reader_ = r;
    return ok;
  }

  // The block's coded data into symbols, before the window is known: a copy from before the part's first
  // byte gives markers, and copies of markers are markers.
  bool codedSymbols(Output<uint16_t>& out) {
    BitReader r = reader_;
    const uint32_t* const lit = lit_;
    const uint32_t* const dist = dist_;
    uint16_t* data = out.data;
    std::size_t size = out.size, capacity = out.capacity, lastMarkerEnd = lastMarkerEnd_;
    bool ok = false;
    for (;;) {
      if (!out.room(limit_, data, size, capacity)) break;
      r.refill();
      const uint64_t before = r.bits();
      const uint32_t e = lookup<kLitRoot>(lit, before);
      r.drop(takenBits(e));
      if (kindOf(e) == kLiteral) {
        data[size++] = static_cast<uint16_t>(valueOf(e));
        continue;
      }
      if (kindOf(e) != kBase) {
        ok = kindOf(e) == kEnd && !r.overrun();
        break;
      }
      const unsigned length = valueOf(e) + extraValue(before, e);
      const uint32_t distance = matchDistance(r, dist);
      if (distance == 0 || distance > size + kWindow) break;
      uint16_t* const to = data + size;
      uint16_t seen = 0;
      if (distance > size) {
        const std::size_t back = distance - size;  // into the window, at kWindow - back
        for (unsigned i = 0; i < length; ++i) {
          to[i] = i < back ? static_cast<uint16_t>(kMarker + kWindow - back + i) : data[i - back];
          seen |= to[i];
        }
      } else {
        const uint16_t* from = to - distance;
        for (unsigned i = 0; i < length; ++i) {
          to[i] = from[i];
          seen |= to[i];
        }
      }
      size += length;
      if (seen >= kMarker) lastMarkerEnd = size;
      if (r.overrun()) break;
    }
    out.size = size;
    lastMarkerEnd_ = lastMarkerEnd;
    reader_ = r;
    return ok;
  }

  // The last 32 KiB of symbols hold no marker: the rest of the part is plain bytes after a copy of them.
  void switchToBytes(Part& part) {
    const std::size_t seed = std::min(part.symbols.size, kWindow);
    if (part.bytes.capacity < 2 * seed + kRoom)
      part.bytes.reserve(std::min(limit_ + kRoom, std::max(2 * seed + kRoom, sizeHint_ + sizeHint_ / 4)));
    for (std::size_t i = 0; i < seed; ++i)
      part.bytes.data[i] = static_cast<uint8_t>(part.symbols.data[part.symbols.size - seed + i]);
    part.bytes.size = part.seed = seed;
    bytesMode_ = true;
  }

  BitReader reader_;
  std::size_t limit_, sizeHint_;
  bool bytesMode_ = false;
  std::size_t lastMarkerEnd_ = 0;  // symbols up to here may hold markers
  const uint32_t* lit_ = nullptr;
  const uint32_t* dist_ = nullptr;
  bool fixedBuilt_ = false;
  std::array<uint32_t, kLitTable> litDynamic_{}, fixedLit_{};
  std::array<uint32_t, kDistTable> distDynamic_{}, fixedDist_{};
  std::array<uint32_t, 1 << kPreRoot> pre_{};
};

// Symbols with markers as bytes into `out`, given the bytes before the part (`window`: its last 32 KiB,
// or all of them when the stream had fewer); false for a marker before the stream's start.
bool resolveSymbols(std::span<const uint16_t> symbols, std::span<const std::byte> window, std::byte* out) {
  const std::size_t missing = kWindow - window.size();  // window bytes before the stream's start
  for (std::size_t i = 0; i < symbols.size(); ++i) {
    const uint16_t s = symbols[i];
    if (s < kMarker) {
      out[i] = static_cast<std::byte>(s);
    } else {
      const std::size_t index = std::size_t{s} - kMarker;  // in the 32 KiB before the part
      if (index < missing) return false;
      out[i] = window[index - missing];
    }
  }
  return true;
}

// Starts `part` at the first position in [from, to) whose block decodes (no window known) and decodes
// that block: the outcome of that first block, or kInvalid when there is none -- after kTrials headers
// whose block did not decode it gives up too (a stream made to look like many headers). Past damage in a
// later block no other start is tried: the caller sees it as kInvalid from next().
Inflater::Step startAtFirstBlock(Inflater& inflater, Part& part, uint64_t from, uint64_t to,
                                 uint64_t stopBit) {
  constexpr int kTrials = 64;
  int trials = 0;
  for (uint64_t bit = from; bit < to && trials < kTrials; ++bit) {
    if (!inflater.plausibleStart(bit)) continue;
    ++trials;
    inflater.begin(part, bit, false);
    const Inflater::Step step = inflater.next(part, stopBit);
    if (step != Inflater::Step::kInvalid) return step;
  }
  return Inflater::Step::kInvalid;
}

}  // namespace

bool gunzipParallel(std::span<const std::byte> inBytes, const ChunkRunner& runner, ByteBuffer& out,
                    std::size_t partBytes) {
  const std::span<const uint8_t> in(reinterpret_cast<const uint8_t*>(inBytes.data()), inBytes.size());
  const std::size_t headerLength = plainGzipHeaderLength(inBytes);
  if (headerLength == 0) return false;
  const std::size_t expected = gzipSizeHint(inBytes);
  const uint8_t* trailer = in.data() + in.size() - 8;
  const uint32_t crc = trailer[0] | trailer[1] << 8 | trailer[2] << 16 | uint32_t{trailer[3]} << 24;
  const uint32_t isize = trailer[4] | trailer[5] << 8 | trailer[6] << 16 | uint32_t{trailer[7]} << 24;
  if (expected == 0 || expected != isize) return false;
  const std::span<const uint8_t> data = in.subspan(headerLength, in.size() - 8 - headerLength);

  if (partBytes == 0) partBytes = std::max(data.size() / std::max(1u, runner.width), kGunzipMinPartBytes);
  const std::size_t parts = std::max<std::size_t>(1, data.size() / std::max<std::size_t>(partBytes, 1));
  auto offset = [&](std::size_t j) { return uint64_t{data.size()} * j / parts * 8; };  // in bits

  out.reserveExactly(expected + kRoom);
  std::vector<Part> decoded(parts);
  decoded[0].bytes.data = reinterpret_cast<uint8_t*>(out.data.get());
  decoded[0].bytes.capacity = expected + kRoom;
  decoded[0].bytes.fixed = true;
  runner.run(parts, 1, [&](std::size_t p0, std::size_t p1) {
    auto inflater = std::make_unique<Inflater>(data, expected, expected / parts + (expected / parts) / 8);
    for (std::size_t j = p0; j < p1; ++j) {
      const uint64_t stop = j + 1 < parts ? offset(j + 1) : UINT64_MAX;
      if (j == 0) {
        inflater->decode(decoded[0], 0, stop, true);
        continue;
      }
      Inflater::Step step = startAtFirstBlock(*inflater, decoded[j], offset(j), offset(j + 1), stop);
      while (step == Inflater::Step::kMore) step = inflater->next(decoded[j], stop);
    }
  });

  // The chain: the first part, then the part that starts where the one before it ended. Where none does
  // (its start was not found: a stored or fixed-code block there, or a false start taken), the stream is
  // decoded on from that end here, to the first block end past the next part's offset.
  std::vector<const Part*> chain{&decoded[0]};
  std::vector<std::size_t> at{0};
  std::deque<Part> bridges;
  std::unique_ptr<Inflater> bridger;
  for (;;) {
    const Part& last = *chain.back();
    if (!last.decoded || at.back() + last.size() > expected) return false;
    if (last.final) break;
    if (parts == 1) return false;
    std::size_t j = 1;  // the part whose offsets hold the end: its start must be there
    while (j + 1 < parts && offset(j + 1) <= last.endBit) ++j;
    const Part* next = &decoded[j];
    if (!(next->decoded && next->beginBit == last.endBit)) {
      if (!bridger) bridger = std::make_unique<Inflater>(data, expected, expected / parts);
      Part& bridge = bridges.emplace_back();
      const uint64_t stop = j + 1 < parts ? offset(j + 1) : UINT64_MAX;
      if (!bridger->decode(bridge, last.endBit, stop, false)) return false;
      next = &bridge;
    }
    at.push_back(at.back() + last.size());
    chain.push_back(next);
  }
  const Part& lastPart = *chain.back();
  // After the last block, the trailer follows at once (one member, nothing after it).
  if ((lastPart.endBit + 7) / 8 != data.size() || at.back() + lastPart.size() != expected) return false;

  // Bytes into place (the first part is there already), then markers resolved in stream order (a
  // window may lie in the part before's symbols), then the CRC-32 of every part.
  std::byte* const whole = out.data.get();
  runner.run(chain.size() - 1, 1, [&](std::size_t c0, std::size_t c1) {
    for (std::size_t c = c0 + 1; c < c1 + 1; ++c) {
      const Part& part = *chain[c];
      if (part.bytes.size > part.seed)  // else the part never became plain bytes
        std::memcpy(whole + at[c] + part.symbols.size, part.bytes.data + part.seed,
                    part.bytes.size - part.seed);
    }
  });
  // Part c's symbols [from, to) resolved into place; false for a marker before the stream's start.
  auto resolve = [&](std::size_t c, std::size_t from, std::size_t to) {
    const std::size_t before = std::min<std::size_t>(at[c], kWindow);
    return resolveSymbols(std::span<const uint16_t>(chain[c]->symbols.data + from, to - from),
                          {whole + at[c] - before, before}, whole + at[c] + from);
  };
  // The last 32 KiB of every part first, in stream order: they are the windows of the parts after them.
  // Then the rest of every part at once.
  auto tailBegin = [&](std::size_t c) {
    const Part& part = *chain[c];
    return std::min(part.symbols.size, part.size() - std::min(part.size(), kWindow));
  };
  for (std::size_t c = 1; c < chain.size(); ++c) {
    if (!resolve(c, tailBegin(c), chain[c]->symbols.size)) return false;
  }
  std::atomic<bool> resolved{true};
  runner.run(chain.size() - 1, 1, [&](std::size_t c0, std::size_t c1) {
    for (std::size_t c = c0 + 1; c < c1 + 1; ++c) {
      if (!resolve(c, 0, tailBegin(c))) resolved.store(false, std::memory_order_relaxed);
    }
  });
  if (!resolved.load()) return false;
  std::vector<uint32_t> crcs(chain.size());
  runner.run(chain.size(), 1, [&](std::size_t c0, std::size_t c1) {
    for (std::size_t c = c0; c < c1; ++c) crcs[c] = libdeflate_crc32(0, whole + at[c], chain[c]->size());
  });
  uint32_t total = 0;
  for (std::size_t c = 0; c < chain.size(); ++c)
    total = static_cast<uint32_t>(crc32_combine(total, crcs[c], static_cast<z_off_t>(chain[c]->size())));
  if (total != crc) return false;
  out.size = expected;
  return true;
}

}  // namespace toposlice
