// Welding: facet corners with bit-identical float coordinates become one vertex (-0.0 equals +0.0).
// No tolerance: STL writers emit shared corners with identical bits, and a tolerance would merge
// distinct features of fine models. Vertices are numbered in order of first appearance, so the result
// depends only on the soup. Expected linear time (open-addressing hash on the coordinate bits).
// With a parallel runner (core/chunk_runner.h) large soups are welded in parallel: corners are
// partitioned by hash, each partition finds first occurrences, and a prefix sum numbers them, so the
// result is the same, bit for bit, for any runner and thread count.
#pragma once

#include <span>

#include "core/chunk_runner.h"
#include "core/mesh/mesh.h"

namespace toposlice {

IndexedMesh weldCorners(std::span<const Point3f> corners, const ChunkRunner& runner = serialChunkRunner());

}  // namespace toposlice
