// A small software renderer for the preview pictures that printer files carry (GOO, SL1 thumbnails,
// NanoDLP's 3d.png) and for `toposlice preview`.
//
// Orthographic camera looking down at the model from the front right (azimuth kPreviewAzimuthDeg from
// -y towards +x, elevation kPreviewElevationDeg above the horizon), the projected bounding box of the
// model fitted into the picture with a margin and centred. Triangles are rasterized with a depth buffer
// at 2 x 2 samples per pixel (averaged, so edges are smooth), one flat Lambert shade per facet from a
// light above, in front and to the left. Facets are lit on the side that faces the camera, so an
// inside-out mesh still shows. Plain C++, split into chunks by a ChunkRunner (core/chunk_runner.h): the
// same mesh gives the same pixels however it is split.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/chunk_runner.h"
#include "core/mesh/mesh.h"

namespace toposlice {

// 8-bit RGB picture, rows top-down, 3 bytes per pixel.
struct RgbImage {
  uint32_t width = 0, height = 0;
  std::vector<uint8_t> rgb;  // width * height * 3
};

inline constexpr double kPreviewAzimuthDeg = 30;
inline constexpr double kPreviewElevationDeg = 40;
inline constexpr uint8_t kPreviewBackground[3] = {36, 38, 46};  // dark slate
inline constexpr uint8_t kPreviewModel[3] = {110, 180, 235};    // fully lit model colour (light blue)

// World direction towards the light (unit length): above, in front (-y) and to the left (-x).
Point3f previewLightDirection();

// Renders the facet soup `corners` (3 per facet, counter-clockwise seen from outside) into `out`
// (replaced) of width x height >= 1. Facets with a non-finite corner are skipped; an empty mesh gives
// the background alone. `runner` runs the bounding box, pieces of the facets (each drawn into its own
// depth buffer, at most 8 at once) and the merge; the picture is the same for any runner.
void renderPreview(std::span<const Point3f> corners, uint32_t width, uint32_t height, RgbImage& out,
                   const ChunkRunner& runner = serialChunkRunner());

struct PreviewSize {
  uint32_t width = 0, height = 0;
};

// The same picture at several sizes (outs[i] at sizes[i], each exactly what renderPreview draws at that
// size) in one pass over the facets: each facet is projected and shaded once for all of them. Printer
// files carry two sizes.
void renderPreviews(std::span<const Point3f> corners, std::span<const PreviewSize> sizes,
                    std::span<RgbImage> outs, const ChunkRunner& runner = serialChunkRunner());

}  // namespace toposlice
