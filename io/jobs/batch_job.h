// Batch jobs: one template, many customized variants, one JSON file (docs/FORMATS.md has the format
// and a full example). The parser checks everything that can be checked without reading a mesh, so a
// job with a typo fails at once rather than after hours of slicing:
// - strict JSON (no comments), an object at the top; unknown keys, duplicate keys and wrong types are
//   errors naming the key by its JSON path ("variants[2].masks");
// - values in range (positive layer height and pixel, whole layer counts, ascending explicit z, known
//   slicing method, output extensions the writers know);
// - variant names unique and non-empty; every output path unique in the job and different from every
//   input path (compared after resolving and normalising).
// Relative paths are resolved against the job file's folder. Errors: InputError("<file>: <path>: <what>").
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace toposlice {

struct BatchVariant {
  std::string name;                                // unique in the job, for progress and reports
  std::filesystem::path model;                     // the variant's mesh (STL, may be gzip-compressed)
  std::filesystem::path contours;                  // contour output (.cli, .3mf, .svg); empty: none
  std::filesystem::path masks;                     // mask output (.sl1, .exr, .vdb); empty: none
  std::filesystem::path report;                    // per-layer report; empty: none
  std::vector<std::filesystem::path> add, remove;  // add-on and removal feature meshes (inter-model reuse)
};

struct BatchJob {
  std::string description;              // free text, not interpreted
  std::filesystem::path templateModel;  // the template mesh; empty when only the table is given
  std::filesystem::path templateFile;   // its .topo table: loaded if present, else built and saved there
  // Planes (core/slicing/planes.h): layerHeight and/or layers with z0, or an explicit list of z.
  std::optional<double> layerHeight;  // mm
  std::optional<uint32_t> layers;
  std::optional<double> z0;             // mm; default: each model's lowest z
  std::vector<double> explicitZ;        // mm, strictly ascending; excludes the three above
  std::string method;                   // "sr", "sr-lazy" or "cp" (parallel/band_slicer.h); empty: default
  std::optional<double> joinTolerance;  // mm, for "sr-lazy" and "cp"
  // Masks (core/raster/mask_image.h PixelGrid): a printer preset and/or explicit image geometry.
  std::string printer;                                // preset name; empty: none
  std::optional<double> pixel;                        // pixel edge, mm
  std::optional<std::array<double, 2>> origin;        // lower-left corner of pixel (0, 0), mm
  std::optional<std::array<uint32_t, 2>> resolution;  // width, height in pixels
  std::optional<bool> mirrorX, mirrorY;               // set together by "mirror"; unset: the printer's
  bool antialias = false;                             // anti-aliased masks (else binary)
  // Printer and material settings (io/jobs/profile.h): a profile file, a material preset or profile,
  // and per-key overrides ("print_settings": {"exposure_time": 6, ...}), checked when parsed.
  std::filesystem::path profile;
  std::string material;
  std::vector<std::pair<std::string, std::string>> printSettings;
  bool cliBinary = false;              // .cli contours in binary CLI (else ASCII)
  uint32_t threads = 0;                // 0: all cores
  bool overwrite = false;              // replace existing outputs
  bool fixOrientation = false;         // "fix_orientation": flip inside-out meshes (slice --fix-orientation)
  std::optional<double> unitMm;        // "units": mm per file unit of the meshes (mm, cm, m, in)
  double scale = 1.0;                  // "scale": multiplies every coordinate after units
  std::vector<BatchVariant> variants;  // at least one
  std::filesystem::path sourceFile;    // the job file (readBatchJob); empty when parsed from text
};

// Output extensions accepted for BatchVariant::contours and ::masks (lower case, with the dot).
inline constexpr std::array<std::string_view, 3> kBatchContourExtensions = {".cli", ".3mf", ".svg"};
inline constexpr std::array<std::string_view, 1> kTableExtensions = {".topo"};
inline constexpr std::array<std::string_view, 1> kBatchReportExtensions = {".csv"};
inline constexpr std::array<std::string_view, 6> kBatchMaskExtensions = {".sl1",     ".sl1s", ".goo",
                                                                         ".nanodlp", ".exr",  ".vdb"};

// Reads and validates a job file; relative paths are resolved against the file's folder (made
// absolute). Throws InputError("<path>: <what>") when the file cannot be read, and as parseBatchJob
// for its content.
BatchJob readBatchJob(const std::filesystem::path& path);

// Parses and validates job text. Relative paths become baseDir / path, normalised (left relative when
// baseDir is empty). Throws InputError("<name>: <json path>: <what>"), or "<name>:<line>:<column>:
// invalid JSON: <what>" for text that is not JSON. The returned job passes every check listed above.
BatchJob parseBatchJob(std::string_view text, const std::filesystem::path& baseDir, const std::string& name);

}  // namespace toposlice
