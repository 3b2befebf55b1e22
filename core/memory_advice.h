#pragma once
// How toposlice asks the kernel and the C library for memory (Linux, glibc). Measured in
// docs/BENCHMARKS.md (thread scaling, "Session 19"): the aligner's contour job took 37 thousand page faults
// on one thread and 51 thousand on two, each a kernel entry and a 4 KiB page to zero, many of them in the
// serial read; with the advice below, 7 and 11-17 thousand.
#include <cstddef>
#include <memory>
#include <type_traits>

#include "core/chunk_runner.h"

namespace toposlice {

// Backs the whole 2 MiB pages inside [data, data + bytes) with transparent huge pages where the kernel
// allows them (its `enabled` setting `always` or `madvise`): one fault per 2 MiB instead of one per
// 4 KiB when the memory is first written. Call it on big arrays before their first write; smaller spans,
// memory already written and a kernel without huge pages are left as they are. Never fails.
void adviseHugePages(void* data, std::size_t bytes) noexcept;

// v.reserve(n), then the advice above on the new storage (for a vector still empty, or growing).
template <class Vector>
void reserveHugePages(Vector& v, std::size_t n) {
  v.reserve(n);
  adviseHugePages(v.data(), v.capacity() * sizeof(typename Vector::value_type));
}

// Faults the pages of [data, data + bytes) in for writing, 2 MiB at a time on every thread of the runner
// (MADV_POPULATE_WRITE; the contents are unchanged), so that a later pass on one thread writes memory
// that is already there instead of taking every page fault and the kernel's zeroing itself. Advice
// only: a kernel without it (before Linux 5.14) leaves the pages to be faulted in as they are written.
void prefaultInParallel(void* data, std::size_t bytes, const ChunkRunner& runner) noexcept;

// v.resize(n) for a vector whose elements a parallel kernel then writes: reserved with the huge-page
// advice and, with a parallel runner, its new storage faulted in on every thread before the resize's
// own pass on the calling thread (docs/BENCHMARKS.md, thread scaling, "Session 26").
template <class Vector>
void resizeFaultedIn(Vector& v, std::size_t n, const ChunkRunner& runner) {
  const std::size_t size = v.size();
  reserveHugePages(v, n);
  if (runner.width > 1 && n > size)
    prefaultInParallel(v.data() + size, (n - size) * sizeof(typename Vector::value_type), runner);
  v.resize(n);
}

// An array of n trivially constructible T, not written here (no zeroing pass on the calling thread), with
// the advice above: for a kernel whose parallel pieces write every element before anything reads it, so
// that the pages are faulted in and zeroed by those pieces, on every thread (docs/BENCHMARKS.md, thread
// scaling, "Session 26").
template <class T>
std::unique_ptr<T[]> uninitializedArray(std::size_t n) {
  static_assert(std::is_trivially_default_constructible_v<T>);
  std::unique_ptr<T[]> array = std::make_unique_for_overwrite<T[]>(n);
  adviseHugePages(array.get(), n * sizeof(T));
  return array;
}

// For the programs' main(): the C library keeps up to 32 MiB of freed memory per heap for the next
// allocation instead of handing it back to the kernel and faulting it in again (bands free and allocate
// the same buffers layer after layer, on every thread), and serves blocks up to 32 MiB from its heaps.
// The peak is unchanged.
void keepFreedMemory() noexcept;

}  // namespace toposlice
