#include "core/contours.h"

#include <algorithm>

namespace toposlice {

double signedArea(std::span<const Point2d> loop) {
  if (loop.size() < 3) return 0.0;
  // Shifted to the first point to keep the products small (better conditioning far from the origin).
  const Point2d o = loop[0];
  double twice = 0.0;
  for (std::size_t i = 1; i + 1 < loop.size(); ++i) {
    const double ax = loop[i].x - o.x, ay = loop[i].y - o.y;
    const double bx = loop[i + 1].x - o.x, by = loop[i + 1].y - o.y;
    twice += ax * by - ay * bx;
  }
  return 0.5 * twice;
}

void canonicalizeLayer(LayerContours& layer, CanonicalScratch& scratch) {
  const std::size_t loops = layer.loopCount();
  auto& loopMin = scratch.loopMin;
  loopMin.resize(loops);
  for (std::size_t l = 0; l < loops; ++l) {
    const auto begin = layer.facets.begin() + layer.loopOffsets[l];
    const auto end = layer.facets.begin() + layer.loopOffsets[l + 1];
    const auto lowest = std::min_element(begin, end);
    loopMin[l] = lowest == end ? UINT32_MAX : *lowest;
    if (!layer.loopClosed[l] || lowest == begin || lowest == end) continue;
    const auto at = lowest - layer.facets.begin();
    std::rotate(layer.points.begin() + layer.loopOffsets[l], layer.points.begin() + at,
                layer.points.begin() + layer.loopOffsets[l + 1]);
    std::rotate(begin, lowest, end);
  }
  if (std::is_sorted(loopMin.begin(), loopMin.end())) return;
  auto& order = scratch.order;
  order.resize(loops);
  for (std::size_t l = 0; l < loops; ++l) order[l] = static_cast<uint32_t>(l);
  std::stable_sort(order.begin(), order.end(),
                   [&](uint32_t a, uint32_t b) { return loopMin[a] < loopMin[b]; });
  LayerContours& sorted = scratch.sorted;
  sorted.clear(layer.z);
  for (const uint32_t l : order) {
    const uint32_t b = layer.loopOffsets[l], e = layer.loopOffsets[l + 1];
    sorted.points.insert(sorted.points.end(), layer.points.begin() + b, layer.points.begin() + e);
    sorted.facets.insert(sorted.facets.end(), layer.facets.begin() + b, layer.facets.begin() + e);
    sorted.endLoop(layer.loopClosed[l] != 0);
  }
  std::swap(sorted, layer);
}

double layerSignedArea(const LayerContours& layer) {
  double area = 0.0;
  for (std::size_t l = 0; l < layer.loopCount(); ++l) area += signedArea(layer.loopPoints(l));
  return area;
}

}  // namespace toposlice
