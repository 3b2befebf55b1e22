// Plate jobs: many different parts, arranged and sliced together on one build plate (or several, when
// `auto` placements spill over). One JSON file; docs/FORMATS.md ("Plate jobs") has the format and an
// example, examples/plate_demo.json a working one. Parsed as strictly as batch jobs (io/jobs/batch_job.h):
// unknown or duplicate keys, wrong types, bad numbers, duplicate part names and outputs that are inputs
// are errors naming the key by its JSON path. Relative paths are resolved against the job file's folder.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace toposlice {

struct PlatePlacement {
  double x = 0, y = 0;  // mm: where the centre of the rotated part's xy bounding box goes on the plate
  double rotation = 0;  // degrees, counter-clockwise seen from +z, about the model's z axis
};

struct PlatePart {
  std::string name;                                // unique in the job
  std::filesystem::path model;                     // the part's mesh
  std::filesystem::path templateFile;              // its template's .topo table; empty: none (built)
  std::vector<std::filesystem::path> add, remove;  // add-on and removal features (in the model's frame)
  std::optional<PlatePlacement> placement;         // empty: "auto"
};

struct PlateJob {
  std::string description;
  std::string printer;   // preset or profile; required unless a profile file has one, or pixel and resolution
  std::string material;  // material preset or profile: exposure and corrections; empty: the file's only one
  // Printer and material settings (io/jobs/profile.h), as in batch jobs: a profile file (JSON, relative to
  // the job's folder) whose printers and materials `printer` and `material` may name, and overrides of
  // any key on top. The display, corrections, exposure and gamma apply to every plate.
  std::filesystem::path profile;
  std::vector<std::pair<std::string, std::string>> printSettings;
  std::optional<double> pixel;                        // mm, overrides the printer's
  std::optional<std::array<uint32_t, 2>> resolution;  // pixels, overrides the printer's
  std::optional<double> buildHeight;                  // mm, overrides the printer's; 0: unchecked
  double layerHeight = 0.05;                          // mm
  std::optional<double> z0;                           // bottom of layer 0; default: the lowest part bottom
  std::string method;                                 // "sr", "sr-lazy", "cp"; empty: default
  std::optional<bool> mirrorX, mirrorY;
  bool antialias = false, cliBinary = false, overwrite = false, allowRebuild = false;
  bool fixOrientation = false;  // flip inside-out (negative volume) models and features
  uint32_t threads = 0;
  std::optional<double> unitMm;
  double scale = 1.0;
  // Arrangement (core/print/arrange.h).
  double spacing = 2.0, margin = 5.0;  // mm
  double rotationStep = 90;            // degrees; 0: parts keep their orientation
  double cell = 0.5;                   // mm, footprint grid
  // Outputs (plate 1's names; plate n > 1 inserts "-plate<n>" before the extension).
  std::filesystem::path masks;                  // .sl1, .sl1s, .exr, .vdb or a PNG folder; empty: none
  std::vector<std::filesystem::path> contours;  // .cli, .svg, .3mf
  std::filesystem::path report;                 // per-part report (JSON)
  std::filesystem::path picture;                // PNG of the plate (every layer's masks, projected)
  std::vector<PlatePart> parts;
  std::filesystem::path sourceFile;
};

PlateJob readPlateJob(const std::filesystem::path& path);
PlateJob parsePlateJob(std::string_view text, const std::filesystem::path& baseDir, const std::string& name);

// The output path of plate `plate` (0-based): plate 0 keeps `path`, plate n inserts "-plate<n+1>".
std::filesystem::path plateOutputPath(const std::filesystem::path& path, uint32_t plate);

}  // namespace toposlice
