// `toposlice batch JOB.json`: one template table, many variants (docs/FORMATS.md, "Batch jobs").
#pragma once

#include <filesystem>

namespace toposlice {

struct BatchRunOptions {
  bool quiet = false;
};

// Runs every variant of the job with the template table loaded once (built and saved first when the
// job names a template model whose table file does not exist yet). A failing variant is reported and
// skipped; a variant whose outputs all exist is skipped as complete. Prints a summary; returns the exit
// status: 0 when every variant succeeded or was complete, 1 otherwise. Throws InputError for a bad job
// or template.
int runBatch(const std::filesystem::path& jobPath, const BatchRunOptions& options);

}  // namespace toposlice
