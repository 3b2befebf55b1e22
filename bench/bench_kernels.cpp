// Kernel benchmarks (Google Benchmark) on the aligner (544,774 facets) at 1 um layers. Each kernel runs
// single-threaded; `--benchmark_filter` picks kernels. Model: TOPOSLICE_BENCH_MODEL or the derived aligner.
#include <benchmark/benchmark.h>

#include <array>
#include <cstdlib>
#include <optional>
#include <thread>

#include "core/mesh/adjacency.h"
#include "core/mesh/mesh_info.h"
#include "core/mesh/weld.h"
#include "core/print/printer.h"
#include "core/raster/rasterize.h"
#include "core/slicing/layer_ranges.h"
#include "core/slicing/march_mesh.h"
#include "core/slicing/planes.h"
#include "core/slicing/slice_closest.h"
#include "core/slicing/slice_follow.h"
#include "core/slicing/slice_march.h"
#include "io/coders/mask_png.h"
#include "io/readers/byte_input.h"
#include "io/readers/parallel_gunzip.h"
#include "io/readers/stl_reader.h"
#include "offset/polygon_offset.h"
#include "parallel/parallel.h"
#include "tests/fixtures/models.h"

namespace toposlice {
namespace {

std::string modelFile() {
  const char* env = std::getenv("TOPOSLICE_BENCH_MODEL");
  return env ? env : fixtures::modelPath("derived/aligner_upper_case0.stl.gz").string();
}

struct Fixture {
  FacetSoup soup;
  IndexedMesh mesh;
  std::vector<int32_t> table;
  std::vector<double> planes;
  FacetLayers layers;
  MarchMesh march;

  Fixture() {
    soup = readStl(modelFile());
    mesh = weldCorners(soup.corners);
    table.resize(soup.corners.size());
    buildAdjacency(mesh.facetVertices, mesh.vertices.size(), table);
    const BoundingBox box = boundsOf(soup.corners);
    PlaneSpec spec;
    spec.layerHeight = 0.001;
    std::string error;
    planes = makePlanes(spec, box.min.z, box.max.z, error);
    layers = computeFacetLayers(soup.corners, planes);
    prepareMarchMesh(layers, soup.facetCount(), march);
    march.missingNeighbours =
        fillMarchFacets(soup.corners, table, layers, planes, 0, march.facets.size(), march);
  }
};

const Fixture& fixture() {
  static const Fixture f;
  return f;
}

void BM_ReadStlGz(benchmark::State& state) {
  const std::string file = modelFile();
  for (auto _ : state) benchmark::DoNotOptimize(readStl(file).corners.data());
}
BENCHMARK(BM_ReadStlGz)->Unit(benchmark::kMillisecond);

// The model's gzip stream inflated, as the readers do: arg 0 zlib (GzipReader, the fallback for several
// members), 1 libdeflate in one call (gunzip, the one-thread read), both into a fresh output buffer
// every time as in a run; 2 ISA-L in chunks on a thread of its own into a ring (GzipChunks, the threaded
// read), each chunk taken as soon as it is whole, nothing done with it.
void BM_Inflate(benchmark::State& state) {
  const std::string name = modelFile();
  const ByteBuffer file = readWholeFile(name);
  if (!isGzip(file.view())) {
    state.SkipWithError("the model is not gzip-compressed");
    return;
  }
  const std::size_t inflatedSize = gzipSizeHint(file.view());
  for (auto _ : state) {
    switch (state.range(0)) {
      case 0:
        benchmark::DoNotOptimize(GzipReader(file.view(), name).readAll().size);
        break;
      case 1: {
        ByteBuffer out;
        if (!inflateWhole(file.view(), inflatedSize, out)) state.SkipWithError("libdeflate");
        benchmark::DoNotOptimize(out.size);
        break;
      }
      default: {
        GzipChunks stream(file.view(), 84, 50 * 4096);
        std::size_t bytes = stream.head().size();
        for (std::span<const std::byte> chunk = stream.next(); !chunk.empty(); chunk = stream.next())
          bytes += chunk.size();
        if (!stream.finish() || bytes != inflatedSize) state.SkipWithError("ISA-L");
        benchmark::DoNotOptimize(bytes);
      }
    }
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations()) * static_cast<int64_t>(inflatedSize));
}
BENCHMARK(BM_Inflate)->DenseRange(0, 2)->UseRealTime()->Unit(benchmark::kMillisecond);

// Thread counts 4, 8, 16, ... up to the machine's cores (the fixed arguments above cover 1 and 2), so a
// bigger machine times the parallel kernels on all of its cores. Second argument as given.
void everyCoreCount(benchmark::internal::Benchmark* bench, int64_t second) {
  for (unsigned threads = 4; threads <= std::thread::hardware_concurrency(); threads *= 2)
    bench->Args({static_cast<int64_t>(threads), second});
}

// The parallel inflate (parallel_gunzip.h, the read on more than two threads) into a fresh buffer, CRC-32
// checked: arg 0 threads, arg 1 parts (0: the default, one per thread). On one thread, 1 part against
// several gives the cost of a part; against BM_Inflate/1, this decoder's speed against libdeflate's.
void BM_InflateParallel(benchmark::State& state) {
  const ByteBuffer file = readWholeFile(modelFile());
  const auto threads = static_cast<unsigned>(state.range(0));
  const auto parts = static_cast<std::size_t>(state.range(1));
  ThreadLimit limit(threads);
  const ChunkRunner runner = threads > 1 ? parallelChunkRunner() : serialChunkRunner();
  const std::size_t partBytes = parts == 0 ? 0 : file.size / parts - 64;  // the header is not cut
  for (auto _ : state) {
    ByteBuffer out;
    if (!gunzipParallel(file.view(), runner, out, partBytes)) state.SkipWithError("not handled");
    benchmark::DoNotOptimize(out.size);
  }
  state.SetBytesProcessed(static_cast<int64_t>(state.iterations()) *
                          static_cast<int64_t>(gzipSizeHint(file.view())));
}
BENCHMARK(BM_InflateParallel)
    ->Args({1, 1})
    ->Args({1, 4})
    ->Args({1, 16})
    ->Args({2, 0})
    ->Args({2, 8})
    ->Apply([](benchmark::internal::Benchmark* bench) { everyCoreCount(bench, 0); })
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

void BM_Weld(benchmark::State& state) {
  const Fixture& f = fixture();
  for (auto _ : state) benchmark::DoNotOptimize(weldCorners(f.soup.corners).vertices.data());
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(f.soup.corners.size()));
}
BENCHMARK(BM_Weld)->Unit(benchmark::kMillisecond);

void BM_Adjacency(benchmark::State& state) {
  const Fixture& f = fixture();
  std::vector<int32_t> table(f.soup.corners.size());
  for (auto _ : state)
    benchmark::DoNotOptimize(buildAdjacency(f.mesh.facetVertices, f.mesh.vertices.size(), table));
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(f.soup.facetCount()));
}
BENCHMARK(BM_Adjacency)->Unit(benchmark::kMillisecond);

// The split forms (core/chunk_runner.h) on range(0) threads with a runner of width range(1), which
// may exceed the threads (the split code on fewer threads): the weld splits from width 4 (2 x width
// partitions); the adjacency from width 2, its parts scanning every facet below width 4 and filed
// from 4 on (8 x width parts).
void BM_WeldSplit(benchmark::State& state) {
  const Fixture& f = fixture();
  ThreadLimit limit(static_cast<unsigned>(state.range(0)));
  ChunkRunner runner = parallelChunkRunner();
  runner.width = static_cast<unsigned>(state.range(1));
  for (auto _ : state) benchmark::DoNotOptimize(weldCorners(f.soup.corners, runner).vertices.data());
}
BENCHMARK(BM_WeldSplit)
    ->Args({1, 4})
    ->Args({2, 4})
    ->Args({2, 16})
    ->Apply([](benchmark::internal::Benchmark* bench) { everyCoreCount(bench, 16); })
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_AdjacencySplit(benchmark::State& state) {
  const Fixture& f = fixture();
  ThreadLimit limit(static_cast<unsigned>(state.range(0)));
  ChunkRunner runner = parallelChunkRunner();
  runner.width = static_cast<unsigned>(state.range(1));
  std::vector<int32_t> table(f.soup.corners.size());
  for (auto _ : state)
    benchmark::DoNotOptimize(buildAdjacency(f.mesh.facetVertices, f.mesh.vertices.size(), table, runner));
}
BENCHMARK(BM_AdjacencySplit)
    ->Args({1, 2})
    ->Args({2, 2})
    ->Args({2, 4})
    ->Args({2, 16})
    ->Apply([](benchmark::internal::Benchmark* bench) { everyCoreCount(bench, 16); })
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

void BM_FacetLayers(benchmark::State& state) {
  const Fixture& f = fixture();
  for (auto _ : state)
    benchmark::DoNotOptimize(computeFacetLayers(f.soup.corners, f.planes).bucketFacets.data());
}
BENCHMARK(BM_FacetLayers)->Unit(benchmark::kMillisecond);

void BM_MarchMeshBuild(benchmark::State& state) {
  const Fixture& f = fixture();
  MarchMesh march;
  for (auto _ : state) {
    prepareMarchMesh(f.layers, f.soup.facetCount(), march);
    fillMarchFacets(f.soup.corners, f.table, f.layers, f.planes, 0, march.facets.size(), march);
    benchmark::DoNotOptimize(march.facets.data());
  }
}
BENCHMARK(BM_MarchMeshBuild)->Unit(benchmark::kMillisecond);

// 512 layers from the middle of the model, marched in facet (file) order through the separate arrays.
void BM_MarchFileOrder(benchmark::State& state) {
  const Fixture& f = fixture();
  MarchScratch scratch;
  scratch.prepare(f.soup.facetCount());
  ActiveFacets active;
  LayerContours out;
  const auto k0 = static_cast<uint32_t>(f.planes.size() / 2 - 256);
  uint64_t segments = 0;
  uint32_t mark = 0;
  for (auto _ : state) {
    for (uint32_t k = k0; k < k0 + 512; ++k) {
      if (k == k0)
        active.start(f.layers, k0);
      else
        active.advance(f.layers);
      marchLayer(f.soup.corners, f.table, active.facets(), f.planes[k], ++mark, scratch, out);
      segments += out.points.size();
    }
  }
  state.SetItemsProcessed(static_cast<int64_t>(segments));
}
BENCHMARK(BM_MarchFileOrder)->Unit(benchmark::kMillisecond);

// The same 512 layers through the reordered 64-byte records (the default sr kernel).
void BM_MarchRecords(benchmark::State& state) {
  const Fixture& f = fixture();
  MarchScratch scratch;
  scratch.prepare(f.march.facets.size());
  ActiveRecords active;
  LayerContours out;
  const auto k0 = static_cast<uint32_t>(f.planes.size() / 2 - 256);
  uint64_t segments = 0;
  uint32_t mark = 0;
  for (auto _ : state) {
    for (uint32_t k = k0; k < k0 + 512; ++k) {
      if (k == k0)
        active.start(f.march, k0);
      else
        active.advance(f.march);
      marchRecordsLayer(f.march.facets, active.records(), f.planes[k], ++mark, scratch, out);
      segments += out.points.size();
    }
  }
  state.SetItemsProcessed(static_cast<int64_t>(segments));
}
BENCHMARK(BM_MarchRecords)->Unit(benchmark::kMillisecond);

// The same 512 layers followed from layer to layer (slice_follow.h: the sr kernel on closed meshes).
void BM_FollowLoops(benchmark::State& state) {
  const Fixture& f = fixture();
  LoopFollower follower;
  ActiveRecords active;
  LayerContours out;
  const auto k0 = static_cast<uint32_t>(f.planes.size() / 2 - 256);
  uint64_t segments = 0;
  for (auto _ : state) {
    for (uint32_t k = k0; k < k0 + 512; ++k) {
      if (k == k0) {
        active.start(f.march, k0);
        follower.start(f.march, active.records(), k, f.planes[k], out);
      } else if (!follower.advance(f.march, k, f.planes[k], out)) {
        state.SkipWithError("inconsistent table");
        return;
      }
      segments += out.points.size();
    }
  }
  state.SetItemsProcessed(static_cast<int64_t>(segments));
}
BENCHMARK(BM_FollowLoops)->Unit(benchmark::kMillisecond);

// Band starts: 64 layers spread over the height, each found and walked from scratch (what every band of
// the parallel engine does once).
void BM_FollowStarts(benchmark::State& state) {
  const Fixture& f = fixture();
  LoopFollower follower;
  ActiveRecords active;
  LayerContours out;
  uint64_t segments = 0;
  for (auto _ : state) {
    for (uint32_t i = 0; i < 64; ++i) {
      const auto k = static_cast<uint32_t>((f.planes.size() - 1) * (2 * i + 1) / 128);
      active.start(f.march, k);
      follower.start(f.march, active.records(), k, f.planes[k], out);
      segments += out.points.size();
    }
  }
  state.SetItemsProcessed(static_cast<int64_t>(segments));
}
BENCHMARK(BM_FollowStarts)->Unit(benchmark::kMillisecond);

// One mid-height layer joined by the closest-point rule (O(s^2)).
void BM_ClosestPointLayer(benchmark::State& state) {
  const Fixture& f = fixture();
  ClosestScratch scratch;
  ActiveFacets active;
  const auto k = static_cast<uint32_t>(f.planes.size() / 2);
  active.start(f.layers, k);
  LayerContours out;
  for (auto _ : state) closestPointLayer(f.soup.corners, active.facets(), f.planes[k], 1e-10, scratch, out);
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(active.facets().size()));
}
BENCHMARK(BM_ClosestPointLayer)->Unit(benchmark::kMillisecond);

// Layers of the aligner on the Prusa SL1 grid (2560 x 1440, 0.04725 mm, centred), binary and
// anti-aliased, at 25, 50 and 75 % of the model's height: what every core encodes once per layer.
struct MaskFixture {
  std::array<std::array<MaskImage, 2>, 3> masks;  // [height 25/50/75 %][binary, anti-aliased]
  std::array<LayerContours, 3> layers;
  PixelGrid grid;

  MaskFixture() {
    const Fixture& f = fixture();
    grid = placeGrid(boundsOf(f.soup.corners), 2560, 1440, 0.04725, std::nullopt, false, false);
    MarchScratch scratch;
    scratch.prepare(f.march.facets.size());
    RasterScratch raster;
    for (uint32_t h = 0; h < 3; ++h) {
      LayerContours& layer = layers[h];
      const auto k = static_cast<uint32_t>(f.planes.size() * (h + 1) / 4);
      ActiveRecords active;
      active.start(f.march, k);
      marchRecordsLayer(f.march.facets, active.records(), f.planes[k], 1, scratch, layer);
      const ContourSet set{&layer, 1};
      rasterizeBinary({&set, 1}, grid, masks[h][0], raster);
      rasterizeCoverage({&set, 1}, grid, masks[h][1], raster);
    }
  }
};

const MaskFixture& maskFixture() {
  static const MaskFixture f;
  return f;
}

// One layer rasterized on the SL1 grid into a reused image; args: height (25, 50, 75 %), anti-aliased
// (0 binary, 1 exact coverage). Items: the layer's contour points.
void BM_RasterizeLayer(benchmark::State& state) {
  const MaskFixture& f = maskFixture();
  const LayerContours& layer = f.layers[state.range(0) / 25 - 1];
  const ContourSet set{&layer, 1};
  RasterScratch raster;
  MaskImage mask;
  for (auto _ : state) {
    if (state.range(1) == 0) {
      rasterizeBinary({&set, 1}, f.grid, mask, raster);
    } else {
      rasterizeCoverage({&set, 1}, f.grid, mask, raster);
    }
    benchmark::DoNotOptimize(mask.pixels.data());
  }
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(layer.points.size()));
}
BENCHMARK(BM_RasterizeLayer)->ArgsProduct({{25, 50, 75}, {0, 1}})->Unit(benchmark::kMicrosecond);

// The absolute correction's raw loops of one layer (grown by 0.05 mm, as the corrections benchmark in
// docs/BENCHMARKS.md): cleaning, offset and trims. Args: height (25, 50, 75 %). Items: contour points.
void BM_GrowLayer(benchmark::State& state) {
  const LayerContours& layer = maskFixture().layers[state.range(0) / 25 - 1];
  const ContourSet set{&layer, 1};
  LayerContours grown;
  for (auto _ : state) {
    rawCorrectedLoops({&set, 1}, {0.05, 0, 0}, 0.0, grown);
    benchmark::DoNotOptimize(grown.points.data());
  }
  state.counters["points"] = static_cast<double>(grown.points.size());
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(layer.points.size()));
}
BENCHMARK(BM_GrowLayer)->Arg(25)->Arg(50)->Arg(75)->Unit(benchmark::kMicrosecond);

// The grown layer's anti-aliased mask. Args: height (25, 50, 75 %); 0: the raw loops (the clusters the
// detours leave in them are decided apart), 1: their union by Clipper (no detours: beside 0, what the
// detours cost the rasterizer). Counters: rows with a cluster decided apart, the loops' points.
void BM_RasterizeGrownLayer(benchmark::State& state) {
  const MaskFixture& f = maskFixture();
  const ContourSet set{&f.layers[state.range(0) / 25 - 1], 1};
  LayerContours grown, united;
  rawCorrectedLoops({&set, 1}, {0.05, 0, 0}, 0.0, grown);
  if (state.range(1) == 1) unitePositive(grown, 0.0, united);
  const ContourSet grownSet{state.range(1) == 1 ? &united : &grown, 1};
  RasterScratch raster;
  MaskImage mask;
  for (auto _ : state) {
    rasterizeCoverage({&grownSet, 1}, f.grid, mask, raster);
    benchmark::DoNotOptimize(mask.pixels.data());
  }
  state.counters["banded_rows"] =
      static_cast<double>(raster.bandedRows) / static_cast<double>(state.iterations());
  state.counters["points"] = static_cast<double>(grownSet.layer->points.size());
}
BENCHMARK(BM_RasterizeGrownLayer)->ArgsProduct({{25, 50, 75}, {0, 1}})->Unit(benchmark::kMicrosecond);

// encodeMaskPng of one layer; args: height (25, 50, 75 %), anti-aliased (0, 1), code (0 smallest: the
// default, dynamic for these layers; 1 fixed). Counter: PNG bytes.
void BM_EncodeMaskPng(benchmark::State& state) {
  const MaskImage& mask = maskFixture().masks[state.range(0) / 25 - 1][state.range(1)];
  const MaskPngCode code = state.range(2) == 0 ? MaskPngCode::smallest : MaskPngCode::fixed;
  std::vector<uint8_t> png;
  MaskPngScratch scratch;
  for (auto _ : state) {
    encodeMaskPng(mask, png, scratch, code);
    benchmark::DoNotOptimize(png.data());
  }
  state.counters["bytes"] = static_cast<double>(png.size());
  state.SetBytesProcessed(state.iterations() * static_cast<int64_t>(mask.pixels.size()));
}
BENCHMARK(BM_EncodeMaskPng)->ArgsProduct({{25, 50, 75}, {0, 1}, {0, 1}})->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace toposlice

BENCHMARK_MAIN();
