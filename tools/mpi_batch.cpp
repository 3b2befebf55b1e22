// toposlice-mpi: a batch job (docs/FORMATS.md, "Batch jobs") or a plate job ("Plate jobs") spread over
// the ranks of an MPI job, on one machine or many (README, "Many machines (MPI)").
// Usage: mpirun -np N toposlice-mpi batch JOB.json [--threads T] [--quiet] [--dispatch-only]
//        mpirun -np N toposlice-mpi plate JOB.json [--threads T] [--quiet]
//
// Batch jobs:
// Every rank reads the job and loads the template table once (rank 0 first builds and saves it when
// the table file does not exist yet, then tells the others to go on), and slices whole variants with
// its local cores through TBB. Outputs go to the paths in the job, written by runSliceJob through
// temporaries renamed into place, so they must be on a file system every rank sees at the same path.
//
// Work distribution (dynamic, largest first). Rank 0 skips the variants whose outputs all exist and
// queues the rest by size on disk, largest first, so the long ones start early and the short ones fill
// the gaps at the end. A worker rank asks for work with a message on kTagRequest: "ready" (its first
// request, after its table loaded), or the result of its previous variant (index, status, seconds,
// layers, message, warnings), which is also its next request; or "setup failed" with the reason, after which
// it gets nothing. Rank 0 answers every request with one int64 on kTagWork: a variant index, or kStop.
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
//
// Plate jobs: every rank reads the whole job and arranges it (PreparedPlateJob: serial and
// integer-based, so every rank gets the same plates; rank 0 compares every rank's placements with its
// own), then slices plate p (0-based) when p mod N is its rank, into temporaries. Rank 0 collects every
// rank's per-plate numbers and temporaries, stages them all in one OutputTransaction in plate order,
// adds the report and commits, so the outputs appear together or not at all and are the same bytes as
// `toposlice plate` writes; a worker removes its temporaries unless rank 0 says it committed them. A
// problem found while preparing (a bad job, overlapping or outside placements) is reported by rank 0
// only; of failures while slicing, rank 0 reports the one of the lowest plate (where `toposlice plate`
// would have stopped). Every rank exits with rank 0's status.
#include <mpi.h>
#include <unistd.h>

#include <CLI/CLI.hpp>

#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <deque>
#include <filesystem>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <type_traits>
#include <vector>

#include "core/memory_advice.h"
#include "io/errors.h"
#include "io/jobs/batch_job.h"
#include "io/output_file.h"
#include "parallel/parallel.h"
#include "tools/batch_plan.h"
#include "tools/plate_job.h"

namespace toposlice {
namespace {

constexpr int kTagRequest = 1;  // worker -> rank 0: a WireMessage
constexpr int kTagWork = 2;     // rank 0 -> worker: one int64, a variant index or kStop
constexpr int kTagPlate = 3;    // worker -> rank 0: a plate job's messages (ByteWriter)
constexpr int64_t kStop = -1;
constexpr std::size_t kMaxDetail = 16 * 1024;  // longer messages are cut

enum class Kind : int32_t { Ready = 0, Result = 1, SetupFailed = 2 };

// A request as bytes: fixed header, the message text (detailBytes), then the variant's warnings, each
// ended by a line feed (a warning is one line). All ranks run the same build, so the header travels as
// raw bytes (no heterogeneous clusters).
struct WireHeader {
  int32_t kind = 0;
  int32_t failed = 0;
  int64_t index = -1;
  double seconds = 0;
  uint64_t layers = 0;
  uint64_t detailBytes = 0;
};

std::vector<char> encode(Kind kind, int64_t index, const BatchOutcome& o) {
  WireHeader h;
  h.kind = static_cast<int32_t>(kind);
  h.failed = o.status == "failed" ? 1 : 0;
  h.index = index;
  h.seconds = o.seconds;
  h.layers = o.layers;
  h.detailBytes = std::min(o.detail.size(), kMaxDetail);
  std::vector<char> bytes(sizeof h);
  std::memcpy(bytes.data(), &h, sizeof h);
  bytes.insert(bytes.end(), o.detail.begin(), o.detail.begin() + static_cast<std::ptrdiff_t>(h.detailBytes));
  for (const std::string& w : o.warnings) {
    bytes.insert(bytes.end(), w.begin(),
                 w.begin() + static_cast<std::ptrdiff_t>(std::min(w.size(), kMaxDetail)));
    bytes.push_back('\n');
  }
  return bytes;
}

bool decode(const std::vector<char>& bytes, WireHeader& h, std::string& detail,
            std::vector<std::string>& warnings) {
  if (bytes.size() < sizeof h) return false;
  std::memcpy(&h, bytes.data(), sizeof h);
  if (h.detailBytes > bytes.size() - sizeof h) return false;
  const char* text = bytes.data() + sizeof h;
  detail.assign(text, h.detailBytes);
  const std::string rest(text + h.detailBytes, bytes.data() + bytes.size());
  for (std::size_t at = 0; at < rest.size();) {
    const std::size_t end = rest.find('\n', at);
    if (end == std::string::npos) return false;
    warnings.push_back(rest.substr(at, end - at));
    at = end + 1;
  }
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

void sendToRoot(const std::vector<char>& bytes, int tag) {
  MPI_Request request;
  MPI_Isend(bytes.data(), static_cast<int>(bytes.size()), MPI_BYTE, 0, tag, MPI_COMM_WORLD, &request);
  waitQuietly(request);
}

void sendRequest(Kind kind, int64_t index, const BatchOutcome& o) {
  sendToRoot(encode(kind, index, o), kTagRequest);
}

// Rank 0: the next message with `tag` from `source`, whatever its size.
std::vector<char> receiveFrom(int source, int tag) {
  auto interval = std::chrono::microseconds(20);
  MPI_Status status;
  for (;;) {
    int flag = 0;
    MPI_Iprobe(source, tag, MPI_COMM_WORLD, &flag, &status);
    if (flag) break;
    pause(interval);
  }
  int count = 0;
  MPI_Get_count(&status, MPI_BYTE, &count);
  std::vector<char> bytes(static_cast<std::size_t>(std::max(count, 0)));
  MPI_Request request;
  MPI_Irecv(bytes.data(), count, MPI_BYTE, source, tag, MPI_COMM_WORLD, &request);
  waitQuietly(request);
  return bytes;
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
  static const char kMessage[] =
      "toposlice-mpi: interrupted: stopped at once; this rank's temporaries removed\n";
  [[maybe_unused]] const ssize_t written = ::write(STDERR_FILENO, kMessage, sizeof kMessage - 1);
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
  if (options.dispatchOnly && size == 1) {  // an option that cannot apply: no other rank to slice
    std::fprintf(stderr,
                 "toposlice-mpi: error: --dispatch-only keeps rank 0 from slicing, and this job has no other "
                 "rank: run it with mpirun -np N, N > 1\n");
    return broadcastInt(2);
  }
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
  const bool progressLines = !options.quiet && ::isatty(STDERR_FILENO) == 1;
  auto record = [&](std::size_t i, BatchOutcome o) {
    ++finished;
    for (const std::string& w : o.warnings)  // never hidden by --quiet, as in toposlice batch
      std::fprintf(stderr, "toposlice-mpi: warning: variant '%s': %s\n", job.variants[i].name.c_str(),
                   w.c_str());
    if (progressLines)  // as toposlice batch's bar: on a terminal, not with --quiet
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
    std::vector<std::string> warnings;
    if (!decode(bytes, h, detail, warnings)) {
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
      o.warnings = std::move(warnings);
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
  // As toposlice batch: the table on stdout unless --quiet, one error line per failed variant on stderr.
  if (!options.quiet) {
    std::string suffix = "; " + std::to_string(size) + (size == 1 ? " rank" : " ranks") + " x " +
                         std::to_string(ThreadLimit::available()) + " threads";
    if (!setupErrors.empty()) {
      suffix += "; could not start:";
      for (const auto& e : setupErrors) suffix += " " + e;
    }
    printBatchSummary(stdout, job, tmpl, outcomes, total, true, suffix);
    std::fflush(stdout);
  }
  for (std::size_t i = 0; i < n; ++i)
    if (outcomes[i].status == "failed")
      std::fprintf(stderr, "toposlice-mpi: error: variant '%s' (%s): %s\n", job.variants[i].name.c_str(),
                   job.variants[i].model.c_str(), outcomes[i].detail.c_str());
  return broadcastInt(totals.failed > 0 ? 1 : 0);
}

// ---------------------------------------------------------------------------------------------------
// Plate jobs: plate p (0-based) is sliced by rank p mod N; rank 0 commits every rank's outputs.

// A plate message as bytes: plain values and length-prefixed strings, read back in the order written.
// All ranks run the same build (as for WireHeader).
class ByteWriter {
 public:
  template <class T>
  void put(const T& value) {
    static_assert(std::is_trivially_copyable_v<T>);
    const char* p = reinterpret_cast<const char*>(&value);
    bytes_.insert(bytes_.end(), p, p + sizeof value);
  }
  void putString(const std::string& text) {
    put<uint64_t>(text.size());
    bytes_.insert(bytes_.end(), text.begin(), text.end());
  }
  const std::vector<char>& bytes() const { return bytes_; }

 private:
  std::vector<char> bytes_;
};

class ByteReader {
 public:
  explicit ByteReader(const std::vector<char>& bytes) : bytes_(bytes) {}
  template <class T>
  T get() {
    static_assert(std::is_trivially_copyable_v<T>);
    T value{};
    if (sizeof value > bytes_.size() - at_) throw std::runtime_error("a plate message is truncated");
    std::memcpy(&value, bytes_.data() + at_, sizeof value);
    at_ += sizeof value;
    return value;
  }
  std::string getString() {
    const uint64_t n = get<uint64_t>();
    if (n > bytes_.size() - at_) throw std::runtime_error("a plate message is truncated");
    std::string text(bytes_.data() + at_, n);
    at_ += n;
    return text;
  }

 private:
  const std::vector<char>& bytes_;
  std::size_t at_ = 0;
};

int plateRank(uint32_t plate, int size) {
  return static_cast<int>(plate % static_cast<uint32_t>(size));
}

// What a rank's arrangement decided, as bytes: rank 0 compares every rank's with its own, bit for bit.
std::string placementBytes(const PlateResult& r) {
  ByteWriter w;
  w.put(r.plates);
  for (const PlatePartResult& p : r.parts)
    for (const double v :
         {static_cast<double>(p.plate), p.placement.x, p.placement.y, p.placement.rotation, p.tx, p.ty})
      w.put(v);
  return {w.bytes().begin(), w.bytes().end()};
}

// A plate a rank has sliced, and the temporaries it staged.
struct PlateDone {
  uint32_t plate = 0;
  std::vector<OutputTransaction::Staged> staged;
};

// What a worker sends when it has sliced its plates (or failed at `failedPlate`).
void putPlatesDone(ByteWriter& w, const PlateResult& r, const std::vector<PlateDone>& done,
                   int64_t failedPlate, const std::string& error) {
  w.put<int64_t>(failedPlate);
  w.putString(error);
  w.put<uint64_t>(done.size());
  for (const PlateDone& d : done) {
    w.put(d.plate);
    w.put(r.layers[d.plate]);
    w.put(r.volumeMl[d.plate]);
    for (const PlatePartResult& p : r.parts)
      if (p.plate == d.plate) {
        w.put(p.volumeMl);
        w.put(p.firstLayer);
        w.put(p.lastLayer);
      }
    w.put<uint64_t>(d.staged.size());
    for (const OutputTransaction::Staged& s : d.staged) {
      // The temporary as an absolute path (rank 0 may run in another folder); the final path as in the
      // job, which names the same file on every rank.
      w.putString(std::filesystem::absolute(s.temp).string());
      w.putString(s.final.string());
      w.put<int32_t>(s.overwrite ? 1 : 0);
      w.put<int32_t>(s.kind == OutputKind::LayerFolder ? 1 : 0);
      w.putString(s.layerExt);
    }
  }
}

// The final paths plate `plate` may write (report excluded: rank 0 writes it).
std::vector<std::filesystem::path> plateOutputs(const PlateJob& job, uint32_t plate) {
  std::vector<std::filesystem::path> paths;
  for (const auto* o : {&job.masks, &job.picture})
    if (!o->empty()) paths.push_back(plateOutputPath(*o, plate));
  for (const auto& c : job.contours) paths.push_back(plateOutputPath(c, plate));
  return paths;
}

// Rank 0 reads what worker `source` sent into `result` and `byPlate`; returns the failed plate (-1: none)
// and its error.
int64_t getPlatesDone(ByteReader& in, int source, int size, const PlateJob& job, PlateResult& result,
                      std::vector<std::vector<OutputTransaction::Staged>>& byPlate, std::string& error) {
  const int64_t failedPlate = in.get<int64_t>();
  error = in.getString();
  const uint64_t plates = in.get<uint64_t>();
  for (uint64_t i = 0; i < plates; ++i) {
    const uint32_t plate = in.get<uint32_t>();
    if (plate >= result.plates || plateRank(plate, size) != source)
      throw std::runtime_error("rank " + std::to_string(source) + " sent plate " + std::to_string(plate + 1) +
                               ", which is not its own");
    result.layers[plate] = in.get<uint32_t>();
    result.volumeMl[plate] = in.get<double>();
    for (PlatePartResult& p : result.parts)
      if (p.plate == plate) {
        p.volumeMl = in.get<double>();
        p.firstLayer = in.get<int64_t>();
        p.lastLayer = in.get<int64_t>();
      }
    const std::vector<std::filesystem::path> allowed = plateOutputs(job, plate);
    const uint64_t staged = in.get<uint64_t>();
    for (uint64_t k = 0; k < staged; ++k) {
      OutputTransaction::Staged s;
      s.temp = in.getString();
      s.final = in.getString();
      s.overwrite = in.get<int32_t>() != 0;
      s.kind = in.get<int32_t>() != 0 ? OutputKind::LayerFolder : OutputKind::File;
      s.layerExt = in.getString();
      if (std::find(allowed.begin(), allowed.end(), s.final) == allowed.end())
        throw std::runtime_error("rank " + std::to_string(source) + " wrote " + s.final.string() +
                                 ", which is no output of plate " + std::to_string(plate + 1));
      byPlate[plate].push_back(std::move(s));
    }
  }
  return failedPlate;
}

// Every rank: reads and arranges the whole job (the same placements everywhere, which rank 0 checks),
// slices its own plates into temporaries and sends rank 0 their numbers and temporaries. Rank 0 then
// stages every rank's temporaries in one transaction, plate by plate as `toposlice plate` does, adds the
// report and commits; the workers keep their temporaries until rank 0 says whether it committed them,
// and remove them if not. Every rank returns rank 0's status.
int runPlateRank(const Options& options, int rank, int size) {
  std::optional<PreparedPlateJob> prepared;
  std::optional<ThreadLimit> jobThreads;
  std::string error;
  try {
    PlateJob job = readPlateJob(options.job);
    jobThreads.emplace(job.threads);
    prepared.emplace(std::move(job));
  } catch (const std::exception& e) {
    error = e.what();
  }
  // 1. Everyone has prepared: rank 0 names the first problem and says whether to go on.
  int go = 0;
  if (rank != 0) {
    ByteWriter w;
    w.putString(error);
    w.putString(prepared ? placementBytes(prepared->result()) : std::string{});
    sendToRoot(w.bytes(), kTagPlate);
    go = broadcastInt(0);
  } else {
    if (!error.empty()) std::fprintf(stderr, "toposlice-mpi: error: %s\n", error.c_str());
    const std::string mine = prepared ? placementBytes(prepared->result()) : std::string{};
    bool ok = error.empty();
    for (int source = 1; source < size; ++source) {
      const std::vector<char> bytes = receiveFrom(source, kTagPlate);
      ByteReader in(bytes);
      std::string theirs, placements;
      try {
        theirs = in.getString();
        placements = in.getString();
      } catch (const std::exception& e) {
        theirs = e.what();
      }
      if (!theirs.empty()) {
        if (ok) std::fprintf(stderr, "toposlice-mpi: error: rank %d: %s\n", source, theirs.c_str());
        ok = false;
      } else if (ok && placements != mine) {
        std::fprintf(stderr,
                     "toposlice-mpi: error: rank %d arranged the parts differently from rank 0 (every rank "
                     "needs the same build and the same job files)\n",
                     source);
        ok = false;
      }
    }
    go = broadcastInt(ok ? 1 : 0);
  }
  if (!go) return broadcastInt(1);
  const auto sliceStart = std::chrono::steady_clock::now();

  // 2. Each rank slices its plates into temporaries of its own transaction (in the outputs' folders,
  // made where missing as `toposlice plate` makes them).
  PlateResult& result = prepared->result();
  const PlateJob& job = prepared->job();
  OutputTransaction mine;
  std::vector<PlateDone> done;
  int64_t failedPlate = -1;
  for (uint32_t plate = static_cast<uint32_t>(rank); plate < result.plates;
       plate += static_cast<uint32_t>(size)) {
    const std::size_t before = mine.staged().size();
    try {
      if (plate == static_cast<uint32_t>(rank)) makePlateOutputFolders(job, result.plates);
      prepared->slicePlate(plate, nullptr);
    } catch (const std::exception& e) {
      failedPlate = plate;
      error = e.what();
      break;
    }
    PlateDone d;
    d.plate = plate;
    d.staged.assign(mine.staged().begin() + static_cast<std::ptrdiff_t>(before), mine.staged().end());
    done.push_back(std::move(d));
  }
  if (rank != 0) {
    ByteWriter w;
    putPlatesDone(w, result, done, failedPlate, error);
    sendToRoot(w.bytes(), kTagPlate);
    const int status = broadcastInt(0);
    // Committed: rank 0 has renamed the temporaries, so they are no longer this rank's to remove.
    if (status == 0)
      for (const OutputTransaction::Staged& s : mine.release()) unregisterPendingOutput(s.registrySlot);
    return status;
  }

  // 3. Rank 0: every rank's plates, the first failure in plate order (the one `toposlice plate` would
  // have stopped at), or one transaction for all outputs.
  std::vector<std::vector<OutputTransaction::Staged>> byPlate(result.plates);
  int64_t firstFailed = failedPlate;
  std::string firstError = error;
  for (int source = 1; source < size; ++source) {
    const std::vector<char> bytes = receiveFrom(source, kTagPlate);
    std::string theirError;
    int64_t theirFailed = -1;
    try {
      ByteReader in(bytes);
      theirFailed = getPlatesDone(in, source, size, job, result, byPlate, theirError);
    } catch (const std::exception& e) {
      theirFailed = static_cast<int64_t>(result.plates);
      theirError = e.what();
    }
    if (theirFailed >= 0 && (firstFailed < 0 || theirFailed < firstFailed)) {
      firstFailed = theirFailed;
      firstError = theirError;
    }
  }
  int status = 0;
  if (firstFailed >= 0) {
    std::fprintf(stderr, "toposlice-mpi: error: %s\n", firstError.c_str());
    status = 1;
  } else {
    try {
      OutputTransaction all;
      std::vector<OutputTransaction::Staged> own = mine.release();
      std::size_t next = 0;
      for (uint32_t plate = 0; plate < result.plates; ++plate) {
        if (plateRank(plate, size) == 0) {
          const std::size_t count = done[plate / static_cast<uint32_t>(size)].staged.size();
          for (std::size_t k = 0; k < count; ++k) all.stage(std::move(own[next++]));
          continue;
        }
        for (OutputTransaction::Staged& s : byPlate[plate]) {
          s.registrySlot = registerPendingOutput(s.temp, s.kind == OutputKind::LayerFolder);
          all.stage(std::move(s));
        }
      }
      result.sliceSeconds =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - sliceStart).count();
      prepared->writeReport();
      all.commit();
      result.written = all.committed();
      warnAboutLaterPlates(job, result);
    } catch (const std::exception& e) {
      std::fprintf(stderr, "toposlice-mpi: error: %s\n", e.what());
      status = 1;
    }
  }
  if (status == 0)  // every rank prepared the same parts: rank 0 says their warnings, even with -q
    for (const auto& w : result.warnings) std::fprintf(stderr, "toposlice-mpi: warning: %s\n", w.c_str());
  if (status == 0 && !options.quiet) {
    printPlateSummary(stdout, result);
    std::printf("ranks: %d x %u threads;", size, ThreadLimit::available());
    for (uint32_t plate = 0; plate < result.plates; ++plate)
      std::printf(" plate %u on rank %d%s", plate + 1, plateRank(plate, size),
                  plate + 1 < result.plates ? "," : "\n");
    std::fflush(stdout);
  }
  return broadcastInt(status);
}

int run(int argc, char** argv) {
  int provided = MPI_THREAD_SINGLE;
  MPI_Init_thread(&argc, &argv, MPI_THREAD_FUNNELED, &provided);
  int rank = 0, size = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);

  CLI::App app{"toposlice-mpi: a toposlice batch or plate job spread over the ranks of an MPI job"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "toposlice-mpi 0.1.0");
  Options options;
  std::string jobPath;
  CLI::App* batch = app.add_subcommand("batch", "Slice every variant of a batch job on every rank");
  batch->add_option("job", jobPath, "Batch job (JSON, see docs/FORMATS.md)")->required();
  batch->add_option("--threads", options.threads, "Worker threads per rank (default: all cores)");
  batch->add_flag("-q,--quiet", options.quiet,
                  "No progress lines or summary; warnings and errors are still printed");
  batch->add_flag("--dispatch-only", options.dispatchOnly,
                  "Rank 0 hands out variants but slices none (with -np > 1)");
  CLI::App* plate = app.add_subcommand(
      "plate", "Slice the plates of a plate job on the ranks: plate n on rank (n - 1) mod N");
  plate->add_option("job", jobPath, "Plate job (JSON, see docs/FORMATS.md)")->required();
  plate->add_option("--threads", options.threads, "Worker threads per rank (default: all cores)");
  plate->add_flag("-q,--quiet", options.quiet, "No summary; warnings and errors are still printed");
  try {
    app.parse(argc, argv);
    // As toposlice's --threads and the job files' "threads".
    if (const std::string problem = threadCountProblem(options.threads); !problem.empty())
      throw CLI::ValidationError("--threads", problem);
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
  // A hang-up stops the job as SIGTERM does (ignored under nohup, it stays ignored).
  const bool hangUpIgnored = std::signal(SIGHUP, onSignal) == SIG_IGN;
  if (hangUpIgnored) std::signal(SIGHUP, SIG_IGN);
  // A file-size limit (ulimit -f) would kill the process with its temporaries in place; ignored, the
  // write fails with EFBIG instead and the job ends as on a full disk, leaving nothing behind.
  std::signal(SIGXFSZ, SIG_IGN);
  setOverwriteHint("set \"overwrite\": true in the job's settings to replace it",  // no --force here
                   "\"overwrite\": true");
  int status = 1;
  {
    ThreadLimit limit(options.threads);
    if (*plate) {
      status = runPlateRank(options, rank, size);
    } else if (rank == 0) {
      status = runDispatcher(options, size, provided);
    } else {
      if (broadcastInt(0) == 0) {
        status = broadcastInt(1);  // rank 0 could not read the job or its table: it said why
      } else {
        status = runWorker(options);
      }
    }
  }
  // Temporaries this rank could not remove as a variant or plate failed (their folder made read-only
  // under it): named, not left unsaid.
  for (const std::string& t : takeUnremovedTemporaries())
    std::fprintf(stderr, "toposlice-mpi: rank %d: the temporary %s; delete it by hand\n", rank, t.c_str());
  // Done, and no temporaries of ours live: a signal now is mpirun ending the ranks after one exited with
  // an error status (the job's failure, already said), not an interrupt to report.
  std::signal(SIGINT, SIG_DFL);
  std::signal(SIGTERM, SIG_DFL);
  std::signal(SIGHUP, hangUpIgnored ? SIG_IGN : SIG_DFL);
  MPI_Finalize();
  return status;
}

}  // namespace
}  // namespace toposlice

int main(int argc, char** argv) {
  toposlice::keepFreedMemory();
  return toposlice::run(argc, argv);
}
