// Following loops from one layer to the next: the `sr` kernel for meshes whose table has no gaps.
//
// Between planes z_{k-1} < z_k a crossed facet keeps its two crossed edges, and so its place in its loop,
// unless one of its corners lies in [z_{k-1}, z_k): its top corner (it stops crossing), its middle
// corner (one crossed edge is swapped for another) or its bottom corner (it starts crossing). At 1 um
// that is a few hundred facets per layer out of thousands, so instead of walking the table for every
// segment of every layer, the follower keeps each loop of the last layer as an array of segments (the
// facet, the line of its entry edge, the last layer it stays valid; stored once, in an arena, and moved
// from layer to layer as 4-byte handles) and builds layer k from it:
//   - each loop is cut into runs of segments still valid at k, which carry over unchanged;
//   - from the end of a run the table is walked through the changed facets until the start of the next
//     run (which may come from another loop: splits and merges need no special case);
//   - loops made only of changed or new facets are walked from those facets.
// Correctness: a valid facet keeps its entry and exit edge, so its neighbours across them are the same
// as at k - 1; a walk reaching a valid facet therefore reaches the start of a run. Every point is
// recomputed from its edge line for z_k (crossing.h), never accumulated, and the loops are put in
// canonical order (DESIGN.md) as the marching kernel does, so the output equals slice_march.h's bit for
// bit (tested on every closed model).
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/slicing/contours.h"
#include "core/slicing/march_mesh.h"

namespace toposlice {

class LoopFollower {
 public:
  // Slices layer k from scratch. `active` lists the records crossing z (any order); the mesh must have
  // no missing neighbours (MarchMesh::missingNeighbours == 0). Returns false only on an inconsistent
  // table (a walk that does not close), leaving `out` unspecified.
  bool start(const MarchMesh& mesh, std::span<const uint32_t> active, uint32_t k, double z,
             LayerContours& out);

  // Slices layer k, the layer after the last one sliced, from its loops. Returns false when the layer
  // could not be followed (an inconsistent table); then start() it from scratch.
  bool advance(const MarchMesh& mesh, uint32_t k, double z, LayerContours& out);

 private:
  struct Line {  // the loop enters facet `record` across the edge whose line is (a, s): 32 bytes
    double sx, sy;
    float ax, ay, az;
    uint32_t record;  // in MarchMesh::facets
  };
  // Every segment made since the last start, as three arrays indexed by a segment's handle. A segment
  // never changes while it lives, so layer to layer the loops move only as arrays of handles; the cut
  // into runs reads only `until` and `id`.
  struct Arena {
    std::vector<Line> lines;
    std::vector<uint32_t> until;  // last layer with the same crossed edges
    std::vector<uint32_t> id;     // facet index in the model
    uint32_t size() const { return static_cast<uint32_t>(lines.size()); }
    void clear() {
      lines.clear();
      until.clear();
      id.clear();
    }
    void push(const Line& line, uint32_t last, uint32_t facet) {
      lines.push_back(line);
      until.push_back(last);
      id.push_back(facet);
    }
  };
  struct Run {  // segments [begin, begin + length) of an old loop, cyclically within [loop, loop + size)
    uint32_t loop, size, begin, length;
    uint32_t lowestId, lowestAt;  // its lowest facet index and where (in handles_)
    bool used;
  };
  // A stretch of a loop being built: positions [begin, begin + length) of handles_ (runs, loops carried
  // over whole), or the segments with handles [begin, begin + length) (facets walked this layer).
  enum Source : uint32_t { kOld = 0, kWalkedSource = 1 };
  struct Piece {
    Source source;
    uint32_t begin, length;
    uint32_t lowestId, lowestAt;  // UINT32_MAX when the stretch cannot hold the loop's lowest index
  };
  struct LoopOrder {  // a loop of the layer being built: pieces [firstPiece, endPiece)
    uint32_t lowestId, lowestPiece, lowestAt, firstPiece, endPiece;
  };
  struct Mark {  // per record, valid when generation matches: walked this layer, or the start of a run
    uint32_t generation;
    uint32_t run;
  };
  static constexpr uint32_t kWalked = UINT32_MAX;

  void beginLayer(const MarchMesh& mesh, uint32_t k, double z);
  bool traceLoop(const MarchMesh& mesh, uint32_t startRecord);
  void addRun(const Run& run);
  void endLoop(uint32_t firstPiece);
  void emitCanonical(LayerContours& out);
  void compactArena();

  Arena arena_;
  std::vector<uint32_t> handles_, nextHandles_;  // last layer's loops (canonical), the next layer's
  std::vector<uint32_t> loops_{0}, nextLoops_;   // loop offsets into handles_ / nextHandles_
  std::vector<Piece> pieces_;
  std::vector<LoopOrder> order_;
  std::vector<Run> runs_;
  std::vector<uint32_t> seeds_;
  std::vector<Mark> marks_;
  uint32_t generation_ = 0, layer_ = 0;
  bool following_ = false;  // handles_ holds layer_'s loops
  double z_ = 0;
  float zf_ = 0;
};

}  // namespace toposlice
