// libFuzzer harness for the profile files (io/jobs/profile.h, docs/FORMATS.md "Profile files"): the input
// is a profile file's text, resolved with no printer or material named (the file's only ones, as
// `--profile FILE` alone does). InputError is the expected answer to bad input; any other exception, a
// sanitizer report or resolved settings that break a promise of the header are a crash:
// - every value reads back: settingValues' text of each key that is not its default, assigned to fresh
//   settings, gives the same text again ("numbers in the shortest form that reads back exactly");
// - the scaling correction is finite and positive on every axis, the exposure times finite and >= 0.
// The text goes to a memory file (memfd) read through /proc/self/fd, so no file is left behind.
#include <sys/mman.h>
#include <unistd.h>

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "io/errors.h"
#include "io/jobs/profile.h"

namespace {

void require(bool condition, const char* what) {
  if (condition) return;
  std::fprintf(stderr, "fuzz_profile: invariant broken: %s\n", what);
  std::abort();
}

void checkSettings(const toposlice::PrintSettings& settings) {
  const auto values = toposlice::settingValues(settings);
  toposlice::PrintSettings again;
  const auto defaults = toposlice::settingValues(again);
  require(defaults.size() == values.size(), "settingValues lists every key");
  for (std::size_t i = 0; i < values.size(); ++i) {
    const auto& [key, value] = values[i];
    // A default (an unset gamma, display_pixels_x 0 for "unknown") is what fresh settings hold already;
    // some are not values one may set.
    if (value == defaults[i].second) continue;
    try {
      toposlice::assignSetting(again, key, value, "read back");
    } catch (const toposlice::InputError& e) {
      std::fprintf(stderr, "fuzz_profile: %s = %s does not read back: %s\n", key.c_str(), value.c_str(),
                   e.what());
      std::abort();
    }
  }
  require(toposlice::settingValues(again) == values, "every value reads back as the same text");
  for (const double s : settings.scale()) require(std::isfinite(s) && s > 0, "the scaling is finite and > 0");
  require(std::isfinite(settings.exposureTime) && settings.exposureTime >= 0, "exposure_time finite, >= 0");
  require(std::isfinite(settings.initialExposureTime) && settings.initialExposureTime >= 0,
          "initial_exposure_time finite, >= 0");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, std::size_t size) {
  static const int fd = memfd_create("fuzz_profile.json", MFD_CLOEXEC);
  require(fd >= 0, "memfd_create works");
  require(ftruncate(fd, 0) == 0, "the memory file can be emptied");
  for (std::size_t at = 0; at < size;) {
    const ssize_t n = pwrite(fd, data + at, size - at, static_cast<off_t>(at));
    require(n > 0, "the memory file takes the input");
    at += static_cast<std::size_t>(n);
  }
  toposlice::ProfileChoice choice;
  choice.file = "/proc/self/fd/" + std::to_string(fd);
  try {
    checkSettings(toposlice::resolvePrintSettings(choice));
  } catch (const toposlice::InputError&) {
    // Bad input, reported as the reader's contract says.
  }
  return 0;
}
