#include "io/readers/stl_reader.h"

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <string_view>
#include <system_error>

#include "core/memory_advice.h"
#include "io/errors.h"
#include "io/readers/byte_input.h"

namespace toposlice {
namespace {

static_assert(sizeof(Point3f) == 12, "Point3f must be three packed floats");

constexpr std::size_t kBinaryHeaderBytes = 80;
constexpr std::size_t kBinaryPrefixBytes = 84;  // header + uint32 facet count
constexpr std::size_t kBinaryFacetBytes = 50;   // normal, 3 corners (12 floats), uint16 attribute

[[noreturn]] void fail(const std::string& name, const std::string& what) {
  throwInputError(name, what);
}

inline uint32_t loadLe32(const std::byte* p) {
  uint32_t v;
  std::memcpy(&v, p, 4);
  if constexpr (std::endian::native == std::endian::big) {
    v = (v >> 24) | ((v >> 8) & 0xFF00u) | ((v << 8) & 0xFF0000u) | (v << 24);
  }
  return v;
}

inline bool isSpace(char c) {
  return c == ' ' || (c >= '\t' && c <= '\r');
}

// ---------------------------------------------------------------------------------------------------
// Binary STL.

std::string headerName(const std::byte* header) {
  std::string_view title(reinterpret_cast<const char*>(header), kBinaryHeaderBytes);
  title = title.substr(0, title.find('\0'));
  while (!title.empty() && isSpace(title.back())) title.remove_suffix(1);
  while (!title.empty() && isSpace(title.front())) title.remove_prefix(1);
  return std::string(title);
}

// Writes the corners of `count` 50-byte facet records to out[0, 3 count); true when any coordinate is
// NaN or infinite.
bool convertBinaryFacets(const std::byte* records, std::size_t count, Point3f* out) {
  bool anyNonFinite = false;
  const std::byte* record = records;
  for (std::size_t f = 0; f < count; ++f, record += kBinaryFacetBytes, out += 3) {
    const std::byte* corner = record + 12;  // skip the normal
    uint32_t bits[9];
    for (int k = 0; k < 9; ++k) {
      bits[k] = loadLe32(corner + 4 * k);
      anyNonFinite |= (bits[k] & 0x7F800000u) == 0x7F800000u;
    }
    for (int c = 0; c < 3; ++c) {
      out[c] = {std::bit_cast<float>(bits[3 * c]), std::bit_cast<float>(bits[3 * c + 1]),
                std::bit_cast<float>(bits[3 * c + 2])};
    }
  }
  return anyNonFinite;
}

// Appends the corners of `count` 50-byte facet records; true when any coordinate is NaN or infinite.
// The vector grows a batch at a time, so its zero-fill and the copy touch memory while it is in cache.
bool appendBinaryFacets(const std::byte* records, std::size_t count, std::vector<Point3f>& corners) {
  constexpr std::size_t kBatch = 2048;
  bool anyNonFinite = false;
  for (std::size_t first = 0; first < count; first += kBatch) {
    const std::size_t batch = std::min(kBatch, count - first);
    const std::size_t at = corners.size();
    corners.resize(at + 3 * batch);
    anyNonFinite |= convertBinaryFacets(records + first * kBinaryFacetBytes, batch, corners.data() + at);
  }
  return anyNonFinite;
}

// The parts, in order, as one array (copied side by side).
void joinParts(std::vector<std::vector<Point3f>>& parts, std::vector<Point3f>& out,
               const ChunkRunner& runner) {
  std::vector<std::size_t> at(parts.size() + 1, out.size());
  for (std::size_t c = 0; c < parts.size(); ++c) at[c + 1] = at[c] + parts[c].size();
  out.resize(at.back());
  runner.run(parts.size(), 1, [&](std::size_t c0, std::size_t c1) {
    for (std::size_t c = c0; c < c1; ++c) {
      std::copy(parts[c].begin(), parts[c].end(), out.begin() + static_cast<std::ptrdiff_t>(at[c]));
      std::vector<Point3f>().swap(parts[c]);
    }
  });
}

[[noreturn]] void failFirstNonFinite(const std::vector<Point3f>& corners, const std::string& name) {
  std::size_t i = 0;
  while (i + 1 < corners.size() && std::isfinite(corners[i].x) && std::isfinite(corners[i].y) &&
         std::isfinite(corners[i].z)) {
    ++i;
  }
  fail(name, "facet " + std::to_string(i / 3) + ": non-finite coordinate (NaN or infinity)");
}

// `bytes` is exactly 84 + 50 * facetCount long. With a parallel runner, chunks of records are
// converted side by side, each straight into its own range of the soup.
void parseBinary(std::span<const std::byte> bytes, uint32_t facetCount, const std::string& name,
                 StlSource& source, FacetSoup& soup, const ChunkRunner& runner) {
  source.binary = true;
  source.solidName = headerName(bytes.data());
  if (facetCount == 0) fail(name, "contains no facets");
  constexpr std::size_t kChunkFacets = 1 << 15;
  if (runner.width <= 1 || facetCount < 4 * kChunkFacets) {
    reserveHugePages(soup.corners, std::size_t{facetCount} * 3);
    if (appendBinaryFacets(bytes.data() + kBinaryPrefixBytes, facetCount, soup.corners))
      failFirstNonFinite(soup.corners, name);
    return;
  }
  const std::size_t chunks = (facetCount + kChunkFacets - 1) / kChunkFacets;
  resizeFaultedIn(soup.corners, std::size_t{facetCount} * 3, runner);
  std::vector<uint8_t> nonFinite(chunks, 0);
  runner.run(chunks, 1, [&](std::size_t c0, std::size_t c1) {
    for (std::size_t c = c0; c < c1; ++c) {
      const std::size_t first = c * kChunkFacets,
                        count = std::min<std::size_t>(kChunkFacets, facetCount - first);
      nonFinite[c] = convertBinaryFacets(bytes.data() + kBinaryPrefixBytes + first * kBinaryFacetBytes, count,
                                         soup.corners.data() + 3 * first);
    }
  });
  source.pieces = chunks;
  if (std::find(nonFinite.begin(), nonFinite.end(), 1) != nonFinite.end())
    failFirstNonFinite(soup.corners, name);
}

// A gzip-compressed binary STL, decompressed a cache-sized chunk at a time straight into the soup
// (no buffer for the whole file). Only tried when the trailer's size says binary; returns false when the
// stream's real length is not 84 + 50 * count, and the caller then reads the stream the general way.
bool streamGzipBinary(std::span<const std::byte> bytes, const std::string& name, StlSource& source,
                      FacetSoup& soup) {
  GzipReader reader(bytes, name);
  std::byte prefix[kBinaryPrefixBytes];
  if (reader.read(prefix, kBinaryPrefixBytes) < kBinaryPrefixBytes) return false;
  const uint32_t facetCount = loadLe32(prefix + kBinaryHeaderBytes);
  if (facetCount == 0 || reader.sizeHint() != kBinaryPrefixBytes + uint64_t{kBinaryFacetBytes} * facetCount) {
    return false;
  }
  constexpr std::size_t kChunkFacets = 2048;  // 100 KiB
  auto chunk = std::make_unique_for_overwrite<std::byte[]>(kChunkFacets * kBinaryFacetBytes);
  reserveHugePages(soup.corners, std::size_t{facetCount} * 3);
  bool anyNonFinite = false;
  for (std::size_t done = 0; done < facetCount;) {
    const std::size_t want = std::min<std::size_t>(kChunkFacets, facetCount - done);
    const std::size_t got = reader.read(chunk.get(), want * kBinaryFacetBytes);
    if (got < want * kBinaryFacetBytes) return false;  // shorter than the count says
    anyNonFinite |= appendBinaryFacets(chunk.get(), want, soup.corners);
    done += want;
  }
  std::byte extra;
  if (reader.read(&extra, 1) != 0) return false;  // longer than the count says
  source.binary = true;
  source.solidName = headerName(prefix);
  if (anyNonFinite) failFirstNonFinite(soup.corners, name);
  return true;
}

// ---------------------------------------------------------------------------------------------------
// ASCII STL.

// Whitespace-separated tokens over [begin, end), with the 1-based line of the last token returned.
class Lexer {
 public:
  Lexer(const char* begin, const char* end) : p_(begin), end_(end) {}

  // The next token, or an empty view at the end of the text.
  std::string_view next() {
    skipSpace();
    tokenLine_ = line_;
    const char* start = p_;
    while (p_ < end_ && !isSpace(*p_)) ++p_;
    return {start, static_cast<std::size_t>(p_ - start)};
  }

  // Consumes the case-insensitive word `lower` if the text continues with it (after whitespace),
  // even when other characters follow it directly ("solidname").
  bool consumePrefix(std::string_view lower) {
    skipSpace();
    tokenLine_ = line_;
    if (static_cast<std::size_t>(end_ - p_) < lower.size()) return false;
    for (std::size_t i = 0; i < lower.size(); ++i) {
      if ((p_[i] | 0x20) != lower[i]) return false;
    }
    p_ += lower.size();
    return true;
  }

  // The rest of the current line, trimmed; the line feed is left for the next token.
  std::string_view restOfLine() {
    const char* start = p_;
    while (p_ < end_ && *p_ != '\n') ++p_;
    std::string_view rest(start, static_cast<std::size_t>(p_ - start));
    while (!rest.empty() && isSpace(rest.front())) rest.remove_prefix(1);
    while (!rest.empty() && isSpace(rest.back())) rest.remove_suffix(1);
    return rest;
  }

  bool atEnd() {
    skipSpace();
    return p_ == end_;
  }
  std::string_view rest() const { return {p_, static_cast<std::size_t>(end_ - p_)}; }
  std::size_t line() const { return tokenLine_; }

 private:
  void skipSpace() {
    while (p_ < end_ && isSpace(*p_)) {
      line_ += *p_ == '\n';
      ++p_;
    }
  }

  const char* p_;
  const char* end_;
  std::size_t line_ = 1;
  std::size_t tokenLine_ = 1;
};

// Keywords are letters only, so OR-ing 0x20 folds case without matching any non-letter.
inline bool isKeyword(std::string_view token, std::string_view lower) {
  if (token.size() != lower.size()) return false;
  for (std::size_t i = 0; i < token.size(); ++i) {
    if ((token[i] | 0x20) != lower[i]) return false;
  }
  return true;
}

enum class NumberRead { kOk, kNotANumber, kOutOfRange };

// Float text as std::from_chars reads it (nan and inf included), with an optional leading '+'.
// Values below float's range round to 0 or a subnormal; values above it are kOutOfRange.
NumberRead readFloat(std::string_view token, float& value) {
  const char* begin = token.data();
  const char* end = begin + token.size();
  if (token.size() > 1 && token[0] == '+' && token[1] != '-') ++begin;
  const auto [ptr, ec] = std::from_chars(begin, end, value);
  if (ptr != end || begin == end) return NumberRead::kNotANumber;
  if (ec == std::errc()) return NumberRead::kOk;
  if (ec != std::errc::result_out_of_range) return NumberRead::kNotANumber;
  double wide = 0;
  const auto [widePtr, wideEc] = std::from_chars(begin, end, wide);
  if (wideEc != std::errc() || widePtr != end || std::abs(wide) > std::numeric_limits<float>::max()) {
    return NumberRead::kOutOfRange;
  }
  value = static_cast<float>(wide);
  return NumberRead::kOk;
}

class AsciiParser {
 public:
  AsciiParser(std::string_view text, const std::string& name)
      : text_(text), lexer_(text.data(), text.data() + text.size()), name_(&name) {}

  void parse(StlSource& source, FacetSoup& soup, std::size_t textBytes, const ChunkRunner& runner) {
    bool first = true;
    if (runner.width > 1 && textBytes >= kSplitTextFrom) {
      // The common file, one solid of well-formed facets, is read in parallel pieces; anything the
      // pieces do not accept (an error, a second solid) is read again here, serially, which names it.
      if (!lexer_.consumePrefix("solid")) failAtLine("expected 'solid', found " + quoteToken(lexer_.next()));
      const std::string_view solidName = lexer_.restOfLine();
      if (parseSplit(lexer_.rest(), soup, runner, source.pieces)) {
        source.solidName.assign(solidName);
        return;
      }
      *this = AsciiParser(text_, *name_);
    }
    // A facet takes 250 bytes in common writers' output, 90 at the least.
    soup.corners.reserve(3 * (textBytes / 192 + 1));
    while (true) {
      if (!lexer_.consumePrefix("solid")) {
        failAtLine("expected 'solid', found " + quoteToken(lexer_.next()));
      }
      const std::string_view solidName = lexer_.restOfLine();
      if (first) source.solidName.assign(solidName);
      first = false;
      if (!parseFacets(soup)) return;  // end of file without endsolid
      lexer_.restOfLine();             // the endsolid name is ignored
      if (lexer_.atEnd()) return;
    }
  }

 private:
  // Reads facets up to endsolid (true) or the end of the text (false).
  bool parseFacets(FacetSoup& soup) {
    for (;;) {
      const std::string_view token = lexer_.next();
      if (token.empty()) return false;
      if (isKeyword(token, "endsolid")) return true;
      if (!isKeyword(token, "facet")) {
        failInFacet("expected 'facet' or 'endsolid', found " + quoteToken(token));
      }
      parseFacet(soup);
    }
  }

  // After the "facet" keyword: normal, loop of vertices, endfacet. Appends 3 corners.
  void parseFacet(FacetSoup& soup) {
    const std::size_t facetLine = lexer_.line();
    expectKeyword("normal");
    for (int k = 0; k < 3; ++k) {
      const std::string_view token = lexer_.next();
      float ignored;
      if (readFloat(token, ignored) == NumberRead::kNotANumber) {
        failInFacet("'facet normal' needs 3 numbers, found " + quoteToken(token));
      }
    }
    expectKeyword("outer");
    expectKeyword("loop");
    Point3f corners[3];
    std::size_t vertexCount = 0;
    for (;;) {
      const std::string_view token = lexer_.next();
      if (isKeyword(token, "endloop")) break;
      if (!isKeyword(token, "vertex"))
        failInFacet("expected 'vertex' or 'endloop', found " + quoteToken(token));
      Point3f p;
      p.x = readCoordinate();
      p.y = readCoordinate();
      p.z = readCoordinate();
      if (vertexCount < 3) corners[vertexCount] = p;
      ++vertexCount;
    }
    if (vertexCount != 3) {
      fail(*name_, "facet " + std::to_string(facetIndex_) + " (line " + std::to_string(facetLine) +
                       "): " + std::to_string(vertexCount) + " vertices, expected 3");
    }
    expectKeyword("endfacet");
    soup.corners.push_back(corners[0]);
    soup.corners.push_back(corners[1]);
    soup.corners.push_back(corners[2]);
    ++facetIndex_;
  }

  float readCoordinate() {
    const std::string_view token = lexer_.next();
    float value = 0;
    switch (readFloat(token, value)) {
      case NumberRead::kOk:
        if (!std::isfinite(value)) failInFacet("non-finite coordinate " + quoteToken(token));
        return value;
      case NumberRead::kOutOfRange:
        failInFacet("coordinate out of float range " + quoteToken(token));
      case NumberRead::kNotANumber:
        break;
    }
    failInFacet("expected a coordinate, found " + quoteToken(token));
  }

  void expectKeyword(std::string_view lower) {
    const std::string_view token = lexer_.next();
    if (!isKeyword(token, lower)) {
      failInFacet("expected '" + std::string(lower) + "', found " + quoteToken(token));
    }
  }

  [[noreturn]] void failInFacet(const std::string& what) const {
    fail(*name_,
         "facet " + std::to_string(facetIndex_) + " (line " + std::to_string(lexer_.line()) + "): " + what);
  }
  [[noreturn]] void failAtLine(const std::string& what) const {
    fail(*name_, "line " + std::to_string(lexer_.line()) + ": " + what);
  }

  // The facets after the first solid's name line, in pieces cut before a "facet" keyword, each read by
  // its own parser. True when every piece held only whole facets and the last ended with endsolid (or
  // the text's end): the soup is then what the serial parse gives. False for anything else.
  bool parseSplit(std::string_view body, FacetSoup& soup, const ChunkRunner& runner,
                  std::size_t& pieceCount) const {
    const std::size_t pieces = std::max<std::size_t>(2, body.size() / kSplitPieceBytes);
    std::vector<std::size_t> cut{0};
    for (std::size_t k = 1; k < pieces; ++k) {
      const std::size_t at = nextFacetKeyword(body, std::max(cut.back(), k * body.size() / pieces));
      if (at >= body.size()) break;
      if (at > cut.back()) cut.push_back(at);
    }
    cut.push_back(body.size());
    const std::size_t count = cut.size() - 1;
    std::vector<std::vector<Point3f>> parts(count);
    std::vector<uint8_t> accepted(count, 0);
    runner.run(count, 1, [&](std::size_t c0, std::size_t c1) {
      for (std::size_t c = c0; c < c1; ++c) {
        FacetSoup piece;
        piece.corners.reserve(3 * ((cut[c + 1] - cut[c]) / 192 + 1));
        AsciiParser parser(body.substr(cut[c], cut[c + 1] - cut[c]), *name_);
        try {
          accepted[c] = parser.parseFacetsOnly(piece, c + 1 == count) ? 1 : 0;
        } catch (const InputError&) {
          accepted[c] = 0;  // the serial read names it
        }
        parts[c] = std::move(piece.corners);
      }
    });
    if (std::find(accepted.begin(), accepted.end(), 0) != accepted.end()) return false;
    joinParts(parts, soup.corners, runner);
    pieceCount = count;
    return !soup.corners.empty();
  }

  // A piece of a split read: facets only; the last piece may end with endsolid and its name line.
  bool parseFacetsOnly(FacetSoup& soup, bool last) {
    for (;;) {
      const std::string_view token = lexer_.next();
      if (token.empty()) return true;
      if (isKeyword(token, "facet")) {
        parseFacet(soup);
        continue;
      }
      if (!last || !isKeyword(token, "endsolid")) return false;
      lexer_.restOfLine();
      return lexer_.atEnd();
    }
  }

  // The offset of the first "facet" keyword (any case, whitespace on both sides) at or after `from`.
  static std::size_t nextFacetKeyword(std::string_view body, std::size_t from) {
    for (std::size_t at = from; at + 6 <= body.size(); ++at) {
      if ((body[at] | 0x20) != 'f' || at == 0 || !isSpace(body[at - 1])) continue;
      if (isKeyword(body.substr(at, 5), "facet") && isSpace(body[at + 5])) return at;
    }
    return body.size();
  }

  static constexpr std::size_t kSplitTextFrom = std::size_t{4} << 20;  // bytes: smaller texts read serially
  static constexpr std::size_t kSplitPieceBytes = std::size_t{1} << 20;

  std::string_view text_;
  Lexer lexer_;
  const std::string* name_;
  std::size_t facetIndex_ = 0;
};

std::size_t byteOrderMarkSize(std::string_view text) {
  return text.starts_with("\xEF\xBB\xBF") ? 3 : 0;
}

bool startsWithSolid(std::string_view text) {
  if (text.size() < 5) return false;
  for (std::size_t i = 0; i < 5; ++i) {
    if ((text[i] | 0x20) != "solid"[i]) return false;
  }
  return true;
}

FacetSoup parseUncompressed(std::span<const std::byte> bytes, const std::string& name, StlSource& source,
                            const ChunkRunner& runner = serialChunkRunner()) {
  if (bytes.empty()) fail(name, "empty file");
  const std::string_view text(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  FacetSoup soup;

  uint64_t binaryBytes = 0;
  uint32_t facetCount = 0;
  if (bytes.size() >= kBinaryPrefixBytes) {
    facetCount = loadLe32(bytes.data() + kBinaryHeaderBytes);
    binaryBytes = kBinaryPrefixBytes + uint64_t{kBinaryFacetBytes} * facetCount;
    if (binaryBytes == bytes.size()) {
      parseBinary(bytes, facetCount, name, source, soup, runner);
      return soup;
    }
  }

  const std::string_view afterMark = text.substr(byteOrderMarkSize(text));
  std::size_t start = 0;
  while (start < afterMark.size() && isSpace(afterMark[start])) ++start;
  if (start == afterMark.size()) fail(name, "empty file (only whitespace)");
  // ASCII STL never holds a NUL byte; a "solid" header padded with NULs is a binary file.
  const bool nulInPrefix = text.substr(0, kBinaryPrefixBytes).find('\0') != std::string_view::npos;
  if (startsWithSolid(afterMark.substr(start)) && !nulInPrefix) {
    AsciiParser(afterMark, name).parse(source, soup, text.size(), runner);  // counts the leading lines too
    if (soup.corners.empty()) fail(name, "contains no facets");
    return soup;
  }

  if (bytes.size() < kBinaryPrefixBytes) {
    fail(name, "not an STL file: " + std::to_string(bytes.size()) +
                   " bytes, too short for a binary STL, and not ASCII text starting with 'solid'");
  }
  const std::string counts = "expected " + std::to_string(facetCount) + " facets (" +
                             std::to_string(binaryBytes) + " bytes), file has " +
                             std::to_string(bytes.size()) + " bytes";
  if (bytes.size() < binaryBytes) {
    fail(name, "truncated: " + counts + " (binary facet count does not match the file length)");
  }
  fail(name, "binary facet count does not match the file length: " + counts);
}

}  // namespace

bool appendBinaryStlRecords(const std::byte* records, std::size_t count, std::vector<Point3f>& corners) {
  return appendBinaryFacets(records, count, corners);
}

std::string binaryStlHeaderName(const std::byte* header) {
  return headerName(header);
}

uint32_t binaryStlFacetCount(const std::byte* prefix) {
  return loadLe32(prefix + kBinaryHeaderBytes);
}

FacetSoup parseStl(std::span<const std::byte> bytes, const std::string& name, StlSource* source) {
  StlSource local;
  StlSource& out = source ? *source : local;
  out = StlSource{};
  if (isGzip(bytes)) {
    out.gzip = true;
    ByteBuffer whole;
    if (inflateWhole(bytes, gzipSizeHint(bytes), whole)) return parseUncompressed(whole.view(), name, out);
    FacetSoup soup;
    if (streamGzipBinary(bytes, name, out, soup)) return soup;
    const ByteBuffer inflated = GzipReader(bytes, name).readAll();
    return parseUncompressed(inflated.view(), name, out);
  }
  return parseUncompressed(bytes, name, out);
}

FacetSoup parseStlUncompressed(std::span<const std::byte> bytes, const std::string& name, StlSource* source,
                               const ChunkRunner& runner) {
  StlSource local;
  StlSource& out = source ? *source : local;
  out = StlSource{};
  return parseUncompressed(bytes, name, out, runner);
}

FacetSoup readStl(const std::filesystem::path& path, StlSource* source) {
  const ByteBuffer file = readWholeFile(path);
  return parseStl(file.view(), path.string(), source);
}

}  // namespace toposlice
