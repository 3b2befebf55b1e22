#include "core/mesh/adjacency.h"

#include <algorithm>
#include <cassert>
#include <vector>

namespace toposlice {
namespace {

// One half-edge in its lower vertex's bucket: the upper vertex beside the half-edge's index, so matching
// a bucket reads only the bucket.
struct BucketEntry {
  uint32_t other;  // the upper vertex; kTaken once grouped
  uint32_t half;   // the half-edge
};
constexpr uint32_t kTaken = 0xFFFFFFFFu;
constexpr std::size_t kSplitFrom = std::size_t{1} << 17;  // half-edges; below, one part is faster

}  // namespace

EdgeStats buildAdjacency(std::span<const uint32_t> facetVertices, std::size_t vertexCount,
                         std::span<int32_t> adjacency, const ChunkRunner& runner) {
  assert(adjacency.size() == facetVertices.size());
  const std::size_t halfEdges = facetVertices.size(), facets = halfEdges / 3;
  // The vertices are split into `parts` equal ranges, and each part owns the buckets of its range: it
  // scans every facet but counts, files and matches only the half-edges whose lower vertex it owns. No
  // two parts write the same word, and a bucket lists its half-edges in index order whatever the split,
  // so the table and the counts are the same for any runner.
  const std::size_t parts =
      runner.width > 1 && halfEdges >= kSplitFrom ? std::min<std::size_t>(runner.width, 64) : 1;
  const ChunkRunner& run = parts > 1 ? runner : serialChunkRunner();
  const std::size_t partVertices = (vertexCount + parts - 1) / std::max<std::size_t>(parts, 1);
  auto degenerate = [](const uint32_t* v) { return v[0] == v[1] || v[1] == v[2] || v[0] == v[2]; };
  // Calls visit(h, lower, upper) for every half-edge of a non-degenerate facet whose lower vertex is in
  // [v0, v1).
  auto forOwned = [&](std::size_t v0, std::size_t v1, auto&& visit) {
    for (std::size_t f = 0; f < facets; ++f) {
      const uint32_t* v = &facetVertices[3 * f];
      if (degenerate(v)) continue;
      for (std::size_t j = 0; j < 3; ++j) {
        const uint32_t a = v[(j + 1) % 3], b = v[(j + 2) % 3];
        const uint32_t lower = std::min(a, b);
        if (lower >= v0 && lower < v1) visit(3 * f + j, lower, std::max(a, b));
      }
    }
  };

  auto from = [&](uint32_t h) { return facetVertices[h - h % 3 + (h % 3 + 1) % 3]; };

  // Every entry starts as "no neighbour" (degenerate facets keep it); the matching writes the pairs.
  constexpr std::size_t kFacetChunk = std::size_t{1} << 15;
  const std::size_t facetChunks = (facets + kFacetChunk - 1) / kFacetChunk;
  std::vector<uint64_t> degenerateFacets(facetChunks, 0);
  run.run(facetChunks, 1, [&](std::size_t c0, std::size_t c1) {
    for (std::size_t c = c0; c < c1; ++c) {
      const std::size_t f1 = std::min(facets, (c + 1) * kFacetChunk);
      std::fill(adjacency.begin() + static_cast<std::ptrdiff_t>(3 * c * kFacetChunk),
                adjacency.begin() + static_cast<std::ptrdiff_t>(3 * f1), -1);
      for (std::size_t f = c * kFacetChunk; f < f1; ++f)
        degenerateFacets[c] += degenerate(&facetVertices[3 * f]);
    }
  });

  std::vector<uint32_t> offsets(vertexCount + 1, 0);
  std::vector<std::size_t> partEntries(parts + 1, 0);
  run.run(parts, 1, [&](std::size_t p0, std::size_t p1) {
    for (std::size_t p = p0; p < p1; ++p) {
      const std::size_t v0 = std::min(vertexCount, p * partVertices),
                        v1 = std::min(vertexCount, (p + 1) * partVertices);
      forOwned(v0, v1, [&](std::size_t, uint32_t lower, uint32_t) { ++offsets[lower + 1]; });
      std::size_t total = 0;
      for (std::size_t v = v0; v < v1; ++v) total += offsets[v + 1];
      partEntries[p + 1] = total;
    }
  });
  for (std::size_t p = 0; p < parts; ++p) partEntries[p + 1] += partEntries[p];
  std::vector<BucketEntry> bucket(partEntries[parts]);
  std::vector<EdgeStats> partStats(parts);
  run.run(parts, 1, [&](std::size_t p0, std::size_t p1) {
    for (std::size_t p = p0; p < p1; ++p) {
      const std::size_t v0 = std::min(vertexCount, p * partVertices),
                        v1 = std::min(vertexCount, (p + 1) * partVertices);
      // Offsets of the part's buckets (a prefix sum from the part's first entry), then the buckets.
      uint32_t at = static_cast<uint32_t>(partEntries[p]);
      for (std::size_t v = v0; v < v1; ++v) {
        const uint32_t count = offsets[v + 1];
        offsets[v + 1] = at;  // fill position of bucket v, until filled: then its start of v + 1
        at += count;
      }
      forOwned(v0, v1, [&](std::size_t h, uint32_t lower, uint32_t upper) {
        bucket[offsets[lower + 1]++] = {upper, static_cast<uint32_t>(h)};
      });
      // Each bucket matches its half-edges: a pair is an edge of two facets; a group of one or of three
      // and more, or a pair in the same direction, has no neighbour.
      EdgeStats& stats = partStats[p];
      for (std::size_t v = v0; v < v1; ++v) {
        const uint32_t begin = v == v0 ? static_cast<uint32_t>(partEntries[p]) : offsets[v],
                       end = offsets[v + 1];
        for (uint32_t i = begin; i < end; ++i) {
          const uint32_t other = bucket[i].other;
          if (other == kTaken) continue;
          const uint32_t first = bucket[i].half;
          uint32_t second = 0, group = 1;
          for (uint32_t j = i + 1; j < end; ++j)
            if (bucket[j].other == other) {
              if (++group == 2) second = bucket[j].half;
              bucket[j].other = kTaken;
            }
          ++stats.edges;
          if (group == 1) {
            ++stats.boundary;
          } else if (group > 2) {
            ++stats.nonManifold;
          } else if (from(first) == from(second) || first / 3 == second / 3) {
            ++stats.inconsistent;
          } else {
            adjacency[first] = static_cast<int32_t>(second / 3);
            adjacency[second] = static_cast<int32_t>(first / 3);
          }
        }
      }
    }
  });
  EdgeStats stats;
  for (const EdgeStats& s : partStats) {
    stats.edges += s.edges;
    stats.boundary += s.boundary;
    stats.nonManifold += s.nonManifold;
    stats.inconsistent += s.inconsistent;
  }
  for (const uint64_t d : degenerateFacets) stats.degenerateFacets += d;
  return stats;
}

}  // namespace toposlice
