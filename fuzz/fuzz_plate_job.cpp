// libFuzzer harness for the plate job reader (io/jobs/plate_job_file.h): the input is the job's JSON text,
// parsed against a fixed absolute base folder. InputError is the expected answer to bad input; any other
// exception, a sanitizer report or a returned job that breaks a promise of the header is a crash:
// - at least one part; names non-empty and unique; every part has a model; every path absolute;
// - output paths unique, none also an input; contour extensions among the known ones; some output; a
//   picture only with masks;
// - a printer, a profile, or pixel and resolution; a positive layer height and pixel, resolution >= 1;
//   build height >= 0; threads <= 4096; mirrorX and mirrorY set together; a known method;
// - arrangement: spacing and margin finite and >= 0, rotation step in [0, 360), cell >= 0.05 mm;
//   given placements finite;
// - print_settings: each key once (each value was checked by the reader); a light map is an input.
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <set>
#include <string>
#include <string_view>

#include "fuzz/job_checks.h"
#include "io/errors.h"
#include "io/jobs/plate_job_file.h"

const char* const fuzzjob::kHarness = "fuzz_plate_job";

namespace {

namespace fs = std::filesystem;
using fuzzjob::require;

constexpr std::array<std::string_view, 3> kContourExtensions = {".cli", ".svg", ".3mf"};

void checkJob(const toposlice::PlateJob& job) {
  fuzzjob::PathCheck paths;
  require(!job.printer.empty() || !job.profile.empty() || (job.pixel && job.resolution),
          "a printer, a profile, or pixel and resolution");
  if (!job.profile.empty()) paths.input(job.profile);
  std::set<std::string> keys;
  for (const auto& [key, value] : job.printSettings) {
    require(!key.empty(), "print_settings keys are not empty");
    require(keys.insert(key).second, "each print_settings key once");
    if (key == "light_map" && !value.empty()) paths.input(value);  // resolved against the base folder
  }
  require(job.layerHeight > 0, "layer_height is positive");
  if (job.buildHeight) require(*job.buildHeight >= 0, "build_height is not negative");
  fuzzjob::checkSliceSettings(job);
  require(job.scale > 0, "scale is positive");
  require(std::isfinite(job.spacing) && job.spacing >= 0, "spacing is finite and >= 0");
  require(std::isfinite(job.margin) && job.margin >= 0, "margin is finite and >= 0");
  require(job.rotationStep >= 0 && job.rotationStep < 360, "rotation step in [0, 360)");
  require(job.cell >= 0.05, "cell >= 0.05 mm");

  require(!job.parts.empty(), "at least one part");
  std::set<std::string> names;
  for (const toposlice::PlatePart& p : job.parts) {
    require(!p.name.empty(), "part names are not empty");
    require(names.insert(p.name).second, "part names are unique");
    require(!p.model.empty(), "every part has a model");
    paths.input(p.model);
    if (!p.templateFile.empty()) paths.input(p.templateFile);
    for (const fs::path& f : p.add) paths.input(f);
    for (const fs::path& f : p.remove) paths.input(f);
    if (p.placement)
      require(std::isfinite(p.placement->x) && std::isfinite(p.placement->y) &&
                  std::isfinite(p.placement->rotation),
              "given placements are finite");
  }

  require(!job.masks.empty() || !job.contours.empty() || !job.report.empty(), "the job has an output");
  require(job.picture.empty() || !job.masks.empty(), "a picture only with masks");
  for (const fs::path* p : {&job.masks, &job.report, &job.picture})
    if (!p->empty()) paths.output(*p);
  for (const fs::path& c : job.contours) {
    require(fuzzjob::hasExtension(c, kContourExtensions), "contour extension is known");
    paths.output(c);
  }
  paths.finish();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    checkJob(toposlice::parsePlateJob(text, "/fuzz/jobs", "fuzz.json"));
  } catch (const toposlice::InputError&) {
    // Bad input, reported as the reader's contract says.
  }
  return 0;
}
