// A one-line progress bar on a terminal's standard error; silent when stderr is not a terminal or the
// user asked for --quiet. Redraws at most ten times a second.
#pragma once

#include <chrono>
#include <cstdint>
#include <string>

namespace toposlice {

class ProgressBar {
 public:
  ProgressBar(std::string label, bool quiet);
  ~ProgressBar();  // ends the line if anything was drawn
  void update(uint64_t done, uint64_t total);
  void setLabel(std::string label) { label_ = std::move(label); }
  bool active() const { return enabled_; }

 private:
  std::string label_;
  bool enabled_;
  bool drawn_ = false;
  std::chrono::steady_clock::time_point last_{};
};

}  // namespace toposlice
