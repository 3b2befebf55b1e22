#include "core/mesh/adjacency.h"

#include <algorithm>
#include <atomic>
#include <cassert>
#include <vector>

namespace toposlice {
namespace {

constexpr std::size_t kChunk = 1 << 15;  // half-edges or vertices per chunk of a split step

}  // namespace

EdgeStats buildAdjacency(std::span<const uint32_t> facetVertices, std::size_t vertexCount,
                         std::span<int32_t> adjacency, const ChunkRunner& runner) {
  assert(adjacency.size() == facetVertices.size());
  const std::size_t halfEdges = facetVertices.size();
  // Split only when it pays; the buckets are then filled with atomic counters, in an order that may
  // change from run to run. Matching inside a bucket does not depend on that order (a pair is a pair,
  // and a group of one or of three and more is counted the same), so the table and the counts are the
  // same for any runner.
  const bool split = runner.width > 1 && halfEdges >= 4 * kChunk;
  const ChunkRunner& run = split ? runner : serialChunkRunner();
  auto from = [&](std::size_t h) { return facetVertices[h - h % 3 + (h % 3 + 1) % 3]; };
  auto to = [&](std::size_t h) { return facetVertices[h - h % 3 + (h % 3 + 2) % 3]; };
  auto degenerateFacet = [&](std::size_t h) {
    const uint32_t* v = &facetVertices[h - h % 3];
    return v[0] == v[1] || v[1] == v[2] || v[0] == v[2];
  };
  auto add = [split](uint32_t& counter) {
    return split ? std::atomic_ref<uint32_t>(counter).fetch_add(1, std::memory_order_relaxed) : counter++;
  };
  const std::size_t edgeChunks = (halfEdges / 3 + kChunk - 1) / kChunk;  // chunks of whole facets
  auto facetRange = [&](std::size_t c0, std::size_t c1) {
    return std::pair{3 * c0 * kChunk, std::min(halfEdges, 3 * c1 * kChunk)};
  };

  std::vector<uint32_t> offsets(vertexCount + 1, 0);
  std::vector<uint64_t> degenerate(edgeChunks, 0);
  run.run(edgeChunks, 1, [&](std::size_t c0, std::size_t c1) {
    const auto [begin, end] = facetRange(c0, c1);
    for (std::size_t h = begin; h < end; ++h) {
      if (degenerateFacet(h)) {
        if (h % 3 == 0) ++degenerate[c0];
        continue;
      }
      add(offsets[std::min(from(h), to(h)) + 1]);
    }
  });
  for (std::size_t v = 0; v < vertexCount; ++v) offsets[v + 1] += offsets[v];
  std::vector<uint32_t> bucket(offsets[vertexCount]);
  {
    std::vector<uint32_t> fill(offsets.begin(), offsets.end() - 1);
    run.run(edgeChunks, 1, [&](std::size_t c0, std::size_t c1) {
      const auto [begin, end] = facetRange(c0, c1);
      for (std::size_t h = begin; h < end; ++h)
        if (!degenerateFacet(h)) bucket[add(fill[std::min(from(h), to(h))])] = static_cast<uint32_t>(h);
    });
  }
  run.run(edgeChunks, 1, [&](std::size_t c0, std::size_t c1) {
    const auto [begin, end] = facetRange(c0, c1);
    std::fill(adjacency.begin() + static_cast<std::ptrdiff_t>(begin),
              adjacency.begin() + static_cast<std::ptrdiff_t>(end), -1);
  });

  // Each vertex chunk matches the half-edges of its buckets: it writes only their entries.
  const std::size_t vertexChunks = (vertexCount + kChunk - 1) / kChunk;
  std::vector<EdgeStats> chunkStats(vertexChunks);
  run.run(vertexChunks, 1, [&](std::size_t c0, std::size_t c1) {
    EdgeStats& stats = chunkStats[c0];
    std::vector<uint32_t> group;
    for (std::size_t v = c0 * kChunk; v < std::min(vertexCount, c1 * kChunk); ++v) {
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
  });
  EdgeStats stats;
  for (const EdgeStats& s : chunkStats) {
    stats.edges += s.edges;
    stats.boundary += s.boundary;
    stats.nonManifold += s.nonManifold;
    stats.inconsistent += s.inconsistent;
  }
  for (const uint64_t d : degenerate) stats.degenerateFacets += d;
  return stats;
}

}  // namespace toposlice
