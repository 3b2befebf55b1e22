// toposlice: the command-line program. Subcommands: info, slice, template, batch, preview, plate.
// Every failure prints one line "toposlice: error: <reason>" to stderr and exits non-zero.
#include <fcntl.h>
#include <unistd.h>
#include <CLI/CLI.hpp>

#include <algorithm>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <new>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "core/edit_distance.h"
#include "core/memory_advice.h"
#include "core/mesh/mesh_info.h"
#include "core/mesh/weld.h"
#include "core/number_text.h"
#include "core/print/printer.h"
#include "core/slicing/planes.h"
#include "io/errors.h"
#include "io/jobs/batch_job.h"
#include "io/jobs/profile.h"
#include "io/jobs/template_file.h"
#include "io/output_file.h"
#include "io/preview_png.h"
#include "io/readers/mesh_reader.h"
#include "parallel/parallel.h"
#include "tools/batch_command.h"
#include "tools/batch_plan.h"
#include "tools/plate_job.h"
#include "tools/progress_bar.h"
#include "tools/slice_job.h"
#include "tools/slice_stages.h"

namespace toposlice {
namespace {

volatile std::sig_atomic_t gSignal = 0;

// What an interrupted command says it left: slice and template commit their outputs together or not at
// all; a batch keeps the variants it completed before the signal.
const char* gInterruptedMessage = "interrupted; no output was left behind";

// First SIGINT/SIGTERM: ask the running job to stop at the next band; it unwinds, every temporary
// (files and staged folders) is removed by its owner, and run() then dies by the same signal. A second
// signal stops at once, removing the temporary files it can from the handler; so does the first while a
// single-model command reads its input (ReadScope: a read may block, and nothing is committed yet).
extern "C" void onSignal(int signal) {
  const bool again = gSignal != 0;
  if (again || (stopAtOnceWhileReading().load() && readsInProgress().load() > 0)) {
    removePendingOutputs();
    static const char kAgain[] = "toposlice: interrupted again: stopped at once; its temporaries removed\n";
    static const char kReading[] =
        "toposlice: interrupted while reading: stopped at once; no output was left behind\n";
    [[maybe_unused]] const ssize_t written = again ? ::write(STDERR_FILENO, kAgain, sizeof kAgain - 1)
                                                   : ::write(STDERR_FILENO, kReading, sizeof kReading - 1);
    std::signal(signal, SIG_DFL);
    std::raise(signal);
    return;
  }
  gSignal = signal;
  interruptRequested().store(true);
}

// Temporaries the job could not remove as it unwound (their folder made read-only, say): said, so that
// no message claims nothing was left.
void sayUnremovedTemporaries() {
  for (const std::string& t : takeUnremovedTemporaries())
    std::fprintf(stderr, "toposlice: the temporary %s; delete it by hand\n", t.c_str());
}

// After an interrupted command has cleaned up: end by the signal, as the shell expects.
void endIfInterrupted() {
  if (gSignal == 0) return;
  sayUnremovedTemporaries();
  std::fprintf(stderr, "toposlice: %s\n", gInterruptedMessage);
  std::signal(gSignal, SIG_DFL);
  std::raise(gSignal);
}

struct CommonOptions {
  unsigned threads = 0;
  bool quiet = false;
  std::string units;
  double scale = 1.0;
  CLI::Option* scaleOpt = nullptr;
};

// --units and --scale of the commands that read meshes.
void addMeshOptions(CLI::App* app, CommonOptions& common) {
  app->add_option(
      "--units", common.units,
      "Length of one file unit: mm (default), cm, m or in (STL, PLY and OBJ carry no units; 3MF does)");
  common.scaleOpt =
      app->add_option("--scale", common.scale, "Multiply every coordinate by F (after --units)");
}

MeshReadOptions meshReadOptions(const CommonOptions& common) {
  MeshReadOptions read;
  if (!common.units.empty()) read.unitMm = parseUnits(common.units);
  if (!std::isfinite(common.scale) || !(common.scale > 0))
    throw InputError("--scale " + formatNumber(common.scale) + ": expected a factor > 0");
  read.scale = common.scale;
  read.runner = parallelChunkRunner();
  return read;
}

void addCommon(CLI::App* app, CommonOptions& common) {
  app->add_option("--threads", common.threads, "Worker threads (default: all cores)");
  app->add_flag("-q,--quiet", common.quiet,
                "No progress bar or summary; warnings and errors are still printed");
}

struct PlaneOptions {
  double layerHeight = 0;
  uint32_t layers = 0;
  double z0 = 0;
  std::string zList;
  CLI::Option* heightOpt = nullptr;
  CLI::Option* layersOpt = nullptr;
  CLI::Option* z0Opt = nullptr;
};

void addPlaneOptions(CLI::App* app, PlaneOptions& p) {
  p.heightOpt = app->add_option("--layer-height,-H", p.layerHeight, "Layer height in mm (default 0.05)");
  p.layersOpt =
      app->add_option("--layers", p.layers, "Number of layers (with no height: divide the model height)");
  p.z0Opt = app->add_option("--z0", p.z0,
                            "Bottom of layer 0 in mm (default: the lowest z of the model and its add-ons)");
  app->add_option("--z", p.zList, "Explicit plane heights in mm, comma separated, ascending")
      ->excludes(p.heightOpt)
      ->excludes(p.layersOpt)
      ->excludes(p.z0Opt);
}

PlaneSpec planeSpec(const PlaneOptions& p) {
  PlaneSpec spec;
  if (!p.zList.empty()) {
    std::string error;
    if (!parseZList(p.zList, spec.explicitZ, &error)) throw InputError("--z '" + p.zList + "': " + error);
    return spec;
  }
  if (*p.heightOpt) spec.layerHeight = p.layerHeight;
  if (*p.layersOpt) spec.layers = p.layers;
  if (*p.z0Opt) spec.z0 = p.z0;
  if (!spec.layerHeight && !spec.layers) spec.layerHeight = 0.05;
  return spec;
}

void printBox(const BoundingBox& b) {
  const auto v = [](float x) { return double{x} + 0.0; };  // -0 prints as 0
  std::printf("bounding box   : [%.6g, %.6g] x [%.6g, %.6g] x [%.6g, %.6g] (size %.6g x %.6g x %.6g)\n",
              v(b.min.x), v(b.max.x), v(b.min.y), v(b.max.y), v(b.min.z), v(b.max.z),
              double{b.max.x} - b.min.x, double{b.max.y} - b.min.y, double{b.max.z} - b.min.z);
}

// readMesh counted as a read in progress (a stop signal may end the process at once meanwhile).
FacetSoup readModel(const std::string& model, const MeshReadOptions& read, MeshSource* source = nullptr) {
  ReadScope reading;
  return readMesh(model, read, source);
}

int runInfo(const std::string& model, const MeshReadOptions& read, bool quiet) {
  MeshSource source;
  const FacetSoup soup = readModel(model, read, &source);
  if (quiet) return 0;  // errors only: the file reads (the exit status says so), no report
  const ChunkRunner runner = parallelChunkRunner();
  const IndexedMesh mesh = weldCorners(soup.corners, runner);
  std::vector<int32_t> table(soup.corners.size());
  const EdgeStats edges = buildAdjacency(mesh.facetVertices, mesh.vertices.size(), table, runner);
  const double volume = signedVolume(soup.corners);
  std::string format = meshFormatName(source.format);
  if (source.format == MeshFormat::Stl || source.format == MeshFormat::Ply)
    format = (source.binary ? "binary " : "ASCII ") + format;
  if (source.gzip) format += ", gzip";
  if (!source.fileUnit.empty()) format += ", unit " + source.fileUnit;
  if (source.polygonsTriangulated > 0)
    format += ", " + std::to_string(source.polygonsTriangulated) + " polygons fan-triangulated";
  std::printf("model          : %s (%s)\n", model.c_str(), format.c_str());
  std::printf("facets         : %zu\n", soup.facetCount());
  std::printf("vertices       : %zu (welded)\n", mesh.vertices.size());
  printBox(boundsOf(soup.corners));
  const bool closed =
      edges.boundary == 0 && edges.nonManifold == 0 && edges.inconsistent == 0 && edges.degenerateFacets == 0;
  // Nine significant digits: a model in metres (--units m aside) keeps its digits too.
  std::printf("volume         : %.9g mm^3%s\n", volume + 0.0,
              !closed ? " (the mesh is not closed: where edges are open, shared by more than two facets or "
                        "turned the wrong way it encloses no definite volume; this is its signed volume "
                        "against the bounding box's centre)"
              : volume < 0 ? " (negative: the mesh is inside out; slice with --fix-orientation)"
                           : "");
  std::printf("surface area   : %.9g mm^2\n", surfaceArea(soup.corners));
  std::printf("shells         : %llu\n",
              static_cast<unsigned long long>(countShells(mesh.facetVertices, mesh.vertices.size())));
  std::printf("edges          : %llu\n", static_cast<unsigned long long>(edges.edges));
  std::printf("boundary edges : %llu\n", static_cast<unsigned long long>(edges.boundary));
  std::printf("non-manifold   : %llu edges\n", static_cast<unsigned long long>(edges.nonManifold));
  std::printf("inconsistent   : %llu edges (two facets in the same direction)\n",
              static_cast<unsigned long long>(edges.inconsistent));
  std::printf("degenerate     : %llu facets with a repeated corner (skipped when slicing)\n",
              static_cast<unsigned long long>(edges.degenerateFacets));
  std::printf("closed         : %s\n",
              closed ? "yes (every edge has exactly two facets, consistently oriented)" : "no");
  return 0;
}

void printWarnings(const std::vector<std::string>& warnings) {
  for (const auto& w : warnings) std::fprintf(stderr, "toposlice: warning: %s\n", w.c_str());
}

void printSliceSummary(const std::string& model, const SliceJobOptions& options, const SliceJobResult& r) {
  std::printf("model      : %s, %llu facets\n", model.c_str(), static_cast<unsigned long long>(r.facets));
  std::printf("method     : %s; topology %s\n", sliceMethodName(options.slice.method), r.topology.c_str());
  if (r.edges.boundary + r.edges.nonManifold + r.edges.inconsistent > 0)
    std::printf("defects    : %llu boundary, %llu non-manifold, %llu inconsistent edges\n",
                static_cast<unsigned long long>(r.edges.boundary),
                static_cast<unsigned long long>(r.edges.nonManifold),
                static_cast<unsigned long long>(r.edges.inconsistent));
  // Every repair, per kind, so nothing is changed silently.
  std::printf(
      "repairs    : %llu degenerate facets skipped; %llu gaps bridged (<= %g mm) closing %llu loops, "
      "%llu wider gaps closed closing %llu loops, %llu polylines left open; orientation %s\n",
      static_cast<unsigned long long>(r.degenerateFacets),
      static_cast<unsigned long long>(r.stats.gaps.joins), options.slice.closeGaps,
      static_cast<unsigned long long>(r.stats.gaps.closedLoops),
      static_cast<unsigned long long>(r.stats.gaps.selfClosed),
      static_cast<unsigned long long>(r.stats.gaps.closedLoopsWider),
      static_cast<unsigned long long>(r.stats.openPolylines),
      r.flipped ? "flipped (the mesh was inside out)"
                : (r.inverted ? "INSIDE OUT (negative volume; use --fix-orientation)" : "ok"));
  std::printf(
      "layers     : %llu, %llu segments, %llu loops, %llu open polylines\n",
      static_cast<unsigned long long>(r.stats.layers), static_cast<unsigned long long>(r.stats.segments),
      static_cast<unsigned long long>(r.stats.loops), static_cast<unsigned long long>(r.stats.openPolylines));
  if (options.slice.method == SliceMethod::SelfReuseLazy)
    std::printf("table      : %llu joins on %llu layers, %llu ends left open\n",
                static_cast<unsigned long long>(r.stats.lazy.joins),
                static_cast<unsigned long long>(r.stats.lazy.joinedLayers),
                static_cast<unsigned long long>(r.stats.lazy.unjoined));
  std::printf("time       : read %.3f s, weld+adjacency %.3f s, slice%s %.3f s, total %.3f s\n",
              r.readSeconds, r.topologySeconds, r.written.empty() ? "" : "+write", r.sliceSeconds,
              r.readSeconds + r.topologySeconds + r.sliceSeconds);
  if (!options.masks.output.empty() || !options.report.empty() || !options.summary.empty())
    std::printf("resin      : %.4f ml\n", r.volumeMl);
  std::printf("peak memory: %.1f MiB\n", peakResidentMiB());
  for (const auto& path : r.written) std::printf("wrote      : %s\n", path.c_str());
}

// The resolved printer, material and correction settings, each with where it came from, and what a job
// will do with them (--explain). `masks`: the mask output (empty: none); `scaleCentre`: about what the
// scaling correction scales, in words.
void explainPrintSettings(const PrintSettings& p, const std::filesystem::path& masks, bool antialiasAsked,
                          const char* scaleCentre) {
  std::printf("printer    : %s\n", !p.printerName.empty() ? p.printerName.c_str()
                                   : masks.empty()        ? "(none)"
                                                   : "(none: the image from --resolution and --pixel)");
  std::printf("material   : %s\n", p.materialName.c_str());
  for (const auto& [key, value] : settingValues(p)) {
    const auto origin = p.origin.find(key);
    std::printf("  %-26s = %-12s %s\n", key.c_str(), value.empty() ? "(unset)" : value.c_str(),
                origin == p.origin.end() ? "(default)" : ("(" + origin->second + ")").c_str());
  }
  const auto scale = p.scale();
  std::printf("scaling    : x %s, y %s, z %s about %s%s\n", formatNumber(scale[0]).c_str(),
              formatNumber(scale[1]).c_str(), formatNumber(scale[2]).c_str(), scaleCentre,
              p.scales() ? "" : " (none)");
  std::printf(
      "offsets    : absolute %s mm on every layer; elephant foot %s mm on layer 0%s, making no feature "
      "narrower than %s mm\n",
      formatNumber(p.absoluteCorrection).c_str(), formatNumber(p.elefantFootCompensation).c_str(),
      p.elephantFootFadeLayers() > 1
          ? (", fading to 0 over " + std::to_string(p.elephantFootFadeLayers()) + " layers" +
             (p.elefantFootLayers > 0 ? "" : " (faded_layers, as PrusaSlicer)"))
                .c_str()
          : "",
      formatNumber(p.elefantFootMinWidth).c_str());
  const bool antialias = antialiasAsked || (p.gammaCorrection && *p.gammaCorrection > 0);
  if (masks.empty()) {
    std::printf("masks      : none (contours only: exposure, gamma and light map unused)\n");
  } else {
    std::printf("masks      : %s, %s%s%s\n", masks.c_str(),
                antialias ? "anti-aliased, gamma " : "binary (pixel-centre rule)",
                antialias ? formatNumber(p.gammaCorrection.value_or(1.0)).c_str() : "",
                p.lightMap.empty() ? "" : (", light map " + p.lightMap.string()).c_str());
    std::printf("exposure   : %s s, first layer %s s, faded over %u layers\n",
                formatNumber(p.exposureTime).c_str(), formatNumber(p.initialExposureTime).c_str(),
                p.fadedLayers);
  }
}

// A setting's key as its command-line option spells it: exposure_time -> exposure-time.
std::string dashed(std::string key) {
  std::replace(key.begin(), key.end(), '_', '-');
  return key;
}

// "WxH" in pixels, each 1 to `max`: digits only, so "4294967297x10" is out of range, not 1x10.
bool parsePixelSize(const std::string& text, uint64_t max, uint32_t& width, uint32_t& height) {
  const std::size_t x = text.find('x');
  if (x == std::string::npos) return false;
  const auto number = [max](std::string_view digits, uint32_t& out) {
    if (digits.empty() || digits.size() > 9) return false;
    uint64_t v = 0;
    for (const char c : digits) {
      if (c < '0' || c > '9') return false;
      v = v * 10 + static_cast<uint64_t>(c - '0');
    }
    if (v == 0 || v > max) return false;
    out = static_cast<uint32_t>(v);
    return true;
  };
  const std::string_view all(text);
  return number(all.substr(0, x), width) && number(all.substr(x + 1), height);
}

// slice --explain: nothing is written, and no mesh is read; what the run would refuse without one is
// refused here too: bad numbers, an input that cannot be opened, the image's settings and a light map
// that does not fit the display.
int explainSettings(const std::string& model, const SliceJobOptions& options) {
  validateSliceOptions(options);
  std::vector<std::filesystem::path> inputs{model};
  inputs.insert(inputs.end(), options.add.begin(), options.add.end());
  inputs.insert(inputs.end(), options.remove.begin(), options.remove.end());
  for (const std::filesystem::path& file : inputs) {
    const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) throw InputError(file.string() + ": cannot open: " + std::generic_category().message(errno));
    ::close(fd);
    if (std::filesystem::is_directory(file)) throw InputError(file.string() + ": is a directory");
  }
  if (!options.masks.output.empty()) {
    // The image's own checks (a size and a pixel pitch, square pixels, an orientation the format can
    // carry), as the run makes them, without the model: its extent only places the image (cropped here).
    MaskOptions masks = options.masks;
    masks.crop = true;
    const MaskJob job = makeMaskJob(masks, options.print, BoundingBox{}, model, {});
    maskTransfer(options.print, job);  // reads the light map: its size against the display
  }
  std::printf("model      : %s\n", model.c_str());
  explainPrintSettings(options.print, options.masks.output, options.masks.antialias,
                       "the bounding-box centre in x and y and the lowest z");
  return 0;
}

// batch --explain: the job file and its profile are read and checked, no model.
int explainBatchSettings(const std::filesystem::path& jobPath) {
  const BatchJob job = readBatchJob(jobPath);
  std::size_t withMasks = 0;
  for (const BatchVariant& v : job.variants) withMasks += v.masks.empty() ? 0 : 1;
  std::printf("batch job  : %s (%zu variants)\n", jobPath.c_str(), job.variants.size());
  const std::string masks = withMasks == 0 ? std::string()
                                           : "each variant's (" + std::to_string(withMasks) + " of " +
                                                 std::to_string(job.variants.size()) + " variants)";
  const PrintSettings settings = batchJobSettings(job);
  PrintSettings print = settings;
  batchMaskOptions(job, {}, print);  // settings.resolution and settings.pixel, as the display's settings
  for (const BatchVariant& v : job.variants)
    checkMaskSettings(print, job.antialias, !v.masks.empty(), "antialias");
  checkBatchMaskImages(job, settings);  // the light map too, as the run does before any variant
  checkBatchFeatureFiles(job);
  explainPrintSettings(print, masks, job.antialias,
                       "each variant's bounding-box centre in x and y and its lowest z");
  return 0;
}

// plate --explain: the job file and its profile are read and checked, no model.
int explainPlateSettings(const std::filesystem::path& jobPath, const std::filesystem::path& outputDir) {
  const PlateJob job = readPlateCommandJob(jobPath, outputDir);
  const PrintSettings print = plateJobSettings(job);
  checkMaskSettings(print, job.antialias, !job.masks.empty(), "settings.antialias");
  checkPlateMaskSettings(job);
  std::printf("plate job  : %s (%zu parts)\n", jobPath.c_str(), job.parts.size());
  explainPrintSettings(print, job.masks, job.antialias,
                       "each part's own centre (its model's bounding box in x and y, lowest z), along the "
                       "plate's axes");
  return 0;
}

int runSlice(const std::string& model, const SliceJobOptions& options, const CommonOptions& common) {
  SliceJobResult result;
  {
    ProgressBar bar("slicing", common.quiet);
    ProgressContext progress;
    progress.report = [&](uint64_t done, uint64_t total) { bar.update(done, total); };
    result = runSliceJob(model, options, &progress);
    bar.update(result.stats.layers, result.stats.layers);
  }  // the bar's line ends here, before anything else is printed
  if (!common.quiet) printSliceSummary(model, options, result);
  printWarnings(result.warnings);  // never hidden by --quiet
  if (result.written.empty())
    std::fprintf(stderr,
                 "toposlice: warning: nothing was written: no output was asked for (-o, --masks, --report or "
                 "--summary)\n");
  return 0;
}

int runTemplate(const std::string& model, const MeshReadOptions& read, const std::string& output, bool force,
                bool quiet) {
  const auto start = std::chrono::steady_clock::now();
  checkNotAnInput(output, {model});
  if (lowerExtension(output) != ".topo")
    throw InputError(output + ": the table is a .topo file: give a .topo file name");
  checkOutputAllowed(output, force);  // before the model is read, not after the work
  // The table is written in a transaction that commits only when no stop signal has come: an
  // interrupted run leaves no table, a finished one a complete table.
  OutputTransaction transaction;
  const FacetSoup soup = readModel(model, read);
  const ChunkRunner runner = parallelChunkRunner();
  const TemplateTable table = buildTemplateTable(weldCorners(soup.corners, runner), runner);
  writeTemplateFile(output, table, force);
  transaction.commit(&interruptRequested());
  if (!quiet) {
    const uint64_t missing =
        static_cast<uint64_t>(std::count(table.adjacency.begin(), table.adjacency.end(), -1));
    std::printf("template   : %s, %u facets, %u vertices, fingerprint %016llx\n", model.c_str(),
                table.facetCount, table.vertexCount, static_cast<unsigned long long>(table.fingerprint));
    std::printf("table      : %llu of %zu entries without a neighbour\n",
                static_cast<unsigned long long>(missing), table.adjacency.size());
    std::printf("time       : %.3f s\n",
                std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    std::printf("wrote      : %s\n", output.c_str());
  }
  return 0;
}

// Renders the model as the printer files' previews show it and writes a PNG.
int runPreview(const std::string& model, const MeshReadOptions& read, const std::string& output,
               const std::string& size, bool force, bool quiet) {
  uint32_t width = 0, height = 0;
  if (!parsePixelSize(size, 8192, width, height))
    throw InputError("--size " + size + ": expected WIDTHxHEIGHT in pixels, each 1 to 8192 (e.g. 800x480)");
  checkNotAnInput(output, {model});
  if (lowerExtension(output) != ".png")
    throw InputError(output + ": the picture is a PNG: give a .png file name");
  checkOutputAllowed(output, force);  // before the model is read, not after the work
  OutputTransaction transaction;
  const FacetSoup soup = readModel(model, read);
  const std::vector<uint8_t> png = previewPng(soup.corners, width, height, parallelChunkRunner());
  OutputFile file(output, force);
  file.write(png.data(), png.size());
  file.commit();
  transaction.commit(&interruptRequested());
  if (!quiet) std::printf("wrote      : %s (%ux%u)\n", output.c_str(), width, height);
  return 0;
}

int run(int argc, char** argv) {
  CLI::App app{
      "toposlice: fast slicing for mask-projection 3D printing, reusing topology across layers and models"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "toposlice " TOPOSLICE_VERSION_TEXT);

  CommonOptions common;
  std::string model;

  CLI::App* info =
      app.add_subcommand("info", "Print facets, vertices, bounds, volume, shells and edge defects");
  info->add_option("model", model, "Mesh file: STL, PLY, OBJ or 3MF (by content), optionally .gz")
      ->required();

  CLI::App* slice = app.add_subcommand("slice", "Slice a model into per-layer contours");
  slice->add_option("model", model, "Mesh file: STL, PLY, OBJ or 3MF (by content), optionally .gz")
      ->required();
  PlaneOptions planes;
  addPlaneOptions(slice, planes);
  SliceJobOptions options;
  std::string method = "sr";
  std::vector<std::string> outputs;
  std::string templatePath, onMismatch = "fail";
  slice->add_option("-o,--output", outputs,
                    "Contour output, by extension: .cli (Common Layer Interface), .svg, .3mf (repeatable)");
  slice->add_option("--method", method, "cp (closest point), sr-lazy (paper's self reuse), sr (default)")
      ->check(CLI::IsMember({"cp", "sr-lazy", "sr"}));
  slice->add_flag("--cli-binary", options.cliBinary, "Write binary CLI instead of ASCII");
  slice->add_option("--svg-layers", options.svgLayers,
                    "Layers for .svg output: e.g. 0,10,20-30,mid,last (default mid)");
  slice->add_option("--template", templatePath,
                    "Template table (.topo) of a model with the same connectivity");
  slice
      ->add_option("--on-mismatch", onMismatch, "When the model does not match the template: fail or rebuild")
      ->check(CLI::IsMember({"fail", "rebuild"}));
  slice->add_option("--band-layers", options.slice.bandLayers,
                    "Layers per parallel band (default or 0: automatic)");
  std::string candidates = "sweep";
  slice
      ->add_option("--candidates", candidates,
                   "How bands find their first layer's facets: sweep (default) or embree")
      ->check(CLI::IsMember({"sweep", "embree"}));
  slice->add_option("--join-tolerance", options.slice.joinTolerance,
                    "mm; cp and sr-lazy join segment ends this close (default 1e-5)");
  std::string resolution, origin;
  std::vector<std::string> contourOutputs;  // joined to `outputs` after parsing: one vector would keep
                                            // only the last option's values
  slice->add_option("--contours", contourOutputs, "Same as -o: contour output (.cli, .svg, .3mf)");
  slice->add_option("--masks", options.masks.output,
                    "Mask stack: .sl1 (Prusa SL1 zip of PNGs), .goo (Elegoo), .nanodlp, .exr, .vdb, or a "
                    "directory of PNGs");
  slice->add_option(
      "--printer", options.masks.printer,
      "Printer preset: " + printerNames() + " (generic-4k has no fixed pixel size: add --pixel)");
  slice->add_option("--pixel", options.masks.pixel, "Pixel size in mm (overrides the preset)");
  slice->add_option("--resolution", resolution, "Image size WxH in pixels (overrides the preset)");
  slice->add_option("--origin", origin,
                    "X,Y of pixel (0,0)'s lower-left corner in mm (default: model centred)");
  slice->add_flag("--mirror-x", options.masks.mirrorX, "Mirror the masks in x");
  slice->add_flag("--mirror-y", options.masks.mirrorY, "Mirror the masks in y");
  slice->add_flag("--antialias", options.masks.antialias, "Anti-aliased masks (covered fraction, 8-bit)");
  slice->add_flag("--crop", options.masks.crop, "Allow a model larger than the image (cut off at its edges)");
  // Printer and material settings (io/jobs/profile.h): profiles, then one option per key.
  std::string profilePath, material;
  std::vector<std::string> setAssignments;
  bool explain = false;
  slice->add_option("--profile", profilePath,
                    "Profile file (JSON) of printers and materials (docs/FORMATS.md, \"Profile files\")");
  slice->add_option("--material", material,
                    "Material preset (" + builtInMaterialNames() + ") or a material of --profile");
  slice->add_option("--set", setAssignments,
                    "KEY=VALUE: set any printer or material key (repeatable; after the options below)");
  slice->add_flag("--explain", explain,
                  "Print the printer, material and correction settings the job would use, then stop");
  const std::span<const SettingKey> keys = settingKeys();
  std::vector<std::string> keyValues(keys.size());
  std::vector<std::string> keyOptions(keys.size());
  for (std::size_t i = 0; i < keys.size(); ++i) {
    keyOptions[i] = "--" + dashed(keys[i].name);
    slice->add_option(keyOptions[i], keyValues[i], keys[i].help)
        ->group(keys[i].owner == SettingOwner::Printer ? "Printer settings" : "Material settings");
  }
  std::string vdbLayout = "single";
  slice
      ->add_option("--vdb-layout", vdbLayout,
                   ".vdb masks: single (one grid for the whole stack, default) or slabs (one grid per "
                   "64 layers: memory bounded by a slab, for very tall or finely detailed stacks)")
      ->check(CLI::IsMember({"single", "slabs"}));
  std::vector<std::string> addFeatures, removeFeatures;
  slice->add_option("--add", addFeatures, "Add-on feature mesh, sliced on its own (repeatable)");
  slice->add_option("--remove", removeFeatures,
                    "Removal feature mesh, subtracted at the winding stage (repeatable)");
  std::string reportPath;
  slice->add_option("--report", reportPath, "Per-layer CSV report (.csv): z, area, loops, islands");
  std::string summaryPath;
  slice->add_option("--summary", summaryPath,
                    "Machine-readable summary (.json): counts, repairs, times, resin volume, outputs");
  slice->add_option("--close-gaps", options.slice.closeGaps,
                    "mm; bridge open contour ends of defective meshes up to this gap (default 0.05, 0: off)");
  bool keepOpen = false;
  slice->add_flag(
      "--keep-open", keepOpen,
      "Leave polylines open that no gap within --close-gaps closes (default: close the wider gaps too)");
  slice->add_flag("--fix-orientation", options.fixOrientation, "Flip an inside-out mesh (negative volume)");
  slice->add_flag(
      "-f,--force", options.overwrite,
      "Replace existing outputs that toposlice wrote (never an input, nor a file or folder of other "
      "content)");

  CLI::App* templ =
      app.add_subcommand("template", "Save a template's adjacency table for its customized variants");
  std::string templateOut;
  bool templateForce = false;
  templ->add_option("model", model, "Template mesh: STL, PLY, OBJ or 3MF, optionally .gz")->required();
  templ->add_option("-o,--output", templateOut, "Table file to write (.topo)")->required();
  templ->add_flag("-f,--force", templateForce, "Replace an existing table that toposlice wrote");

  CLI::App* batch = app.add_subcommand("batch", "Slice every variant of a batch job with one template table");
  std::string jobPath;
  batch->add_option("job", jobPath, "Batch job (JSON, see docs/FORMATS.md)")->required();
  bool batchExplain = false;
  batch->add_flag("--explain", batchExplain,
                  "Print the printer, material and correction settings the job would use, then stop");

  CLI::App* preview = app.add_subcommand(
      "preview", "Render the model from above at an angle into a PNG, as printer files show it");
  std::string previewOut, previewSize = "800x480";
  bool previewForce = false;
  preview->add_option("model", model, "Mesh file: STL, PLY, OBJ or 3MF (by content), optionally .gz")
      ->required();
  preview->add_option("-o,--output", previewOut, "Picture to write (.png)")->required();
  preview->add_option("--size", previewSize, "Picture size WIDTHxHEIGHT in pixels (default 800x480)");
  preview->add_flag("-f,--force", previewForce, "Replace an existing PNG");

  CLI::App* plate = app.add_subcommand("plate", "Arrange and slice many parts together on build plates");
  std::string plateJobPath;
  plate->add_option("job", plateJobPath, "Plate job (JSON, see docs/FORMATS.md)")->required();
  std::string plateOutputDir;
  plate->add_option("-O,--output-dir", plateOutputDir,
                    "Write every output into this folder, made when missing (file names as in the job)");
  bool plateExplain = false;
  plate->add_flag("--explain", plateExplain,
                  "Print the printer, material and correction settings the job would use, then stop");

  for (CLI::App* sub : {info, slice, templ, batch, preview, plate}) addCommon(sub, common);
  for (CLI::App* sub : {info, slice, templ, preview}) addMeshOptions(sub, common);

  // A first word that is no subcommand (a typo such as "slise") is named, with the nearest command.
  const std::vector<CLI::App*> commands{info, slice, templ, batch, preview, plate};
  if (argc > 1 && argv[1][0] != '-') {
    const std::string word = argv[1];
    const bool known =
        std::any_of(commands.begin(), commands.end(), [&](CLI::App* c) { return c->get_name() == word; });
    if (!known) {
      std::string names, nearest;
      std::size_t best = 3;  // at most two edits away
      for (CLI::App* c : commands) {
        names += (names.empty() ? "" : ", ") + c->get_name();
        const std::size_t d = editDistance(word, c->get_name());
        if (d < best) best = d, nearest = c->get_name();
      }
      std::fprintf(
          stderr, "toposlice: error: unknown command '%s'%s; the commands are %s (see toposlice --help)\n",
          word.c_str(), nearest.empty() ? "" : (" (did you mean '" + nearest + "'?)").c_str(), names.c_str());
      return 2;
    }
  }

  try {
    // `--masks=` with nothing after the '=' is an empty value too; CLI11 would take the next argument
    // for it (`--masks= -q` wrote the masks into a folder named -q).
    for (int i = 1; i < argc; ++i) {
      const std::string_view arg = argv[i];
      if (arg == "--") break;
      if (arg.size() > 3 && arg.starts_with("--") && arg.find('=') == arg.size() - 1)
        throw CLI::ValidationError(std::string(arg.substr(0, arg.size() - 1)),
                                   "an empty value: expected one");
    }
    app.parse(argc, argv);
    // The job files' bound too (settings.threads): a count beyond any machine is a typing mistake.
    if (const std::string problem = threadCountProblem(common.threads); !problem.empty())
      throw CLI::ValidationError("--threads", problem);
    outputs.insert(outputs.end(), contourOutputs.begin(), contourOutputs.end());
    // An option given an empty value (--masks "", --z "") is a mistake, not the option left out.
    for (const CLI::App* c : app.get_subcommands())
      for (const CLI::Option* o : c->get_options())
        if (o->count() > 0 && o->get_type_size() != 0)
          for (const std::string& value : o->results())
            if (value.empty()) throw CLI::ValidationError(o->get_name(), "an empty value: expected one");
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    // Usage errors: one line, status 2 (input and I/O errors are status 1), pointing to the help of the
    // subcommand that was being parsed.
    std::string help = "toposlice --help";
    if (argc > 1)
      for (CLI::App* c : commands)
        if (c->get_name() == argv[1]) help = "toposlice " + c->get_name() + " --help";
    std::fprintf(stderr, "toposlice: error: %s (see %s)\n", e.what(), help.c_str());
    return 2;
  }

  ThreadLimit limit(common.threads);
  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);
  // A hang-up (the terminal closed, an ssh session dropped) stops the job as SIGTERM does; under nohup,
  // which ignores it, it stays ignored.
  if (std::signal(SIGHUP, onSignal) == SIG_IGN) std::signal(SIGHUP, SIG_IGN);
  // A file-size limit (ulimit -f) would kill the process with its temporaries in place; ignored, the
  // write fails with EFBIG instead and the job ends as on a full disk, leaving nothing behind.
  std::signal(SIGXFSZ, SIG_IGN);
  auto runCommand = [&]() -> int {
    if (*plate || *batch)
      setOverwriteHint("set \"overwrite\": true in the job's settings to replace it", "\"overwrite\": true");
    // One model, nothing committed while it is read: a stop signal then ends these at once (a batch or a
    // plate may be committing another variant's or plate's outputs meanwhile).
    stopAtOnceWhileReading().store(*info || *preview || *templ || *slice);
    if (*info) return runInfo(model, meshReadOptions(common), common.quiet);
    // A length unit or a scale changes nothing in a preview (the picture is fitted to the model) or in a
    // template's table (the mesh's connectivity): refused there, as options that cannot apply.
    for (const auto& [command, what] :
         {std::pair<CLI::App*, const char*>{preview, "the picture is fitted to the model"},
          {templ, "the table holds the mesh's connectivity, not its size"}})
      for (const char* opt : {"--units", "--scale"})
        if (*command && command->count(opt) > 0)
          throw InputError(std::string(opt) + " does nothing in " + command->get_name() + ": " + what);
    if (*preview)
      return runPreview(model, meshReadOptions(common), previewOut, previewSize, previewForce, common.quiet);
    if (*templ) return runTemplate(model, meshReadOptions(common), templateOut, templateForce, common.quiet);
    if (*plate)
      return plateExplain ? explainPlateSettings(plateJobPath, plateOutputDir)
                          : runPlateCommand(plateJobPath, common.quiet, plateOutputDir);
    if (*batch && batchExplain) return explainBatchSettings(jobPath);
    if (*batch) {
      gInterruptedMessage =
          "interrupted; the variants completed before the signal are kept, the others left nothing behind "
          "(run the same command again to finish the job)";
      return runBatch(jobPath, BatchRunOptions{common.quiet});
    }
    // Options that cannot apply to this job are errors, not silently ignored.
    auto anyOutput = [&outputs](const char* ext) {
      return std::any_of(outputs.begin(), outputs.end(),
                         [ext](const std::string& o) { return lowerExtension(o) == ext; });
    };
    const bool anySvg = anyOutput(".svg"), anyCli = anyOutput(".cli");
    auto needs = [](bool given, bool applies, const char* option, const char* what) {
      if (given && !applies)
        throw InputError(std::string(option) + " does nothing in this job: it needs " + what);
    };
    needs(slice->count("--svg-layers") > 0, anySvg, "--svg-layers", "an .svg output (-o FILE.svg)");
    needs(options.cliBinary, anyCli, "--cli-binary", "a .cli output (-o FILE.cli)");
    const bool masks = !options.masks.output.empty();
    for (const char* opt :
         {"--pixel", "--resolution", "--origin", "--mirror-x", "--mirror-y", "--antialias", "--crop"})
      needs(slice->count(opt) > 0, masks, opt, "mask output (--masks)");
    needs(slice->count("--vdb-layout") > 0, lowerExtension(options.masks.output) == ".vdb", "--vdb-layout",
          "a .vdb mask output (--masks FILE.vdb)");
    options.masks.vdbSlabs = vdbLayout == "slabs";
    needs(slice->count("--on-mismatch") > 0, !templatePath.empty(), "--on-mismatch",
          "a template (--template)");
    // The closest-point method uses no adjacency: a template's table would be read and never checked
    // against the model (a variant of other connectivity went through without a word).
    needs(!templatePath.empty(), method != "cp", "--template",
          "--method sr or sr-lazy (--method cp uses no adjacency table)");
    needs(slice->count("--join-tolerance") > 0, method != "sr", "--join-tolerance",
          "--method cp or sr-lazy (the default sr joins segments through the adjacency table)");
    // sr-lazy slices its layers in order on one thread, from the first facets up: no bands to size, no
    // band starts to find.
    for (const char* opt : {"--band-layers", "--candidates"})
      needs(slice->count(opt) > 0, method != "sr-lazy", opt,
            "--method sr or cp (--method sr-lazy slices its layers in order, without bands)");
    options.read = meshReadOptions(common);
    options.planes = planeSpec(planes);
    parseSliceMethod(method, options.slice.method);
    parseCandidateSearch(candidates, options.slice.candidates);
    options.slice.closeRemaining = !keepOpen;
    for (const auto& o : outputs) options.outputs.emplace_back(o);
    for (const auto& f : addFeatures) options.add.emplace_back(f);
    for (const auto& f : removeFeatures) options.remove.emplace_back(f);
    options.report = reportPath;
    options.summary = summaryPath;
    // A folder of masks given as "pngs/" or ".": the folder itself (its temporary goes beside it, not
    // inside it as "pngs/.tmp-..." or "..tmp-...").
    std::filesystem::path& maskPath = options.masks.output;
    while (!maskPath.empty() && maskPath.filename().empty() && maskPath != maskPath.root_path())
      maskPath = maskPath.parent_path();
    if (maskPath.filename() == "." || maskPath.filename() == "..") maskPath = resolvedPath(maskPath);
    if (!resolution.empty()) {
      uint32_t w = 0, h = 0;
      if (!parsePixelSize(resolution, kMaxImageSide, w, h))
        throw InputError("--resolution '" + resolution + "': expected WxH in pixels, each 1 to " +
                         std::to_string(kMaxImageSide) + ", e.g. 2560x1440");
      options.masks.resolution = std::pair<uint32_t, uint32_t>{w, h};
    }
    if (!origin.empty()) {
      double x = 0, y = 0;
      char extra = 0;
      if (std::sscanf(origin.c_str(), "%lf,%lf%c", &x, &y, &extra) != 2)
        throw InputError("--origin '" + origin + "': expected X,Y in mm");
      options.masks.origin = std::pair<double, double>{x, y};
    }
    ProfileChoice choice{profilePath,    options.masks.printer, material,    {},
                         "command line", "--printer",           "--material"};
    std::vector<std::string>
        givenAs;  // each override as the user typed it: "--exposure-time", "--set exposure_time"
    for (std::size_t i = 0; i < keys.size(); ++i) {
      if (slice->count(keyOptions[i]) == 0) continue;
      choice.overrides.emplace_back(keys[i].name, keyValues[i]);
      givenAs.push_back("--" + dashed(std::string(keys[i].name)));
    }
    for (const std::string& assignment : setAssignments) {
      const std::size_t eq = assignment.find('=');
      if (eq == std::string::npos || eq == 0)
        throw InputError("--set '" + assignment + "': expected KEY=VALUE, e.g. exposure_time=6");
      choice.overrides.emplace_back(assignment.substr(0, eq), assignment.substr(eq + 1));
      givenAs.push_back("--set " + assignment.substr(0, eq));
    }
    options.print = resolvePrintSettings(choice);
    // --mirror-x/-y mirror the display on top of the printer's own mirroring, --resolution and --pixel
    // replace its size: recorded as its settings, so that --explain and the summary say what the images
    // have.
    // (--mirror-x/-y mirror on top of display_mirror_x/y, whatever set it: no contradiction there.)
    checkDisplayOverrides(options.print, "command line", options.masks.resolution.has_value(),
                          options.masks.pixel.has_value(), std::nullopt, std::nullopt,
                          {"--resolution", "--pixel", "--mirror-x", "--mirror-y"});
    applyJobMirror(options.print, options.masks.mirrorX ? std::optional<bool>(true) : std::nullopt,
                   options.masks.mirrorY ? std::optional<bool>(true) : std::nullopt, "command line");
    recordDisplayOptions(options.print, options.masks);
    options.print = settingsForMaskFormat(options.print, options.masks.output);
    const PrintSettings& print = options.print;
    needs(slice->count("--printer") > 0, masks || print.scales() || print.correctsOutlines(), "--printer",
          "mask output (--masks), or a printer whose corrections change the contours");
    // Settings given here that only the masks use do nothing without them.
    const std::vector<std::filesystem::path> maskOutputs =
        masks ? std::vector<std::filesystem::path>{options.masks.output}
              : std::vector<std::filesystem::path>{};
    // A material chosen by name for contours only does nothing unless one of its settings changes the
    // contours (a material_correction) or the summary (material_density): its exposures need masks.
    if (slice->count("--material") > 0 && !masks) {
      const std::string why =
          unusedMaterialReason(options.print, !options.summary.empty(), "the contours", "the summary");
      if (!why.empty())
        throw InputError("--material " + material + " does nothing in this job: " + why +
                         "; its exposures need mask output (--masks)");
    }
    for (std::size_t i = 0; i < choice.overrides.size(); ++i) {
      const std::string& k = choice.overrides[i].first;
      if (const std::string why =
              settingUnusedReason(k, maskOutputs, "mask output (--masks)", !options.summary.empty());
          !why.empty())
        throw InputError(givenAs[i] + " does nothing in this job: " + why);
      needs(k.starts_with("elefant_foot_") && k != "elefant_foot_compensation",
            options.print.elefantFootCompensation > 0, givenAs[i].c_str(), "elefant_foot_compensation > 0");
    }
    options.rebuildOnMismatch = onMismatch == "rebuild";
    options.templateFile = templatePath;
    options.otherInputs = {profilePath, options.print.lightMap};  // never replaced by an output either
    if (explain) return explainSettings(model, options);
    return runSlice(model, options, common);
  };
  try {
    const int status = runCommand();
    // The command is over (its outputs committed, or it failed or stopped): a stop signal from here on
    // changes nothing, and must not end the process as interrupted with its outputs complete. (An
    // interrupted command still ends by its signal below: endIfInterrupted restores the default first.)
    for (const int stop : {SIGINT, SIGTERM, SIGHUP}) std::signal(stop, SIG_IGN);
    if (gSignal != 0 && !*batch) {
      // The signal came after the outputs had been committed: the job is complete, and saying
      // "nothing was left" would be untrue. It ends normally.
      std::fprintf(stderr,
                   "toposlice: the stop signal came after the job had finished; its outputs are complete\n");
      return status;
    }
    endIfInterrupted();
    sayUnremovedTemporaries();  // a batch's variants that failed
    return status;
  } catch (const std::bad_alloc&) {
    // Not "std::bad_alloc": what ran out, for which input, and what makes a job smaller. Every temporary
    // was removed as the job unwound.
    endIfInterrupted();
    const std::string input = *batch ? jobPath : *plate ? plateJobPath : model;
    std::fprintf(stderr,
                 "toposlice: error: %s: out of memory: the job needs more than the system gives this process "
                 "(fewer --threads, a smaller image or --band-layers, or a smaller model); no output was "
                 "left behind\n",
                 input.c_str());
    return 1;
  } catch (const std::exception& e) {
    endIfInterrupted();
    std::fprintf(stderr, "toposlice: error: %s\n", e.what());
    sayUnremovedTemporaries();
    return 1;
  }
}

}  // namespace
}  // namespace toposlice

int main(int argc, char** argv) {
  toposlice::keepFreedMemory();
  return toposlice::run(argc, argv);
}
