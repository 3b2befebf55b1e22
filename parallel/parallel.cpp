#include "parallel/parallel.h"

#include <tbb/blocked_range.h>
#include <tbb/concurrent_queue.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_pipeline.h>
#include <tbb/task_group.h>

#include <atomic>
#include <cstdint>
#include <exception>
#include <optional>
#include <utility>
#include <vector>

#if defined(__SANITIZE_THREAD__)
#define TOPOSLICE_TSAN 1
#elif defined(__has_feature)
#if __has_feature(thread_sanitizer)
#define TOPOSLICE_TSAN 1
#endif
#endif
#ifdef TOPOSLICE_TSAN
#include <sanitizer/tsan_interface.h>
#endif

namespace toposlice {

struct ThreadLimit::Impl {
  std::optional<tbb::global_control> control;
};

ThreadLimit::ThreadLimit(unsigned threads) : impl_(std::make_unique<Impl>()) {
  if (threads > 0) impl_->control.emplace(tbb::global_control::max_allowed_parallelism, threads);
}

ThreadLimit::~ThreadLimit() = default;

unsigned ThreadLimit::available() {
  return static_cast<unsigned>(
      tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
}

// oneTBB synchronises its workers inside libtbb, which is not built with ThreadSanitizer, so TSan cannot
// see those happens-before edges. The release/acquire pairs below state the same edges in code TSan
// sees (caller -> task start, task end -> caller, work(i) -> consume(i) -> the slot's next work); they
// cost one atomic operation per chunk and change nothing else.
class SchedulerEdges {
 public:
  SchedulerEdges() { count_.store(1, std::memory_order_release); }  // the caller's work so far -> tasks
  void taskStarts() const { (void)count_.load(std::memory_order_acquire); }
  void taskEnds() { count_.fetch_add(1, std::memory_order_release); }
  void joined() const { (void)count_.load(std::memory_order_acquire); }  // every task -> the caller

 private:
  std::atomic<std::size_t> count_{0};
};

// A task's last step comes after taskEnds(): oneTBB's header code, compiled into our objects and so seen
// by TSan, counts down the call's wait context with a release, and the caller's wait acquires it inside
// libtbb, unseen. parallel_for and parallel_invoke keep that context on the caller's stack. So when the
// caller later reuses that stack while the worker has gone on to long work that no edge orders before the
// caller (a BackgroundTask drawing previews), and TSan's history of the worker has lost the countdown,
// TSan reports a race with "failed to restore the stack", which the libtbb suppression cannot match
// (tests/tsan_stack_reuse.cpp). acquireReturnedCallStack() repeats the acquire where TSan sees it, on
// every word of the stack the returned call may have used; TSan looks its sync objects up by address and
// touches no memory. (A BackgroundTask's context lives in its task group, whose destructor loads it in
// header code: TSan sees that one.) Other builds get an empty function.
namespace {
#ifdef TOPOSLICE_TSAN
void acquireWords(std::uintptr_t begin, std::uintptr_t end) {
  for (std::uintptr_t a = begin & ~std::uintptr_t{7}; a < end; a += 8)
    __tsan_acquire(reinterpret_cast<void*>(a));  // NOLINT(performance-no-int-to-ptr)
}

// Called right after the parallel call returns: the call's frames lay below this one's, or in the
// caller's own frame just above it when the compiler inlined oneTBB's entry.
[[gnu::noinline]] void acquireReturnedCallStack() {
  constexpr std::uintptr_t kBelow = 16 * 1024, kAbove = 4 * 1024;
  const auto frame = reinterpret_cast<std::uintptr_t>(__builtin_frame_address(0));
  acquireWords(frame - kBelow, frame + kAbove);
}
#else
void acquireReturnedCallStack() {}
#endif
}  // namespace

void parallelForChunks(std::size_t count, std::size_t grain,
                       const std::function<void(std::size_t, std::size_t)>& body) {
  if (count == 0) return;
  SchedulerEdges edges;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, grain > 0 ? grain : 1),
                    [&](const tbb::blocked_range<std::size_t>& r) {
                      edges.taskStarts();
                      body(r.begin(), r.end());
                      edges.taskEnds();
                    });
  edges.joined();
  acquireReturnedCallStack();
}

ChunkRunner parallelChunkRunner() {
  return ChunkRunner{[](std::size_t count, std::size_t grain, const ChunkBody& body) {
                       parallelForChunks(count, grain, body);
                     },
                     ThreadLimit::available()};
}

void parallelInvoke(const std::function<void()>& a, const std::function<void()>& b) {
  std::exception_ptr errorA, errorB;
  SchedulerEdges edges;
  const auto task = [&edges](const std::function<void()>& f, std::exception_ptr& error) {
    edges.taskStarts();
    try {
      f();
    } catch (...) {
      error = std::current_exception();
    }
    edges.taskEnds();
  };
  tbb::parallel_invoke([&] { task(a, errorA); }, [&] { task(b, errorB); });
  edges.joined();
  acquireReturnedCallStack();
  if (errorA) std::rethrow_exception(errorA);
  if (errorB) std::rethrow_exception(errorB);
}

struct BackgroundTask::Impl {
  std::function<void()> work;
  std::exception_ptr error;
  SchedulerEdges edges;
  tbb::task_group group;
  std::atomic<bool> finished{false};
  bool waited = false;
};

BackgroundTask::BackgroundTask(std::function<void()> work) : impl_(std::make_unique<Impl>()) {
  impl_->work = std::move(work);
  Impl& t = *impl_;
  t.group.run([&t] {
    t.edges.taskStarts();
    try {
      t.work();
    } catch (...) {
      t.error = std::current_exception();
    }
    t.edges.taskEnds();
    t.finished.store(true, std::memory_order_release);
  });
}

BackgroundTask::~BackgroundTask() {
  if (!impl_->waited) impl_->group.wait();
}

bool BackgroundTask::done() const {
  return impl_->waited || impl_->finished.load(std::memory_order_acquire);
}

void BackgroundTask::wait() {
  if (impl_->waited) return;
  impl_->group.wait();
  impl_->waited = true;
  impl_->edges.joined();
  if (impl_->error) std::rethrow_exception(std::exchange(impl_->error, nullptr));
}

void orderedPipeline(std::size_t count, std::size_t inFlight,
                     const std::function<void(std::size_t, std::size_t)>& work,
                     const std::function<void(std::size_t, std::size_t)>& consume) {
  if (count == 0) return;
  if (inFlight == 0) inFlight = 1;
  tbb::concurrent_bounded_queue<std::size_t> freeSlots;
  for (std::size_t s = 0; s < inFlight; ++s) freeSlots.push(s);
  std::vector<std::atomic<uint32_t>> slotSync(inFlight);  // happens-before edges for TSan, see above
  for (auto& a : slotSync) a.store(0, std::memory_order_release);
  std::atomic<uint32_t> consumeSync{0};
  struct Token {
    std::size_t task, slot;
  };
  std::size_t next = 0;
  tbb::parallel_pipeline(
      inFlight,
      tbb::make_filter<void, Token>(tbb::filter_mode::serial_in_order, [&](tbb::flow_control& fc) -> Token {
        if (next == count) {
          fc.stop();
          return {};
        }
        std::size_t slot = 0;
        freeSlots.pop(slot);  // never blocks: tokens <= slots
        return {next++, slot};
      }) & tbb::make_filter<Token, Token>(tbb::filter_mode::parallel, [&](Token t) {
        (void)slotSync[t.slot].load(std::memory_order_acquire);
        work(t.task, t.slot);
        slotSync[t.slot].fetch_add(1, std::memory_order_release);
        return t;
      }) & tbb::make_filter<Token, void>(tbb::filter_mode::serial_in_order, [&](Token t) {
        (void)slotSync[t.slot].load(std::memory_order_acquire);
        (void)consumeSync.load(std::memory_order_acquire);
        consume(t.task, t.slot);
        consumeSync.fetch_add(1, std::memory_order_release);
        slotSync[t.slot].fetch_add(1, std::memory_order_release);
        freeSlots.push(t.slot);
      }));
  (void)consumeSync.load(std::memory_order_acquire);
}

}  // namespace toposlice
