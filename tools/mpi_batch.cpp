// toposlice-mpi: a batch job (docs/FORMATS.md, "Batch jobs") spread over the ranks of an MPI job, on
// one machine or many (README, "Many machines (MPI)").
// Usage: mpirun -np N toposlice-mpi batch JOB.json [--threads T] [--quiet] [--dispatch-only]
//
// Every rank reads the job and loads the template table once (rank 0 first builds and saves it when
// the table file does not exist yet, then tells the others to go on), and slices whole variants with
// its local cores through TBB. Outputs go to the paths in the job, written by runSliceJob through
// temporaries renamed into place, so they must be on a file system every rank sees at the same path.
//
// Work distribution (dynamic, largest first). Rank 0 skips the variants whose outputs all exist and
// queues the rest by size on disk, largest first, so the long ones start early and the short ones fill
// the gaps at the end. A worker rank asks for work with a message on kTagRequest: "ready" (its first
// request, after its table loaded), or the result of its previous variant (index, status, seconds,
// layers, message), which is also its next request; or "setup failed" with the reason, after which it
// gets nothing. Rank 0 answers every request with one int64 on kTagWork: a variant index, or kStop.
//
// Rank 0 works too: a second thread on rank 0 takes variants from the same queue and slices them,
// while rank 0's main thread is the dispatcher (the only thread that calls MPI, so MPI_THREAD_FUNNELED
// is enough). With -np N there are N slicing ranks, with -np 1 the program is the single-machine
// runner. No rank ever blocks inside MPI: Open MPI waits by spinning a core, which would take
// a core from the slicer beside it (and from the other ranks on an oversubscribed machine), so every
// wait here is a test-and-sleep loop (MPI_Iprobe, MPI_Test on nonblocking operations) costing about
// nothing; a request waits at most a millisecond, against seconds per variant. --dispatch-only keeps
// rank 0 from slicing (for a head node that should stay free).
//
// Failures: a failing variant is reported and the others go on; a rank whose setup fails (no job or
// table file on its machine) reports it and takes no work. Rank 0 prints the summary of
// `toposlice batch` with a rank column and broadcasts the exit status (1 when any variant failed), so
// every rank exits with it. A rank that dies (a lost node) makes mpirun end the job; its variant never
// appears under its output names, and running the job again slices only what is missing.
#include <mpi.h>

#include <CLI/CLI.hpp>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <deque>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "io/errors.h"
#include "io/jobs/batch_job.h"
#include "io/output_file.h"
#include "parallel/parallel.h"
#include "tools/batch_plan.h"

namespace toposlice {
namespace {

constexpr int kTagRequest = 1;  // worker -> rank 0: a WireMessage
constexpr int kTagWork = 2;     // rank 0 -> worker: one int64, a variant index or kStop
constexpr int64_t kStop = -1;
constexpr std::size_t kMaxDetail = 16 * 1024;  // longer messages are cut

enum class Kind : int32_t { Ready = 0, Result = 1, SetupFailed = 2 };

// A request as bytes: fixed header, then the message text. All ranks run the same build, so the
// header travels as raw bytes (no heterogeneous clusters).
struct WireHeader {
  int32_t kind = 0;
  int32_t failed = 0;
  int64_t index = -1;
  double seconds = 0;
  uint64_t layers = 0;
};

std::vector<char> encode(Kind kind, int64_t index, const BatchOutcome& o) {
  WireHeader h;
  h.kind = static_cast<int32_t>(kind);
  h.failed = o.status == "failed" ? 1 : 0;
  h.index = index;
  h.seconds = o.seconds;
  h.layers = o.layers;
  const std::size_t n = std::min(o.detail.size(), kMaxDetail);
  std::vector<char> bytes(sizeof h + n);
  std::memcpy(bytes.data(), &h, sizeof h);
  if (n > 0) std::memcpy(bytes.data() + sizeof h, o.detail.data(), n);
  return bytes;
}

bool decode(const std::vector<char>& bytes, WireHeader& h, std::string& detail) {
  if (bytes.size() < sizeof h) return false;
  std::memcpy(&h, bytes.data(), sizeof h);
  detail.assign(bytes.data() + sizeof h, bytes.size() - sizeof h);
  return true;
}

void pause(std::chrono::microseconds& interval) {
  std::this_thread::sleep_for(interval);
  interval = std::min(interval * 2, std::chrono::microseconds(1000));
}

// Waits for a nonblocking operation without spinning a core.
void waitQuietly(MPI_Request& request) {
  auto interval = std::chrono::microseconds(20);
  for (;;) {
    int done = 0;
    MPI_Test(&request, &done, MPI_STATUS_IGNORE);
    if (done) return;
    pause(interval);
  }
}

int broadcastInt(int value) {
  MPI_Request request;
  MPI_Ibcast(&value, 1, MPI_INT, 0, MPI_COMM_WORLD, &request);
  waitQuietly(request);
  return value;
}

void sendRequest(Kind kind, int64_t index, const BatchOutcome& o) {
  std::vector<char> bytes = encode(kind, index, o);
  MPI_Request request;
  MPI_Isend(bytes.data(), static_cast<int>(bytes.size()), MPI_BYTE, 0, kTagRequest, MPI_COMM_WORLD, &request);
  waitQuietly(request);
}

int64_t receiveWork() {
  int64_t index = kStop;
  MPI_Request request;
  MPI_Irecv(&index, 1, MPI_INT64_T, 0, kTagWork, MPI_COMM_WORLD, &request);
  waitQuietly(request);
  return index;
}

extern "C" void onSignal(int signal) {
  removePendingOutputs();
  std::signal(signal, SIG_DFL);
  std::raise(signal);
}

struct Options {
  std::filesystem::path job;
  unsigned threads = 0;
  bool quiet = false;
  bool dispatchOnly = false;
};

// The variant queue shared by rank 0's dispatcher and its own slicing thread.
class WorkQueue {
 public:
  explicit WorkQueue(std::vector<std::size_t> order) : queue_(order.begin(), order.end()) {}
  std::optional<std::size_t> pop() {
    std::lock_guard lock(mutex_);
    if (queue_.empty()) return std::nullopt;
    const std::size_t i = queue_.front();
    queue_.pop_front();
    return i;
  }

 private:
  std::mutex mutex_;
  std::deque<std::size_t> queue_;
};

// Results of rank 0's own slicing thread, collected by the dispatcher.
struct LocalResults {
  std::mutex mutex;
  std::vector<std::pair<std::size_t, BatchOutcome>> ready;
  std::atomic<bool> finished{false};
};

int runWorker(const Options& options) {
  BatchJob job;
  BatchTemplate tmpl;
  std::optional<ThreadLimit> jobThreads;
  try {
    job = readBatchJob(options.job);
    jobThreads.emplace(job.threads);
    tmpl = loadOrBuildBatchTemplate(job, options.job, false);  // rank 0 has saved the table file already
  } catch (const std::exception& e) {
    BatchOutcome o;
    o.status = "failed";
    o.detail = e.what();
    sendRequest(Kind::SetupFailed, -1, o);
    return broadcastInt(1);
  }
  sendRequest(Kind::Ready, -1, BatchOutcome{});
  for (;;) {
    const int64_t index = receiveWork();
    if (index < 0) break;
    BatchOutcome o;
    if (static_cast<std::size_t>(index) < job.variants.size()) {
      o = runBatchVariant(job, job.variants[static_cast<std::size_t>(index)], tmpl.table, nullptr);
    } else {
      o.status = "failed";
      o.detail = "variant index " + std::to_string(index) + " is not in this rank's copy of the job";
    }
    sendRequest(Kind::Result, index, o);
  }
  return broadcastInt(0);
}

int runDispatcher(const Options& options, int size, int provided) {
  const auto start = std::chrono::steady_clock::now();
  BatchJob job;
  BatchTemplate tmpl;
  std::optional<ThreadLimit> jobThreads;
  int ok = 1;
  try {
    job = readBatchJob(options.job);
    jobThreads.emplace(job.threads);
    tmpl = loadOrBuildBatchTemplate(job, options.job, true);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "toposlice-mpi: error: %s\n", e.what());
    ok = 0;
  }
  broadcastInt(ok);  // also the barrier: the table file is saved before any other rank looks for it
  if (!ok) return broadcastInt(1);

  const std::size_t n = job.variants.size();
  std::vector<BatchOutcome> outcomes(n);
  std::vector<std::size_t> pending;
  for (std::size_t i = 0; i < n; ++i) {
    if (batchVariantComplete(job, job.variants[i]))
      outcomes[i] = completeBatchOutcome();
    else
      pending.push_back(i);
  }
  const std::size_t toSlice = pending.size();
  WorkQueue queue(largestFirst(job, std::move(pending)));
  std::size_t finished = 0;
  auto record = [&](std::size_t i, BatchOutcome o) {
    ++finished;
    if (!options.quiet)
      std::fprintf(stderr, "toposlice-mpi: [%zu/%zu] %s %s in %.2f s on rank %d%s%s\n", finished, toSlice,
                   job.variants[i].name.c_str(), o.status.c_str(), o.seconds, o.rank,
                   o.status == "failed" ? ": " : "", o.status == "failed" ? o.detail.c_str() : "");
    outcomes[i] = std::move(o);
  };

  // Rank 0 slices in a second thread unless told not to, or unless MPI cannot have a second thread
  // beside the one that calls it (then it only dispatches, or with -np 1 slices in this thread).
  const bool localThread = !options.dispatchOnly || size == 1;
  const bool threadOk = provided >= MPI_THREAD_FUNNELED;
  LocalResults local;
  std::thread slicer;
  // inlineRecord: on the dispatcher's own thread (-np 1), which then records each outcome at once.
  auto sliceLocally = [&](bool inlineRecord) {
    while (const auto i = queue.pop()) {
      BatchOutcome o = runBatchVariant(job, job.variants[*i], tmpl.table, nullptr);
      o.rank = 0;
      if (inlineRecord) {
        record(*i, std::move(o));
        continue;
      }
      std::lock_guard lock(local.mutex);
      local.ready.emplace_back(*i, std::move(o));
    }
    local.finished = true;
  };
  if (size == 1 || !threadOk) {
    if (size == 1) sliceLocally(true);
    local.finished = true;
  } else if (localThread) {
    slicer = std::thread(sliceLocally, false);
  } else {
    local.finished = true;
  }

  int remoteActive = size - 1;  // worker ranks not yet told to stop (or failed to start)
  std::vector<std::string> setupErrors;
  auto drainLocal = [&] {
    std::vector<std::pair<std::size_t, BatchOutcome>> ready;
    {
      std::lock_guard lock(local.mutex);
      ready.swap(local.ready);
    }
    for (auto& [i, o] : ready) record(i, std::move(o));
  };
  auto interval = std::chrono::microseconds(20);
  while (remoteActive > 0 || !local.finished.load()) {
    drainLocal();
    if (remoteActive == 0) {
      pause(interval);
      continue;
    }
    int flag = 0;
    MPI_Status status;
    MPI_Iprobe(MPI_ANY_SOURCE, kTagRequest, MPI_COMM_WORLD, &flag, &status);
    if (!flag) {
      pause(interval);
      continue;
    }
    interval = std::chrono::microseconds(20);
    int count = 0;
    MPI_Get_count(&status, MPI_BYTE, &count);
    std::vector<char> bytes(static_cast<std::size_t>(std::max(count, 0)));
    const int source = status.MPI_SOURCE;
    MPI_Recv(bytes.data(), count, MPI_BYTE, source, kTagRequest, MPI_COMM_WORLD, MPI_STATUS_IGNORE);
    WireHeader h;
    std::string detail;
    if (!decode(bytes, h, detail)) {
      std::fprintf(stderr, "toposlice-mpi: error: rank %d sent a malformed request\n", source);
      MPI_Abort(MPI_COMM_WORLD, 2);
    }
    if (h.kind == static_cast<int32_t>(Kind::SetupFailed)) {
      std::fprintf(stderr, "toposlice-mpi: rank %d could not start and takes no variants: %s\n", source,
                   detail.c_str());
      setupErrors.push_back("rank " + std::to_string(source));
      --remoteActive;
      continue;
    }
    if (h.kind == static_cast<int32_t>(Kind::Result) && h.index >= 0 &&
        static_cast<std::size_t>(h.index) < n) {
      BatchOutcome o;
      o.status = h.failed ? "failed" : "ok";
      o.detail = std::move(detail);
      o.seconds = h.seconds;
      o.layers = h.layers;
      o.rank = source;
      record(static_cast<std::size_t>(h.index), std::move(o));
    }
    const auto next = queue.pop();
    int64_t answer = next ? static_cast<int64_t>(*next) : kStop;
    MPI_Send(&answer, 1, MPI_INT64_T, source, kTagWork, MPI_COMM_WORLD);
    if (!next) --remoteActive;
  }
  if (slicer.joinable()) slicer.join();
  drainLocal();

  // Every rank that could not start left its variants to the others; a variant is lost only when no
  // rank was left to slice it (--dispatch-only with every worker failing).
  for (auto& o : outcomes)
    if (o.status.empty()) {
      o.status = "failed";
      o.detail = "not sliced: no rank was able to take it";
    }

  const double total = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const BatchTotals totals = batchTotals(outcomes);
  if (!options.quiet || totals.failed > 0) {
    std::string suffix = "; " + std::to_string(size) + (size == 1 ? " rank" : " ranks") + " x " +
                         std::to_string(ThreadLimit::available()) + " threads";
    if (!setupErrors.empty()) {
      suffix += "; could not start:";
      for (const auto& e : setupErrors) suffix += " " + e;
    }
    std::FILE* out = options.quiet ? stderr : stdout;
    printBatchSummary(out, job, tmpl, outcomes, total, true, suffix);
    std::fflush(out);
  }
  return broadcastInt(totals.failed > 0 ? 1 : 0);
}

int run(int argc, char** argv) {
  int provided = MPI_THREAD_SINGLE;
  MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided);
  int rank = 0, size = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);

  CLI::App app{"toposlice-mpi: a toposlice batch job spread over the ranks of an MPI job"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "toposlice-mpi 0.1.0");
  Options options;
  std::string jobPath;
  CLI::App* batch = app.add_subcommand("batch", "Slice every variant of a batch job on every rank");
  batch->add_option("job", jobPath, "Batch job (JSON, see docs/FORMATS.md)")->required();
  batch->add_option("--threads", options.threads, "Worker threads per rank (default: all cores)");
  batch->add_flag("-q,--quiet", options.quiet, "No progress lines or summary, errors only");
  batch->add_flag("--dispatch-only", options.dispatchOnly,
                  "Rank 0 hands out variants but slices none (with -np > 1)");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // Every rank parses the same command line; rank 0 alone answers. As in toposlice: help and version
    // as CLI11 prints them, a usage error as one line with status 2.
    const bool informational = dynamic_cast<const CLI::CallForHelp*>(&e) != nullptr ||
                               dynamic_cast<const CLI::CallForAllHelp*>(&e) != nullptr ||
                               dynamic_cast<const CLI::CallForVersion*>(&e) != nullptr;
    int code = informational ? e.get_exit_code() : 2;
    if (rank == 0) {
      if (informational)
        code = app.exit(e);
      else
        std::fprintf(stderr, "toposlice-mpi: error: %s (see toposlice-mpi --help)\n", e.what());
    }
    MPI_Finalize();
    return code;
  }
  options.job = jobPath;

  std::signal(SIGINT, onSignal);
  std::signal(SIGTERM, onSignal);
  int status = 1;
  {
    ThreadLimit limit(options.threads);
    if (rank == 0) {
      status = runDispatcher(options, size, provided);
    } else {
      if (broadcastInt(0) == 0) {
        status = broadcastInt(1);  // rank 0 could not read the job or its table: it said why
      } else {
        status = runWorker(options);
      }
    }
  }
  MPI_Finalize();
  return status;
}

}  // namespace
}  // namespace toposlice

int main(int argc, char** argv) {
  return toposlice::run(argc, argv);
}
