#include "core/slicing/layer_ranges.h"

#include <algorithm>

#include "core/slicing/crossing.h"

namespace toposlice {

PlaneLocator::PlaneLocator(std::span<const double> planes) : planes_(planes) {
  if (planes.size() < 2) return;
  const double step = (planes.back() - planes.front()) / static_cast<double>(planes.size() - 1);
  if (step > 0) {
    origin_ = planes.front();
    inverseStep_ = 1.0 / step;
  }
}

uint32_t PlaneLocator::countAtOrBelow(double z) const {
  const std::size_t n = planes_.size();
  std::size_t k = 0;
  if (inverseStep_ == 0) {
    k = static_cast<std::size_t>(std::upper_bound(planes_.begin(), planes_.end(), z) - planes_.begin());
  } else {
    const double guess = (z - origin_) * inverseStep_ + 1.0;
    if (guess >= static_cast<double>(n))
      k = n;
    else if (guess > 0)
      k = static_cast<std::size_t>(guess);
    while (k > 0 && planes_[k - 1] > z) --k;
    while (k < n && planes_[k] <= z) ++k;
  }
  return static_cast<uint32_t>(k);
}

void computeFacetLayerRange(std::span<const Point3f> corners, std::span<const double> planes,
                            std::size_t begin, std::size_t end, std::span<uint32_t> first,
                            std::span<uint32_t> last) {
  const PlaneLocator locate(planes);
  for (std::size_t f = begin; f < end; ++f) {
    const Point3f* c = &corners[3 * f];
    if (isDegenerateFacet(c)) {  // crosses nothing
      first[f] = static_cast<uint32_t>(planes.size());
      last[f] = UINT32_MAX;
      continue;
    }
    const double zmin = std::min({c[0].z, c[1].z, c[2].z});
    const double zmax = std::max({c[0].z, c[1].z, c[2].z});
    first[f] = locate.countAtOrBelow(zmin);  // first plane > zmin
    // last = (first plane > zmax) - 1: an empty range gets last = first - 1 (UINT32_MAX below plane 0).
    last[f] = locate.countAtOrBelow(zmax) - 1u;
  }
}

void bucketFacetsByFirstLayer(std::size_t layerCount, FacetLayers& layers) {
  const std::size_t facetCount = layers.first.size();
  layers.bucketOffsets.assign(layerCount + 1, 0);
  for (std::size_t f = 0; f < facetCount; ++f) {
    const uint32_t a = layers.first[f], b = layers.last[f];
    if (a < layerCount && b != UINT32_MAX && a <= b) ++layers.bucketOffsets[a + 1];
  }
  for (std::size_t k = 0; k < layerCount; ++k) layers.bucketOffsets[k + 1] += layers.bucketOffsets[k];
  layers.bucketFacets.resize(layers.bucketOffsets[layerCount]);
  std::vector<uint32_t> fill(layers.bucketOffsets.begin(), layers.bucketOffsets.end() - 1);
  for (std::size_t f = 0; f < facetCount; ++f) {
    const uint32_t a = layers.first[f], b = layers.last[f];
    if (a < layerCount && b != UINT32_MAX && a <= b)
      layers.bucketFacets[fill[a]++] = static_cast<uint32_t>(f);
  }
}

FacetLayers computeFacetLayers(std::span<const Point3f> corners, std::span<const double> planes) {
  FacetLayers layers;
  const std::size_t facetCount = corners.size() / 3;
  layers.first.resize(facetCount);
  layers.last.resize(facetCount);
  computeFacetLayerRange(corners, planes, 0, facetCount, layers.first, layers.last);
  bucketFacetsByFirstLayer(planes.size(), layers);
  return layers;
}

namespace {
// A facet crosses layer k when first <= k <= last (last may be UINT32_MAX for "no plane at or below").
inline bool crossesLayer(const FacetLayers& layers, uint32_t f, uint32_t k) {
  const uint32_t b = layers.last[f];
  return layers.first[f] <= k && b != UINT32_MAX && k <= b;
}
}  // namespace

void ActiveFacets::start(const FacetLayers& layers, uint32_t layer) {
  layer_ = layer;
  active_.clear();
  const auto facetCount = static_cast<uint32_t>(layers.first.size());
  for (uint32_t f = 0; f < facetCount; ++f)
    if (crossesLayer(layers, f, layer)) active_.push_back(f);
}

void ActiveFacets::advance(const FacetLayers& layers) {
  const uint32_t k = ++layer_;
  const uint32_t* added = layers.bucketFacets.data() + layers.bucketOffsets[k];
  const uint32_t* addedEnd = layers.bucketFacets.data() + layers.bucketOffsets[k + 1];
  next_.clear();
  next_.reserve(active_.size() + static_cast<std::size_t>(addedEnd - added));
  for (const uint32_t f : active_) {
    if (layers.last[f] < k) continue;
    while (added != addedEnd && *added < f) next_.push_back(*added++);
    next_.push_back(f);
  }
  next_.insert(next_.end(), added, addedEnd);
  active_.swap(next_);
}

}  // namespace toposlice
