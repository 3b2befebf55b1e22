#include "io/readers/mesh_reader.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <string_view>

#include "core/memory_advice.h"
#include "core/mesh/weld.h"
#include "io/errors.h"
#include "io/readers/byte_input.h"
#include "io/readers/obj_reader.h"
#include "io/readers/parallel_gunzip.h"
#include "io/readers/ply_reader.h"
#include "io/readers/stl_reader.h"
#include "io/readers/threemf_reader.h"

namespace toposlice {
namespace {

enum class Detected { kStl, kPly, kObj, kThreeMf, kNotMesh };

constexpr std::size_t kSniffBytes = 64 * 1024;
constexpr int kObjLinesChecked = 16;

inline bool isSpace(char c) {
  return c == ' ' || (c >= '\t' && c <= '\r');
}

bool startsWithPlyLine(std::string_view text) {
  if (!text.starts_with("ply")) return false;
  std::size_t i = 3;
  while (i < text.size() && (text[i] == ' ' || text[i] == '\t' || text[i] == '\r')) ++i;
  return i < text.size() && text[i] == '\n';
}

bool startsWithSolidWord(std::string_view text) {
  if (text.size() < 5) return false;
  for (std::size_t i = 0; i < 5; ++i) {
    if ((text[i] | 0x20) != "solid"[i]) return false;
  }
  return true;
}

// No NUL and at most 1% other control bytes (tab, line feed, CR, VT, FF and bytes >= 0x80 count as text).
bool looksLikeText(std::string_view sample) {
  std::size_t controls = 0;
  for (const char c : sample) {
    const auto u = static_cast<unsigned char>(c);
    if (u == 0) return false;
    controls += (u < 0x20 && !isSpace(c)) || u == 0x7F;
  }
  return controls * 100 <= sample.size();
}

bool isObjKeyword(std::string_view word) {
  static constexpr std::string_view kKeywords[] = {
      "v",      "vt",         "vn",        "vp",     "f",        "l",        "p",    "o",
      "g",      "s",          "usemtl",    "mtllib", "cstype",   "deg",      "bmat", "step",
      "curv",   "curv2",      "surf",      "parm",   "trim",     "hole",     "scrv", "sp",
      "end",    "con",        "mg",        "bevel",  "c_interp", "d_interp", "lod",  "maplib",
      "usemap", "shadow_obj", "trace_obj", "ctech",  "stech"};
  return std::find(std::begin(kKeywords), std::end(kKeywords), word) != std::end(kKeywords);
}

// The first meaningful lines of `sample` (blank and # lines skipped, at most kObjLinesChecked) all start
// with an OBJ keyword, and there is at least one. `complete`: the sample is the whole text (else its last
// line may be cut and is not judged).
bool looksLikeObj(std::string_view sample, bool complete) {
  int checked = 0;
  std::size_t pos = 0;
  while (pos < sample.size() && checked < kObjLinesChecked) {
    const std::size_t lf = sample.find('\n', pos);
    if (lf == std::string_view::npos && !complete) break;
    const std::size_t end = lf == std::string_view::npos ? sample.size() : lf;
    std::string_view line = sample.substr(pos, end - pos);
    pos = end + 1;
    std::size_t i = 0;
    while (i < line.size() && isSpace(line[i])) ++i;
    line.remove_prefix(i);
    if (line.empty() || line[0] == '#') continue;
    std::size_t w = 0;
    while (w < line.size() && !isSpace(line[w])) ++w;
    if (!isObjKeyword(line.substr(0, w))) return false;
    ++checked;
  }
  return checked > 0;
}

Detected detect(std::span<const std::byte> bytes) {
  const std::string_view text(reinterpret_cast<const char*>(bytes.data()), bytes.size());
  if (text.empty()) return Detected::kStl;
  if (startsWithPlyLine(text)) return Detected::kPly;
  if (text.starts_with(std::string_view("PK\x03\x04", 4))) return Detected::kThreeMf;
  if (bytes.size() >= 84 && 84 + uint64_t{50} * binaryStlFacetCount(bytes.data()) == bytes.size())
    return Detected::kStl;
  const std::string_view afterMark = text.substr(text.starts_with("\xEF\xBB\xBF") ? 3 : 0);
  const std::size_t start = std::find_if_not(afterMark.begin(), afterMark.end(), isSpace) - afterMark.begin();
  if (start == afterMark.size() || startsWithSolidWord(afterMark.substr(start))) return Detected::kStl;
  const std::string_view sample = afterMark.substr(0, kSniffBytes);
  if (!looksLikeText(sample)) return Detected::kStl;
  return looksLikeObj(sample, sample.size() == afterMark.size()) ? Detected::kObj : Detected::kNotMesh;
}

void checkFactor(const std::string& name, const char* option, double value) {
  if (!std::isfinite(value) || value <= 0) {
    throwInputError(name, std::string(option) + " " + std::to_string(value) + ": expected a positive number");
  }
}

// Multiplies every coordinate by `factor` in double, rounding once to float.
void scaleSoup(FacetSoup& soup, double factor, const std::string& name) {
  if (factor == 1.0) return;
  constexpr double kMax = std::numeric_limits<float>::max();
  for (std::size_t i = 0; i < soup.corners.size(); ++i) {
    Point3f& p = soup.corners[i];
    const double x = p.x * factor, y = p.y * factor, z = p.z * factor;
    if (std::abs(x) > kMax || std::abs(y) > kMax || std::abs(z) > kMax) {
      throwInputError(
          name, "facet " + std::to_string(i / 3) + ": coordinate beyond float's range after --units/--scale");
    }
    p = {static_cast<float>(x), static_cast<float>(y), static_cast<float>(z)};
  }
}

FacetSoup parseInflated(std::span<const std::byte> bytes, const std::string& name,
                        const MeshReadOptions& options, MeshSource& source) {
  FacetSoup soup;
  switch (detect(bytes)) {
    case Detected::kStl: {
      source.format = MeshFormat::Stl;
      StlSource stl;
      soup = parseStlUncompressed(bytes, name, &stl, options.runner);
      source.binary = stl.binary;
      source.name = stl.solidName;
      break;
    }
    case Detected::kPly: {
      source.format = MeshFormat::Ply;
      PlySource ply;
      soup = parsePly(bytes, name, &ply, options.runner);
      source.binary = ply.binary;
      source.polygonsTriangulated = ply.polygonsTriangulated;
      break;
    }
    case Detected::kObj: {
      source.format = MeshFormat::Obj;
      ObjSource obj;
      soup = parseObj(bytes, name, &obj);
      source.polygonsTriangulated = obj.polygonsTriangulated;
      break;
    }
    case Detected::kThreeMf: {
      source.format = MeshFormat::ThreeMf;
      ThreeMfSource threeMf;
      soup = parseThreeMf(bytes, name, options.scale, &threeMf);  // converted to mm and scaled
      source.name = threeMf.objectName;
      source.fileUnit = threeMf.unit;
      if (options.unitMm) {
        throwInputError(name, "3MF files state their unit (" + threeMf.unit + "); --units does not apply");
      }
      return soup;
    }
    case Detected::kNotMesh:
      throwInputError(name, "not a mesh file (toposlice reads STL, PLY, OBJ and 3MF, recognised by content)");
  }
  scaleSoup(soup, options.unitMm.value_or(1.0) * options.scale, name);
  return soup;
}

// A gzip'd binary STL parsed while it inflates (GzipChunks, on its own thread): the records are converted
// a chunk at a time as they arrive. Only when the trailer's size is that of a binary STL with the count
// the header gives (and the header does not make it a PLY or 3MF file to detection); the soup is kept
// only when the stream inflated cleanly to exactly that size with every coordinate finite. Otherwise the
// caller reads the stream again the general way, which gives its result or error message.
bool parseGzipBinaryStlAhead(std::span<const std::byte> bytes, FacetSoup& soup, MeshSource& source,
                             IndexedMesh* weldInto) {
  constexpr std::size_t kPrefix = 84, kRecord = 50, kBatch = 4096;  // facets converted at a time
  GzipChunks stream(bytes, kPrefix, kRecord * kBatch);
  const std::size_t expected = stream.expectedSize();
  const std::span<const std::byte> header = stream.head();
  if (header.size() < kPrefix) return false;
  // Detection (`detect`) of the whole stream, from its header: a binary STL of this size unless it reads
  // as the start of a PLY header or a ZIP archive, which the general way then decides.
  const std::string_view text(reinterpret_cast<const char*>(header.data()), header.size());
  if (text.starts_with("ply") || text.starts_with(std::string_view("PK\x03\x04", 4))) return false;
  const uint32_t count = binaryStlFacetCount(header.data());
  if (count == 0 || kPrefix + uint64_t{kRecord} * count != expected) return false;
  const std::string name = binaryStlHeaderName(header.data());
  reserveHugePages(soup.corners, std::size_t{3} * count);
  std::optional<IncrementalWeld> weld;
  if (weldInto) weld.emplace(std::size_t{3} * count);
  std::size_t done = 0;
  bool nonFinite = false;
  for (std::span<const std::byte> chunk = stream.next(); !chunk.empty(); chunk = stream.next()) {
    const std::size_t records = chunk.size() / kRecord;  // whole chunks of records: the size is checked
    nonFinite |= appendBinaryStlRecords(chunk.data(), records, soup.corners);
    if (weld) weld->add(std::span<const Point3f>(soup.corners).subspan(3 * done));
    done += records;
  }
  if (!stream.finish() || done != count || nonFinite) {
    soup = FacetSoup{};
    return false;
  }
  if (weld) *weldInto = weld->take();
  source.format = MeshFormat::Stl;
  source.binary = true;
  source.name = name;
  return true;
}

}  // namespace

FacetSoup parseMesh(std::span<const std::byte> bytes, const std::string& name, const MeshReadOptions& options,
                    MeshSource* source) {
  MeshSource local;
  MeshSource& out = source ? *source : local;
  out = MeshSource{};
  if (options.unitMm) checkFactor(name, "--units", *options.unitMm);
  checkFactor(name, "--scale", options.scale);
  if (isGzip(bytes)) {
    out.gzip = true;
    // Two threads: ISA-L inflates on one while the other parses and welds (the streamed read). More:
    // every thread inflates a part of the stream, and the parse (and from four threads the weld) then
    // use them all (docs/BENCHMARKS.md, thread scaling, "Session 22": on two threads the streamed read
    // is faster, and libdeflate for text).
    constexpr unsigned kStreamedWidth = 2;
    if (options.runner.width > kStreamedWidth) {
      ByteBuffer inflated;
      if (gunzipParallel(bytes, options.runner, inflated))
        return parseInflated(inflated.view(), name, options, out);
    } else if (options.runner.width > 1) {  // a thread to inflate on, beside the parse
      FacetSoup soup;
      const double factor = options.unitMm.value_or(1.0) * options.scale;
      if (parseGzipBinaryStlAhead(bytes, soup, out, factor == 1.0 ? options.weld : nullptr)) {
        scaleSoup(soup, factor, name);
        return soup;
      }
    }
    const ByteBuffer inflated = gunzip(bytes, name);
    return parseInflated(inflated.view(), name, options, out);
  }
  return parseInflated(bytes, name, options, out);
}

FacetSoup readMesh(const std::filesystem::path& path, const MeshReadOptions& options, MeshSource* source) {
  const ByteBuffer file = readWholeFile(path);
  return parseMesh(file.view(), path.string(), options, source);
}

const char* meshFormatName(MeshFormat format) {
  switch (format) {
    case MeshFormat::Stl:
      return "STL";
    case MeshFormat::Ply:
      return "PLY";
    case MeshFormat::Obj:
      return "OBJ";
    case MeshFormat::ThreeMf:
      return "3MF";
  }
  return "?";
}

double parseUnits(const std::string& text) {
  if (text == "mm") return 1.0;
  if (text == "cm") return 10.0;
  if (text == "m") return 1000.0;
  if (text == "in") return 25.4;
  throw InputError("--units '" + text + "': expected mm, cm, m or in");
}

}  // namespace toposlice
