#include "io/jobs/batch_job.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <fstream>
#include <initializer_list>
#include <iterator>
#include <map>
#include <set>
#include <system_error>

#include <nlohmann/json.hpp>

#include "core/number_text.h"
#include "io/errors.h"
#include "io/jobs/profile.h"

namespace toposlice {
namespace {

using Json = nlohmann::json;
namespace fs = std::filesystem;

constexpr std::uintmax_t kMaxJobFileSize = std::uintmax_t{64} << 20;

// The slicing methods parallel/band_slicer.h's parseSliceMethod accepts (io/ does not link parallel/).
constexpr std::array<std::string_view, 3> kMethods = {"sr", "sr-lazy", "cp"};

std::string childPath(const std::string& parent, std::string_view key) {
  return parent.empty() ? std::string(key) : parent + "." + std::string(key);
}

std::string indexPath(const std::string& parent, std::size_t index) {
  return parent + "[" + std::to_string(index) + "]";
}

template <std::size_t N>
std::string listOf(const std::array<std::string_view, N>& items) {
  std::string text;
  for (std::size_t i = 0; i < N; ++i) {
    if (i > 0) text += i + 1 == N ? " or " : ", ";
    text += items[i];
  }
  return text;
}

std::string inQuotes(std::string_view s) {
  return "\"" + std::string(s) + "\"";
}

// Thrown out of the parser callback when an object repeats a key (nlohmann keeps the last silently).
struct DuplicateKey {
  std::string path;
};

// Follows the parser's events to know the JSON path of each key, and rejects repeated keys.
class DuplicateKeyGuard {
 public:
  bool operator()(int /*depth*/, Json::parse_event_t event, Json& parsed) {
    switch (event) {
      case Json::parse_event_t::object_start:
        frames_.emplace_back().array = false;
        break;
      case Json::parse_event_t::array_start:
        frames_.emplace_back().array = true;
        break;
      case Json::parse_event_t::key: {
        Frame& top = frames_.back();
        top.key = parsed.get<std::string>();
        if (!top.keys.insert(top.key).second) throw DuplicateKey{currentPath()};
        break;
      }
      case Json::parse_event_t::value:
        elementDone();
        break;
      case Json::parse_event_t::object_end:
      case Json::parse_event_t::array_end:
        frames_.pop_back();
        elementDone();
        break;
    }
    return true;
  }

 private:
  struct Frame {
    bool array = false;
    std::size_t index = 0;  // arrays: the element being parsed
    std::string key;        // objects: the member being parsed
    std::set<std::string> keys;
  };

  void elementDone() {
    if (!frames_.empty() && frames_.back().array) ++frames_.back().index;
  }

  std::string currentPath() const {
    std::string path;
    for (const Frame& f : frames_) path = f.array ? indexPath(path, f.index) : childPath(path, f.key);
    return path;
  }

  std::vector<Frame> frames_;
};

class JobParser {
 public:
  JobParser(const fs::path& baseDir, const std::string& name) : baseDir_(baseDir), name_(name) {}

  BatchJob parse(std::string_view text) {
    const Json root = parseJson(text);
    if (!root.is_object())
      fail("", "expected a JSON object at the top, got " + std::string(root.type_name()));
    checkKeys(root, "", {"version", "description", "template", "settings", "variants"});
    if (const Json* v = find(root, "version")) {
      const uint64_t version = whole(*v, "version", 0, UINT32_MAX);
      if (version != 1)
        fail("version", "unsupported batch job version " + std::to_string(version) + " (this build reads 1)");
    }
    if (const Json* v = find(root, "description")) job_.description = string(*v, "description", true);
    parseTemplate(require(root, "", "template"));
    parseSettings(find(root, "settings"));
    parseVariants(require(root, "", "variants"));
    checkOutputs();
    return std::move(job_);
  }

 private:
  [[noreturn]] void fail(const std::string& path, const std::string& what) const {
    throw InputError(name_ + ": " + (path.empty() ? "" : path + ": ") + what);
  }

  Json parseJson(std::string_view text) const {
    try {
      return Json::parse(text.begin(), text.end(), DuplicateKeyGuard(), true, false);
    } catch (const DuplicateKey& d) {
      fail(d.path, "duplicate key (each key may appear once per object)");
    } catch (const Json::parse_error& e) {
      // e.byte counts from 1 and points just past the offending character.
      const std::size_t at = std::min(e.byte == 0 ? 0 : e.byte - 1, text.size());
      const std::size_t line =
          1 + static_cast<std::size_t>(std::count(text.begin(), text.begin() + at, '\n'));
      const std::size_t lineStart = text.rfind('\n', at == 0 ? 0 : at - 1);
      const std::size_t column = lineStart == std::string_view::npos || at == 0 ? at + 1 : at - lineStart;
      std::string what = e.what();
      if (const std::size_t colon = what.find(": "); colon != std::string::npos)
        what = what.substr(colon + 2);
      throw InputError(name_ + ":" + std::to_string(line) + ":" + std::to_string(column) +
                       ": invalid JSON: " + what);
    } catch (const Json::exception& e) {  // out_of_range 406: a number too large for a double
      std::string what = e.what();
      if (const std::size_t bracket = what.find("] "); bracket != std::string::npos)
        what = what.substr(bracket + 2);
      throw InputError(name_ + ": invalid JSON: " + what);
    }
  }

  void checkKeys(const Json& object, const std::string& path,
                 std::initializer_list<std::string_view> allowed) const {
    for (const auto& [key, value] : object.items()) {
      if (std::find(allowed.begin(), allowed.end(), key) != allowed.end()) continue;
      std::string expected;
      for (const std::string_view a : allowed) expected += (expected.empty() ? "" : ", ") + std::string(a);
      fail(childPath(path, key), "unknown key (expected one of: " + expected + ")");
    }
  }

  static const Json* find(const Json& object, std::string_view key) {
    const auto it = object.find(key);
    return it == object.end() ? nullptr : &*it;
  }

  const Json& require(const Json& object, const std::string& path, std::string_view key) const {
    const Json* v = find(object, key);
    if (v == nullptr) fail(childPath(path, key), "missing (required)");
    return *v;
  }

  [[noreturn]] void wrongType(const Json& v, const std::string& path, const char* expected) const {
    fail(path, std::string("expected ") + expected + ", got " + v.type_name());
  }

  const Json& object(const Json& v, const std::string& path) const {
    if (!v.is_object()) wrongType(v, path, "an object");
    return v;
  }

  std::string string(const Json& v, const std::string& path, bool allowEmpty = false) const {
    if (!v.is_string()) wrongType(v, path, "a string");
    std::string s = v.get<std::string>();
    if (s.empty() && !allowEmpty) fail(path, "must not be empty");
    return s;
  }

  double number(const Json& v, const std::string& path) const {
    if (!v.is_number()) wrongType(v, path, "a number");
    return v.get<double>();
  }

  double positive(const Json& v, const std::string& path) const {
    const double x = number(v, path);
    if (!(x > 0)) fail(path, "must be positive, got " + v.dump());
    return x;
  }

  bool boolean(const Json& v, const std::string& path) const {
    if (!v.is_boolean()) wrongType(v, path, "true or false");
    return v.get<bool>();
  }

  uint64_t whole(const Json& v, const std::string& path, uint64_t min, uint64_t max) const {
    if (!v.is_number()) wrongType(v, path, "a whole number");
    bool inRange = false;
    uint64_t value = 0;
    if (v.is_number_unsigned()) {
      value = v.get<uint64_t>();
      inRange = true;
    } else if (v.is_number_integer()) {
      inRange = v.get<int64_t>() >= 0;
      if (inRange) value = static_cast<uint64_t>(v.get<int64_t>());
    } else {
      const double d = v.get<double>();
      if (d != std::floor(d)) fail(path, "must be a whole number, got " + v.dump());
      inRange = d >= 0 && d <= static_cast<double>(max);
      if (inRange) value = static_cast<uint64_t>(d);
    }
    if (!inRange || value < min || value > max) {
      fail(path,
           "must be between " + std::to_string(min) + " and " + std::to_string(max) + ", got " + v.dump());
    }
    return value;
  }

  // A non-empty path string, resolved against the job's folder and normalised.
  fs::path path(const Json& v, const std::string& jsonPath) {
    const fs::path p(string(v, jsonPath));
    const fs::path resolved = p.is_absolute() || baseDir_.empty() ? p : baseDir_ / p;
    return resolved.lexically_normal();
  }

  fs::path input(const Json& v, const std::string& jsonPath) {
    fs::path p = path(v, jsonPath);
    inputs_.emplace(p.string(), jsonPath);
    return p;
  }

  fs::path output(const Json& v, const std::string& jsonPath) {
    fs::path p = path(v, jsonPath);
    if (!p.has_filename()) fail(jsonPath, p.string() + " names a folder, not a file");
    const auto [it, added] = outputs_.emplace(p.string(), jsonPath);
    if (!added) fail(jsonPath, p.string() + " is already written by " + it->second);
    return p;
  }

  template <std::size_t N>
  fs::path output(const Json& v, const std::string& jsonPath,
                  const std::array<std::string_view, N>& extensions, const char* kind) {
    fs::path p = output(v, jsonPath);
    std::string ext = p.extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    if (std::find(extensions.begin(), extensions.end(), ext) == extensions.end()) {
      fail(jsonPath, std::string("unknown ") + kind + " format " + inQuotes(p.extension().string()) +
                         " (expected " + listOf(extensions) + ")");
    }
    return p;
  }

  void parseTemplate(const Json& v) {
    const std::string at = "template";
    object(v, at);
    checkKeys(v, at, {"model", "table"});
    if (const Json* m = find(v, "model")) job_.templateModel = input(*m, childPath(at, "model"));
    // The table is read when it exists and written otherwise, so it must not collide with any other file.
    if (const Json* t = find(v, "table")) job_.templateFile = output(*t, childPath(at, "table"));
    if (job_.templateModel.empty() && job_.templateFile.empty()) {
      fail(at, "give model (the template mesh), table (its .topo file) or both");
    }
  }

  void parseSettings(const Json* v) {
    const std::string at = "settings";
    if (v == nullptr) fail(at, "missing (required: the slicing planes, layer_height, layers or z)");
    object(*v, at);
    checkKeys(*v, at,
              {"layer_height", "layers", "z0",         "z",       "method",    "join_tolerance", "printer",
               "pixel",        "origin", "resolution", "mirror",  "antialias", "cli_binary",     "threads",
               "overwrite",    "units",  "scale",      "profile", "material",  "print_settings"});
    const auto key = [&](std::string_view k) { return childPath(at, k); };
    if (const Json* x = find(*v, "layer_height")) job_.layerHeight = positive(*x, key("layer_height"));
    if (const Json* x = find(*v, "layers")) {
      job_.layers = static_cast<uint32_t>(whole(*x, key("layers"), 1, UINT32_MAX));
    }
    if (const Json* x = find(*v, "z0")) job_.z0 = number(*x, key("z0"));
    if (const Json* x = find(*v, "z")) {
      if (job_.layerHeight || job_.layers || job_.z0) {
        fail(key("z"), "an explicit list of planes cannot be combined with layer_height, layers or z0");
      }
      if (!x->is_array()) wrongType(*x, key("z"), "an array of numbers");
      if (x->empty()) fail(key("z"), "must list at least one plane");
      for (std::size_t i = 0; i < x->size(); ++i) {
        const double z = number((*x)[i], indexPath(key("z"), i));
        if (i > 0 && !(z > job_.explicitZ.back())) {
          fail(indexPath(key("z"), i), "planes must be strictly ascending (" + (*x)[i].dump() + " follows " +
                                           (*x)[i - 1].dump() + ")");
        }
        job_.explicitZ.push_back(z);
      }
    } else if (!job_.layerHeight && !job_.layers) {
      fail(at, "give the slicing planes: layer_height, layers (with optional z0) or z");
    }
    if (const Json* x = find(*v, "method")) {
      job_.method = string(*x, key("method"));
      if (std::find(kMethods.begin(), kMethods.end(), job_.method) == kMethods.end()) {
        fail(key("method"),
             "unknown slicing method " + inQuotes(job_.method) + " (expected " + listOf(kMethods) + ")");
      }
    }
    if (const Json* x = find(*v, "join_tolerance")) {
      const double tol = number(*x, key("join_tolerance"));
      if (!(tol >= 0)) fail(key("join_tolerance"), "must not be negative, got " + x->dump());
      job_.joinTolerance = tol;
    }
    if (const Json* x = find(*v, "printer")) job_.printer = string(*x, key("printer"));
    if (const Json* x = find(*v, "pixel")) job_.pixel = positive(*x, key("pixel"));
    if (const Json* x = find(*v, "origin")) {
      if (!x->is_array() || x->size() != 2) wrongType(*x, key("origin"), "[x0, y0] in mm");
      job_.origin = {number((*x)[0], indexPath(key("origin"), 0)),
                     number((*x)[1], indexPath(key("origin"), 1))};
    }
    if (const Json* x = find(*v, "resolution")) {
      if (!x->is_array() || x->size() != 2) wrongType(*x, key("resolution"), "[width, height] in pixels");
      job_.resolution = {
          static_cast<uint32_t>(whole((*x)[0], indexPath(key("resolution"), 0), 1, UINT32_MAX)),
          static_cast<uint32_t>(whole((*x)[1], indexPath(key("resolution"), 1), 1, UINT32_MAX))};
    }
    if (const Json* x = find(*v, "mirror")) {
      const std::string mirror = string(*x, key("mirror"));
      if (mirror != "none" && mirror != "x" && mirror != "y" && mirror != "xy") {
        fail(key("mirror"), "unknown mirroring " + inQuotes(mirror) + " (expected none, x, y or xy)");
      }
      job_.mirrorX = mirror.find('x') != std::string::npos;
      job_.mirrorY = mirror.find('y') != std::string::npos;
    }
    if (const Json* x = find(*v, "antialias")) job_.antialias = boolean(*x, key("antialias"));
    if (const Json* x = find(*v, "cli_binary")) job_.cliBinary = boolean(*x, key("cli_binary"));
    if (const Json* x = find(*v, "threads"))
      job_.threads = static_cast<uint32_t>(whole(*x, key("threads"), 0, 4096));
    if (const Json* x = find(*v, "overwrite")) job_.overwrite = boolean(*x, key("overwrite"));
    if (const Json* x = find(*v, "units")) {
      const std::string units = string(*x, key("units"));
      static const std::pair<const char*, double> kUnits[] = {
          {"mm", 1.0}, {"cm", 10.0}, {"m", 1000.0}, {"in", 25.4}};
      const auto* found =
          std::find_if(std::begin(kUnits), std::end(kUnits), [&](const auto& u) { return units == u.first; });
      if (found == std::end(kUnits))
        fail(key("units"), "unknown unit " + inQuotes(units) + " (expected mm, cm, m or in)");
      job_.unitMm = found->second;
    }
    if (const Json* x = find(*v, "scale")) job_.scale = positive(*x, key("scale"));
    if (const Json* x = find(*v, "profile")) job_.profile = input(*x, key("profile"));
    if (const Json* x = find(*v, "material")) job_.material = string(*x, key("material"));
    if (const Json* x = find(*v, "print_settings")) {
      object(*x, key("print_settings"));
      PrintSettings check;  // every key and value checked now, not after hours of slicing
      for (const auto& [k, value] : x->items()) {
        const std::string where = childPath(key("print_settings"), k);
        std::string text;
        if (value.is_string())
          text = value.get<std::string>();
        else if (value.is_boolean())
          text = value.get<bool>() ? "1" : "0";
        else if (value.is_number_float())
          text = formatNumber(value.get<double>());
        else if (value.is_number())
          text = value.dump();
        else
          wrongType(value, where, "a number, a string or true/false");
        if (k == "light_map" && !text.empty()) text = input(value, where).string();
        try {
          assignSetting(check, k, text, "print_settings");
        } catch (const InputError& e) {
          std::string what = e.what();
          if (what.starts_with("print_settings: ")) what = what.substr(16);
          fail(where, what);
        }
        job_.printSettings.emplace_back(k, text);
      }
    }
  }

  std::vector<fs::path> inputList(const Json& v, const std::string& at) {
    if (!v.is_array()) wrongType(v, at, "an array of paths");
    std::vector<fs::path> paths;
    for (std::size_t i = 0; i < v.size(); ++i) paths.push_back(input(v[i], indexPath(at, i)));
    return paths;
  }

  void parseVariants(const Json& v) {
    if (!v.is_array()) wrongType(v, "variants", "an array of variants");
    if (v.empty()) fail("variants", "must list at least one variant");
    std::map<std::string, std::string> names;  // name -> JSON path of its first use
    for (std::size_t i = 0; i < v.size(); ++i) {
      const std::string at = indexPath("variants", i);
      const Json& item = object(v[i], at);
      checkKeys(item, at, {"name", "model", "contours", "masks", "report", "add", "remove"});
      BatchVariant variant;
      variant.name = string(require(item, at, "name"), childPath(at, "name"));
      if (const auto [it, added] = names.emplace(variant.name, at); !added) {
        fail(childPath(at, "name"), inQuotes(variant.name) + " is already the name of " + it->second);
      }
      variant.model = input(require(item, at, "model"), childPath(at, "model"));
      if (const Json* x = find(item, "contours")) {
        variant.contours = output(*x, childPath(at, "contours"), kBatchContourExtensions, "contour");
      }
      if (const Json* x = find(item, "masks")) {
        variant.masks = output(*x, childPath(at, "masks"), kBatchMaskExtensions, "mask");
      }
      if (const Json* x = find(item, "report")) variant.report = output(*x, childPath(at, "report"));
      if (variant.contours.empty() && variant.masks.empty() && variant.report.empty()) {
        fail(at, "no output (give contours, masks and/or report)");
      }
      if (const Json* x = find(item, "add")) variant.add = inputList(*x, childPath(at, "add"));
      if (const Json* x = find(item, "remove")) variant.remove = inputList(*x, childPath(at, "remove"));
      job_.variants.push_back(std::move(variant));
    }
  }

  // No file is both read and written by the job (the table counts as written: it may be created).
  void checkOutputs() const {
    for (const auto& [file, jsonPath] : outputs_) {
      if (const auto it = inputs_.find(file); it != inputs_.end()) {
        fail(jsonPath, file + " is also an input (" + it->second + ")");
      }
    }
  }

  fs::path baseDir_;
  std::string name_;
  BatchJob job_;
  std::map<std::string, std::string> inputs_;   // normalised path -> JSON path of its first use
  std::map<std::string, std::string> outputs_;  // normalised path -> JSON path
};

}  // namespace

BatchJob parseBatchJob(std::string_view text, const std::filesystem::path& baseDir, const std::string& name) {
  return JobParser(baseDir, name).parse(text);
}

BatchJob readBatchJob(const std::filesystem::path& path) {
  const std::string name = path.string();
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    throw InputError(name + ": is a directory, not a batch job file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(name + ": cannot open: " + std::generic_category().message(errno));
  const std::uintmax_t size = std::filesystem::file_size(path, ec);
  if (!ec && size > kMaxJobFileSize) {
    throw InputError(name + ": " + std::to_string(size) + " bytes is too large for a batch job file");
  }
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw InputError(name + ": read error");
  BatchJob job = parseBatchJob(text, std::filesystem::absolute(path).parent_path(), name);
  job.sourceFile = std::filesystem::absolute(path);
  return job;
}

}  // namespace toposlice
