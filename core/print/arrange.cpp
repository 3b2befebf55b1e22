#include "core/print/arrange.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <tuple>

#include "core/mesh/mesh_info.h"

namespace toposlice {
namespace {

int32_t cellOf(double v, double cell) {
  return static_cast<int32_t>(std::floor(v / cell));
}

// Occupancy bitmap over a window of cells: row-major bytes (small shapes) for building shapes.
struct CellWindow {
  int32_t i0 = 0, j0 = 0;
  uint32_t width = 0, height = 0;
  std::vector<uint8_t> cells;
  void reset(int32_t i0_, int32_t j0_, int32_t i1, int32_t j1) {
    i0 = i0_;
    j0 = j0_;
    width = static_cast<uint32_t>(std::max(0, i1 - i0 + 1));
    height = static_cast<uint32_t>(std::max(0, j1 - j0 + 1));
    cells.assign(static_cast<std::size_t>(width) * height, 0);
  }
  // Marks columns [a, b] (absolute, inclusive) of absolute row j.
  void markRow(int32_t j, int32_t a, int32_t b) {
    a = std::max(a, i0);
    b = std::min(b, i0 + static_cast<int32_t>(width) - 1);
    if (j < j0 || j >= j0 + static_cast<int32_t>(height) || a > b) return;
    uint8_t* row = cells.data() + static_cast<std::size_t>(j - j0) * width;
    std::fill(row + (a - i0), row + (b - i0) + 1, uint8_t{1});
  }
};

// The x range of triangle (a, b, c) within the slab y0 <= y <= y1; false when it misses the slab.
bool slabRange(const Point2d* t, double y0, double y1, double& xmin, double& xmax) {
  xmin = INFINITY;
  xmax = -INFINITY;
  for (int k = 0; k < 3; ++k) {
    const Point2d p = t[k], q = t[(k + 1) % 3];
    if (p.y >= y0 && p.y <= y1) {
      xmin = std::min(xmin, p.x);
      xmax = std::max(xmax, p.x);
    }
    for (const double y : {y0, y1}) {
      if ((p.y < y) == (q.y < y) || p.y == q.y) continue;
      const double x = p.x + (y - p.y) / (q.y - p.y) * (q.x - p.x);
      xmin = std::min(xmin, x);
      xmax = std::max(xmax, x);
    }
  }
  return xmin <= xmax;
}

// ---- Distances between projected facets ----

struct Triangle2 {
  Point2d p[3];
  double x0, y0, x1, y1;  // bounding box
};

double cross(const Point2d& o, const Point2d& a, const Point2d& b) {
  return (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x);
}

double pointSegmentDistance(const Point2d& p, const Point2d& a, const Point2d& b) {
  const double dx = b.x - a.x, dy = b.y - a.y, length2 = dx * dx + dy * dy;
  double t = length2 > 0 ? ((p.x - a.x) * dx + (p.y - a.y) * dy) / length2 : 0.0;
  t = std::clamp(t, 0.0, 1.0);
  return std::hypot(p.x - (a.x + t * dx), p.y - (a.y + t * dy));
}

// Whether closed segments ab and cd share a point.
bool segmentsMeet(const Point2d& a, const Point2d& b, const Point2d& c, const Point2d& d) {
  const double d1 = cross(c, d, a), d2 = cross(c, d, b), d3 = cross(a, b, c), d4 = cross(a, b, d);
  if (((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0))) return true;
  // Touching or collinear: some end lies on the other segment.
  return pointSegmentDistance(a, c, d) == 0 || pointSegmentDistance(b, c, d) == 0 ||
         pointSegmentDistance(c, a, b) == 0 || pointSegmentDistance(d, a, b) == 0;
}

// Inside or on a triangle of either orientation (a degenerate one contains nothing: its edges decide).
bool insideTriangle(const Point2d& p, const Triangle2& t) {
  const double c0 = cross(t.p[0], t.p[1], p), c1 = cross(t.p[1], t.p[2], p), c2 = cross(t.p[2], t.p[0], p);
  return (c0 >= 0 && c1 >= 0 && c2 >= 0 && (c0 > 0 || c1 > 0 || c2 > 0)) ||
         (c0 <= 0 && c1 <= 0 && c2 <= 0 && (c0 < 0 || c1 < 0 || c2 < 0));
}

double triangleDistance(const Triangle2& s, const Triangle2& t) {
  double best = std::numeric_limits<double>::infinity();
  for (int i = 0; i < 3; ++i)
    for (int k = 0; k < 3; ++k) {
      const Point2d &a = s.p[i], &b = s.p[(i + 1) % 3], &c = t.p[k], &d = t.p[(k + 1) % 3];
      if (segmentsMeet(a, b, c, d)) return 0;
      best = std::min({best, pointSegmentDistance(a, c, d), pointSegmentDistance(b, c, d),
                       pointSegmentDistance(c, a, b), pointSegmentDistance(d, a, b)});
    }
  if (insideTriangle(s.p[0], t) || insideTriangle(t.p[0], s)) return 0;
  return best;
}

// The projected facets of `lists` moved by (dx, dy) whose boxes come within `reach` of `box` (x0, y0,
// x1, y1); and the box of all of them when `box` is null.
std::vector<Triangle2> projectedTriangles(std::span<const std::span<const Point3f>> lists, double dx,
                                          double dy, const double* box, double reach) {
  std::vector<Triangle2> out;
  for (const auto& corners : lists)
    for (std::size_t f = 0; f + 2 < corners.size(); f += 3) {
      Triangle2 t;
      for (int c = 0; c < 3; ++c) t.p[c] = {corners[f + c].x + dx, corners[f + c].y + dy};
      t.x0 = std::min({t.p[0].x, t.p[1].x, t.p[2].x});
      t.x1 = std::max({t.p[0].x, t.p[1].x, t.p[2].x});
      t.y0 = std::min({t.p[0].y, t.p[1].y, t.p[2].y});
      t.y1 = std::max({t.p[0].y, t.p[1].y, t.p[2].y});
      if (!(std::isfinite(t.x0) && std::isfinite(t.x1) && std::isfinite(t.y0) && std::isfinite(t.y1)))
        continue;
      if (box &&
          (t.x0 > box[2] + reach || t.x1 < box[0] - reach || t.y0 > box[3] + reach || t.y1 < box[1] - reach))
        continue;
      out.push_back(t);
    }
  return out;
}

}  // namespace

void rotationCosSin(double degrees, double& c, double& s) {
  double d = std::fmod(degrees, 360.0);
  if (d < 0) d += 360.0;
  if (d == 0) {
    c = 1, s = 0;
  } else if (d == 90) {
    c = 0, s = 1;
  } else if (d == 180) {
    c = -1, s = 0;
  } else if (d == 270) {
    c = 0, s = -1;
  } else {
    const double r = d * (M_PI / 180.0);
    c = std::cos(r);
    s = std::sin(r);
  }
}

Footprint projectFootprint(std::span<const Point3f> corners, double cell) {
  const std::span<const Point3f> lists[1] = {corners};
  return projectFootprint(lists, cell, serialChunkRunner());
}

Footprint projectFootprint(std::span<const std::span<const Point3f>> lists, double cell,
                           const ChunkRunner& runner) {
  Footprint fp;
  fp.cell = cell;
  // Facet f of the lists taken one after another: list `l` holds facets [first[l], first[l + 1]).
  std::vector<std::size_t> first(lists.size() + 1, 0);
  for (std::size_t l = 0; l < lists.size(); ++l) first[l + 1] = first[l] + lists[l].size() / 3;
  const std::size_t facets = first.back();
  if (facets == 0) return fp;
  // Calls visit(span) with the corners of facets [f0, f1) of the lists joined, one span per list touched.
  auto forSpans = [&](std::size_t f0, std::size_t f1, auto&& visit) {
    for (std::size_t l = 0; l < lists.size(); ++l) {
      const std::size_t b = std::max(f0, first[l]), e = std::min(f1, first[l + 1]);
      if (b < e) visit(lists[l].subspan(3 * (b - first[l]), 3 * (e - b)));
    }
  };
  // Piece k of n: facets [pieceBegin(k, n), pieceBegin(k + 1, n)), at least 32768 of them.
  constexpr std::size_t kMinFacets = 32768, kWindowBytes = std::size_t{64} << 20;
  auto pieceBegin = [&](std::size_t k, std::size_t n) { return facets * k / n; };
  auto runPieces = [&](std::size_t n, auto&& body) {
    (n > 1 ? runner : serialChunkRunner()).run(n, 1, [&](std::size_t k0, std::size_t k1) {
      for (std::size_t k = k0; k < k1; ++k)
        forSpans(pieceBegin(k, n), pieceBegin(k + 1, n),
                 [&](std::span<const Point3f> corners) { body(k, corners); });
    });
  };
  // The bounds: each piece's spans' boxes (boundsOf), then the box of all their corners.
  const std::size_t boundPieces = std::clamp<std::size_t>(facets / kMinFacets, 1, std::max(1u, runner.width));
  std::vector<std::vector<Point3f>> boxCorners(boundPieces);
  runPieces(boundPieces, [&](std::size_t k, std::span<const Point3f> corners) {
    const BoundingBox box = boundsOf(corners);
    boxCorners[k].insert(boxCorners[k].end(), {box.min, box.max});
  });
  std::vector<Point3f> extremes;
  for (const std::vector<Point3f>& c : boxCorners) extremes.insert(extremes.end(), c.begin(), c.end());
  const BoundingBox box = boundsOf(extremes);
  CellWindow whole;
  whole.reset(cellOf(box.min.x, cell), cellOf(box.min.y, cell), cellOf(box.max.x, cell),
              cellOf(box.max.y, cell));
  // The cells: one window per piece (fewer pieces where the windows would pass 64 MiB), then their union.
  const std::size_t cells = whole.cells.size();
  const std::size_t pieces =
      std::min(boundPieces, std::max<std::size_t>(1, kWindowBytes / std::max<std::size_t>(cells, 1)));
  std::vector<CellWindow> windows(pieces, whole);
  runPieces(pieces, [&](std::size_t k, std::span<const Point3f> corners) {
    CellWindow& w = windows[k];
    for (std::size_t c = 0; c + 2 < corners.size(); c += 3) {
      const Point2d t[3] = {{corners[c].x, corners[c].y},
                            {corners[c + 1].x, corners[c + 1].y},
                            {corners[c + 2].x, corners[c + 2].y}};
      const double ty0 = std::min({t[0].y, t[1].y, t[2].y}), ty1 = std::max({t[0].y, t[1].y, t[2].y});
      const int32_t j0 = cellOf(ty0, cell), j1 = cellOf(ty1, cell);
      for (int32_t j = j0; j <= j1; ++j) {
        double xmin = 0, xmax = 0;
        if (!slabRange(t, std::max(ty0, j * cell), std::min(ty1, (j + 1) * cell), xmin, xmax)) continue;
        w.markRow(j, cellOf(xmin, cell), cellOf(xmax, cell));
      }
    }
  });
  CellWindow& w = windows[0];  // the union of every piece's cells
  for (std::size_t k = 1; k < pieces; ++k)
    for (std::size_t i = 0; i < cells; ++i) w.cells[i] |= windows[k].cells[i];
  for (uint32_t j = 0; j < w.height; ++j)
    for (uint32_t i = 0; i < w.width; ++i)
      if (w.cells[static_cast<std::size_t>(j) * w.width + i])
        fp.centres.push_back(
            {(w.i0 + static_cast<int32_t>(i) + 0.5) * cell, (w.j0 + static_cast<int32_t>(j) + 0.5) * cell});
  return fp;
}

CellShape placeFootprint(const Footprint& footprint, double degrees, double tx, double ty, double grow) {
  CellShape shape;
  if (footprint.centres.empty()) return shape;
  const double cell = footprint.cell, radius = cell * std::sqrt(0.5) + std::max(0.0, grow);
  double c = 1, s = 0;
  rotationCosSin(degrees, c, s);
  std::vector<Point2d> moved(footprint.centres.size());
  double minX = INFINITY, minY = INFINITY, maxX = -INFINITY, maxY = -INFINITY;
  for (std::size_t k = 0; k < moved.size(); ++k) {
    const Point2d p = footprint.centres[k];
    moved[k] = {c * p.x - s * p.y + tx, s * p.x + c * p.y + ty};
    minX = std::min(minX, moved[k].x), maxX = std::max(maxX, moved[k].x);
    minY = std::min(minY, moved[k].y), maxY = std::max(maxY, moved[k].y);
  }
  CellWindow w;
  w.reset(cellOf(minX - radius, cell), cellOf(minY - radius, cell), cellOf(maxX + radius, cell),
          cellOf(maxY + radius, cell));
  for (const Point2d q : moved) {
    // Cells whose square comes within `radius` of q: per row, the chord of the disc over the row's band.
    for (int32_t j = cellOf(q.y - radius, cell); j <= cellOf(q.y + radius, cell); ++j) {
      const double lo = j * cell, hi = lo + cell;
      const double dy = q.y < lo ? lo - q.y : q.y > hi ? q.y - hi : 0.0;
      if (dy > radius) continue;
      const double half = std::sqrt(radius * radius - dy * dy);
      w.markRow(j, cellOf(q.x - half, cell), cellOf(q.x + half, cell));
    }
  }
  shape.j0 = w.j0;
  shape.minI = INT32_MAX;
  shape.maxI = INT32_MIN;
  for (uint32_t j = 0; j < w.height; ++j) {
    const uint8_t* row = w.cells.data() + static_cast<std::size_t>(j) * w.width;
    for (uint32_t i = 0; i < w.width;) {
      if (!row[i]) {
        ++i;
        continue;
      }
      uint32_t e = i;
      while (e < w.width && row[e]) ++e;
      shape.spans.push_back({w.i0 + static_cast<int32_t>(i), w.i0 + static_cast<int32_t>(e)});
      shape.minI = std::min(shape.minI, w.i0 + static_cast<int32_t>(i));
      shape.maxI = std::max(shape.maxI, w.i0 + static_cast<int32_t>(e));
      i = e;
    }
    shape.rowOffsets.push_back(static_cast<uint32_t>(shape.spans.size()));
  }
  return shape;
}

CellShape shiftShape(CellShape shape, int32_t di, int32_t dj) {
  shape.j0 += dj;
  shape.minI += di;
  shape.maxI += di;
  for (auto& span : shape.spans) span.first += di, span.second += di;
  return shape;
}

bool shapesOverlap(const CellShape& a, const CellShape& b) {
  if (a.empty() || b.empty() || a.maxI <= b.minI || b.maxI <= a.minI) return false;
  const int32_t j0 = std::max(a.j0, b.j0);
  const int32_t j1 = std::min(a.j0 + static_cast<int32_t>(a.rows()), b.j0 + static_cast<int32_t>(b.rows()));
  for (int32_t j = j0; j < j1; ++j) {
    const uint32_t ra = static_cast<uint32_t>(j - a.j0), rb = static_cast<uint32_t>(j - b.j0);
    uint32_t p = a.rowOffsets[ra], q = b.rowOffsets[rb];
    while (p < a.rowOffsets[ra + 1] && q < b.rowOffsets[rb + 1]) {
      const auto sa = a.spans[p], sb = b.spans[q];
      if (sa.first < sb.second && sb.first < sa.second) return true;
      if (sa.second <= sb.second)
        ++p;
      else
        ++q;
    }
  }
  return false;
}

namespace {

// One plate's occupied cells, a bit per cell, rows of 64-bit words.
class PlateCells {
 public:
  PlateCells(int32_t width, int32_t height)
      : width_(width),
        height_(height),
        words_((static_cast<std::size_t>(width) + 63) / 64),
        bits_(words_ * static_cast<std::size_t>(height), 0) {}

  // The highest occupied column in [a, b) of row j, or -1.
  int32_t highestIn(int32_t j, int32_t a, int32_t b) const {
    a = std::max(a, 0);
    b = std::min(b, width_);
    if (j < 0 || j >= height_ || a >= b) return -1;
    const uint64_t* row = bits_.data() + static_cast<std::size_t>(j) * words_;
    for (int32_t w = (b - 1) / 64; w >= a / 64; --w) {
      uint64_t bits = row[w];
      const int32_t lo = w * 64, hi = lo + 64;
      if (b < hi) bits &= (uint64_t{1} << (b - lo)) - 1;
      if (a > lo) bits &= ~((uint64_t{1} << (a - lo)) - 1);
      if (bits) return lo + 63 - std::countl_zero(bits);
    }
    return -1;
  }

  void mark(const CellShape& shape, int32_t di, int32_t dj) {
    for (uint32_t r = 0; r < shape.rows(); ++r) {
      const int32_t j = shape.j0 + static_cast<int32_t>(r) + dj;
      if (j < 0 || j >= height_) continue;
      uint64_t* row = bits_.data() + static_cast<std::size_t>(j) * words_;
      for (uint32_t k = shape.rowOffsets[r]; k < shape.rowOffsets[r + 1]; ++k)
        for (int32_t i = std::max(0, shape.spans[k].first + di);
             i < std::min(width_, shape.spans[k].second + di); ++i)
          row[i / 64] |= uint64_t{1} << (i % 64);
    }
  }

  // 0 when `shape` moved by (di, dj) touches no occupied cell; else the smallest larger di worth trying.
  int32_t conflict(const CellShape& shape, int32_t di, int32_t dj) const {
    for (uint32_t r = 0; r < shape.rows(); ++r) {
      const int32_t j = shape.j0 + static_cast<int32_t>(r) + dj;
      for (uint32_t k = shape.rowOffsets[r]; k < shape.rowOffsets[r + 1]; ++k) {
        const auto [a, b] = shape.spans[k];
        const int32_t q = highestIn(j, a + di, b + di);
        if (q >= 0) return q - a + 1;
      }
    }
    return 0;
  }

 private:
  int32_t width_, height_;
  std::size_t words_;
  std::vector<uint64_t> bits_;
};

struct Candidate {
  int32_t top = INT32_MAX, left = INT32_MAX;
  std::size_t rotation = 0;
  int32_t di = 0, dj = 0;
};

}  // namespace

Arrangement arrangeFootprints(std::span<const ArrangeItem> items, const ArrangeSettings& settings) {
  Arrangement result;
  result.parts.resize(items.size());
  if (items.empty()) return result;
  const double cell = items[0].footprint->cell;
  const int32_t width = static_cast<int32_t>(std::floor(settings.plateWidth / cell + 1e-9));
  const int32_t height = static_cast<int32_t>(std::floor(settings.plateHeight / cell + 1e-9));
  const int32_t margin = static_cast<int32_t>(std::ceil(settings.margin / cell - 1e-9));
  result.usableArea = std::max(0.0, settings.plateWidth - 2 * settings.margin) *
                      std::max(0.0, settings.plateHeight - 2 * settings.margin);
  std::vector<double> angles{0.0};
  if (settings.rotationStep > 0)
    for (double a = settings.rotationStep; a < 360.0 - 1e-9; a += settings.rotationStep) angles.push_back(a);

  std::vector<PlateCells> plates;
  const auto openPlate = [&] {
    plates.emplace_back(width, height);
    result.footprintArea.push_back(0.0);
  };
  openPlate();
  std::vector<std::size_t> order;
  for (std::size_t k = 0; k < items.size(); ++k) {
    const ArrangeItem& item = items[k];
    if (!item.fixedTx) {
      order.push_back(k);
      continue;
    }
    const double rotation = item.fixedRotation.value_or(0.0);
    plates[0].mark(placeFootprint(*item.footprint, rotation, *item.fixedTx, item.fixedTy.value_or(0.0),
                                  0.5 * settings.spacing),
                   0, 0);
    result.parts[k] = {0, rotation, *item.fixedTx, item.fixedTy.value_or(0.0)};
    result.footprintArea[0] += item.footprint->area();
  }
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
    return items[a].footprint->centres.size() > items[b].footprint->centres.size();
  });

  for (const std::size_t k : order) {
    // A stop signal ends the arrangement between parts (it may take a while for many parts and angles).
    if (settings.cancel != nullptr && settings.cancel->load(std::memory_order_relaxed)) {
      result.cancelled = true;
      return result;
    }
    const Footprint& fp = *items[k].footprint;
    std::vector<CellShape> raw, grown;
    for (const double a : angles) {
      raw.push_back(placeFootprint(fp, a, 0, 0, 0));
      grown.push_back(placeFootprint(fp, a, 0, 0, 0.5 * settings.spacing));
    }
    bool placed = false;
    for (std::size_t p = 0; p <= plates.size() && !placed; ++p) {
      if (p == plates.size()) {
        if (p > 0 && result.footprintArea[p - 1] == 0) break;  // did not fit an empty plate either
        openPlate();
      }
      Candidate best;
      for (std::size_t r = 0; r < angles.size(); ++r) {
        const CellShape& s = raw[r];
        if (s.empty()) continue;
        const int32_t diMin = margin - s.minI, diMax = width - margin - s.maxI;
        const int32_t djMin = margin - s.j0,
                      djMax = height - margin - (s.j0 + static_cast<int32_t>(s.rows()));
        for (int32_t dj = djMin; dj <= djMax; ++dj) {
          const int32_t top = s.j0 + static_cast<int32_t>(s.rows()) + dj;
          if (top > best.top) break;
          for (int32_t di = diMin; di <= diMax;) {
            const int32_t next = plates[p].conflict(grown[r], di, dj);
            if (next == 0) {
              const Candidate c{top, s.minI + di, r, di, dj};
              if (std::tie(c.top, c.left) < std::tie(best.top, best.left)) best = c;
              break;
            }
            di = std::max(di + 1, next);
          }
          if (best.top == top) break;
        }
      }
      if (best.top == INT32_MAX) continue;
      plates[p].mark(grown[best.rotation], best.di, best.dj);
      result.parts[k] = {static_cast<uint32_t>(p), angles[best.rotation], best.di * cell, best.dj * cell};
      result.footprintArea[p] += fp.area();
      placed = true;
    }
    if (!placed) throw std::invalid_argument(std::to_string(k));
  }
  while (result.footprintArea.size() > 1 && result.footprintArea.back() == 0) result.footprintArea.pop_back();
  result.plates = static_cast<uint32_t>(result.footprintArea.size());
  return result;
}

Arrangement shelfPackBoxes(std::span<const ArrangeItem> items, const ArrangeSettings& settings) {
  Arrangement result;
  result.parts.resize(items.size());
  result.usableArea = std::max(0.0, settings.plateWidth - 2 * settings.margin) *
                      std::max(0.0, settings.plateHeight - 2 * settings.margin);
  struct Box {
    double w, h, rotation, x0, y0;  // size grown by the spacing, rotation, lower-left of the raw cells
  };
  std::vector<Box> boxes;
  for (const ArrangeItem& item : items) {
    Box best{INFINITY, INFINITY, 0, 0, 0};
    for (const double a : {0.0, 90.0}) {
      const CellShape s = placeFootprint(*item.footprint, a, 0, 0, 0);
      const double c = item.footprint->cell;
      const Box b{(s.maxI - s.minI) * c + settings.spacing, s.rows() * c + settings.spacing, a, s.minI * c,
                  s.j0 * c};
      if (b.h < best.h) best = b;
    }
    boxes.push_back(best);
  }
  std::vector<std::size_t> order(items.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](std::size_t a, std::size_t b) { return boxes[a].h > boxes[b].h; });
  const double usableW = settings.plateWidth - 2 * settings.margin + settings.spacing;
  const double usableH = settings.plateHeight - 2 * settings.margin + settings.spacing;
  struct Shelf {
    uint32_t plate;
    double y, h, x;
  };
  std::vector<Shelf> shelves;
  std::vector<double> plateTop;  // used height per plate
  for (const std::size_t k : order) {
    const Box& b = boxes[k];
    if (b.w > usableW || b.h > usableH) throw std::invalid_argument(std::to_string(k));
    Shelf* shelf = nullptr;
    for (Shelf& s : shelves)
      if (b.h <= s.h && s.x + b.w <= usableW) {
        shelf = &s;
        break;
      }
    if (shelf == nullptr) {
      uint32_t plate = 0;
      while (plate < plateTop.size() && plateTop[plate] + b.h > usableH) ++plate;
      if (plate == plateTop.size()) {
        plateTop.push_back(0);
        result.footprintArea.push_back(0);
      }
      shelves.push_back({plate, plateTop[plate], b.h, 0});
      plateTop[plate] += b.h;
      shelf = &shelves.back();
    }
    result.parts[k] = {shelf->plate, b.rotation, settings.margin + shelf->x - b.x0,
                       settings.margin + shelf->y - b.y0};
    result.footprintArea[shelf->plate] += items[k].footprint->area();
    shelf->x += b.w;
  }
  result.plates = static_cast<uint32_t>(plateTop.size());
  return result;
}

double projectionDistance(std::span<const std::span<const Point3f>> a, double ax, double ay,
                          std::span<const std::span<const Point3f>> b, double bx, double by, double limit) {
  const auto boxOf = [](std::span<const std::span<const Point3f>> lists, double dx, double dy) {
    std::array<double, 4> box{
        std::numeric_limits<double>::infinity(), std::numeric_limits<double>::infinity(),
        -std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity()};
    for (const auto& corners : lists)
      for (const Point3f& p : corners) {
        if (!(std::isfinite(p.x) && std::isfinite(p.y))) continue;
        box = {std::min(box[0], p.x + dx), std::min(box[1], p.y + dy), std::max(box[2], p.x + dx),
               std::max(box[3], p.y + dy)};
      }
    return box;
  };
  const std::array<double, 4> boxA = boxOf(a, ax, ay), boxB = boxOf(b, bx, by);
  // Only facets near the other part can be nearer than `limit`.
  const std::vector<Triangle2> near = projectedTriangles(a, ax, ay, boxB.data(), limit);
  const std::vector<Triangle2> other = projectedTriangles(b, bx, by, boxA.data(), limit);
  double best = limit;
  if (near.empty() || other.empty()) return best;
  // `other` in buckets of a grid (about one facet per bucket on average, at least `limit` wide).
  double x0 = other[0].x0, y0 = other[0].y0, x1 = other[0].x1, y1 = other[0].y1;
  for (const Triangle2& t : other) {
    x0 = std::min(x0, t.x0), y0 = std::min(y0, t.y0), x1 = std::max(x1, t.x1), y1 = std::max(y1, t.y1);
  }
  const double extent = std::max({x1 - x0, y1 - y0, 1e-9});
  const double cell = std::max(limit, extent / std::max(1.0, std::ceil(std::sqrt(double(other.size())))));
  const auto columns = static_cast<int64_t>(std::floor((x1 - x0) / cell)) + 1;
  const auto rows = static_cast<int64_t>(std::floor((y1 - y0) / cell)) + 1;
  const auto column = [&](double x) {
    return std::clamp<int64_t>(static_cast<int64_t>(std::floor((x - x0) / cell)), 0, columns - 1);
  };
  const auto row = [&](double y) {
    return std::clamp<int64_t>(static_cast<int64_t>(std::floor((y - y0) / cell)), 0, rows - 1);
  };
  std::vector<uint32_t> start(static_cast<std::size_t>(columns * rows) + 1, 0), items;
  for (int pass = 0; pass < 2; ++pass) {
    for (uint32_t k = 0; k < other.size(); ++k) {
      const Triangle2& t = other[k];
      for (int64_t j = row(t.y0); j <= row(t.y1); ++j)
        for (int64_t i = column(t.x0); i <= column(t.x1); ++i) {
          const auto bucket = static_cast<std::size_t>(j * columns + i);
          if (pass == 0)
            ++start[bucket + 1];
          else
            items[start[bucket]++] = k;
        }
    }
    if (pass == 0) {
      std::partial_sum(start.begin(), start.end(), start.begin());
      items.resize(start.back());
    } else {  // start[b] moved to the end of bucket b: shift back
      for (std::size_t bucket = start.size() - 1; bucket > 0; --bucket) start[bucket] = start[bucket - 1];
      start[0] = 0;
    }
  }
  std::vector<uint32_t> seen(other.size(), std::numeric_limits<uint32_t>::max());
  for (uint32_t n = 0; n < near.size(); ++n) {
    const Triangle2& s = near[n];
    if (s.x0 > x1 + best || s.x1 < x0 - best || s.y0 > y1 + best || s.y1 < y0 - best) continue;
    for (int64_t j = row(s.y0 - best); j <= row(s.y1 + best); ++j)
      for (int64_t i = column(s.x0 - best); i <= column(s.x1 + best); ++i) {
        const auto bucket = static_cast<std::size_t>(j * columns + i);
        for (uint32_t e = start[bucket]; e < start[bucket + 1]; ++e) {
          const uint32_t k = items[e];
          if (seen[k] == n) continue;
          seen[k] = n;
          const Triangle2& t = other[k];
          if (t.x0 > s.x1 + best || t.x1 < s.x0 - best || t.y0 > s.y1 + best || t.y1 < s.y0 - best) continue;
          best = std::min(best, triangleDistance(s, t));
          if (best == 0) return 0;
        }
      }
  }
  return best;
}

}  // namespace toposlice
