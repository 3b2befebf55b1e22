#include "core/mesh/adjacency.h"

#include <algorithm>
#include <cassert>
#include <vector>

namespace toposlice {

EdgeStats buildAdjacency(std::span<const uint32_t> facetVertices, std::size_t vertexCount,
                         std::span<int32_t> adjacency) {
  assert(adjacency.size() == facetVertices.size());
  const std::size_t halfEdges = facetVertices.size();
  auto from = [&](std::size_t h) { return facetVertices[h - h % 3 + (h % 3 + 1) % 3]; };
  auto to = [&](std::size_t h) { return facetVertices[h - h % 3 + (h % 3 + 2) % 3]; };

  auto degenerateFacet = [&](std::size_t h) {
    const uint32_t* v = &facetVertices[h - h % 3];
    return v[0] == v[1] || v[1] == v[2] || v[0] == v[2];
  };
  std::vector<uint32_t> offsets(vertexCount + 1, 0);
  for (std::size_t h = 0; h < halfEdges; ++h)
    if (!degenerateFacet(h)) ++offsets[std::min(from(h), to(h)) + 1];
  for (std::size_t v = 0; v < vertexCount; ++v) offsets[v + 1] += offsets[v];
  std::vector<uint32_t> bucket(halfEdges);
  {
    std::vector<uint32_t> fill(offsets.begin(), offsets.end() - 1);
    for (std::size_t h = 0; h < halfEdges; ++h)
      if (!degenerateFacet(h)) bucket[fill[std::min(from(h), to(h))]++] = static_cast<uint32_t>(h);
  }
  bucket.resize(offsets[vertexCount]);

  EdgeStats stats;
  for (std::size_t h = 0; h < halfEdges; h += 3) stats.degenerateFacets += degenerateFacet(h) ? 1 : 0;
  std::fill(adjacency.begin(), adjacency.end(), -1);
  std::vector<uint32_t> group;
  for (std::size_t v = 0; v < vertexCount; ++v) {
    const uint32_t begin = offsets[v], end = offsets[v + 1];
    for (uint32_t i = begin; i < end; ++i) {
      const uint32_t hi = bucket[i];
      if (hi == UINT32_MAX) continue;  // already grouped
      const uint32_t other = std::max(from(hi), to(hi));
      group.assign(1, hi);
      for (uint32_t j = i + 1; j < end; ++j) {
        const uint32_t hj = bucket[j];
        if (hj != UINT32_MAX && std::max(from(hj), to(hj)) == other) {
          group.push_back(hj);
          bucket[j] = UINT32_MAX;
        }
      }
      ++stats.edges;
      if (group.size() == 1) {
        ++stats.boundary;
      } else if (group.size() > 2) {
        ++stats.nonManifold;
      } else if (from(group[0]) == from(group[1]) || group[0] / 3 == group[1] / 3) {
        ++stats.inconsistent;
      } else {
        adjacency[group[0]] = static_cast<int32_t>(group[1] / 3);
        adjacency[group[1]] = static_cast<int32_t>(group[0] / 3);
      }
    }
  }
  return stats;
}

}  // namespace toposlice
