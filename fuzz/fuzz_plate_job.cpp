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
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <set>
#include <string>
#include <string_view>

#include "io/errors.h"
#include "io/jobs/plate_job_file.h"

namespace {

namespace fs = std::filesystem;

void require(bool condition, const char* what) {
  if (condition) return;
  std::fprintf(stderr, "fuzz_plate_job: invariant broken: %s\n", what);
  std::abort();
}

void checkJob(const toposlice::PlateJob& job) {
  std::set<std::string> inputs, outputs;
  const auto input = [&](const fs::path& p) {
    require(p.is_absolute(), "input paths are resolved against the base folder");
    inputs.insert(p.string());
  };
  const auto output = [&](const fs::path& p) {
    require(p.is_absolute(), "output paths are resolved against the base folder");
    require(outputs.insert(p.string()).second, "every output path is unique");
  };
  require(!job.printer.empty() || !job.profile.empty() || (job.pixel && job.resolution),
          "a printer, a profile, or pixel and resolution");
  if (!job.profile.empty()) input(job.profile);
  std::set<std::string> keys;
  for (const auto& [key, value] : job.printSettings) {
    require(!key.empty(), "print_settings keys are not empty");
    require(keys.insert(key).second, "each print_settings key once");
    if (key == "light_map" && !value.empty()) input(value);  // resolved against the base folder
  }
  require(job.layerHeight > 0, "layer_height is positive");
  if (job.pixel) require(*job.pixel > 0, "pixel is positive");
  if (job.resolution) require((*job.resolution)[0] >= 1 && (*job.resolution)[1] >= 1, "resolution >= 1");
  if (job.buildHeight) require(*job.buildHeight >= 0, "build_height is not negative");
  require(job.method.empty() || job.method == "sr" || job.method == "sr-lazy" || job.method == "cp",
          "the method is known");
  require(job.mirrorX.has_value() == job.mirrorY.has_value(), "mirrorX and mirrorY are set together");
  require(job.threads <= 4096, "threads <= 4096");
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
    input(p.model);
    if (!p.templateFile.empty()) input(p.templateFile);
    for (const fs::path& f : p.add) input(f);
    for (const fs::path& f : p.remove) input(f);
    if (p.placement)
      require(std::isfinite(p.placement->x) && std::isfinite(p.placement->y) &&
                  std::isfinite(p.placement->rotation),
              "given placements are finite");
  }

  require(!job.masks.empty() || !job.contours.empty() || !job.report.empty(), "the job has an output");
  require(job.picture.empty() || !job.masks.empty(), "a picture only with masks");
  for (const fs::path* p : {&job.masks, &job.report, &job.picture})
    if (!p->empty()) output(*p);
  for (const fs::path& c : job.contours) {
    std::string ext = c.extension().string();
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
    require(ext == ".cli" || ext == ".svg" || ext == ".3mf", "contour extension is known");
    output(c);
  }
  for (const std::string& out : outputs) require(!inputs.contains(out), "no output is also an input");
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
