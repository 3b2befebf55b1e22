#include "parallel/band_slicer.h"

#include <algorithm>
#include <atomic>
#include <memory>
#include <vector>

#include "core/slicing/layer_ranges.h"
#include "core/slicing/march_mesh.h"
#include "core/slicing/slice_closest.h"
#include "core/slicing/slice_follow.h"
#include "core/slicing/slice_march.h"
#include "parallel/embree_queries.h"
#include "parallel/parallel.h"

namespace toposlice {

bool parseCandidateSearch(const std::string& name, CandidateSearch& search) {
  if (name == "sweep")
    search = CandidateSearch::Sweep;
  else if (name == "embree")
    search = CandidateSearch::Embree;
  else
    return false;
  return true;
}

bool parseSliceMethod(const std::string& name, SliceMethod& method) {
  if (name == "cp")
    method = SliceMethod::ClosestPoint;
  else if (name == "sr-lazy")
    method = SliceMethod::SelfReuseLazy;
  else if (name == "sr")
    method = SliceMethod::SelfReuse;
  else
    return false;
  return true;
}

const char* sliceMethodName(SliceMethod method) {
  switch (method) {
    case SliceMethod::ClosestPoint:
      return "cp";
    case SliceMethod::SelfReuseLazy:
      return "sr-lazy";
    case SliceMethod::SelfReuse:
      return "sr";
  }
  return "?";
}

namespace {

void countLayer(const LayerContours& layer, SliceStats& stats) {
  ++stats.layers;
  stats.loops += layer.loopCount();
  for (std::size_t l = 0; l < layer.loopCount(); ++l) {
    const uint64_t n = layer.loopOffsets[l + 1] - layer.loopOffsets[l];
    stats.segments += layer.loopClosed[l] ? n : n - 1;
    stats.openPolylines += layer.loopClosed[l] ? 0 : 1;
  }
}

FacetLayers facetLayersParallel(std::span<const Point3f> corners, std::span<const double> planes) {
  FacetLayers layers;
  const std::size_t facetCount = corners.size() / 3;
  layers.first.resize(facetCount);
  layers.last.resize(facetCount);
  parallelForChunks(facetCount, 16384, [&](std::size_t begin, std::size_t end) {
    computeFacetLayerRange(corners, planes, begin, end, layers.first, layers.last);
  });
  bucketFacetsByFirstLayer(planes.size(), layers);
  return layers;
}

// One mesh's slicing state inside a band (or the whole run, for sr-lazy).
struct MeshState {
  FacetLayers layers;
  std::unique_ptr<FacetBvh> bvh;   // CandidateSearch::Embree
  MarchMesh march;                 // sr
  std::vector<int32_t> lazyTable;  // sr-lazy
};

struct SlotMesh {
  std::vector<uint32_t> candidates;  // BVH query results
  ActiveFacets active;
  ActiveRecords records;
  MarchScratch march;
  LoopFollower follow;
  ClosestScratch closest;
  GapScratch gaps;
};

// The records crossing layer k, found from scratch: a query of the BVH when there is one, else a scan.
void startRecords(const MeshState& state, uint32_t k, double z, SlotMesh& slot) {
  if (state.bvh) {
    startRecordsFromBvh(*state.bvh, state.march, z, k, slot.candidates);
    slot.records.startFrom(slot.candidates, k);
  } else {
    slot.records.start(state.march, k);
  }
}

// Slices layer k of one mesh into `out` (cp or sr; the band's first layer starts the sweep).
uint32_t sliceBandLayer(const SliceMesh& mesh, const MeshState& state, SliceMethod method, uint32_t k,
                        bool first, double z, double tolerance2, SlotMesh& slot, LayerContours& out) {
  if (method == SliceMethod::SelfReuse) {
    // Meshes whose table has no gaps follow the loops of the layer below (slice_follow.h); a band start,
    // a mesh with gaps, or (only with an inconsistent table) a walk that does not close marches instead.
    const bool closed = state.march.missingNeighbours == 0;
    if (closed && !first && slot.follow.advance(state.march, k, z, out)) return 0;
    if (first || closed) {
      startRecords(state, k, z, slot);
      if (closed && slot.follow.start(state.march, slot.records.records(), k, z, out)) return 0;
      slot.march.prepare(state.march.facets.size());
      slot.march.forgetWalk();
    } else {
      slot.records.advance(state.march);
    }
    return marchRecordsLayer(state.march.facets, slot.records.records(), z, k + 1, slot.march, out);
  }
  if (first && state.bvh) {
    state.bvh->facetsCrossingPlane(z, slot.candidates);
    std::erase_if(slot.candidates, [&](uint32_t f) {
      return state.layers.first[f] > state.layers.last[f] || state.layers.last[f] == UINT32_MAX;
    });
    slot.active.startFrom(slot.candidates, k);
  } else if (first) {
    slot.active.start(state.layers, k);
  } else {
    slot.active.advance(state.layers);
  }
  return closestPointLayer(mesh.corners, slot.active.facets(), z, tolerance2, slot.closest, out);
}

SliceStats sliceLazy(std::span<const SliceMesh> meshes, std::vector<MeshState>& states,
                     std::span<const double> planes, const SliceSettings& settings, const LayerStages& stages,
                     const ProgressContext* progress) {
  SliceStats stats;
  std::vector<LazySlicer> slicers;
  std::vector<ActiveFacets> active(meshes.size());
  std::vector<GapScratch> gapScratch(meshes.size());
  slicers.reserve(meshes.size());
  for (std::size_t i = 0; i < meshes.size(); ++i) {
    states[i].lazyTable.assign(meshes[i].adjacency.begin(), meshes[i].adjacency.end());
    if (states[i].lazyTable.empty()) states[i].lazyTable.assign(meshes[i].corners.size(), -1);
    slicers.emplace_back(meshes[i].corners, states[i].lazyTable, settings.joinTolerance);
  }
  std::vector<LayerContours> out(meshes.size());
  const auto count = static_cast<uint32_t>(planes.size());
  const bool repairs = settings.closeGaps > 0 || settings.closeRemaining;
  for (uint32_t k = 0; k < count; ++k) {
    for (std::size_t i = 0; i < meshes.size(); ++i) {
      if (k == 0)
        active[i].start(states[i].layers, 0);
      else
        active[i].advance(states[i].layers);
      GapStats gaps;
      if (slicers[i].sliceLayer(active[i].facets(), planes[k], k, out[i]) > 0 && repairs)
        gaps = closeGaps(out[i], settings.closeGaps, settings.closeRemaining, gapScratch[i]);
      if (i == 0) stats.gaps += gaps;
    }
    if (stages.process) stages.process(k, out, 0, 0);
    if (stages.consume) stages.consume(k, out, 0, 0);
    countLayer(out[0], stats);
    if (progress && (k % 64 == 63 || k + 1 == count)) {
      progress->update(k + 1, count);
      if (progress->cancelled()) {
        stats.cancelled = true;
        break;
      }
    }
  }
  stats.lazy = slicers[0].stats();
  return stats;
}

}  // namespace

BandPlan planBands(std::size_t layerCount, const SliceSettings& settings) {
  if (settings.method == SliceMethod::SelfReuseLazy) return {1, 1};
  const std::size_t threads = std::max(1u, ThreadLimit::available());
  uint32_t band = settings.bandLayers;
  if (band == 0) band = std::clamp<uint32_t>(static_cast<uint32_t>(layerCount / (threads * 8)), 8, 16);
  // A band never holds more layers than the job has: the per-band storage is sized by it (a given
  // --band-layers of 10^8 on a 20-layer job allocated gigabytes for nothing).
  band = static_cast<uint32_t>(std::min<std::size_t>(band, std::max<std::size_t>(layerCount, 1)));
  const std::size_t bands = std::max<std::size_t>(1, (layerCount + band - 1) / band);
  return {band, std::min<std::size_t>(bands, 2 * threads)};
}

SliceStats sliceMeshes(std::span<const SliceMesh> meshes, std::span<const double> planes,
                       const SliceSettings& settings, const LayerStages& stages,
                       const ProgressContext* progress) {
  std::vector<MeshState> states(meshes.size());
  for (std::size_t i = 0; i < meshes.size(); ++i)
    states[i].layers = facetLayersParallel(meshes[i].corners, planes);
  if (settings.method == SliceMethod::SelfReuseLazy)
    return sliceLazy(meshes, states, planes, settings, stages, progress);

  if (settings.candidates == CandidateSearch::Embree)
    for (std::size_t i = 0; i < meshes.size(); ++i)
      states[i].bvh = std::make_unique<FacetBvh>(meshes[i].corners, FacetBvh::kSlabQueries);
  if (settings.method == SliceMethod::SelfReuse) {
    for (std::size_t i = 0; i < meshes.size(); ++i) {
      MeshState& state = states[i];
      allocateMarchMesh(state.layers, meshes[i].corners.size() / 3, state.march);
      constexpr std::size_t kBlock = MarchMesh::kBlockRecords;
      const std::size_t records = state.march.facets.size();
      parallelForChunks(state.march.blockLast.size(), 64, [&](std::size_t b0, std::size_t b1) {
        placeMarchRecords(state.layers, b0 * kBlock, std::min(records, b1 * kBlock), state.march);
      });
      std::atomic<std::size_t> missing{0};
      parallelForChunks(state.march.facets.size(), 16384, [&](std::size_t begin, std::size_t end) {
        missing += fillMarchFacets(meshes[i].corners, meshes[i].adjacency, state.layers, planes, begin, end,
                                   state.march);
      });
      state.march.missingNeighbours = missing.load();
    }
  }

  const auto layerCount = static_cast<uint32_t>(planes.size());
  const BandPlan plan = planBands(layerCount, settings);
  const uint32_t band = plan.bandLayers;
  const std::size_t bands = (layerCount + band - 1) / band;
  const std::size_t meshCount = meshes.size();
  const double tolerance2 = settings.joinTolerance * settings.joinTolerance;
  const bool repairs = settings.closeGaps > 0 || settings.closeRemaining;

  struct Slot {
    std::vector<SlotMesh> mesh;
    std::vector<LayerContours> out;  // [position * meshCount + mesh]
    std::vector<GapStats> gaps;      // model's, per position
  };
  std::vector<Slot> slotData(plan.slots);
  SliceStats stats;
  std::atomic<bool> stop{false};
  orderedPipeline(
      bands, plan.slots,
      [&](std::size_t b, std::size_t s) {
        if (stop) return;
        Slot& slot = slotData[s];
        slot.mesh.resize(meshCount);
        slot.out.resize(std::size_t{band} * meshCount);
        slot.gaps.assign(band, GapStats{});
        const auto k0 = static_cast<uint32_t>(b * band);
        const uint32_t k1 = std::min(layerCount, k0 + band);
        for (uint32_t k = k0; k < k1; ++k) {
          const uint32_t position = k - k0;
          for (std::size_t i = 0; i < meshCount; ++i) {
            LayerContours& out = slot.out[position * meshCount + i];
            const uint32_t open = sliceBandLayer(meshes[i], states[i], settings.method, k, k == k0, planes[k],
                                                 tolerance2, slot.mesh[i], out);
            if (open > 0 && repairs) {
              const GapStats gaps =
                  closeGaps(out, settings.closeGaps, settings.closeRemaining, slot.mesh[i].gaps);
              if (i == 0) slot.gaps[position] = gaps;
            }
          }
          if (stages.process)
            stages.process(k,
                           std::span<const LayerContours>(slot.out).subspan(position * meshCount, meshCount),
                           s, position);
        }
      },
      [&](std::size_t b, std::size_t s) {
        if (stop) return;
        Slot& slot = slotData[s];
        const auto k0 = static_cast<uint32_t>(b * band);
        const uint32_t k1 = std::min(layerCount, k0 + band);
        for (uint32_t k = k0; k < k1; ++k) {
          const uint32_t position = k - k0;
          const auto layer =
              std::span<const LayerContours>(slot.out).subspan(position * meshCount, meshCount);
          if (stages.consume) stages.consume(k, layer, s, position);
          countLayer(layer[0], stats);
          stats.gaps += slot.gaps[position];
        }
        if (progress) {
          progress->update(k1, layerCount);
          if (progress->cancelled()) stop = true;
        }
      });
  stats.cancelled = stop.load();
  return stats;
}

SliceStats sliceModel(std::span<const Point3f> corners, std::span<const int32_t> adjacency,
                      std::span<const double> planes, const SliceSettings& settings,
                      const LayerConsumer& consume, const ProgressContext* progress) {
  const SliceMesh mesh{corners, adjacency};
  LayerStages stages;
  stages.consume = [&](uint32_t k, std::span<const LayerContours> layer, std::size_t, uint32_t) {
    consume(k, layer[0]);
  };
  return sliceMeshes(std::span<const SliceMesh>(&mesh, 1), planes, settings, stages, progress);
}

}  // namespace toposlice
