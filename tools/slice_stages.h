// The pieces of runSliceJob (tools/slice_job.h) that the plate job (tools/plate_job.h) shares: topology,
// output sinks, the mask grid and rasterizing one layer's contour sets. Defined in slice_job.cpp.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/raster/rasterize.h"
#include "io/contours/contour_sink.h"
#include "io/jobs/profile.h"
#include "io/masks/mask_sink.h"
#include "offset/polygon_offset.h"
#include "tools/slice_job.h"

namespace toposlice {

// The contour sinks of options.outputs by extension (.cli, .svg, .3mf). `mesh` and `features` are what
// a .3mf writes as meshes (mesh may be null: slice stacks only). Throws InputError for an unknown type.
std::vector<std::unique_ptr<ContourSink>> openContourSinks(const SliceJobOptions& options,
                                                           const ContourJob& job, const FacetSoup* mesh,
                                                           std::span<const FacetSoup> features,
                                                           double layerHeight);

// Welds `soup` and builds its adjacency into `table` (3 per facet); `stats` receives the edge counts.
// `welded`, when its facetVertices match the soup's corners, is the soup already welded (the reader
// welds a gzip'd binary STL while it inflates, MeshReadOptions::weld); it is moved from.
void buildTable(const FacetSoup& soup, std::vector<int32_t>& table, EdgeStats* stats = nullptr,
                IndexedMesh* welded = nullptr);

// The model's adjacency: the template's after the linear check, built (into `built`), or none, as
// options.slice.method needs. Fills result.topology (and result.edges when built). A variant whose
// connectivity differs throws InputError naming `model` unless options.rebuildOnMismatch.
std::span<const int32_t> modelTopology(const std::filesystem::path& model, const FacetSoup& soup,
                                       const TemplateTable* templateTable, const SliceJobOptions& options,
                                       SliceJobResult& result, std::vector<int32_t>& built,
                                       IndexedMesh* welded = nullptr);

// The layer height as given (see slice_job.cpp).
double nominalLayerHeight(const PlaneSpec& spec, const std::vector<double>& planes, double zmin);

// The mask job for `extent` (grid, printer model, layer count). Throws InputError for a missing image
// size or pixel, or an extent that does not fit (unless o.crop).
// --resolution and --pixel (a job's settings.resolution and settings.pixel: `resolutionName`,
// `pixelName`) as the printer's display settings (display_pixels_x/y, display_width/height, naming the
// option), so that --explain, the summary and a plate's report give the display the masks have;
// --resolution alone keeps the printer's pitch, which `o` then carries as its pixel (the same bits the
// masks use).
void recordDisplayOptions(PrintSettings& print, MaskOptions& o, const char* resolutionName = "--resolution",
                          const char* pixelName = "--pixel");

// The job's own display options and the display settings the user set (those whose origin is
// `userOrigin`: "command line", "batch job print_settings", ...) must not both say one thing: the option
// replaced the setting without a word (--display-pixels-x 400 --resolution 300x300 made 300). Throws
// InputError naming both for an image size (`resolution`) with display_pixels_x/y, a pixel size
// (`pixel`) with display_width/height, or a mirroring (`mirrorX/Y`: given, and to what) with
// display_mirror_x/y of the other value. `names`: how the options are called in that job.
struct DisplayOptionNames {
  const char* resolution;
  const char* pixel;
  const char* mirrorX;
  const char* mirrorY;
};
void checkDisplayOverrides(const PrintSettings& print, const std::string& userOrigin, bool resolution,
                           bool pixel, std::optional<bool> mirrorX, std::optional<bool> mirrorY,
                           const DisplayOptionNames& names);

MaskJob makeMaskJob(const MaskOptions& o, const PrintSettings& print, const BoundingBox& extent,
                    const std::string& name, const std::vector<double>& planes);

// The settings as a mask output `masks` of its format uses them. EXR and VDB stacks are volumes in the
// model's frame, GOO and NanoDLP files landscape images: a printer preset's portrait display (sl1,
// sl1s) and the mirroring that belongs to it (display_mirror_x/y that came with the printer) become
// landscape and unmirrored, so that --explain, the summary and the files say what the masks have. A
// mirroring the user set (an option, --set, a job's settings) stays and applies. A portrait orientation
// the user set is left for makeMaskJob to refuse. Other outputs: unchanged.
PrintSettings settingsForMaskFormat(PrintSettings print, const std::filesystem::path& masks);

// The extent of a job's contours (a CLI's $$DIMENSION, an SVG's panels): `box` (the model's and its
// add-ons') grown in x and y by a positive absolute_correction, so that it holds every corrected contour.
BoundingBox contourExtent(const BoundingBox& box, const PrintSettings& print);

// Whether masks of extension `ext` are landscape whatever the display: .exr and .vdb (volumes in the
// model's frame), .goo and .nanodlp (landscape images).
bool landscapeOnlyFormat(const std::string& ext);

// For a job without masks that names a material: "" when one of the material's settings changes what
// is written (a material_correction the contours, material_density the resin mass of a `summary`), else
// why the material does nothing ("none of its settings (exposure_time, ...) changes <written> or
// <report>"; `report` empty: the job writes none).
std::string unusedMaterialReason(const PrintSettings& print, bool summary, const std::string& written,
                                 const std::string& report);

// A job file's print_settings (`given`) naming an elephant-foot key other than the compensation while the
// resolved settings have none: refused as doing nothing, as slice refuses the options. `where`: the
// settings' place in the file ("settings.print_settings."). Throws InputError naming `jobFile`.
void checkElephantFootKeys(const PrintSettings& print,
                           const std::vector<std::pair<std::string, std::string>>& given,
                           const std::filesystem::path& jobFile, const std::string& where);

// The settings' mask options that contradict each other: gamma_correction 0 (binary) with anti-aliasing
// (`antialiasName`, the option or key that asks for it), and a light map on binary masks (when `masks`).
// Throws InputError.
void checkMaskSettings(const PrintSettings& print, bool antialias, bool masks, const char* antialiasName);

// The settings as the summary and the plate report give them: printer, material, every value that is set,
// where each came from, the scaling factors and, in words, the centre they scale about.
// `antialiasBy`: for a job with masks, how it asked for anti-aliasing (--antialias, settings.antialias;
// nullptr: no masks): a gamma_correction left unset is then given as the masks have it (1 anti-aliased,
// 0 binary), set by that option or "default", as the printer files record it.
nlohmann::ordered_json printSettingsJson(const PrintSettings& print, const char* scaleCentre,
                                         const char* antialiasBy = nullptr, bool antialias = false);

// What the settings do to every mask of `job` as it is rasterized (anti-aliased masks only): the gamma
// curve, when gamma_correction is set and not 1, and the light-uniformity map, read from light_map (a
// grayscale PNG of the masks' size). Throws InputError naming the light map's file for an unreadable
// file, another format or another size.
struct MaskTransfer {
  CoverageCurve gammaCurve;
  bool gamma = false;
  LightMap lightMap;  // empty: none
};
MaskTransfer maskTransfer(const PrintSettings& print, const MaskJob& job);

// The absolute correction and elephant foot (offset/polygon_offset.h) of layer k of a job of `layers`
// layers: the foot fades over min(layers, the fade layers), as PrusaSlicer does. Nil (any() false) on
// every layer of a job without corrections.
LayerCorrection layerCorrection(const PrintSettings& print, uint32_t k, std::size_t layers);

// Bounds, signed volume and degenerate facets of a soup, in parallel over fixed blocks of facets whose
// partial sums are added in block order: the same bits for any thread count.
struct SoupMeasures {
  BoundingBox bounds;
  double volume = 0;
  uint64_t degenerateFacets = 0;
};
SoupMeasures measureSoup(std::span<const Point3f> corners);

// Turns every facet of a soup over (its second and third corners swapped): an inside-out mesh made right.
void flipFacets(std::span<Point3f> corners);

// For a soup that is inside out (negative volume), the warning about it, else "". With `fix` the soup is
// turned right side out ("<named> was inside out (negative volume): flipped (<option>)"); without, it is
// left ("<named> is inside out (negative volume), so it <consequence>; flip it with <option>").
// `option` is how the job asks for the fix (--fix-orientation, a job's "fix_orientation").
std::string fixInsideOut(FacetSoup& soup, const std::string& named, bool fix, const std::string& option,
                         const std::string& consequence);

// Per-pipeline-slot buffers of the mask stage: the layer's contour sets, the rasterizer's scratch, the
// mask, and the encoder's scratch (reused from layer to layer).
struct MaskSlotScratch {
  RasterScratch raster;
  MaskImage mask;
  std::vector<ContourSet> sets;
  MaskEncodeScratch encodeScratch;
};

// Rasterizes the sets onto job.grid (binary or anti-aliased as the job says) into `mask`; returns the
// solid area in mm^2. Anti-aliased only: the transfer's gamma curve maps the exact coverage as it is
// written, and its light map then multiplies the values (the area is taken before both).
double rasterizeLayerSets(std::span<const ContourSet> sets, const MaskJob& job, MaskImage& mask,
                          RasterScratch& scratch, const MaskTransfer* transfer = nullptr);

}  // namespace toposlice
