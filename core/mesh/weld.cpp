#include "core/mesh/weld.h"

#include <algorithm>
#include <cstring>
#include <memory>
#include <utility>

#include "core/memory_advice.h"

namespace toposlice {
namespace {

using CornerKey = WeldKey;  // both zeros hash and compare alike

inline uint64_t hashKey(const CornerKey& k) {
  uint64_t h = (uint64_t{k.x} << 32 | k.y) * 0x9E3779B97F4A7C15ull;
  h ^= (uint64_t{k.z} + 0x632BE59BD9B4E019ull) * 0xC2B2AE3D27D4EB4Full;
  return h ^ (h >> 29);
}

constexpr uint32_t kEmpty = 0xFFFFFFFFu;

IndexedMesh weldSerially(std::span<const Point3f> corners) {
  IncrementalWeld weld(corners.size());
  constexpr std::size_t kPiece = std::size_t{1} << 16;  // corners: the table grows only as vertices come
  for (std::size_t at = 0; at < corners.size(); at += kPiece)
    weld.add(corners.subspan(at, std::min(kPiece, corners.size() - at)));
  return weld.take();
}

// The split weld. Corners are partitioned by their hash, so equal corners meet in one partition; each
// partition, scanning the corners in order, finds every corner's first occurrence on its own; then the
// first occurrences are numbered in corner order by a prefix sum. Every step writes only what its chunk
// or partition owns, and the numbering is the serial one whatever ran the pieces or how many there are.
IndexedMesh weldSplit(std::span<const Point3f> corners, const ChunkRunner& runner) {
  constexpr std::size_t kChunk = std::size_t{1} << 16;  // corners
  const std::size_t n = corners.size(), chunks = (n + kChunk - 1) / kChunk;
  const unsigned parts = std::min(64u, 2 * runner.width);
  auto chunkEnd = [&](std::size_t c) { return std::min(n, (c + 1) * kChunk); };
  const std::unique_ptr<uint8_t[]> part = uninitializedArray<uint8_t>(n);
  std::vector<uint32_t> partSize(chunks * parts, 0);
  runner.run(chunks, 1, [&](std::size_t c0, std::size_t c1) {
    for (std::size_t c = c0; c < c1; ++c)
      for (std::size_t i = c * kChunk; i < chunkEnd(c); ++i) {
        const auto p = static_cast<uint8_t>(((hashKey(weldKey(corners[i])) >> 32) * parts) >> 32);
        part[i] = p;
        ++partSize[c * parts + p];
      }
  });
  // The chunks file their corners by partition (partition after partition, each in corner order), so
  // each partition reads only its own. (Gathering them instead from a scan of all corners per partition
  // cost more from 4 partitions on, and grew with their number: BM_WeldSplit, the aligner, 2 threads,
  // 4 partitions 14.8 ms filed against 15.6 gathered, 16 partitions 16.4 against 21.4.)
  const std::unique_ptr<uint32_t[]> members = uninitializedArray<uint32_t>(n);  // every partition's corners
  // partSize: from here, each chunk's next position in `members`
  const std::vector<std::size_t> partBegin = filePositions(std::span(partSize), chunks, parts);
  runner.run(chunks, 1, [&](std::size_t c0, std::size_t c1) {
    for (std::size_t c = c0; c < c1; ++c)
      for (std::size_t i = c * kChunk; i < chunkEnd(c); ++i)
        members[partSize[c * parts + part[i]]++] = static_cast<uint32_t>(i);
  });
  // Each corner's first occurrence, and how many first occurrences each chunk and partition holds.
  const std::unique_ptr<uint32_t[]> first = uninitializedArray<uint32_t>(n);
  std::vector<uint32_t> firsts(chunks * parts, 0);
  runner.run(parts, 1, [&](std::size_t p0, std::size_t p1) {
    std::vector<uint32_t> table;                       // per slot an index into `seen` or kEmpty
    std::vector<std::pair<CornerKey, uint32_t>> seen;  // each key met, with its first corner
    for (std::size_t p = p0; p < p1; ++p) {
      const std::size_t count = partBegin[p + 1] - partBegin[p];
      std::size_t capacity = 16;
      while (capacity < count * 2) capacity <<= 1;
      const uint64_t mask = capacity - 1;
      table.assign(capacity, kEmpty);
      seen.clear();
      seen.reserve(count / 4 + 16);
      const uint32_t* const own = members.get() + partBegin[p];
      for (std::size_t m = 0; m < count; ++m) {
        const std::size_t i = own[m];
        const CornerKey key = weldKey(corners[i]);
        for (uint64_t slot = hashKey(key) & mask;; slot = (slot + 1) & mask) {
          const uint32_t k = table[slot];
          if (k == kEmpty) {
            table[slot] = static_cast<uint32_t>(seen.size());
            seen.emplace_back(key, static_cast<uint32_t>(i));
            first[i] = static_cast<uint32_t>(i);
            ++firsts[(i / kChunk) * parts + p];
            break;
          }
          const CornerKey& other = seen[k].first;
          if (other == key) {
            first[i] = seen[k].second;
            break;
          }
        }
      }
    }
  });
  std::vector<uint32_t> base(chunks + 1, 0);  // vertices numbered before each chunk
  for (std::size_t c = 0; c < chunks; ++c) {
    base[c + 1] = base[c];
    for (unsigned p = 0; p < parts; ++p) base[c + 1] += firsts[c * parts + p];
  }
  IndexedMesh mesh;
  resizeFaultedIn(mesh.vertices, base[chunks], runner);
  resizeFaultedIn(mesh.facetVertices, n, runner);
  runner.run(chunks, 1, [&](std::size_t c0, std::size_t c1) {
    for (std::size_t c = c0; c < c1; ++c) {
      uint32_t v = base[c];
      for (std::size_t i = c * kChunk; i < chunkEnd(c); ++i)
        if (first[i] == i) {
          mesh.facetVertices[i] = v;
          mesh.vertices[v++] = corners[i];
        }
    }
  });
  runner.run(chunks, 1, [&](std::size_t c0, std::size_t c1) {
    for (std::size_t i = c0 * kChunk; i < chunkEnd(c1 - 1); ++i)
      if (first[i] != i) mesh.facetVertices[i] = mesh.facetVertices[first[i]];
  });
  return mesh;
}

}  // namespace

IncrementalWeld::IncrementalWeld(std::size_t expectedCorners) {
  std::size_t capacity = 16;
  // Closed meshes share each corner among about six facets: a table for corners / 2 stays at most half
  // full, and it doubles (the vertices re-inserted) before a piece could fill it past half.
  while (capacity < expectedCorners / 2) capacity <<= 1;
  mask_ = capacity - 1;
  reserveHugePages(table_, capacity);
  table_.assign(capacity, kEmpty);
  reserveHugePages(keys_, expectedCorners / 4 + 16);
  reserveHugePages(mesh_.vertices, expectedCorners / 4 + 16);
  reserveHugePages(mesh_.facetVertices, expectedCorners);
}

void IncrementalWeld::add(std::span<const Point3f> corners) {
  if (2 * (keys_.size() + corners.size()) > table_.size()) {
    // The piece could fill the table past half: a table twice as large, the vertices re-inserted.
    std::size_t capacity = table_.size();
    while (capacity < 2 * (keys_.size() + corners.size())) capacity <<= 1;
    mask_ = capacity - 1;
    table_.assign(capacity, kEmpty);
    for (std::size_t v = 0; v < keys_.size(); ++v) {
      uint64_t slot = hashKey(keys_[v]) & mask_;
      while (table_[slot] != kEmpty) slot = (slot + 1) & mask_;
      table_[slot] = static_cast<uint32_t>(v);
    }
  }
  const std::size_t at = mesh_.facetVertices.size();
  mesh_.facetVertices.resize(at + corners.size());
  uint32_t* const out = mesh_.facetVertices.data() + at;
  for (std::size_t c = 0; c < corners.size(); ++c) {
    const CornerKey key = weldKey(corners[c]);
    uint64_t slot = hashKey(key) & mask_;
    for (;;) {
      const uint32_t v = table_[slot];
      if (v == kEmpty) {
        const auto index = static_cast<uint32_t>(keys_.size());
        table_[slot] = index;
        keys_.push_back(key);
        mesh_.vertices.push_back(corners[c]);
        out[c] = index;
        break;
      }
      if (keys_[v] == key) {
        out[c] = v;
        break;
      }
      slot = (slot + 1) & mask_;
    }
  }
}

IndexedMesh weldCorners(std::span<const Point3f> corners, const ChunkRunner& runner) {
  constexpr std::size_t kSplitFrom = std::size_t{1}
                                     << 17;  // corners; below, the split costs more than it saves
  // The split does about 2.5 times the serial work (the aligner, BM_WeldSplit on 1 thread: 27 ms against
  // 11 ms serial), so it gains from 4 threads on; on 2 it took 14.8 ms against the serial 10.8.
  constexpr unsigned kSplitFromWidth = 4;
  if (runner.width < kSplitFromWidth || corners.size() < kSplitFrom) return weldSerially(corners);
  return weldSplit(corners, runner);
}

}  // namespace toposlice
