// Strict JSON job files (batch jobs, plate jobs): the shared reader. Unknown keys, duplicate keys and
// wrong types are errors naming the key by its JSON path ("variants[2].masks"); relative paths are
// resolved against the job file's folder; every output is unique and no output is an input.
// Errors: InputError("<name>: <json path>: <what>").
#pragma once

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <initializer_list>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "io/errors.h"
#include "io/output_file.h"

namespace toposlice::jobjson {

using Json = nlohmann::json;
namespace fs = std::filesystem;

inline std::string childPath(const std::string& parent, std::string_view key) {
  return parent.empty() ? std::string(key) : parent + "." + std::string(key);
}

inline std::string indexPath(const std::string& parent, std::size_t index) {
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

inline std::string inQuotes(std::string_view s) {
  return "\"" + std::string(s) + "\"";
}

// Thrown out of the parser callback when an object repeats a key (nlohmann keeps the last silently).
struct DuplicateKey {
  std::string path;
};

// Follows the parser's events to know the JSON path of each key, and rejects repeated keys. For any
// nlohmann JSON type (the jobs' json, the profiles' ordered_json).
class DuplicateKeyGuard {
 public:
  template <class AnyJson>
  bool operator()(int /*depth*/, Json::parse_event_t event, AnyJson& parsed) {
    switch (event) {
      case Json::parse_event_t::object_start:
        frames_.emplace_back().array = false;
        break;
      case Json::parse_event_t::array_start:
        frames_.emplace_back().array = true;
        break;
      case Json::parse_event_t::key: {
        Frame& top = frames_.back();
        top.key = parsed.template get<std::string>();
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

// The text of a job file (at most 64 MiB). Throws InputError("<path>: <what>") for a folder, a file that
// cannot be read or one too large; `kind` names the file in messages ("batch job").
std::string readJobText(const fs::path& path, const char* kind);

// Base of the job parsers: typed accessors that fail with the JSON path, and the job's inputs and outputs.
class JsonReader {
 public:
  JsonReader(const fs::path& baseDir, const std::string& name) : baseDir_(baseDir), name_(name) {}

 protected:
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
    const std::string text = string(v, jsonPath);
    // JSON can hold "\u0000"; a path cannot (the system would read it cut short, another file).
    if (text.find('\0') != std::string::npos) fail(jsonPath, "a path holds no NUL character (\\u0000)");
    const fs::path p(text);
    const fs::path resolved = p.is_absolute() || baseDir_.empty() ? p : baseDir_ / p;
    return resolved.lexically_normal();
  }

  // A path as the file it names: links in its folders resolved ("same/o.cli" with same -> . is
  // "o.cli"), so two spellings of one file compare equal.
  static std::string fileKey(const fs::path& p) { return resolvedPath(p).string(); }

  fs::path input(const Json& v, const std::string& jsonPath) {
    fs::path p = path(v, jsonPath);
    inputs_.emplace(fileKey(p), jsonPath);
    return p;
  }

  fs::path output(const Json& v, const std::string& jsonPath) {
    fs::path p = path(v, jsonPath);
    if (!p.has_filename()) fail(jsonPath, p.string() + " names a folder, not a file");
    const auto [it, added] = outputs_.emplace(fileKey(p), jsonPath);
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

  // "units": mm per file unit (mm, cm, m, in).
  double unitsMm(const Json& v, const std::string& at) const {
    const std::string units = string(v, at);
    static const std::pair<const char*, double> kUnits[] = {
        {"mm", 1.0}, {"cm", 10.0}, {"m", 1000.0}, {"in", 25.4}};
    for (const auto& u : kUnits)
      if (units == u.first) return u.second;
    fail(at, "unknown unit " + inQuotes(units) + " (expected mm, cm, m or in)");
  }

  // "mirror": none, x, y or xy.
  void mirror(const Json& v, const std::string& at, std::optional<bool>& x, std::optional<bool>& y) const {
    const std::string m = string(v, at);
    if (m != "none" && m != "x" && m != "y" && m != "xy")
      fail(at, "unknown mirroring " + inQuotes(m) + " (expected none, x, y or xy)");
    x = m.find('x') != std::string::npos;
    y = m.find('y') != std::string::npos;
  }

  std::vector<fs::path> inputList(const Json& v, const std::string& at) {
    if (!v.is_array()) wrongType(v, at, "an array of paths");
    std::vector<fs::path> paths;
    for (std::size_t i = 0; i < v.size(); ++i) paths.push_back(input(v[i], indexPath(at, i)));
    return paths;
  }

  // "print_settings": an object of printer and material keys (io/jobs/profile.h) over the chosen
  // profiles, each value checked now (not after hours of slicing) and returned as text in order; a
  // light_map path is a job input, resolved against the job's folder.
  std::vector<std::pair<std::string, std::string>> printSettings(const Json& v, const std::string& at);

  // No file is both read and written by the job (the table counts as written: it may be created), and
  // nothing the job reads or writes lies inside one of its outputs (a folder of EXR or PNG layers is made
  // and replaced as a whole).
  void checkOutputs() const {
    for (const auto& [file, jsonPath] : outputs_) {
      if (const auto it = inputs_.find(file); it != inputs_.end()) {
        fail(jsonPath, file + " is also an input (" + it->second + ")");
      }
    }
    for (const auto* paths : {&outputs_, &inputs_})
      for (const auto& [file, jsonPath] : *paths)
        for (const auto& [folder, folderPath] : outputs_)
          if (file.size() > folder.size() + 1 && file.starts_with(folder) && file[folder.size()] == '/')
            fail(jsonPath, file + " lies inside " + folder + " (" + folderPath +
                               "), an output this job writes as a whole: give it a place outside");
  }

  fs::path baseDir_;
  std::string name_;
  std::map<std::string, std::string> inputs_;   // fileKey -> JSON path of its first use
  std::map<std::string, std::string> outputs_;  // fileKey -> JSON path
};

}  // namespace toposlice::jobjson
