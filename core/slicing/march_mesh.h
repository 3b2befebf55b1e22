// A slicing-friendly copy of a mesh for the marching kernel (data-oriented layout).
//
// Facets that cross some plane are reordered by the first layer they cross (the order of the
// first-layer buckets), so the facets of one layer lie close together in memory and a band of layers
// sweeps a window of the array. Each facet is one 64-byte record: its corners, its neighbours as record
// positions, its original index and layer range. The marching walk then follows neighbours within a
// cache-resident window instead of jumping through three arrays in file order. Built in linear time from
// the facet layer ranges and the adjacency table (built or loaded from a template).
#pragma once

#include <cstdint>
#include <memory>
#include <new>
#include <span>
#include <utility>
#include <vector>

#include "core/mesh/mesh.h"
#include "core/slicing/layer_ranges.h"

namespace toposlice {

struct alignas(64) MarchFacet {
  Point3f corner[3];
  int32_t next[3];       // record position across edge j, or -1
  uint32_t id;           // the facet's index in the model
  uint32_t first, last;  // layer range it crosses
  // First layer (clamped to first..last + 1) above its middle corner: before it, one corner lies below
  // the plane; from it on, two. The facet's crossed edges -- its place in a loop -- change only there.
  uint32_t mid;
};
static_assert(sizeof(MarchFacet) == 64);

// An allocator whose resize() leaves trivial elements uninitialised: the record array is written whole
// by fillMarchFacets, so zeroing it first (and faulting its pages in on one thread) would be wasted.
template <class T>
struct UninitialisedAllocator : std::allocator<T> {
  template <class U>
  struct rebind {
    using other = UninitialisedAllocator<U>;
  };
  UninitialisedAllocator() = default;
  template <class U>
  explicit UninitialisedAllocator(const UninitialisedAllocator<U>&) noexcept {}
  template <class U>
  void construct(U* p) noexcept {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};

struct MarchMesh {
  std::vector<MarchFacet, UninitialisedAllocator<MarchFacet>> facets;  // crossing facets, first-layer order
  std::vector<uint32_t> layerStart;  // per layer + 1: records whose first layer is k start at layerStart[k]
  std::vector<int32_t> position;     // per model facet: its record, or -1 when it crosses no plane
  std::vector<uint32_t> last;        // per record: last layer (compact copy for band start scans)
  // Per block of kBlockRecords records: the largest `last`, so a band start skips blocks that ended.
  static constexpr uint32_t kBlockRecords = 256;
  std::vector<uint32_t> blockLast;
  // Crossing records with an edge that has no neighbour (boundary, non-manifold or inconsistent): then
  // walks may end open, and only the layer-by-layer march (slice_march.h) handles them.
  std::size_t missingNeighbours = 0;
};

// The records crossing the current layer, maintained layer by layer like ActiveFacets (in record order,
// not facet order: marchRecordsLayer restores the canonical order).
class ActiveRecords {
 public:
  void start(const MarchMesh& mesh, uint32_t layer);
  // Starts at `layer` from its crossing records found elsewhere (e.g. a BVH query), in any order.
  void startFrom(std::span<const uint32_t> records, uint32_t layer) {
    active_.assign(records.begin(), records.end());
    layer_ = layer;
  }
  void advance(const MarchMesh& mesh);  // to layer() + 1
  std::span<const uint32_t> records() const { return active_; }
  uint32_t layer() const { return layer_; }

 private:
  std::vector<uint32_t> active_, next_;
  uint32_t layer_ = 0;
};

// Sizes the mesh (records left unwritten) and fills `layerStart`; `position` is -1 everywhere.
void allocateMarchMesh(const FacetLayers& layers, std::size_t facetCount, MarchMesh& mesh);

// Fills `position`, `last` and `blockLast` for records [begin, end); `begin` must be a multiple of
// MarchMesh::kBlockRecords (callers may split the records across threads in such ranges).
void placeMarchRecords(const FacetLayers& layers, std::size_t begin, std::size_t end, MarchMesh& mesh);

// allocateMarchMesh, then placeMarchRecords for every record (serial).
void prepareMarchMesh(const FacetLayers& layers, std::size_t facetCount, MarchMesh& mesh);

// Fills records [begin, end) (callers may split the range across threads) and returns how many of their
// edges have no neighbour (add them up into mesh.missingNeighbours). Needs prepareMarchMesh first;
// `planes` are the ones `layers` was computed for.
std::size_t fillMarchFacets(std::span<const Point3f> corners, std::span<const int32_t> adjacency,
                            const FacetLayers& layers, std::span<const double> planes, std::size_t begin,
                            std::size_t end, MarchMesh& mesh);

}  // namespace toposlice
