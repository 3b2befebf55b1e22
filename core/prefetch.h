// A hint to fetch the cache line holding `p`; no effect where the compiler has no such builtin.
#pragma once

namespace toposlice {

inline void prefetch(const void* p) {
#if defined(__GNUC__)
  __builtin_prefetch(p);
#else
  (void)p;
#endif
}

}  // namespace toposlice
