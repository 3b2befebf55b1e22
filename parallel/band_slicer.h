// Slicing a whole model: the layer range is cut into bands, bands are sliced in parallel (each with its
// own scratch, writing only its own slot's layer buffers) and handed to the consumer strictly in layer
// order through a bounded pipeline, so output is streamed, memory does not grow with the layer count,
// and the bytes are the same for any thread count and band size.
#pragma once

#include <cstdint>
#include <functional>
#include <span>
#include <string>

#include "core/mesh/mesh.h"
#include "core/progress.h"
#include "core/slicing/close_gaps.h"
#include "core/slicing/contours.h"
#include "core/slicing/slice_lazy.h"

namespace toposlice {

enum class SliceMethod { ClosestPoint, SelfReuseLazy, SelfReuse };

// How a band finds the facets crossing its first layer: a linear sweep over the facets sorted by first
// layer, or a query of Embree's BVH (built once per mesh). Both give the same set; see BENCHMARKS.md for
// which is faster (the default).
enum class CandidateSearch { Sweep, Embree };
bool parseCandidateSearch(const std::string& name, CandidateSearch& search);

// "cp", "sr-lazy", "sr" <-> SliceMethod; parse returns false on an unknown name.
bool parseSliceMethod(const std::string& name, SliceMethod& method);
const char* sliceMethodName(SliceMethod method);

struct SliceSettings {
  SliceMethod method = SliceMethod::SelfReuse;
  uint32_t bandLayers = 0;      // layers per band; 0 picks a size from the layer and thread counts
  double joinTolerance = 1e-5;  // mm; cp and sr-lazy join segment ends closer than this
  double closeGaps = 0.05;      // mm; open polylines (defective meshes) are bridged up to this gap
  bool closeRemaining = true;   // then close what is still open on itself (close_gaps.h)
  CandidateSearch candidates = CandidateSearch::Sweep;
};

struct SliceStats {
  uint64_t layers = 0, segments = 0, loops = 0, openPolylines = 0;
  LazyStats lazy;
  GapStats gaps;
  bool cancelled = false;
};

using LayerConsumer = std::function<void(uint32_t layer, const LayerContours& contours)>;

// Slices `corners` (3 per facet) at `planes` (ascending). `adjacency` (3 per facet): for SelfReuse the
// complete table (built, or loaded from a template); for SelfReuseLazy the table to start from (empty for
// all -1, or a template's), copied and completed as layers need it; unused for ClosestPoint. The
// caller's table is never modified. `consume` is called once per layer, in layer order, from one thread
// at a time. Progress counts layers.
SliceStats sliceModel(std::span<const Point3f> corners, std::span<const int32_t> adjacency,
                      std::span<const double> planes, const SliceSettings& settings,
                      const LayerConsumer& consume, const ProgressContext* progress = nullptr);

// Several meshes on one z grid (a model and its add-on / removal features, each with its own table),
// with an optional parallel stage per layer (rasterize, encode) before the in-order consumer.
struct SliceMesh {
  std::span<const Point3f> corners;
  std::span<const int32_t> adjacency;  // as for sliceModel
};

// The band size and number of pipeline slots sliceMeshes will use, so callers can size per-slot storage.
struct BandPlan {
  uint32_t bandLayers = 1;
  std::size_t slots = 1;
};
BandPlan planBands(std::size_t layerCount, const SliceSettings& settings);

struct LayerStages {
  // Optional. Runs in parallel, once per layer, after every mesh of the layer is sliced. `meshes[i]` is
  // mesh i's contours; `slot` < plan.slots and `position` < plan.bandLayers name storage the caller owns
  // for this layer until its consume call (no other running call uses the same pair).
  std::function<void(uint32_t layer, std::span<const LayerContours> meshes, std::size_t slot,
                     uint32_t position)>
      process;
  // Runs in layer order from one thread at a time, with the same slot and position.
  std::function<void(uint32_t layer, std::span<const LayerContours> meshes, std::size_t slot,
                     uint32_t position)>
      consume;
};

// Stats count the first mesh (the model) only; gaps are bridged in every mesh.
SliceStats sliceMeshes(std::span<const SliceMesh> meshes, std::span<const double> planes,
                       const SliceSettings& settings, const LayerStages& stages,
                       const ProgressContext* progress = nullptr);

}  // namespace toposlice
