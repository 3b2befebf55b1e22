#include "core/mesh/weld.h"

#include <bit>
#include <cstring>

namespace toposlice {
namespace {

struct CornerKey {
  uint32_t x, y, z;
};

// -0.0f + 0.0f is +0.0f, so both zeros hash and compare alike.
inline CornerKey keyOf(const Point3f& p) {
  return {std::bit_cast<uint32_t>(p.x + 0.0f), std::bit_cast<uint32_t>(p.y + 0.0f),
          std::bit_cast<uint32_t>(p.z + 0.0f)};
}

inline uint64_t hashKey(const CornerKey& k) {
  uint64_t h = (uint64_t{k.x} << 32 | k.y) * 0x9E3779B97F4A7C15ull;
  h ^= (uint64_t{k.z} + 0x632BE59BD9B4E019ull) * 0xC2B2AE3D27D4EB4Full;
  return h ^ (h >> 29);
}

}  // namespace

IndexedMesh weldCorners(std::span<const Point3f> corners) {
  IndexedMesh mesh;
  mesh.facetVertices.resize(corners.size());
  std::size_t capacity = 16;
  while (capacity < corners.size() * 2) capacity <<= 1;  // load factor <= 1/2 even with no sharing
  const uint64_t mask = capacity - 1;
  constexpr uint32_t kEmpty = 0xFFFFFFFFu;
  std::vector<uint32_t> table(capacity, kEmpty);
  std::vector<CornerKey> keys;
  keys.reserve(corners.size() / 4 + 16);
  mesh.vertices.reserve(corners.size() / 4 + 16);
  for (std::size_t c = 0; c < corners.size(); ++c) {
    const CornerKey key = keyOf(corners[c]);
    uint64_t slot = hashKey(key) & mask;
    for (;;) {
      const uint32_t v = table[slot];
      if (v == kEmpty) {
        const auto index = static_cast<uint32_t>(mesh.vertices.size());
        table[slot] = index;
        keys.push_back(key);
        mesh.vertices.push_back(corners[c]);
        mesh.facetVertices[c] = index;
        break;
      }
      const CornerKey& k = keys[v];
      if (k.x == key.x && k.y == key.y && k.z == key.z) {
        mesh.facetVertices[c] = v;
        break;
      }
      slot = (slot + 1) & mask;
    }
  }
  return mesh;
}

}  // namespace toposlice
