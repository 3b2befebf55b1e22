#include "io/readers/ply_reader.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>
#include <string_view>
#include <type_traits>
#include <vector>

#include "io/readers/byte_input.h"

namespace toposlice {
namespace {

enum class Scalar : uint8_t { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

struct TypeName {
  std::string_view name;
  Scalar type;
};
constexpr TypeName kTypeNames[] = {
    {"char", Scalar::kInt8},       {"int8", Scalar::kInt8},       {"uchar", Scalar::kUint8},
    {"uint8", Scalar::kUint8},     {"short", Scalar::kInt16},     {"int16", Scalar::kInt16},
    {"ushort", Scalar::kUint16},   {"uint16", Scalar::kUint16},   {"int", Scalar::kInt32},
    {"int32", Scalar::kInt32},     {"uint", Scalar::kUint32},     {"uint32", Scalar::kUint32},
    {"float", Scalar::kFloat32},   {"float32", Scalar::kFloat32}, {"double", Scalar::kFloat64},
    {"float64", Scalar::kFloat64},
};

std::size_t sizeOf(Scalar t) {
  switch (t) {
    case Scalar::kInt8:
    case Scalar::kUint8:
      return 1;
    case Scalar::kInt16:
    case Scalar::kUint16:
      return 2;
    case Scalar::kInt32:
    case Scalar::kUint32:
    case Scalar::kFloat32:
      return 4;
    case Scalar::kFloat64:
      return 8;
  }
  return 0;
}

bool isInteger(Scalar t) {
  return t != Scalar::kFloat32 && t != Scalar::kFloat64;
}

struct Property {
  std::string name;
  bool list = false;
  Scalar countType = Scalar::kUint8;  // lists only
  Scalar type = Scalar::kFloat32;     // the value, or each list item
};

struct Element {
  std::string name;
  uint64_t count = 0;
  std::size_t line = 0;  // header line of its "element" keyword
  std::vector<Property> properties;
};

enum class Encoding { kAscii, kBinaryLittle, kBinaryBig };

struct Header {
  Encoding encoding = Encoding::kAscii;
  std::vector<Element> elements;
  std::size_t dataOffset = 0;
};

inline bool isBlank(char c) {
  return c == ' ' || (c >= '\t' && c <= '\r');
}

void splitWords(std::string_view line, std::vector<std::string_view>& words) {
  words.clear();
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && isBlank(line[i])) ++i;
    const std::size_t start = i;
    while (i < line.size() && !isBlank(line[i])) ++i;
    if (i > start) words.push_back(line.substr(start, i - start));
  }
}

// Header lines, LF or CRLF terminated, counted from 1.
class HeaderLines {
 public:
  explicit HeaderLines(std::string_view text) : text_(text) {}
  bool next(std::string_view& line) {
    if (pos_ >= text_.size()) return false;
    const std::size_t lf = text_.find('\n', pos_);
    const std::size_t end = lf == std::string_view::npos ? text_.size() : lf;
    line = text_.substr(pos_, end - pos_);
    pos_ = lf == std::string_view::npos ? text_.size() : lf + 1;
    ++number_;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    return true;
  }
  std::size_t number() const { return number_; }
  std::size_t offset() const { return pos_; }

 private:
  std::string_view text_;
  std::size_t pos_ = 0;
  std::size_t number_ = 0;
};

Header parseHeader(std::string_view text, const std::string& name) {
  HeaderLines lines(text);
  const auto failAt = [&](const std::string& what) {
    throwInputError(name, "PLY header line " + std::to_string(lines.number()) + ": " + what);
  };
  const auto parseType = [&](std::string_view word) {
    for (const TypeName& t : kTypeNames) {
      if (t.name == word) return t.type;
    }
    failAt("unknown property type " + quoteToken(word));
    return Scalar::kUint8;  // not reached
  };

  Header header;
  std::string_view line;
  std::vector<std::string_view> words;
  lines.next(line);
  splitWords(line, words);
  if (words.size() != 1 || words[0] != "ply") failAt("expected 'ply'");
  bool haveFormat = false;
  while (true) {
    if (!lines.next(line)) {
      throwInputError(name, "PLY header: the file ends before 'end_header'");
    }
    splitWords(line, words);
    if (words.empty() || words[0] == "comment" || words[0] == "obj_info") continue;
    const std::string_view keyword = words[0];
    if (keyword == "format") {
      if (haveFormat) failAt("a second 'format' line");
      if (!header.elements.empty()) failAt("'format' after the first element");
      if (words.size() != 3) failAt("expected 'format <encoding> 1.0'");
      if (words[1] == "ascii") {
        header.encoding = Encoding::kAscii;
      } else if (words[1] == "binary_little_endian") {
        header.encoding = Encoding::kBinaryLittle;
      } else if (words[1] == "binary_big_endian") {
        header.encoding = Encoding::kBinaryBig;
      } else {
        failAt("unknown format " + quoteToken(words[1]) +
               " (ascii, binary_little_endian or binary_big_endian)");
      }
      if (words[2] != "1.0") failAt("unsupported version " + quoteToken(words[2]) + " (1.0)");
      haveFormat = true;
    } else if (keyword == "element") {
      if (!haveFormat) failAt("'element' before the 'format' line");
      if (words.size() != 3) failAt("expected 'element <name> <count>'");
      Element element;
      element.name = words[1];
      element.line = lines.number();
      const auto [ptr, ec] =
          std::from_chars(words[2].data(), words[2].data() + words[2].size(), element.count);
      if (ec != std::errc() || ptr != words[2].data() + words[2].size()) {
        failAt("element count " + quoteToken(words[2]) + " is not a non-negative integer");
      }
      header.elements.push_back(std::move(element));
    } else if (keyword == "property") {
      if (header.elements.empty()) failAt("'property' before any 'element'");
      Property property;
      if (words.size() >= 2 && words[1] == "list") {
        if (words.size() != 5) failAt("expected 'property list <count type> <item type> <name>'");
        property.list = true;
        property.countType = parseType(words[2]);
        property.type = parseType(words[3]);
        property.name = words[4];
        if (!isInteger(property.countType)) failAt("a list count type must be an integer type");
      } else {
        if (words.size() != 3) failAt("expected 'property <type> <name>'");
        property.type = parseType(words[1]);
        property.name = words[2];
      }
      header.elements.back().properties.push_back(std::move(property));
    } else if (keyword == "end_header") {
      if (words.size() != 1) failAt("expected 'end_header' alone on its line");
      if (!haveFormat) failAt("no 'format' line");
      header.dataOffset = lines.offset();
      return header;
    } else {
      failAt("unknown keyword " + quoteToken(keyword));
    }
  }
}

// The property of `element` named `name` (nullptr when absent).
const Property* findProperty(const Element& element, std::string_view name) {
  for (const Property& p : element.properties) {
    if (p.name == name) return &p;
  }
  return nullptr;
}

// ---------------------------------------------------------------------------------------------------
// Binary scalars: `size` bytes at p in the file's byte order as one bit pattern, and that pattern as the
// scalar type's value.

uint64_t loadBits(const std::byte* p, std::size_t size, bool bigEndian) {
  uint64_t v = 0;
  for (std::size_t i = 0; i < size; ++i)
    v = (v << 8) | std::to_integer<uint64_t>(p[bigEndian ? i : size - 1 - i]);
  return v;
}

int64_t integerOfBits(uint64_t bits, Scalar t) {
  switch (t) {
    case Scalar::kInt8:
      return static_cast<int8_t>(bits);
    case Scalar::kInt16:
      return static_cast<int16_t>(bits);
    case Scalar::kInt32:
      return static_cast<int32_t>(bits);
    default:
      return static_cast<int64_t>(bits);  // unsigned types, zero-extended
  }
}

double realOfBits(uint64_t bits, Scalar t) {
  switch (t) {
    case Scalar::kFloat32: {
      const auto narrow = static_cast<uint32_t>(bits);
      float f;
      std::memcpy(&f, &narrow, 4);
      return f;
    }
    case Scalar::kFloat64: {
      double d;
      std::memcpy(&d, &bits, 8);
      return d;
    }
    default:
      return static_cast<double>(integerOfBits(bits, t));
  }
}

// ---------------------------------------------------------------------------------------------------
// Data cursors: the same interface over binary records and ASCII tokens.

// The record being read, named in errors ("vertex 12", "face 3", "edge 0"); built only on failure.
struct Item {
  std::string_view kind;
  uint64_t index;
  std::string label() const { return std::string(kind) + " " + std::to_string(index); }
};

class BinaryCursor {
 public:
  BinaryCursor(std::span<const std::byte> data, bool bigEndian, const std::string& name)
      : p_(data.data()), end_(data.data() + data.size()), bigEndian_(bigEndian), name_(name) {}

  // How many more values of `bytes` bytes each can there be at most.
  uint64_t roomFor(std::size_t bytes) const { return bytes == 0 ? UINT64_MAX : left() / bytes; }
  std::size_t left() const { return static_cast<std::size_t>(end_ - p_); }

  double real(Scalar t, const Item& item) { return realOfBits(take(t, item), t); }
  int64_t integer(Scalar t, const Item& item) { return integerOfBits(take(t, item), t); }
  void skip(Scalar t, const Item& item) { take(t, item); }
  void skipItems(Scalar t, uint64_t count, const Item& item) {
    if (count > roomFor(sizeOf(t))) truncated(item);
    p_ += count * sizeOf(t);
  }
  std::string where() const { return ""; }
  // "" when every byte was read, else what is left.
  std::string leftOver() const {
    return left() == 0 ? "" : std::to_string(left()) + " bytes after the last element";
  }

 private:
  uint64_t take(Scalar t, const Item& item) {
    const std::size_t size = sizeOf(t);
    if (left() < size) truncated(item);
    const uint64_t v = loadBits(p_, size, bigEndian_);
    p_ += size;
    return v;
  }
  [[noreturn]] void truncated(const Item& item) const {
    throwInputError(name_, "truncated: the data ends inside " + item.label());
  }

  const std::byte* p_;
  const std::byte* end_;
  bool bigEndian_;
  const std::string& name_;
};

class AsciiCursor {
 public:
  AsciiCursor(std::string_view text, std::size_t firstLine, const std::string& name)
      : p_(text.data()), end_(text.data() + text.size()), line_(firstLine), name_(name) {}

  // At most how many more tokens of which `perRecord` make one record: a token and a separator each.
  uint64_t roomFor(std::size_t perRecord) const {
    return perRecord == 0 ? UINT64_MAX : (static_cast<uint64_t>(end_ - p_) / 2 + 1) / perRecord;
  }

  double real(Scalar, const Item& item) {
    const std::string_view token = next(item);
    double value = 0;
    const char* begin = token.data() + (token.size() > 1 && token[0] == '+' && token[1] != '-');
    const auto [ptr, ec] = std::from_chars(begin, token.data() + token.size(), value);
    if (ptr != token.data() + token.size() || (ec != std::errc() && ec != std::errc::result_out_of_range)) {
      fail(item.label() + ": expected a number, found " + quoteToken(token));
    }
    if (ec == std::errc::result_out_of_range) {
      // Beyond double's range: a negative exponent underflows to 0, anything else is too large.
      const std::size_t e = token.find_first_of("eE");
      const bool underflow = e != std::string_view::npos && e + 1 < token.size() && token[e + 1] == '-';
      value = underflow ? 0.0 : HUGE_VAL;
    }
    return value;
  }
  int64_t integer(Scalar, const Item& item) {
    const std::string_view token = next(item);
    int64_t value = 0;
    const char* begin = token.data() + (token.size() > 1 && token[0] == '+' && token[1] != '-');
    const auto [ptr, ec] = std::from_chars(begin, token.data() + token.size(), value);
    if (ec != std::errc() || ptr != token.data() + token.size()) {
      fail(item.label() + ": expected an integer, found " + quoteToken(token));
    }
    return value;
  }
  void skip(Scalar, const Item& item) { next(item); }
  void skipItems(Scalar t, uint64_t count, const Item& item) {
    if (count > roomFor(1)) fail("truncated: the data ends inside " + item.label());
    for (uint64_t i = 0; i < count; ++i) skip(t, item);
  }
  std::string where() const { return " (line " + std::to_string(line_) + ")"; }
  // "" when only blanks are left, else where the next token is.
  std::string leftOver() {
    while (p_ < end_ && isBlank(*p_)) line_ += *p_++ == '\n';
    return p_ == end_ ? "" : "data after the last element, line " + std::to_string(line_);
  }

 private:
  std::string_view next(const Item& item) {
    while (p_ < end_ && isBlank(*p_)) line_ += *p_++ == '\n';
    const char* start = p_;
    while (p_ < end_ && !isBlank(*p_)) ++p_;
    if (p_ == start) fail("truncated: the data ends inside " + item.label());
    return {start, static_cast<std::size_t>(p_ - start)};
  }
  [[noreturn]] void fail(const std::string& what) const {
    throwInputError(name_, "line " + std::to_string(line_) + ": " + what);
  }

  const char* p_;
  const char* end_;
  std::size_t line_;
  const std::string& name_;
};

// ---------------------------------------------------------------------------------------------------
// Elements.

class PlyParser {
 public:
  PlyParser(const Header& header, const std::string& name) : header_(header), name_(name) {
    for (const Element& e : header.elements) {
      if (e.name == "vertex") {
        if (vertexElement_) headerFail(e, "a second 'vertex' element");
        vertexElement_ = &e;
      } else if (e.name == "face") {
        if (faceElement_) headerFail(e, "a second 'face' element");
        faceElement_ = &e;
      }
    }
    if (vertexElement_) {
      const char* axes[3] = {"x", "y", "z"};
      for (int k = 0; k < 3; ++k) {
        const Property* p = findProperty(*vertexElement_, axes[k]);
        if (!p || p->list)
          headerFail(*vertexElement_, std::string("element vertex has no scalar property ") + axes[k]);
        axis_[k] = p;
      }
      if (vertexElement_->count > UINT32_MAX) headerFail(*vertexElement_, "more than 2^32 - 1 vertices");
      vertexCount_ = vertexElement_->count;
    }
    if (faceElement_) {
      cornerList_ = findProperty(*faceElement_, "vertex_indices");
      if (!cornerList_) cornerList_ = findProperty(*faceElement_, "vertex_index");
      if (!cornerList_ || !cornerList_->list) {
        headerFail(*faceElement_, "element face has no list property vertex_indices (or vertex_index)");
      }
      if (!isInteger(cornerList_->type))
        headerFail(*faceElement_, "face vertex indices must have an integer type");
    }
  }

  template <class Cursor>
  void read(Cursor& cursor, PlySource& source, FacetSoup& soup) {
    for (const Element& e : header_.elements) {
      if (e.count == 0 || e.properties.empty()) continue;  // nothing to read
      std::size_t minimum = 0;  // binary: fixed bytes per record; ASCII: tokens per record
      for (const Property& p : e.properties)
        minimum += std::is_same_v<Cursor, BinaryCursor> ? sizeOf(p.list ? p.countType : p.type) : 1;
      if (e.count > cursor.roomFor(minimum)) {
        throwInputError(name_, "truncated: element '" + e.name + "' declares " + std::to_string(e.count) +
                                   " records, more than the data after the header can hold");
      }
      if (&e == vertexElement_) {
        readVertices(cursor, e, soup);
      } else if (&e == faceElement_) {
        readFaces(cursor, e, source);
      } else {
        for (uint64_t r = 0; r < e.count; ++r) {
          for (const Property& p : e.properties) skipProperty(cursor, p, Item{e.name, r});
        }
      }
    }
    // A count that is too small leaves records unread: refused rather than dropping facets silently.
    if (const std::string rest = cursor.leftOver(); !rest.empty())
      throwInputError(name_, rest + ": the header's element counts do not cover the file");
    if (triangles_.empty()) throwInputError(name_, "contains no facets");
    soup.corners.resize(triangles_.size());
    for (std::size_t i = 0; i < triangles_.size(); ++i) soup.corners[i] = vertices_[triangles_[i]];
  }

 private:
  template <class Cursor>
  void skipProperty(Cursor& cursor, const Property& p, const Item& item) {
    if (!p.list) return cursor.skip(p.type, item);
    const int64_t count = cursor.integer(p.countType, item);
    if (count < 0) {
      throwInputError(name_,
                      item.label() + cursor.where() + ": negative list length " + std::to_string(count));
    }
    cursor.skipItems(p.type, static_cast<uint64_t>(count), item);
  }

  template <class Cursor>
  void readVertices(Cursor& cursor, const Element& e, FacetSoup&) {
    vertices_.reserve(e.count);  // checked against the data left by the caller
    for (uint64_t v = 0; v < e.count; ++v) {
      const Item item{"vertex", v};
      double xyz[3] = {0, 0, 0};
      for (const Property& p : e.properties) {
        const int k = &p == axis_[0] ? 0 : &p == axis_[1] ? 1 : &p == axis_[2] ? 2 : -1;
        if (k < 0) {
          skipProperty(cursor, p, item);
          continue;
        }
        xyz[k] = cursor.real(p.type, item);
        if (!std::isfinite(xyz[k])) {
          throwInputError(name_, item.label() + cursor.where() + ": non-finite coordinate (NaN or infinity)");
        }
        if (std::abs(xyz[k]) > std::numeric_limits<float>::max()) {
          throwInputError(name_, item.label() + cursor.where() + ": coordinate out of float range");
        }
      }
      vertices_.push_back(
          {static_cast<float>(xyz[0]), static_cast<float>(xyz[1]), static_cast<float>(xyz[2])});
    }
  }

  template <class Cursor>
  void readFaces(Cursor& cursor, const Element& e, PlySource& source) {
    triangles_.reserve(3 * e.count);  // checked against the data left by the caller
    std::vector<uint32_t> corners;
    for (uint64_t f = 0; f < e.count; ++f) {
      const Item item{"face", f};
      for (const Property& p : e.properties) {
        if (&p != cornerList_) {
          skipProperty(cursor, p, item);
          continue;
        }
        const int64_t count = cursor.integer(p.countType, item);
        const std::string where = cursor.where();
        if (count < 3) {
          throwInputError(
              name_, item.label() + where + ": " + std::to_string(count) + " corners, expected at least 3");
        }
        if (static_cast<uint64_t>(count) >
            cursor.roomFor(std::is_same_v<Cursor, BinaryCursor> ? sizeOf(p.type) : 1)) {
          throwInputError(name_, "truncated: the data ends inside " + item.label());
        }
        corners.clear();
        for (int64_t i = 0; i < count; ++i) {
          const int64_t index = cursor.integer(p.type, item);
          if (index < 0 || static_cast<uint64_t>(index) >= vertexCount_) {
            throwInputError(name_, item.label() + where + ": vertex index " + std::to_string(index) +
                                       " out of range (" + std::to_string(vertexCount_) + " vertices)");
          }
          corners.push_back(static_cast<uint32_t>(index));
        }
        for (std::size_t i = 1; i + 1 < corners.size(); ++i) {
          triangles_.push_back(corners[0]);
          triangles_.push_back(corners[i]);
          triangles_.push_back(corners[i + 1]);
        }
        source.polygonsTriangulated += corners.size() > 3;
      }
    }
  }

  // A field of a fixed-size record: its byte offset in the record and its type.
  struct Field {
    std::size_t offset = 0;
    Scalar type = Scalar::kUint8;
  };

 public:
  // The common binary file, read in chunks on `runner`: every element's records have one size (no list
  // property but the faces' corners, and every face a triangle). Returns false, having changed nothing
  // the caller keeps, for anything else -- another layout, a polygon, an index out of range, a
  // coordinate that is not finite or beyond float, data too short -- and the caller then reads record by
  // record (read()), which gives that path's result or its error message. Where it returns true, the
  // soup is the one read() gives.
  bool readFixed(std::span<const std::byte> data, bool bigEndian, FacetSoup& soup,
                 const ChunkRunner& runner) {
    if (!vertexElement_ || !faceElement_ || faceElement_->count == 0) return false;
    std::size_t vertexStart = 0, vertexRecord = 0, faceStart = 0, faceRecord = 0, at = 0;
    Field axes[3], count, corner;
    for (const Element& e : header_.elements) {
      if (e.count == 0 || e.properties.empty()) continue;  // nothing to read, as read() does
      std::size_t record = 0;
      for (const Property& p : e.properties) {
        if (&e == vertexElement_) {
          for (int k = 0; k < 3; ++k)
            if (&p == axis_[k]) axes[k] = {record, p.type};
        }
        if (p.list && &p != cornerList_) return false;  // records of several sizes
        if (&p == cornerList_) {
          count = {record, p.countType};
          corner = {record + sizeOf(p.countType), p.type};
          record += sizeOf(p.countType) + 3 * sizeOf(p.type);
        } else {
          record += sizeOf(p.type);
        }
      }
      if (e.count > (data.size() - at) / record) return false;  // read() names the truncation
      if (&e == vertexElement_) vertexStart = at, vertexRecord = record;
      if (&e == faceElement_) faceStart = at, faceRecord = record;
      at += static_cast<std::size_t>(e.count) * record;
    }
    if (at != data.size()) return false;  // bytes after the last element: read() names them
    const std::size_t vertices = static_cast<std::size_t>(vertexElement_->count),
                      faces = static_cast<std::size_t>(faceElement_->count);
    constexpr std::size_t kChunk = std::size_t{1} << 15;  // records
    const auto chunks = [](std::size_t n) { return (n + kChunk - 1) / kChunk; };
    const std::byte* const bytes = data.data();

    std::vector<Point3f> points(vertices);
    std::vector<uint8_t> pointsBad(chunks(vertices), 0);
    runner.run(pointsBad.size(), 1, [&](std::size_t c0, std::size_t c1) {
      for (std::size_t c = c0; c < c1; ++c) {
        const std::size_t end = std::min(vertices, (c + 1) * kChunk);
        for (std::size_t v = c * kChunk; v < end; ++v) {
          const std::byte* record = bytes + vertexStart + v * vertexRecord;
          float xyz[3];
          for (int k = 0; k < 3; ++k) {
            const double value =
                realOfBits(loadBits(record + axes[k].offset, sizeOf(axes[k].type), bigEndian), axes[k].type);
            pointsBad[c] |= !std::isfinite(value) || std::abs(value) > std::numeric_limits<float>::max();
            xyz[k] = static_cast<float>(value);
          }
          points[v] = {xyz[0], xyz[1], xyz[2]};
        }
      }
    });
    if (std::find(pointsBad.begin(), pointsBad.end(), 1) != pointsBad.end()) return false;

    std::vector<Point3f> corners(3 * faces);
    std::vector<uint8_t> facesBad(chunks(faces), 0);
    const std::size_t cornerSize = sizeOf(corner.type);
    runner.run(facesBad.size(), 1, [&](std::size_t c0, std::size_t c1) {
      for (std::size_t c = c0; c < c1; ++c) {
        const std::size_t end = std::min(faces, (c + 1) * kChunk);
        for (std::size_t f = c * kChunk; f < end && !facesBad[c]; ++f) {
          const std::byte* record = bytes + faceStart + f * faceRecord;
          if (integerOfBits(loadBits(record + count.offset, sizeOf(count.type), bigEndian), count.type) !=
              3) {
            facesBad[c] = 1;  // a polygon (or a bad count): read() fans it out or names it
            break;
          }
          for (std::size_t j = 0; j < 3; ++j) {
            const int64_t index = integerOfBits(
                loadBits(record + corner.offset + j * cornerSize, cornerSize, bigEndian), corner.type);
            if (index < 0 || static_cast<uint64_t>(index) >= vertices) {
              facesBad[c] = 1;
              break;
            }
            corners[3 * f + j] = points[static_cast<std::size_t>(index)];
          }
        }
      }
    });
    if (std::find(facesBad.begin(), facesBad.end(), 1) != facesBad.end()) return false;
    soup.corners = std::move(corners);
    return true;
  }

 private:
  [[noreturn]] void headerFail(const Element& e, const std::string& what) const {
    throwInputError(name_, "PLY header line " + std::to_string(e.line) + ": " + what);
  }

  const Header& header_;
  const std::string& name_;
  const Element* vertexElement_ = nullptr;
  const Element* faceElement_ = nullptr;
  const Property* axis_[3] = {nullptr, nullptr, nullptr};
  const Property* cornerList_ = nullptr;
  uint64_t vertexCount_ = 0;
  std::vector<Point3f> vertices_;
  std::vector<uint32_t> triangles_;  // 3 vertex indices per facet
};

// The record-by-record reading of the data after `header` (parsed from `bytes`).
FacetSoup readRecords(std::span<const std::byte> bytes, const Header& header, PlyParser& parser,
                      const std::string& name, PlySource& out) {
  out = PlySource{};
  FacetSoup soup;
  if (header.encoding == Encoding::kAscii) {
    const std::string_view text(reinterpret_cast<const char*>(bytes.data()), bytes.size());
    const std::size_t headerLines =
        static_cast<std::size_t>(std::count(text.begin(), text.begin() + header.dataOffset, '\n'));
    AsciiCursor cursor(text.substr(header.dataOffset), headerLines + 1, name);
    parser.read(cursor, out, soup);
  } else {
    out.binary = true;
    BinaryCursor cursor(bytes.subspan(header.dataOffset), header.encoding == Encoding::kBinaryBig, name);
    parser.read(cursor, out, soup);
  }
  return soup;
}

}  // namespace

FacetSoup parsePly(std::span<const std::byte> bytes, const std::string& name, PlySource* source,
                   const ChunkRunner& runner) {
  PlySource local;
  PlySource& out = source ? *source : local;
  const std::string_view text(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  const Header header = parseHeader(text, name);
  PlyParser parser(header, name);
  if (header.encoding != Encoding::kAscii) {
    FacetSoup soup;
    if (parser.readFixed(bytes.subspan(header.dataOffset), header.encoding == Encoding::kBinaryBig, soup,
                         runner)) {
      out = PlySource{};
      out.binary = true;
      return soup;
    }
  }
  return readRecords(bytes, header, parser, name, out);
}

FacetSoup parsePlyRecords(std::span<const std::byte> bytes, const std::string& name, PlySource* source) {
  PlySource local;
  const std::string_view text(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  const Header header = parseHeader(text, name);
  PlyParser parser(header, name);
  return readRecords(bytes, header, parser, name, source ? *source : local);
}

}  // namespace toposlice
