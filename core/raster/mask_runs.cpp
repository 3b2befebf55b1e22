#include "core/raster/mask_runs.h"

#include <algorithm>
#include <cstring>

namespace toposlice {

void encodeMaskRuns(const MaskImage& mask, std::vector<uint8_t>& out) {
  out.clear();
  for (uint32_t j = 0; j < mask.height; ++j) {
    const uint8_t* row = mask.pixels.data() + std::size_t{j} * mask.width;
    uint32_t i = 0;
    while (i < mask.width) {
      const uint8_t value = row[i];
      uint32_t run = 1;
      while (i + run < mask.width && run < 0xFFFF && row[i + run] == value) ++run;
      out.push_back(value);
      out.push_back(static_cast<uint8_t>(run & 0xFF));
      out.push_back(static_cast<uint8_t>(run >> 8));
      i += run;
    }
  }
}

bool decodeMaskRuns(std::span<const uint8_t> runs, MaskImage& mask) {
  mask.pixels.resize(std::size_t{mask.width} * mask.height);
  std::size_t at = 0, pos = 0;
  const std::size_t total = mask.pixels.size();
  while (at + 3 <= runs.size()) {
    const uint8_t value = runs[at];
    const std::size_t run = runs[at + 1] | (std::size_t{runs[at + 2]} << 8);
    at += 3;
    if (run == 0 || pos + run > total) return false;
    std::memset(mask.pixels.data() + pos, value, run);
    pos += run;
  }
  return at == runs.size() && pos == total;
}

}  // namespace toposlice
