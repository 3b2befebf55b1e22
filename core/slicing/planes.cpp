#include "core/slicing/planes.h"

#include <cerrno>

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
        error = "z value number " + std::to_string(i + 1) + " is not a finite number";
        return {};
      }
      if (i > 0 && !(spec.explicitZ[i - 1] < spec.explicitZ[i])) {
        std::ostringstream text;
        text.precision(17);
        text << "explicit plane z values must be strictly increasing (" << spec.explicitZ[i - 1] << " then "
             << spec.explicitZ[i] << ")";
        error = text.str();
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
    const double wanted =
        spec.layers ? static_cast<double>(*spec.layers) : std::max(0.0, std::ceil((zmax - z0) / h));
    if (!(wanted <= 1e12)) {  // checked before the conversion, which would overflow
      std::ostringstream text;
      text << "layer height " << h << " mm gives too many layers (" << wanted << ")";
      error = text.str();
      return {};
    }
    count = static_cast<uint64_t>(wanted);
    if (count == 0) {
      std::ostringstream text;
      text.precision(10);
      text << "z0 " << z0 << " mm is at or above the model's top (z " << zmax << " mm): no layer to slice";
      error = text.str();
      return {};
    }
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

bool parseZList(const std::string& text, std::vector<double>& out, std::string* error) {
  out.clear();
  auto fail = [&](const std::string& why) {
    if (error) *error = why;
    return false;
  };
  // Values are separated by commas and/or whitespace; two commas with nothing between them, or a comma
  // at either end, leave a value out: an error rather than a silently shorter list.
  std::size_t i = 0;
  bool expectValue = true;  // at the start, or just after a comma
  std::size_t position = 0;
  while (i < text.size()) {
    const char c = text[i];
    if (c == ' ' || c == '\t') {
      ++i;
      continue;
    }
    if (c == ',') {
      if (expectValue)
        return fail("value " + std::to_string(position + 1) + " is missing (empty between commas)");
      expectValue = true;
      ++i;
      continue;
    }
    std::size_t end = i;
    while (end < text.size() && text[end] != ',' && text[end] != ' ' && text[end] != '\t') ++end;
    const std::string token = text.substr(i, end - i);
    char* stop = nullptr;
    errno = 0;
    const double v = std::strtod(token.c_str(), &stop);
    if (stop == token.c_str() || *stop != '\0') return fail("'" + token + "' is not a number");
    if (!std::isfinite(v) || errno == ERANGE) {
      if (!(std::isfinite(v) && v == 0 && errno == ERANGE))
        return fail("'" + token + "' is not a finite number");
    }
    out.push_back(v);
    ++position;
    expectValue = false;
    i = end;
  }
  if (out.empty()) return fail("no values");
  if (expectValue) return fail("a value is missing after the last comma");
  return true;
}

std::size_t firstUnevenPlane(const std::vector<double>& z) {
  for (std::size_t i = 2; i < z.size(); ++i)
    if (std::abs((z[i] - z[i - 1]) - (z[1] - z[0])) > 1e-9 * std::max(1.0, std::abs(z[i]))) return i;
  return z.size();
}

}  // namespace toposlice
