// Progress and cancellation, through one small context object checked once per chunk of work
// (a band of layers, a variant), never inside a kernel's inner loop.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>

namespace toposlice {

struct ProgressContext {
  // Called with (units done, units total) from one thread at a time, in increasing order of `done`.
  std::function<void(uint64_t, uint64_t)> report;
  // Set (e.g. by a signal handler) to ask long work to stop at the next chunk.
  const std::atomic<bool>* cancel = nullptr;

  bool cancelled() const { return cancel != nullptr && cancel->load(std::memory_order_relaxed); }
  void update(uint64_t done, uint64_t total) const {
    if (report) report(done, total);
  }
};

}  // namespace toposlice
