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

}  // namespace

std::size_t correctLayer(std::span<const ContourSet> sets, const LayerCorrection& correction, double z,
                         LayerContours& out) {
  const bool growOnly =
      sets.size() == 1 && sets[0].sign > 0 && correction.absolute > 0 && !(correction.elephantFoot > 0);
  Paths solid = offset(solidRegion(sets, growOnly), correction.absolute);
  if (correction.elephantFoot > 0)
    solid = compensateElephantFoot(solid, correction.elephantFoot, correction.minWidth);
  out.clear(z);
  constexpr double kMm = 1.0 / kOffsetUnitsPerMm;
  for (const Path& path : solid) {
    if (path.size() < 3) continue;
    for (const IntPoint& p : path)
      out.addPoint({static_cast<double>(p.X) * kMm, static_cast<double>(p.Y) * kMm}, kCorrectedFacet);
    out.endLoop(true);
  }
  return out.loopCount();
}

}  // namespace toposlice
