#include "tools/batch_command.h"

#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include "io/batch_job.h"
#include "parallel/parallel.h"
#include "tools/batch_plan.h"
#include "tools/progress_bar.h"
#include "tools/slice_job.h"

namespace toposlice {

int runBatch(const std::filesystem::path& jobPath, const BatchRunOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  const BatchJob job = readBatchJob(jobPath);
  ThreadLimit threads(job.threads);  // 0: keep the command line's limit
  const BatchTemplate tmpl = loadOrBuildBatchTemplate(job, jobPath, true);

  std::vector<BatchOutcome> outcomes(job.variants.size());
  ProgressBar bar("batch", options.quiet);
  for (std::size_t i = 0; i < job.variants.size(); ++i) {
    if (interruptRequested()) break;  // the rest stays to do: a re-run finishes the job
    const BatchVariant& v = job.variants[i];
    if (batchVariantComplete(job, v)) {
      outcomes[i] = completeBatchOutcome();
      continue;
    }
    bar.setLabel("variant " + std::to_string(i + 1) + "/" + std::to_string(job.variants.size()) + " " + v.name);
    ProgressContext progress;
    progress.report = [&](uint64_t done, uint64_t total) { bar.update(done, total); };
    outcomes[i] = runBatchVariant(job, v, tmpl.table, &progress);
  }

  const double total = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const BatchTotals totals = batchTotals(outcomes);
  if (!options.quiet || totals.failed > 0)
    printBatchSummary(options.quiet ? stderr : stdout, job, tmpl, outcomes, total, false);
  return totals.failed > 0 ? 1 : 0;
}

}  // namespace toposlice
