#include "core/memory_advice.h"

#include <malloc.h>
#include <sys/mman.h>

#include <algorithm>
#include <cstdint>

namespace toposlice {

void adviseHugePages(void* data, std::size_t bytes) noexcept {
  constexpr std::uintptr_t kHuge = std::uintptr_t{2} << 20;
  const auto begin = reinterpret_cast<std::uintptr_t>(data);
  const std::uintptr_t first = (begin + kHuge - 1) & ~(kHuge - 1), end = (begin + bytes) & ~(kHuge - 1);
  if (bytes < kHuge || end <= first) return;
  // Advice only: EINVAL where the kernel has no transparent huge pages changes nothing.
  (void)madvise(reinterpret_cast<void*>(first), end - first, MADV_HUGEPAGE);
}

void prefaultInParallel(void* data, std::size_t bytes, const ChunkRunner& runner) noexcept {
  if (bytes == 0) return;
  constexpr std::uintptr_t kPage = 4096, kPiece = std::uintptr_t{2} << 20;
  const auto first = reinterpret_cast<std::uintptr_t>(data) & ~(kPage - 1);
  const std::uintptr_t end = (reinterpret_cast<std::uintptr_t>(data) + bytes + kPage - 1) & ~(kPage - 1);
  // Pieces on 2 MiB boundaries, so that no huge page is faulted from two threads at once.
  const std::uintptr_t base = first & ~(kPiece - 1);
  const std::size_t pieces = (end - base + kPiece - 1) / kPiece;
  try {
    runner.run(pieces, 1, [&](std::size_t p0, std::size_t p1) {
      const std::uintptr_t from = std::max(first, base + p0 * kPiece), to = std::min(end, base + p1 * kPiece);
      // EINVAL (an older kernel) or ENOMEM leave the pages to be faulted in as they are written.
      (void)madvise(reinterpret_cast<void*>(from), to - from, MADV_POPULATE_WRITE);
    });
  } catch (...) {  // the runner could not start its tasks: the advice is skipped
  }
}

void keepFreedMemory() noexcept {
  // Setting either turns off glibc's own adjustment of the mmap threshold, which otherwise follows the
  // largest block freed and keeps the 4-40 MiB arrays of one job moving between mmap and the heaps.
  (void)mallopt(M_MMAP_THRESHOLD, 32 << 20);  // glibc's largest allowed on 64-bit (HEAP_MAX_SIZE / 2)
  // Up to 32 MiB free at the top of each heap stay with the process: enough to keep the bands' buffers
  // (1 GiB faulted no less on the aligner), and a bound on what each thread's heap holds unused.
  (void)mallopt(M_TRIM_THRESHOLD, 32 << 20);
}

}  // namespace toposlice
