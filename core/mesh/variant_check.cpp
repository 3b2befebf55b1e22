#include "core/mesh/variant_check.h"

#include <bit>
#include <cassert>
#include <cstdio>

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
  return (std::bit_cast<uint32_t>(p.x + 0.0f) ^ std::bit_cast<uint32_t>(q.x + 0.0f)) |
         (std::bit_cast<uint32_t>(p.y + 0.0f) ^ std::bit_cast<uint32_t>(q.y + 0.0f)) |
         (std::bit_cast<uint32_t>(p.z + 0.0f) ^ std::bit_cast<uint32_t>(q.z + 0.0f));
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
  if (screen(corners, adjacency, 0, adjacency.size() / 3) == 0) return std::nullopt;
  return firstMismatch(corners, adjacency);
}

bool variantMayMismatch(std::span<const Point3f> corners, std::span<const int32_t> adjacency,
                        std::size_t begin, std::size_t end) {
  assert(adjacency.size() % 3 == 0 && end <= adjacency.size() / 3);
  if (corners.size() != adjacency.size()) return true;
  return screen(corners, adjacency, begin, end) != 0;
}

}  // namespace toposlice
