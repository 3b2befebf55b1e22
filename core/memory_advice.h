#pragma once
// How toposlice asks the kernel and the C library for memory (Linux, glibc). Measured in
// docs/BENCHMARKS.md (thread scaling, "Session 19"): the aligner's contour job took 37 thousand page faults
// on one thread and 51 thousand on two, each a kernel entry and a 4 KiB page to zero, many of them in the
// serial read; with the advice below, 7 and 11-17 thousand.
#include <cstddef>

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

// For the programs' main(): the C library keeps up to 32 MiB of freed memory per heap for the next
// allocation instead of handing it back to the kernel and faulting it in again (bands free and allocate
// the same buffers layer after layer, on every thread), and serves blocks up to 32 MiB from its heaps.
// The peak is unchanged.
void keepFreedMemory() noexcept;

}  // namespace toposlice
