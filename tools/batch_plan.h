// The pieces of a batch run that do not depend on how variants are dispatched, for the MPI runner
// (`toposlice-mpi batch`, tools/mpi_batch.cpp) and the single-machine runner (`toposlice batch`,
// tools/batch_command.cpp, whose private copies of the same logic these replace): the template table,
// the slicing options of a variant, completion checks, one variant's run with its failure caught, the
// dispatch order and the summary. Going through one copy, a variant is sliced with the same options
// (and gives the same bytes) whichever runner or rank slices it.
#pragma once

#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "core/progress.h"
#include "io/jobs/batch_job.h"
#include "io/jobs/template_file.h"
#include "tools/slice_job.h"

namespace toposlice {

// The template table of a job and where it came from, for the summary ("loaded <file>", "built from
// <model>, saved to <file>").
struct BatchTemplate {
  TemplateTable table;
  std::string source;
};

// Loads the job's table file when it exists; otherwise builds the table from the template model and,
// when `save` and the job names a table file, saves it there (creating its folder). Throws InputError
// naming jobPath when there is neither a table file nor a model to build it from, and, before anything
// is read, as batchJobSettings when the job's printer, material, profile or print_settings are bad.
BatchTemplate loadOrBuildBatchTemplate(const BatchJob& job, const std::filesystem::path& jobPath, bool save);

// The variant's output paths (contours, masks, report; those given), in that order.
std::vector<std::filesystem::path> batchVariantOutputs(const BatchVariant& variant);

// True when the variant has outputs, every one exists and is toposlice's (its mark), and the job does
// not overwrite: such a variant is skipped as complete.
bool batchVariantComplete(const BatchJob& job, const BatchVariant& variant);

// The job's printer, material and corrections: its profile file (when given), printer and material, then
// print_settings. Throws InputError for an unknown name, a bad file, key or value.
PrintSettings batchJobSettings(const BatchJob& job);

// The job's mask options for the mask output `masks` (image size, pixel, origin, mirroring,
// anti-aliasing), and its settings.resolution and settings.pixel recorded into `print` as the display's
// settings (recordDisplayOptions), so that --explain says what the images have.
MaskOptions batchMaskOptions(const BatchJob& job, const std::filesystem::path& masks, PrintSettings& print);

// The image's own checks of every mask format the variants write, as a variant's run makes them, without a
// model (a size and a pixel pitch, an orientation the format carries, the light map against the display),
// once per format, before any variant. `settings`: batchJobSettings(job). Throws InputError naming the
// job and the first such variant.
void checkBatchMaskImages(const BatchJob& job, const PrintSettings& settings);

// Every variant's feature files, before any variant: one given twice, both added and removed, or the
// variant's model given as its own feature (slice's checkFeatureFiles). Throws InputError naming the job
// and the variant.
void checkBatchFeatureFiles(const BatchJob& job);

// The runSliceJob options for one variant: the job's planes (default layer height 0.05 mm when none is
// given), method, join tolerance, overwrite, mask settings, features and report, with `table` as the
// template. Throws InputError for an unknown method.
SliceJobOptions batchSliceOptions(const BatchJob& job, const BatchVariant& variant,
                                  const TemplateTable& table);

// What happened to one variant.
struct BatchOutcome {
  std::string status;  // "ok", "complete" (skipped), "failed"; empty: not run (yet)
  std::string detail;  // topology source when ok, the error when failed
  double seconds = 0;
  uint64_t layers = 0;
  int rank = -1;  // MPI rank that sliced it; -1: none (complete, or the single-machine runner)
  std::vector<std::string> warnings;  // the slice job's warnings (an inside-out mesh, empty layers)
};

// The outcome of a variant whose outputs all exist.
BatchOutcome completeBatchOutcome();

// Slices one variant (creating its output folders first) and catches every failure into the outcome,
// so one bad variant never stops a batch. `progress` may be null. A variant with some of its outputs
// but not all (a run interrupted between two commits, or an output deleted by hand) is sliced again
// with overwrite for its own outputs, so the rerun of an interrupted job completes it; the detail then
// says "resumed". Call it only for variants that are not complete (batchVariantComplete).
BatchOutcome runBatchVariant(const BatchJob& job, const BatchVariant& variant, const TemplateTable& table,
                             const ProgressContext* progress);

// Bytes on disk of the variant's model plus its feature meshes (0 for a file that cannot be read): the
// size estimate for dispatching large variants first.
uint64_t batchVariantBytes(const BatchVariant& variant);

// The given variant indices ordered largest first by batchVariantBytes, ties in job order.
std::vector<std::size_t> largestFirst(const BatchJob& job, std::vector<std::size_t> indices);

// Counts over the outcomes.
struct BatchTotals {
  std::size_t sliced = 0, complete = 0, failed = 0;
  uint64_t layers = 0;  // layers of the variants sliced
};
BatchTotals batchTotals(const std::vector<BatchOutcome>& outcomes);

// Prints the summary: a "template" line, one line per variant in job order, and the totals line
// ("summary    : N sliced, N already complete, N failed of N; N layers in S s (R variants/min)"),
// followed by `totalsSuffix` before the newline. With `withRank`, each variant line gets a rank column
// after the time ("rank 2", or "rank -" for a variant no rank sliced). Without it the format is the one
// `toposlice batch` has always printed.
void printBatchSummary(std::FILE* out, const BatchJob& job, const BatchTemplate& tmpl,
                       const std::vector<BatchOutcome>& outcomes, double totalSeconds, bool withRank,
                       const std::string& totalsSuffix = {});

}  // namespace toposlice
