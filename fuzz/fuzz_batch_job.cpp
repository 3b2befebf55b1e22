// libFuzzer harness for the batch job reader (io/jobs/batch_job.h): the input is the job's JSON text, parsed
// against a fixed absolute base folder. InputError is the expected answer to bad input; any other
// exception, a sanitizer report or a returned job that breaks a promise of the header is a crash:
// - at least one variant; names non-empty and unique; every variant has a model and an output;
// - the template gives a model, a table or both; every path is absolute (resolved against the base);
// - output paths unique, none also an input; contour and mask extensions among the known ones;
// - planes: an explicit z list (strictly ascending, nothing else) or layer_height/layers; positive layer
//   height and pixel, layers and resolution >= 1, join tolerance >= 0, a known method, threads <= 4096;
//   mirrorX and mirrorY set together.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string_view>

#include "fuzz/job_checks.h"
#include "io/errors.h"
#include "io/jobs/batch_job.h"

const char* const fuzzjob::kHarness = "fuzz_batch_job";

namespace {

using fuzzjob::hasExtension;
using fuzzjob::PathCheck;
using fuzzjob::require;
namespace fs = std::filesystem;

void checkJob(const toposlice::BatchJob& job) {
  PathCheck paths;
  require(!job.templateModel.empty() || !job.templateFile.empty(), "the template gives a model or a table");
  if (!job.templateModel.empty()) paths.input(job.templateModel);
  if (!job.templateFile.empty()) paths.output(job.templateFile);

  if (!job.explicitZ.empty()) {
    require(!job.layerHeight && !job.layers && !job.z0, "explicit z excludes layer_height, layers and z0");
    require(std::adjacent_find(job.explicitZ.begin(), job.explicitZ.end(),
                               [](double a, double b) { return !(a < b); }) == job.explicitZ.end(),
            "explicit z is strictly ascending");
  } else {
    require(job.layerHeight || job.layers, "the planes are given");
  }
  if (job.layerHeight) require(*job.layerHeight > 0, "layer_height is positive");
  if (job.layers) require(*job.layers >= 1, "layers >= 1");
  if (job.joinTolerance) require(*job.joinTolerance >= 0, "join_tolerance is not negative");
  fuzzjob::checkSliceSettings(job);

  require(!job.variants.empty(), "at least one variant");
  std::set<std::string> names;
  for (const toposlice::BatchVariant& v : job.variants) {
    require(!v.name.empty(), "variant names are not empty");
    require(names.insert(v.name).second, "variant names are unique");
    require(!v.model.empty(), "every variant has a model");
    paths.input(v.model);
    for (const fs::path& p : v.add) paths.input(p);
    for (const fs::path& p : v.remove) paths.input(p);
    require(!v.contours.empty() || !v.masks.empty() || !v.report.empty(), "every variant has an output");
    if (!v.contours.empty()) {
      require(hasExtension(v.contours, toposlice::kBatchContourExtensions), "contour extension is known");
      paths.output(v.contours);
    }
    if (!v.masks.empty()) {
      require(hasExtension(v.masks, toposlice::kBatchMaskExtensions), "mask extension is known");
      paths.output(v.masks);
    }
    if (!v.report.empty()) paths.output(v.report);
  }
  paths.finish();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    checkJob(toposlice::parseBatchJob(text, "/fuzz/jobs", "fuzz.json"));
  } catch (const toposlice::InputError&) {
    // Bad input, reported as the reader's contract says.
  }
  return 0;
}
