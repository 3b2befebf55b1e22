// Checks shared by the job-reader harnesses (fuzz_batch_job.cpp, fuzz_plate_job.cpp): an invariant that
// aborts with the harness's name, known file extensions, the job's input and output paths, and the slice
// settings both kinds of job carry under the same names.
#pragma once

#include <algorithm>
#include <array>
#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <set>
#include <string>
#include <string_view>

namespace fuzzjob {

namespace fs = std::filesystem;

// Defined by each harness: its name, which starts every broken-invariant message.
extern const char* const kHarness;

inline void require(bool condition, const char* what) {
  if (condition) return;
  std::fprintf(stderr, "%s: invariant broken: %s\n", kHarness, what);
  std::abort();
}

template <std::size_t N>
bool hasExtension(const fs::path& p, const std::array<std::string_view, N>& extensions) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return std::find(extensions.begin(), extensions.end(), ext) != extensions.end();
}

// Every path absolute (resolved against the base folder), outputs unique, no output also an input.
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

// method, pixel, resolution, mirrorX/mirrorY and threads, as batch and plate jobs both hold them.
template <class Job>
void checkSliceSettings(const Job& job) {
  require(job.method.empty() || job.method == "sr" || job.method == "sr-lazy" || job.method == "cp",
          "the method is known");
  if (job.pixel) require(*job.pixel > 0, "pixel is positive");
  if (job.resolution) require((*job.resolution)[0] >= 1 && (*job.resolution)[1] >= 1, "resolution >= 1");
  require(job.mirrorX.has_value() == job.mirrorY.has_value(), "mirrorX and mirrorY are set together");
  require(job.threads <= 4096, "threads <= 4096");
}

}  // namespace fuzzjob
