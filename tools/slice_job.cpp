#include "tools/slice_job.h"

#include <sys/resource.h>
#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>

#include "core/crossing.h"
#include "core/mesh_info.h"
#include "core/printer.h"
#include "core/rasterize.h"
#include "core/variant_check.h"
#include "core/weld.h"
#include "io/contours/cli_writer.h"
#include "io/contours/svg_writer.h"
#include "io/contours/threemf_writer.h"
#include "io/errors.h"
#include "io/jobs/layer_report.h"
#include "io/masks/mask_sink.h"
#include "io/readers/stl_reader.h"
#include "parallel/parallel.h"
#include "parallel/variant_screen.h"

namespace toposlice {
namespace {

double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

std::string lowerExtension(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

std::vector<std::unique_ptr<ContourSink>> openContourSinks(const SliceJobOptions& options,
                                                           const ContourJob& job, const FacetSoup& mesh,
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
      sinks.push_back(makeThreeMfWriter(path, job, &mesh, options.overwrite, layerHeight));
    } else {
      throw InputError(path.string() + ": unknown contour output type '" + ext +
                       "' (use .cli, .svg or .3mf)");
    }
  }
  return sinks;
}

void buildTable(const FacetSoup& soup, std::vector<int32_t>& table, EdgeStats* stats = nullptr) {
  const IndexedMesh mesh = weldCorners(soup.corners);
  table.resize(soup.corners.size());
  const EdgeStats s = buildAdjacency(mesh.facetVertices, mesh.vertices.size(), table);
  if (stats) *stats = s;
}

// The model's adjacency: loaded from a verified template, built, or none (cp / sr-lazy discover it).
std::span<const int32_t> modelTopology(const std::filesystem::path& model, const FacetSoup& soup,
                                       const TemplateTable* templateTable, const SliceJobOptions& options,
                                       SliceJobResult& result, std::vector<int32_t>& built) {
  const SliceMethod method = options.slice.method;
  bool build = method == SliceMethod::SelfReuse;
  if (templateTable != nullptr && method != SliceMethod::ClosestPoint) {
    const TemplateTable& table = *templateTable;
    // Linear check (core/variant_check.h): facet count, then every adjacent pair shares its edge.
    const std::optional<VariantMismatch> mismatch =
        checkVariantConnectivityParallel(soup.corners, table.adjacency);
    if (!mismatch) {
      result.topology = "loaded from template (connectivity verified)";
      return table.adjacency;
    }
    // The reason names the facet, edge and neighbour (or the facet counts) and says the connectivity differs.
    if (!options.rebuildOnMismatch) throw InputError(model.string() + ": " + mismatch->reason);
    result.topology = "template mismatch (" + mismatch->reason + "), rebuilt";
  }
  if (build) {
    buildTable(soup, built, &result.edges);
    if (result.topology.empty()) result.topology = "built (weld + adjacency)";
    return built;
  }
  if (result.topology.empty())
    result.topology =
        method == SliceMethod::ClosestPoint ? "none (closest point)" : "discovered while slicing";
  return {};
}

// Thickness of layer k: h for uniform planes; for an explicit list, half the distance between the
// neighbouring planes (one-sided at the ends).
double layerThickness(const std::vector<double>& planes, uint32_t k, const PlaneSpec& spec) {
  if (spec.explicitZ.empty() && planes.size() >= 2) return planes[1] - planes[0];
  if (planes.size() < 2) return spec.layerHeight.value_or(0.0);
  const std::size_t lo = k == 0 ? 0 : k - 1, hi = std::min<std::size_t>(planes.size() - 1, k + 1);
  return (planes[hi] - planes[lo]) / static_cast<double>(hi - lo);
}

MaskJob makeMaskJob(const MaskOptions& o, const BoundingBox& extent, const std::string& name,
                    const std::vector<double>& planes) {
  MaskJob job;
  job.name = name;
  uint32_t width = 0, height = 0;
  double pixel = 0;
  if (!o.printer.empty()) {
    const auto preset = findPrinter(o.printer);
    if (!preset) throw InputError("unknown printer '" + o.printer + "' (known: " + printerNames() + ")");
    width = preset->width;
    height = preset->height;
    pixel = preset->pixel;
    job.printerModel = preset->model;
  }
  if (o.resolution) std::tie(width, height) = *o.resolution;
  if (o.pixel) pixel = *o.pixel;
  if (width == 0 || height == 0)
    throw InputError("masks need an image size: give --printer (" + printerNames() + ") or --resolution WxH");
  if (!(pixel > 0)) throw InputError("masks need a positive pixel size: give --pixel MM");
  job.grid = placeGrid(extent, width, height, pixel, o.origin, o.mirrorX, o.mirrorY);
  const double overhang = gridOverhang(extent, job.grid);
  if (overhang > 0 && !o.crop) {
    char text[256];
    std::snprintf(text, sizeof text,
                  "the model does not fit the %ux%u image at %g mm pixels (%.3f x %.3f mm): it sticks out by "
                  "%.3f mm (use --crop to cut it off, a smaller model or larger pixels)",
                  width, height, pixel, width * pixel, height * pixel, overhang);
    throw InputError(text);
  }
  job.layerHeight = planes.size() >= 2 ? planes[1] - planes[0] : 0.0;
  job.layerCount = static_cast<uint32_t>(planes.size());
  job.antiAliased = o.antialias;
  return job;
}

}  // namespace

// Bounds, signed volume and degenerate facets of a soup, in parallel over fixed blocks of facets whose
// partial sums are added in block order: the same bits for any thread count.
struct SoupMeasures {
  BoundingBox bounds;
  double volume = 0;
  uint64_t degenerateFacets = 0;
};

static SoupMeasures measureSoup(std::span<const Point3f> corners) {
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

std::atomic<bool>& interruptRequested() {
  static std::atomic<bool> requested{false};
  return requested;
}

double peakResidentMiB() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;
}

// Two outputs with the same path would race for one name (and the first would stay behind when the
// second fails): refused before anything is read or written.
static void checkDistinctOutputs(const SliceJobOptions& options) {
  std::vector<std::filesystem::path> all = options.outputs;
  if (!options.masks.output.empty()) all.push_back(options.masks.output);
  if (!options.report.empty()) all.push_back(options.report);
  for (auto& p : all) p = std::filesystem::absolute(p).lexically_normal();
  for (std::size_t i = 0; i < all.size(); ++i)
    for (std::size_t j = i + 1; j < all.size(); ++j)
      if (all[i] == all[j]) throw InputError(all[i].string() + ": given as more than one output");
}

SliceJobResult runSliceJob(const std::filesystem::path& model, const SliceJobOptions& options,
                           const ProgressContext* progress) {
  checkDistinctOutputs(options);
  SliceJobResult result;
  auto start = std::chrono::steady_clock::now();
  FacetSoup soup;
  // A template file is read (and its checksum checked) on a second thread while the model is read.
  TemplateTable loadedTemplate;
  const TemplateTable* templateTable = options.templateTable;
  if (templateTable == nullptr && !options.templateFile.empty()) {
    parallelInvoke([&] { loadedTemplate = readTemplateFile(options.templateFile); },
                   [&] { soup = readStl(model); });
    templateTable = &loadedTemplate;
  } else {
    soup = readStl(model);
  }
  std::vector<FacetSoup> features;  // add-ons first, then removals
  for (const auto* list : {&options.add, &options.remove})
    for (const auto& path : *list) features.push_back(readStl(path));
  result.readSeconds = secondsSince(start);
  result.facets = soup.facetCount();
  const SoupMeasures measures = measureSoup(soup.corners);
  result.bounds = measures.bounds;
  result.volume = measures.volume;
  result.degenerateFacets = measures.degenerateFacets;
  result.inverted = result.volume < 0;
  if (result.inverted && options.fixOrientation) {
    for (std::size_t c = 0; c < soup.corners.size(); c += 3)
      std::swap(soup.corners[c + 1], soup.corners[c + 2]);
    result.flipped = true;
  }

  start = std::chrono::steady_clock::now();
  const SliceMethod method = options.slice.method;
  std::vector<int32_t> built;
  std::span<const int32_t> adjacency = modelTopology(model, soup, templateTable, options, result, built);
  // Features are separate meshes with their own tables; the template's table is never touched.
  std::vector<std::vector<int32_t>> featureTables(features.size());
  if (method == SliceMethod::SelfReuse)
    for (std::size_t i = 0; i < features.size(); ++i) buildTable(features[i], featureTables[i]);
  result.topologySeconds = secondsSince(start);

  std::string error;
  const std::vector<double> planes =
      makePlanes(options.planes, result.bounds.min.z, result.bounds.max.z, error);
  if (!error.empty()) throw InputError(model.string() + ": " + error);

  ContourJob job;
  job.name = model.stem().string();
  if (job.name.size() > 4 && job.name.ends_with(".stl")) job.name.resize(job.name.size() - 4);
  job.bounds = result.bounds;
  job.layerCount = static_cast<uint32_t>(planes.size());
  const bool uniform = options.planes.explicitZ.empty();
  auto sinks =
      openContourSinks(options, job, soup, uniform && planes.size() >= 2 ? planes[1] - planes[0] : 0.0);

  // Masks: grid, sink, and per-slot rasterizer state.
  const bool masks = !options.masks.output.empty();
  MaskJob maskJob;
  std::unique_ptr<MaskSink> maskSink;
  if (masks) {
    BoundingBox extent = result.bounds;
    for (std::size_t i = 0; i < options.add.size(); ++i) {
      const BoundingBox b = boundsOf(features[i].corners);
      extent.min = {std::min(extent.min.x, b.min.x), std::min(extent.min.y, b.min.y), extent.min.z};
      extent.max = {std::max(extent.max.x, b.max.x), std::max(extent.max.y, b.max.y), extent.max.z};
    }
    maskJob = makeMaskJob(options.masks, extent, job.name, planes);
    // Archive timestamps come from the model file, so the same input gives the same bytes.
    struct stat info {};
    if (::stat(model.c_str(), &info) == 0) maskJob.created = info.st_mtim.tv_sec;
    maskSink = makeMaskSink(options.masks.output, maskJob, options.overwrite);
  }
  std::unique_ptr<LayerReport> report;
  if (!options.report.empty()) report = std::make_unique<LayerReport>(options.report, options.overwrite);

  std::vector<SliceMesh> meshes{{soup.corners, adjacency}};
  for (std::size_t i = 0; i < features.size(); ++i) meshes.push_back({features[i].corners, featureTables[i]});
  const std::size_t addCount = options.add.size();

  struct LayerResult {
    EncodedMaskLayer encoded;  // the mask as the sink encoded it (a PNG, an EXR file, mask runs)
    double area = 0;
    uint64_t islands = 0;
  };
  struct SlotState {
    RasterScratch raster;
    MaskImage mask;
    std::vector<ContourSet> sets;
    std::vector<LayerResult> layers;
    MaskEncodeScratch encodeScratch;
  };
  const BandPlan plan = planBands(planes.size(), options.slice);
  std::vector<SlotState> slots(plan.slots);
  for (SlotState& s : slots) s.layers.resize(plan.bandLayers);
  double volumeMm3 = 0;

  LayerStages stages;
  // Per-layer area and islands feed the masks (the archive's resin volume) and the report; a contour-only
  // run without a report prints no volume, so it skips that pass over every point.
  const bool measureLayers = masks || report;
  stages.process = [&](uint32_t k, std::span<const LayerContours> layer, std::size_t slot,
                       uint32_t position) {
    if (!measureLayers) return;
    SlotState& s = slots[slot];
    LayerResult& r = s.layers[position];
    r.islands = 0;
    double modelArea = 0;
    for (std::size_t l = 0; l < layer[0].loopCount(); ++l) {
      const double area = signedArea(layer[0].loopPoints(l));
      r.islands += layer[0].loopClosed[l] && area > 0 ? 1 : 0;
      modelArea += area;
    }
    if (!masks) {
      r.area = modelArea;  // layerSignedArea(layer[0]), without a second pass
      for (std::size_t i = 1; i < layer.size(); ++i)
        r.area += (i <= addCount ? 1 : -1) * layerSignedArea(layer[i]);
      return;
    }
    s.sets.clear();
    for (std::size_t i = 0; i < layer.size(); ++i)
      s.sets.push_back({&layer[i], i == 0 || i <= addCount ? 1 : -1});
    if (maskJob.antiAliased) {
      rasterizeCoverage(s.sets, maskJob.grid, s.mask, s.raster);
      r.area = maskArea(s.mask, maskJob.grid.pixel);
    } else {
      uint64_t lit = 0;
      rasterizeBinary(s.sets, maskJob.grid, s.mask, s.raster, &lit);
      r.area = static_cast<double>(lit) * maskJob.grid.pixel * maskJob.grid.pixel;
    }
    maskSink->encodeLayer(k, planes[k], s.mask, r.encoded, s.encodeScratch);
  };
  stages.consume = [&](uint32_t k, std::span<const LayerContours> layer, std::size_t slot,
                       uint32_t position) {
    const LayerResult& r = slots[slot].layers[position];
    for (auto& sink : sinks) sink->writeLayer(k, layer[0]);
    if (maskSink) maskSink->writeEncodedLayer(k, planes[k], r.encoded);
    if (report) report->addLayer(k, planes[k], r.area, layer[0].loopCount(), r.islands);
    volumeMm3 += r.area * layerThickness(planes, k, options.planes);
  };

  start = std::chrono::steady_clock::now();
  ProgressContext context = progress ? *progress : ProgressContext{};
  context.cancel = &interruptRequested();
  result.stats = sliceMeshes(meshes, planes, options.slice, stages, &context);
  if (result.stats.cancelled) throw InputError("interrupted");
  result.volumeMl = volumeMm3 / 1000.0;
  for (auto& sink : sinks) sink->finish();
  result.written = options.outputs;
  if (maskSink) {
    maskJob.volumeMl = result.volumeMl;
    maskSink->finish(maskJob);
    result.written.push_back(options.masks.output);
  }
  if (report) {
    report->finish(result.volumeMl);
    result.written.push_back(options.report);
  }
  result.sliceSeconds = secondsSince(start);
  return result;
}

}  // namespace toposlice
