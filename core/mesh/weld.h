// Welding: facet corners with bit-identical float coordinates become one vertex (-0.0 equals +0.0).
// No tolerance: STL writers emit shared corners with identical bits, and a tolerance would merge
// distinct features of fine models. Vertices are numbered in order of first appearance, so the result
// depends only on the soup. Expected linear time (open-addressing hash on the coordinate bits).
// With a parallel runner (core/chunk_runner.h) large soups are welded in parallel: corners are
// partitioned by hash, each partition finds first occurrences, and a prefix sum numbers them, so the
// result is the same, bit for bit, for any runner and thread count.
#pragma once

#include <bit>
#include <compare>
#include <cstdint>
#include <span>
#include <vector>

#include "core/chunk_runner.h"
#include "core/mesh/mesh.h"

namespace toposlice {

// A corner's coordinate bits under the welding rule: -0.0f + 0.0f is +0.0f, so both zeros give one key.
// Equal keys are one vertex.
struct WeldKey {
  uint32_t x, y, z;
  auto operator<=>(const WeldKey&) const = default;
};
inline WeldKey weldKey(const Point3f& p) {
  return {std::bit_cast<uint32_t>(p.x + 0.0f), std::bit_cast<uint32_t>(p.y + 0.0f),
          std::bit_cast<uint32_t>(p.z + 0.0f)};
}

IndexedMesh weldCorners(std::span<const Point3f> corners, const ChunkRunner& runner = serialChunkRunner());

// The serial weld fed a piece at a time, in corner order (a reader welds corners as they arrive): the
// result is weldCorners' for all the pieces joined, bit for bit (weldCorners' serial form is this).
class IncrementalWeld {
 public:
  explicit IncrementalWeld(std::size_t expectedCorners);
  void add(std::span<const Point3f> corners);
  IndexedMesh take() { return std::move(mesh_); }

 private:
  using Key = WeldKey;
  IndexedMesh mesh_;
  std::vector<uint32_t> table_;  // per slot a vertex number, or empty
  std::vector<Key> keys_;        // per vertex its coordinate bits
  uint64_t mask_ = 0;
};

}  // namespace toposlice
