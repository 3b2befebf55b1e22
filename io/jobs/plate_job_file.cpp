#include "io/jobs/plate_job_file.h"

#include "core/chunk_runner.h"
#include "core/print/printer.h"
#include "io/jobs/batch_job.h"  // kBatchMaskExtensions: every mask format but the PNG folder
#include "io/jobs/json_reader.h"
#include "io/jobs/profile.h"

namespace toposlice {
namespace {

using namespace jobjson;

constexpr std::array<std::string_view, 3> kMethods = {"sr", "sr-lazy", "cp"};
constexpr std::array<std::string_view, 3> kContourExtensions = {".cli", ".svg", ".3mf"};
constexpr std::array<std::string_view, 1> kReportExtensions = {".json"};
constexpr std::array<std::string_view, 1> kPictureExtensions = {".png"};

class PlateParser : public JsonReader {
 public:
  using JsonReader::JsonReader;

  PlateJob parse(std::string_view text) {
    const Json root = parseJson(text);
    if (!root.is_object())
      fail("", "expected a JSON object at the top, got " + std::string(root.type_name()));
    checkKeys(root, "",
              {"version", "description", "printer", "material", "profile", "print_settings", "settings",
               "arrange", "parts", "outputs"});
    if (const Json* v = find(root, "version"); v && whole(*v, "version", 0, UINT32_MAX) != 1)
      fail("version", "unsupported plate job version " + v->dump() + " (this build reads 1)");
    if (const Json* v = find(root, "description")) job_.description = string(*v, "description", true);
    if (const Json* v = find(root, "printer")) job_.printer = string(*v, "printer");
    if (const Json* v = find(root, "material")) job_.material = string(*v, "material");
    if (const Json* v = find(root, "profile")) job_.profile = input(*v, "profile");
    if (const Json* v = find(root, "print_settings"))
      job_.printSettings = printSettings(*v, "print_settings");
    if (const Json* v = find(root, "settings")) parseSettings(object(*v, "settings"));
    if (const Json* v = find(root, "arrange")) parseArrange(object(*v, "arrange"));
    if (job_.printer.empty() && job_.profile.empty() && !(job_.pixel && job_.resolution))
      fail("printer",
           "missing (give a printer preset, a profile file with its printer, or settings.pixel and "
           "settings.resolution)");
    parseParts(require(root, "", "parts"));
    parseOutputs(object(require(root, "", "outputs"), "outputs"));
    checkOutputs();
    checkSettingsApply(root);
    return std::move(job_);
  }

 private:
  // Settings that cannot apply to this job are errors, not silently ignored (as on slice's command line).
  void checkSettingsApply(const Json& root) {
    std::vector<std::filesystem::path> masks;
    if (!job_.masks.empty()) masks.push_back(job_.masks);
    bool anyCli = false, anyTemplate = false, anyAuto = false;
    for (const auto& c : job_.contours) anyCli = anyCli || lowerExtension(c) == ".cli";
    for (const PlatePart& p : job_.parts) {
      anyTemplate = anyTemplate || !p.templateFile.empty();
      anyAuto = anyAuto || !p.placement;
    }
    const auto needs = [&](const char* section, const char* k, bool applies, const char* what) {
      const Json* s = find(root, section);
      if (s != nullptr && find(*s, k) != nullptr && !applies)
        fail(childPath(section, k), std::string("does nothing in this job: it needs ") + what);
    };
    needs("settings", "antialias", !masks.empty(), "outputs.masks");
    needs("settings", "mirror", !masks.empty(), "outputs.masks");
    needs("settings", "cli_binary", anyCli, "a .cli contour output");
    needs("settings", "allow_rebuild", anyTemplate, "a part with a template");
    if (anyTemplate && job_.method == "cp")
      fail(childPath("settings", "method"),
           "cp uses no adjacency table, so the parts' templates would do nothing (use sr or sr-lazy, or "
           "drop the templates)");
    needs("arrange", "rotation_step", anyAuto, "a part placed \"auto\"");
    for (const auto& [k, value] : job_.printSettings)
      if (const std::string why = settingUnusedReason(k, masks, "outputs.masks"); !why.empty())
        fail(childPath("print_settings", k), "does nothing in this job: " + why);
  }

  void parseSettings(const Json& v) {
    const std::string at = "settings";
    checkKeys(v, at,
              {"layer_height", "z0", "method", "pixel", "resolution", "build_height", "mirror", "antialias",
               "cli_binary", "threads", "overwrite", "units", "scale", "allow_rebuild", "fix_orientation"});
    const auto key = [&](std::string_view k) { return childPath(at, k); };
    if (const Json* x = find(v, "layer_height")) job_.layerHeight = positive(*x, key("layer_height"));
    if (const Json* x = find(v, "z0")) job_.z0 = number(*x, key("z0"));
    if (const Json* x = find(v, "method")) {
      job_.method = string(*x, key("method"));
      if (std::find(kMethods.begin(), kMethods.end(), job_.method) == kMethods.end())
        fail(key("method"),
             "unknown slicing method " + inQuotes(job_.method) + " (expected " + listOf(kMethods) + ")");
    }
    if (const Json* x = find(v, "pixel")) job_.pixel = positive(*x, key("pixel"));
    if (const Json* x = find(v, "resolution")) {
      if (!x->is_array() || x->size() != 2) wrongType(*x, key("resolution"), "[width, height] in pixels");
      job_.resolution = {
          static_cast<uint32_t>(whole((*x)[0], indexPath(key("resolution"), 0), 1, kMaxImageSide)),
          static_cast<uint32_t>(whole((*x)[1], indexPath(key("resolution"), 1), 1, kMaxImageSide))};
    }
    if (const Json* x = find(v, "build_height")) {
      job_.buildHeight = number(*x, key("build_height"));
      if (!(*job_.buildHeight >= 0)) fail(key("build_height"), "must not be negative, got " + x->dump());
    }
    if (const Json* x = find(v, "mirror")) mirror(*x, key("mirror"), job_.mirrorX, job_.mirrorY);
    if (const Json* x = find(v, "antialias")) job_.antialias = boolean(*x, key("antialias"));
    if (const Json* x = find(v, "cli_binary")) job_.cliBinary = boolean(*x, key("cli_binary"));
    if (const Json* x = find(v, "threads"))
      job_.threads = static_cast<uint32_t>(whole(*x, key("threads"), 0, kMaxThreads));
    if (const Json* x = find(v, "overwrite")) job_.overwrite = boolean(*x, key("overwrite"));
    if (const Json* x = find(v, "units")) job_.unitMm = unitsMm(*x, key("units"));
    if (const Json* x = find(v, "scale")) job_.scale = positive(*x, key("scale"));
    if (const Json* x = find(v, "allow_rebuild")) job_.allowRebuild = boolean(*x, key("allow_rebuild"));
    if (const Json* x = find(v, "fix_orientation")) job_.fixOrientation = boolean(*x, key("fix_orientation"));
  }

  double nonNegative(const Json& v, const std::string& at) const {
    const double x = number(v, at);
    if (!(x >= 0) || !std::isfinite(x)) fail(at, "must be a finite number >= 0, got " + v.dump());
    return x;
  }

  void parseArrange(const Json& v) {
    const std::string at = "arrange";
    checkKeys(v, at, {"spacing", "margin", "rotation_step", "cell"});
    const auto key = [&](std::string_view k) { return childPath(at, k); };
    if (const Json* x = find(v, "spacing")) job_.spacing = nonNegative(*x, key("spacing"));
    if (const Json* x = find(v, "margin")) job_.margin = nonNegative(*x, key("margin"));
    if (const Json* x = find(v, "rotation_step")) {
      if (x->is_string() && x->get<std::string>() == "free") {
        job_.rotationStep = 10;
      } else {
        job_.rotationStep = nonNegative(*x, key("rotation_step"));
        if (job_.rotationStep >= 360)
          fail(key("rotation_step"), "must be below 360 degrees, got " + x->dump());
        // Every rotation is tried for every part at every free position: a step of 1e-5 degrees ran for
        // minutes in gigabytes. One degree is finer than a plate's cells tell apart.
        if (job_.rotationStep > 0 && job_.rotationStep < 1)
          fail(key("rotation_step"), "must be 0 (no rotation) or at least 1 degree, got " + x->dump());
      }
    }
    if (const Json* x = find(v, "cell")) {
      job_.cell = positive(*x, key("cell"));
      if (job_.cell < 0.05) fail(key("cell"), "must be at least 0.05 mm, got " + x->dump());
    }
  }

  void parseParts(const Json& v) {
    if (!v.is_array()) wrongType(v, "parts", "an array of parts");
    if (v.empty()) fail("parts", "must list at least one part");
    std::map<std::string, std::string> names;
    for (std::size_t i = 0; i < v.size(); ++i) {
      const std::string at = indexPath("parts", i);
      const Json& item = object(v[i], at);
      checkKeys(item, at, {"name", "model", "template", "add", "remove", "placement"});
      PlatePart part;
      part.name = string(require(item, at, "name"), childPath(at, "name"));
      if (const auto [it, added] = names.emplace(part.name, at); !added)
        fail(childPath(at, "name"), inQuotes(part.name) + " is already the name of " + it->second);
      part.model = input(require(item, at, "model"), childPath(at, "model"));
      if (const Json* x = find(item, "template")) part.templateFile = input(*x, childPath(at, "template"));
      if (const Json* x = find(item, "add")) part.add = inputList(*x, childPath(at, "add"));
      if (const Json* x = find(item, "remove")) part.remove = inputList(*x, childPath(at, "remove"));
      const std::string pat = childPath(at, "placement");
      const Json& p = require(item, at, "placement");
      if (p.is_string()) {
        if (p.get<std::string>() != "auto") fail(pat, "expected \"auto\" or {\"x\", \"y\", \"rotation\"}");
      } else {
        checkKeys(object(p, pat), pat, {"x", "y", "rotation"});
        PlatePlacement placement;
        placement.x = number(require(p, pat, "x"), childPath(pat, "x"));
        placement.y = number(require(p, pat, "y"), childPath(pat, "y"));
        if (const Json* r = find(p, "rotation")) {
          placement.rotation = number(*r, childPath(pat, "rotation"));
          if (!(std::abs(placement.rotation) <= 360))  // 1e300 turned the part by a rounding remainder
            fail(childPath(pat, "rotation"),
                 "must be a number of degrees from -360 to 360, got " + r->dump());
        }
        if (!std::isfinite(placement.x) || !std::isfinite(placement.y) || !std::isfinite(placement.rotation))
          fail(pat, "must hold finite numbers");
        // No plate is a kilometre wide; 1e308 made the outside-the-plate message print "inf mm".
        for (const auto& [value, axis] : {std::pair{placement.x, "x"}, std::pair{placement.y, "y"}})
          if (!(std::abs(value) <= 1e6))
            fail(childPath(pat, axis),
                 "must be a position on the plate in mm (at most 1e6), got " + p[axis].dump());
        part.placement = placement;
      }
      job_.parts.push_back(std::move(part));
    }
  }

  void parseOutputs(const Json& v) {
    const std::string at = "outputs";
    checkKeys(v, at, {"masks", "contours", "report", "picture"});
    const auto key = [&](std::string_view k) { return childPath(at, k); };
    // A mask format, or a name without an extension: a folder of PNGs (as slice --masks).
    if (const Json* x = find(v, "masks"))
      job_.masks = path(*x, key("masks")).has_extension()
                       ? output(*x, key("masks"), kBatchMaskExtensions, "mask")
                       : output(*x, key("masks"));
    if (const Json* x = find(v, "contours")) {
      if (!x->is_array()) wrongType(*x, key("contours"), "an array of paths");
      for (std::size_t i = 0; i < x->size(); ++i)
        job_.contours.push_back(
            output((*x)[i], indexPath(key("contours"), i), kContourExtensions, "contour"));
    }
    if (const Json* x = find(v, "report"))
      job_.report = output(*x, key("report"), kReportExtensions, "report");
    if (const Json* x = find(v, "picture")) {
      job_.picture = output(*x, key("picture"), kPictureExtensions, "picture");
      if (job_.masks.empty())
        fail(key("picture"), "the picture is drawn from the masks: give outputs.masks too");
    }
    if (job_.masks.empty() && job_.contours.empty() && job_.report.empty())
      fail(at, "no output (give masks, contours and/or report)");
  }

  PlateJob job_;
};

}  // namespace

PlateJob parsePlateJob(std::string_view text, const std::filesystem::path& baseDir, const std::string& name) {
  return PlateParser(baseDir, name).parse(text);
}

PlateJob readPlateJob(const std::filesystem::path& path) {
  const std::string text = readJobText(path, "plate job");
  PlateJob job = parsePlateJob(text, std::filesystem::absolute(path).parent_path(), path.string());
  job.sourceFile = std::filesystem::absolute(path);
  return job;
}

std::filesystem::path plateOutputPath(const std::filesystem::path& path, uint32_t plate) {
  if (plate == 0) return path;
  std::filesystem::path out = path;
  out.replace_filename(path.stem().string() + "-plate" + std::to_string(plate + 1) +
                       path.extension().string());
  return out;
}

}  // namespace toposlice
