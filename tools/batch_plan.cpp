#include "tools/batch_plan.h"

#include <algorithm>
#include <chrono>
#include <set>
#include <system_error>

#include "core/mesh/weld.h"
#include "core/print/printer.h"
#include "io/errors.h"
#include "io/masks/mask_sink.h"
#include "io/output_file.h"
#include "io/readers/mesh_reader.h"
#include "parallel/parallel.h"
#include "parallel/variant_screen.h"
#include "tools/slice_job.h"
#include "tools/slice_stages.h"

namespace toposlice {

BatchTemplate loadOrBuildBatchTemplate(const BatchJob& job, const std::filesystem::path& jobPath, bool save) {
  // The printer, material and profile first: a typo there fails at once, before a table is built and
  // saved and every variant then fails on it.
  checkBatchMaskImages(job, batchJobSettings(job));
  checkBatchFeatureFiles(job);
  BatchTemplate t;
  const auto readTemplateModel = [&job] {
    FacetSoup soup = readMesh(job.templateModel, MeshReadOptions{job.unitMm, job.scale});
    // With "fix_orientation" the variants are turned right side out: so is an inside-out template, whose
    // table they are checked against.
    if (job.fixOrientation && measureSoup(soup.corners).volume < 0) flipFacets(soup.corners);
    return soup;
  };
  if (!job.templateFile.empty() && std::filesystem::exists(job.templateFile)) {
    t.table = readTemplateFile(job.templateFile);
    t.source = "loaded " + job.templateFile.string();
    // A table left from another template would fail every variant, each blamed for its connectivity:
    // with the model named too, the table must describe it (the check every variant gets, linear).
    if (!job.templateModel.empty()) {
      const FacetSoup soup = readTemplateModel();
      if (const auto mismatch = checkVariantConnectivityParallel(soup.corners, t.table.adjacency)) {
        // The model's table with every facet reversed (built with the other "fix_orientation" from an
        // inside-out model) is its table all the same: the variants are checked against both.
        std::vector<int32_t> reversed;
        reverseFacetsOfTable(t.table.adjacency, reversed);
        if (checkVariantConnectivityParallel(soup.corners, reversed)) {
          std::string why = mismatch->reason;  // the check's words are a variant's and a template's
          for (const auto& [from, to] : {std::pair<std::string, std::string>{"the variant", "the model"},
                                         {"the template has", "the table has"},
                                         {"its neighbour in the template", "its neighbour in the table"},
                                         {"the template's connectivity", "the table's connectivity"}})
            for (std::size_t at = why.find(from); at != std::string::npos;
                 at = why.find(from, at + to.size()))
              why.replace(at, from.size(), to);
          throw InputError(jobPath.string() + ": template.table " + job.templateFile.string() +
                           " is not the table of template.model " + job.templateModel.string() + " (" + why +
                           "): it was built from another model; delete it to build it again");
        }
      }
      t.source += " (matches " + job.templateModel.string() + ")";
    }
  } else if (!job.templateModel.empty()) {
    const ChunkRunner runner = parallelChunkRunner();
    FacetSoup soup = readTemplateModel();
    t.table = buildTemplateTable(weldCorners(soup.corners, runner), runner);
    t.source = "built from " + job.templateModel.string();
    if (save && !job.templateFile.empty()) {
      // Committed only when no stop signal has come: an interrupted batch saves no table, and takes away
      // the folder it made for it when it holds nothing else.
      MadeFolders made;
      made.note(job.templateFile.parent_path());
      try {
        if (!job.templateFile.parent_path().empty())
          std::filesystem::create_directories(job.templateFile.parent_path());
        OutputTransaction transaction;
        writeTemplateFile(job.templateFile, t.table, false);
        transaction.commit(&interruptRequested());
      } catch (...) {
        made.removeEmpty();
        throw;
      }
      made.removeEmpty();
      t.source += ", saved to " + job.templateFile.string();
    }
  } else {
    throw InputError(jobPath.string() + ": the template table " + job.templateFile.string() +
                     " does not exist and no template model is given to build it");
  }
  return t;
}

std::vector<std::filesystem::path> batchVariantOutputs(const BatchVariant& variant) {
  std::vector<std::filesystem::path> out;
  for (const auto* p : {&variant.contours, &variant.masks, &variant.report})
    if (!p->empty()) out.push_back(*p);
  return out;
}

namespace {

// An output of a variant that a re-run keeps: there, toposlice's own (its mark, a folder of marked
// layers) and whole (not empty, not cut short where its format's end tells, a folder's layers without
// a gap). Anything else is no finished output: the variant is sliced again (and fails on another
// program's file, naming it).
bool finishedOutput(const std::filesystem::path& p, bool masks) {
  if (!std::filesystem::exists(p)) return false;
  try {
    if (masks)
      checkMaskOutputAllowed(p, true);
    else
      checkOutputAllowed(p, true);
  } catch (const OutputError&) {
    return false;
  }
  return outputLooksWhole(p, lowerExtension(p) == ".exr" ? ".exr" : "");  // an EXR stack is a folder
}

}  // namespace

bool batchVariantComplete(const BatchJob& job, const BatchVariant& variant) {
  const auto outputs = batchVariantOutputs(variant);
  if (outputs.empty() || job.overwrite) return false;
  return std::all_of(outputs.begin(), outputs.end(),
                     [&](const std::filesystem::path& p) { return finishedOutput(p, p == variant.masks); });
}

PrintSettings batchJobSettings(const BatchJob& job) {
  PrintSettings print = resolvePrintSettings(
      {job.profile, job.printer, job.material, job.printSettings, "batch job print_settings",
       job.sourceFile.string() + ": settings.printer", job.sourceFile.string() + ": settings.material"});
  checkDisplayOverrides(print, "batch job print_settings", job.resolution.has_value(), job.pixel.has_value(),
                        job.mirrorX, job.mirrorY,
                        {"settings.resolution", "settings.pixel", "settings.mirror", "settings.mirror"});
  applyJobMirror(print, job.mirrorX, job.mirrorY, "batch job settings.mirror");
  // The elephant foot's other keys shape its compensation: without one they do nothing (slice refuses them).
  checkElephantFootKeys(print, job.printSettings, job.sourceFile, "settings.print_settings.");
  // Masks need an image: refused here, before the template and any variant (it was found per variant,
  // naming slice's options).
  const bool masks = std::any_of(job.variants.begin(), job.variants.end(),
                                 [](const BatchVariant& v) { return !v.masks.empty(); });
  // A material named for contours only does nothing unless a material_correction changes them.
  if (!job.material.empty() && !masks)
    if (const std::string why = unusedMaterialReason(print, false, "the contours", ""); !why.empty())
      throw InputError(job.sourceFile.string() + ": settings.material: does nothing in this job: " + why +
                       "; its exposures need a variant with masks");
  // What every variant's masks would refuse, refused once here naming the job's settings (each variant
  // failed with slice's option names): anti-aliasing against gamma_correction 0, a light map on binary
  // masks, a portrait display the user set for masks that are landscape only.
  try {
    checkMaskSettings(print, job.antialias, masks, "settings.antialias");
  } catch (const InputError& e) {
    throw InputError(job.sourceFile.string() + ": " + e.what());
  }
  const auto orientationFrom = print.origin.find("display_orientation");
  if (print.orientation == "portrait" && orientationFrom != print.origin.end() &&
      !orientationFrom->second.starts_with("printer "))
    for (const BatchVariant& v : job.variants) {
      const std::string ext = lowerExtension(v.masks);
      if (landscapeOnlyFormat(ext))
        throw InputError(job.sourceFile.string() + ": variant '" + v.name +
                         "': display_orientation portrait (" + orientationFrom->second +
                         ") applies to SL1 archives and PNG folders only; " + ext +
                         " stacks are written landscape");
    }
  if (masks) {
    const uint32_t width = job.resolution ? (*job.resolution)[0] : print.pixelsX;
    const uint32_t height = job.resolution ? (*job.resolution)[1] : print.pixelsY;
    const double pixel =
        job.pixel ? *job.pixel
                  : (print.pixelsX > 0 && print.displayWidth > 0 ? print.displayWidth / print.pixelsX : 0.0);
    const std::string where = job.sourceFile.string() + ": ";
    if (width == 0 || height == 0)
      throw InputError(where + "masks need an image size: give settings.printer (" + printerNames() +
                       ") or settings.resolution [W, H]");
    if (!(pixel > 0))
      throw InputError(
          where + "masks need a pixel size: give settings.pixel (mm)" +
          (print.printerName.empty() ? "" : ", printer '" + print.printerName + "' has none of its own"));
  }
  return print;
}

MaskOptions batchMaskOptions(const BatchJob& job, const std::filesystem::path& masks, PrintSettings& print) {
  MaskOptions o;
  o.output = masks;
  o.printer = job.printer;
  o.pixel = job.pixel;
  if (job.resolution)
    o.resolution = std::pair<uint32_t, uint32_t>{(*job.resolution)[0], (*job.resolution)[1]};
  if (job.origin) o.origin = std::pair<double, double>{(*job.origin)[0], (*job.origin)[1]};
  o.mirrorX = job.mirrorX.value_or(false);
  o.mirrorY = job.mirrorY.value_or(false);
  o.antialias = job.antialias;
  o.fitAdvice = "set settings.origin to move the image, or use a smaller model or larger pixels";
  recordDisplayOptions(print, o, "settings.resolution", "settings.pixel");
  return o;
}

void checkBatchMaskImages(const BatchJob& job, const PrintSettings& settings) {
  std::set<std::string> formats;
  for (const BatchVariant& v : job.variants) {
    if (v.masks.empty() || !formats.insert(lowerExtension(v.masks)).second) continue;
    PrintSettings print = settings;
    MaskOptions o = batchMaskOptions(job, v.masks, print);
    o.crop = true;  // no model: its extent only places the image
    print = settingsForMaskFormat(print, v.masks);
    try {
      maskTransfer(print, makeMaskJob(o, print, BoundingBox{}, v.masks.stem().string(), {}));
    } catch (const InputError& e) {
      throw InputError(job.sourceFile.string() + ": variant '" + v.name + "': " + e.what());
    }
  }
}

void checkBatchFeatureFiles(const BatchJob& job) {
  for (const BatchVariant& v : job.variants) {
    try {
      checkFeatureFiles(v.model, v.add, v.remove);
    } catch (const InputError& e) {
      throw InputError(job.sourceFile.string() + ": variant '" + v.name + "': " + e.what());
    }
  }
}

SliceJobOptions batchSliceOptions(const BatchJob& job, const BatchVariant& variant,
                                  const TemplateTable& table) {
  SliceJobOptions o;
  o.read.unitMm = job.unitMm;
  o.read.scale = job.scale;
  o.read.runner = parallelChunkRunner();
  o.planes.layerHeight = job.layerHeight;
  o.planes.layers = job.layers;
  o.planes.z0 = job.z0;
  o.planes.explicitZ = job.explicitZ;
  if (!o.planes.layerHeight && !o.planes.layers && o.planes.explicitZ.empty()) o.planes.layerHeight = 0.05;
  if (!job.method.empty() && !parseSliceMethod(job.method, o.slice.method))
    throw InputError("unknown method '" + job.method + "'");
  if (job.joinTolerance) o.slice.joinTolerance = *job.joinTolerance;
  o.overwrite = job.overwrite;
  o.fixOrientation = job.fixOrientation;
  o.fixOrientationOption = "\"fix_orientation\": true in the job's settings";
  o.cliBinary = job.cliBinary;
  o.templateTable = &table;
  if (!variant.contours.empty()) o.outputs.push_back(variant.contours);
  PrintSettings print = batchJobSettings(job);
  o.masks = batchMaskOptions(job, variant.masks, print);
  o.print = settingsForMaskFormat(print, variant.masks);
  o.add = variant.add;
  o.remove = variant.remove;
  o.report = variant.report;
  // No output of the job may replace one of its inputs, even through a link: the job file, the
  // template's model and table, and every variant's meshes.
  o.otherInputs = {job.sourceFile, job.templateModel, job.templateFile, job.profile, o.print.lightMap};
  for (const BatchVariant& v : job.variants) {
    o.otherInputs.push_back(v.model);
    o.otherInputs.insert(o.otherInputs.end(), v.add.begin(), v.add.end());
    o.otherInputs.insert(o.otherInputs.end(), v.remove.begin(), v.remove.end());
  }
  return o;
}

BatchOutcome completeBatchOutcome() {
  BatchOutcome o;
  o.status = "complete";
  o.detail = "outputs exist, skipped";
  return o;
}

BatchOutcome runBatchVariant(const BatchJob& job, const BatchVariant& variant, const TemplateTable& table,
                             const ProgressContext* progress) {
  BatchOutcome outcome;
  const auto t0 = std::chrono::steady_clock::now();
  try {
    const auto outputs = batchVariantOutputs(variant);
    std::size_t existing = 0, finished = 0;
    for (const auto& p : outputs) {
      if (!p.parent_path().empty()) std::filesystem::create_directories(p.parent_path());
      existing += std::filesystem::exists(p) ? 1 : 0;
      finished += finishedOutput(p, p == variant.masks) ? 1 : 0;
    }
    SliceJobOptions options = batchSliceOptions(job, variant, table);
    // Some outputs but not all: an interrupted run committed the first ones (runSliceJob commits the
    // outputs one after another at the end). Slice again and replace them along with the missing ones:
    // the same input gives the same bytes, and the report's resin volume needs the masks computed anyway.
    const bool resumed = existing > 0 && !job.overwrite;
    if (resumed) options.overwrite = true;
    const SliceJobResult r = runSliceJob(variant.model, options, progress);
    outcome.status = "ok";
    outcome.layers = r.stats.layers;
    outcome.detail = r.topology;
    outcome.warnings = r.warnings;
    if (resumed)
      outcome.detail += "; resumed: " + std::to_string(outputs.size() - finished) + " of " +
                        std::to_string(outputs.size()) + " outputs were missing or not whole, all rewritten";
  } catch (const std::bad_alloc&) {  // said as such, not "std::bad_alloc"
    outcome.status = "failed";
    outcome.detail =
        "out of memory: the variant needs more than the system gives this process (fewer "
        "variants side by side or threads, a smaller image, or a smaller model)";
  } catch (const std::exception& e) {
    outcome.status = "failed";
    outcome.detail = e.what();
  } catch (...) {
    outcome.status = "failed";
    outcome.detail = "unknown error";
  }
  outcome.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return outcome;
}

uint64_t batchVariantBytes(const BatchVariant& variant) {
  uint64_t bytes = 0;
  auto add = [&bytes](const std::filesystem::path& p) {
    std::error_code ec;
    const auto size = std::filesystem::file_size(p, ec);
    if (!ec) bytes += size;
  };
  add(variant.model);
  for (const auto& f : variant.add) add(f);
  for (const auto& f : variant.remove) add(f);
  return bytes;
}

std::vector<std::size_t> largestFirst(const BatchJob& job, std::vector<std::size_t> indices) {
  std::vector<uint64_t> bytes(job.variants.size(), 0);
  for (const std::size_t i : indices) bytes[i] = batchVariantBytes(job.variants[i]);
  std::stable_sort(indices.begin(), indices.end(),
                   [&](std::size_t a, std::size_t b) { return bytes[a] > bytes[b]; });
  return indices;
}

BatchTotals batchTotals(const std::vector<BatchOutcome>& outcomes) {
  BatchTotals t;
  for (const auto& o : outcomes) {
    t.failed += o.status == "failed";
    t.complete += o.status == "complete";
    if (o.status == "ok") {
      ++t.sliced;
      t.layers += o.layers;
    }
  }
  return t;
}

void printBatchSummary(std::FILE* out, const BatchJob& job, const BatchTemplate& tmpl,
                       const std::vector<BatchOutcome>& outcomes, double totalSeconds, bool withRank,
                       const std::string& totalsSuffix) {
  const BatchTotals t = batchTotals(outcomes);
  std::fprintf(out, "template   : %u facets, table %s\n", tmpl.table.facetCount, tmpl.source.c_str());
  for (std::size_t i = 0; i < outcomes.size() && i < job.variants.size(); ++i) {
    const BatchOutcome& o = outcomes[i];
    if (withRank) {
      const std::string rank = o.rank >= 0 ? std::to_string(o.rank) : "-";
      std::fprintf(out, "%-10s : %-8s %7.2f s  rank %-3s %s\n", job.variants[i].name.c_str(),
                   o.status.c_str(), o.seconds, rank.c_str(), o.detail.c_str());
    } else {
      std::fprintf(out, "%-10s : %-8s %7.2f s  %s\n", job.variants[i].name.c_str(), o.status.c_str(),
                   o.seconds, o.detail.c_str());
    }
  }
  std::fprintf(out, "summary    : %zu sliced, %zu already complete, %zu failed of %zu; %llu layers in %.2f s",
               t.sliced, t.complete, t.failed, outcomes.size(), static_cast<unsigned long long>(t.layers),
               totalSeconds);
  if (t.sliced > 0 && totalSeconds > 0)
    std::fprintf(out, " (%.1f variants/min)", 60.0 * static_cast<double>(t.sliced) / totalSeconds);
  std::fprintf(out, "%s\n", totalsSuffix.c_str());
}

}  // namespace toposlice
