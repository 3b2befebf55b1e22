#include "core/slicing/march_mesh.h"

#include <algorithm>

#include "core/memory_advice.h"

namespace toposlice {

void allocateMarchMesh(const FacetLayers& layers, std::size_t facetCount, MarchMesh& mesh) {
  const std::size_t records = layers.bucketFacets.size();
  mesh.facets.resize(records);  // not written yet (UninitialisedAllocator)
  adviseHugePages(mesh.facets.data(), records * sizeof(MarchFacet));
  mesh.layerStart = layers.bucketOffsets;
  mesh.position.assign(facetCount, -1);
  mesh.last.resize(records);
  mesh.blockLast.resize((records + MarchMesh::kBlockRecords - 1) / MarchMesh::kBlockRecords);
}

void placeMarchRecords(const FacetLayers& layers, std::size_t begin, std::size_t end, MarchMesh& mesh) {
  for (std::size_t block = begin; block < end; block += MarchMesh::kBlockRecords) {
    uint32_t blockLast = 0;
    for (std::size_t p = block; p < std::min(end, block + MarchMesh::kBlockRecords); ++p) {
      const uint32_t f = layers.bucketFacets[p];
      mesh.position[f] = static_cast<int32_t>(p);
      mesh.last[p] = layers.last[f];
      blockLast = std::max(blockLast, layers.last[f]);
    }
    mesh.blockLast[block / MarchMesh::kBlockRecords] = blockLast;
  }
}

void prepareMarchMesh(const FacetLayers& layers, std::size_t facetCount, MarchMesh& mesh) {
  allocateMarchMesh(layers, facetCount, mesh);
  placeMarchRecords(layers, 0, mesh.facets.size(), mesh);
}

void ActiveRecords::start(const MarchMesh& mesh, uint32_t layer) {
  layer_ = layer;
  active_.clear();
  const uint32_t end = mesh.layerStart[layer + 1];  // records whose first layer is <= layer
  for (uint32_t block = 0; block * MarchMesh::kBlockRecords < end; ++block) {
    if (mesh.blockLast[block] < layer) continue;  // every record of the block ended below this layer
    const uint32_t blockEnd = std::min(end, (block + 1) * MarchMesh::kBlockRecords);
    for (uint32_t p = block * MarchMesh::kBlockRecords; p < blockEnd; ++p)
      if (mesh.last[p] >= layer) active_.push_back(p);
  }
}

void ActiveRecords::advance(const MarchMesh& mesh) {
  const uint32_t k = ++layer_;
  next_.clear();
  for (const uint32_t p : active_)
    if (mesh.last[p] >= k) next_.push_back(p);
  for (uint32_t p = mesh.layerStart[k]; p < mesh.layerStart[k + 1]; ++p) next_.push_back(p);
  active_.swap(next_);
}

std::size_t fillMarchFacets(std::span<const Point3f> corners, std::span<const int32_t> adjacency,
                            const FacetLayers& layers, std::span<const double> planes, std::size_t begin,
                            std::size_t end, MarchMesh& mesh) {
  const PlaneLocator locate(planes);
  std::size_t missing = 0;
  for (std::size_t p = begin; p < end; ++p) {
    const uint32_t f = layers.bucketFacets[p];
    MarchFacet& r = mesh.facets[p];
    for (unsigned j = 0; j < 3; ++j) {
      r.corner[j] = corners[3 * std::size_t{f} + j];
      const int32_t n = adjacency[3 * std::size_t{f} + j];
      r.next[j] = n < 0 ? -1 : mesh.position[static_cast<std::size_t>(n)];
      missing += n < 0 ? 1 : 0;
    }
    r.id = f;
    r.first = layers.first[f];
    r.last = layers.last[f];
    const float a = r.corner[0].z, b = r.corner[1].z, c = r.corner[2].z;
    const float middle = std::max(std::min(a, b), std::min(std::max(a, b), c));
    r.mid = std::clamp(locate.countAtOrBelow(middle), r.first, r.last + 1);
  }
  return missing;
}

}  // namespace toposlice
