// How a core kernel that can split its work runs the pieces. core/ stays plain serial C++: a kernel
// takes a ChunkRunner and calls it with a body over an index range; the default runs the chunks one
// after another, and parallel/parallel.h's parallelChunkRunner() runs them on every core. A body writes
// only what its chunk owns, so the result never depends on which runner ran it.
#pragma once

#include <cstddef>
#include <functional>

namespace toposlice {

using ChunkBody = std::function<void(std::size_t begin, std::size_t end)>;

struct ChunkRunner {
  // Calls body(begin, end) on disjoint chunks covering [0, count), each about `grain` indices long.
  std::function<void(std::size_t count, std::size_t grain, const ChunkBody& body)> run;
  // How many chunks can run at once (1: serial). Kernels pick their serial form when it is 1.
  unsigned width = 1;
};

// The serial runner: one call over the whole range.
inline const ChunkRunner& serialChunkRunner() {
  static const ChunkRunner runner{[](std::size_t count, std::size_t, const ChunkBody& body) {
                                    if (count > 0) body(0, count);
                                  },
                                  1};
  return runner;
}

}  // namespace toposlice
