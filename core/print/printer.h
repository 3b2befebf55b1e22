// Printer presets and placing the pixel grid over a model (DESIGN.md, "Pixels").
#pragma once

#include <optional>
#include <string>

#include "core/mesh/mesh.h"
#include "core/raster/mask_image.h"

namespace toposlice {

// The widest and tallest mask image, in pixels, wherever its size is given (--resolution, a job's
// settings.resolution, a profile's display_pixels_x/y): beyond any display made, so a larger number is a
// mistake.
inline constexpr uint32_t kMaxImageSide = 100000;

struct PrinterPreset {
  const char* name;
  uint32_t width, height;  // pixels
  double pixel;            // mm; 0 = the user must give --pixel
  const char* model;       // SL1 printerModel written into archives
  double buildHeight = 0;  // mm of z travel; 0: unknown (not checked)
  // Portrait display (PrusaSlicer's display_orientation = portrait, display_mirror_x = 1): the SL1 and
  // SL1S firmware shows only images as tall as the display's long side (1440 x 2560, 1620 x 2560).
  bool portrait = false;
};

// "sl1" (Prusa SL1: 2560x1440 at 0.04725 mm), "sl1s" (SL1S: 2560x1620 at 0.05 mm),
// "generic-4k" (3840x2160, pixel from --pixel), "generic-8k" (7680x4320 at 0.043 mm: a 15" 8K
// monochrome LCD, 330 x 186 mm, as in large-format factory printers such as the Phrozen Sonic Mega 8K;
// 300 mm of z). Case-insensitive; nullopt for an unknown name.
std::optional<PrinterPreset> findPrinter(const std::string& name);
std::string printerNames();  // for help and error texts

// The grid of width x height pixels of size `pixel`: with no origin, centred on the centre of the xy
// bounding box of `box`; else pixel (0, 0) starts at origin.
PixelGrid placeGrid(const BoundingBox& box, uint32_t width, uint32_t height, double pixel,
                    const std::optional<std::pair<double, double>>& origin, bool mirrorX, bool mirrorY);

// How far (mm) the xy bounding box sticks out of the grid: the largest overhang on any side, 0 if it fits.
double gridOverhang(const BoundingBox& box, const PixelGrid& grid);

}  // namespace toposlice
