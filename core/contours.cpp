#include "core/contours.h"

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

double layerSignedArea(const LayerContours& layer) {
  double area = 0.0;
  for (std::size_t l = 0; l < layer.loopCount(); ++l) area += signedArea(layer.loopPoints(l));
  return area;
}

}  // namespace toposlice
