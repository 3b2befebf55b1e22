#include "core/slicing/contours.h"

#include <algorithm>

namespace toposlice {

double signedArea(std::span<const Point2d> loop) {
  const std::size_t n = loop.size();
  if (n < 3) return 0.0;
  // Shifted to the first point to keep the products small (better conditioning far from the origin).
  // Four partial sums, term i going to sum (i - 1) % 4: four independent chains of additions instead of
  // one (a sum over every point of every layer is otherwise bound by the latency of one addition).
  const Point2d o = loop[0];
  double sum[4] = {0.0, 0.0, 0.0, 0.0};
  double px = loop[1].x - o.x, py = loop[1].y - o.y;
  std::size_t i = 1;
  for (; i + 4 < n; i += 4) {
    for (std::size_t r = 0; r < 4; ++r) {
      const double qx = loop[i + r + 1].x - o.x, qy = loop[i + r + 1].y - o.y;
      sum[r] += px * qy - py * qx;
      px = qx;
      py = qy;
    }
  }
  for (std::size_t r = 0; i + 1 < n; ++i, ++r) {
    const double qx = loop[i + 1].x - o.x, qy = loop[i + 1].y - o.y;
    sum[r] += px * qy - py * qx;
    px = qx;
    py = qy;
  }
  return 0.5 * ((sum[0] + sum[1]) + (sum[2] + sum[3]));
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

bool outerLoopsMayOverlap(const LayerContours& layer) {
  if (layer.loopCount() < 2) return false;
  struct Box {
    double x0, x1, y0, y1;
  };
  std::vector<Box> boxes;
  for (std::size_t l = 0; l < layer.loopCount(); ++l) {
    const std::span<const Point2d> loop = layer.loopPoints(l);
    if (signedArea(loop) <= 0) continue;
    Box b{loop[0].x, loop[0].x, loop[0].y, loop[0].y};
    for (const Point2d& p : loop) {
      b.x0 = std::min(b.x0, p.x);
      b.x1 = std::max(b.x1, p.x);
      b.y0 = std::min(b.y0, p.y);
      b.y1 = std::max(b.y1, p.y);
    }
    boxes.push_back(b);
  }
  std::sort(boxes.begin(), boxes.end(), [](const Box& a, const Box& b) { return a.x0 < b.x0; });
  for (std::size_t i = 0; i < boxes.size(); ++i)
    for (std::size_t j = i + 1; j < boxes.size() && boxes[j].x0 < boxes[i].x1; ++j)
      if (boxes[j].y0 < boxes[i].y1 && boxes[i].y0 < boxes[j].y1) return true;
  return false;
}

}  // namespace toposlice
