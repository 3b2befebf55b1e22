// Contours as a Common Layer Interface file (CLI 2.00), ASCII or binary. Byte layout: docs/FORMATS.md.
//
// Header (both variants, '\n' line ends, nothing time- or machine-dependent: same input, same bytes):
//   $$HEADERSTART / $$ASCII or $$BINARY / $$UNITS/00000001.000000 (coordinates in mm) / $$VERSION/200 /
//   $$LABEL/1,<name> / [$$LABEL/<i+2>,add <feature> or remove <feature>, one per job.features[i]] /
//   $$DIMENSION/x0,y0,z0,x1,y1,z1 / $$LAYERS/<count> / $$HEADEREND
// Geometry per layer: a layer command with the cutting-plane height z (layer.z), then one polyline per
// loop, part after part (model, add-ons, removals), with the part's label id and dir 1 = outer
// (counter-clockwise as written, signed area > 0), 0 = hole (clockwise as written or zero area), 2 = open
// polyline (loopClosed == 0). A removal's loops are written reversed (a closed loop keeps its first
// point: p0, p(n-1), ..., p1), so its outer loops are clockwise with dir 0: the layer's solid is where
// the winding numbers of all closed polylines of all ids add up to more than zero. Closed loops repeat
// their first point at the end (n counts it); open polylines do not. Loops without points are skipped.
// ASCII: "$$GEOMETRYSTART", "$$LAYER/z", "$$POLYLINE/1,dir,n,x1,y1,...", "$$GEOMETRYEND"; every number in
// fixed notation with 6 decimals (1 nm), "-0.000000" written as "0.000000".
// Binary: follows "$$HEADEREND" directly (no line end); little-endian, unaligned: uint16 127 + float32 z
// (start layer long), uint16 130 + int32 id + int32 dir + int32 n + n x (float32 x, float32 y) (start
// polyline long). Each layer is encoded into one reused buffer and written with one call.
#pragma once

#include <filesystem>
#include <memory>

#include "io/contours/contour_sink.h"

namespace toposlice {

// Opens `path` (through OutputFile: a temporary until finish()) and writes the header. Throws OutputError
// when the file exists and !overwrite, or cannot be created.
std::unique_ptr<ContourSink> makeCliWriter(const std::filesystem::path& path, const ContourJob& job,
                                           bool binary, bool overwrite);

}  // namespace toposlice
