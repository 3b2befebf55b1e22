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
#include <array>
#include <cctype>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <set>
#include <string>
#include <string_view>

#include "io/errors.h"
#include "io/jobs/batch_job.h"

namespace {

namespace fs = std::filesystem;

void require(bool condition, const char* what) {
  if (condition) return;
  std::fprintf(stderr, "fuzz_batch_job: invariant broken: %s\n", what);
  std::abort();
}

template <std::size_t N>
bool hasExtension(const fs::path& p, const std::array<std::string_view, N>& extensions) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return std::find(extensions.begin(), extensions.end(), ext) != extensions.end();
}

class PathCheck {
 public:
  void input(const fs::path& p) {
    require(p.is_absolute(), "input paths are resolved against the base folder");
    inputs_.insert(p.string());
  }
  void output(const fs::path& p) {
    require(p.is_absolute(), "output paths are resolved against the base folder");
    require(outputs_.insert(p.string()).second, "every output path is unique");
  }
  void finish() const {
    for (const std::string& out : outputs_) require(!inputs_.contains(out), "no output is also an input");
  }

 private:
  std::set<std::string> inputs_, outputs_;
};

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
  require(job.method.empty() || job.method == "sr" || job.method == "sr-lazy" || job.method == "cp",
          "the method is known");
  if (job.pixel) require(*job.pixel > 0, "pixel is positive");
  if (job.resolution) require((*job.resolution)[0] >= 1 && (*job.resolution)[1] >= 1, "resolution >= 1");
  require(job.mirrorX.has_value() == job.mirrorY.has_value(), "mirrorX and mirrorY are set together");
  require(job.threads <= 4096, "threads <= 4096");

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
