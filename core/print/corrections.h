// Printer and material corrections that need no polygon library (issue "Production print settings"):
// the scaling correction of a model, the elephant-foot schedule over the bottom layers and the
// anti-aliasing gamma's curve. Offsets live in offset/polygon_offset.h; the rasterizer applies the gamma
// curve and the light-uniformity map as it writes each value (core/raster/rasterize.h).
#pragma once

#include <array>
#include <cstdint>
#include <span>

#include "core/mesh/mesh.h"
#include "core/raster/rasterize.h"

namespace toposlice {

// Centre of the scaling correction: the centre of the xy bounding box, at the lowest z (the model stays
// on the platform and centred where the pixel grid is centred by default).
std::array<double, 3> scaleCentre(const BoundingBox& box);

// Scales every corner about `centre` by `factors` (x, y, z, each > 0): p' = c + f (p - c), computed in
// double and rounded to float once. A pure function of the corner: the same bits for any split.
void scaleCorners(std::span<Point3f> corners, const std::array<double, 3>& factors,
                  const std::array<double, 3>& centre);

// Elephant-foot shrink of layer `k` (0 = the bottom layer) over the first `layers` layers, as
// PrusaSlicer's SLA printer corrections fade it over the material's faded layers: with
// n = max(1, layers - 1), layer k < layers gets amount * (n - k) / n (the full amount on layer 0,
// nothing on layer layers - 1 when layers > 1), later layers 0. layers >= 1; the caller limits it to the
// job's layer count, as PrusaSlicer does.
double elephantFootAt(uint32_t k, double amount, uint32_t layers);

// The anti-aliasing gamma as a coverage curve (core/raster/rasterize.h): a pixel covered by the fraction
// a gets round(255 a^gamma) (halves up), from the exact coverage. gamma > 0 (gamma = 0 means binary
// masks, which the rasterizer makes directly); gamma = 1 is round(255 a), as without a curve.
CoverageCurve gammaCurve(double gamma);

}  // namespace toposlice
