#include "parallel/parallel.h"

#include <tbb/blocked_range.h>
#include <tbb/concurrent_queue.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_pipeline.h>

#include <optional>

namespace toposlice {

struct ThreadLimit::Impl {
  std::optional<tbb::global_control> control;
};

ThreadLimit::ThreadLimit(unsigned threads) : impl_(std::make_unique<Impl>()) {
  if (threads > 0) impl_->control.emplace(tbb::global_control::max_allowed_parallelism, threads);
}

ThreadLimit::~ThreadLimit() = default;

unsigned ThreadLimit::available() {
  return static_cast<unsigned>(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
}

void parallelForChunks(std::size_t count, std::size_t grain,
                       const std::function<void(std::size_t, std::size_t)>& body) {
  if (count == 0) return;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, grain > 0 ? grain : 1),
                    [&](const tbb::blocked_range<std::size_t>& r) { body(r.begin(), r.end()); });
}

void orderedPipeline(std::size_t count, std::size_t inFlight, const std::function<void(std::size_t, std::size_t)>& work,
                     const std::function<void(std::size_t, std::size_t)>& consume) {
  if (count == 0) return;
  if (inFlight == 0) inFlight = 1;
  tbb::concurrent_bounded_queue<std::size_t> freeSlots;
  for (std::size_t s = 0; s < inFlight; ++s) freeSlots.push(s);
  struct Token {
    std::size_t task, slot;
  };
  std::size_t next = 0;
  tbb::parallel_pipeline(
      inFlight,
      tbb::make_filter<void, Token>(tbb::filter_mode::serial_in_order,
                                    [&](tbb::flow_control& fc) -> Token {
                                      if (next == count) {
                                        fc.stop();
                                        return {};
                                      }
                                      std::size_t slot = 0;
                                      freeSlots.pop(slot);  // never blocks: tokens <= slots
                                      return {next++, slot};
                                    }) &
          tbb::make_filter<Token, Token>(tbb::filter_mode::parallel,
                                         [&](Token t) {
                                           work(t.task, t.slot);
                                           return t;
                                         }) &
          tbb::make_filter<Token, void>(tbb::filter_mode::serial_in_order, [&](Token t) {
            consume(t.task, t.slot);
            freeSlots.push(t.slot);
          }));
}

}  // namespace toposlice
