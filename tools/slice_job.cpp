#include "tools/slice_job.h"

#include <sys/resource.h>

#include <chrono>
#include <memory>

#include "core/crossing.h"
#include "core/mesh_info.h"
#include "core/variant_check.h"
#include "core/weld.h"
#include "io/cli_writer.h"
#include "io/errors.h"
#include "io/stl_reader.h"
#include "io/svg_writer.h"

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

std::vector<std::unique_ptr<ContourSink>> openContourSinks(const SliceJobOptions& options, const ContourJob& job) {
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
    } else {
      throw InputError(path.string() + ": unknown contour output type '" + ext + "' (use .cli or .svg)");
    }
  }
  return sinks;
}

}  // namespace

double peakResidentMiB() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;
}

SliceJobResult runSliceJob(const std::filesystem::path& model, const SliceJobOptions& options,
                           const ProgressContext* progress) {
  SliceJobResult result;
  auto start = std::chrono::steady_clock::now();
  FacetSoup soup = readStl(model);
  result.readSeconds = secondsSince(start);
  result.facets = soup.facetCount();
  result.bounds = boundsOf(soup.corners);
  result.volume = signedVolume(soup.corners);
  result.inverted = result.volume < 0;
  if (result.inverted && options.fixOrientation) {
    for (std::size_t c = 0; c < soup.corners.size(); c += 3) std::swap(soup.corners[c + 1], soup.corners[c + 2]);
    result.flipped = true;
  }
  for (std::size_t c = 0; c < soup.corners.size(); c += 3) result.degenerateFacets += isDegenerateFacet(&soup.corners[c]);

  start = std::chrono::steady_clock::now();
  std::vector<int32_t> built;
  std::span<const int32_t> adjacency;
  const SliceMethod method = options.slice.method;
  bool build = method == SliceMethod::SelfReuse;
  if (options.templateTable != nullptr && method != SliceMethod::ClosestPoint) {
    const TemplateTable& table = *options.templateTable;
    std::optional<VariantMismatch> mismatch;
    if (table.facetCount != soup.facetCount()) {
      mismatch = VariantMismatch{kNoIndex, kNoIndex, kNoIndex,
                                 "it has " + std::to_string(soup.facetCount()) + " facets, the template " +
                                     std::to_string(table.facetCount)};
    } else {
      mismatch = checkVariantConnectivity(soup.corners, table.adjacency);
    }
    if (!mismatch) {
      adjacency = table.adjacency;
      build = false;
      result.topology = "loaded from template (connectivity verified)";
    } else {
      std::string where = mismatch->reason;
      if (mismatch->facet != kNoIndex)
        where = "facet " + std::to_string(mismatch->facet) + " edge " + std::to_string(mismatch->edge) +
                " (neighbour " + std::to_string(mismatch->neighbour) + "): " + mismatch->reason;
      if (!options.rebuildOnMismatch)
        throw InputError(model.string() + ": does not share the template's connectivity: " + where);
      result.topology = "template mismatch (" + where + "), rebuilt";
      build = method == SliceMethod::SelfReuse;
    }
  }
  if (build) {
    const IndexedMesh mesh = weldCorners(soup.corners);
    built.resize(soup.corners.size());
    result.edges = buildAdjacency(mesh.facetVertices, mesh.vertices.size(), built);
    adjacency = built;
    if (result.topology.empty()) result.topology = "built (weld + adjacency)";
  } else if (result.topology.empty()) {
    result.topology = method == SliceMethod::ClosestPoint ? "none (closest point)" : "discovered while slicing";
  }
  result.topologySeconds = secondsSince(start);

  std::string error;
  const std::vector<double> planes = makePlanes(options.planes, result.bounds.min.z, result.bounds.max.z, error);
  if (!error.empty()) throw InputError(model.string() + ": " + error);

  ContourJob job;
  job.name = model.stem().string();
  if (job.name.size() > 4 && job.name.ends_with(".stl")) job.name.resize(job.name.size() - 4);
  job.bounds = result.bounds;
  job.layerCount = static_cast<uint32_t>(planes.size());
  auto sinks = openContourSinks(options, job);

  start = std::chrono::steady_clock::now();
  result.stats = sliceModel(soup.corners, adjacency, planes, options.slice,
                            [&](uint32_t k, const LayerContours& layer) {
                              for (auto& sink : sinks) sink->writeLayer(k, layer);
                            },
                            progress);
  if (result.stats.cancelled) throw InputError("interrupted");
  for (auto& sink : sinks) sink->finish();
  result.sliceSeconds = secondsSince(start);
  result.written = options.outputs;
  return result;
}

}  // namespace toposlice
