#include "tools/batch_command.h"

#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "core/weld.h"
#include "io/batch_job.h"
#include "io/errors.h"
#include "io/stl_reader.h"
#include "io/template_file.h"
#include "parallel/parallel.h"
#include "tools/progress_bar.h"
#include "tools/slice_job.h"

namespace toposlice {
namespace {

struct VariantOutcome {
  std::string status;  // "ok", "complete" (skipped), "failed"
  std::string detail;
  double seconds = 0;
  uint64_t layers = 0;
};

std::vector<std::filesystem::path> outputsOf(const BatchVariant& v) {
  std::vector<std::filesystem::path> out;
  for (const auto* p : {&v.contours, &v.masks, &v.report})
    if (!p->empty()) out.push_back(*p);
  return out;
}

void applyMaskSettings(const BatchJob& job, const BatchVariant& variant, SliceJobOptions& o) {
  o.masks.output = variant.masks;
  o.masks.printer = job.printer;
  o.masks.pixel = job.pixel;
  if (job.resolution) o.masks.resolution = std::pair<uint32_t, uint32_t>{(*job.resolution)[0], (*job.resolution)[1]};
  if (job.origin) o.masks.origin = std::pair<double, double>{(*job.origin)[0], (*job.origin)[1]};
  o.masks.mirrorX = job.mirrorX.value_or(false);
  o.masks.mirrorY = job.mirrorY.value_or(false);
  o.masks.antialias = job.antialias;
  o.add = variant.add;
  o.remove = variant.remove;
  o.report = variant.report;
}

SliceJobOptions optionsFor(const BatchJob& job, const BatchVariant& variant, const TemplateTable& table) {
  SliceJobOptions o;
  o.planes.layerHeight = job.layerHeight;
  o.planes.layers = job.layers;
  o.planes.z0 = job.z0;
  o.planes.explicitZ = job.explicitZ;
  if (!o.planes.layerHeight && !o.planes.layers && o.planes.explicitZ.empty()) o.planes.layerHeight = 0.05;
  if (!job.method.empty() && !parseSliceMethod(job.method, o.slice.method))
    throw InputError("unknown method '" + job.method + "'");
  if (job.joinTolerance) o.slice.joinTolerance = *job.joinTolerance;
  o.overwrite = job.overwrite;
  o.templateTable = &table;
  if (!variant.contours.empty()) o.outputs.push_back(variant.contours);
  applyMaskSettings(job, variant, o);
  return o;
}

}  // namespace

int runBatch(const std::filesystem::path& jobPath, const BatchRunOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  const BatchJob job = readBatchJob(jobPath);
  ThreadLimit threads(job.threads);  // 0: keep the command line's limit

  TemplateTable table;
  std::string tableSource;
  if (!job.templateFile.empty() && std::filesystem::exists(job.templateFile)) {
    table = readTemplateFile(job.templateFile);
    tableSource = "loaded " + job.templateFile.string();
  } else if (!job.templateModel.empty()) {
    table = buildTemplateTable(weldCorners(readStl(job.templateModel).corners));
    tableSource = "built from " + job.templateModel.string();
    if (!job.templateFile.empty()) {
      std::filesystem::create_directories(job.templateFile.parent_path());
      writeTemplateFile(job.templateFile, table, false);
      tableSource += ", saved to " + job.templateFile.string();
    }
  } else {
    throw InputError(jobPath.string() + ": the template table " + job.templateFile.string() +
                     " does not exist and no template model is given to build it");
  }

  std::vector<VariantOutcome> outcomes(job.variants.size());
  ProgressBar bar("batch", options.quiet);
  uint64_t layersDone = 0;
  for (std::size_t i = 0; i < job.variants.size(); ++i) {
    const BatchVariant& v = job.variants[i];
    VariantOutcome& outcome = outcomes[i];
    const auto outputs = outputsOf(v);
    bool complete = !outputs.empty() && !job.overwrite;
    for (const auto& p : outputs) complete = complete && std::filesystem::exists(p);
    if (complete) {
      outcome.status = "complete";
      outcome.detail = "outputs exist, skipped";
      continue;
    }
    bar.setLabel("variant " + std::to_string(i + 1) + "/" + std::to_string(job.variants.size()) + " " + v.name);
    ProgressContext progress;
    progress.report = [&](uint64_t done, uint64_t total) { bar.update(done, total); };
    const auto t0 = std::chrono::steady_clock::now();
    try {
      for (const auto& p : outputs)
        if (!p.parent_path().empty()) std::filesystem::create_directories(p.parent_path());
      const SliceJobResult r = runSliceJob(v.model, optionsFor(job, v, table), &progress);
      outcome.status = "ok";
      outcome.layers = r.stats.layers;
      outcome.detail = r.topology;
      layersDone += r.stats.layers;
    } catch (const std::exception& e) {
      outcome.status = "failed";
      outcome.detail = e.what();
    }
    outcome.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }

  const double total = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::size_t failed = 0, done = 0, skipped = 0;
  for (const auto& o : outcomes) {
    failed += o.status == "failed";
    done += o.status == "ok";
    skipped += o.status == "complete";
  }
  if (!options.quiet || failed > 0) {
    std::FILE* out = options.quiet ? stderr : stdout;
    std::fprintf(out, "template   : %u facets, table %s\n", table.facetCount, tableSource.c_str());
    for (std::size_t i = 0; i < outcomes.size(); ++i)
      std::fprintf(out, "%-10s : %-8s %7.2f s  %s\n", job.variants[i].name.c_str(), outcomes[i].status.c_str(),
                   outcomes[i].seconds, outcomes[i].detail.c_str());
    std::fprintf(out, "summary    : %zu sliced, %zu already complete, %zu failed of %zu; %llu layers in %.2f s",
                 done, skipped, failed, outcomes.size(), static_cast<unsigned long long>(layersDone), total);
    if (done > 0) std::fprintf(out, " (%.1f variants/min)", 60.0 * static_cast<double>(done) / total);
    std::fprintf(out, "\n");
  }
  return failed > 0 ? 1 : 0;
}

}  // namespace toposlice
