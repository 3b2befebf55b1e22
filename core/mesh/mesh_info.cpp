#include "core/mesh/mesh_info.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <vector>

namespace toposlice {

BoundingBox boundsOf(std::span<const Point3f> points) {
  BoundingBox box;
  if (points.empty()) return box;
  box.min = box.max = points[0];
  for (const Point3f& p : points) {
    box.min = {std::min(box.min.x, p.x), std::min(box.min.y, p.y), std::min(box.min.z, p.z)};
    box.max = {std::max(box.max.x, p.x), std::max(box.max.y, p.y), std::max(box.max.z, p.z)};
  }
  return box;
}

double signedVolumeTerms(std::span<const Point3f> corners, const BoundingBox& bounds, std::size_t beginFacet,
                         std::size_t endFacet) {
  const double cx = 0.5 * (double{bounds.min.x} + bounds.max.x),
               cy = 0.5 * (double{bounds.min.y} + bounds.max.y),
               cz = 0.5 * (double{bounds.min.z} + bounds.max.z);
  double sum = 0;
  for (std::size_t c = 3 * beginFacet; c < 3 * endFacet; c += 3) {
    const double ax = corners[c].x - cx, ay = corners[c].y - cy, az = corners[c].z - cz;
    const double bx = corners[c + 1].x - cx, by = corners[c + 1].y - cy, bz = corners[c + 1].z - cz;
    const double dx = corners[c + 2].x - cx, dy = corners[c + 2].y - cy, dz = corners[c + 2].z - cz;
    sum += ax * (by * dz - bz * dy) - ay * (bx * dz - bz * dx) + az * (bx * dy - by * dx);
  }
  return sum;
}

double signedVolume(std::span<const Point3f> corners) {
  return signedVolumeTerms(corners, boundsOf(corners), 0, corners.size() / 3) / 6.0;
}

double surfaceArea(std::span<const Point3f> corners) {
  double sum = 0;
  for (std::size_t c = 0; c + 2 < corners.size(); c += 3) {
    const double ux = double{corners[c + 1].x} - corners[c].x, uy = double{corners[c + 1].y} - corners[c].y,
                 uz = double{corners[c + 1].z} - corners[c].z;
    const double vx = double{corners[c + 2].x} - corners[c].x, vy = double{corners[c + 2].y} - corners[c].y,
                 vz = double{corners[c + 2].z} - corners[c].z;
    const double nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
    sum += 0.5 * std::sqrt(nx * nx + ny * ny + nz * nz);
  }
  return sum;
}

uint64_t countShells(std::span<const uint32_t> facetVertices, std::size_t vertexCount) {
  std::vector<uint32_t> parent(vertexCount);
  std::iota(parent.begin(), parent.end(), 0u);
  auto find = [&](uint32_t v) {
    while (parent[v] != v) v = parent[v] = parent[parent[v]];
    return v;
  };
  std::vector<uint8_t> used(vertexCount, 0);
  for (std::size_t c = 0; c + 2 < facetVertices.size(); c += 3) {
    used[facetVertices[c]] = used[facetVertices[c + 1]] = used[facetVertices[c + 2]] = 1;
    for (int k = 1; k < 3; ++k) {
      const uint32_t a = find(facetVertices[c]);
      const uint32_t b = find(facetVertices[c + k]);
      if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
  }
  uint64_t shells = 0;
  for (uint32_t v = 0; v < vertexCount; ++v) shells += (used[v] && find(v) == v) ? 1 : 0;
  return shells;
}

}  // namespace toposlice
