#include "parallel/embree_queries.h"

#include <embree3/rtcore.h>

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <limits>
#include <new>
#include <stdexcept>
#include <string>

// Embree 3 API used: rtcBuildBVH (the SAH builder with user node/leaf callbacks), user geometry
// (bounds and intersect callbacks) and rtcIntersect1 with an extended RTCIntersectContext carrying the
// query's double-precision line. The crossing test is the simulation-of-simplicity idea (Edelsbrunner and
// Muecke, "Simulation of Simplicity", ACM TOG 9(1), 1990) applied to 2D edge functions.

namespace toposlice {
namespace {

constexpr uint32_t kLeafBit = 0x80000000u;
constexpr uint32_t kNoChild = 0xFFFFFFFFu;
constexpr unsigned kBranching = 4;
constexpr unsigned kMaxDepth = 64;
constexpr std::size_t kStackSize = (kBranching - 1) * kMaxDepth + 2;
constexpr float kInf = std::numeric_limits<float>::infinity();

// ---- slab tree --------------------------------------------------------------------------------------

struct LeafEntry {
  float zmin, zmax;  // the facet's exact z range
  uint32_t facet;
};

// A flattened node: per child its z range and reference (node index, kLeafBit | leaf index, kNoChild).
struct SlabNode {
  std::array<float, kBranching> zlo, zhi;
  std::array<uint32_t, kBranching> child;
};

// Nodes as the builder makes them (in memory owned by the RTCBVH), flattened right after the build.
enum class BuildKind : uint32_t { Inner, Leaf };
struct BuildInner {
  BuildKind kind;  // first member: read through the void* the builder hands around
  uint32_t count;
  std::array<const void*, kBranching> child;
  std::array<float, kBranching> zlo, zhi;
};
struct BuildLeaf {
  BuildKind kind;
  uint32_t count;
  LeafEntry* entries;
};

BuildKind kindOf(const void* node) {
  return *static_cast<const BuildKind*>(node);
}

void* createNode(RTCThreadLocalAllocator alloc, unsigned int childCount, void*) {
  void* mem = rtcThreadLocalAlloc(alloc, sizeof(BuildInner), alignof(BuildInner));
  auto* node = new (mem) BuildInner{BuildKind::Inner, childCount, {}, {}, {}};
  node->child.fill(nullptr);
  node->zlo.fill(kInf);
  node->zhi.fill(-kInf);
  return node;
}

void setNodeChildren(void* nodePtr, void** children, unsigned int childCount, void*) {
  auto* node = static_cast<BuildInner*>(nodePtr);
  for (unsigned i = 0; i < childCount; ++i) node->child[i] = children[i];
}

void setNodeBounds(void* nodePtr, const RTCBounds** bounds, unsigned int childCount, void*) {
  auto* node = static_cast<BuildInner*>(nodePtr);
  for (unsigned i = 0; i < childCount; ++i) {
    node->zlo[i] = bounds[i]->lower_z;
    node->zhi[i] = bounds[i]->upper_z;
  }
}

void* createLeaf(RTCThreadLocalAllocator alloc, const RTCBuildPrimitive* prims, size_t count, void*) {
  void* mem = rtcThreadLocalAlloc(alloc, sizeof(BuildLeaf), alignof(BuildLeaf));
  void* entryMem = rtcThreadLocalAlloc(alloc, count * sizeof(LeafEntry), alignof(LeafEntry));
  auto* entries = static_cast<LeafEntry*>(entryMem);
  for (std::size_t i = 0; i < count; ++i) entries[i] = {prims[i].lower_z, prims[i].upper_z, prims[i].primID};
  return new (mem) BuildLeaf{BuildKind::Leaf, static_cast<uint32_t>(count), entries};
}

struct SlabTree {
  std::vector<SlabNode> nodes;
  std::vector<LeafEntry> entries;  // leaf l is entries[leafBegin[l] .. leafBegin[l+1])
  std::vector<uint32_t> leafBegin{0};
  uint32_t root = kNoChild;

  uint32_t flatten(const void* node, unsigned depth) {
    if (depth > kMaxDepth) throw std::runtime_error("Embree BVH deeper than expected");
    if (kindOf(node) == BuildKind::Leaf) {
      const auto* leaf = static_cast<const BuildLeaf*>(node);
      entries.insert(entries.end(), leaf->entries, leaf->entries + leaf->count);
      leafBegin.push_back(static_cast<uint32_t>(entries.size()));
      return kLeafBit | static_cast<uint32_t>(leafBegin.size() - 2);
    }
    const auto* inner = static_cast<const BuildInner*>(node);
    const auto index = static_cast<uint32_t>(nodes.size());
    nodes.emplace_back();
    SlabNode flat;
    flat.zlo.fill(kInf);
    flat.zhi.fill(-kInf);
    flat.child.fill(kNoChild);
    for (unsigned i = 0; i < inner->count; ++i) {
      flat.zlo[i] = inner->zlo[i];
      flat.zhi[i] = inner->zhi[i];
      flat.child[i] = flatten(inner->child[i], depth + 1);
    }
    nodes[index] = flat;
    return index;
  }

  // Appends every leaf entry accepted by `keep` under children accepted by `visit` (both take a float z
  // range; `visit` must accept every range that holds an entry `keep` accepts).
  template <class Visit, class Keep>
  void walk(Visit visit, Keep keep, std::vector<uint32_t>& out) const {
    if (root == kNoChild) return;
    std::array<uint32_t, kStackSize> stack;
    std::size_t top = 0;
    stack[top++] = root;
    while (top > 0) {
      const uint32_t ref = stack[--top];
      if (ref & kLeafBit) {
        const uint32_t l = ref & ~kLeafBit;
        for (uint32_t e = leafBegin[l]; e < leafBegin[l + 1]; ++e)
          if (keep(entries[e].zmin, entries[e].zmax)) out.push_back(entries[e].facet);
        continue;
      }
      const SlabNode& node = nodes[ref];
      for (unsigned i = kBranching; i-- > 0;)  // pushed in reverse: children are visited in order
        if (visit(node.zlo[i], node.zhi[i])) stack[top++] = node.child[i];
    }
  }
};

// ---- exact line / facet crossing ---------------------------------------------------------------------

bool lexLess(const Point3f& a, const Point3f& b) {
  if (a.x != b.x) return a.x < b.x;
  if (a.y != b.y) return a.y < b.y;
  return a.z < b.z;
}

struct EdgeSide {
  double value;  // edge function at the unperturbed point
  int sign;      // its sign at the perturbed point (0 only for an edge with no extent in y and z)
};

// Edge function of lo -> hi at (y, z) in the yz plane: (hi.y - lo.y)(z - lo.z) - (hi.z - lo.z)(y - lo.y),
// positive when the point is left of the edge. At the perturbed point (y + d, z - e), e >> d, a zero
// value takes the sign of -(hi.y - lo.y), or when that is zero, of -(hi.z - lo.z).
EdgeSide edgeSide(const Point3f& lo, const Point3f& hi, double y, double z) {
  const double dy = static_cast<double>(hi.y) - lo.y;
  const double dz = static_cast<double>(hi.z) - lo.z;
  const double value = dy * (z - lo.z) - dz * (y - lo.y);
  int sign = value > 0 ? 1 : (value < 0 ? -1 : 0);
  if (sign == 0) sign = dy != 0 ? (dy > 0 ? -1 : 1) : (dz > 0 ? -1 : (dz < 0 ? 1 : 0));
  return {value, sign};
}

// The same for the directed edge a -> b, always evaluated from the lexicographically smaller end so that
// the facet on the other side of the edge (which has b -> a) gets exactly the negated result.
EdgeSide directedEdgeSide(const Point3f& a, const Point3f& b, double y, double z) {
  if (lexLess(b, a)) {
    const EdgeSide s = edgeSide(b, a, y, z);
    return {-s.value, -s.sign};
  }
  return edgeSide(a, b, y, z);
}

// Whether the line {(t, y, z)} crosses the facet under the perturbation rule; if so, where and how.
bool lineCrossesFacet(const Point3f* c, double y, double z, double& x, int32_t& step) {
  const EdgeSide e0 = directedEdgeSide(c[1], c[2], y, z);  // opposite corner 0
  if (e0.sign == 0) return false;
  const EdgeSide e1 = directedEdgeSide(c[2], c[0], y, z);
  if (e1.sign != e0.sign) return false;
  const EdgeSide e2 = directedEdgeSide(c[0], c[1], y, z);
  if (e2.sign != e0.sign) return false;
  // Inside: the barycentric weight of corner i is the edge function of the opposite edge.
  const double sum = e0.value + e1.value + e2.value;
  const double xmin = std::min({c[0].x, c[1].x, c[2].x}), xmax = std::max({c[0].x, c[1].x, c[2].x});
  x = sum != 0 ? (e0.value * c[0].x + e1.value * c[1].x + e2.value * c[2].x) / sum : xmin;
  x = std::clamp(std::isfinite(x) ? x : xmin, xmin, xmax);
  step = -e0.sign;  // e0.sign is the sign of the normal's x component (the yz projection's orientation)
  return true;
}

float below(float v) {
  return std::nextafter(v, -kInf);
}
float above(float v) {
  return std::nextafter(v, kInf);
}

}  // namespace

// ---- FacetBvh ------------------------------------------------------------------------------------------

struct FacetBvh::Impl {
  std::span<const Point3f> corners;
  std::size_t facets = 0;
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  float rayOriginX = 0;
  bool slab = false, ray = false;
  SlabTree tree;
  std::string error;

  ~Impl() {
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }

  void check(const char* what) const {
    if (!error.empty() || rtcGetDeviceError(device) != RTC_ERROR_NONE)
      throw std::runtime_error(std::string("Embree: ") + what + " failed" +
                               (error.empty() ? "" : ": " + error));
  }

  void buildSlabTree();
  void buildRayScene();
};

namespace {

struct RayContext {
  RTCIntersectContext base;  // first member: Embree hands this pointer back to the callbacks
  const Point3f* corners;
  double y, z;
  std::vector<RayCrossing>* out;
};

void facetBounds(const RTCBoundsFunctionArguments* args) {
  const auto* corners = static_cast<const Point3f*>(args->geometryUserPtr);
  const Point3f* c = corners + 3 * std::size_t{args->primID};
  RTCBounds* b = args->bounds_o;
  // One float step outward, so that the float ray (the query's y and z rounded) lies inside the box of
  // every facet the exact test may accept, even on the box's boundary.
  b->lower_x = below(std::min({c[0].x, c[1].x, c[2].x}));
  b->lower_y = below(std::min({c[0].y, c[1].y, c[2].y}));
  b->lower_z = below(std::min({c[0].z, c[1].z, c[2].z}));
  b->upper_x = above(std::max({c[0].x, c[1].x, c[2].x}));
  b->upper_y = above(std::max({c[0].y, c[1].y, c[2].y}));
  b->upper_z = above(std::max({c[0].z, c[1].z, c[2].z}));
}

void intersectFacet(const RTCIntersectFunctionNArguments* args) {
  if (args->N != 1 || args->valid[0] == 0) return;  // only rtcIntersect1 is used
  auto* ctx = reinterpret_cast<RayContext*>(args->context);
  RayCrossing crossing{0, args->primID, 0};
  if (lineCrossesFacet(ctx->corners + 3 * std::size_t{args->primID}, ctx->y, ctx->z, crossing.x,
                       crossing.step))
    ctx->out->push_back(crossing);
  // The hit is neither committed nor the ray shortened: traversal goes on to every box the ray touches.
}

void occludedNothing(const RTCOccludedFunctionNArguments*) {}

void reportError(void* userPtr, RTCError, const char* message) {
  auto* error = static_cast<std::string*>(userPtr);
  if (error->empty()) *error = message ? message : "unknown error";
}

}  // namespace

void FacetBvh::Impl::buildSlabTree() {
  std::vector<RTCBuildPrimitive> prims(facets);
  for (std::size_t f = 0; f < facets; ++f) {
    const Point3f* c = &corners[3 * f];
    const float zmin = std::min({c[0].z, c[1].z, c[2].z}), zmax = std::max({c[0].z, c[1].z, c[2].z});
    // The builder sees each facet as the cube [zmin, zmax]^3: its SAH then splits only by z extent, which
    // is what slab queries prune on (x and y extents would only make z ranges of sibling nodes overlap).
    prims[f] = {zmin, zmin, zmin, 0u, zmax, zmax, zmax, static_cast<unsigned>(f)};
  }
  // The builder's nodes live in the RTCBVH's memory until it is released, after the flat copy is made.
  const std::unique_ptr<RTCBVHTy, decltype(&rtcReleaseBVH)> bvh(rtcNewBVH(device), rtcReleaseBVH);
  RTCBuildArguments args = rtcDefaultBuildArguments();
  args.buildQuality = RTC_BUILD_QUALITY_MEDIUM;
  args.maxBranchingFactor = kBranching;
  args.maxDepth = kMaxDepth;
  args.minLeafSize = 1;
  args.maxLeafSize = 16;
  args.bvh = bvh.get();
  args.primitives = prims.data();
  args.primitiveCount = prims.size();
  args.primitiveArrayCapacity = prims.size();
  args.createNode = createNode;
  args.setNodeChildren = setNodeChildren;
  args.setNodeBounds = setNodeBounds;
  args.createLeaf = createLeaf;
  const void* root = rtcBuildBVH(&args);
  check("building the slab BVH");
  if (root == nullptr) throw std::runtime_error("Embree: building the slab BVH failed");
  tree.entries.reserve(facets);
  tree.root = tree.flatten(root, 0);
}

void FacetBvh::Impl::buildRayScene() {
  scene = rtcNewScene(device);
  rtcSetSceneFlags(scene, RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_MEDIUM);
  RTCGeometry geometry = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_USER);
  rtcSetGeometryUserPrimitiveCount(geometry, static_cast<unsigned>(facets));
  void* user = const_cast<Point3f*>(corners.data());  // read only, by the callbacks above
  rtcSetGeometryUserData(geometry, user);
  rtcSetGeometryBoundsFunction(geometry, facetBounds, user);
  rtcSetGeometryIntersectFunction(geometry, intersectFacet);
  rtcSetGeometryOccludedFunction(geometry, occludedNothing);
  rtcCommitGeometry(geometry);
  rtcAttachGeometry(scene, geometry);
  rtcReleaseGeometry(geometry);
  rtcCommitScene(scene);
  check("building the ray scene");
  RTCBounds bounds;
  rtcGetSceneBounds(scene, &bounds);
  rayOriginX = bounds.lower_x - (1.0f + std::abs(bounds.lower_x));  // left of every box
}

FacetBvh::FacetBvh(std::span<const Point3f> corners, unsigned queries) : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.corners = corners;
  m.facets = corners.size() / 3;
  if (m.facets >= kLeafBit) throw std::runtime_error("FacetBvh: too many facets");
  m.slab = (queries & kSlabQueries) != 0;
  m.ray = (queries & kRayQueries) != 0;
  if (m.facets == 0) return;  // every query answers nothing
  m.device = rtcNewDevice(nullptr);
  if (m.device == nullptr) throw std::runtime_error("Embree: cannot create a device");
  rtcSetDeviceErrorFunction(m.device, reportError, &m.error);
  if (m.slab) m.buildSlabTree();
  if (m.ray) m.buildRayScene();
}

FacetBvh::~FacetBvh() = default;
FacetBvh::FacetBvh(FacetBvh&&) noexcept = default;
FacetBvh& FacetBvh::operator=(FacetBvh&&) noexcept = default;

std::size_t FacetBvh::facetCount() const {
  return impl_->facets;
}

void FacetBvh::facetsInSlab(double zlo, double zhi, std::vector<uint32_t>& out, FacetOrder order) const {
  assert(impl_->slab || impl_->facets == 0);
  out.clear();
  const auto overlaps = [zlo, zhi](float lo, float hi) { return lo <= zhi && hi >= zlo; };
  impl_->tree.walk(overlaps, overlaps, out);
  if (order == FacetOrder::Ascending) std::sort(out.begin(), out.end());
}

void FacetBvh::facetsCrossingPlane(double z, std::vector<uint32_t>& out, FacetOrder order) const {
  assert(impl_->slab || impl_->facets == 0);
  out.clear();
  // A subtree's range holds its facets' ranges, so zmin < z <= zmax for a facet implies it for the node.
  const auto crosses = [z](float lo, float hi) { return lo < z && z <= hi; };
  impl_->tree.walk(crosses, crosses, out);
  if (order == FacetOrder::Ascending) std::sort(out.begin(), out.end());
}

void FacetBvh::rayCrossings(double y, double z, std::vector<RayCrossing>& out) const {
  assert(impl_->ray || impl_->facets == 0);
  out.clear();
  if (impl_->scene == nullptr) return;
  RayContext ctx;
  rtcInitIntersectContext(&ctx.base);
  ctx.corners = impl_->corners.data();
  ctx.y = y;
  ctx.z = z;
  ctx.out = &out;
  RTCRayHit rayhit;
  rayhit.ray.org_x = impl_->rayOriginX;
  rayhit.ray.org_y = static_cast<float>(y);
  rayhit.ray.org_z = static_cast<float>(z);
  rayhit.ray.tnear = 0;
  rayhit.ray.dir_x = 1;
  rayhit.ray.dir_y = 0;
  rayhit.ray.dir_z = 0;
  rayhit.ray.time = 0;
  rayhit.ray.tfar = kInf;
  rayhit.ray.mask = 0xFFFFFFFFu;
  rayhit.ray.id = 0;
  rayhit.ray.flags = 0;
  rayhit.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rayhit.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &ctx.base, &rayhit);
  std::sort(out.begin(), out.end(), [](const RayCrossing& a, const RayCrossing& b) {
    return a.x != b.x ? a.x < b.x : a.facet < b.facet;
  });
  // A facet referenced by two leaves would be reported twice, at the same x: keep one.
  out.erase(std::unique(out.begin(), out.end()), out.end());
}

void startRecordsFromBvh(const FacetBvh& bvh, const MarchMesh& mesh, double z, uint32_t layer,
                         std::vector<uint32_t>& records) {
  bvh.facetsCrossingPlane(z, records, FacetOrder::Any);
  std::size_t kept = 0;
  for (const uint32_t f : records) {
    const int32_t p = mesh.position[f];
    if (p < 0) continue;  // a degenerate facet: it crosses nothing in the slicer
    assert(static_cast<uint32_t>(p) < mesh.layerStart[layer + 1] &&
           mesh.last[static_cast<uint32_t>(p)] >= layer);
    records[kept++] = static_cast<uint32_t>(p);
  }
  records.resize(kept);
  (void)layer;
}

}  // namespace toposlice
