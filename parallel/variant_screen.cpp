#include "parallel/variant_screen.h"

#include <atomic>

#include "parallel/parallel.h"

namespace toposlice {

std::optional<VariantMismatch> checkVariantConnectivityParallel(std::span<const Point3f> corners,
                                                                std::span<const int32_t> adjacency) {
  std::atomic<bool> mayFail{corners.size() != adjacency.size()};
  if (!mayFail) {
    parallelForChunks(adjacency.size() / 3, 65536, [&](std::size_t begin, std::size_t end) {
      if (variantMayMismatch(corners, adjacency, begin, end)) mayFail.store(true, std::memory_order_relaxed);
    });
  }
  if (!mayFail) return checkOpenEdges(corners, adjacency);
  return checkVariantConnectivity(corners, adjacency);
}

}  // namespace toposlice
