// The thin parallel layer: the only place the rest of toposlice reaches oneTBB through. core/ stays
// serial; callers express parallel work as a for-each over an index range or an ordered pipeline.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>

#include "core/chunk_runner.h"

namespace toposlice {

// Limits the worker threads for the lifetime of the object (0 = all cores). One per process run.
class ThreadLimit {
 public:
  explicit ThreadLimit(unsigned threads);
  ~ThreadLimit();
  ThreadLimit(const ThreadLimit&) = delete;
  ThreadLimit& operator=(const ThreadLimit&) = delete;
  static unsigned available();  // threads the current limit allows

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Calls body(begin, end) on disjoint chunks covering [0, count), in parallel; chunks hold about
// `grain` indices. The body must write only slots it owns.
void parallelForChunks(std::size_t count, std::size_t grain,
                       const std::function<void(std::size_t, std::size_t)>& body);

// A runner for core kernels that split their work (core/chunk_runner.h): chunks on every thread the
// current limit allows (width 1, the serial form, when that is one thread).
ChunkRunner parallelChunkRunner();

// Runs a() and b() at the same time when a second thread is free, and returns when both are done. When
// either throws, the exception of a() is rethrown if it threw, else b()'s: the same error whatever the
// timing.
void parallelInvoke(const std::function<void()>& a, const std::function<void()>& b);

// Runs `work` as a task beside what the caller does next: a free thread takes it, or the thread that
// waits runs it then. wait() returns once it is done and rethrows what it threw (once); the destructor
// waits too and drops any exception. A waiting thread runs other tasks meanwhile, so a pipeline stage
// may wait for it.
class BackgroundTask {
 public:
  explicit BackgroundTask(std::function<void()> work);
  ~BackgroundTask();
  BackgroundTask(const BackgroundTask&) = delete;
  BackgroundTask& operator=(const BackgroundTask&) = delete;
  void wait();
  // Whether the work has finished (then wait() returns at once). Never blocks and never runs the work:
  // a caller that has other things to do asks this first and waits only when it must.
  bool done() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// An ordered bounded pipeline over tasks 0..count-1: work(i, slot) runs in parallel on at most
// `inFlight` tasks at once, each given a slot index in [0, inFlight) that no other running task holds
// (for per-slot buffers); then consume(i, slot) runs serially, in ascending i. Memory stays bounded by
// the slots whatever the task count.
void orderedPipeline(std::size_t count, std::size_t inFlight,
                     const std::function<void(std::size_t, std::size_t)>& work,
                     const std::function<void(std::size_t, std::size_t)>& consume);

}  // namespace toposlice
