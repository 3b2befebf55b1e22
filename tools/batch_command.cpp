#include "tools/batch_command.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "io/jobs/batch_job.h"
#include "io/output_file.h"
#include "parallel/parallel.h"
#include "tools/batch_plan.h"
#include "tools/progress_bar.h"
#include "tools/slice_job.h"

namespace toposlice {

namespace {

// One progress bar for variants sliced side by side: the label counts variants, the bar counts layers
// (the total is estimated from the variants whose layer count is known so far). Updates come from every
// variant's in-order stage, so they are serialized here; counts are kept as running sums.
class BatchProgress {
 public:
  BatchProgress(std::size_t variants, bool quiet)
      : bar_("batch", quiet), done_(variants, 0), total_(variants, 0) {
    remaining_ = variants;
  }
  void report(std::size_t variant, uint64_t done, uint64_t total) {
    const std::lock_guard lock(mutex_);
    layersDone_ += done - done_[variant];
    done_[variant] = done;
    if (total_[variant] == 0 && total > 0) {
      total_[variant] = total;
      knownTotal_ += total;
      ++known_;
    }
    draw();
  }
  void finished(bool sliced) {
    const std::lock_guard lock(mutex_);
    ++finished_;
    if (!sliced) --remaining_;  // skipped as complete: no layers to wait for
    draw();
  }

 private:
  void draw() {
    if (!bar_.active() || known_ == 0) return;
    const uint64_t estimate =
        knownTotal_ + (remaining_ > known_ ? (remaining_ - known_) * (knownTotal_ / known_) : 0);
    bar_.setLabel("batch " + std::to_string(finished_) + "/" + std::to_string(done_.size()) +
                  " variants, layers");
    bar_.update(layersDone_, std::max(estimate, layersDone_));
  }

  std::mutex mutex_;
  ProgressBar bar_;
  std::vector<uint64_t> done_, total_;
  uint64_t layersDone_ = 0, knownTotal_ = 0;
  std::size_t known_ = 0, finished_ = 0, remaining_ = 0;
};

}  // namespace

int runBatch(const std::filesystem::path& jobPath, const BatchRunOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  const BatchJob job = readBatchJob(jobPath);
  ThreadLimit threads(job.threads);  // 0: keep the command line's limit
  const BatchTemplate tmpl = loadOrBuildBatchTemplate(job, jobPath, true);

  // Variants are sliced side by side as well as each on every core: a short job's serial parts (reading,
  // the connectivity check, the in-order writer) then overlap with another's slicing. At most
  // kMaxVariantsInFlight at once bounds memory; each variant's bytes do not depend on it.
  constexpr std::size_t kMaxVariantsInFlight = 4;
  const std::size_t count = job.variants.size();
  const std::size_t inFlight = std::max<std::size_t>(
      1, std::min({count, std::size_t{ThreadLimit::available()}, kMaxVariantsInFlight}));
  std::vector<BatchOutcome> outcomes(count);
  // The folders the variants' outputs go into that this run makes: those left without a file at the end
  // (every variant there failed, or the run was stopped) are taken away again.
  MadeFolders made;
  for (const BatchVariant& v : job.variants)
    for (const auto& p : batchVariantOutputs(v)) made.note(p.parent_path());
  std::optional<BatchProgress> progress(std::in_place, count, options.quiet);
  orderedPipeline(
      count, inFlight,
      [&](std::size_t i, std::size_t) {
        if (interruptRequested()) return;  // the rest stays to do: a re-run finishes the job
        const BatchVariant& v = job.variants[i];
        if (batchVariantComplete(job, v)) {
          outcomes[i] = completeBatchOutcome();
          progress->finished(false);
          return;
        }
        ProgressContext context;
        context.report = [&progress, i](uint64_t done, uint64_t total) { progress->report(i, done, total); };
        outcomes[i] = runBatchVariant(job, v, tmpl.table, &context);
        progress->finished(true);
      },
      [](std::size_t, std::size_t) {});
  made.removeEmpty();

  progress.reset();  // the bar's line ends before the table and the messages below
  const double total = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const BatchTotals totals = batchTotals(outcomes);
  if (!options.quiet) printBatchSummary(stdout, job, tmpl, outcomes, total, false);
  // Warnings (never hidden by --quiet) and one error line per failed variant, on stderr.
  for (std::size_t i = 0; i < count; ++i) {
    const BatchVariant& v = job.variants[i];
    for (const std::string& w : outcomes[i].warnings)
      std::fprintf(stderr, "toposlice: warning: variant '%s': %s\n", v.name.c_str(), w.c_str());
    if (outcomes[i].status == "failed")
      std::fprintf(stderr, "toposlice: error: variant '%s' (%s): %s\n", v.name.c_str(), v.model.c_str(),
                   outcomes[i].detail.c_str());
  }
  return totals.failed > 0 ? 1 : 0;
}

}  // namespace toposlice
