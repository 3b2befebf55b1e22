#include "offset/polygon_offset.h"

#include <polyclipping/clipper.hpp>

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

// Clean, oriented polygons grown by `mm` (shrunk when negative); Clipper unions the pieces.
Paths offset(const Paths& region, double mm) {
  if (region.empty()) return {};
  if (mm == 0) return region;
  ClipperLib::ClipperOffset offsetter(kMiterLimit);
  // Vertices within kCleanMm of their neighbours' line go first: dense, nearly straight outlines of
  // fine meshes otherwise make the offset's self-intersection pass the slowest step by far.
  Paths cleaned;
  ClipperLib::CleanPolygons(region, cleaned, kCleanMm * kOffsetUnitsPerMm);
  offsetter.AddPaths(cleaned, ClipperLib::jtMiter, ClipperLib::etClosedPolygon);
  Paths out;
  offsetter.Execute(out, static_cast<double>(toUnits(mm)));
  return out;
}

Paths combine(const Paths& a, const Paths& b, ClipperLib::ClipType type) {
  Paths out;
  ClipperLib::Clipper clipper;
  clipper.AddPaths(a, ClipperLib::ptSubject, true);
  clipper.AddPaths(b, ClipperLib::ptClip, true);
  clipper.Execute(type, out, ClipperLib::pftNonZero, ClipperLib::pftNonZero);
  return out;
}

Paths compensateElephantFoot(const Paths& solid, double shrink, double minWidth) {
  Paths shrunk = offset(solid, -shrink);
  const double r = 0.5 * minWidth;
  if (!(r > 0)) return shrunk;
  const Paths opened = offset(offset(solid, -r), r);
  Paths thin = combine(solid, opened, ClipperLib::ctDifference);
  thin = offset(offset(thin, -kSliverMm), kSliverMm);
  if (thin.empty()) return shrunk;
  const Paths roots = combine(offset(thin, shrink), solid, ClipperLib::ctIntersection);
  return combine(shrunk, roots, ClipperLib::ctUnion);
}

// The result of ClipperOffset::Execute before its union, for closed polygons and mitred joins
// (Clipper 6.4's ClipperOffset: AddPath, FixOrientations, DoOffset, OffsetPoint, DoMiter, DoSquare),
// re-derived here: the same points in the same order.
class RawOffset {
 public:
  RawOffset(double delta, double miterLimit)
      : delta_(delta), miterBound_(miterLimit > 2 ? 2 / (miterLimit * miterLimit) : 0.5) {}

  // AddPath: consecutive duplicates (and a last point equal to the first) dropped; fewer than three
  // points left: nothing. Also tracks the lowest point (largest y, then smallest x) of all paths.
  void add(const Path& path) {
    std::size_t last = path.size();
    while (last > 1 && path[0] == path[last - 1]) --last;
    if (last < 3) return;
    Path clean;
    clean.reserve(last);
    clean.push_back(path[0]);
    std::size_t lowest = 0;
    for (std::size_t i = 1; i < last; ++i) {
      if (path[i] == clean.back()) continue;
      clean.push_back(path[i]);
      if (lower(path[i], clean[lowest])) lowest = clean.size() - 1;
    }
    if (clean.size() < 3) return;
    const IntPoint p = clean[lowest];
    if (!hasLowest_ || lower(p, lowestPoint_)) {
      hasLowest_ = true;
      lowestPoint_ = p;
      lowestPath_ = paths_.size();
    }
    paths_.push_back(std::move(clean));
  }

  // FixOrientations, then DoOffset for every path.
  void build(Paths& out) {
    if (hasLowest_ && !ClipperLib::Orientation(paths_[lowestPath_]))
      for (Path& p : paths_) ClipperLib::ReversePath(p);
    for (const Path& src : paths_) {
      const std::size_t n = src.size();
      normals_.resize(n);
      for (std::size_t j = 0; j < n; ++j) normals_[j] = unitNormal(src[j], src[j + 1 == n ? 0 : j + 1]);
      Path dest;
      dest.reserve(n + n / 2);
      std::size_t k = n - 1;
      for (std::size_t j = 0; j < n; ++j) offsetPoint(src, j, k, dest);
      out.push_back(std::move(dest));
    }
  }

 private:
  struct Normal {
    double x, y;
  };

  static Normal unitNormal(const IntPoint& a, const IntPoint& b) {
    if (a.X == b.X && a.Y == b.Y) return {0, 0};
    double dx = static_cast<double>(b.X - a.X), dy = static_cast<double>(b.Y - a.Y);
    const double f = 1 / std::sqrt(dx * dx + dy * dy);
    dx *= f;
    dy *= f;
    return {dy, -dx};
  }

  // Clipper's order for the lowest point: larger y, then smaller x.
  static bool lower(const IntPoint& a, const IntPoint& b) { return a.Y > b.Y || (a.Y == b.Y && a.X < b.X); }

  static cInt round(double v) { return v < 0 ? static_cast<cInt>(v - 0.5) : static_cast<cInt>(v + 0.5); }

  IntPoint moved(const IntPoint& p, double x, double y) const {
    return IntPoint(round(static_cast<double>(p.X) + x), round(static_cast<double>(p.Y) + y));
  }

  void offsetPoint(const Path& src, std::size_t j, std::size_t& k, Path& dest) const {
    const Normal nk = normals_[k], nj = normals_[j];
    const IntPoint& p = src[j];
    double sinA = nk.x * nj.y - nj.x * nk.y;
    if (std::fabs(sinA * delta_) < 1.0) {
      if (nk.x * nj.x + nj.y * nk.y > 0) {  // nearly straight on: one point, and k stays (as in Clipper)
        dest.push_back(moved(p, nk.x * delta_, nk.y * delta_));
        return;
      }
    } else if (sinA > 1.0) {
      sinA = 1.0;
    } else if (sinA < -1.0) {
      sinA = -1.0;
    }
    if (sinA * delta_ < 0) {  // concave: through the vertex
      dest.push_back(moved(p, nk.x * delta_, nk.y * delta_));
      dest.push_back(p);
      dest.push_back(moved(p, nj.x * delta_, nj.y * delta_));
    } else {
      const double r = 1 + (nj.x * nk.x + nj.y * nk.y);
      if (r >= miterBound_) {  // mitre
        const double q = delta_ / r;
        dest.push_back(moved(p, (nk.x + nj.x) * q, (nk.y + nj.y) * q));
      } else {  // squared off
        const double dx = std::tan(std::atan2(sinA, nk.x * nj.x + nk.y * nj.y) / 4);
        dest.push_back(moved(p, delta_ * (nk.x - nk.y * dx), delta_ * (nk.y + nk.x * dx)));
        dest.push_back(moved(p, delta_ * (nj.x + nj.y * dx), delta_ * (nj.y - nj.x * dx)));
      }
    }
    k = j;
  }

  double delta_, miterBound_;
  std::vector<Path> paths_;
  std::vector<Normal> normals_;
  bool hasLowest_ = false;
  IntPoint lowestPoint_;
  std::size_t lowestPath_ = 0;
};

void writeLoops(const Paths& paths, double z, LayerContours& out) {
  out.clear(z);
  constexpr double kMm = 1.0 / kOffsetUnitsPerMm;
  for (const Path& path : paths) {
    if (path.size() < 3) continue;
    for (const IntPoint& p : path)
      out.addPoint({static_cast<double>(p.X) * kMm, static_cast<double>(p.Y) * kMm}, kCorrectedFacet);
    out.endLoop(true);
  }
}

bool growsOnly(std::span<const ContourSet> sets, const LayerCorrection& correction) {
  return sets.size() == 1 && sets[0].sign > 0 && correction.absolute > 0 && !(correction.elephantFoot > 0);
}

}  // namespace

bool rawCorrectedLoops(std::span<const ContourSet> sets, const LayerCorrection& correction, double z,
                       LayerContours& out) {
  if (!growsOnly(sets, correction)) return false;
  const Paths region = solidRegion(sets, true);
  Paths cleaned;
  ClipperLib::CleanPolygons(region, cleaned, kCleanMm * kOffsetUnitsPerMm);
  RawOffset raw(static_cast<double>(toUnits(correction.absolute)), kMiterLimit);
  for (const Path& p : cleaned) raw.add(p);
  Paths loops;
  raw.build(loops);
  writeLoops(loops, z, out);
  return true;
}

std::size_t unitePositive(const LayerContours& loops, double z, LayerContours& out) {
  Paths input;
  for (std::size_t l = 0; l < loops.loopCount(); ++l) {
    Path path;
    for (const Point2d& p : loops.loopPoints(l)) path.push_back(IntPoint(toUnits(p.x), toUnits(p.y)));
    input.push_back(std::move(path));
  }
  Paths united;
  ClipperLib::Clipper clipper;
  clipper.AddPaths(input, ClipperLib::ptSubject, true);
  clipper.Execute(ClipperLib::ctUnion, united, ClipperLib::pftPositive, ClipperLib::pftPositive);
  writeLoops(united, z, out);
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
