#include "io/readers/threemf_reader.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <zip.h>

#include "Model/COM/NMR_DLLInterfaces.h"
#include "io/readers/byte_input.h"
#include "io/readers/lib3mf_handle.h"

namespace toposlice {
namespace {

constexpr int kMaxComponentDepth = 32;
// What a model may expand to through its components (each placing an object again): the facets must fit
// the adjacency's int32 indices, and the placements themselves are bounded too (a few kilobytes of nested
// components can place a mesh 10^10 times, which ran for hours).
constexpr uint64_t kMaxFacets = 0x7fffffffu;
constexpr uint64_t kMaxPlacements = 100'000'000;

// Row-major 3x4 affine map, x' = m[0][0] x + m[0][1] y + m[0][2] z + m[0][3] (lib3mf's MODELTRANSFORM
// layout).
using Affine = std::array<std::array<double, 4>, 3>;

Affine identity() {
  return {{{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}}};
}

Affine fromLib3mf(const NMR::MODELTRANSFORM& t) {
  Affine a;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) a[r][c] = t.m_fFields[r][c];
  }
  return a;
}

// a after b: (a * b)(p) = a(b(p)).
Affine compose(const Affine& a, const Affine& b) {
  Affine out{};
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 4; ++c) {
      double v = c == 3 ? a[r][3] : 0.0;
      for (int k = 0; k < 3; ++k) v += a[r][k] * b[k][c];
      out[r][c] = v;
    }
  }
  return out;
}

double determinant(const Affine& m) {
  return m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) -
         m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0]) +
         m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
}

// Calls use(archive) with the zip `bytes` opened read-only; nothing when it cannot be opened.
template <class Use>
void withZip(std::span<const std::byte> bytes, Use&& use) {
  zip_error_t error;
  zip_error_init(&error);
  zip_source_t* source = zip_source_buffer_create(bytes.data(), bytes.size(), 0, &error);
  zip_t* archive = source != nullptr ? zip_open_from_source(source, ZIP_RDONLY, &error) : nullptr;
  if (archive == nullptr) {
    if (source != nullptr) zip_source_free(source);
  } else {
    use(archive);
    zip_discard(archive);  // frees the source too
  }
  zip_error_fini(&error);
}

// The first `limit` bytes (at most) of the zip entry `entry` of `bytes`, empty when there is none or it
// cannot be read.
std::string zipEntryText(std::span<const std::byte> bytes, const std::string& entry, std::size_t limit) {
  std::string text;
  withZip(bytes, [&](zip_t* archive) {
    zip_stat_t st;
    zip_stat_init(&st);
    if (zip_stat(archive, entry.c_str(), 0, &st) != 0 || !(st.valid & ZIP_STAT_SIZE)) return;
    if (zip_file_t* file = zip_fopen(archive, entry.c_str(), 0)) {
      text.resize(std::min<std::size_t>(st.size, limit));
      const zip_int64_t n = zip_fread(file, text.data(), text.size());
      text.resize(n > 0 ? static_cast<std::size_t>(n) : 0);
      zip_fclose(file);
    }
  });
  return text;
}

// The name of a part the zip `bytes` holds twice, empty when none is (or it cannot be opened: lib3mf
// says why then). Part names are compared as OPC compares them, ASCII case ignored: readers differ in
// which of two parts of one name they read (libzip the first, others the last), so the package does not
// say what its model is.
std::string twiceNamedEntry(std::span<const std::byte> bytes) {
  std::string twice;
  withZip(bytes, [&](zip_t* archive) {
    std::map<std::string, std::string> seen;  // lower case -> as named
    const zip_int64_t count = zip_get_num_entries(archive, 0);
    for (zip_int64_t i = 0; i < count && twice.empty(); ++i) {
      const char* name = zip_get_name(archive, static_cast<zip_uint64_t>(i), ZIP_FL_ENC_RAW);
      if (name == nullptr) continue;
      std::string key = name;
      for (char& c : key) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
      if (!seen.emplace(key, name).second) twice = name;
    }
  });
  return twice;
}

// Whether the zip `bytes` holds the entry `entry`.
bool zipHasEntry(std::span<const std::byte> bytes, const std::string& entry) {
  bool found = false;
  withZip(bytes, [&](zip_t* archive) { found = zip_name_locate(archive, entry.c_str(), 0) >= 0; });
  return found;
}

// The package without the relationships of _rels/.rels whose target part it does not hold, other than
// the root model's (PrusaSlicer's headless export names a thumbnail it leaves out, and lib3mf then
// refuses the whole package: "Could not create OPC Part"). Empty when nothing is missing or the
// package cannot be rewritten; a thumbnail is no part of the model.
std::vector<std::byte> withoutMissingParts(std::span<const std::byte> bytes, const std::string& root) {
  const std::string rels = zipEntryText(bytes, "_rels/.rels", 1 << 16);
  std::string kept = rels;
  bool removed = false;
  for (std::size_t t = kept.find("Target=\""); t != std::string::npos; t = kept.find("Target=\"", t + 1)) {
    const std::size_t close = kept.find('"', t + 8);
    if (close == std::string::npos) break;
    std::string target = kept.substr(t + 8, close - t - 8);
    if (!target.empty() && target[0] == '/') target.erase(0, 1);
    if (target.empty() || target == root || zipHasEntry(bytes, target)) continue;
    const std::size_t begin = kept.rfind('<', t), end = kept.find('>', t);
    if (begin == std::string::npos || end == std::string::npos) return {};
    kept.erase(begin, end + 1 - begin);
    removed = true;
    t = begin;
  }
  if (!removed) return {};
  // The copy is libzip's to free (freep 1): its buffer source frees the data it started from when a
  // write is committed, even with freep 0 (libzip 1.7), which freed a vector's storage under it.
  void* copy = std::malloc(bytes.size());
  if (copy == nullptr) return {};
  std::memcpy(copy, bytes.data(), bytes.size());
  zip_error_t error;
  zip_error_init(&error);
  std::vector<std::byte> out;
  zip_source_t* source = zip_source_buffer_create(copy, bytes.size(), 1, &error);
  if (source == nullptr) std::free(copy);
  zip_t* archive = source != nullptr ? zip_open_from_source(source, 0, &error) : nullptr;
  if (archive == nullptr) {
    if (source != nullptr) zip_source_free(source);
    zip_error_fini(&error);
    return out;
  }
  zip_source_keep(source);  // the archive's close writes the new package into it
  zip_source_t* relsSource = zip_source_buffer(archive, kept.data(), kept.size(), 0);
  bool written = false;
  if (relsSource != nullptr) {
    if (zip_file_add(archive, "_rels/.rels", relsSource, ZIP_FL_OVERWRITE) < 0)
      zip_source_free(relsSource);
    else
      written = zip_close(archive) == 0;
  }
  if (!written) {
    zip_discard(archive);
    zip_source_free(source);
    zip_error_fini(&error);
    return out;
  }
  zip_stat_t st;
  zip_stat_init(&st);
  if (zip_source_open(source) == 0) {
    if (zip_source_stat(source, &st) == 0 && (st.valid & ZIP_STAT_SIZE)) {
      out.resize(st.size);
      if (zip_source_read(source, out.data(), st.size) != static_cast<zip_int64_t>(st.size)) out.clear();
    }
    zip_source_close(source);
  }
  zip_source_free(source);
  zip_error_fini(&error);
  return out;
}

// The zip entry of the package's root model part, as its relationship names it.
std::string rootModelEntry(std::span<const std::byte> bytes) {
  std::string root = "3D/3dmodel.model";
  const std::string rels = zipEntryText(bytes, "_rels/.rels", 1 << 16);
  if (const std::size_t type = rels.find("/3dmodel\""); type != std::string::npos) {
    const std::size_t begin = rels.rfind('<', type), end = rels.find('>', type);
    // (A relationship without its '<' or '>', in a damaged package: the whole text around it.)
    const std::string relationship = rels.substr(
        begin == std::string::npos ? 0 : begin,
        end == std::string::npos ? std::string::npos : end - (begin == std::string::npos ? 0 : begin));
    if (const std::size_t t = relationship.find("Target=\""); t != std::string::npos) {
      const std::size_t close = relationship.find('"', t + 8);
      if (close != std::string::npos) root = relationship.substr(t + 8, close - t - 8);
    }
  }
  if (!root.empty() && root[0] == '/') root.erase(0, 1);
  return root;
}

// An attribute's value without the white space an XML schema number may have around it.
std::string trimmed(const std::string& value) {
  std::size_t first = 0, last = value.size();
  while (first < last && std::isspace(static_cast<unsigned char>(value[first]))) ++first;
  while (last > first && std::isspace(static_cast<unsigned char>(value[last - 1]))) --last;
  return value.substr(first, last - first);
}

// The value of attribute `name` in the tag text `tag` ("" when absent). (XML allows white space around the
// '='.)
std::string attributeOf(std::string_view tag, std::string_view name) {
  const auto space = [&](std::size_t i) {
    return i < tag.size() && std::isspace(static_cast<unsigned char>(tag[i]));
  };
  for (std::size_t at = tag.find(name); at != std::string_view::npos; at = tag.find(name, at + 1)) {
    if (at == 0 || !space(at - 1)) continue;
    std::size_t eq = at + name.size();
    while (space(eq)) ++eq;
    if (eq >= tag.size() || tag[eq] != '=') continue;
    std::size_t quote = eq + 1;
    while (space(quote)) ++quote;
    if (quote >= tag.size() || (tag[quote] != '"' && tag[quote] != '\'')) continue;
    const std::size_t close = tag.find(tag[quote], quote + 1);
    if (close != std::string_view::npos) return std::string(tag.substr(quote + 1, close - quote - 1));
  }
  return "";
}

// What a scan of the root model part's text finds wrong that lib3mf does not name (its messages name no
// element) or lets through: a vertex coordinate that is not a number, a triangle naming a vertex its
// mesh does not have, and, when lib3mf failed or found nothing (`readFailed`), a part cut short. ""
// when none is found.
std::string modelPartProblem(std::span<const std::byte> bytes, bool readFailed) {
  const std::string entry = rootModelEntry(bytes);
  if (readFailed) {  // a part the package's relationships name and it does not hold (lib3mf: "OPC Part")
    const std::string rels = zipEntryText(bytes, "_rels/.rels", 1 << 16);
    for (std::size_t t = rels.find("Target=\""); t != std::string::npos; t = rels.find("Target=\"", t + 1)) {
      const std::size_t close = rels.find('"', t + 8);
      if (close == std::string::npos) break;
      std::string target = rels.substr(t + 8, close - t - 8);
      if (!target.empty() && target[0] == '/') target.erase(0, 1);
      if (!target.empty() && !zipHasEntry(bytes, target))
        return "its relationships name the part /" + target + ", which the package does not hold";
    }
  }
  constexpr std::size_t kLimit = std::size_t{1} << 28;  // a larger part is not scanned
  const std::string model = zipEntryText(bytes, entry, kLimit);
  if (model.empty() || model.size() == kLimit) return "";
  std::string_view text(model);
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back()))) text.remove_suffix(1);
  if (readFailed && !text.ends_with("model>"))
    return "its model part " + entry + " is cut short (its XML ends before </model>)";
  for (std::size_t object = text.find("<object"); object != std::string_view::npos;
       object = text.find("<object", object + 1)) {
    const std::size_t end = text.find("</object>", object);
    const std::string_view body = text.substr(object, end == std::string_view::npos ? end : end - object);
    const std::string id = attributeOf(body.substr(0, body.find('>')), "id");
    uint64_t vertices = 0;
    for (std::size_t v = body.find("<vertex"); v != std::string_view::npos; v = body.find("<vertex", v + 1)) {
      if (body.substr(v, 9) == "<vertices") continue;
      // lib3mf reads a coordinate that is not a number ("abc", "1,5", "") as what it can of it, silently.
      const std::string_view tag = body.substr(v, body.find('>', v) - v);
      for (const char* axis : {"x", "y", "z"}) {
        const std::string value = attributeOf(tag, axis), number = trimmed(value);
        char* stop = nullptr;
        std::strtod(number.c_str(), &stop);
        if (number.empty() || stop == number.c_str() || *stop != '\0')
          return "object " + id + ", vertex " + std::to_string(vertices) + ": " + axis + "=\"" + value +
                 "\" is not a number";
      }
      ++vertices;
    }
    uint64_t triangle = 0;
    for (std::size_t t = body.find("<triangle"); t != std::string_view::npos;
         t = body.find("<triangle", t + 1)) {
      if (body.substr(t, 10) == "<triangles") continue;
      const std::string_view tag = body.substr(t, body.find('>', t) - t);
      for (const char* corner : {"v1", "v2", "v3"}) {
        const std::string value = attributeOf(tag, corner), number = trimmed(value);
        char* stop = nullptr;
        const long long index = std::strtoll(number.c_str(), &stop, 10);
        if (number.empty() || *stop != '\0' || index < 0 || static_cast<uint64_t>(index) >= vertices)
          return "object " + id + ", triangle " + std::to_string(triangle) + ": " + corner + "=\"" + value +
                 "\" is no vertex of its mesh (it has " + std::to_string(vertices) + ")";
      }
      ++triangle;
    }
  }
  return "";
}

// The start tag of the package's root model (`<model ...`, without its '>'); nullopt when the part does
// not open with one within its first 64 KiB.
std::optional<std::string> modelStartTag(std::span<const std::byte> bytes) {
  const std::string model = zipEntryText(bytes, rootModelEntry(bytes), 1 << 16);
  const std::size_t tag = model.find("<model");
  if (tag == std::string::npos) return std::nullopt;
  return model.substr(tag, model.find('>', tag) - tag);
}

// The first extension the root model lists in `requiredextensions` that this reader cannot honour, as
// "<namespace> (<what it holds>)"; "" when there is none. A consumer must not process a package whose
// required extensions it does not support (3MF Core Specification, "requiredextensions"): lib3mf reads
// beam lattices and slice stacks, but toposlice takes only the meshes, so a model whose geometry lies in
// beams, or whose mesh is a low-resolution stand-in for its slices, would be sliced wrong without a
// word. Materials and colours (no geometry) and the production extension (parts, components) are read.
std::string unsupportedRequiredExtension(const std::string& modelTag) {
  static constexpr std::string_view kRead[] = {
      "http://schemas.microsoft.com/3dmanufacturing/core/2015/02",
      "http://schemas.microsoft.com/3dmanufacturing/material/2015/02",
      "http://schemas.microsoft.com/3dmanufacturing/production/2015/06",
  };
  static constexpr std::pair<std::string_view, std::string_view> kKnown[] = {
      {"beamlattice", "beam lattices"},
      {"slice", "slice stacks; its mesh may be only a low-resolution stand-in"},
      {"securecontent", "encrypted parts"},
      {"volumetric", "volumetric data"},
      {"displacement", "displacement maps"},
      {"booleanoperations", "boolean shapes"},
  };
  const std::string required = attributeOf(modelTag, "requiredextensions");
  std::size_t at = 0;
  while (at < required.size()) {
    while (at < required.size() && std::isspace(static_cast<unsigned char>(required[at]))) ++at;
    std::size_t end = at;
    while (end < required.size() && !std::isspace(static_cast<unsigned char>(required[end]))) ++end;
    if (end == at) break;
    const std::string prefix = required.substr(at, end - at);
    at = end;
    const std::string space = attributeOf(modelTag, "xmlns:" + prefix);
    if (std::find(std::begin(kRead), std::end(kRead), space) != std::end(kRead)) continue;
    std::string what = "an extension toposlice does not know";
    for (const auto& [name, holds] : kKnown)
      if (space.find("/3dmanufacturing/" + std::string(name) + "/") != std::string::npos) what = holds;
    return (space.empty() ? "prefix '" + prefix + "'" : space) + " (" + what + ")";
  }
  return "";
}

// The unit attribute of the root model's start tag (modelStartTag), as written ("" when it states none,
// the millimetre). lib3mf takes a unit it does not know for millimetres without a word (unit="parsec"
// read 1:1), so the reader checks the attribute itself.
std::optional<std::string> statedUnit(const std::string& start) {
  const std::size_t unit = start.find(" unit=");
  if (unit == std::string::npos || unit + 7 > start.size()) return std::nullopt;
  const char quote = start[unit + 6];
  const std::size_t close = start.find(quote, unit + 7);
  if (close == std::string::npos) return std::nullopt;
  return start.substr(unit + 7, close - unit - 7);  // "" for unit="": no unit of the six either
}

class Reader {
 public:
  Reader(const std::string& name, double factor, ThreeMfSource& source, FacetSoup& soup)
      : name_(name), factor_(factor), source_(source), soup_(soup) {}

  void read(std::span<const std::byte> bytes) {
    Lib3mfHandle model, reader;
    check(NMR::lib3mf_createmodel(model.out()), nullptr, "cannot create a lib3mf model");
    check(NMR::lib3mf_model_queryreader(model.get(), "3mf", reader.out()), model.get(),
          "cannot create a reader");
    // lib3mf only reads the buffer; its interface is not const-correct.
    auto* data = const_cast<BYTE*>(reinterpret_cast<const BYTE*>(bytes.data()));
    if (NMR::lib3mf_reader_readfrombuffer(reader.get(), data, bytes.size()) != LIB3MF_OK) {
      const std::string why = lastError(reader.get()), problem = modelPartProblem(bytes, true);
      throwInputError(name_, "not a valid 3MF file: " + (problem.empty() ? why : problem + " (" + why + ")"));
    }
    // What lib3mf lets through (a coordinate that is not a number) or reads as nothing.
    if (const std::string problem = modelPartProblem(bytes, false); !problem.empty())
      throwInputError(name_, "not a valid 3MF file: " + problem);
    // The root model's start tag, inflated once for its required extensions and its unit.
    const std::optional<std::string> tag = modelStartTag(bytes);
    if (tag)
      if (const std::string extension = unsupportedRequiredExtension(*tag); !extension.empty())
        throwInputError(
            name_, "its model requires the 3MF extension " + extension + ", which toposlice does not read");
    DWORD unit = 0;
    check(NMR::lib3mf_model_getunit(model.get(), &unit), model.get(), "unit");
    setUnit(unit);
    if (const std::optional<std::string> stated = tag ? statedUnit(*tag) : std::nullopt;
        stated && *stated != source_.unit)
      throwInputError(name_, "unknown 3MF unit '" + *stated +
                                 "' (a 3MF states micron, millimeter, centimeter, inch, foot or meter)");

    Lib3mfHandle items;
    check(NMR::lib3mf_model_getbuilditems(model.get(), items.out()), model.get(), "build items");
    BOOL more = false;
    check(NMR::lib3mf_builditemiterator_movenext(items.get(), &more), items.get(), "build items");
    bool first = true;
    while (more) {
      Lib3mfHandle item, object;
      check(NMR::lib3mf_builditemiterator_getcurrent(items.get(), item.out()), items.get(), "build item");
      check(NMR::lib3mf_builditem_getobjectresource(item.get(), object.out()), item.get(),
            "build item object");
      const Affine placement = transformOf(item.get(), NMR::lib3mf_builditem_hasobjecttransform,
                                           NMR::lib3mf_builditem_getobjecttransform, "build item transform");
      if (first) source_.objectName = objectName(object.get());
      first = false;
      // The whole expansion is counted before any of it is placed (every object once: memoized).
      const Expansion e = expansionOf(object.get(), 0);
      facets_ = saturatingAdd(facets_, e.facets);
      placements_ = saturatingAdd(placements_, e.placements);
      if (facets_ > kMaxFacets || placements_ > kMaxPlacements)
        throwInputError(name_, "its build items expand through their components to " +
                                   (facets_ > kMaxFacets
                                        ? "more than " + std::to_string(kMaxFacets) + " facets"
                                        : "more than " + std::to_string(kMaxPlacements) + " placed objects") +
                                   ", more than toposlice slices");
      addObject(object.get(), placement, 0);
      check(NMR::lib3mf_builditemiterator_movenext(items.get(), &more), items.get(), "build items");
    }
    if (soup_.corners.empty()) {
      const std::string problem = modelPartProblem(bytes, true);
      throwInputError(name_, problem.empty() ? "contains no facets" : "not a valid 3MF file: " + problem);
    }
  }

 private:
  struct Expansion {
    uint64_t facets = 0, placements = 0;
  };
  static uint64_t saturatingAdd(uint64_t a, uint64_t b) { return a > UINT64_MAX - b ? UINT64_MAX : a + b; }

  // The facets and object placements that `object` expands to (supports skipped, as addObject does).
  Expansion expansionOf(NMR::PLib3MFBase* object, int depth) {
    if (depth > kMaxComponentDepth) {
      throwInputError(name_,
                      "components nested more than " + std::to_string(kMaxComponentDepth) + " levels deep");
    }
    DWORD id = 0;
    check(NMR::lib3mf_resource_getresourceid(object, &id), object, "object id");
    if (const auto it = expansions_.find(id); it != expansions_.end()) return it->second;
    Expansion e{0, 1};
    DWORD type = 0;
    check(NMR::lib3mf_object_gettype(object, &type), object, "object type");
    BOOL isMesh = false, isComponents = false;
    check(NMR::lib3mf_object_ismeshobject(object, &isMesh), object, "object");
    check(NMR::lib3mf_object_iscomponentsobject(object, &isComponents), object, "object");
    if (type == NMR::MODELOBJECTTYPE_SUPPORT || type == NMR::MODELOBJECTTYPE_SOLIDSUPPORT) {
      e.placements = 0;
    } else if (isMesh) {
      DWORD triangles = 0;
      check(NMR::lib3mf_meshobject_gettrianglecount(object, &triangles), object, "mesh");
      e.facets = triangles;
    } else if (isComponents) {
      forEachComponent(object, [&](NMR::PLib3MFBase*, NMR::PLib3MFBase* child) {
        const Expansion c = expansionOf(child, depth + 1);
        e.facets = saturatingAdd(e.facets, c.facets);
        e.placements = saturatingAdd(e.placements, c.placements);
      });
    }
    expansions_[id] = e;
    return e;
  }

  // The transform of a build item or component (`has` and `get` are lib3mf's functions for it), identity
  // when it states none.
  Affine transformOf(NMR::PLib3MFBase* owner, LIB3MFRESULT (*has)(NMR::PLib3MFBase*, BOOL*),
                     LIB3MFRESULT (*get)(NMR::PLib3MFBase*, NMR::MODELTRANSFORM*), const char* what) const {
    BOOL hasTransform = false;
    check(has(owner, &hasTransform), owner, what);
    if (!hasTransform) return identity();
    NMR::MODELTRANSFORM t;
    check(get(owner, &t), owner, what);
    return fromLib3mf(t);
  }

  void setUnit(DWORD unit) {
    struct Unit {
      const char* name;
      double mm;
    };
    static constexpr Unit kUnits[] = {{"micron", 0.001}, {"millimeter", 1.0}, {"centimeter", 10.0},
                                      {"inch", 25.4},    {"foot", 304.8},     {"meter", 1000.0}};
    if (unit >= std::size(kUnits)) throwInputError(name_, "unknown 3MF unit " + std::to_string(unit));
    source_.unit = kUnits[unit].name;
    source_.unitMm = kUnits[unit].mm;
  }

  void addObject(NMR::PLib3MFBase* object, const Affine& placement, int depth) {
    if (depth > kMaxComponentDepth) {
      throwInputError(name_,
                      "components nested more than " + std::to_string(kMaxComponentDepth) + " levels deep");
    }
    DWORD type = 0;
    check(NMR::lib3mf_object_gettype(object, &type), object, "object type");
    if (type == NMR::MODELOBJECTTYPE_SUPPORT || type == NMR::MODELOBJECTTYPE_SOLIDSUPPORT) {
      ++source_.supportsSkipped;
      return;
    }
    BOOL isMesh = false, isComponents = false;
    check(NMR::lib3mf_object_ismeshobject(object, &isMesh), object, "object");
    if (isMesh) return addMesh(object, placement);
    check(NMR::lib3mf_object_iscomponentsobject(object, &isComponents), object, "object");
    if (!isComponents) return;
    forEachComponent(object, [&](NMR::PLib3MFBase* component, NMR::PLib3MFBase* child) {
      const Affine local = transformOf(component, NMR::lib3mf_component_hastransform,
                                       NMR::lib3mf_component_gettransform, "component transform");
      addObject(child, compose(placement, local), depth + 1);
    });
  }

  // Calls visit(component, its object) for every component of a components object, in order.
  template <class Visit>
  void forEachComponent(NMR::PLib3MFBase* object, Visit&& visit) {
    DWORD count = 0;
    check(NMR::lib3mf_componentsobject_getcomponentcount(object, &count), object, "components");
    for (DWORD i = 0; i < count; ++i) {
      Lib3mfHandle component, child;
      check(NMR::lib3mf_componentsobject_getcomponent(object, i, component.out()), object, "component");
      check(NMR::lib3mf_component_getobjectresource(component.get(), child.out()), component.get(),
            "component object");
      visit(component.get(), child.get());
    }
  }

  void addMesh(NMR::PLib3MFBase* mesh, const Affine& placement) {
    DWORD vertexCount = 0, triangleCount = 0;
    check(NMR::lib3mf_meshobject_getvertexcount(mesh, &vertexCount), mesh, "mesh");
    check(NMR::lib3mf_meshobject_gettrianglecount(mesh, &triangleCount), mesh, "mesh");
    if (triangleCount == 0) return;
    vertices_.resize(vertexCount);
    triangles_.resize(triangleCount);
    check(NMR::lib3mf_meshobject_getvertices(mesh, vertices_.data(), vertexCount, nullptr), mesh, "vertices");
    check(NMR::lib3mf_meshobject_gettriangleindices(mesh, triangles_.data(), triangleCount, nullptr), mesh,
          "triangles");

    const double scale = source_.unitMm * factor_;
    placed_.resize(vertexCount);
    for (DWORD v = 0; v < vertexCount; ++v) {
      const float* p = vertices_[v].m_fPosition;
      double xyz[3];
      for (int r = 0; r < 3; ++r) {
        const double value = scale * (placement[r][0] * p[0] + placement[r][1] * p[1] +
                                      placement[r][2] * p[2] + placement[r][3]);
        if (!std::isfinite(value) || std::abs(value) > std::numeric_limits<float>::max()) {
          throwInputError(name_, "object '" + objectName(mesh) + "' vertex " + std::to_string(v) +
                                     ": coordinate not finite or beyond float's range once placed");
        }
        xyz[r] = value;
      }
      placed_[v] = {static_cast<float>(xyz[0]), static_cast<float>(xyz[1]), static_cast<float>(xyz[2])};
    }
    const bool mirrored = determinant(placement) < 0;
    // Grown geometrically (an exact reserve per placed mesh copied the whole soup at every one of 10^5
    // placements: quadratic).
    const std::size_t needed = soup_.corners.size() + 3 * std::size_t{triangleCount};
    if (needed > soup_.corners.capacity())
      soup_.corners.reserve(std::max(needed, 2 * soup_.corners.capacity()));
    for (DWORD t = 0; t < triangleCount; ++t) {
      const DWORD* i = triangles_[t].m_nIndices;
      if (i[0] >= vertexCount || i[1] >= vertexCount || i[2] >= vertexCount) {
        throwInputError(name_, "object '" + objectName(mesh) + "' triangle " + std::to_string(t) +
                                   ": vertex index out of range");
      }
      soup_.corners.push_back(placed_[i[0]]);
      soup_.corners.push_back(placed_[mirrored ? i[2] : i[1]]);
      soup_.corners.push_back(placed_[mirrored ? i[1] : i[2]]);
    }
  }

  std::string objectName(NMR::PLib3MFBase* object) const {
    ULONG needed = 0;
    if (NMR::lib3mf_object_getnameutf8(object, nullptr, 0, &needed) != LIB3MF_OK || needed == 0) return "";
    std::string text(needed + 1, '\0');
    if (NMR::lib3mf_object_getnameutf8(object, text.data(), needed + 1, &needed) != LIB3MF_OK) return "";
    text.resize(std::min<std::size_t>(needed, text.size()));
    while (!text.empty() && text.back() == '\0') text.pop_back();
    return text;
  }

  static std::string lastError(NMR::PLib3MFBase* instance) {
    DWORD code = 0;
    LPCSTR message = nullptr;
    if (instance == nullptr || NMR::lib3mf_getlasterror(instance, &code, &message) != LIB3MF_OK) {
      return "lib3mf gives no reason";
    }
    char hex[16];
    std::snprintf(hex, sizeof hex, "0x%x", static_cast<unsigned>(code));
    std::string text = message && *message ? message : "no message";
    return text + " (lib3mf error " + hex + ")";
  }

  void check(LIB3MFRESULT rc, NMR::PLib3MFBase* instance, const char* what) const {
    if (rc != LIB3MF_OK) throwInputError(name_, std::string("3MF ") + what + ": " + lastError(instance));
  }

  const std::string& name_;
  double factor_;
  ThreeMfSource& source_;
  FacetSoup& soup_;
  std::vector<NMR::MODELMESHVERTEX> vertices_;     // scratch, per mesh
  std::vector<NMR::MODELMESHTRIANGLE> triangles_;  // scratch, per mesh
  std::vector<Point3f> placed_;                    // scratch, per mesh
  std::map<DWORD, Expansion> expansions_;          // by object resource id
  uint64_t facets_ = 0, placements_ = 0;           // of the build items so far, expanded
};

}  // namespace

FacetSoup parseThreeMf(std::span<const std::byte> bytes, const std::string& name, double factor,
                       ThreeMfSource* source) {
  ThreeMfSource local;
  ThreeMfSource& out = source ? *source : local;
  out = ThreeMfSource{};
  FacetSoup soup;
  if (const std::string twice = twiceNamedEntry(bytes); !twice.empty())
    throwInputError(name, "not a valid 3MF file: its package holds two parts named " + twice +
                              ", and readers differ in which one they read");
  const std::vector<std::byte> repaired = withoutMissingParts(bytes, rootModelEntry(bytes));
  Reader(name, factor, out, soup).read(repaired.empty() ? bytes : std::span<const std::byte>(repaired));
  return soup;
}

}  // namespace toposlice
