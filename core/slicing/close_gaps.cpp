#include "core/slicing/close_gaps.h"

#include <algorithm>
#include <limits>

#include "core/slicing/crossing.h"

namespace toposlice {

GapStats closeGaps(LayerContours& layer, double maxGap, bool closeRest, GapScratch& scratch) {
  GapStats stats;
  auto& open = scratch.open;
  open.clear();
  for (std::size_t l = 0; l < layer.loopCount(); ++l)
    if (!layer.loopClosed[l]) open.push_back(static_cast<uint32_t>(l));
  if (open.empty()) return stats;
  const auto n = static_cast<uint32_t>(open.size());
  auto first = [&](uint32_t o) { return layer.points[layer.loopOffsets[open[o]]]; };
  auto last = [&](uint32_t o) { return layer.points[layer.loopOffsets[open[o] + 1] - 1]; };

  auto& candidates = scratch.candidates;
  auto& next = scratch.next;
  auto& prev = scratch.prev;
  next.assign(n, -1);
  prev.assign(n, -1);
  // Greedy nearest-first matching of free ends (no successor yet) to free starts (no predecessor yet),
  // over the pairs at most sqrt(max2) apart; ties by polyline order. Returns the joins made; `wider`
  // marks them (wide[from]) as joins wider than maxGap, for the counts.
  auto& wide = scratch.wide;
  wide.assign(n, 0);
  auto match = [&](double max2, bool wider) {
    candidates.clear();
    for (uint32_t i = 0; i < n; ++i) {
      if (next[i] >= 0) continue;
      for (uint32_t j = 0; j < n; ++j) {
        if (prev[j] >= 0) continue;
        const double d = squaredDistance(last(i), first(j));
        if (d <= max2) candidates.push_back({d, i, j});
      }
    }
    std::sort(candidates.begin(), candidates.end(), [](const auto& a, const auto& b) {
      if (a.distance2 != b.distance2) return a.distance2 < b.distance2;
      return a.from != b.from ? a.from < b.from : a.to < b.to;
    });
    uint64_t joins = 0;
    for (const auto& c : candidates) {
      if (next[c.from] >= 0 || prev[c.to] >= 0) continue;
      next[c.from] = static_cast<int32_t>(c.to);
      prev[c.to] = static_cast<int32_t>(c.from);
      wide[c.from] = wider ? 1 : 0;
      ++joins;
    }
    return joins;
  };
  stats.joins = match(maxGap * maxGap, false);
  // Then, with closeRest, the gaps wider than maxGap, nearest first: every end finds a start (there
  // are as many free starts as free ends, its own chain's among them), so every chain closes.
  if (closeRest) stats.selfClosed = match(std::numeric_limits<double>::infinity(), true);
  if (stats.joins == 0 && stats.selfClosed == 0) {
    stats.leftOpen = n;
    return stats;
  }

  // Rebuild: closed loops as they were, then each chain (open from a polyline with no predecessor,
  // closed around a cycle).
  LayerContours& out = scratch.rebuilt;
  out.clear(layer.z);
  for (std::size_t l = 0; l < layer.loopCount(); ++l) {
    if (!layer.loopClosed[l]) continue;
    const uint32_t b = layer.loopOffsets[l], e = layer.loopOffsets[l + 1];
    out.points.insert(out.points.end(), layer.points.begin() + b, layer.points.begin() + e);
    out.facets.insert(out.facets.end(), layer.facets.begin() + b, layer.facets.begin() + e);
    out.endLoop(true);
  }
  auto& used = scratch.used;
  used.assign(n, 0);
  auto appendPolyline = [&](uint32_t o) {
    const uint32_t b = layer.loopOffsets[open[o]], e = layer.loopOffsets[open[o] + 1];
    out.points.insert(out.points.end(), layer.points.begin() + b, layer.points.begin() + e);
    out.facets.insert(out.facets.end(), layer.facets.begin() + b, layer.facets.begin() + e);
    used[o] = 1;
  };
  for (uint32_t o = 0; o < n; ++o) {  // chains with a beginning stay open
    if (prev[o] >= 0) continue;
    for (int32_t c = static_cast<int32_t>(o); c >= 0; c = next[static_cast<uint32_t>(c)])
      appendPolyline(static_cast<uint32_t>(c));
    out.endLoop(false);
    ++stats.leftOpen;
  }
  for (uint32_t o = 0; o < n; ++o) {  // what is left are cycles
    if (used[o]) continue;
    bool anyWide = false;
    for (int32_t c = static_cast<int32_t>(o); !used[static_cast<uint32_t>(c)];
         c = next[static_cast<uint32_t>(c)]) {
      anyWide = anyWide || wide[static_cast<uint32_t>(c)] != 0;
      appendPolyline(static_cast<uint32_t>(c));
    }
    out.endLoop(true);
    ++(anyWide ? stats.closedLoopsWider : stats.closedLoops);
  }
  std::swap(out, layer);
  canonicalizeLayer(layer, scratch.canonical);
  return stats;
}

}  // namespace toposlice
