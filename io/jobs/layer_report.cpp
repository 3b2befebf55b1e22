#include "io/jobs/layer_report.h"

#include <cstdio>

#include "io/output_file.h"

namespace toposlice {

LayerReport::LayerReport(const std::filesystem::path& path, bool overwrite)
    : file_(std::make_unique<OutputFile>(path, overwrite)) {
  static constexpr char kHeader[] = "layer,z_mm,area_mm2,loops,islands\n";
  file_->write(kHeader, sizeof kHeader - 1);
}

LayerReport::~LayerReport() = default;

void LayerReport::addLayer(uint32_t index, double z, double areaMm2, uint64_t loops, uint64_t islands) {
  char line[160];
  const int n =
      std::snprintf(line, sizeof line, "%u,%.6f,%.6f,%llu,%llu\n", index, z, areaMm2,
                    static_cast<unsigned long long>(loops), static_cast<unsigned long long>(islands));
  file_->write(line, static_cast<std::size_t>(n));
}

void LayerReport::finish() {
  file_->commit();
}

}  // namespace toposlice
