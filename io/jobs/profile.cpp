#include "io/jobs/profile.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>

#include "core/edit_distance.h"
#include "core/number_text.h"
#include "core/print/printer.h"
#include "io/errors.h"
#include "io/jobs/json_reader.h"
#include "io/output_file.h"

namespace toposlice {
namespace {

enum class Kind { Number, Count, Flag, Text, Path };

// A key's storage and range. Numbers must be finite and in [min, max] (min excluded when minOpen).
struct KeyRule {
  Kind kind;
  double min, max;
  bool minOpen;
  double& (*number)(PrintSettings&);
  uint32_t& (*count)(PrintSettings&);
  bool& (*flag)(PrintSettings&);
  std::string& (*text)(PrintSettings&);
  std::filesystem::path& (*path)(PrintSettings&);
  std::string (*show)(const PrintSettings&);
};

constexpr double kHuge = 1e9;

KeyRule number(double min, bool minOpen, double max, double& (*ref)(PrintSettings&),
               std::string (*show)(const PrintSettings&)) {
  return {Kind::Number, min, max, minOpen, ref, nullptr, nullptr, nullptr, nullptr, show};
}
KeyRule count(double min, double max, uint32_t& (*ref)(PrintSettings&),
              std::string (*show)(const PrintSettings&)) {
  return {Kind::Count, min, max, false, nullptr, ref, nullptr, nullptr, nullptr, show};
}
KeyRule flag(bool& (*ref)(PrintSettings&), std::string (*show)(const PrintSettings&)) {
  return {Kind::Flag, 0, 1, false, nullptr, nullptr, ref, nullptr, nullptr, show};
}
KeyRule text(std::string& (*ref)(PrintSettings&), std::string (*show)(const PrintSettings&)) {
  return {Kind::Text, 0, 0, false, nullptr, nullptr, nullptr, ref, nullptr, show};
}
KeyRule path(std::filesystem::path& (*ref)(PrintSettings&), std::string (*show)(const PrintSettings&)) {
  return {Kind::Path, 0, 0, false, nullptr, nullptr, nullptr, nullptr, ref, show};
}

#define TS_NUMBER(member)                               \
  [](PrintSettings& s) -> double& { return s.member; }, \
      [](const PrintSettings& s) { return formatNumber(s.member); }
#define TS_COUNT(member)                                  \
  [](PrintSettings& s) -> uint32_t& { return s.member; }, \
      [](const PrintSettings& s) { return std::to_string(s.member); }
#define TS_FLAG(member)                               \
  [](PrintSettings& s) -> bool& { return s.member; }, \
      [](const PrintSettings& s) { return std::string(s.member ? "1" : "0"); }
#define TS_TEXT(member) \
  [](PrintSettings& s) -> std::string& { return s.member; }, [](const PrintSettings& s) { return s.member; }

constexpr SettingOwner P = SettingOwner::Printer;
constexpr SettingOwner M = SettingOwner::Material;

const SettingKey kKeys[] = {
    {"printer_model", P, "printer model written into SL1 archives (printerModel), e.g. SL1, SL1S", false},
    {"display_pixels_x", P, "display width in pixels", false},
    {"display_pixels_y", P, "display height in pixels", false},
    {"display_width", P, "display width in mm (pixel size = display_width / display_pixels_x)", false},
    {"display_height", P, "display height in mm (must give the same, square, pixel size)", false},
    {"display_orientation", P,
     "landscape, or portrait: images display_pixels_y wide and display_pixels_x tall, as PrusaSlicer writes "
     "them",
     false},
    {"display_mirror_x", P, "mirror the images in x (0 or 1; in portrait, as PrusaSlicer means it)", false},
    {"display_mirror_y", P, "mirror the images in y (0 or 1; in portrait, as PrusaSlicer means it)", false},
    {"max_print_height", P, "mm; a model taller than this (after corrections) is refused; 0: no limit",
     false},
    {"relative_correction_x", P, "printer scaling correction in x (factor)", false},
    {"relative_correction_y", P, "printer scaling correction in y (factor)", false},
    {"relative_correction_z", P, "printer scaling correction in z (factor; changes the layer count)", false},
    {"absolute_correction", P, "mm; every slice grown (+) or shrunk (-) by this distance", false},
    {"elefant_foot_compensation", P, "mm; the first layer(s) shrunk by this distance", false},
    {"elefant_foot_min_width", P,
     "mm; the elephant foot makes no feature narrower than this (thinner ones keep their width)", false},
    {"elefant_foot_layers", P,
     "layers over which the elephant-foot shrink fades to 0 (default: the material's faded_layers, as "
     "PrusaSlicer)",
     true},
    {"gamma_correction", P, "anti-aliasing gamma; 0: binary masks (pixel-centre rule); 1: linear coverage",
     false},
    {"light_map", P, "grayscale PNG of the display's relative intensity, multiplied into every layer", true},
    {"lift_distance", P, "mm; platform lift after each layer (GOO, NanoDLP)", true},
    {"lift_speed", P, "mm/min; platform lift speed", true},
    {"bottom_lift_distance", P, "mm; platform lift after the bottom layers", true},
    {"bottom_lift_speed", P, "mm/min; platform lift speed after the bottom layers", true},
    {"retract_speed", P, "mm/min; platform speed back down to the next layer", true},
    {"wait_before_exposure", P, "s; resin settling time before each exposure", true},
    {"light_pwm", P, "UV light power 0..255", true},
    {"exposure_time", M, "s; exposure of every layer after the fade", false},
    {"initial_exposure_time", M, "s; exposure of the first layer", false},
    {"faded_layers", M, "layers of the fade from initial_exposure_time to exposure_time (3..20)", false},
    {"material_correction_x", M, "material scaling correction in x (factor)", false},
    {"material_correction_y", M, "material scaling correction in y (factor)", false},
    {"material_correction_z", M, "material scaling correction in z (factor)", false},
    {"material_density", M, "g/ml; for the resin mass in the summary", false},
};

KeyRule ruleOf(std::string_view key) {
  if (key == "printer_model") return text(TS_TEXT(printerModel));
  if (key == "display_pixels_x") return count(1, kMaxImageSide, TS_COUNT(pixelsX));
  if (key == "display_pixels_y") return count(1, kMaxImageSide, TS_COUNT(pixelsY));
  if (key == "display_width") return number(0, false, 1e5, TS_NUMBER(displayWidth));
  if (key == "display_height") return number(0, false, 1e5, TS_NUMBER(displayHeight));
  if (key == "display_orientation") return text(TS_TEXT(orientation));
  if (key == "display_mirror_x") return flag(TS_FLAG(mirrorX));
  if (key == "display_mirror_y") return flag(TS_FLAG(mirrorY));
  if (key == "max_print_height") return number(0, false, 1e5, TS_NUMBER(maxPrintHeight));
  if (key == "relative_correction_x") return number(0, true, 10, TS_NUMBER(relativeCorrection[0]));
  if (key == "relative_correction_y") return number(0, true, 10, TS_NUMBER(relativeCorrection[1]));
  if (key == "relative_correction_z") return number(0, true, 10, TS_NUMBER(relativeCorrection[2]));
  if (key == "absolute_correction") return number(-10, false, 10, TS_NUMBER(absoluteCorrection));
  if (key == "elefant_foot_compensation") return number(0, false, 10, TS_NUMBER(elefantFootCompensation));
  if (key == "elefant_foot_min_width") return number(0, false, 100, TS_NUMBER(elefantFootMinWidth));
  if (key == "elefant_foot_layers")
    return count(
        1, 10000, [](PrintSettings& s) -> uint32_t& { return s.elefantFootLayers; },
        [](const PrintSettings& s) { return std::to_string(s.elephantFootFadeLayers()); });
  if (key == "gamma_correction")
    return number(
        0, false, 10, [](PrintSettings& s) -> double& { return s.gammaCorrection.emplace(); },
        [](const PrintSettings& s) {
          return s.gammaCorrection ? formatNumber(*s.gammaCorrection) : std::string();
        });
  if (key == "light_map")
    return path([](PrintSettings& s) -> std::filesystem::path& { return s.lightMap; },
                [](const PrintSettings& s) { return s.lightMap.string(); });
  if (key == "lift_distance") return number(0, false, 1000, TS_NUMBER(liftDistance));
  if (key == "lift_speed") return number(0, true, 1e5, TS_NUMBER(liftSpeed));
  if (key == "bottom_lift_distance") return number(0, false, 1000, TS_NUMBER(bottomLiftDistance));
  if (key == "bottom_lift_speed") return number(0, true, 1e5, TS_NUMBER(bottomLiftSpeed));
  if (key == "retract_speed") return number(0, true, 1e5, TS_NUMBER(retractSpeed));
  if (key == "wait_before_exposure") return number(0, false, 1000, TS_NUMBER(waitBeforeExposure));
  if (key == "light_pwm") return count(0, 255, TS_COUNT(lightPwm));
  if (key == "exposure_time") return number(0, true, 1000, TS_NUMBER(exposureTime));
  if (key == "initial_exposure_time") return number(0, true, 1000, TS_NUMBER(initialExposureTime));
  if (key == "faded_layers") return count(3, 20, TS_COUNT(fadedLayers));
  if (key == "material_correction_x") return number(0, true, 10, TS_NUMBER(materialCorrection[0]));
  if (key == "material_correction_y") return number(0, true, 10, TS_NUMBER(materialCorrection[1]));
  if (key == "material_correction_z") return number(0, true, 10, TS_NUMBER(materialCorrection[2]));
  if (key == "material_density") return number(0, true, 100, TS_NUMBER(materialDensity));
  return {Kind::Text, 0, 0, false, nullptr, nullptr, nullptr, nullptr, nullptr, nullptr};
}

#undef TS_NUMBER
#undef TS_COUNT
#undef TS_FLAG
#undef TS_TEXT

const SettingKey* findKey(std::string_view name) {
  for (const SettingKey& k : kKeys)
    if (name == k.name) return &k;
  return nullptr;
}

// Whether `text` holds a control character (a line break, a tab, DEL): never in a setting or a profile
// name, which go into line-based files (config.ini, prusaslicer.ini) and one-line messages.
bool hasControlCharacter(std::string_view text) {
  return std::any_of(text.begin(), text.end(), [](char c) {
    const auto u = static_cast<unsigned char>(c);
    return u < 0x20 || u == 0x7f;
  });
}

// `text` for a one-line message: control characters written as \n, \r, \t or \xNN.
std::string printable(std::string_view text) {
  std::string out;
  for (const char c : text) {
    const auto u = static_cast<unsigned char>(c);
    if (u >= 0x20 && u != 0x7f) {
      out += c;
    } else if (c == '\n') {
      out += "\\n";
    } else if (c == '\r') {
      out += "\\r";
    } else if (c == '\t') {
      out += "\\t";
    } else {
      static constexpr char kHex[] = "0123456789abcdef";
      out += "\\x";
      out += kHex[u >> 4];
      out += kHex[u & 15];
    }
  }
  return out;
}

std::string unknownKeyMessage(std::string_view key) {
  const SettingKey* nearest = nullptr;
  std::size_t best = 4;
  for (const SettingKey& k : kKeys) {
    const std::size_t d = editDistance(key, k.name);
    if (d < best) best = d, nearest = &k;
  }
  std::string message = "unknown setting '" + std::string(key) + "'";
  if (nearest) message += " (did you mean '" + std::string(nearest->name) + "'?)";
  return message + "; the settings are listed in docs/FORMATS.md, \"Profile files\"";
}

bool parseDouble(std::string_view text, double& value) {
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, value);
  return ec == std::errc{} && ptr == end && !text.empty();
}

// Built-in printer presets as assignments (core/print/printer.h keeps the grid figures of the old --printer).
std::vector<std::pair<std::string, std::string>> printerPreset(const PrinterPreset& p) {
  std::vector<std::pair<std::string, std::string>> a = {
      {"printer_model", p.model},
      {"display_pixels_x", std::to_string(p.width)},
      {"display_pixels_y", std::to_string(p.height)},
  };
  if (p.pixel > 0) {
    // In whole nanometres, as a user types them (120.96, not 120.96000000000001); 120.96 / 2560 is
    // 0.04725 exactly again, so the grid is the preset's.
    a.emplace_back("display_width", formatNumber(std::round(p.width * p.pixel * 1e6) / 1e6));
    a.emplace_back("display_height", formatNumber(std::round(p.height * p.pixel * 1e6) / 1e6));
  }
  if (p.buildHeight > 0) a.emplace_back("max_print_height", formatNumber(p.buildHeight));
  if (p.portrait) {
    a.emplace_back("display_orientation", "portrait");
    a.emplace_back("display_mirror_x", "1");
  }
  return a;
}

// Built-in materials: "default" is toposlice's fixed exposure before profiles existed.
const std::pair<const char*, std::vector<std::pair<std::string, std::string>>> kMaterials[] = {
    {"default", {{"exposure_time", "8"}, {"initial_exposure_time", "35"}, {"faded_layers", "10"}}},
};

using Json = nlohmann::ordered_json;

std::string jsonValueText(const Json& value, const std::string& where) {
  if (value.is_string()) return value.get<std::string>();
  if (value.is_boolean()) return value.get<bool>() ? "true" : "false";  // for flags only: not a number
  if (value.is_number_integer() || value.is_number_unsigned()) return value.dump();
  if (value.is_number_float()) return formatNumber(value.get<double>());
  throw InputError(where + ": expected a number, a string or true/false, got " + value.dump());
}

struct ProfileFile {
  std::filesystem::path path;
  Json root;
};

ProfileFile readProfileFile(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  if (!in) throw InputError(file.string() + ": cannot read the profile file");
  std::stringstream buffer;
  buffer << in.rdbuf();
  ProfileFile profile{file, {}};
  const std::string text = buffer.str();
  try {
    // A repeated key is refused, as in job files (nlohmann would keep the last silently).
    profile.root = Json::parse(text.begin(), text.end(), jobjson::DuplicateKeyGuard(), true, false);
  } catch (const jobjson::DuplicateKey& d) {
    throw InputError(file.string() + ": " + d.path + ": duplicate key (each key may appear once per object)");
  } catch (const nlohmann::json::exception& e) {  // parse errors, and out_of_range 406: a number too large
    throw InputError(file.string() + ": invalid JSON: " + e.what());
  }
  if (!profile.root.is_object()) throw InputError(file.string() + ": expected a JSON object at the top");
  for (const auto& [key, value] : profile.root.items()) {
    if (key != "printers" && key != "materials" && key != "description")
      throw InputError(file.string() + ": unknown key '" + key +
                       "' (expected printers, materials, description)");
    if (key != "description" && !value.is_object())
      throw InputError(file.string() + ": " + key + ": expected an object of named profiles");
    if (key != "description")
      for (const auto& [name, entry] : value.items())
        if (hasControlCharacter(name) || name.empty())
          throw InputError(file.string() + ": " + key + ": the name '" + printable(name) +
                           "' is empty or holds a control character (names go into the printer files)");
  }
  return profile;
}

const Json* fileProfile(const ProfileFile* file, const char* section, const std::string& name) {
  if (file == nullptr || !file->root.contains(section)) return nullptr;
  const Json& s = file->root[section];
  return s.contains(name) ? &s[name] : nullptr;
}

// Applies the named printer or material (from the file, else built in), after what it inherits.
// `askedWhere`: where the name was given ("--printer", "job.json: settings.printer"), which an unknown
// name's message starts with; empty for an inherited name (the entry that inherits it names itself).
void applyProfile(PrintSettings& settings, const ProfileFile* file, SettingOwner owner,
                  const std::string& name, int depth, const std::string& askedWhere = {}) {
  const std::string askedAt = askedWhere.empty() ? std::string() : askedWhere + ": ";
  const char* section = owner == SettingOwner::Printer ? "printers" : "materials";
  const char* what = owner == SettingOwner::Printer ? "printer" : "material";
  if (depth > 16) {
    // A circle, or a straight chain that deep: which one, by walking on from here.
    std::set<std::string> seen;
    std::string at = name;
    bool circle = false;
    for (const Json* p = fileProfile(file, section, at);
         p != nullptr && p->is_object() && p->contains("inherits") && (*p)["inherits"].is_string();
         p = fileProfile(file, section, at)) {
      if (!seen.insert(at).second) {
        circle = true;
        break;
      }
      at = (*p)["inherits"].get<std::string>();
    }
    throw InputError(std::string(what) + " '" + name + "': " +
                     (circle ? "'inherits' goes round in a circle"
                             : "'inherits' goes more than 16 levels deep, more than a profile may"));
  }
  if (const Json* profile = fileProfile(file, section, name)) {
    const std::string where = file->path.string() + ": " + section + "." + name;
    if (!profile->is_object()) throw InputError(where + ": expected an object of settings");
    if (profile->contains("inherits")) {
      const Json& parent = (*profile)["inherits"];
      if (!parent.is_string()) throw InputError(where + ".inherits: expected a profile name");
      try {
        applyProfile(settings, file, owner, parent.get<std::string>(), depth + 1);
      } catch (const InputError& e) {
        // A built-in name that does not exist says so without the file: name where it was asked for.
        const std::string message = e.what();
        if (message.starts_with(file->path.string() + ": ")) throw;
        throw InputError(where + ".inherits: " + message);
      }
    }
    const std::string origin = "profile " + file->path.filename().string() + " " + what + " " + name;
    for (const auto& [key, value] : profile->items()) {
      if (key == "inherits") continue;
      const SettingKey* k = findKey(key);
      if (k == nullptr) throw InputError(where + ": " + unknownKeyMessage(key));
      if (k->owner != owner)
        throw InputError(
            where + ": " + key + " is a " + (k->owner == SettingOwner::Printer ? "printer" : "material") +
            " setting: put it under " + (k->owner == SettingOwner::Printer ? "printers" : "materials"));
      std::string valueText = jsonValueText(value, where + "." + key);
      // A light map named in a file is relative to the file's folder.
      if (key == "light_map" && !valueText.empty() && std::filesystem::path(valueText).is_relative())
        valueText = (file->path.parent_path() / valueText).lexically_normal().string();
      assignSetting(settings, key, valueText, origin);
    }
    return;
  }
  if (owner == SettingOwner::Printer) {
    const auto preset = findPrinter(name);
    if (!preset) {
      std::string known = printerNames();
      if (file && file->root.contains("printers"))
        for (const auto& [n, v] : file->root["printers"].items()) known += ", " + n;
      throw InputError(askedAt + "unknown printer '" + printable(name) + "' (known: " + known + ")");
    }
    for (const auto& [key, value] : printerPreset(*preset))
      assignSetting(settings, key, value, "printer " + std::string(preset->name));
    return;
  }
  for (const auto& [materialName, assignments] : kMaterials) {
    if (name != materialName) continue;
    for (const auto& [key, value] : assignments) assignSetting(settings, key, value, "material " + name);
    settings.origin.erase("exposure_time");  // the built-in default is no choice of the user's
    settings.origin.erase("initial_exposure_time");
    settings.origin.erase("faded_layers");
    return;
  }
  std::string known = builtInMaterialNames();
  if (file && file->root.contains("materials"))
    for (const auto& [n, v] : file->root["materials"].items()) known += ", " + n;
  throw InputError(askedAt + "unknown material '" + printable(name) + "' (known: " + known + ")");
}

// The file's only entry of a section, if it has exactly one.
std::string onlyEntry(const ProfileFile* file, const char* section) {
  if (file == nullptr || !file->root.contains(section) || file->root[section].size() != 1) return {};
  return file->root[section].items().begin().key();
}

}  // namespace

namespace {

bool maskFormatCarries(const std::string& ext, std::string_view key) {
  static constexpr std::string_view kExposure[] = {"exposure_time", "initial_exposure_time", "faded_layers"};
  static constexpr std::string_view kNanoDlpMotion[] = {"lift_distance", "lift_speed", "retract_speed",
                                                        "wait_before_exposure"};
  const auto in = [key](std::span<const std::string_view> list) {
    return std::find(list.begin(), list.end(), key) != list.end();
  };
  if (ext == ".goo" || ext == ".exr" || ext == ".vdb") return true;
  if (ext == ".sl1" || ext == ".sl1s") return key == "printer_model" || in(kExposure);
  if (ext == ".nanodlp") return in(kExposure) || in(kNanoDlpMotion);
  return false;  // a folder of PNGs carries no settings
}

}  // namespace

std::string settingUnusedReason(std::string_view key, std::span<const std::filesystem::path> maskOutputs,
                                std::string_view maskOutputName, bool summary) {
  if (key == "material_density") {  // it only turns the resin volume into a mass where one is written
    if (summary) return "";
    for (const auto& path : maskOutputs)
      for (const char* ext : {".sl1", ".sl1s", ".goo", ".exr", ".vdb"})
        if (lowerExtension(path) == ext) return "";
    return "it gives the resin mass of a summary and of .sl1, .goo, .exr and .vdb masks";
  }
  static constexpr std::string_view kPrinterFileOnly[] = {
      "printer_model",        "exposure_time",     "initial_exposure_time",
      "faded_layers",         "lift_distance",     "lift_speed",
      "bottom_lift_distance", "bottom_lift_speed", "retract_speed",
      "wait_before_exposure", "light_pwm"};
  const bool fileOnly =
      std::find(std::begin(kPrinterFileOnly), std::end(kPrinterFileOnly), key) != std::end(kPrinterFileOnly);
  const bool maskOnly =
      fileOnly || key.starts_with("display_") || key == "gamma_correction" || key == "light_map";
  if (!maskOnly) return "";
  if (maskOutputs.empty()) return "it needs " + std::string(maskOutputName);
  if (!fileOnly) return "";
  std::string formats;
  for (const auto& path : maskOutputs) {
    const std::string ext = lowerExtension(path);
    if (maskFormatCarries(ext, key)) return "";
    const std::string name = ext.empty() ? "a folder of PNGs" : ext;
    if (formats.find(name) == std::string::npos) formats += (formats.empty() ? "" : ", ") + name;
  }
  std::string carriers;
  for (const char* ext : {".sl1", ".goo", ".nanodlp", ".exr", ".vdb"})
    if (maskFormatCarries(ext, key)) carriers += (carriers.empty() ? "" : ", ") + std::string(ext);
  return "the masks (" + formats + ") do not carry it; " + carriers + " masks do";
}

std::span<const SettingKey> settingKeys() {
  return kKeys;
}

std::string builtInMaterialNames() {
  std::string names;
  for (const auto& m : kMaterials) names += (names.empty() ? "" : ", ") + std::string(m.first);
  return names;
}

void assignSetting(PrintSettings& settings, std::string_view key, std::string_view value,
                   const std::string& origin) {
  if (findKey(key) == nullptr) throw InputError(origin + ": " + unknownKeyMessage(key));
  const KeyRule rule = ruleOf(key);
  const std::string where = origin + ": " + std::string(key) + " '" + printable(value) + "'";
  // A line break in printer_model would start another key = value line in config.ini (an exposure the
  // user never set): refused, as every control character.
  if (hasControlCharacter(value))
    throw InputError(where + ": a setting is one line without control characters");
  switch (rule.kind) {
    case Kind::Number:
    case Kind::Count: {
      double v = 0;
      if (!parseDouble(value, v) || !std::isfinite(v)) throw InputError(where + ": expected a number");
      const bool below = rule.minOpen ? !(v > rule.min) : v < rule.min;
      if (below || v > rule.max)
        throw InputError(where + ": expected a value " + (rule.minOpen ? "> " : ">= ") +
                         formatNumber(rule.min) + " and <= " + formatNumber(rule.max));
      if (rule.kind == Kind::Count) {
        if (v != std::floor(v)) throw InputError(where + ": expected a whole number");
        rule.count(settings) = static_cast<uint32_t>(v);
      } else {
        rule.number(settings) = v;
      }
      break;
    }
    case Kind::Flag:
      if (value == "1" || value == "true")
        rule.flag(settings) = true;
      else if (value == "0" || value == "false")
        rule.flag(settings) = false;
      else
        throw InputError(where + ": expected 0 or 1");
      break;
    case Kind::Text:
      if (key == "display_orientation" && value != "landscape" && value != "portrait")
        throw InputError(where + ": expected landscape or portrait");
      if (value.empty()) throw InputError(where + ": expected a value");
      rule.text(settings) = std::string(value);
      break;
    case Kind::Path:
      rule.path(settings) = std::filesystem::path(value);
      break;
  }
  settings.origin[std::string(key)] = origin;
}

PrintSettings resolvePrintSettings(const ProfileChoice& choice) {
  for (const auto& [name, where] :
       {std::pair{&choice.printer, &choice.printerWhere}, std::pair{&choice.material, &choice.materialWhere}})
    if (hasControlCharacter(*name))
      throw InputError((where->empty() ? std::string() : *where + ": ") + "'" + printable(*name) +
                       "': a printer or material name holds no control characters");
  std::optional<ProfileFile> file;
  if (!choice.file.empty()) file = readProfileFile(choice.file);
  const ProfileFile* f = file ? &*file : nullptr;
  PrintSettings settings;
  std::string printer = choice.printer.empty() ? onlyEntry(f, "printers") : choice.printer;
  if (!printer.empty()) {
    // A name that is neither in the file nor built in is reported where it was given.
    applyProfile(settings, f, SettingOwner::Printer, printer, 0,
                 choice.printer.empty() ? std::string() : choice.printerWhere);
    settings.printerName = printer;
  }
  std::string material = choice.material.empty() ? onlyEntry(f, "materials") : choice.material;
  if (material.empty()) material = "default";
  applyProfile(settings, f, SettingOwner::Material, material, 0,
               choice.material.empty() ? std::string() : choice.materialWhere);
  settings.materialName = material;
  for (const auto& [key, value] : choice.overrides)
    assignSetting(settings, key, value, choice.overrideOrigin);
  return settings;
}

void applyJobMirror(PrintSettings& settings, std::optional<bool> mirrorX, std::optional<bool> mirrorY,
                    const std::string& origin) {
  if (mirrorX) assignSetting(settings, "display_mirror_x", *mirrorX ? "1" : "0", origin);
  if (mirrorY) assignSetting(settings, "display_mirror_y", *mirrorY ? "1" : "0", origin);
}

std::vector<std::pair<std::string, std::string>> settingValues(const PrintSettings& settings) {
  std::vector<std::pair<std::string, std::string>> values;
  for (const SettingKey& k : kKeys) values.emplace_back(k.name, ruleOf(k.name).show(settings));
  return values;
}

}  // namespace toposlice
