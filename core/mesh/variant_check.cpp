#include "core/mesh/variant_check.h"

#include <algorithm>
#include <cassert>
#include <cstdio>
#include <unordered_map>

#include "core/mesh/weld.h"
#include "core/prefetch.h"

namespace toposlice {
namespace {

inline unsigned next(unsigned c) {
  return c == 2 ? 0 : c + 1;
}
inline unsigned prev(unsigned c) {
  return c == 0 ? 2 : c - 1;
}

std::string describePoint(const Point3f& p) {
  char text[96];
  std::snprintf(text, sizeof text, "(%.9g, %.9g, %.9g)", static_cast<double>(p.x), static_cast<double>(p.y),
                static_cast<double>(p.z));
  return text;
}

std::string describeEdge(const Point3f* facet, std::size_t index, unsigned edge) {
  return "facet " + std::to_string(index) + " edge " + std::to_string(edge) + " " +
         describePoint(facet[next(edge)]) + " -> " + describePoint(facet[prev(edge)]);
}

enum class Problem { OutOfRange, Self, NoBackEntry, Geometry };

// Cold path: builds the report for table entry (i, j) = k.
[[gnu::noinline, gnu::cold]] VariantMismatch report(std::span<const Point3f> corners,
                                                    std::span<const int32_t> adjacency, std::size_t i,
                                                    unsigned j, int32_t k, Problem problem) {
  VariantMismatch m;
  m.facet = static_cast<uint32_t>(i);
  m.edge = j;
  m.neighbour = static_cast<uint32_t>(k);
  const std::string entry = "table entry of facet " + std::to_string(i) + " edge " + std::to_string(j) +
                            " (" + std::to_string(k) + ")";
  switch (problem) {
    case Problem::OutOfRange:
      m.reason = entry + " is outside [-1, " + std::to_string(adjacency.size() / 3) + "): not a valid table";
      break;
    case Problem::Self:
      m.reason = entry + " names its own facet: not a valid table";
      break;
    case Problem::NoBackEntry:
      m.reason = entry + " is not named back by facet " + std::to_string(k) + ": the table is not symmetric";
      break;
    case Problem::Geometry: {
      const auto ku = static_cast<std::size_t>(k);
      unsigned back = 0;
      while (back < 2 && adjacency[3 * ku + back] != static_cast<int32_t>(i)) ++back;
      m.reason = describeEdge(&corners[3 * i], i, j) + " is not the reverse of " +
                 describeEdge(&corners[3 * ku], ku, back) +
                 ", its neighbour in the template: the variant does not share the template's connectivity";
      break;
    }
  }
  return m;
}

// Bits that differ between two positions under the welding rule; 0 when they are the same corner.
inline uint32_t positionDifference(const Point3f& p, const Point3f& q) {
  const WeldKey a = weldKey(p), b = weldKey(q);
  return (a.x ^ b.x) | (a.y ^ b.y) | (a.z ^ b.z);
}

// How many facets ahead the screening pass prefetches its neighbours' rows: enough to hide a cache
// miss on meshes whose neighbours are far apart in facet order (an iso-surface's aligner has 20 % of
// its entries more than 4096 facets away), small enough to stay in L1.
constexpr std::size_t kPrefetchFacets = 48;

// Fast screening pass, branch-light: nonzero when some entry may fail. It checks the same rule as
// firstMismatch but takes the first back entry only, so it may flag a valid pair that names the same
// neighbour on several edges; firstMismatch then decides.
uint32_t screen(std::span<const Point3f> corners, std::span<const int32_t> adjacency, std::size_t begin,
                std::size_t end) {
  const std::size_t t = adjacency.size() / 3;
  uint32_t bad = 0;
  for (std::size_t i = begin; i < end; ++i) {
    if (i + kPrefetchFacets < t) {
      for (std::size_t e = 3 * (i + kPrefetchFacets); e < 3 * (i + kPrefetchFacets) + 3; ++e) {
        const auto ahead = static_cast<std::size_t>(static_cast<uint32_t>(adjacency[e]));
        if (ahead < t) {
          prefetch(&adjacency[3 * ahead]);
          prefetch(&corners[3 * ahead]);
          prefetch(&corners[3 * ahead + 2]);
        }
      }
    }
    const Point3f* a = &corners[3 * i];
    const auto self = static_cast<int32_t>(i);
    for (unsigned j = 0; j < 3; ++j) {
      const int32_t k = adjacency[3 * i + j];
      const auto ku = static_cast<std::size_t>(static_cast<uint32_t>(k));  // -1 and negatives: huge
      if (ku <= i || ku >= t) {  // checked from facet k, self, none, or out of range
        bad |= static_cast<uint32_t>(ku == i) | static_cast<uint32_t>(ku >= t && k != -1);
        continue;
      }
      const int32_t* back = &adjacency[3 * ku];
      const unsigned m = back[1] == self ? 1u : (back[2] == self ? 2u : 0u);
      const Point3f* b = &corners[3 * ku];
      bad |= positionDifference(b[next(m)], a[prev(j)]) | positionDifference(b[prev(m)], a[next(j)]) |
             static_cast<uint32_t>(back[m] != self);
    }
  }
  return bad;
}

// Exact pass: the first entry, in facet order, that the variant contradicts (see the header).
std::optional<VariantMismatch> firstMismatch(std::span<const Point3f> corners,
                                             std::span<const int32_t> adjacency) {
  const std::size_t t = adjacency.size() / 3;
  for (std::size_t i = 0; i < t; ++i) {
    const Point3f* a = &corners[3 * i];
    const auto self = static_cast<int32_t>(i);
    for (unsigned j = 0; j < 3; ++j) {
      const int32_t k = adjacency[3 * i + j];
      if (k == -1) continue;
      if (k < -1 || static_cast<std::size_t>(k) >= t) {
        return report(corners, adjacency, i, j, k, Problem::OutOfRange);
      }
      const auto ku = static_cast<std::size_t>(k);
      if (ku == i) return report(corners, adjacency, i, j, k, Problem::Self);
      if (ku < i) continue;  // the pair is checked from facet k
      const int32_t* back = &adjacency[3 * ku];
      const Point3f* b = &corners[3 * ku];
      bool named = false, matched = false;
      for (unsigned m = 0; m < 3 && !matched; ++m) {
        if (back[m] != self) continue;
        named = true;
        matched = positionDifference(b[next(m)], a[prev(j)]) == 0 &&
                  positionDifference(b[prev(m)], a[next(j)]) == 0;
      }
      if (!matched)
        return report(corners, adjacency, i, j, k, named ? Problem::Geometry : Problem::NoBackEntry);
    }
  }
  return std::nullopt;
}

// An undirected edge by its two corners' weld keys, the lower first.
struct EdgeKey {
  WeldKey lo, hi;
  bool operator==(const EdgeKey&) const = default;
};
struct EdgeKeyHash {
  std::size_t operator()(const EdgeKey& k) const {
    uint64_t h = 0x9E3779B97F4A7C15ull;
    for (const uint32_t b : {k.lo.x, k.lo.y, k.lo.z, k.hi.x, k.hi.y, k.hi.z}) h = (h ^ b) * 0x100000001B3ull;
    return static_cast<std::size_t>(h ^ (h >> 29));
  }
};
// The key of the edge from p to q, and whether it runs from the lower end (p) to the higher.
inline EdgeKey edgeKey(const Point3f& p, const Point3f& q, bool& forward) {
  const WeldKey a = weldKey(p), b = weldKey(q);
  forward = a < b;
  return forward ? EdgeKey{a, b} : EdgeKey{b, a};
}
inline bool degenerate(const Point3f* f) {
  return positionDifference(f[0], f[1]) == 0 || positionDifference(f[1], f[2]) == 0 ||
         positionDifference(f[2], f[0]) == 0;
}

// The open entries (-1) of non-degenerate facets: the table claims that no single facet lies across the
// edge (a boundary, non-manifold or inconsistent edge). The variant contradicts it where exactly two
// non-degenerate facets use the edge, in opposite directions: its own table would pair them (a table of
// another model with more open edges, or one whose entries are all -1, passed the pair check before).
std::optional<VariantMismatch> firstOpenEdgeMismatch(std::span<const Point3f> corners,
                                                     std::span<const int32_t> adjacency) {
  const std::size_t t = adjacency.size() / 3;
  if (std::find(adjacency.begin(), adjacency.end(), -1) == adjacency.end()) return std::nullopt;  // closed
  struct Uses {
    uint32_t count = 0, forward = 0;
    uint32_t facet = 0, edge = 0;  // the first open entry with this edge
  };
  std::unordered_map<EdgeKey, Uses, EdgeKeyHash> open;
  for (std::size_t i = 0; i < t; ++i) {
    const Point3f* a = &corners[3 * i];
    const int32_t* entries = &adjacency[3 * i];
    if ((entries[0] != -1 && entries[1] != -1 && entries[2] != -1) || degenerate(a)) continue;
    for (unsigned j = 0; j < 3; ++j) {
      if (entries[j] != -1) continue;
      bool forward = false;
      const EdgeKey key = edgeKey(a[next(j)], a[prev(j)], forward);
      open.try_emplace(key, Uses{0, 0, static_cast<uint32_t>(i), j});
    }
  }
  if (open.empty()) return std::nullopt;
  for (std::size_t i = 0; i < t; ++i) {
    const Point3f* a = &corners[3 * i];
    if (degenerate(a)) continue;
    for (unsigned j = 0; j < 3; ++j) {
      bool forward = false;
      const auto it = open.find(edgeKey(a[next(j)], a[prev(j)], forward));
      if (it == open.end()) continue;
      ++it->second.count;
      it->second.forward += forward ? 1 : 0;
    }
  }
  std::optional<VariantMismatch> first;
  for (const auto& [key, uses] : open) {
    if (uses.count != 2 || uses.forward != 1) continue;
    if (first && (first->facet < uses.facet || (first->facet == uses.facet && first->edge < uses.edge)))
      continue;
    VariantMismatch m;
    m.facet = uses.facet;
    m.edge = uses.edge;
    m.reason = describeEdge(&corners[3 * std::size_t{uses.facet}], uses.facet, uses.edge) +
               " is open in the template's table (-1), but the variant has one facet across it: the variant "
               "does not share the template's connectivity (or the table is another model's)";
    first = std::move(m);
  }
  return first;
}

}  // namespace

std::optional<VariantMismatch> checkVariantConnectivity(std::span<const Point3f> corners,
                                                        std::span<const int32_t> adjacency) {
  assert(adjacency.size() % 3 == 0);
  if (corners.size() != adjacency.size()) {
    VariantMismatch m;
    m.reason =
        "the variant has " + std::to_string(corners.size() / 3) + " facets" +
        (corners.size() % 3 != 0 ? " (and " + std::to_string(corners.size() % 3) + " extra corners)" : "") +
        ", the template has " + std::to_string(adjacency.size() / 3) +
        ": the variant does not share the template's connectivity";
    return m;
  }
  if (screen(corners, adjacency, 0, adjacency.size() / 3) != 0)
    if (auto m = firstMismatch(corners, adjacency)) return m;
  return firstOpenEdgeMismatch(corners, adjacency);
}

std::optional<VariantMismatch> checkOpenEdges(std::span<const Point3f> corners,
                                              std::span<const int32_t> adjacency) {
  assert(corners.size() == adjacency.size());
  return firstOpenEdgeMismatch(corners, adjacency);
}

bool variantMayMismatch(std::span<const Point3f> corners, std::span<const int32_t> adjacency,
                        std::size_t begin, std::size_t end) {
  assert(adjacency.size() % 3 == 0 && end <= adjacency.size() / 3);
  if (corners.size() != adjacency.size()) return true;
  return screen(corners, adjacency, begin, end) != 0;
}

}  // namespace toposlice
