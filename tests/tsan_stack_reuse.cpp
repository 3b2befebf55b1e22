// ThreadSanitizer check of parallel/parallel.cpp's scheduler edges, registered only in TSan builds and
// run with history_size=0 (tests/CMakeLists.txt), so that a worker's accesses leave its history soon.
//
// A oneTBB worker's last step of a parallel call counts down the wait context that oneTBB keeps on the
// caller's stack, and TSan sees no acquire of it afterwards. When the worker then runs a long
// BackgroundTask and the caller reuses that stack, TSan cannot restore the worker's stack to match the
// libtbb suppression and reports a race: the failure CI met once in
// CliToolDeterminism.PrinterFilesWithPreviewsDrawnBesideTheLayersAreTheOneThreadFiles. The scenario named
// by the argument makes a worker end the call, keeps it busy, and has the caller reuse the stack; the
// program exits non-zero (halt_on_error) on any report.
#include "parallel/parallel.h"

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <thread>
#include <vector>

namespace {

using namespace std::chrono_literals;
using toposlice::BackgroundTask;

const std::thread::id kMainThread = std::this_thread::get_id();

// The body of a parallel call whose last task ends on a worker: the caller's tasks wait until a worker
// has begun one, which then sleeps well past them. The flag is relaxed, so TSan sees no synchronisation
// through it.
std::atomic<bool> workerBegan{false};

void finishLastOnAWorker() {
  if (std::this_thread::get_id() != kMainThread) {
    workerBegan.store(true, std::memory_order_relaxed);
    std::this_thread::sleep_for(100ms);
    return;
  }
  for (int i = 0; i < 10000 && !workerBegan.load(std::memory_order_relaxed); ++i)
    std::this_thread::sleep_for(1ms);
  if (!workerBegan.load(std::memory_order_relaxed)) {
    std::puts("no worker took a task in 10 s: the check cannot run");
    std::exit(1);
  }
}

// A BackgroundTask that makes millions of accesses, far past a worker's history at history_size=0, and
// then waits until released. Its flags are relaxed: TSan sees no synchronisation through them, so nothing
// the worker did before can be ordered before the caller's accesses by this helper.
class BusyWorker {
 public:
  BusyWorker()
      : task_([this] {
          std::vector<long> values(1 << 16);
          for (int round = 0; round < 200; ++round)
            for (auto& v : values) v += round;
          if (values[7] == 42) std::puts("unreachable");
          busy_.store(true, std::memory_order_relaxed);
          while (!released_.load(std::memory_order_relaxed)) std::this_thread::sleep_for(1ms);
        }) {
    while (!busy_.load(std::memory_order_relaxed)) std::this_thread::sleep_for(5ms);
  }
  ~BusyWorker() {
    released_.store(true, std::memory_order_relaxed);
    task_.wait();
  }
  BusyWorker(const BusyWorker&) = delete;
  BusyWorker& operator=(const BusyWorker&) = delete;

 private:
  std::atomic<bool> busy_{false}, released_{false};
  BackgroundTask task_;
};

// Runs the call 32 KiB down this thread's stack, below where starting the BusyWorker writes.
template <typename Call>
[[gnu::noinline]] void callDeep(const Call& call) {
  char pad[32 * 1024];
  asm volatile("" : : "r"(pad) : "memory");
  call();
  asm volatile("" : : "r"(pad) : "memory");
}

// Writes 64 KiB of this thread's stack below the caller: over where the deep call's frames, and its
// wait context, were. The array's address escapes (the empty asm), or TSan would not check a local
// that no other thread can see.
[[gnu::noinline]] void reuseStack() {
  long slots[8 * 1024];
  asm volatile("" : : "r"(slots) : "memory");
  for (int i = 0; i < 8 * 1024; ++i) slots[i] = i;
  asm volatile("" : : "r"(slots) : "memory");
}

// The caller reuses the stack while a worker, after ending the parallel call, runs a long task.
template <typename Call>
void stackReuse(const Call& call) {
  callDeep(call);
  const BusyWorker busy;
  reuseStack();
}

}  // namespace

int main(int argc, char** argv) {
  const std::string scenario = argc == 2 ? argv[1] : "";
  if (toposlice::ThreadLimit::available() < 2) {  // no worker to end a call or to keep busy
    std::puts("one thread only: skipped");
    return 77;
  }
  if (scenario == "parallelForChunks")
    stackReuse(
        [] { toposlice::parallelForChunks(2, 1, [](std::size_t, std::size_t) { finishLastOnAWorker(); }); });
  else if (scenario == "parallelInvoke")
    stackReuse([] { toposlice::parallelInvoke(finishLastOnAWorker, finishLastOnAWorker); });
  else {
    std::puts("usage: tsan_stack_reuse parallelForChunks|parallelInvoke");
    return 2;
  }
  std::printf("%s: no report\n", scenario.c_str());
  return 0;
}
