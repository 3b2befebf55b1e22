#include "tools/slice_job.h"
#include "tools/slice_stages.h"

#include <sys/resource.h>
#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <memory>
#include <optional>

#include <nlohmann/json.hpp>

#include "core/memory_advice.h"
#include "core/mesh/mesh_info.h"
#include "core/mesh/variant_check.h"
#include "core/mesh/weld.h"
#include "core/number_text.h"
#include "core/print/corrections.h"
#include "core/print/printer.h"
#include "core/raster/rasterize.h"
#include "core/slicing/crossing.h"
#include "io/coders/mask_png.h"
#include "io/contours/cli_writer.h"
#include "io/contours/svg_writer.h"
#include "io/contours/threemf_writer.h"
#include "io/errors.h"
#include "io/jobs/layer_report.h"
#include "io/masks/mask_sink.h"
#include "io/output_file.h"
#include "offset/polygon_offset.h"
#include "parallel/parallel.h"
#include "parallel/variant_screen.h"

namespace toposlice {
namespace {

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

std::vector<std::unique_ptr<ContourSink>> openContourSinks(const SliceJobOptions& options,
                                                           const ContourJob& job, const FacetSoup* mesh,
                                                           std::span<const FacetSoup> features,
                                                           double layerHeight) {
  std::vector<std::unique_ptr<ContourSink>> sinks;
  for (const auto& path : options.outputs) {
    const std::string ext = lowerExtension(path);
    if (ext == ".cli") {
      sinks.push_back(makeCliWriter(path, job, options.cliBinary, options.overwrite));
    } else if (ext == ".svg") {
      std::vector<uint32_t> layers;
      std::string error;
      if (!parseLayerList(options.svgLayers, job.layerCount, layers, error))
        throw InputError("--svg-layers '" + options.svgLayers + "': " + error);
      sinks.push_back(makeSvgWriter(path, job, std::move(layers), options.overwrite));
    } else if (ext == ".3mf") {
      sinks.push_back(makeThreeMfWriter(path, job, mesh, options.overwrite, layerHeight, features));
    } else {
      throw InputError(path.string() + ": unknown contour output type '" + ext +
                       "' (use .cli, .svg or .3mf)");
    }
  }
  return sinks;
}

void buildTable(const FacetSoup& soup, std::vector<int32_t>& table, EdgeStats* stats, IndexedMesh* welded) {
  const ChunkRunner runner = parallelChunkRunner();
  const IndexedMesh mesh = welded && welded->facetVertices.size() == soup.corners.size()
                               ? std::move(*welded)
                               : weldCorners(soup.corners, runner);
  resizeFaultedIn(table, soup.corners.size(), runner);
  const EdgeStats s = buildAdjacency(mesh.facetVertices, mesh.vertices.size(), table, runner);
  if (stats) *stats = s;
}

// The model's adjacency: loaded from a verified template, built, or none (cp / sr-lazy discover it).
std::span<const int32_t> modelTopology(const std::filesystem::path& model, const FacetSoup& soup,
                                       const TemplateTable* templateTable, const SliceJobOptions& options,
                                       SliceJobResult& result, std::vector<int32_t>& built,
                                       IndexedMesh* welded) {
  const SliceMethod method = options.slice.method;
  bool build = method == SliceMethod::SelfReuse;
  if (templateTable != nullptr && method != SliceMethod::ClosestPoint) {
    const TemplateTable& table = *templateTable;
    // Linear check (core/mesh/variant_check.h): facet count, then every adjacent pair shares its edge.
    const std::optional<VariantMismatch> mismatch =
        checkVariantConnectivityParallel(soup.corners, table.adjacency);
    if (!mismatch) {
      result.topology = "loaded from template (connectivity verified)";
      return table.adjacency;
    }
    // Every facet the template's reversed (an inside-out variant flipped by --fix-orientation, or one
    // against a template that was flipped): corners 1 and 2 swapped, so edges 1 and 2 (each opposite
    // its corner) trade places and the table with those entries swapped describes it.
    reverseFacetsOfTable(table.adjacency, built);
    if (!checkVariantConnectivityParallel(soup.corners, built)) {
      result.topology = "loaded from template, every facet reversed (connectivity verified)";
      return built;
    }
    // The reason names the facet, edge and neighbour (or the facet counts) and says the connectivity differs.
    if (!options.rebuildOnMismatch) throw InputError(model.string() + ": " + mismatch->reason);
    result.topology = "template mismatch (" + mismatch->reason + "), rebuilt";
    // Said on stderr too (never hidden by --quiet): the variant did not share the template's connectivity.
    result.warnings.push_back(model.string() + ": does not match the template (" + mismatch->reason +
                              "): its adjacency was rebuilt, as asked");
  }
  if (build) {
    buildTable(soup, built, &result.edges, welded);
    result.edgesCounted = true;
    if (result.topology.empty()) result.topology = "built (weld + adjacency)";
    return built;
  }
  if (result.topology.empty())
    result.topology =
        method == SliceMethod::ClosestPoint ? "none (closest point)" : "discovered while slicing";
  return {};
}

// The layer height of uniform planes (not an explicit list): as given, else the planes' spacing, else
// (one plane, from a layer count) twice its height above z0, since layer 0 is cut at z0 + h / 2.
static double uniformLayerHeight(const PlaneSpec& spec, const std::vector<double>& planes, double zmin) {
  if (spec.layerHeight) return *spec.layerHeight;
  if (planes.size() >= 2) return planes[1] - planes[0];
  return planes.empty() ? 0.0 : 2 * (planes[0] - spec.z0.value_or(zmin));
}

// Thickness of layer k: h for uniform planes; for an explicit list, half the distance between the
// neighbouring planes (one-sided at the ends; 0 for a single plane). zmin: the model's lowest z.
double layerThickness(const std::vector<double>& planes, uint32_t k, const PlaneSpec& spec, double zmin) {
  if (spec.explicitZ.empty())
    return planes.size() >= 2 ? planes[1] - planes[0] : uniformLayerHeight(spec, planes, zmin);
  if (planes.size() < 2) return 0.0;  // one explicit plane: no thickness to infer
  const std::size_t lo = k == 0 ? 0 : k - 1, hi = std::min<std::size_t>(planes.size() - 1, k + 1);
  return (planes[hi] - planes[lo]) / static_cast<double>(hi - lo);
}

// The layer height as the user gave it (0.01, not the difference of two planes, 0.009999999999999998),
// so that printer files and the summary carry a value that reads back exactly; for an explicit list or a
// layer count, the distance between the first two planes.
double nominalLayerHeight(const PlaneSpec& spec, const std::vector<double>& planes, double zmin) {
  if (spec.explicitZ.empty()) return uniformLayerHeight(spec, planes, zmin);
  return planes.size() >= 2 ? planes[1] - planes[0] : 0.0;
}

void checkDisplayOverrides(const PrintSettings& print, const std::string& userOrigin, bool resolution,
                           bool pixel, std::optional<bool> mirrorX, std::optional<bool> mirrorY,
                           const DisplayOptionNames& names) {
  const auto userSet = [&](const char* key) {
    const auto origin = print.origin.find(key);
    return origin != print.origin.end() && origin->second == userOrigin;
  };
  const auto refuse = [&](const char* option, const char* key, const char* what) {
    throw InputError(std::string(option) + " and " + key + " (" + userOrigin + ") both give " + what +
                     ": give one of them");
  };
  for (const char* key : {"display_pixels_x", "display_pixels_y"})
    if (resolution && userSet(key)) refuse(names.resolution, key, "the image size");
  for (const char* key : {"display_width", "display_height"})
    if (pixel && userSet(key)) refuse(names.pixel, key, "the pixel size");
  const auto contradiction = [&](const char* option, const char* key, bool value) {
    throw InputError(std::string(option) + " and " + key + " " + (value ? "1" : "0") + " (" + userOrigin +
                     ") contradict each other: give one of them");
  };
  if (mirrorX && userSet("display_mirror_x") && *mirrorX != print.mirrorX)
    contradiction(names.mirrorX, "display_mirror_x", print.mirrorX);
  if (mirrorY && userSet("display_mirror_y") && *mirrorY != print.mirrorY)
    contradiction(names.mirrorY, "display_mirror_y", print.mirrorY);
}

void recordDisplayOptions(PrintSettings& print, MaskOptions& o, const char* resolutionName,
                          const char* pixelName) {
  if (!o.resolution && !o.pixel) return;
  const bool pixelGiven = o.pixel.has_value();
  // The printer's pitch, kept exactly as the masks use it (display_width / display_pixels_x).
  const double printerPixel =
      print.pixelsX > 0 && print.displayWidth > 0 ? print.displayWidth / print.pixelsX : 0.0;
  if (!pixelGiven && printerPixel > 0) o.pixel = printerPixel;
  const auto [width, height] =
      o.resolution.value_or(std::pair<uint32_t, uint32_t>{print.pixelsX, print.pixelsY});
  if (o.resolution) {
    assignSetting(print, "display_pixels_x", std::to_string(width), resolutionName);
    assignSetting(print, "display_pixels_y", std::to_string(height), resolutionName);
  }
  const auto nanometres = [](double mm) { return std::round(mm * 1e6) / 1e6; };
  // (A display wider than the setting's range, 100 m, keeps the printer's numbers: the masks are
  // refused as too large to fit in any case.)
  if (o.pixel && *o.pixel > 0 && width > 0 && height > 0 &&
      nanometres(std::max(width, height) * *o.pixel) <= 1e5) {
    const std::string origin = pixelGiven ? pixelName : resolutionName;
    assignSetting(print, "display_width", formatNumber(nanometres(width * *o.pixel)), origin);
    assignSetting(print, "display_height", formatNumber(nanometres(height * *o.pixel)), origin);
  }
}

BoundingBox contourExtent(const BoundingBox& box, const PrintSettings& print) {
  const float grow = static_cast<float>(std::max(0.0, print.absoluteCorrection));
  BoundingBox out = box;
  out.min = {box.min.x - grow, box.min.y - grow, box.min.z};
  out.max = {box.max.x + grow, box.max.y + grow, box.max.z};
  return out;
}

std::string unusedMaterialReason(const PrintSettings& print, bool summary, const std::string& written,
                                 const std::string& report) {
  std::string keys;
  for (const auto& [key, from] : print.origin) {
    if (!from.starts_with("material ") && from.find(" material ") == std::string::npos) continue;
    if (settingUnusedReason(key, {}, "", summary).empty()) return "";
    keys += (keys.empty() ? "" : ", ") + key;
  }
  if (!keys.empty())
    return "none of its settings (" + keys + ") changes " + written + (report.empty() ? "" : " or " + report);
  return report.empty() ? "it does not change " + written
                        : "it changes neither " + written + " nor " + report;
}

bool landscapeOnlyFormat(const std::string& ext) {
  return ext == ".exr" || ext == ".vdb" || ext == ".goo" || ext == ".nanodlp";
}

void checkElephantFootKeys(const PrintSettings& print,
                           const std::vector<std::pair<std::string, std::string>>& given,
                           const std::filesystem::path& jobFile, const std::string& where) {
  for (const auto& [k, value] : given)
    if (k.starts_with("elefant_foot_") && k != "elefant_foot_compensation" &&
        !(print.elefantFootCompensation > 0))
      throw InputError(jobFile.string() + ": " + where + k +
                       ": does nothing in this job: it needs elefant_foot_compensation > 0");
}

namespace {

bool setByPrinter(const PrintSettings& print, const char* key) {
  const auto origin = print.origin.find(key);
  return origin == print.origin.end() || origin->second.starts_with("printer ");
}

}  // namespace

PrintSettings settingsForMaskFormat(PrintSettings print, const std::filesystem::path& masks) {
  const std::string ext = lowerExtension(masks);
  if (print.orientation != "portrait" || !landscapeOnlyFormat(ext) ||
      !setByPrinter(print, "display_orientation"))
    return print;
  const auto origin = print.origin.find("display_orientation");
  const std::string why = (origin != print.origin.end() ? origin->second : std::string("printer")) + ", as " +
                          ext + " masks have it";
  assignSetting(print, "display_orientation", "landscape", why);
  for (const char* key : {"display_mirror_x", "display_mirror_y"})
    if (setByPrinter(print, key)) assignSetting(print, key, "0", why);
  return print;
}

MaskJob makeMaskJob(const MaskOptions& o, const PrintSettings& print, const BoundingBox& extent,
                    const std::string& name, const std::vector<double>& planes) {
  MaskJob job;
  job.name = name;
  job.vdbSlabs = o.vdbSlabs;
  uint32_t width = print.pixelsX, height = print.pixelsY;
  double pixel = print.pixelsX > 0 && print.displayWidth > 0 ? print.displayWidth / print.pixelsX : 0.0;
  // A display of the printer's own must have square pixels; a pixel the job gives replaces it (its
  // display_width and _height, recorded in nanometres, may then differ in the last digit).
  if (!o.pixel && print.pixelsY > 0 && print.displayHeight > 0 && pixel > 0 &&
      std::abs(print.displayHeight / print.pixelsY - pixel) > 1e-9 * pixel)
    throw InputError("printer '" + print.printerName + "': display_width / display_pixels_x (" +
                     formatNumber(pixel) + " mm) and display_height / display_pixels_y (" +
                     formatNumber(print.displayHeight / print.pixelsY) +
                     " mm) differ: toposlice's pixels are square");
  job.printerModel = print.printerModel;
  job.exposureTime = print.exposureTime;
  job.initialExposureTime = print.initialExposureTime;
  job.fadeLayers = print.fadedLayers;
  job.liftDistance = print.liftDistance;
  job.liftSpeed = print.liftSpeed;
  job.bottomLiftDistance = print.bottomLiftDistance;
  job.bottomLiftSpeed = print.bottomLiftSpeed;
  job.retractSpeed = print.retractSpeed;
  job.waitBeforeExposure = print.waitBeforeExposure;
  job.lightPwm = static_cast<uint8_t>(print.lightPwm);
  job.resinDensity = print.materialDensity;
  if (o.resolution) std::tie(width, height) = *o.resolution;
  if (o.pixel) pixel = *o.pixel;
  if (width == 0 || height == 0)
    throw InputError("masks need an image size: give --printer (" + printerNames() + ") or --resolution WxH");
  if (!(pixel > 0))
    throw InputError(print.printerName.empty() || o.pixel
                         ? "masks need a positive pixel size: give --pixel MM"
                         : "printer '" + print.printerName +
                               "' has no fixed pixel size: give --pixel MM (the display's pixel pitch)");
  // EXR and VDB stacks are volumes in the model's frame, GOO and NanoDLP files landscape images: a
  // preset's portrait display (sl1, sl1s) and its mirroring, which belongs to it, do not apply to them.
  const std::string ext = lowerExtension(o.output);
  // GOO's printer name: a built-in generic preset's printer_model is the SL1 model that SL1 archives
  // need, not a name of the printer; the preset's own name is.
  if (ext == ".goo" && setByPrinter(print, "printer_model")) {
    const std::optional<PrinterPreset> preset = findPrinter(print.printerName);
    const std::optional<PrinterPreset> named = findPrinter(print.printerModel);  // SL1, SL1S: their own
    if (preset && print.printerModel == preset->model &&
        !(named && named->name == std::string_view(preset->name)))
      job.printerModel = preset->name;
  }
  if (ext == ".goo" && print.printerModel.size() > 31)  // it was cut off there without a word
    throw InputError(o.output.string() + ": printer_model '" + print.printerModel + "' has " +
                     std::to_string(print.printerModel.size()) +
                     " bytes, and a GOO header holds a printer name of 31 at most");
  const bool portraitIgnored = print.orientation == "portrait" && landscapeOnlyFormat(ext);
  // --mirror-x/-y mirror on top of the printer's own mirroring (in PrusaSlicer's sense of the setting);
  // a mirroring the user set applies to every format (settingsForMaskFormat).
  const bool mirrorX =
      o.mirrorX || (print.mirrorX && (!portraitIgnored || !setByPrinter(print, "display_mirror_x")));
  const bool mirrorY =
      o.mirrorY || (print.mirrorY && (!portraitIgnored || !setByPrinter(print, "display_mirror_y")));
  job.grid = placeGrid(extent, width, height, pixel, o.origin, mirrorX, mirrorY);
  const double overhang = gridOverhang(extent, job.grid);
  if (overhang > 0 && !o.crop) {
    // Which edges the model crosses, and by how much, in the model's coordinates.
    const double x1 = job.grid.x0 + width * pixel, y1 = job.grid.y0 + height * pixel;
    const struct {
      double by;
      const char* side;
    } sides[] = {{job.grid.x0 - extent.min.x, "-x (left)"},
                 {double{extent.max.x} - x1, "+x (right)"},
                 {job.grid.y0 - extent.min.y, "-y (front)"},
                 {double{extent.max.y} - y1, "+y (back)"}};
    std::string where;
    for (const auto& side : sides) {
      if (!(side.by > 0)) continue;
      char part[96];
      std::snprintf(part, sizeof part, "%s%.3f mm beyond the %s edge", where.empty() ? "" : ", ", side.by,
                    side.side);
      where += part;
    }
    char text[640];
    std::snprintf(
        text, sizeof text,
        "the model (x %.3f .. %.3f, y %.3f .. %.3f mm) does not fit the %ux%u image at %g mm pixels "
        "(x %.3f .. %.3f, y %.3f .. %.3f mm): it sticks out %s (%s)",
        extent.min.x, extent.max.x, extent.min.y, extent.max.y, width, height, pixel, job.grid.x0, x1,
        job.grid.y0, y1, where.c_str(), o.fitAdvice.c_str());
    throw InputError(text);
  }
  const auto orientationSetBy = print.origin.find("display_orientation");
  if (portraitIgnored && orientationSetBy != print.origin.end() &&
      !orientationSetBy->second.starts_with("printer "))
    throw InputError(o.output.string() + ": display_orientation portrait (" + orientationSetBy->second +
                     ") applies to SL1 archives and PNG folders only; " + ext +
                     " stacks are written landscape");
  if (print.orientation == "portrait" && !portraitIgnored) {
    // PrusaSlicer's portrait images (checked pixel for pixel against its SL1s, bench/prusa_compare.sh
    // TOPO_PORTRAIT=1): with display_mirror_x = mx and display_mirror_y = my, the grid that runs along
    // the model's y across and its x up, mirrored by (!mx, my). The SL1's own setting (1, 0) is that grid
    // unmirrored.
    const PixelGrid bed = job.grid;
    job.grid.x0 = bed.y0;
    job.grid.y0 = bed.x0;
    job.grid.width = bed.height;
    job.grid.height = bed.width;
    job.grid.mirrorX = !bed.mirrorX;
    job.grid.mirrorY = bed.mirrorY;
    job.grid.transposed = true;
  }
  job.layerCount = static_cast<uint32_t>(planes.size());
  job.antiAliased = o.antialias || (print.gammaCorrection && *print.gammaCorrection > 0);
  job.printerProfile = print.printerName;
  job.materialName = print.materialName;
  job.settings = settingValues(print);
  // The display as the images have it: --resolution and --pixel override the printer's, and a printer
  // without a pixel pitch (generic-4k) gets one from --pixel (the EXR and VDB metadata said 0 there).
  const auto nanometres = [](double mm) { return std::round(mm * 1e6) / 1e6; };
  for (auto& [key, value] : job.settings) {
    if (key == "gamma_correction" && value.empty()) value = job.antiAliased ? "1" : "0";  // as chosen
    // The mirroring and orientation applied, not only the printer's: what the files' readers are told.
    if (key == "display_mirror_x") value = mirrorX ? "1" : "0";
    if (key == "display_mirror_y") value = mirrorY ? "1" : "0";
    if (key == "display_orientation" && portraitIgnored) value = "landscape";
    if (key == "display_pixels_x") value = std::to_string(width);
    if (key == "display_pixels_y") value = std::to_string(height);
    if (key == "display_width") value = formatNumber(nanometres(width * pixel));
    if (key == "display_height") value = formatNumber(nanometres(height * pixel));
  }
  return job;
}

namespace {

// The light-uniformity map: an 8-bit grayscale PNG as the display shows it (the masks' own layout and
// mirroring), exactly the masks' size.
MaskImage readLightMap(const std::filesystem::path& path, const MaskJob& job) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path.string() + ": cannot read the light map (light_map)");
  const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  MaskImage map;
  if (!decodeMaskPng(bytes, map))
    throw InputError(path.string() + ": the light map must be an 8-bit (or less) grayscale PNG");
  // The same display turned (a portrait printer's map for landscape-only masks, or the other way):
  // said as such, not only as the wrong size.
  if (map.width == job.grid.height && map.height == job.grid.width && map.width != map.height)
    throw InputError(
        path.string() + ": the light map is " + std::to_string(map.width) + "x" + std::to_string(map.height) +
        " pixels, the masks " + std::to_string(job.grid.width) + "x" + std::to_string(job.grid.height) +
        (job.grid.transposed
             ? " (the portrait display's): a portrait display's light map is a portrait image"
             : " (landscape: .goo, .nanodlp, .exr and .vdb masks are, whatever the display): the "
               "light map for them is the landscape image"));
  if (map.width != job.grid.width || map.height != job.grid.height)
    throw InputError(path.string() + ": the light map is " + std::to_string(map.width) + "x" +
                     std::to_string(map.height) + " pixels, the masks " + std::to_string(job.grid.width) +
                     "x" + std::to_string(job.grid.height) + ": it must have the display's size");
  return map;
}

}  // namespace

MaskTransfer maskTransfer(const PrintSettings& print, const MaskJob& job) {
  MaskTransfer t;
  t.gamma = job.antiAliased && print.gammaCorrection && *print.gammaCorrection != 1.0;
  if (t.gamma) t.gammaCurve = gammaCurve(*print.gammaCorrection);
  if (!print.lightMap.empty()) t.lightMap = lightMapOf(readLightMap(print.lightMap, job));
  return t;
}

LayerCorrection layerCorrection(const PrintSettings& print, uint32_t k, std::size_t layers) {
  const auto footLayers =
      static_cast<uint32_t>(std::clamp<std::size_t>(layers, 1, print.elephantFootFadeLayers()));
  return {print.absoluteCorrection, elephantFootAt(k, print.elefantFootCompensation, footLayers),
          print.elefantFootMinWidth};
}

nlohmann::ordered_json printSettingsJson(const PrintSettings& print, const char* scaleCentre,
                                         const char* antialiasBy, bool antialias) {
  nlohmann::ordered_json settings = nlohmann::ordered_json::object();
  for (const auto& [key, value] : settingValues(print))
    if (!value.empty()) settings[key] = value;
  nlohmann::ordered_json origins = nlohmann::ordered_json::object();
  for (const auto& [key, origin] : print.origin) origins[key] = origin;
  if (antialiasBy != nullptr && !print.gammaCorrection) {
    settings["gamma_correction"] = antialias ? "1" : "0";
    origins["gamma_correction"] = antialias ? antialiasBy : "default";
  }
  const auto scale = print.scale();
  return {{"printer", print.printerName},
          {"material", print.materialName},
          {"values", settings},
          {"set_by", origins},
          {"scale_xyz", {scale[0], scale[1], scale[2]}},
          {"scale_centre", scaleCentre}};
}

void checkMaskSettings(const PrintSettings& print, bool antialias, bool masks, const char* antialiasName) {
  if (print.gammaCorrection && *print.gammaCorrection == 0 && antialias)
    throw InputError(std::string(antialiasName) +
                     " and gamma_correction 0 (binary masks) contradict each other: give one");
  if (!print.lightMap.empty() && masks && !antialias &&
      !(print.gammaCorrection && *print.gammaCorrection > 0))
    throw InputError("light_map " + print.lightMap.string() + " multiplies anti-aliased masks: add " +
                     antialiasName + " (or gamma_correction > 0)");
}

void flipFacets(std::span<Point3f> corners) {
  for (std::size_t c = 0; c + 2 < corners.size(); c += 3) std::swap(corners[c + 1], corners[c + 2]);
}

std::string fixInsideOut(FacetSoup& soup, const std::string& named, bool fix, const std::string& option,
                         const std::string& consequence) {
  if (!(measureSoup(soup.corners).volume < 0)) return "";
  if (!fix)
    return named + " is inside out (negative volume), so it " + consequence + "; flip it with " + option;
  flipFacets(soup.corners);
  return named + " was inside out (negative volume): flipped (" + option + ")";
}

SoupMeasures measureSoup(std::span<const Point3f> corners) {
  constexpr std::size_t kBlock = 32768;  // facets
  const std::size_t facets = corners.size() / 3, blocks = (facets + kBlock - 1) / kBlock;
  std::vector<Point3f> extremes(2 * blocks);  // each block's bounding-box corners
  std::vector<uint64_t> degenerate(blocks, 0);
  std::vector<double> terms(blocks, 0.0);
  auto blockEnd = [&](std::size_t b) { return std::min(facets, (b + 1) * kBlock); };
  parallelForChunks(blocks, 1, [&](std::size_t b0, std::size_t b1) {
    for (std::size_t b = b0; b < b1; ++b) {
      const BoundingBox box = boundsOf(corners.subspan(3 * b * kBlock, 3 * (blockEnd(b) - b * kBlock)));
      extremes[2 * b] = box.min;
      extremes[2 * b + 1] = box.max;
      for (std::size_t f = b * kBlock; f < blockEnd(b); ++f)
        degenerate[b] += isDegenerateFacet(&corners[3 * f]);
    }
  });
  SoupMeasures m;
  m.bounds = boundsOf(extremes);
  parallelForChunks(blocks, 1, [&](std::size_t b0, std::size_t b1) {
    for (std::size_t b = b0; b < b1; ++b)
      terms[b] = signedVolumeTerms(corners, m.bounds, b * kBlock, blockEnd(b));
  });
  double sum = 0;
  for (const double t : terms) sum += t;
  m.volume = sum / 6.0;
  for (const uint64_t d : degenerate) m.degenerateFacets += d;
  return m;
}

double rasterizeLayerSets(std::span<const ContourSet> sets, const MaskJob& job, MaskImage& mask,
                          RasterScratch& scratch, const MaskTransfer* transfer) {
  if (job.antiAliased) {
    // Gamma and the light map are applied as the values are written (no second pass, only lit pixels);
    // the area is taken before them: they change the light, not the part.
    uint64_t valueSum = 0;  // maskArea without a pass over the image
    const bool gamma = transfer != nullptr && transfer->gamma;
    const bool light = transfer != nullptr && !transfer->lightMap.empty();
    CoverageTransfer coverage;
    coverage.curve = gamma ? &transfer->gammaCurve : nullptr;
    coverage.lightMap = light ? &transfer->lightMap : nullptr;
    rasterizeCoverage(sets, job.grid, mask, scratch, &valueSum, gamma || light ? &coverage : nullptr);
    return static_cast<double>(valueSum) / 255.0 * job.grid.pixel * job.grid.pixel;
  }
  uint64_t lit = 0;
  rasterizeBinary(sets, job.grid, mask, scratch, &lit);
  return static_cast<double>(lit) * job.grid.pixel * job.grid.pixel;
}

std::atomic<bool>& interruptRequested() {
  static std::atomic<bool> requested{false};
  return requested;
}

std::atomic<int>& readsInProgress() {
  static std::atomic<int> reads{0};
  return reads;
}

std::atomic<bool>& stopAtOnceWhileReading() {
  static std::atomic<bool> allowed{false};
  return allowed;
}

double peakResidentMiB() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;
}

// Two outputs with the same path would race for one name (and the first would stay behind when the
// second fails): refused before anything is read or written.
static std::vector<std::filesystem::path> allOutputs(const SliceJobOptions& options) {
  std::vector<std::filesystem::path> all = options.outputs;
  for (const auto* p : {&options.masks.output, &options.report, &options.summary})
    if (!p->empty()) all.push_back(*p);
  return all;
}

static void checkDistinctOutputs(const SliceJobOptions& options) {
  std::vector<std::filesystem::path> all = allOutputs(options);
  std::vector<std::filesystem::path> resolved;
  for (const auto& p : all) resolved.push_back(resolvedPath(p));
  for (std::size_t i = 0; i < all.size(); ++i)
    for (std::size_t j = i + 1; j < all.size(); ++j)
      if (resolved[i] == resolved[j])
        throw InputError(all[j].string() + ": given as more than one output" +
                         (all[i] == all[j] ? "" : " (it is " + all[i].string() + ")"));
  // A folder of masks (PNG or EXR layers) is made and replaced as a whole: no other output may lie in it.
  const std::string maskExt = lowerExtension(options.masks.output);
  if (options.masks.output.empty() || !(maskExt.empty() || maskExt == ".exr")) return;
  const std::filesystem::path folder = resolvedPath(options.masks.output);
  for (std::size_t i = 0; i < all.size(); ++i) {
    if (all[i] == options.masks.output) continue;
    const auto [f, o] = std::mismatch(folder.begin(), folder.end(), resolved[i].begin(), resolved[i].end());
    if (f == folder.end())
      throw InputError(all[i].string() + ": lies inside the mask folder " + options.masks.output.string() +
                       ", which this job writes as a whole: give it a place outside");
  }
}

void checkNotAnInput(const std::filesystem::path& output, const std::vector<std::filesystem::path>& inputs) {
  // An output that does not exist yet cannot be an input (inputs exist); one that does is compared by
  // device and inode, following links, so links and hard links to an input are caught as well.
  struct stat out {};
  if (::stat(output.c_str(), &out) != 0) return;
  if (S_ISDIR(out.st_mode)) {
    // A folder output (a PNG or EXR stack) replaces the whole folder: no input may lie inside it.
    const std::filesystem::path folder = resolvedPath(output);
    for (const auto& input : inputs) {
      if (input.empty()) continue;
      const std::filesystem::path in = resolvedPath(input);
      const auto [f, i] = std::mismatch(folder.begin(), folder.end(), in.begin(), in.end());
      if (f == folder.end() && i != in.end())
        throw InputError(output.string() + ": holds the job's input " + input.string() +
                         "; an output never replaces an input, even with --force");
    }
  }
  for (const auto& input : inputs) {
    struct stat in {};
    if (input.empty() || ::stat(input.c_str(), &in) != 0) continue;
    if (in.st_dev == out.st_dev && in.st_ino == out.st_ino)
      throw InputError(output.string() + ": is the job's input " + input.string() +
                       "; an output never replaces an input, even with --force");
  }
}

void checkFeatureFiles(const std::filesystem::path& model, const std::vector<std::filesystem::path>& add,
                       const std::vector<std::filesystem::path>& remove) {
  // Compared by device and inode (links and hard links too); a file that cannot be opened is left to
  // the reader's message.
  struct Seen {
    std::filesystem::path path;
    const char* role;
    dev_t dev;
    ino_t ino;
  };
  std::vector<Seen> seen;
  const auto see = [&seen](const std::filesystem::path& path, const char* role) {
    struct stat st {};
    if (path.empty() || ::stat(path.c_str(), &st) != 0) return;
    for (const Seen& s : seen) {
      if (s.dev != st.st_dev || s.ino != st.st_ino) continue;
      const std::string same = path == s.path ? "" : " (the same file as " + s.path.string() + ")";
      if (std::strcmp(s.role, "model") == 0)
        throw InputError(path.string() + ": the model itself given as " + role + same +
                         "; a feature is another mesh");
      if (std::strcmp(s.role, role) == 0)
        throw InputError(path.string() + ": given twice as " + role + same + "; give each feature once");
      throw InputError(path.string() + ": given both as " + s.role + " and as " + role + same +
                       "; a feature is added or removed, not both");
    }
    seen.push_back({path, role, st.st_dev, st.st_ino});
  };
  see(model, "model");
  for (const auto& f : add) see(f, "an add-on feature");
  for (const auto& f : remove) see(f, "a removal feature");
}

std::string maskOutputKinds() {
  return ".sl1, .sl1s, .goo, .nanodlp, .exr, .vdb, or a folder of PNGs (a name without an extension)";
}

void validateSliceOptions(const SliceJobOptions& options) {
  const SliceSettings& s = options.slice;
  if (!std::isfinite(s.closeGaps) || s.closeGaps < 0)
    throw InputError("--close-gaps " + formatNumber(s.closeGaps) + ": expected a distance >= 0 mm");
  if (!std::isfinite(s.joinTolerance) || !(s.joinTolerance > 0))
    throw InputError("--join-tolerance " + formatNumber(s.joinTolerance) + ": expected a distance > 0 mm");
  if (options.planes.layerHeight &&
      !(std::isfinite(*options.planes.layerHeight) && *options.planes.layerHeight > 0))
    throw InputError("--layer-height " + formatNumber(*options.planes.layerHeight) +
                     ": the layer height must be a number > 0 mm");
  if (options.planes.z0 && !std::isfinite(*options.planes.z0))
    throw InputError("--z0 " + formatNumber(*options.planes.z0) + ": expected a finite height in mm");
  if (options.planes.layers && *options.planes.layers == 0)
    throw InputError("--layers 0: expected at least 1");
  // Checked here, before the model is read, so that the message names --z rather than the model.
  const std::vector<double>& z = options.planes.explicitZ;
  for (std::size_t i = 0; i < z.size(); ++i) {
    if (!std::isfinite(z[i]))
      throw InputError("--z: " + formatNumber(z[i]) + " is not a finite height in mm");
    if (i > 0 && !(z[i] > z[i - 1]))
      throw InputError("--z: the planes must be strictly increasing (" + formatNumber(z[i - 1]) + " then " +
                       formatNumber(z[i]) + ")");
  }
  if (options.masks.pixel && !(std::isfinite(*options.masks.pixel) && *options.masks.pixel > 0))
    throw InputError("--pixel " + formatNumber(*options.masks.pixel) + ": expected a pixel size > 0 mm");
  if (options.masks.origin &&
      !(std::isfinite(options.masks.origin->first) && std::isfinite(options.masks.origin->second)))
    throw InputError("--origin: expected finite X,Y in mm");
  if (!options.masks.output.empty()) {
    const std::string ext = lowerExtension(options.masks.output);
    if (!ext.empty() && ext != ".sl1" && ext != ".sl1s" && ext != ".goo" && ext != ".nanodlp" &&
        ext != ".exr" && ext != ".vdb")
      throw InputError(options.masks.output.string() + ": toposlice does not write '" + ext +
                       "' masks; it writes " + maskOutputKinds());
    // A printer file moves the platform by one layer height for every layer: uneven planes would print
    // a part of another height (planes 0.5, 1, 3, 6 as 0.5, 1, 1.5, 2), so they are refused there.
    const bool printerFile = ext == ".sl1" || ext == ".sl1s" || ext == ".goo" || ext == ".nanodlp";
    if (const std::size_t i = firstUnevenPlane(z); printerFile && i < z.size())
      throw InputError("--z: the planes are not evenly spaced (" + formatNumber(z[1] - z[0]) + " mm, then " +
                       formatNumber(z[i] - z[i - 1]) + " mm), and " + options.masks.output.string() +
                       " moves the platform by one layer height for every layer: give even planes or "
                       "--layer-height, or write a PNG folder, .exr or .vdb");
  }
  for (const auto& path : options.outputs) {
    const std::string ext = lowerExtension(path);
    if (ext != ".cli" && ext != ".svg" && ext != ".3mf")
      throw InputError(path.string() + ": unknown contour output type '" + ext +
                       "' (use .cli, .svg or .3mf)");
  }
  checkMaskSettings(options.print, options.masks.antialias, !options.masks.output.empty(), "--antialias");
  if (!options.report.empty() && lowerExtension(options.report) != ".csv")
    throw InputError(options.report.string() + ": the per-layer report is CSV: give a .csv file name");
  if (!options.summary.empty() && lowerExtension(options.summary) != ".json")
    throw InputError(options.summary.string() + ": the summary is JSON: give a .json file name");
}

// A job whose planes all miss the model makes nothing: refused. Planes beyond the model's height on one
// side (a z0 below the model, say) are allowed, with a warning, since a user may mean them.
static void checkPlanesCutModel(const std::filesystem::path& model, const std::vector<double>& planes,
                                const SliceJobResult& result, const SliceJobOptions& options,
                                std::vector<std::string>& warnings) {
  if (planes.empty())
    throw InputError(model.string() + ": the planes give no layer to slice (layer height " +
                     formatNumber(options.planes.layerHeight.value_or(0)) + " mm)");
  const float zmin = result.printed.min.z, zmax = result.printed.max.z;  // mesh coordinates, printed as such
  std::size_t outside = 0;
  // A vertex on a plane counts as above it (DESIGN.md): a plane at the bottom cuts nothing, one at the
  // top cuts the facets that rise to it (the top face's outline).
  for (const double z : planes) outside += z <= zmin || z > zmax ? 1 : 0;
  const bool addOnsBeyond = zmin < result.bounds.min.z || zmax > result.bounds.max.z;
  const auto planeText = [](double z) { return readableNumber(std::round(z * 1e6) / 1e6); };  // 73.425
  char span[200];
  std::snprintf(span, sizeof span, "planes at z %s .. %s mm, the model%s spans z %s .. %s mm",
                planeText(planes.front()).c_str(), planeText(planes.back()).c_str(),
                addOnsBeyond ? " with its add-ons" : "", readableNumber(zmin).c_str(),
                readableNumber(zmax).c_str());
  if (outside == planes.size())
    throw InputError(model.string() + ": no plane cuts the model (" + span + "): nothing to slice");
  // The default planes (z0 at the model's bottom, ceil(height / h) layers) may end half a layer above the
  // top: that is the convention, not a choice to warn about.
  const bool chosen = options.planes.z0 || options.planes.layers || !options.planes.explicitZ.empty();
  if (outside > 0 && chosen)
    warnings.push_back(model.string() + ": " + std::to_string(outside) + " of " +
                       std::to_string(planes.size()) +
                       " layers lie outside the model's height and are empty (" + span + ")");
}

// The machine-readable summary (--summary FILE.json, docs/FORMATS.md): written through the job's
// transaction, so it appears only together with the outputs it lists.
static void writeSliceSummary(OutputFile& file, const std::filesystem::path& model,
                              const SliceJobOptions& options, const SliceJobResult& r,
                              const std::vector<double>& planes) {
  nlohmann::ordered_json j;
  j["toposlice"] = TOPOSLICE_VERSION_TEXT;
  j["model"] = model.string();
  j["format"] = std::string(meshFormatName(r.source.format)) + (r.source.gzip ? " (gzip)" : "");
  j["units_mm"] = options.read.unitMm.value_or(1.0);
  j["scale"] = options.read.scale;
  j["polygons_triangulated"] = r.source.polygonsTriangulated;
  j["facets"] = r.facets;
  j["bounds_mm"] = {{"min", {r.bounds.min.x, r.bounds.min.y, r.bounds.min.z}},
                    {"max", {r.bounds.max.x, r.bounds.max.y, r.bounds.max.z}}};
  j["method"] = sliceMethodName(options.slice.method);
  j["topology"] = r.topology;
  j["layers"] = {{"count", r.stats.layers},
                 {"first_z_mm", planes.front()},
                 {"last_z_mm", planes.back()},
                 {"layer_height_mm", nominalLayerHeight(options.planes, planes, r.printed.min.z)}};
  j["contours"] = {
      {"segments", r.stats.segments}, {"loops", r.stats.loops}, {"open_polylines", r.stats.openPolylines}};
  // Counted only where the adjacency was built: null (not 0) after a template's table or for cp / sr-lazy.
  const auto counted = [&](uint64_t n) { return r.edgesCounted ? nlohmann::ordered_json(n) : nullptr; };
  j["defects"] = {{"boundary_edges", counted(r.edges.boundary)},
                  {"non_manifold_edges", counted(r.edges.nonManifold)},
                  {"inconsistent_edges", counted(r.edges.inconsistent)}};
  j["repairs"] = {{"degenerate_facets_skipped", r.degenerateFacets},
                  {"gaps_bridged", r.stats.gaps.joins},
                  {"close_gaps_mm", options.slice.closeGaps},
                  {"loops_closed_by_bridges", r.stats.gaps.closedLoops},
                  {"wider_gaps_closed", r.stats.gaps.selfClosed},
                  {"loops_closed_by_wider_gaps", r.stats.gaps.closedLoopsWider},
                  {"polylines_left_open", r.stats.openPolylines},
                  {"inside_out", r.inverted},
                  {"orientation_flipped", r.flipped}};
  nlohmann::ordered_json features = nlohmann::ordered_json::array();
  for (const auto& f : options.add) features.push_back({{"role", "add"}, {"file", f.string()}});
  for (const auto& f : options.remove) features.push_back({{"role", "remove"}, {"file", f.string()}});
  j["features"] = features;
  j["print_settings"] =
      printSettingsJson(options.print, "bounding-box centre in x and y, lowest z",
                        options.masks.output.empty() ? nullptr : "--antialias", options.masks.antialias);
  j["volume_ml"] = r.volumeMl;
  j["resin_mass_g"] = r.volumeMl * options.print.materialDensity;
  j["volume_source"] =
      options.masks.output.empty() ? "contour area x layer thickness" : "lit mask area x layer thickness";
  j["model_volume_ml"] = std::abs(r.volume) / 1000.0;
  j["seconds"] = {{"read", r.readSeconds},
                  {"topology", r.topologySeconds},
                  {"slice_and_write", r.sliceSeconds},
                  {"total", r.readSeconds + r.topologySeconds + r.sliceSeconds}};
  j["peak_memory_mib"] = peakResidentMiB();
  nlohmann::ordered_json outputs = nlohmann::ordered_json::array();
  for (const auto& p : allOutputs(options)) outputs.push_back(p.string());
  j["outputs"] = outputs;
  j["warnings"] = r.warnings;
  const std::string text = j.dump(2) + "\n";
  file.write(text.data(), text.size());
  file.commit();
}

// Every input of the job: nothing it writes may be one of them.
static std::vector<std::filesystem::path> allInputs(const std::filesystem::path& model,
                                                    const SliceJobOptions& options) {
  std::vector<std::filesystem::path> inputs{model};
  inputs.insert(inputs.end(), options.add.begin(), options.add.end());
  inputs.insert(inputs.end(), options.remove.begin(), options.remove.end());
  if (!options.templateFile.empty()) inputs.push_back(options.templateFile);
  inputs.insert(inputs.end(), options.otherInputs.begin(), options.otherInputs.end());
  return inputs;
}

SliceJobResult runSliceJob(const std::filesystem::path& model, const SliceJobOptions& options,
                           const ProgressContext* progress) {
  const std::vector<std::filesystem::path> inputs = allInputs(model, options);
  for (const auto& output : allOutputs(options)) checkNotAnInput(output, inputs);
  validateSliceOptions(options);
  checkFeatureFiles(model, options.add, options.remove);
  checkDistinctOutputs(options);
  // An output that may not be written (it exists and there is no --force, or it is not toposlice's to
  // replace) is refused before the model is read, not after the work; each writer checks again when it
  // opens and when the job commits (a file may appear meanwhile).
  for (const auto& output : allOutputs(options)) {
    if (output == options.masks.output)
      checkMaskOutputAllowed(output, options.overwrite);
    else
      checkOutputAllowed(output, options.overwrite);
  }
  // Every output of the job joins this transaction: they appear together at the end, or not at all.
  OutputTransaction transaction;
  SliceJobResult result;
  auto start = std::chrono::steady_clock::now();
  FacetSoup soup;
  // The model, its features and the template file (its checksum checked) are read side by side; the
  // first input in that order that fails is the one reported, whatever the timing.
  TemplateTable loadedTemplate;
  const TemplateTable* templateTable = options.templateTable;
  const bool readTemplate = templateTable == nullptr && !options.templateFile.empty();
  std::vector<std::filesystem::path> featurePaths(options.add.begin(), options.add.end());
  featurePaths.insert(featurePaths.end(), options.remove.begin(), options.remove.end());
  std::vector<FacetSoup> features(featurePaths.size());  // add-ons first, then removals
  const std::size_t reads = 1 + featurePaths.size() + (readTemplate ? 1 : 0);
  std::vector<std::exception_ptr> readErrors(reads);
  // The model is welded while it is read where the reader can (a gzip'd binary STL) and the weld is
  // needed as read: the table is built, and no scaling correction changes the corners first.
  IndexedMesh welded;
  MeshReadOptions modelRead = options.read;
  if (options.slice.method == SliceMethod::SelfReuse && templateTable == nullptr && !readTemplate &&
      !options.print.scales())
    modelRead.weld = &welded;
  std::optional<ReadScope> reading(std::in_place);
  parallelForChunks(reads, 1, [&](std::size_t i0, std::size_t i1) {
    for (std::size_t i = i0; i < i1; ++i) try {
        if (i == 0)
          soup = readMesh(model, modelRead, &result.source);
        else if (i <= featurePaths.size())
          features[i - 1] = readMesh(featurePaths[i - 1], options.read);
        else
          loadedTemplate = readTemplateFile(options.templateFile);
      } catch (...) {
        readErrors[i] = std::current_exception();
      }
  });
  reading.reset();
  for (const std::exception_ptr& error : readErrors)
    if (error) std::rethrow_exception(error);
  if (readTemplate) templateTable = &loadedTemplate;
  result.readSeconds = secondsSince(start);
  result.facets = soup.facetCount();
  SoupMeasures measures = measureSoup(soup.corners);
  const PrintSettings& print = options.print;
  if (print.scales()) {
    // The scaling correction, once, on the model and its features about the model's centre (bottom
    // centre of its bounding box), so every output agrees and z scaling changes the layer count.
    const std::array<double, 3> centre = scaleCentre(measures.bounds), factors = print.scale();
    auto scaleAll = [&](std::vector<Point3f>& corners) {
      constexpr std::size_t kBlock = 65536;
      parallelForChunks((corners.size() + kBlock - 1) / kBlock, 1, [&](std::size_t b0, std::size_t b1) {
        const std::size_t end = std::min(corners.size(), b1 * kBlock);
        scaleCorners(std::span<Point3f>(corners).subspan(b0 * kBlock, end - b0 * kBlock), factors, centre);
      });
    };
    scaleAll(soup.corners);
    for (FacetSoup& f : features) scaleAll(f.corners);
    measures = measureSoup(soup.corners);
  }
  const std::span<const FacetSoup> addOns = std::span<const FacetSoup>(features).first(options.add.size());
  result.printed = unite(measures.bounds, addOns);
  const BoundingBox& printed = result.printed;
  const bool addOnsBeyond = printed.min.z < measures.bounds.min.z || printed.max.z > measures.bounds.max.z;
  if (print.maxPrintHeight > 0 && double{printed.max.z} - printed.min.z > print.maxPrintHeight)
    throw InputError(model.string() + ": the model" + (addOnsBeyond ? " with its add-ons" : "") + " is " +
                     formatNumber(printed.max.z - printed.min.z) +  // a float: "6.2"
                     " mm tall, more than the printer's max_print_height " +
                     formatNumber(print.maxPrintHeight) + " mm" +
                     (print.scales() ? " (after the scaling correction)" : ""));
  result.bounds = measures.bounds;
  result.volume = measures.volume;
  result.degenerateFacets = measures.degenerateFacets;
  result.inverted = result.volume < 0;
  if (result.inverted && options.fixOrientation) {
    flipFacets(soup.corners);
    for (std::size_t c = 0; c + 2 < welded.facetVertices.size(); c += 3)
      std::swap(welded.facetVertices[c + 1], welded.facetVertices[c + 2]);
    result.flipped = true;
  }
  // An inside-out feature counts with the opposite sign at the winding stage (an add-on would cut the
  // model away, a removal add to it): flipped with --fix-orientation, else a warning naming it.
  for (std::size_t i = 0; i < features.size(); ++i) {
    const std::string role = i < options.add.size() ? "add-on" : "removal";
    if (std::string w = fixInsideOut(features[i], featurePaths[i].string() + ": the " + role + " feature",
                                     options.fixOrientation, options.fixOrientationOption,
                                     "counts with the opposite sign");
        !w.empty())
      result.warnings.push_back(std::move(w));
  }

  // The topology (weld and adjacency, or the template check) and the outputs' set-up (planes, files,
  // the printer files' thumbnails) need nothing of each other: they run side by side. A topology error
  // is still the one reported when both fail, as when they ran one after the other.
  const SliceMethod method = options.slice.method;
  std::vector<int32_t> built;
  std::span<const int32_t> adjacency;
  std::vector<std::vector<int32_t>> featureTables(features.size());
  const auto topology = [&] {
    const auto begin = std::chrono::steady_clock::now();
    adjacency = modelTopology(model, soup, templateTable, options, result, built, &welded);
    // Features are separate meshes with their own tables; the template's table is never touched.
    if (method == SliceMethod::SelfReuse)
      for (std::size_t i = 0; i < features.size(); ++i) buildTable(features[i], featureTables[i]);
    result.topologySeconds = secondsSince(begin);
  };

  std::vector<double> planes;
  ContourJob job;
  std::vector<std::unique_ptr<ContourSink>> sinks;
  const bool masks = !options.masks.output.empty();
  MaskJob maskJob;
  std::unique_ptr<MaskSink> maskSink;
  MaskTransfer transfer;             // gamma and the light-uniformity map of every mask
  std::vector<Point3f> previewSoup;  // the model and its add-ons for the printer files' pictures
  std::unique_ptr<LayerReport> report;
  std::optional<OutputFile> summaryFile;  // opened with the other outputs, written at the end
  OutputTransaction* const outputs = OutputTransaction::current();
  const auto setUpOutputs = [&] {
    const OutputTransaction::Adopt use(outputs);  // this may run on another thread
    std::string error;
    planes = makePlanes(options.planes, result.printed.min.z, result.printed.max.z, error);
    if (!error.empty()) throw InputError(model.string() + ": " + error);
    checkPlanesCutModel(model, planes, result, options, result.warnings);
    if (masks && planes.size() == 1 && !options.planes.explicitZ.empty())
      throw InputError(
          "--z " + formatNumber(planes[0]) +
          ": one explicit plane gives its layer no thickness, which masks need (the layer height a "
          "printer file or an EXR/VDB volume records, the resin volume): give two planes or more, or "
          "--layers 1");

    job.name = model.stem().string();
    for (const char* ext : {".stl", ".ply", ".obj", ".3mf", ".STL", ".PLY", ".OBJ", ".3MF"})
      if (job.name.size() > 4 && job.name.ends_with(ext)) job.name.resize(job.name.size() - 4);
    // What is printed: the model and its add-ons (the masks' image is placed on it).
    const BoundingBox& extent = result.printed;
    // The contours' extent (a CLI's $$DIMENSION, an SVG's view box): every part's contours, the
    // removals' too, grown by a growing absolute_correction, so that it holds every corrected contour.
    job.bounds =
        contourExtent(unite(extent, std::span<const FacetSoup>(features).subspan(options.add.size())), print);
    job.layerCount = static_cast<uint32_t>(planes.size());
    job.outlinesCorrected = print.correctsOutlines();
    const auto partName = [](const std::filesystem::path& path) {  // "a.stl.gz" -> "a", as for the model
      std::string name = path.stem().string();
      if (name.size() > 4 && name.ends_with(".stl")) name.resize(name.size() - 4);
      return name;
    };
    for (const auto& path : options.add) job.features.push_back({partName(path), PartRole::Add});
    for (const auto& path : options.remove) job.features.push_back({partName(path), PartRole::Remove});
    const bool uniform = options.planes.explicitZ.empty();
    sinks = openContourSinks(options, job, &soup, features,
                             uniform && planes.size() >= 2 ? planes[1] - planes[0] : 0.0);

    // Masks: grid and sink (per-slot rasterizer state below).
    if (masks) {
      maskJob = makeMaskJob(options.masks, print, extent, job.name, planes);
      maskJob.layerHeight = nominalLayerHeight(options.planes, planes, result.printed.min.z);
      // Archive timestamps come from the model file, so the same input gives the same bytes.
      struct stat info {};
      if (::stat(model.c_str(), &info) == 0) maskJob.created = info.st_mtim.tv_sec;
      // The soup outlives the sink's use of it: its previews are drawn beside the bands (below). They
      // show what is printed: the model and its add-ons (a copy of both when there are add-ons).
      if (!options.add.empty()) {
        previewSoup = soup.corners;
        for (std::size_t i = 0; i < options.add.size(); ++i)
          previewSoup.insert(previewSoup.end(), features[i].corners.begin(), features[i].corners.end());
      }
      maskJob.previewModel = options.add.empty() ? std::span<const Point3f>(soup.corners) : previewSoup;
      maskJob.deferPreviews = true;
      maskJob.previewRunner = parallelChunkRunner();
      maskSink = makeMaskSink(options.masks.output, maskJob, options.overwrite);
      maskJob.previewModel = {};
    }
    if (masks) transfer = maskTransfer(print, maskJob);
    if (!options.report.empty()) report = std::make_unique<LayerReport>(options.report, options.overwrite);
    if (!options.summary.empty()) summaryFile.emplace(options.summary, options.overwrite);
  };
  parallelInvoke(topology, setUpOutputs);
  // Deferred previews (the printer files' pictures) are drawn as a task beside the bands. GOO and
  // NanoDLP store them at finish, which waits for the task. SL1 stores its thumbnails first, as when
  // drawn before: while the task draws, the in-order stage sets the encoded layers aside (moved out of
  // their slots, up to kHeldBytes) instead of waiting for it, so no thread idles there; they are
  // written, in order, once it is done. On one thread nothing else could draw them: the first layer
  // waits (and so draws them) at once.
  std::optional<BackgroundTask> previews;
  if (maskSink) previews.emplace([&maskSink] { maskSink->drawPreviews(); });
  struct HeldLayer {
    uint32_t k;
    EncodedMaskLayer encoded;
  };
  constexpr std::size_t kHeldBytes = std::size_t{64} << 20;
  std::vector<HeldLayer> held;
  std::size_t heldBytes = 0;
  const bool previewsFirst = maskSink && maskSink->previewsBeforeLayers();
  const bool holdLayers = previewsFirst && ThreadLimit::available() > 1;
  const auto writeHeldLayers = [&] {
    if (previews) previews->wait();
    for (HeldLayer& h : held) maskSink->writeEncodedLayer(h.k, planes[h.k], h.encoded);
    held.clear();
    heldBytes = 0;
  };

  std::vector<SliceMesh> meshes{{soup.corners, adjacency}};
  for (std::size_t i = 0; i < features.size(); ++i) meshes.push_back({features[i].corners, featureTables[i]});
  const std::size_t addCount = options.add.size();

  struct LayerResult {
    EncodedMaskLayer encoded;              // the mask as the sink encoded it (a PNG, an EXR file, mask runs)
    std::vector<LayerContours> corrected;  // with corrections: the corrected layer, then empty features
    bool correctedLayer = false;           // this layer's outputs are `corrected` (its correction is not nil)
    std::vector<TextBuffer> contourBytes;  // per contour sink that encodes its layers (CLI)
    double area = 0;
    uint64_t islands = 0;
  };
  struct SlotState : MaskSlotScratch {
    std::vector<LayerResult> layers;
    LayerContours rawLoops;  // with a growing correction: the layer's raw offset loops, for its masks
    LayerContours solid;     // without masks, a layer with features: its solid region's loops
  };
  const BandPlan plan = planBands(planes.size(), options.slice);
  std::vector<SlotState> slots(plan.slots);
  std::vector<const ContourSink*> encoding;  // contour sinks whose layers are made in the parallel stage
  for (const auto& sink : sinks)
    if (sink->encodesLayers()) encoding.push_back(sink.get());
  for (SlotState& s : slots) {
    s.layers.resize(plan.bandLayers);
    for (LayerResult& r : s.layers) r.contourBytes.resize(encoding.size());
  }
  double volumeMm3 = 0;
  double litArea = 0;  // summed over the layers: a job of one explicit plane has no volume, but an area

  LayerStages stages;
  // Per-layer area and islands feed the masks (the archive's resin volume) and the report; a contour-only
  // run without a report prints no volume, so it skips that pass over every point.
  const bool measureLayers = masks || report || !options.summary.empty();
  const bool polygonsNeeded = !sinks.empty() || report != nullptr;  // outputs made of the corrected loops
  stages.process = [&](uint32_t k, std::span<const LayerContours> sliced, std::size_t slot,
                       uint32_t position) {
    SlotState& s = slots[slot];
    LayerResult& r = s.layers[position];
    std::span<const LayerContours> layer = sliced;
    bool raw = false;  // the masks rasterize s.rawLoops
    // A layer whose correction is nil (no correction set, or above the elephant foot without an absolute
    // one) is the sliced layer, not a union of it.
    const LayerCorrection correction = layerCorrection(print, k, planes.size());
    r.correctedLayer = correction.any();
    if (r.correctedLayer) {
      // Absolute correction and elephant foot on the layer's solid region (model, add-ons and removals
      // under the positive rule): every output below and in consume sees the corrected layer.
      r.corrected.resize(sliced.size());
      s.sets.clear();
      for (std::size_t i = 0; i < sliced.size(); ++i)
        s.sets.push_back({&sliced[i], i == 0 || i <= addCount ? 1 : -1});
      // An absolute correction alone: the masks (binary or anti-aliased) rasterize the raw offset loops,
      // whose positive-winding region is the corrected one (polygon_offset.h), and the polygons, when
      // contour outputs or the report need them, are those loops united (correctLayer's result, exactly).
      raw = masks && rawCorrectedLoops(s.sets, correction, sliced[0].z, s.rawLoops);
      if (!raw)
        correctLayer(s.sets, correction, sliced[0].z, r.corrected[0]);
      else if (polygonsNeeded)
        unitePositive(s.rawLoops, sliced[0].z, r.corrected[0]);
      else
        r.corrected[0].clear(sliced[0].z);
      for (std::size_t i = 1; i < sliced.size(); ++i) r.corrected[i].clear(sliced[i].z);
      layer = r.corrected;
    }
    for (std::size_t i = 0; i < encoding.size(); ++i) encoding[i]->encodeLayer(layer, r.contourBytes[i]);
    if (!measureLayers) return;
    r.islands = 0;
    double modelArea = 0;
    for (std::size_t l = 0; l < layer[0].loopCount(); ++l) {
      const double area = signedArea(layer[0].loopPoints(l));
      r.islands += layer[0].loopClosed[l] && area > 0 ? 1 : 0;
      modelArea += area;
    }
    if (!masks) {
      r.area = modelArea;  // layerSignedArea(layer[0]), without a second pass
      // With features, or outer loops that may overlap, the solid region under the positive rule, as
      // the masks light it: an add-on over the model counts once, a removal reaching out of it takes
      // nothing there (the signed areas' sum counted both, off by 0.5 % on the aligner's monogram
      // layers), and where two shells of the model intersect their common part counts once.
      if (std::any_of(layer.begin() + 1, layer.end(),
                      [](const LayerContours& f) { return f.loopCount() > 0; }) ||
          outerLoopsMayOverlap(layer[0])) {
        s.sets.clear();
        for (std::size_t i = 0; i < layer.size(); ++i)
          s.sets.push_back({&layer[i], i == 0 || i <= addCount ? 1 : -1});
        correctLayer(s.sets, LayerCorrection{}, layer[0].z, s.solid);
        r.area = 0;
        for (std::size_t l = 0; l < s.solid.loopCount(); ++l) r.area += signedArea(s.solid.loopPoints(l));
      }
      return;
    }
    s.sets.clear();
    if (raw)
      s.sets.push_back({&s.rawLoops, 1});
    else
      for (std::size_t i = 0; i < layer.size(); ++i)
        s.sets.push_back({&layer[i], i == 0 || i <= addCount ? 1 : -1});
    r.area = rasterizeLayerSets(s.sets, maskJob, s.mask, s.raster, &transfer);
    maskSink->encodeLayer(k, planes[k], s.mask, r.encoded, s.encodeScratch);
  };
  stages.consume = [&](uint32_t k, std::span<const LayerContours> layer, std::size_t slot,
                       uint32_t position) {
    LayerResult& r = slots[slot].layers[position];
    if (r.correctedLayer) layer = r.corrected;
    for (std::size_t i = 0, e = 0; i < sinks.size(); ++i) {
      if (sinks[i]->encodesLayers())
        sinks[i]->writeEncodedLayer(k, r.contourBytes[e++]);
      else
        sinks[i]->writeLayer(k, layer);
    }
    if (maskSink) {
      if (holdLayers && previews && !previews->done() && heldBytes + r.encoded.bytes.size() <= kHeldBytes) {
        heldBytes += r.encoded.bytes.size();
        held.push_back({k, std::move(r.encoded)});  // the slot's next encodeLayer allocates anew
      } else {
        if (previewsFirst) writeHeldLayers();
        maskSink->writeEncodedLayer(k, planes[k], r.encoded);
      }
    }
    if (report) report->addLayer(k, planes[k], r.area, layer[0].loopCount(), r.islands);
    volumeMm3 += r.area * layerThickness(planes, k, options.planes, result.printed.min.z);
    litArea += r.area;
  };

  start = std::chrono::steady_clock::now();
  ProgressContext context = progress ? *progress : ProgressContext{};
  context.cancel = &interruptRequested();
  result.stats = sliceMeshes(meshes, planes, options.slice, stages, &context);
  if (result.stats.cancelled) throw InputError("interrupted");
  result.volumeMl = volumeMm3 / 1000.0;
  if (result.inverted && !result.flipped)
    result.warnings.push_back(model.string() + ": the mesh is inside out (negative volume); flip it with " +
                              options.fixOrientationOption);
  // Results that hold nothing are refused before any output appears.
  if (result.stats.loops == 0 && result.stats.openPolylines == 0)
    throw InputError(model.string() + ": every one of the " + std::to_string(planes.size()) +
                     " layers is empty: nothing to write");
  if (masks && !(litArea > 0))
    throw InputError(model.string() + ": every mask layer is dark: nothing would print" +
                     (result.inverted && !result.flipped
                          ? " (the mesh is inside out: flip it with " + options.fixOrientationOption + ")"
                          : " (the contours enclose no area on the pixel grid)"));
  for (auto& sink : sinks) sink->finish();
  if (maskSink) {
    writeHeldLayers();
    maskJob.volumeMl = result.volumeMl;
    maskSink->finish(maskJob);
  }
  if (report) report->finish();
  result.sliceSeconds = secondsSince(start);
  if (summaryFile) writeSliceSummary(*summaryFile, model, options, result, planes);
  transaction.commit(&interruptRequested());
  result.written = transaction.committed();
  return result;
}

}  // namespace toposlice
