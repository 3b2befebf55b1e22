// Which layers each facet crosses, and the sweep that keeps the set of crossing facets per layer.
//
// With the on-plane rule (crossing.h) facet f crosses plane z exactly when zmin_f < z <= zmax_f, so it
// crosses the contiguous layer range first[f]..last[f]: first = the first plane above zmin, last = the
// last plane at or below zmax (an empty range when first > last). Found with PlaneLocator, exact for any
// ascending plane list, so no floating-point layer formula can disagree with the rule.
// Degenerate facets (two equal corners, crossing.h) get an empty range: no path slices them.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/mesh/mesh.h"

namespace toposlice {

struct FacetLayers {
  std::vector<uint32_t> first, last;    // per facet; first > last when the facet crosses no plane
  std::vector<uint32_t> bucketOffsets;  // per layer + 1: facets whose first layer is k are
  std::vector<uint32_t> bucketFacets;   //   bucketFacets[bucketOffsets[k] .. bucketOffsets[k+1]), ascending
};

// The number of planes at or below a height (= the index of the first plane above it), for ascending
// planes. Exact for any list: a guess from the spacing is corrected against the planes themselves, so it
// costs O(1) for evenly spaced planes (the usual case) and never disagrees with a binary search.
class PlaneLocator {
 public:
  explicit PlaneLocator(std::span<const double> planes);
  uint32_t countAtOrBelow(double z) const;

 private:
  std::span<const double> planes_;
  double origin_ = 0, inverseStep_ = 0;
};

// Fills first/last for facets [begin, end) (callers may split the range across threads).
// `first` and `last` must already hold one entry per facet.
void computeFacetLayerRange(std::span<const Point3f> corners, std::span<const double> planes,
                            std::size_t begin, std::size_t end, std::span<uint32_t> first,
                            std::span<uint32_t> last);

// Builds the first-layer buckets (count, prefix sum, fill) once first/last are known.
void bucketFacetsByFirstLayer(std::size_t layerCount, FacetLayers& layers);

// Both steps, serially.
FacetLayers computeFacetLayers(std::span<const Point3f> corners, std::span<const double> planes);

// The ascending list of facets crossing the current layer, maintained layer by layer:
// start(k) scans every facet once, advance() moves to the next layer by dropping facets whose range ended
// and merging the new layer's bucket (both lists ascending, so the result stays sorted).
class ActiveFacets {
 public:
  void start(const FacetLayers& layers, uint32_t layer);
  // Starts at `layer` from its crossing facets found elsewhere (e.g. a BVH query), ascending.
  void startFrom(std::span<const uint32_t> facets, uint32_t layer) {
    active_.assign(facets.begin(), facets.end());
    layer_ = layer;
  }
  void advance(const FacetLayers& layers);  // to layer() + 1
  std::span<const uint32_t> facets() const { return active_; }
  uint32_t layer() const { return layer_; }

 private:
  std::vector<uint32_t> active_, next_;
  uint32_t layer_ = 0;
};

}  // namespace toposlice
