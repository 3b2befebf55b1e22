#include "parallel/band_slicer.h"

#include <algorithm>
#include <atomic>
#include <vector>

#include "core/layer_ranges.h"
#include "core/march_mesh.h"
#include "core/slice_closest.h"
#include "core/slice_march.h"
#include "parallel/parallel.h"

namespace toposlice {

bool parseSliceMethod(const std::string& name, SliceMethod& method) {
  if (name == "cp") method = SliceMethod::ClosestPoint;
  else if (name == "sr-lazy") method = SliceMethod::SelfReuseLazy;
  else if (name == "sr") method = SliceMethod::SelfReuse;
  else return false;
  return true;
}

const char* sliceMethodName(SliceMethod method) {
  switch (method) {
    case SliceMethod::ClosestPoint: return "cp";
    case SliceMethod::SelfReuseLazy: return "sr-lazy";
    case SliceMethod::SelfReuse: return "sr";
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

SliceStats sliceLazy(std::span<const Point3f> corners, std::span<const int32_t> startTable,
                     std::span<const double> planes, const FacetLayers& layers, const SliceSettings& settings,
                     const LayerConsumer& consume, const ProgressContext* progress) {
  SliceStats stats;
  std::vector<int32_t> table(startTable.begin(), startTable.end());
  if (table.empty()) table.assign(corners.size(), -1);
  LazySlicer slicer(corners, table, settings.joinTolerance);
  GapScratch gapScratch;
  ActiveFacets active;
  LayerContours out;
  const auto count = static_cast<uint32_t>(planes.size());
  for (uint32_t k = 0; k < count; ++k) {
    if (k == 0) active.start(layers, 0);
    else active.advance(layers);
    if (slicer.sliceLayer(active.facets(), planes[k], k, out) > 0 && settings.closeGaps > 0)
      stats.gaps += closeGaps(out, settings.closeGaps, gapScratch);
    consume(k, out);
    countLayer(out, stats);
    if (progress && (k % 64 == 63 || k + 1 == count)) {
      progress->update(k + 1, count);
      if (progress->cancelled()) {
        stats.cancelled = true;
        break;
      }
    }
  }
  stats.lazy = slicer.stats();
  return stats;
}

}  // namespace

SliceStats sliceModel(std::span<const Point3f> corners, std::span<const int32_t> adjacency, std::span<const double> planes,
                      const SliceSettings& settings, const LayerConsumer& consume, const ProgressContext* progress) {
  const FacetLayers layers = facetLayersParallel(corners, planes);
  if (settings.method == SliceMethod::SelfReuseLazy)
    return sliceLazy(corners, adjacency, planes, layers, settings, consume, progress);

  const auto layerCount = static_cast<uint32_t>(planes.size());
  const std::size_t threads = std::max(1u, ThreadLimit::available());
  uint32_t band = settings.bandLayers;
  if (band == 0) band = std::clamp<uint32_t>(layerCount / static_cast<uint32_t>(threads * 8), 8, 128);
  const std::size_t bands = (layerCount + band - 1) / band;
  const std::size_t slots = std::min<std::size_t>(bands, 2 * threads);
  const double tolerance2 = settings.joinTolerance * settings.joinTolerance;

  MarchMesh marchMesh;
  const bool march = settings.method == SliceMethod::SelfReuse;
  if (march) {
    prepareMarchMesh(layers, corners.size() / 3, marchMesh);
    parallelForChunks(marchMesh.facets.size(), 16384, [&](std::size_t begin, std::size_t end) {
      fillMarchFacets(corners, adjacency, layers, begin, end, marchMesh);
    });
  }

  struct Slot {
    ActiveFacets active;
    ActiveRecords records;
    MarchScratch march;
    ClosestScratch closest;
    GapScratch gapScratch;
    std::vector<LayerContours> out;
    std::vector<GapStats> gaps;
  };
  std::vector<Slot> slotData(slots);
  SliceStats stats;
  std::atomic<bool> stop{false};
  orderedPipeline(
      bands, slots,
      [&](std::size_t b, std::size_t s) {
        Slot& slot = slotData[s];
        if (stop) return;
        const auto k0 = static_cast<uint32_t>(b * band);
        const uint32_t k1 = std::min(layerCount, k0 + band);
        slot.out.resize(band);
        slot.gaps.assign(band, GapStats{});
        for (uint32_t k = k0; k < k1; ++k) {
          LayerContours& out = slot.out[k - k0];
          uint32_t open = 0;
          if (march) {
            if (k == k0) {
              slot.march.prepare(marchMesh.facets.size());
              slot.records.start(marchMesh, k0);
            } else {
              slot.records.advance(marchMesh);
            }
            open = marchRecordsLayer(marchMesh.facets, slot.records.records(), planes[k], k + 1, slot.march, out);
          } else {
            if (k == k0) slot.active.start(layers, k0);
            else slot.active.advance(layers);
            open = closestPointLayer(corners, slot.active.facets(), planes[k], tolerance2, slot.closest, out);
          }
          if (open > 0 && settings.closeGaps > 0)
            slot.gaps[k - k0] = closeGaps(out, settings.closeGaps, slot.gapScratch);
        }
      },
      [&](std::size_t b, std::size_t s) {
        if (stop) return;
        const auto k0 = static_cast<uint32_t>(b * band);
        const uint32_t k1 = std::min(layerCount, k0 + band);
        for (uint32_t k = k0; k < k1; ++k) {
          consume(k, slotData[s].out[k - k0]);
          countLayer(slotData[s].out[k - k0], stats);
          stats.gaps += slotData[s].gaps[k - k0];
        }
        if (progress) {
          progress->update(k1, layerCount);
          if (progress->cancelled()) stop = true;
        }
      });
  stats.cancelled = stop.load();
  return stats;
}

}  // namespace toposlice
