// parallel/parallel.h's BackgroundTask: the work runs (on a free thread, or on the thread that waits),
// its exception reaches the waiter once, and a task may wait for it from inside other parallel work.
#include <gtest/gtest.h>

#include <atomic>
#include <stdexcept>
#include <thread>
#include <vector>

#include "parallel/band_slicer.h"
#include "parallel/parallel.h"

namespace toposlice {
namespace {

// A band holds at most the job's layers: --band-layers 100000000 on a 20-layer job sized its storage by
// the option (3.4 GB, then an out-of-memory kill at 10^8).
TEST(BandPlan, ABandNeverHoldsMoreLayersThanTheJob) {
  SliceSettings settings;
  for (const uint32_t given : {100000000u, 21u, 20u}) {
    settings.bandLayers = given;
    const BandPlan plan = planBands(20, settings);
    EXPECT_EQ(plan.bandLayers, 20u) << given;
    EXPECT_EQ(plan.slots, 1u) << given;
  }
  settings.bandLayers = 7;
  EXPECT_EQ(planBands(20, settings).bandLayers, 7u);
  settings.bandLayers = 5;
  EXPECT_EQ(planBands(0, settings).bandLayers, 1u);
}

TEST(BackgroundTask, RunsTheWorkOnAnyThreadCount) {
  for (const unsigned threads : {1u, 2u, 4u}) {
    ThreadLimit limit(threads);
    std::vector<int> squares(1000);
    BackgroundTask task([&] {
      parallelForChunks(squares.size(), 10, [&](std::size_t b, std::size_t e) {
        for (std::size_t i = b; i < e; ++i) squares[i] = static_cast<int>(i * i);
      });
    });
    task.wait();
    for (std::size_t i = 0; i < squares.size(); ++i)
      ASSERT_EQ(squares[i], static_cast<int>(i * i)) << threads;
    task.wait();  // a second wait returns at once
  }
}

TEST(BackgroundTask, RethrowsItsExceptionOnceAndTheDestructorWaits) {
  BackgroundTask failing([] { throw std::runtime_error("drawn badly"); });
  EXPECT_THROW(failing.wait(), std::runtime_error);
  EXPECT_NO_THROW(failing.wait());
  std::atomic<bool> done{false};
  {
    BackgroundTask unwaited([&] { done = true; });
  }
  EXPECT_TRUE(done);
  {
    BackgroundTask dropped([] { throw std::runtime_error("never waited for"); });
  }  // no throw
}

// done() never blocks nor runs the work; it turns true once the work has ended, and after wait().
TEST(BackgroundTask, DoneTellsWithoutWaiting) {
  for (const unsigned threads : {1u, 2u}) {
    ThreadLimit limit(threads);
    std::atomic<bool> release{false};
    BackgroundTask task([&] {
      while (!release.load()) std::this_thread::yield();
    });
    EXPECT_FALSE(task.done()) << threads;  // the work cannot end before it is released
    release = true;
    if (threads > 1)
      while (!task.done()) std::this_thread::yield();  // a free thread runs it and it ends
    task.wait();
    EXPECT_TRUE(task.done()) << threads;
  }
}

// A pipeline's in-order stage waits for the task (as the slice job's first layer waits for the SL1
// thumbnails) while the other chunks keep the threads busy: it completes on one thread and on several.
TEST(BackgroundTask, CanBeWaitedForFromInsideParallelWork) {
  for (const unsigned threads : {1u, 2u, 3u}) {
    ThreadLimit limit(threads);
    std::atomic<int> drawn{0};
    BackgroundTask task([&] {
      parallelForChunks(64, 1, [&](std::size_t b, std::size_t e) { drawn += static_cast<int>(e - b); });
    });
    std::vector<int> seen;
    orderedPipeline(
        32, 4, [](std::size_t, std::size_t) {},
        [&](std::size_t i, std::size_t) {
          if (i == 0) task.wait();
          seen.push_back(drawn.load());
        });
    ASSERT_EQ(seen.size(), 32u);
    EXPECT_EQ(seen.front(), 64) << threads;
  }
}

}  // namespace
}  // namespace toposlice
