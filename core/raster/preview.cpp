// Preview renderer (preview.h): project, fit, rasterize with edge functions and a depth buffer at 2 x 2
// samples per pixel, then average the samples.
#include "core/raster/preview.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

namespace toposlice {
namespace {

struct Vec3 {
  double x, y, z;
};

Vec3 operator-(Vec3 a, Vec3 b) {
  return {a.x - b.x, a.y - b.y, a.z - b.z};
}
double dot(Vec3 a, Vec3 b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
Vec3 cross(Vec3 a, Vec3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
Vec3 normalized(Vec3 a) {
  const double n = std::sqrt(dot(a, a));
  return n > 0 ? Vec3{a.x / n, a.y / n, a.z / n} : Vec3{0, 0, 0};
}
Vec3 toVec(Point3f p) {
  return {p.x, p.y, p.z};
}

struct Camera {
  Vec3 right, up, toward;  // screen x, screen y, and the direction towards the viewer
};

Camera previewCamera() {
  constexpr double kDeg = std::numbers::pi / 180;
  const double az = kPreviewAzimuthDeg * kDeg, el = kPreviewElevationDeg * kDeg;
  Camera c;
  c.toward = {std::cos(el) * std::sin(az), -std::cos(el) * std::cos(az), std::sin(el)};
  c.right = {std::cos(az), std::sin(az), 0};
  c.up = cross(c.toward, c.right);
  return c;
}

bool finite(Point3f p) {
  return std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z);
}

// Signed doubled area of (a, b, p): positive when p is left of a->b in screen coordinates (y down).
double edge(double ax, double ay, double bx, double by, double px, double py) {
  return (bx - ax) * (py - ay) - (by - ay) * (px - ax);
}

}  // namespace

Point3f previewLightDirection() {
  const Vec3 l = normalized({-0.35, -0.55, 1.0});
  return {static_cast<float>(l.x), static_cast<float>(l.y), static_cast<float>(l.z)};
}

void renderPreview(std::span<const Point3f> corners, uint32_t width, uint32_t height, RgbImage& out) {
  constexpr uint32_t kSamples = 2;  // per pixel and axis
  out.width = width;
  out.height = height;
  out.rgb.assign(std::size_t{width} * height * 3, 0);
  const uint32_t sw = width * kSamples, sh = height * kSamples;
  // Per sample: depth towards the viewer (larger is nearer) and shade (negative: background).
  std::vector<float> depth(std::size_t{sw} * sh, -std::numeric_limits<float>::infinity());
  std::vector<float> shade(std::size_t{sw} * sh, -1.0f);

  const Camera cam = previewCamera();
  const Point3f lf = previewLightDirection();
  const Vec3 light{lf.x, lf.y, lf.z};
  double minX = std::numeric_limits<double>::infinity(), maxX = -minX, minY = minX, maxY = -minX;
  const std::size_t facets = corners.size() / 3;
  for (std::size_t i = 0; i < facets * 3; ++i) {
    if (!finite(corners[i])) continue;
    const Vec3 p = toVec(corners[i]);
    const double x = dot(p, cam.right), y = dot(p, cam.up);
    minX = std::min(minX, x);
    maxX = std::max(maxX, x);
    minY = std::min(minY, y);
    maxY = std::max(maxY, y);
  }
  if (minX <= maxX) {
    const double margin = 0.06 * std::min(sw, sh);
    const double spanX = std::max(maxX - minX, 1e-12), spanY = std::max(maxY - minY, 1e-12);
    const double scale = std::min((sw - 2 * margin) / spanX, (sh - 2 * margin) / spanY);
    const double cx = 0.5 * (minX + maxX), cy = 0.5 * (minY + maxY);
    for (std::size_t f = 0; f < facets; ++f) {
      const Point3f* c = &corners[3 * f];
      if (!finite(c[0]) || !finite(c[1]) || !finite(c[2])) continue;
      double sx[3], sy[3], sd[3];
      for (int k = 0; k < 3; ++k) {
        const Vec3 p = toVec(c[k]);
        sx[k] = 0.5 * sw + (dot(p, cam.right) - cx) * scale;
        sy[k] = 0.5 * sh - (dot(p, cam.up) - cy) * scale;
        sd[k] = dot(p, cam.toward);
      }
      const double area = edge(sx[0], sy[0], sx[1], sy[1], sx[2], sy[2]);
      if (!(std::abs(area) > 1e-12)) continue;
      Vec3 n = normalized(cross(toVec(c[1]) - toVec(c[0]), toVec(c[2]) - toVec(c[0])));
      if (dot(n, cam.toward) < 0) n = {-n.x, -n.y, -n.z};
      const float s = static_cast<float>(0.25 + 0.75 * std::max(0.0, dot(n, light)));
      const double loX = std::max(0.0, std::floor(std::min({sx[0], sx[1], sx[2]})));
      const double hiX = std::min(sw - 1.0, std::ceil(std::max({sx[0], sx[1], sx[2]})));
      const double loY = std::max(0.0, std::floor(std::min({sy[0], sy[1], sy[2]})));
      const double hiY = std::min(sh - 1.0, std::ceil(std::max({sy[0], sy[1], sy[2]})));
      for (double y = loY; y <= hiY; ++y) {
        const double py = y + 0.5;
        for (double x = loX; x <= hiX; ++x) {
          const double px = x + 0.5;
          const double b0 = edge(sx[1], sy[1], sx[2], sy[2], px, py) / area;
          const double b1 = edge(sx[2], sy[2], sx[0], sy[0], px, py) / area;
          const double b2 = 1 - b0 - b1;
          if (b0 < 0 || b1 < 0 || b2 < 0) continue;
          const float d = static_cast<float>(b0 * sd[0] + b1 * sd[1] + b2 * sd[2]);
          const std::size_t at = static_cast<std::size_t>(y) * sw + static_cast<std::size_t>(x);
          if (d > depth[at]) {
            depth[at] = d;
            shade[at] = s;
          }
        }
      }
    }
  }
  for (uint32_t y = 0; y < height; ++y) {
    for (uint32_t x = 0; x < width; ++x) {
      double sum[3] = {0, 0, 0};
      for (uint32_t j = 0; j < kSamples; ++j) {
        for (uint32_t i = 0; i < kSamples; ++i) {
          const float s = shade[std::size_t{y * kSamples + j} * sw + x * kSamples + i];
          for (int k = 0; k < 3; ++k) sum[k] += s < 0 ? kPreviewBackground[k] : kPreviewModel[k] * s;
        }
      }
      uint8_t* px = &out.rgb[(std::size_t{y} * width + x) * 3];
      for (int k = 0; k < 3; ++k)
        px[k] = static_cast<uint8_t>(std::lround(std::min(255.0, sum[k] / (kSamples * kSamples))));
    }
  }
}

}  // namespace toposlice
