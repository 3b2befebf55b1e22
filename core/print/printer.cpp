#include "core/print/printer.h"

#include <algorithm>
#include <cctype>

namespace toposlice {
namespace {

constexpr PrinterPreset kPresets[] = {
    {"sl1", 2560, 1440, 0.04725, "SL1", 150.0, true},
    {"sl1s", 2560, 1620, 0.05, "SL1S", 150.0, true},
    {"generic-4k", 3840, 2160, 0.0, "SL1", 0.0},
    {"generic-8k", 7680, 4320, 0.043, "SL1", 300.0},
};

}  // namespace

std::optional<PrinterPreset> findPrinter(const std::string& name) {
  std::string lower = name;
  for (char& c : lower) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  for (const PrinterPreset& p : kPresets)
    if (lower == p.name) return p;
  return std::nullopt;
}

std::string printerNames() {
  std::string names;
  for (const PrinterPreset& p : kPresets) names += (names.empty() ? "" : ", ") + std::string(p.name);
  return names;
}

PixelGrid placeGrid(const BoundingBox& box, uint32_t width, uint32_t height, double pixel,
                    const std::optional<std::pair<double, double>>& origin, bool mirrorX, bool mirrorY) {
  PixelGrid grid;
  grid.width = width;
  grid.height = height;
  grid.pixel = pixel;
  grid.mirrorX = mirrorX;
  grid.mirrorY = mirrorY;
  if (origin) {
    grid.x0 = origin->first;
    grid.y0 = origin->second;
  } else {
    grid.x0 = 0.5 * (double{box.min.x} + box.max.x) - 0.5 * width * pixel;
    grid.y0 = 0.5 * (double{box.min.y} + box.max.y) - 0.5 * height * pixel;
  }
  return grid;
}

double gridOverhang(const BoundingBox& box, const PixelGrid& grid) {
  const double x1 = grid.x0 + grid.width * grid.pixel, y1 = grid.y0 + grid.height * grid.pixel;
  return std::max(
      {0.0, grid.x0 - box.min.x, grid.y0 - box.min.y, double{box.max.x} - x1, double{box.max.y} - y1});
}

}  // namespace toposlice
