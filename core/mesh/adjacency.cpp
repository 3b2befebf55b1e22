#include "core/mesh/adjacency.h"

#include <algorithm>
#include <cassert>
#include <memory>
#include <vector>

#include "core/memory_advice.h"

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
// From this runner width on, the half-edges are first filed by part, 8 parts per thread (smaller parts
// keep their buckets in cache); below it, each of `width` parts scans every facet, which costs less
// for two parts but grows with their number (the aligner, BM_AdjacencySplit on 2 threads: 2 parts
// scanning 14.4 ms, 8 parts 27.9 ms, 16 parts 45.5 ms; filed 12.2-12.7 ms for 16 to 128 parts; in the
// slice job on 2 threads, where the set-up of the outputs runs beside it, scanning 0.021 s against
// filed 0.027 s).
constexpr unsigned kFileFromWidth = 4;
constexpr std::size_t kPartsPerThread = 8, kMaxParts = 256;

}  // namespace

EdgeStats buildAdjacency(std::span<const uint32_t> facetVertices, std::size_t vertexCount,
                         std::span<int32_t> adjacency, const ChunkRunner& runner) {
  assert(adjacency.size() == facetVertices.size());
  const std::size_t halfEdges = facetVertices.size(), facets = halfEdges / 3;
  // The vertices are split into `parts` equal ranges, and each part owns the buckets of its range: it
  // counts, files and matches only the half-edges whose lower vertex it owns. From kFileFromWidth on,
  // chunks of facets first file the half-edges by part, so that no part scans every facet; below it,
  // each part scans them all. No two parts write the same word, and a bucket lists its half-edges in
  // index order whatever the split, so the table and the counts are the same for any runner.
  const bool split = runner.width > 1 && halfEdges >= kSplitFrom;
  const bool filed = split && runner.width >= kFileFromWidth;
  const std::size_t parts = !split  ? 1
                            : filed ? std::min<std::size_t>(kPartsPerThread * runner.width, kMaxParts)
                                    : runner.width;
  const ChunkRunner& run = parts > 1 ? runner : serialChunkRunner();
  const std::size_t partVertices = (vertexCount + parts - 1) / std::max<std::size_t>(parts, 1);
  auto degenerate = [](const uint32_t* v) { return v[0] == v[1] || v[1] == v[2] || v[0] == v[2]; };
  // Calls visit(h, lower, upper) for every half-edge of a non-degenerate facet among facets [f0, f1).
  auto forHalfEdges = [&](std::size_t f0, std::size_t f1, auto&& visit) {
    for (std::size_t f = f0; f < f1; ++f) {
      const uint32_t* v = &facetVertices[3 * f];
      if (degenerate(v)) continue;
      for (std::size_t j = 0; j < 3; ++j) {
        const uint32_t a = v[(j + 1) % 3], b = v[(j + 2) % 3];
        visit(3 * f + j, std::min(a, b), std::max(a, b));
      }
    }
  };
  auto partOf = [&](uint32_t lower) { return static_cast<std::size_t>(lower / partVertices); };

  auto from = [&](uint32_t h) { return facetVertices[h - h % 3 + (h % 3 + 1) % 3]; };

  // Every entry starts as "no neighbour" (degenerate facets keep it); the matching writes the pairs.
  // Split: each chunk of facets also counts its half-edges per part (the part of their lower vertex).
  constexpr std::size_t kFacetChunk = std::size_t{1} << 15;
  const std::size_t facetChunks = (facets + kFacetChunk - 1) / kFacetChunk;
  std::vector<uint64_t> degenerateFacets(facetChunks, 0);
  std::vector<std::size_t> chunkPartAt(filed ? facetChunks * parts : 0, 0);  // counts, then positions
  auto chunkEnd = [&](std::size_t c) { return std::min(facets, (c + 1) * kFacetChunk); };
  run.run(facetChunks, 1, [&](std::size_t c0, std::size_t c1) {
    for (std::size_t c = c0; c < c1; ++c) {
      std::fill(adjacency.begin() + static_cast<std::ptrdiff_t>(3 * c * kFacetChunk),
                adjacency.begin() + static_cast<std::ptrdiff_t>(3 * chunkEnd(c)), -1);
      for (std::size_t f = c * kFacetChunk; f < chunkEnd(c); ++f)
        degenerateFacets[c] += degenerate(&facetVertices[3 * f]);
      if (filed)
        forHalfEdges(c * kFacetChunk, chunkEnd(c), [&](std::size_t, uint32_t lower, uint32_t) {
          ++chunkPartAt[c * parts + partOf(lower)];
        });
    }
  });

  // Split: the half-edges are filed by part (part by part, each in half-edge order: chunk after chunk),
  // each chunk writing its own positions; each part then reads only its own.
  struct Owned {
    uint32_t lower, upper, half;
  };
  std::vector<std::size_t> partBegin;
  std::unique_ptr<Owned[]> owned;  // every entry written by the filing below
  if (filed) {
    partBegin = filePositions(std::span(chunkPartAt), facetChunks, parts);
    owned = uninitializedArray<Owned>(partBegin[parts]);
    run.run(facetChunks, 1, [&](std::size_t c0, std::size_t c1) {
      for (std::size_t c = c0; c < c1; ++c)
        forHalfEdges(c * kFacetChunk, chunkEnd(c), [&](std::size_t h, uint32_t lower, uint32_t upper) {
          owned[chunkPartAt[c * parts + partOf(lower)]++] = {lower, upper, static_cast<uint32_t>(h)};
        });
    });
  }
  // Calls visit(h, lower, upper) for every half-edge whose lower vertex part p owns, in half-edge order.
  auto forOwned = [&](std::size_t p, auto&& visit) {
    if (!filed) {
      const std::size_t v0 = p * partVertices, v1 = (p + 1) * partVertices;
      return forHalfEdges(0, facets, [&](std::size_t h, uint32_t lower, uint32_t upper) {
        if (lower >= v0 && lower < v1) visit(h, lower, upper);
      });
    }
    for (std::size_t i = partBegin[p]; i < partBegin[p + 1]; ++i)
      visit(owned[i].half, owned[i].lower, owned[i].upper);
  };

  std::vector<uint32_t> offsets(vertexCount + 1, 0);
  std::vector<std::size_t> partEntries(parts + 1, 0);
  run.run(parts, 1, [&](std::size_t p0, std::size_t p1) {
    for (std::size_t p = p0; p < p1; ++p) {
      const std::size_t v0 = std::min(vertexCount, p * partVertices),
                        v1 = std::min(vertexCount, (p + 1) * partVertices);
      forOwned(p, [&](std::size_t, uint32_t lower, uint32_t) { ++offsets[lower + 1]; });
      std::size_t total = 0;
      for (std::size_t v = v0; v < v1; ++v) total += offsets[v + 1];
      partEntries[p + 1] = total;
    }
  });
  for (std::size_t p = 0; p < parts; ++p) partEntries[p + 1] += partEntries[p];
  // Every entry written by its part's filing below, before its matching reads it.
  const std::unique_ptr<BucketEntry[]> bucket = uninitializedArray<BucketEntry>(partEntries[parts]);
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
      forOwned(p, [&](std::size_t h, uint32_t lower, uint32_t upper) {
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
