#include "core/slicing/slice_follow.h"

#include <algorithm>
#include <cstring>

#include "core/prefetch.h"
#include "core/slicing/crossing.h"

namespace toposlice {

void LoopFollower::beginLayer(const MarchMesh& mesh, uint32_t k, double z) {
  if (marks_.size() != mesh.facets.size() || ++generation_ == 0) {
    marks_.assign(mesh.facets.size(), Mark{0, 0});
    generation_ = 1;
  }
  following_ = false;
  layer_ = k;
  z_ = z;
  zf_ = planeAsFloat(z);
  pieces_.clear();
  order_.clear();
  runs_.clear();
  seeds_.clear();
}

void LoopFollower::addRun(const Run& run) {
  const uint32_t head = std::min(run.length, run.size - run.begin);
  const uint32_t begin = run.loop + run.begin;
  const bool lowestInHead = run.lowestAt >= begin && run.lowestAt < begin + head;
  pieces_.push_back({kOld, begin, head, lowestInHead ? run.lowestId : UINT32_MAX, run.lowestAt});
  if (run.length > head)
    pieces_.push_back(
        {kOld, run.loop, run.length - head, lowestInHead ? UINT32_MAX : run.lowestId, run.lowestAt});
}

void LoopFollower::endLoop(uint32_t firstPiece) {
  const auto endPiece = static_cast<uint32_t>(pieces_.size());
  LoopOrder o{UINT32_MAX, firstPiece, 0, firstPiece, endPiece};
  for (uint32_t p = firstPiece; p < endPiece; ++p)
    if (pieces_[p].lowestId < o.lowestId) {
      o.lowestId = pieces_[p].lowestId;
      o.lowestPiece = p;
      o.lowestAt = pieces_[p].lowestAt;
    }
  order_.push_back(o);
}

// Walks one loop of the current layer from `startRecord` (an unwalked record or the start of an unused
// run): through changed facets by the table, across runs, until it is back at the start.
bool LoopFollower::traceLoop(const MarchMesh& mesh, uint32_t startRecord) {
  const auto firstPiece = static_cast<uint32_t>(pieces_.size());
  auto walkBegin = arena_.size();
  uint32_t walkLowest = UINT32_MAX, walkLowestAt = 0;
  auto endWalk = [&] {
    const auto end = arena_.size();
    if (end > walkBegin)
      pieces_.push_back({kWalkedSource, walkBegin, end - walkBegin, walkLowest, walkLowestAt});
    walkBegin = end;
    walkLowest = UINT32_MAX;
  };
  uint32_t r = startRecord;
  for (;;) {
    Mark& mark = marks_[r];
    if (mark.generation == generation_) {
      if (mark.run == kWalked || runs_[mark.run].used) {
        if (r != startRecord) return false;  // joined another loop: the table is inconsistent
        break;
      }
      Run& run = runs_[mark.run];
      run.used = true;
      endWalk();
      addRun(run);
      r = arena_.lines[handles_[run.loop + (run.begin + run.length) % run.size]].record;
      continue;
    }
    const MarchFacet& f = mesh.facets[r];
    const unsigned mask = aboveMaskF(f.corner, zf_);
    if (!crossesPlane(mask)) return false;
    const EdgeLine line = edgeLine(f.corner, kDownEdge[mask], z_);
    if (f.id < walkLowest) {
      walkLowest = f.id;
      walkLowestAt = arena_.size();
    }
    arena_.push({line.sx, line.sy, line.ax, line.ay, line.az, r}, layer_ < f.mid ? f.mid - 1 : f.last, f.id);
    mark = {generation_, kWalked};
    const int32_t exit = f.next[kUpEdge[mask]];
    if (exit < 0) return false;
    r = static_cast<uint32_t>(exit);
  }
  endWalk();
  endLoop(firstPiece);
  return true;
}

// Writes the layer's loops in canonical form (DESIGN.md: each rotated to start at its lowest facet
// index, ordered by it; a facet has one segment per layer, so the lowest index is unique) into `out`,
// and the same segments, in the same order, as the loops to follow to the next layer.
void LoopFollower::emitCanonical(LayerContours& out) {
  std::sort(order_.begin(), order_.end(),
            [](const LoopOrder& a, const LoopOrder& b) { return a.lowestId < b.lowestId; });
  std::size_t total = 0;
  for (const Piece& p : pieces_) total += p.length;
  const std::size_t loops = order_.size();
  // Sized without clear(): only growth is initialised, then every element is overwritten.
  if (nextHandles_.size() < total) nextHandles_.resize(total);
  out.z = z_;
  out.points.resize(total);
  out.facets.resize(total);
  out.loopOffsets.resize(loops + 1);
  out.loopClosed.assign(loops, 1);
  nextLoops_.resize(loops + 1);
  // The handles in canonical order, stretch by stretch.
  uint32_t* const first = nextHandles_.data();
  uint32_t* to = first;
  auto copy = [&](Source source, uint32_t begin, uint32_t end) {
    if (source == kOld) {
      std::memcpy(to, handles_.data() + begin, (end - begin) * sizeof(uint32_t));
      to += end - begin;
    } else {
      for (uint32_t h = begin; h < end; ++h) *to++ = h;
    }
  };
  auto copyPiece = [&](const Piece& p) { copy(p.source, p.begin, p.begin + p.length); };
  out.loopOffsets[0] = 0;
  nextLoops_[0] = 0;
  for (std::size_t l = 0; l < loops; ++l) {
    const LoopOrder& o = order_[l];
    const Piece& lowest = pieces_[o.lowestPiece];
    copy(lowest.source, o.lowestAt, lowest.begin + lowest.length);
    for (uint32_t p = o.lowestPiece + 1; p < o.endPiece; ++p) copyPiece(pieces_[p]);
    for (uint32_t p = o.firstPiece; p < o.lowestPiece; ++p) copyPiece(pieces_[p]);
    copy(lowest.source, lowest.begin, o.lowestAt);
    out.loopOffsets[l + 1] = static_cast<uint32_t>(to - first);
    nextLoops_[l + 1] = static_cast<uint32_t>(to - first);
  }
  // Then each point from its segment's line, and its facet.
  const double z = z_;
  const Line* const line = arena_.lines.data();
  const uint32_t* const id = arena_.id.data();
  Point2d* const point = out.points.data();
  uint32_t* const facet = out.facets.data();
  for (std::size_t i = 0; i < total; ++i) {
    const uint32_t h = first[i];
    point[i] = EdgeLine{line[h].sx, line[h].sy, line[h].ax, line[h].ay, line[h].az}.at(z);
    facet[i] = id[h];
  }
  handles_.swap(nextHandles_);
  loops_.swap(nextLoops_);
  following_ = true;
  if (arena_.size() > 2 * total + 4096) compactArena();
}

// Keeps only the live segments, in loop order (the arena grows by the walked segments of each layer).
void LoopFollower::compactArena() {
  const std::size_t live = loops_.back();
  Arena kept;
  kept.lines.resize(live);
  kept.until.resize(live);
  kept.id.resize(live);
  for (std::size_t i = 0; i < live; ++i) {
    const uint32_t h = handles_[i];
    kept.lines[i] = arena_.lines[h];
    kept.until[i] = arena_.until[h];
    kept.id[i] = arena_.id[h];
    handles_[i] = static_cast<uint32_t>(i);
  }
  std::swap(arena_, kept);
}

bool LoopFollower::start(const MarchMesh& mesh, std::span<const uint32_t> active, uint32_t k, double z,
                         LayerContours& out) {
  beginLayer(mesh, k, z);
  arena_.clear();
  // The walk visits every active record in loop order, which is random in memory: fetching them all
  // first, in list order, overlaps the cache misses instead of taking them one after another.
  for (const uint32_t r : active) {
    prefetch(&mesh.facets[r]);
    prefetch(&marks_[r]);
  }
  for (const uint32_t r : active)
    if (marks_[r].generation != generation_ && !traceLoop(mesh, r)) return false;
  emitCanonical(out);
  return true;
}

bool LoopFollower::advance(const MarchMesh& mesh, uint32_t k, double z, LayerContours& out) {
  if (!following_ || k != layer_ + 1) return false;
  beginLayer(mesh, k, z);
  // Cut the last layer's loops into runs of segments still valid at k; untouched loops carry over whole.
  // The records of changed facets are fetched ahead: they are walked next, in table order.
  const std::size_t oldLoops = loops_.size() - 1;
  for (std::size_t l = 0; l < oldLoops; ++l) {
    const uint32_t begin = loops_[l], size = loops_[l + 1] - begin;
    const uint32_t* handle = handles_.data() + begin;
    const uint32_t* until = arena_.until.data();
    const uint32_t* id = arena_.id.data();
    uint32_t firstChanged = 0, lowestId = UINT32_MAX, lowestAt = 0;
    for (; firstChanged < size && until[handle[firstChanged]] >= k; ++firstChanged)
      if (id[handle[firstChanged]] < lowestId) {
        lowestId = id[handle[firstChanged]];
        lowestAt = begin + firstChanged;
      }
    if (firstChanged == size) {
      const auto firstPiece = static_cast<uint32_t>(pieces_.size());
      pieces_.push_back({kOld, begin, size, lowestId, lowestAt});
      endLoop(firstPiece);
      continue;
    }
    uint32_t i = firstChanged;
    do {  // loop[i] changed; the run after it ends at the next changed segment (firstChanged at the latest)
      const uint32_t record = arena_.lines[handle[i]].record;
      prefetch(&mesh.facets[record]);
      prefetch(&marks_[record]);
      if (mesh.last[record] >= k) seeds_.push_back(record);
      const uint32_t runBegin = i + 1 == size ? 0 : i + 1;
      uint32_t j = runBegin, length = 0;
      Run run{begin, size, runBegin, 0, UINT32_MAX, 0, false};
      while (until[handle[j]] >= k) {
        if (id[handle[j]] < run.lowestId) {
          run.lowestId = id[handle[j]];
          run.lowestAt = begin + j;
        }
        ++length;
        j = j + 1 == size ? 0 : j + 1;
      }
      if (length > 0) {
        run.length = length;
        marks_[arena_.lines[handle[runBegin]].record] = {generation_, static_cast<uint32_t>(runs_.size())};
        runs_.push_back(run);
      }
      i = j;
    } while (i != firstChanged);
  }
  // Loops through runs, then loops of changed facets only, then loops born at this layer.
  for (std::size_t r = 0; r < runs_.size(); ++r) {
    if (runs_[r].used) continue;
    if (!traceLoop(mesh, arena_.lines[handles_[runs_[r].loop + runs_[r].begin]].record)) return false;
  }
  for (const uint32_t r : seeds_)
    if (marks_[r].generation != generation_ && !traceLoop(mesh, r)) return false;
  for (uint32_t r = mesh.layerStart[k]; r < mesh.layerStart[k + 1]; ++r)
    if (marks_[r].generation != generation_ && !traceLoop(mesh, r)) return false;
  emitCanonical(out);
  return true;
}

}  // namespace toposlice
