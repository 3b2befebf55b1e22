// How a core kernel that can split its work runs the pieces. core/ stays plain serial C++: a kernel
// takes a ChunkRunner and calls it with a body over an index range; the default runs the chunks one
// after another, and parallel/parallel.h's parallelChunkRunner() runs them on every core. A body writes
// only what its chunk owns, so the result never depends on which runner ran it.
#pragma once

#include <cstddef>
#include <functional>
#include <span>
#include <string>
#include <vector>

namespace toposlice {

using ChunkBody = std::function<void(std::size_t begin, std::size_t end)>;

// The most worker threads a job may ask for (--threads, a job file's "threads"; 0 means all cores): a
// count beyond any machine is a typing mistake.
inline constexpr unsigned kMaxThreads = 4096;

// What is wrong with a thread count a command line gives, as the job files say it; "" when nothing is.
inline std::string threadCountProblem(unsigned threads) {
  if (threads <= kMaxThreads) return "";
  return "must be between 0 (all cores) and " + std::to_string(kMaxThreads) + ", got " +
         std::to_string(threads);
}

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

// Filing items by part, chunk by chunk, so that each part later reads only its own (the split weld and
// adjacency): counts[c * parts + p] holds how many items chunk c files into part p. Turns each count into
// the position where chunk c writes its first such item, in one array of part after part (each part's
// items in chunk order), and returns where each part begins (parts + 1 entries, the last the total). A
// chunk then writes its items at counts[c * parts + p]++, sharing no word with another chunk.
template <class Count>
std::vector<std::size_t> filePositions(std::span<Count> counts, std::size_t chunks, std::size_t parts) {
  std::vector<std::size_t> partBegin(parts + 1, 0);
  std::size_t at = 0;
  for (std::size_t p = 0; p < parts; ++p) {
    partBegin[p] = at;
    for (std::size_t c = 0; c < chunks; ++c) {
      const std::size_t count = counts[c * parts + p];
      counts[c * parts + p] = static_cast<Count>(at);
      at += count;
    }
  }
  partBegin[parts] = at;
  return partBegin;
}

}  // namespace toposlice
