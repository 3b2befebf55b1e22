// Slicing planes (DESIGN.md): layer k is cut at z_k = z0 + (k + 1/2) h, z0 defaults to the lowest z of
// what is printed (the model and its add-ons), and the layer count defaults to ceil((zmax - z0) / h). An
// explicit ascending list of z values may be given instead.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace toposlice {

struct PlaneSpec {
  std::optional<double> layerHeight;  // h in mm
  std::optional<uint32_t> layers;     // layer count; with no height, h = (zmax - z0) / layers
  std::optional<double> z0;           // bottom of layer 0; default: zmin
  std::vector<double> explicitZ;      // when not empty, these planes are used as given
};

// Returns the planes for a model spanning [zmin, zmax], or an error message in `error` (and an empty
// vector) when the specification cannot make planes (non-positive height, no layers, unsorted list...).
std::vector<double> makePlanes(const PlaneSpec& spec, double zmin, double zmax, std::string& error);

// The first plane of an explicit list whose distance to the one before differs from the first distance
// (beyond rounding: 1e-9 relative), or z.size() when the planes are evenly spaced. Printer files carry one
// layer height, so they need even planes.
std::size_t firstUnevenPlane(const std::vector<double>& z);

// Parses "0.1,0.2,0.35" (commas or whitespace) into values; returns false on malformed text.
bool parseZList(const std::string& text, std::vector<double>& out, std::string* error = nullptr);

}  // namespace toposlice
