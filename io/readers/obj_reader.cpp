#include "io/readers/obj_reader.h"

#include <tiny_obj_loader.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <istream>
#include <limits>
#include <map>
#include <streambuf>
#include <string_view>
#include <vector>

#include "io/readers/byte_input.h"

namespace toposlice {
namespace {

// Reads the bytes in place, without a copy. The get area is only read: a stream buffer writes into it
// only from pbackfail/sputbackc with a different character, which the default pbackfail refuses.
class SpanStreamBuf : public std::streambuf {
 public:
  explicit SpanStreamBuf(std::string_view text) {
    char* begin = const_cast<char*>(text.data());
    setg(begin, begin, begin + text.size());
  }
};

// Materials are never loaded: no .mtl file is opened, whatever the OBJ's mtllib says.
class NoMaterials : public tinyobj::MaterialReader {
 public:
  bool operator()(const std::string&, std::vector<tinyobj::material_t>*, std::map<std::string, int>*,
                  std::string*, std::string*) override {
    return true;
  }
};

struct ObjState {
  const std::string* name = nullptr;
  std::vector<Point3f> vertices;
  std::vector<uint32_t> triangles;  // 3 vertex indices per facet
  std::vector<uint32_t> corners;    // scratch: the current face
  uint64_t faces = 0;               // f lines so far
  uint64_t polygons = 0;            // faces with more than 3 corners
  // Faces with a positive index beyond the vertices defined so far (legal if defined later), checked
  // at the end: (face, largest index).
  std::vector<std::pair<uint64_t, uint32_t>> forward;
};

// tinyobjloader reads a coordinate it cannot parse ("nan", "inf", "abc", "1,5") as 0 or a prefix without a
// word, and a missing one as 0; it reads vertex indices into an int that wraps (4294967297 became 1). So
// every v and f line is checked here first: a v line holds at least three coordinates, each a finite
// number as std::from_chars reads it (with an optional leading '+'); each corner of an f line starts with
// a whole vertex index an int holds.
void checkVertexLines(std::string_view text, const std::string& name) {
  const auto blank = [](char c) { return c == ' ' || c == '\t' || c == '\r'; };
  uint64_t vertex = 0, face = 0, line = 0;
  for (std::size_t pos = 0; pos < text.size();) {
    const std::size_t lf = std::min(text.find('\n', pos), text.size());
    std::string_view rest = text.substr(pos, lf - pos);
    pos = lf + 1;
    ++line;
    while (!rest.empty() && blank(rest.front())) rest.remove_prefix(1);
    if ((rest.size() >= 2 && rest[0] == 'f' && blank(rest[1])) || rest == "f") {
      ++face;
      rest.remove_prefix(std::min<std::size_t>(2, rest.size()));
      for (int k = 0;; ++k) {
        while (!rest.empty() && blank(rest.front())) rest.remove_prefix(1);
        if (rest.empty() || rest.front() == '#') {
          // (tinyobjloader skipped a face of no corner without a word)
          if (k < 3)
            throwInputError(name, "face " + std::to_string(face - 1) + " (line " + std::to_string(line) +
                                      "): " + std::to_string(k) + " corners, expected at least 3");
          break;
        }
        std::size_t end = 0;
        while (end < rest.size() && !blank(rest[end])) ++end;
        const std::string_view corner = rest.substr(0, end);
        rest.remove_prefix(end);
        const std::string_view token = corner.substr(0, corner.find('/'));
        const char* begin = token.data() + (token.size() > 1 && token[0] == '+' && token[1] != '-');
        int64_t index = 0;
        const auto [ptr, ec] = std::from_chars(begin, token.data() + token.size(), index);
        if (ec == std::errc() && ptr == token.data() + token.size() &&
            index >= std::numeric_limits<int>::min() + 1 && index <= std::numeric_limits<int>::max())
          continue;
        throwInputError(
            name, "face " + std::to_string(face - 1) + " (line " + std::to_string(line) + "): corner " +
                      std::to_string(k) + ": vertex index " + quoteToken(token) +
                      (ec == std::errc() || ec == std::errc::result_out_of_range ? " is out of range"
                                                                                 : " is not a whole number"));
      }
      continue;
    }
    if (rest.empty() || rest[0] != 'v' || (rest.size() > 1 && !blank(rest[1]))) continue;  // vn, vt, ...
    ++vertex;
    rest.remove_prefix(std::min<std::size_t>(2, rest.size()));
    for (int k = 0; k < 3; ++k) {
      while (!rest.empty() && blank(rest.front())) rest.remove_prefix(1);
      if (rest.empty() || rest.front() == '#')
        throwInputError(name, "vertex " + std::to_string(vertex) + " (line " + std::to_string(line) +
                                  "): expected 3 coordinates, found " + std::to_string(k));
      std::size_t end = 0;
      while (end < rest.size() && !blank(rest[end])) ++end;
      const std::string_view token = rest.substr(0, end);
      rest.remove_prefix(end);
      const char* begin = token.data() + (token.size() > 1 && token[0] == '+' && token[1] != '-');
      double value = 0;
      const auto [ptr, ec] = std::from_chars(begin, token.data() + token.size(), value);
      if (ec != std::errc() || ptr != token.data() + token.size() || !std::isfinite(value)) {
        throwInputError(name, "vertex " + std::to_string(vertex) + " (line " + std::to_string(line) +
                                  "): coordinate " + quoteToken(token) + " is not a finite number");
      }
    }
  }
}

void onVertex(void* user, tinyobj::real_t x, tinyobj::real_t y, tinyobj::real_t z, tinyobj::real_t) {
  auto& s = *static_cast<ObjState*>(user);
  if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) {
    throwInputError(*s.name, "vertex " + std::to_string(s.vertices.size() + 1) +
                                 ": non-finite coordinate (NaN, infinity or beyond float's range)");
  }
  s.vertices.push_back({x, y, z});
}

void onFace(void* user, tinyobj::index_t* indices, int count) {
  auto& s = *static_cast<ObjState*>(user);
  const uint64_t face = s.faces++;
  const auto fail = [&](const std::string& what) {
    throwInputError(*s.name, "face " + std::to_string(face) + ": " + what);
  };
  if (count < 3) fail(std::to_string(count) + " corners, expected at least 3");
  s.corners.clear();
  uint32_t largest = 0;
  const int64_t defined = static_cast<int64_t>(s.vertices.size());
  for (int k = 0; k < count; ++k) {
    const int64_t raw = indices[k].vertex_index;
    if (raw == 0) fail("corner " + std::to_string(k) + " has vertex index 0 or no number");
    const int64_t index = raw > 0 ? raw - 1 : defined + raw;
    if (index < 0 || index > int64_t{UINT32_MAX} - 1) {
      fail("vertex index " + std::to_string(raw) + " out of range (" + std::to_string(defined) +
           " vertices before it)");
    }
    s.corners.push_back(static_cast<uint32_t>(index));
    largest = std::max(largest, static_cast<uint32_t>(index));
  }
  if (largest >= s.vertices.size()) s.forward.emplace_back(face, largest);
  for (std::size_t i = 1; i + 1 < s.corners.size(); ++i) {
    s.triangles.push_back(s.corners[0]);
    s.triangles.push_back(s.corners[i]);
    s.triangles.push_back(s.corners[i + 1]);
  }
  s.polygons += count > 3;
}

}  // namespace

FacetSoup parseObj(std::span<const std::byte> bytes, const std::string& name, ObjSource* source) {
  ObjSource local;
  ObjSource& out = source ? *source : local;
  out = ObjSource{};

  std::string_view text(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  // A UTF-8 byte order mark (editors on Windows write one) is not part of the first line: left there,
  // it made tinyobjloader read a first "v" line as another statement, dropping that vertex and
  // shifting every face onto the wrong corners without a word.
  if (text.starts_with("\xEF\xBB\xBF")) text.remove_prefix(3);
  // A comment after a statement ("f 1 2 3 # top") is no part of it; tinyobjloader took it for a corner
  // of a face. Comments are blanked out (a copy of the text, only when it has one).
  std::string uncommented;
  if (text.find('#') != std::string_view::npos) {
    uncommented.assign(text);
    for (std::size_t hash = uncommented.find('#'); hash != std::string::npos;
         hash = uncommented.find('#', hash)) {
      const std::size_t end = std::min(uncommented.find('\n', hash), uncommented.size());
      std::fill(uncommented.begin() + static_cast<std::ptrdiff_t>(hash),
                uncommented.begin() + static_cast<std::ptrdiff_t>(end), ' ');
      hash = end;
    }
    text = uncommented;
  }
  checkVertexLines(text, name);
  SpanStreamBuf buffer(text);
  std::istream stream(&buffer);
  ObjState state;
  state.name = &name;
  tinyobj::callback_t callbacks;
  callbacks.vertex_cb = onVertex;
  callbacks.index_cb = onFace;
  NoMaterials noMaterials;
  std::string warnings, errors;
  if (!tinyobj::LoadObjWithCallback(stream, callbacks, &state, &noMaterials, &warnings, &errors)) {
    const std::string first = errors.substr(0, errors.find('\n'));
    throwInputError(name, "not a readable OBJ file: " + (first.empty() ? "tinyobjloader failed" : first));
  }
  for (const auto& [face, largest] : state.forward) {
    if (largest >= state.vertices.size()) {
      throwInputError(name, "face " + std::to_string(face) + ": vertex index " +
                                std::to_string(largest + uint64_t{1}) + " out of range (" +
                                std::to_string(state.vertices.size()) + " vertices)");
    }
  }
  if (state.triangles.empty()) throwInputError(name, "contains no facets");
  out.polygonsTriangulated = state.polygons;
  FacetSoup soup;
  soup.corners.resize(state.triangles.size());
  for (std::size_t i = 0; i < state.triangles.size(); ++i)
    soup.corners[i] = state.vertices[state.triangles[i]];
  return soup;
}

}  // namespace toposlice
