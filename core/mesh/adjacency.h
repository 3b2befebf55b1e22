// The t x 3 facet adjacency table (DESIGN.md, the paper's section 3).
//
// adjacency[3 i + j] is the facet across edge j of facet i (the edge opposite corner j, running corner
// j+1 -> corner j+2), or -1 where there is no single such facet: a boundary edge (one facet), a
// non-manifold edge (three or more facets), an edge two facets traverse in the same direction
// (inconsistent orientation), and every edge of a degenerate facet (a repeated vertex: it has no area,
// is left out of the table and counted, so its neighbours pair up across it). The table is symmetric:
// if adjacency[3i+j] = k then adjacency[3k+m] = i for the m naming the same edge in k.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

#include "core/chunk_runner.h"

namespace toposlice {

struct EdgeStats {
  uint64_t edges = 0;             // undirected edges (vertex pairs) with two distinct ends
  uint64_t boundary = 0;          // used by one facet
  uint64_t nonManifold = 0;       // used by three or more facets
  uint64_t inconsistent = 0;      // used by two facets in the same direction
  uint64_t degenerateFacets = 0;  // facets with a repeated vertex: skipped, all their entries -1
};

// Builds the table from welded facet-vertex indices (3 per facet, all < vertexCount) in expected linear
// time: half-edges are bucketed by their lower vertex (count, prefix sum, fill), each with its upper
// vertex, then matched inside each small bucket. `adjacency` must hold 3 entries per facet; every entry
// is written. With a parallel runner (core/chunk_runner.h) the vertices are split into one range per
// thread, each range's buckets built and matched by one chunk without atomics; the table and the counts
// are the same for any runner.
EdgeStats buildAdjacency(std::span<const uint32_t> facetVertices, std::size_t vertexCount,
                         std::span<int32_t> adjacency, const ChunkRunner& runner = serialChunkRunner());

}  // namespace toposlice
