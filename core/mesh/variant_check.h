// Checking that a customized variant shares its template's connectivity (DESIGN.md, intra-model reuse).
//
// A variant is sliced with its template's adjacency table only when every table entry still describes
// its geometry: for each entry adjacency[3i+j] = k >= 0, edge j of facet i (corner j+1 -> corner j+2)
// and the edge m of facet k whose entry names i back (adjacency[3k+m] = i) join the same two corner
// positions in opposite directions. Positions compare bit for bit, except that -0.0 equals +0.0 (the
// welding rule, core/mesh/weld.h). An entry of -1 (no single facet across: a boundary, non-manifold or
// inconsistent edge) holds unless exactly two non-degenerate facets of the variant use that edge, in
// opposite directions (its own table would pair them); a table of another model, with more open edges,
// fails there.
// A variant with other facet order, rotated corners, a moved corner or another facet count fails, so a
// model whose connectivity differs is detected and never sliced with a wrong table.
#pragma once

#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "core/mesh/mesh.h"

namespace toposlice {

inline constexpr uint32_t kNoIndex = UINT32_MAX;

// The first table entry (in facet order) that the variant contradicts. For a facet-count mismatch all
// three indices are kNoIndex. `reason` is a one-line message naming facets, edges and positions.
struct VariantMismatch {
  uint32_t facet = kNoIndex;      // facet i of the failing entry (the lower index of the pair)
  uint32_t edge = kNoIndex;       // its edge j (0..2), opposite corner j
  uint32_t neighbour = kNoIndex;  // the entry's value k
  std::string reason;
};

// The table of the same mesh with every facet reversed (corners 1 and 2 swapped, as flipping an
// inside-out mesh does): entries 1 and 2 of each facet trade places, each edge being opposite its corner.
// Written into `out` (resized).
inline void reverseFacetsOfTable(std::span<const int32_t> adjacency, std::vector<int32_t>& out) {
  out.assign(adjacency.begin(), adjacency.end());
  for (std::size_t e = 0; e + 2 < out.size(); e += 3) std::swap(out[e + 1], out[e + 2]);
}

// Checks the variant soup `corners` (3 per facet) against a template table (3 entries per facet) in
// linear time, each neighbouring pair once, from its lower facet index i < k. Returns nullopt when every
// pair holds, else the first mismatch in facet order. Entries outside [-1, t) or naming their own facet
// are reported, so no table causes an out-of-range read; so is an entry (i, j) = k > i that facet k
// does not name back. Precondition: adjacency.size() % 3 == 0 and the table is symmetric (buildAdjacency
// and readTemplateFile guarantee it), since entries (i, j) = k < i are left to facet k's side.
std::optional<VariantMismatch> checkVariantConnectivity(std::span<const Point3f> corners,
                                                        std::span<const int32_t> adjacency);

// The open-entry half of that check alone (the variant has the table's facet count): the first -1 entry
// the variant contradicts. Linear in the facets when the table has open entries, nothing otherwise.
std::optional<VariantMismatch> checkOpenEdges(std::span<const Point3f> corners,
                                              std::span<const int32_t> adjacency);

// The fast half of that check for facets [begin, end): false when every pair checked from those facets
// holds, true when one may fail (or the facet counts differ); then checkVariantConnectivity finds and
// names the first mismatch. Ranges may be screened in parallel (parallel/variant_screen.h).
bool variantMayMismatch(std::span<const Point3f> corners, std::span<const int32_t> adjacency,
                        std::size_t begin, std::size_t end);

}  // namespace toposlice
