#include "offset/polygon_offset.h"

#include <polyclipping/clipper.hpp>

#include <algorithm>
#include <cmath>

namespace toposlice {
namespace {

using ClipperLib::cInt;
using ClipperLib::IntPoint;
using ClipperLib::Path;
using ClipperLib::Paths;

constexpr double kMiterLimit = 3.0;
// Slivers thinner than this (rounding leftovers of an opening) are not thin features.
constexpr double kSliverMm = 0.0005;
// Outline simplification before an offset: moves the outline by at most this much.
constexpr double kCleanMm = 0.0005;

cInt toUnits(double mm) {
  return static_cast<cInt>(std::llround(mm * kOffsetUnitsPerMm));
}

bool finiteLoop(std::span<const Point2d> loop) {
  for (const Point2d& p : loop)
    if (!std::isfinite(p.x) || !std::isfinite(p.y)) return false;
  return true;
}

// The clean polygons of the sets' positive-winding region: removal sets enter reversed, so that they
// subtract one level of the count, as in the rasterizer.
Paths solidRegion(std::span<const ContourSet> sets, bool growOnly) {
  Paths input;
  for (const ContourSet& set : sets) {
    const LayerContours& layer = *set.layer;
    for (std::size_t l = 0; l < layer.loopCount(); ++l) {
      if (layer.loopClosed[l] == 0) continue;
      const std::span<const Point2d> loop = layer.loopPoints(l);
      if (loop.size() < 3 || !finiteLoop(loop)) continue;
      Path path;
      path.reserve(loop.size());
      for (const Point2d& p : loop) path.push_back(IntPoint(toUnits(p.x), toUnits(p.y)));
      if (set.sign < 0) ClipperLib::ReversePath(path);
      input.push_back(std::move(path));
    }
  }
  // Growing distributes over a union ((A u B) + d = (A + d) u (B + d)) and the offset unions its
  // pieces under the positive rule: a single set grown needs no union first.
  if (growOnly) return input;
  Paths clean;
  ClipperLib::Clipper clipper;
  clipper.AddPaths(input, ClipperLib::ptSubject, true);
  clipper.Execute(ClipperLib::ctUnion, clean, ClipperLib::pftPositive, ClipperLib::pftPositive);
  return clean;
}

Paths trimmedOffset(const Paths& region, double mm);

// Clean, oriented polygons grown by `mm` (shrunk when negative); Clipper unions the pieces.
Paths offset(const Paths& region, double mm) {
  if (region.empty()) return {};
  if (mm == 0) return region;
  return trimmedOffset(region, mm);
}

Paths combine(const Paths& a, const Paths& b, ClipperLib::ClipType type) {
  Paths out;
  ClipperLib::Clipper clipper;
  clipper.AddPaths(a, ClipperLib::ptSubject, true);
  clipper.AddPaths(b, ClipperLib::ptClip, true);
  clipper.Execute(type, out, ClipperLib::pftNonZero, ClipperLib::pftNonZero);
  return out;
}

// The elephant-foot shrink by `shrink` that leaves no feature narrower than minWidth because of it
// (polygon_offset.h): in steps of at most kFootStepMm, each shrinking the region by the step except
// its thin part, the points no disc of diameter minWidth + 2 step inside the region covers (those would
// end narrower than minWidth), which keeps its width and stays joined by its root.
constexpr double kFootStepMm = 0.0125;
Paths compensateElephantFoot(const Paths& solid, double shrink, double minWidth) {
  const double r = 0.5 * minWidth;
  if (!(r > 0)) return offset(solid, -shrink);
  const int steps = std::max(1, static_cast<int>(std::ceil(shrink / kFootStepMm - 1e-9)));
  const double step = shrink / steps;
  Paths region = solid;
  for (int i = 0; i < steps && !region.empty(); ++i) {
    Paths shrunk = offset(region, -step);
    const Paths opened = offset(offset(region, -(r + step)), r + step);
    Paths thin = combine(region, opened, ClipperLib::ctDifference);
    thin = offset(offset(thin, -kSliverMm), kSliverMm);
    if (thin.empty()) {
      region = std::move(shrunk);
      continue;
    }
    const Paths roots = combine(offset(thin, step), region, ClipperLib::ctIntersection);
    region = combine(shrunk, roots, ClipperLib::ctUnion);
  }
  // The steps leave notches a step wide where a root turns from thin to wide (a saw of 12.5 um teeth
  // along a neck): closed by a closing of one step, which fills nothing wider. United with the region,
  // which the closing's two outline cleanings would otherwise wear down where it is finely drawn (a
  // 256-sided pin of 0.15 mm came out 0.145 mm).
  if (steps == 1) return region;
  return combine(region, offset(offset(region, step), -step), ClipperLib::ctUnion);
}

// std::llround, exactly, without the library call: v - trunc(v) is exact in double precision.
cInt roundToUnits(double mm) {
  const double v = mm * kOffsetUnitsPerMm;
  const cInt t = static_cast<cInt>(v);
  const double f = v - static_cast<double>(t);
  return t + static_cast<cInt>(f >= 0.5) - static_cast<cInt>(f <= -0.5);
}

// ClipperLib::CleanPolygon (Clipper 6.4.2), re-derived on index links instead of a heap-allocated
// node list: the same tests in the same order (a visit whose triangle clearly turns skips them:
// clearlyTurns), and a point near the line of its neighbours dropped only where every point dropped
// between them stays near it (dropsStayNear). Appends the cleaned loop to `out`.
// Growing and shrinking both clean with it.
class LoopCleaner {
 public:
  void clean(std::span<const IntPoint> in, double distance, std::vector<IntPoint>& out) {
    std::size_t size = in.size();
    if (size == 0) return;
    next_.resize(size);
    prev_.resize(size);
    done_.assign(size, 0);
    for (std::size_t i = 0; i < size; ++i) {
      next_[i] = static_cast<uint32_t>(i + 1 == size ? 0 : i + 1);
      prev_[i] = static_cast<uint32_t>(i == 0 ? size - 1 : i - 1);
    }
    const double distSqrd = distance * distance;
    uint32_t op = 0;
    while (done_[op] == 0 && next_[op] != prev_[op]) {
      const IntPoint& p = in[op];
      const IntPoint& before = in[prev_[op]];
      const IntPoint& after = in[next_[op]];
      if (clearlyTurns(before, p, after, distSqrd)) {
        done_[op] = 1;
        op = next_[op];
      } else if (close(p, before, distSqrd)) {
        op = exclude(op);
        --size;
      } else if (close(before, after, distSqrd)) {
        exclude(next_[op]);
        op = exclude(op);
        size -= 2;
      } else if (nearlyCollinear(before, p, after, distSqrd) &&
                 dropsStayNear(in, prev_[op], next_[op], distSqrd)) {
        op = exclude(op);
        --size;
      } else {
        done_[op] = 1;
        op = next_[op];
      }
    }
    if (size < 3) return;
    for (std::size_t i = 0; i < size; ++i, op = next_[op]) out.push_back(in[op]);
  }

 private:
  uint32_t exclude(uint32_t op) {
    const uint32_t result = prev_[op];
    next_[result] = next_[op];
    prev_[next_[op]] = result;
    done_[result] = 0;
    return result;
  }

  // Whether the three tests of a visit (close, close, nearlyCollinear) must all fail, known from twice the
  // area A of the triangle b, p, a and its longest side L alone (most visits): each corner's distance
  // from the line through the other two is A over that side's length, at least A / L; so where A > d L
  // no corner lies within d of a line, and no side is d or shorter (A is at most the product of two
  // sides, the other at most L). The differences here are exact; the margin (A^2 above d^2 L^2 by a
  // factor 1 + 1e-6) covers the rounding of Clipper's own sums (a * x + b * y with coordinates up to
  // X round by about X L 1e-16, against the margin's 2.5e-4 L for d = 500 units: safe up to kilometres).
  // Clipper's decisions are unchanged (tests compare them).
  static bool clearlyTurns(const IntPoint& b, const IntPoint& p, const IntPoint& a, double distSqrd) {
    const double x1 = static_cast<double>(p.X - b.X), y1 = static_cast<double>(p.Y - b.Y);
    const double x2 = static_cast<double>(a.X - p.X), y2 = static_cast<double>(a.Y - p.Y);
    const double twiceArea = x1 * y2 - y1 * x2;
    const double x3 = x1 + x2, y3 = y1 + y2;
    const double longest = std::max({x1 * x1 + y1 * y1, x2 * x2 + y2 * y2, x3 * x3 + y3 * y3});
    return twiceArea * twiceArea > distSqrd * longest * (1 + 1e-6);
  }

  // Whether every input point after `from` and before `to` (the points dropped between two kept ones,
  // and the one tested) lies within the distance of the line through in[from] and in[to]. Clipper's
  // rule tests the one point against its neighbours as they are then, so that on a finely drawn curve
  // each drop let the next one go a little farther (a 4,000-sided circle of 5 mm came out 30 um inside
  // after cleaning): measured against every point it replaces, the outline moves by at most the distance.
  // A stretch longer than kMaxDropped points is not shortened further (a long straight wall, drawn in
  // many points, then costs the offset more points, not this test a quadratic time).
  static constexpr std::size_t kMaxDropped = 256;
  static bool dropsStayNear(std::span<const IntPoint> in, uint32_t from, uint32_t to, double distSqrd) {
    const std::size_t n = in.size();
    std::size_t count = 0;
    for (std::size_t i = from + 1 == n ? 0 : from + 1; i != to; i = i + 1 == n ? 0 : i + 1)
      if (++count > kMaxDropped || !nearLine(in[i], in[from], in[to], distSqrd)) return false;
    return true;
  }

  static bool close(const IntPoint& a, const IntPoint& b, double distSqrd) {
    const double dx = static_cast<double>(a.X) - static_cast<double>(b.X);
    const double dy = static_cast<double>(a.Y) - static_cast<double>(b.Y);
    return dx * dx + dy * dy <= distSqrd;
  }

  // Clipper's DistanceFromLineSqrd(p, l1, l2) < distSqrd, that is fl(c^2 / (a^2 + b^2)) < distSqrd: decided
  // by a product where the two sides are more than 1e-12 apart (rounding moves each by far less), by
  // the same division otherwise.
  static bool nearLine(const IntPoint& p, const IntPoint& l1, const IntPoint& l2, double distSqrd) {
    const double a = static_cast<double>(l1.Y - l2.Y);
    const double b = static_cast<double>(l2.X - l1.X);
    double c = a * static_cast<double>(l1.X) + b * static_cast<double>(l1.Y);
    c = a * static_cast<double>(p.X) + b * static_cast<double>(p.Y) - c;
    const double numerator = c * c, denominator = a * a + b * b, bound = distSqrd * denominator;
    if (numerator < bound * (1 - 1e-12)) return true;
    if (numerator > bound * (1 + 1e-12)) return false;
    return numerator / denominator < distSqrd;
  }

  // The distance is measured from whichever of the three points lies between the other two.
  static bool nearlyCollinear(const IntPoint& p1, const IntPoint& p2, const IntPoint& p3, double distSqrd) {
    if (std::abs(p1.X - p2.X) > std::abs(p1.Y - p2.Y)) {
      if ((p1.X > p2.X) == (p1.X < p3.X)) return nearLine(p1, p2, p3, distSqrd);
      if ((p2.X > p1.X) == (p2.X < p3.X)) return nearLine(p2, p1, p3, distSqrd);
      return nearLine(p3, p1, p2, distSqrd);
    }
    if ((p1.Y > p2.Y) == (p1.Y < p3.Y)) return nearLine(p1, p2, p3, distSqrd);
    if ((p2.Y > p1.Y) == (p2.Y < p3.Y)) return nearLine(p2, p1, p3, distSqrd);
    return nearLine(p3, p1, p2, distSqrd);
  }

  std::vector<uint32_t> next_, prev_;
  std::vector<uint8_t> done_;
};

// The result of ClipperOffset::Execute before its union, for closed polygons and mitred joins
// (Clipper 6.4's ClipperOffset: AddPath, FixOrientations, DoOffset, OffsetPoint, DoMiter, DoSquare),
// re-derived here: the same points in the same order. Paths are kept in one flat array, so that a
// thread reusing the object allocates nothing once it has seen its largest layer.
class RawOffset {
 public:
  void reset(double delta, double miterLimit) {
    delta_ = delta;
    miterBound_ = miterLimit > 2 ? 2 / (miterLimit * miterLimit) : 0.5;
    points_.clear();
    starts_.assign(1, 0);
    hasLowest_ = false;
  }

  // AddPath: consecutive duplicates (and a last point equal to the first) dropped; fewer than three
  // points left: nothing. Also tracks the lowest point (largest y, then smallest x) of all paths.
  void add(std::span<const IntPoint> path) {
    std::size_t last = path.size();
    while (last > 1 && path[0] == path[last - 1]) --last;
    if (last < 3) return;
    const std::size_t first = points_.size();
    points_.push_back(path[0]);
    std::size_t lowest = first;
    for (std::size_t i = 1; i < last; ++i) {
      if (path[i] == points_.back()) continue;
      points_.push_back(path[i]);
      if (lower(path[i], points_[lowest])) lowest = points_.size() - 1;
    }
    if (points_.size() - first < 3) {
      points_.resize(first);
      return;
    }
    const IntPoint p = points_[lowest];
    if (!hasLowest_ || lower(p, lowestPoint_)) {
      hasLowest_ = true;
      lowestPoint_ = p;
      lowestPath_ = starts_.size() - 1;
    }
    starts_.push_back(static_cast<uint32_t>(points_.size()));
  }

  // FixOrientations, then DoOffset for every path with its concave corners trimmed: each loop, in
  // integer units, goes to sink(const Path&).
  template <class Sink>
  void build(Sink&& sink) {
    fixOrientations();
    for (std::size_t i = 0; i + 1 < starts_.size(); ++i) {
      const std::span<const IntPoint> src = path(i);
      offsetPath(src);
      trim(src);
      if (trimmed_.size() >= 3) sink(trimmed_);
    }
  }

 private:
  struct Normal {
    double x, y;
  };
  struct Trim {
    double x = 0, y = 0;     // the crossing of the two moved edges
    double in = 0, out = 0;  // the length of moved edge before and after it that the trim removes
    double edgeOut = 0;      // the original edge after the corner
    double segOut = 0;       // the moved segment the trim ends on (its "out" is measured along it)
    bool ok = false;
    uint8_t before = 0, after = 0;  // 1: the point before (after) the detour goes too (a swallowed edge)
    // Detours it replaces: 1, or k for a run's envelope (runTrim; 0 for the other detours of the run),
    // whose points are envelope_[first, first + count) instead of (x, y).
    uint32_t span = 1, first = 0, count = 0;
  };

  // Where the lines A -> b and a -> B cross: A + s (b - A) = a + u (B - a).
  struct Crossing {
    double s = 0, u = 0, cross = 0;
    bool valid = false;
  };
  static Crossing crossing(const IntPoint& A, const IntPoint& b, const IntPoint& a, const IntPoint& B) {
    Crossing c;
    const double d1x = static_cast<double>(b.X - A.X), d1y = static_cast<double>(b.Y - A.Y);
    const double d2x = static_cast<double>(B.X - a.X), d2y = static_cast<double>(B.Y - a.Y);
    c.cross = d1x * d2y - d1y * d2x;
    if (!(std::fabs(c.cross) > 0)) return c;
    const double ex = static_cast<double>(a.X - A.X), ey = static_cast<double>(a.Y - A.Y);
    c.s = (ex * d2y - ey * d2x) / c.cross;
    c.u = (ex * d1y - ey * d1x) / c.cross;
    c.valid = true;
    return c;
  }

  std::span<const IntPoint> path(std::size_t i) const {
    return std::span<const IntPoint>(points_).subspan(starts_[i], starts_[i + 1] - starts_[i]);
  }

  // The unit normal of edge j (from src[j]) of the path offsetPath last took.
  Normal normal(std::size_t j) const { return {normalX_[j], normalY_[j]}; }

  // Clipper's order for the lowest point: larger y, then smaller x.
  static bool lower(const IntPoint& a, const IntPoint& b) { return a.Y > b.Y || (a.Y == b.Y && a.X < b.X); }

  // Half away from zero (v - 0.5 below 0, v + 0.5 otherwise; -0.0 gives 0 either way) without a branch on
  // the sign, which the offset's points change from one to the next around the origin.
  static cInt round(double v) { return static_cast<cInt>(v + std::copysign(0.5, v)); }

  // ClipperLib::Area's sum, in its order: the orientation Clipper tests on the lowest path.
  static bool positive(std::span<const IntPoint> poly) {
    double a = 0;
    for (std::size_t i = 0, j = poly.size() - 1; i < poly.size(); j = i++)
      a += (static_cast<double>(poly[j].X) + static_cast<double>(poly[i].X)) *
           (static_cast<double>(poly[j].Y) - static_cast<double>(poly[i].Y));
    return -a * 0.5 >= 0;
  }

  void fixOrientations() {
    if (hasLowest_ && !positive(path(lowestPath_)))
      for (std::size_t i = 0; i + 1 < starts_.size(); ++i)
        std::reverse(points_.begin() + starts_[i], points_.begin() + starts_[i + 1]);
    hasLowest_ = false;  // once
  }

  IntPoint moved(const IntPoint& p, double x, double y) const {
    return IntPoint(round(static_cast<double>(p.X) + x), round(static_cast<double>(p.Y) + y));
  }

  // DoOffset of one closed path into dest_, noting each point's source vertex and each concave detour.
  void offsetPath(std::span<const IntPoint> src) {
    const std::size_t n = src.size();
    // Each edge's length and unit normal (dy, -dx) / length, as Clipper's GetUnitNormal, in loops GCC
    // vectorizes (two edges per sqrtpd and divpd: the same values; the file is built with
    // -fno-math-errno, which only drops the errno of a square root of a negative, never taken here).
    // add() dropped repeated points, so no edge has length 0 (the 1 added there keeps f finite).
    lengths_.resize(n);
    normalX_.resize(n);
    normalY_.resize(n);
    for (std::size_t j = 0; j < n; ++j) {  // the edge vectors first, turned into normals in place
      const IntPoint& a = src[j];
      const IntPoint& b = src[j + 1 == n ? 0 : j + 1];
      normalX_[j] = static_cast<double>(b.X - a.X);
      normalY_[j] = static_cast<double>(b.Y - a.Y);
    }
    double* __restrict dx = normalX_.data();
    double* __restrict dy = normalY_.data();
    double* __restrict len = lengths_.data();
    for (std::size_t j = 0; j < n; ++j) {
      const double l = std::sqrt(dx[j] * dx[j] + dy[j] * dy[j]);
      const double f = 1 / (l + static_cast<double>(l == 0));
      len[j] = l;
      const double nx = dy[j] * f, ny = -(dx[j] * f);
      dx[j] = nx;
      dy[j] = ny;
    }
    kinds_.resize(n);
    dest_.clear();
    detours_.clear();
    corners_.clear();
    std::size_t k = n - 1;
    for (std::size_t j = 0; j < n; ++j) offsetPoint(src, j, k);
  }

  void offsetPoint(std::span<const IntPoint> src, std::size_t j, std::size_t& k) {
    const Normal nk = normal(k), nj = normal(j);
    const IntPoint& p = src[j];
    double sinA = nk.x * nj.y - nj.x * nk.y;
    if (std::fabs(sinA * delta_) < 1.0) {
      if (nk.x * nj.x + nj.y * nk.y > 0) {  // nearly straight on: one point, and k stays (as in Clipper)
        kinds_[j] = kStraight;
        dest_.push_back(moved(p, nk.x * delta_, nk.y * delta_));
        return;
      }
    } else if (sinA > 1.0) {
      sinA = 1.0;
    } else if (sinA < -1.0) {
      sinA = -1.0;
    }
    if (sinA * delta_ < 0) {  // concave: through the vertex
      kinds_[j] = kDetour;
      detours_.push_back(static_cast<uint32_t>(dest_.size()));
      corners_.push_back(static_cast<uint32_t>(j));
      dest_.push_back(moved(p, nk.x * delta_, nk.y * delta_));
      dest_.push_back(p);
      dest_.push_back(moved(p, nj.x * delta_, nj.y * delta_));
    } else {
      const double r = 1 + (nj.x * nk.x + nj.y * nk.y);
      kinds_[j] = r >= miterBound_ ? kMitre : kSquare;
      if (r >= miterBound_) {  // mitre
        const double q = delta_ / r;
        dest_.push_back(moved(p, (nk.x + nj.x) * q, (nk.y + nj.y) * q));
      } else {  // squared off
        const double dx = std::tan(std::atan2(sinA, nk.x * nj.x + nk.y * nj.y) / 4);
        dest_.push_back(moved(p, delta_ * (nk.x - nk.y * dx), delta_ * (nk.y + nk.x * dx)));
        dest_.push_back(moved(p, delta_ * (nj.x + nj.y * dx), delta_ * (nj.y - nj.x * dx)));
      }
    }
    k = j;
  }

  // A concave corner's detour b, v, a (b the end of the edge before v moved out, a the start of the edge
  // after it) leaves a small loop X -> b -> v -> a -> X, where X is the crossing of the two moved edges.
  // Replacing the detour by X removes that loop and keeps the positive-winding region
  // (docs/DESIGN.md, "Growing by trimmed raw loops"), where the corner's trims fit its edges: X lies on both
  // moved edges; the trims at the two ends of one edge do not overlap; and the reach of the corner,
  // d max(tan(phi / 2), sin(phi)) for a turn of phi, the farthest along an edge that the trimmed-away
  // ends of the other edge fall, stays within both original edges.
  void trim(std::span<const IntPoint> src) {
    const std::size_t m = dest_.size();
    if (detours_.empty() || m < 6) {
      trimmed_ = dest_;
      return;
    }
    // Pass 1: each detour's crossing, trims and reach.
    trims_.assign(detours_.size(), Trim{});
    const std::size_t n = src.size();
    for (std::size_t t = 0; t < detours_.size(); ++t) {
      const std::size_t i = detours_[t];
      const IntPoint& A = dest_[i == 0 ? m - 1 : i - 1];
      const IntPoint& b = dest_[i];
      const IntPoint& a = dest_[i + 2];
      const IntPoint& B = dest_[i + 3 >= m ? i + 3 - m : i + 3];
      const std::size_t j = corners_[t];
      Trim& corner = trims_[t];
      const Crossing c = crossing(A, b, a, B);
      if (!(c.s > 0 && c.s < 1 && c.u > 0 && c.u < 1)) {
        if (n >= 6 && c.valid) corner.ok = swallowed(src, j, i, c, corner);
        continue;
      }
      const double d1x = static_cast<double>(b.X - A.X), d1y = static_cast<double>(b.Y - A.Y);
      const double d2x = static_cast<double>(B.X - a.X), d2y = static_cast<double>(B.Y - a.Y);
      const double len1 = std::sqrt(d1x * d1x + d1y * d1y), len2 = std::sqrt(d2x * d2x + d2y * d2y);
      corner.x = static_cast<double>(A.X) + c.s * d1x;
      corner.y = static_cast<double>(A.Y) + c.s * d1y;
      corner.in = (1 - c.s) * len1;
      corner.out = c.u * len2;
      corner.segOut = len2;
      // The original edges before and after the corner (every vertex adds at least one point, so A
      // comes from the vertex before and B from the one after).
      const double edgeIn = lengths_[j == 0 ? n - 1 : j - 1];
      corner.edgeOut = lengths_[j];
      // 1 unit of slack for the rounding of b and a to whole units.
      const double reach =
          std::max(std::max(corner.in, corner.out), std::fabs(delta_ * c.cross) / (len1 * len2)) + 1;
      corner.ok = reach <= edgeIn && reach <= corner.edgeOut;
      if (!corner.ok && n >= 6) corner.ok = inBand(b, src, j, true) && inBand(a, src, j, false);
    }
    // Pass 2: runs of concave corners in a row (detours 3 points apart) where pass 1 left a detour, or
    // where two trims overlap on the edge between them, go by their envelope where it is sound (runTrim).
    envelope_.clear();
    const std::size_t count = detours_.size();
    const bool wraps = (detours_.back() + 3) % m == detours_[0];
    for (std::size_t t = 0; t < count;) {
      std::size_t e = t;
      bool open = !trims_[t].ok;
      while (e + 1 < count && detours_[e + 1] == detours_[e] + 3) {
        open = open || !trims_[e + 1].ok || trims_[e].out + trims_[e + 1].in + 2 > trims_[e].edgeOut;
        ++e;
      }
      if (open && e > t && !(wraps && (t == 0 || e + 1 == count))) runTrim(src, t, e);
      t = e + 1;
    }
    // Pass 3: two trimmed corners at the ends of one edge share it; a trim that also removes the point
    // before or after its detour keeps clear of the detours next to it.
    for (std::size_t t = 0; t < detours_.size(); ++t) {
      if (trims_[t].span == 0) continue;
      const std::size_t last = t + trims_[t].span - 1;  // a run's last detour
      const std::size_t next = last + 1 == detours_.size() ? 0 : last + 1;
      if (next == t) continue;
      const std::size_t gap = (detours_[next] + m - detours_[last]) % m;
      Trim& here = trims_[t];
      Trim& there = trims_[next];
      if (!here.ok || !there.ok) continue;
      if (gap == 3) {
        if (here.out + there.in + 2 > here.edgeOut) here.ok = there.ok = false;
      } else if ((gap == 4 || gap == 5) && here.after && there.before) {
        here.ok = there.ok = false;  // both would remove the same point or cut the same segment
      } else if (gap == 4 && (here.after || there.before)) {
        if (here.out + there.in + 2 > here.segOut) here.ok = there.ok = false;  // one segment, in order
      }
    }
    // Pass 4: the loop, each trimmed detour (or run) replaced by its crossing (or envelope).
    trimmed_.resize(m);
    IntPoint* out = trimmed_.data();
    std::size_t from = 0;
    for (std::size_t t = 0; t < detours_.size(); ++t) {
      const Trim& corner = trims_[t];
      if (!corner.ok) continue;
      const std::size_t i = detours_[t];
      out = std::copy(dest_.begin() + static_cast<std::ptrdiff_t>(from),
                      dest_.begin() + static_cast<std::ptrdiff_t>(i - corner.before), out);
      if (corner.span == 1) {
        *out++ = IntPoint(round(corner.x), round(corner.y));
      } else {
        out =
            std::copy(envelope_.begin() + corner.first, envelope_.begin() + corner.first + corner.count, out);
      }
      from = i + 3 * corner.span + corner.after;
    }
    out = std::copy(dest_.begin() + static_cast<std::ptrdiff_t>(from), dest_.end(), out);
    trimmed_.resize(static_cast<std::size_t>(out - trimmed_.data()));
  }

  // Where a corner's reach does not fit its edges, the small loop a trim removes may still lie where two
  // sweeps count (docs/DESIGN.md, "Growing by trimmed raw loops"): the edge v -> w after the corner moved
  // by d sweeps, together with the join at w when it is a mitre (or nearly straight) and the next edge,
  // a convex region; so does the edge before the corner with its own join and edge, backwards. A loop
  // whose corners lie in both regions lies in both, where the count is at least 2.
  //
  // Whether q lies in the region of the edge from the corner src[j] forward (or backward): in the edge's
  // frame (s along v -> w, h along delta n), s >= 0 and 0 <= h <= d; beyond w (s > |vw|), where w's join
  // is a mitre or nearly straight, also within the next edge's moved line and before its end. One unit
  // (a nanometre) of slack, as for the reach.
  bool inBand(const IntPoint& q, std::span<const IntPoint> src, std::size_t j, bool forward) const {
    const std::size_t n = src.size();
    const auto step = [&](std::size_t k) {
      return forward ? (k + 1 == n ? 0 : k + 1) : (k == 0 ? n - 1 : k - 1);
    };
    const std::size_t w = step(j), x = step(w);
    const Normal nv = normal(forward ? j : w), nx = normal(forward ? w : x);
    const double d = std::fabs(delta_), sign = delta_ < 0 ? -1.0 : 1.0;
    const double ex = static_cast<double>(src[w].X - src[j].X), ey = static_cast<double>(src[w].Y - src[j].Y);
    const double len = lengths_[forward ? j : w];
    if (!(len > 0)) return false;
    const double qx = static_cast<double>(q.X - src[j].X), qy = static_cast<double>(q.Y - src[j].Y);
    const double s = (qx * ex + qy * ey) / len, h = sign * (qx * nv.x + qy * nv.y);
    if (s < -1 || h < -1 || h > d + 1) return false;
    if (s <= len) return true;
    if (!sweepsItsKite(w)) return false;
    const double fx = static_cast<double>(src[x].X - src[w].X), fy = static_cast<double>(src[x].Y - src[w].Y);
    const double flen = lengths_[forward ? w : x];
    if (!(flen > 0)) return false;
    const double rx = static_cast<double>(q.X - src[w].X), ry = static_cast<double>(q.Y - src[w].Y);
    return sign * (rx * nx.x + ry * nx.y) <= d + 1 && (rx * fx + ry * fy) / flen <= flen;
  }

  // Whether vertex k's join sweeps the kite between its two moved edges: a mitre, or nearly straight.
  bool sweepsItsKite(std::size_t k) const { return kinds_[k] == kMitre || kinds_[k] == kStraight; }

  bool inBands(const IntPoint& q, std::span<const IntPoint> src, std::size_t j) const {
    return inBand(q, src, j, true) && inBand(q, src, j, false);
  }

  static double length(const IntPoint& p, const IntPoint& q) {
    const double x = static_cast<double>(q.X - p.X), y = static_cast<double>(q.Y - p.Y);
    return std::sqrt(x * x + y * y);
  }

  // Whether the segments p0 -> p1 and q0 -> q1 cross or touch.
  static bool meet(const IntPoint& p0, const IntPoint& p1, const IntPoint& q0, const IntPoint& q1) {
    const auto side = [](const IntPoint& o, const IntPoint& a, const IntPoint& b) {
      const double v = static_cast<double>(a.X - o.X) * static_cast<double>(b.Y - o.Y) -
                       static_cast<double>(a.Y - o.Y) * static_cast<double>(b.X - o.X);
      return (v > 0) - (v < 0);
    };
    return side(p0, p1, q0) * side(p0, p1, q1) <= 0 && side(q0, q1, p0) * side(q0, q1, p1) <= 0;
  }

  // A detour whose moved edges do not cross on both segments because one of them is swallowed (shorter
  // than the other edge's reach): the edge before it (A -> b) may cross the piece after the swallowed
  // edge (B -> C), or the piece before the swallowed edge (Z -> A) the edge after it (a -> B). Then the
  // five points X, b, v, a, B (or X, A, b, v, a) make a loop that goes, where it is simple and its
  // corners lie in both regions of inBand. Sets corner.x/y and .before/.after; returns whether it fits.
  bool swallowed(std::span<const IntPoint> src, std::size_t j, std::size_t i, const Crossing& c,
                 Trim& corner) const {
    const std::size_t m = dest_.size(), n = src.size();
    const std::size_t next = j + 1 == n ? 0 : j + 1, prev = j == 0 ? n - 1 : j - 1;
    IntPoint loop[5];
    if (c.u >= 1 && c.s > 0 && c.s < 1 && i >= 1 && i + 4 < m && sweepsItsKite(next)) {
      const IntPoint &A = dest_[i - 1], &B = dest_[i + 3], &C = dest_[i + 4];
      const Crossing e = crossing(A, dest_[i], B, C);
      if (!(e.valid && e.s > 0 && e.s < 1 && e.u > 0 && e.u < 1)) return false;
      corner.x = static_cast<double>(A.X) + e.s * static_cast<double>(dest_[i].X - A.X);
      corner.y = static_cast<double>(A.Y) + e.s * static_cast<double>(dest_[i].Y - A.Y);
      corner.after = 1;
      corner.in = (1 - e.s) * length(A, dest_[i]);
      corner.segOut = length(B, C);
      corner.out = e.u * corner.segOut;
      loop[1] = dest_[i], loop[2] = dest_[i + 1], loop[3] = dest_[i + 2], loop[4] = B;
    } else if (c.s <= 0 && c.u > 0 && c.u < 1 && i >= 2 && i + 3 < m && sweepsItsKite(prev)) {
      const IntPoint &Z = dest_[i - 2], &A = dest_[i - 1], &a = dest_[i + 2], &B = dest_[i + 3];
      const Crossing e = crossing(Z, A, a, B);
      if (!(e.valid && e.s > 0 && e.s < 1 && e.u > 0 && e.u < 1)) return false;
      corner.x = static_cast<double>(Z.X) + e.s * static_cast<double>(A.X - Z.X);
      corner.y = static_cast<double>(Z.Y) + e.s * static_cast<double>(A.Y - Z.Y);
      corner.before = 1;
      corner.in = (1 - e.s) * length(Z, A);
      corner.segOut = corner.edgeOut = length(a, B);
      corner.out = e.u * corner.segOut;
      loop[1] = A, loop[2] = dest_[i], loop[3] = dest_[i + 1], loop[4] = a;
    } else {
      return false;
    }
    loop[0] = IntPoint(round(corner.x), round(corner.y));
    for (const IntPoint& q : loop)
      if (!inBands(q, src, j)) return false;
    for (int e = 0; e < 5; ++e)  // simple: no two edges that are not neighbours meet
      for (int f = e + 2; f < 5; ++f)
        if (!(e == 0 && f == 4) && meet(loop[e], loop[e + 1], loop[f], loop[(f + 1) % 5])) return false;
    return true;
  }

  // A run of k concave corners in a row, v_1 = src[corners_[t]], ..., v_k = src[corners_[e]] (their
  // detours 3 points apart in dest_), between v_0 and v_{k+1}: its k + 1 moved edges (the first from
  // the point before the first detour, the last to the point after the last one) are replaced by their
  // envelope, the boundary of the region beyond all their lines, where that is sound (docs/DESIGN.md,
  // "Runs of concave corners"): the edges turn by less than a half turn in all and every edge's band
  // lies beyond every line; the envelope's first vertex stays on the first edge and its last on the
  // last edge while the distance grows (v_0 beyond every line by d (1 - n_0 . n_j), v_{k+1} likewise);
  // and the bands lie after v_0 along the first edge and before v_{k+1} along the last. One unit of
  // slack on each side, as for the reach. For one corner these are the reach rule of pass 1. Sets
  // trims_[t] to the run's trim.
  void runTrim(std::span<const IntPoint> src, std::size_t t, std::size_t e) {
    const std::size_t m = dest_.size(), n = src.size();
    const std::size_t k = e - t + 1, i0 = detours_[t];
    if (n < k + 4 || i0 < 1 || i0 + 3 * k >= m) return;
    const std::size_t j0 = corners_[t] + n - 1;  // v_i = src[(j0 + i) % n]; edge i runs from v_i
    const auto vertex = [&](std::size_t i) -> const IntPoint& { return src[(j0 + i) % n]; };
    const auto edgeNormal = [&](std::size_t i) { return normal((j0 + i) % n); };
    // Moved edge i: from the point before the first detour (i = 0) or a_i, to b_{i+1} or the point after.
    const auto from = [&](std::size_t i) -> const IntPoint& {
      return dest_[i == 0 ? i0 - 1 : i0 + 3 * i - 1];
    };
    const auto to = [&](std::size_t i) -> const IntPoint& { return dest_[i0 + 3 * i]; };
    const double d = std::fabs(delta_), sign = delta_ < 0 ? -1.0 : 1.0;
    const Normal n0 = edgeNormal(0), nk = edgeNormal(k);
    const auto dot = [](const Normal& a, const Normal& b) { return a.x * b.x + a.y * b.y; };
    // Less than a half turn in all: every corner turns one way by less than a half turn, so the normals
    // stay on one side of n_0 until the turn reaches a half.
    const auto cross = [](const Normal& a, const Normal& b) { return a.x * b.y - a.y * b.x; };
    const double way = cross(n0, edgeNormal(1)) > 0 ? 1.0 : -1.0;
    for (std::size_t i = 1; i <= k; ++i)
      if (!(way * cross(n0, edgeNormal(i)) > 0)) return;
    const auto over = [&](std::size_t j, double x, double y) {  // (x, y) over edge j's line, outwards
      const Normal nj = edgeNormal(j);
      return sign *
             ((x - static_cast<double>(vertex(j).X)) * nj.x + (y - static_cast<double>(vertex(j).Y)) * nj.y);
    };
    const auto height = [&](std::size_t j, const IntPoint& q) {
      return over(j, static_cast<double>(q.X), static_cast<double>(q.Y));
    };
    // Every band on the outer side of every line (the run is a convex arc, so this holds for edges less
    // than a quarter turn apart): the moved ends of the others.
    for (std::size_t i = 0; i <= k; ++i) {
      const Normal ni = edgeNormal(i);
      for (std::size_t j = 0; j <= k; ++j) {
        if (j == i || dot(ni, edgeNormal(j)) >= 0) continue;
        for (const std::size_t end : {i, i + 1}) {
          const double x = static_cast<double>(vertex(end).X) + delta_ * ni.x;
          const double y = static_cast<double>(vertex(end).Y) + delta_ * ni.y;
          if (over(j, x, y) < 1) return;
        }
      }
    }
    for (std::size_t j = 0; j <= k; ++j) {
      if (j > 0 && height(j, vertex(0)) < d * (1 - dot(n0, edgeNormal(j))) + 1) return;
      if (j < k && height(j, vertex(k + 1)) < d * (1 - dot(nk, edgeNormal(j))) + 1) return;
    }
    const IntPoint &v0 = vertex(0), &vk = vertex(k);
    const double l0 = lengths_[j0 % n], lk = lengths_[(j0 + k) % n];  // edges 0 and k
    if (!(l0 > 0 && lk > 0)) return;
    const double u0x = static_cast<double>(vertex(1).X - v0.X) / l0,
                 u0y = static_cast<double>(vertex(1).Y - v0.Y) / l0;
    const double ukx = static_cast<double>(vertex(k + 1).X - vk.X) / lk,
                 uky = static_cast<double>(vertex(k + 1).Y - vk.Y) / lk;
    for (std::size_t i = 0; i <= k; ++i) {  // the moved ends of edge i, along the first and the last edge
      const Normal ni = edgeNormal(i);
      for (const std::size_t end : {i, i + 1}) {
        const double qx = static_cast<double>(vertex(end).X) + delta_ * ni.x;
        const double qy = static_cast<double>(vertex(end).Y) + delta_ * ni.y;
        const double px = static_cast<double>(vertex(end).X), py = static_cast<double>(vertex(end).Y);
        if (i > 0 &&
            std::min((qx - static_cast<double>(v0.X)) * u0x + (qy - static_cast<double>(v0.Y)) * u0y,
                     (px - static_cast<double>(v0.X)) * u0x + (py - static_cast<double>(v0.Y)) * u0y) < 1)
          return;
        if (i < k && std::max((qx - static_cast<double>(vk.X)) * ukx + (qy - static_cast<double>(vk.Y)) * uky,
                              (px - static_cast<double>(vk.X)) * ukx +
                                  (py - static_cast<double>(vk.Y)) * uky) > lk - 1)
          return;
      }
    }
    // The envelope: the lines in turn, each dropping those before it whose piece it empties; at[l] is
    // where line lines[l] starts (a fraction of its moved edge), points[l - 1] that point.
    std::vector<uint32_t>& lines = runLines_;
    std::vector<double>& at = runAt_;
    std::vector<Point2d>& points = runPoints_;
    lines.assign(1, 0);
    at.assign(1, 0.0);
    points.clear();
    double first = 0;  // where the envelope leaves the first edge
    for (std::size_t i = 1; i <= k; ++i) {
      for (;;) {
        const std::size_t top = lines.back();
        const Crossing c = crossing(from(top), to(top), from(i), to(i));
        if (!c.valid) return;
        if (lines.size() > 1 && c.s <= at.back()) {
          lines.pop_back();
          at.pop_back();
          points.pop_back();
          continue;
        }
        if (lines.size() == 1) {
          if (!(c.s > 0 && c.s <= 1)) return;
          first = c.s;
        }
        const IntPoint& p = from(top);
        points.push_back({static_cast<double>(p.X) + c.s * static_cast<double>(to(top).X - p.X),
                          static_cast<double>(p.Y) + c.s * static_cast<double>(to(top).Y - p.Y)});
        lines.push_back(static_cast<uint32_t>(i));
        at.push_back(c.u);
        break;
      }
    }
    if (!(at.back() >= 0 && at.back() < 1)) return;
    Trim run;
    run.ok = true;
    run.span = static_cast<uint32_t>(k);
    run.first = static_cast<uint32_t>(envelope_.size());
    run.count = static_cast<uint32_t>(points.size());
    for (const Point2d& p : points) envelope_.push_back(IntPoint(round(p.x), round(p.y)));
    run.in = (1 - first) * length(from(0), to(0));
    run.segOut = length(from(k), to(k));
    run.out = at.back() * run.segOut;
    run.edgeOut = lk;
    for (std::size_t u = t; u <= e; ++u) {
      trims_[u] = Trim{};
      trims_[u].span = 0;
    }
    trims_[t] = run;
  }

  static constexpr uint8_t kStraight = 0, kDetour = 1, kMitre = 2, kSquare = 3;
  double delta_ = 0, miterBound_ = 0.5;
  std::vector<IntPoint> points_;
  std::vector<uint32_t> starts_{0};
  std::vector<double> lengths_;            // of each edge of the path
  std::vector<double> normalX_, normalY_;  // and its unit normal (offsetPath), read by normal(j)
  std::vector<uint8_t> kinds_;             // each source vertex's join: kStraight, kDetour, kMitre or kSquare
  Path dest_, trimmed_;
  std::vector<uint32_t> detours_;  // where each concave corner's three points start in dest_
  std::vector<uint32_t> corners_;  // and the source vertex of each
  std::vector<Trim> trims_;
  std::vector<IntPoint> envelope_;  // the runs' envelope points (runTrim)
  std::vector<uint32_t> runLines_;
  std::vector<double> runAt_;
  std::vector<Point2d> runPoints_;
  bool hasLowest_ = false;
  IntPoint lowestPoint_;
  std::size_t lowestPath_ = 0;
};

// What one thread reuses from layer to layer.
struct RawScratch {
  std::vector<IntPoint> units;
  std::vector<IntPoint> cleaned;
  LoopCleaner cleaner;
  RawOffset offset;

  // CleanPolygon, then ClipperOffset::AddPath.
  void add(std::span<const IntPoint> loop) {
    cleaned.clear();
    cleaner.clean(loop, kCleanMm * kOffsetUnitsPerMm, cleaned);
    offset.add(cleaned);
  }
};

RawScratch& rawScratch() {
  thread_local RawScratch scratch;
  return scratch;
}

// The trimmed raw offset loops of `region` for `mm`, each to sink(const Path&), before their union.
template <class Sink>
void trimmedRawLoops(const Paths& region, double mm, Sink&& sink) {
  RawScratch& scratch = rawScratch();
  scratch.offset.reset(static_cast<double>(toUnits(mm)), kMiterLimit);
  for (const Path& path : region) scratch.add(path);
  scratch.offset.build(sink);
}

Paths unite(const Paths& loops) {
  Paths united;
  ClipperLib::Clipper clipper;
  clipper.AddPaths(loops, ClipperLib::ptSubject, true);
  clipper.Execute(ClipperLib::ctUnion, united, ClipperLib::pftPositive, ClipperLib::pftPositive);
  return united;
}

// The region offset by `mm`: the positive-winding union of its trimmed raw offset loops. Growing
// (mm > 0): docs/DESIGN.md, "Growing by trimmed raw loops". Shrinking (mm < 0) a clean region (a union's
// polygons: count 0 or 1) is growing its complement, whose count 1 - count is never negative: the raw
// loops for -d are those for +d of the reversed loops, reversed, and ClipperOffset's own shrink is the
// region where their count is positive (the union under the negative rule with an outer box that it
// makes). So the trims apply alike, at the convex corners, and the region is ClipperOffset's.
Paths trimmedOffset(const Paths& region, double mm) {
  Paths loops;
  trimmedRawLoops(region, mm, [&](const Path& loop) { loops.push_back(loop); });
  return unite(loops);
}

// One closed loop of integer units appended to `out` in mm.
void appendLoop(const Path& loop, LayerContours& out) {
  constexpr double kMm = 1.0 / kOffsetUnitsPerMm;
  const std::size_t first = out.points.size();
  out.points.resize(first + loop.size());
  out.facets.resize(first + loop.size(), kCorrectedFacet);
  for (std::size_t i = 0; i < loop.size(); ++i)
    out.points[first + i] = {static_cast<double>(loop[i].X) * kMm, static_cast<double>(loop[i].Y) * kMm};
  out.endLoop(true);
}

void writeLoops(const Paths& paths, double z, LayerContours& out) {
  out.clear(z);
  for (const Path& path : paths)
    if (path.size() >= 3) appendLoop(path, out);
}

bool growsOnly(std::span<const ContourSet> sets, const LayerCorrection& correction) {
  return sets.size() == 1 && sets[0].sign > 0 && correction.absolute > 0 && !(correction.elephantFoot > 0);
}

}  // namespace

bool rawCorrectedLoops(std::span<const ContourSet> sets, const LayerCorrection& correction, double z,
                       LayerContours& out) {
  if (correction.absolute < 0 && !(correction.elephantFoot > 0)) {
    // trimmedOffset(solidRegion(sets, false), absolute) before its last union: the same loops.
    const Paths solid = solidRegion(sets, false);
    out.clear(z);
    trimmedRawLoops(solid, correction.absolute, [&](const Path& loop) { appendLoop(loop, out); });
    return true;
  }
  if (!growsOnly(sets, correction)) return false;
  // trimmedOffset(solidRegion(sets, true), absolute) before its union, without the Paths: the same loops.
  RawScratch& scratch = rawScratch();
  scratch.offset.reset(static_cast<double>(toUnits(correction.absolute)), kMiterLimit);
  const LayerContours& layer = *sets[0].layer;
  for (std::size_t l = 0; l < layer.loopCount(); ++l) {
    if (layer.loopClosed[l] == 0) continue;
    const std::span<const Point2d> loop = layer.loopPoints(l);
    if (loop.size() < 3 || !finiteLoop(loop)) continue;
    scratch.units.resize(loop.size());
    for (std::size_t i = 0; i < loop.size(); ++i)
      scratch.units[i] = IntPoint(roundToUnits(loop[i].x), roundToUnits(loop[i].y));
    scratch.add(scratch.units);
  }
  out.clear(z);
  scratch.offset.build([&](const Path& loop) { appendLoop(loop, out); });
  return true;
}

std::vector<std::array<int64_t, 2>> cleanedOutline(std::span<const std::array<int64_t, 2>> loop,
                                                   double distance) {
  Path in, out;
  for (const auto& p : loop) in.push_back(IntPoint(p[0], p[1]));
  LoopCleaner().clean(in, distance, out);
  std::vector<std::array<int64_t, 2>> kept;
  for (const IntPoint& p : out) kept.push_back({p.X, p.Y});
  return kept;
}

std::size_t unitePositive(const LayerContours& loops, double z, LayerContours& out) {
  Paths input;
  for (std::size_t l = 0; l < loops.loopCount(); ++l) {
    Path path;
    for (const Point2d& p : loops.loopPoints(l)) path.push_back(IntPoint(toUnits(p.x), toUnits(p.y)));
    input.push_back(std::move(path));
  }
  writeLoops(unite(input), z, out);
  return out.loopCount();
}

std::size_t correctLayer(std::span<const ContourSet> sets, const LayerCorrection& correction, double z,
                         LayerContours& out) {
  Paths solid = offset(solidRegion(sets, growsOnly(sets, correction)), correction.absolute);
  if (correction.elephantFoot > 0)
    solid = compensateElephantFoot(solid, correction.elephantFoot, correction.minWidth);
  writeLoops(solid, z, out);
  return out.loopCount();
}

}  // namespace toposlice
