// Footprints of parts on a build plate and nesting them (issue "Build plates").
//
// A footprint is the outline of a part's projection onto the plate, kept as the centres of the occupied
// cells of a square grid (cell edge `cell` mm) in the part's own frame: every cell that the xy projection
// of a facet touches is occupied, so the cells cover the real outline (concave arches stay concave, and
// other parts may nest into them). Placing a footprint (rotation about the model's z axis through its
// origin, then a translation) marks every plate cell within half a cell diagonal of a rotated centre,
// plus `grow` mm: a conservative cover, never smaller than the part. Plate cells start at the plate's
// lower-left corner (0, 0).
//
// Nesting is greedy and serial, so the same input gives the same placements on every run and thread
// count: parts by decreasing footprint area (ties: input order), each at the lowest, then leftmost,
// free position over the allowed rotations, on the first plate where it fits, opening plates as needed.
// Spacing: the parts' covers, each grown by half the spacing, share no cell (so the parts are at least
// `spacing` apart); margin: no part's cover within `margin` mm of the plate's edge.
#pragma once

#include <atomic>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/chunk_runner.h"
#include "core/mesh/mesh.h"
#include "core/slicing/contours.h"

namespace toposlice {

struct Footprint {
  double cell = 0.5;             // mm
  std::vector<Point2d> centres;  // occupied cells' centres in the model's frame, row by row
  double area() const { return static_cast<double>(centres.size()) * cell * cell; }  // mm^2
};

// The footprint of `corners` (3 per facet) on a grid of `cell` mm aligned at the model's origin.
// Degenerate (zero-area) projections still mark the cells their edges cross. O(facets + cells).
Footprint projectFootprint(std::span<const Point3f> corners, double cell);

// The footprint of several corner lists together (a part and its add-ons), their facets split over the
// runner's chunks, each marking a window of its own that are then merged: the same cells as one list of
// them all on one thread, for any runner.
Footprint projectFootprint(std::span<const std::span<const Point3f>> lists, double cell,
                           const ChunkRunner& runner);

// cos and sin of `degrees`, exact (0, +-1) for multiples of 90.
void rotationCosSin(double degrees, double& c, double& s);

// Plate cells covered by a placed footprint: rows j0 .. j0 + rows - 1, each a list of [begin, end) cell
// columns (absolute plate columns, may be negative outside the plate).
struct CellShape {
  int32_t j0 = 0;
  std::vector<uint32_t> rowOffsets{0};             // row r's spans are [rowOffsets[r], rowOffsets[r+1])
  std::vector<std::pair<int32_t, int32_t>> spans;  // [begin, end) columns
  int32_t minI = 0, maxI = 0;                      // column range covered: [minI, maxI)
  uint32_t rows() const { return static_cast<uint32_t>(rowOffsets.size() - 1); }
  bool empty() const { return spans.empty(); }
};

// The footprint rotated by `degrees` about the model's origin, translated by (tx, ty) mm and grown by
// `grow` mm, on the plate's cell grid (cells of footprint.cell mm from (0, 0)).
CellShape placeFootprint(const Footprint& footprint, double degrees, double tx, double ty, double grow);

// `shape` moved by (di, dj) cells.
CellShape shiftShape(CellShape shape, int32_t di, int32_t dj);

// True when the two shapes share a cell.
bool shapesOverlap(const CellShape& a, const CellShape& b);

// The distance in the plate's xy plane between the projections of two parts, each given as lists of
// corners (3 per facet) moved by (ax, ay) and (bx, by) mm: the smallest distance between a projected
// facet of one and one of the other, 0 where they overlap or touch (exact up to floating-point
// rounding). Only facets closer than `limit` mm to the other part's bounding box are compared: returns
// min(distance, limit). For given placements, whose cell covers (placeFootprint) are conservative by
// up to a few cells.
double projectionDistance(std::span<const std::span<const Point3f>> a, double ax, double ay,
                          std::span<const std::span<const Point3f>> b, double bx, double by, double limit);

struct ArrangeSettings {
  double plateWidth = 0, plateHeight = 0;     // mm, the printable area from (0, 0)
  double margin = 0;                          // mm kept free along every edge
  double spacing = 1;                         // mm between parts
  double rotationStep = 90;                   // degrees tried: 0, step, 2 step, ... < 360; 0: no rotation
  const std::atomic<bool>* cancel = nullptr;  // when set and true, arranging stops between parts
};

struct ArrangeItem {
  const Footprint* footprint = nullptr;  // cell sizes must all be equal
  // A given placement (plate 0): the part is kept there and the others are nested around it.
  std::optional<double> fixedRotation, fixedTx, fixedTy;
};

struct ArrangedPart {
  uint32_t plate = 0;
  double rotation = 0;    // degrees, about the model's origin
  double tx = 0, ty = 0;  // mm, after the rotation
};

struct Arrangement {
  std::vector<ArrangedPart> parts;  // one per item, in item order
  uint32_t plates = 0;
  std::vector<double> footprintArea;  // per plate: the placed footprints' area, mm^2
  double usableArea = 0;              // mm^2 of one plate inside the margin
  bool cancelled = false;             // stopped by ArrangeSettings::cancel: the placements are partial
  double density(uint32_t plate) const { return usableArea > 0 ? footprintArea[plate] / usableArea : 0; }
};

// Nests the items (see the file comment). Throws std::invalid_argument naming the item index when a
// part fits no empty plate; the caller turns it into a message with the part's name.
Arrangement arrangeFootprints(std::span<const ArrangeItem> items, const ArrangeSettings& settings);

// Baseline for comparisons: shelf packing of the footprints' axis-aligned bounding boxes (rotation 0
// or 90, whichever is lower), boxes grown by the spacing, by decreasing height, new shelf when a row is
// full, new plate when no shelf fits. Same result type.
Arrangement shelfPackBoxes(std::span<const ArrangeItem> items, const ArrangeSettings& settings);

}  // namespace toposlice
