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

#include "core/chunk_runner.h"
#include "core/print/printer.h"
#include "core/slicing/planes.h"
#include "io/errors.h"
#include "io/jobs/json_reader.h"
#include "io/jobs/profile.h"

namespace toposlice {
namespace {

using namespace jobjson;

// The slicing methods parallel/band_slicer.h's parseSliceMethod accepts (io/ does not link parallel/).
constexpr std::array<std::string_view, 3> kMethods = {"sr", "sr-lazy", "cp"};

class JobParser : public JsonReader {
 public:
  using JsonReader::JsonReader;

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
    checkSettingsApply(root);
    return std::move(job_);
  }

 private:
  void parseTemplate(const Json& v) {
    const std::string at = "template";
    object(v, at);
    checkKeys(v, at, {"model", "table"});
    if (const Json* m = find(v, "model")) job_.templateModel = input(*m, childPath(at, "model"));
    // The table is read when it exists and written otherwise, so it must not collide with any other file.
    if (const Json* t = find(v, "table"))
      job_.templateFile = output(*t, childPath(at, "table"), kTableExtensions, "table");
    if (job_.templateModel.empty() && job_.templateFile.empty()) {
      fail(at, "give model (the template mesh), table (its .topo file) or both");
    }
  }

  void parseSettings(const Json* v) {
    const std::string at = "settings";
    if (v == nullptr) fail(at, "missing (required: the slicing planes, layer_height, layers or z)");
    object(*v, at);
    checkKeys(*v, at, {"layer_height",   "layers",    "z0",         "z",        "method",
                       "join_tolerance", "printer",   "pixel",      "origin",   "resolution",
                       "mirror",         "antialias", "cli_binary", "threads",  "overwrite",
                       "units",          "scale",     "profile",    "material", "print_settings",
                       "fix_orientation"});
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
      if (!(tol > 0)) fail(key("join_tolerance"), "must be positive (a distance in mm), got " + x->dump());
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
          static_cast<uint32_t>(whole((*x)[0], indexPath(key("resolution"), 0), 1, kMaxImageSide)),
          static_cast<uint32_t>(whole((*x)[1], indexPath(key("resolution"), 1), 1, kMaxImageSide))};
    }
    if (const Json* x = find(*v, "mirror")) mirror(*x, key("mirror"), job_.mirrorX, job_.mirrorY);
    if (const Json* x = find(*v, "antialias")) job_.antialias = boolean(*x, key("antialias"));
    if (const Json* x = find(*v, "cli_binary")) job_.cliBinary = boolean(*x, key("cli_binary"));
    if (const Json* x = find(*v, "threads"))
      job_.threads = static_cast<uint32_t>(whole(*x, key("threads"), 0, kMaxThreads));
    if (const Json* x = find(*v, "overwrite")) job_.overwrite = boolean(*x, key("overwrite"));
    if (const Json* x = find(*v, "fix_orientation"))
      job_.fixOrientation = boolean(*x, key("fix_orientation"));
    if (const Json* x = find(*v, "units")) job_.unitMm = unitsMm(*x, key("units"));
    if (const Json* x = find(*v, "scale")) job_.scale = positive(*x, key("scale"));
    if (const Json* x = find(*v, "profile")) job_.profile = input(*x, key("profile"));
    if (const Json* x = find(*v, "material")) job_.material = string(*x, key("material"));
    if (const Json* x = find(*v, "print_settings"))
      job_.printSettings = printSettings(*x, key("print_settings"));
  }

  // Settings that cannot apply to any variant are errors, not silently ignored (as on slice's command
  // line): mask settings without a variant that writes masks, cli_binary without .cli contours, a join
  // tolerance for the default method, printer-file settings no variant's mask format carries.
  void checkSettingsApply(const Json& root) {
    const Json* settings = find(root, "settings");
    if (settings == nullptr) return;
    std::vector<std::filesystem::path> masks;
    bool anyCli = false;
    for (const BatchVariant& v : job_.variants) {
      if (!v.masks.empty()) masks.push_back(v.masks);
      anyCli = anyCli || lowerExtension(v.contours) == ".cli";
    }
    const auto needs = [&](const char* k, bool applies, const char* what) {
      if (find(*settings, k) != nullptr && !applies)
        fail(childPath("settings", k), std::string("does nothing in this job: it needs ") + what);
    };
    for (const char* k : {"printer", "pixel", "origin", "resolution", "mirror", "antialias"})
      needs(k, !masks.empty(), "a variant with masks");
    needs("cli_binary", anyCli, "a variant with .cli contours");
    needs("join_tolerance", !job_.method.empty() && job_.method != "sr",
          "method cp or sr-lazy (the default sr joins segments through the adjacency table)");
    // The template's table is the point of a batch job; cp would neither use it nor check the variants.
    if (job_.method == "cp")
      fail(childPath("settings", "method"),
           "cp uses no adjacency table, so the job's template would neither serve nor check the variants "
           "(use sr or sr-lazy)");
    for (const auto& [k, value] : job_.printSettings)
      if (const std::string why = settingUnusedReason(k, masks, "a variant with masks"); !why.empty())
        fail(childPath(childPath("settings", "print_settings"), k), "does nothing in this job: " + why);
    // Printer files carry one layer height (as slice's --z): uneven planes would print another part.
    for (const auto& m : masks) {
      const std::string ext = lowerExtension(m);
      if ((ext == ".sl1" || ext == ".sl1s" || ext == ".goo" || ext == ".nanodlp") &&
          firstUnevenPlane(job_.explicitZ) < job_.explicitZ.size())
        fail(childPath("settings", "z"), "the planes are not evenly spaced, and " + m.string() +
                                             " moves the platform by one layer height for every layer");
    }
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
      if (const Json* x = find(item, "report"))
        variant.report = output(*x, childPath(at, "report"), kBatchReportExtensions, "report");
      if (variant.contours.empty() && variant.masks.empty() && variant.report.empty()) {
        fail(at, "no output (give contours, masks and/or report)");
      }
      if (const Json* x = find(item, "add")) variant.add = inputList(*x, childPath(at, "add"));
      if (const Json* x = find(item, "remove")) variant.remove = inputList(*x, childPath(at, "remove"));
      job_.variants.push_back(std::move(variant));
    }
  }

  BatchJob job_;
};

}  // namespace

BatchJob parseBatchJob(std::string_view text, const std::filesystem::path& baseDir, const std::string& name) {
  return JobParser(baseDir, name).parse(text);
}

BatchJob readBatchJob(const std::filesystem::path& path) {
  const std::string text = readJobText(path, "batch job");
  BatchJob job = parseBatchJob(text, std::filesystem::absolute(path).parent_path(), path.string());
  job.sourceFile = std::filesystem::absolute(path);
  return job;
}

}  // namespace toposlice
