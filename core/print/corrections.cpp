#include "core/print/corrections.h"

#include <algorithm>
#include <cassert>
#include <cmath>

namespace toposlice {

std::array<double, 3> scaleCentre(const BoundingBox& box) {
  return {0.5 * (double{box.min.x} + box.max.x), 0.5 * (double{box.min.y} + box.max.y), double{box.min.z}};
}

void scaleCorners(std::span<Point3f> corners, const std::array<double, 3>& factors,
                  const std::array<double, 3>& centre) {
  for (Point3f& p : corners) {
    p.x = static_cast<float>(centre[0] + factors[0] * (double{p.x} - centre[0]));
    p.y = static_cast<float>(centre[1] + factors[1] * (double{p.y} - centre[1]));
    p.z = static_cast<float>(centre[2] + factors[2] * (double{p.z} - centre[2]));
  }
}

double elephantFootAt(uint32_t k, double amount, uint32_t layers) {
  assert(layers >= 1);
  if (k >= layers || !(amount > 0)) return 0.0;
  const uint32_t n = std::max<uint32_t>(1, layers - 1);
  return amount * static_cast<double>(n - k) / static_cast<double>(n);
}

CoverageCurve gammaCurve(double gamma) {
  // round(255 a^g) >= v exactly where a^g >= (v - 1/2) / 255, i.e. a >= ((v - 1/2) / 255)^(1 / g).
  std::array<double, 256> thresholds{};
  for (int v = 1; v < 256; ++v)
    thresholds[static_cast<std::size_t>(v)] = std::pow((v - 0.5) / 255.0, 1.0 / gamma);
  return coverageCurve(thresholds);
}

}  // namespace toposlice
