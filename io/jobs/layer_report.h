// The per-layer report (`--report FILE.csv`): one row per layer with its z (mm), solid area (mm^2),
// loop count and island count (outer loops), nothing else, so that every CSV reader takes it as it is
// (the resin volume is in the summary, `--summary FILE.json`). Written through a temporary name like
// every output.
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>

namespace toposlice {

class OutputFile;

class LayerReport {
 public:
  LayerReport(const std::filesystem::path& path, bool overwrite);  // throws OutputError
  ~LayerReport();
  void addLayer(uint32_t index, double z, double areaMm2, uint64_t loops, uint64_t islands);
  void finish();

 private:
  std::unique_ptr<OutputFile> file_;
};

}  // namespace toposlice
