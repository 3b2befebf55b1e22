// checkVariantConnectivity (core/mesh/variant_check.h) with its screening pass split over the cores; the
// exact, serial pass runs only when some range may fail, so the result is the same.
#pragma once

#include <optional>
#include <span>

#include "core/mesh/mesh.h"
#include "core/mesh/variant_check.h"

namespace toposlice {

std::optional<VariantMismatch> checkVariantConnectivityParallel(std::span<const Point3f> corners,
                                                                std::span<const int32_t> adjacency);

}  // namespace toposlice
