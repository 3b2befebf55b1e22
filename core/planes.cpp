#include "core/planes.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <sstream>

namespace toposlice {

std::vector<double> makePlanes(const PlaneSpec& spec, double zmin, double zmax, std::string& error) {
  error.clear();
  if (!spec.explicitZ.empty()) {
    for (std::size_t i = 0; i < spec.explicitZ.size(); ++i) {
      if (!std::isfinite(spec.explicitZ[i])) {
        error = "plane z value " + std::to_string(i) + " is not a finite number";
        return {};
      }
      if (i > 0 && !(spec.explicitZ[i - 1] < spec.explicitZ[i])) {
        error = "explicit plane z values must be strictly increasing (value " + std::to_string(i) + ")";
        return {};
      }
    }
    return spec.explicitZ;
  }
  const double z0 = spec.z0.value_or(zmin);
  if (!std::isfinite(z0)) {
    error = "z0 is not a finite number";
    return {};
  }
  double h = 0;
  uint64_t count = 0;
  if (spec.layerHeight) {
    h = *spec.layerHeight;
    if (!(h > 0) || !std::isfinite(h)) {
      error = "layer height must be a positive number of millimetres";
      return {};
    }
    count = spec.layers ? *spec.layers : static_cast<uint64_t>(std::max(0.0, std::ceil((zmax - z0) / h)));
  } else if (spec.layers) {
    if (*spec.layers == 0) {
      error = "the layer count must be at least 1";
      return {};
    }
    count = *spec.layers;
    h = (zmax - z0) / static_cast<double>(count);
    if (!(h > 0)) {
      error = "the model has no height above z0 to divide into layers";
      return {};
    }
  } else {
    error = "give a layer height, a layer count or an explicit list of z values";
    return {};
  }
  constexpr uint64_t kMaxLayers = 100'000'000;
  if (count > kMaxLayers) {
    error = "too many layers (" + std::to_string(count) + "); the limit is " + std::to_string(kMaxLayers);
    return {};
  }
  std::vector<double> planes(count);
  for (uint64_t k = 0; k < count; ++k) planes[k] = z0 + (static_cast<double>(k) + 0.5) * h;
  return planes;
}

bool parseZList(const std::string& text, std::vector<double>& out) {
  out.clear();
  std::string cleaned = text;
  std::replace(cleaned.begin(), cleaned.end(), ',', ' ');
  std::istringstream in(cleaned);
  std::string token;
  while (in >> token) {
    char* end = nullptr;
    const double v = std::strtod(token.c_str(), &end);
    if (end == token.c_str() || *end != '\0') return false;
    out.push_back(v);
  }
  return true;
}

}  // namespace toposlice
