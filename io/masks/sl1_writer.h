// SL1 archive writer: the Prusa SL1/SL1S print file, read by PrusaSlicer (import), UVtools and the
// printers' firmware (docs/FORMATS.md, "SL1").
//
// Layout: a zip holding, when the job has a preview model, PrusaSlicer's thumbnails
// "thumbnail/thumbnail400x400.png" and "thumbnail/thumbnail800x480.png" (core/raster/preview.h), then
// "<name>00000.png", "<name>00001.png", ... (8-bit grayscale, stored without recompression, exactly the
// encodeMaskPng bytes), then config.ini and prusaslicer.ini, written at finish() when the layer count
// and volume are final. Entries are streamed one by one with minizip
// (libzip keeps every entry's data until zip_close, so it cannot stream); the archive is written to an
// OutputFile temporary and renamed at finish(). Memory: one layer plus the zip central directory that
// minizip must keep until the end (about 80 bytes per layer, 8 MB at 100,000 layers). Past 65,534
// entries the Zip64 end records are added after minizip closes the archive (Debian's minizip 1.1 only
// adds them past 4 GiB, leaving an archive that libzip, unzip and .NET reject).
//
// Limits: layer names carry exactly 5 digits (UVtools parses the 5 characters before ".png", the firmware
// sorts names), so an SL1 holds at most kSl1MaxLayers layers; a larger job is refused when the sink is
// created. Timestamps (zip entry times, fileCreationTimestamp) are the current time, or
// SOURCE_DATE_EPOCH when that environment variable is set, for byte-identical archives.
#pragma once

#include <cstdint>
#include <ctime>
#include <filesystem>
#include <memory>
#include <string>

#include "io/masks/mask_sink.h"

namespace toposlice {

inline constexpr uint32_t kSl1MaxLayers = 100000;
inline constexpr double kSl1LayerOverheadS = 5.0;  // tilt and settle time per layer in printTime (fast tilt)

std::unique_ptr<MaskSink> makeSl1Sink(const std::filesystem::path& path, const MaskJob& job, bool overwrite);

// config.ini: the firmware's and UVtools' keys (jobDir, expTime, expTimeFirst, numFade, numFast,
// numSlow, layerHeight, layerHeightFirst, usedMaterial, printTime, printerModel, ...), one "key = value"
// per line, sorted. `layers` is the number of layers in the archive; `created` the creation time.
std::string sl1ConfigIni(const MaskJob& job, uint32_t layers, std::time_t created);

// prusaslicer.ini: the printer/print/material profile PrusaSlicer needs to import the archive
// (display_pixels_x/y, display_width/height, display_mirror_x/y, display_orientation, layer_height, ...).
// The display is landscape: display_pixels_x is the PNG width.
std::string sl1PrusaSlicerIni(const MaskJob& job, uint32_t layers);

}  // namespace toposlice
