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

namespace {

struct ScreenBox {
  double minX = std::numeric_limits<double>::infinity(), maxX = -minX, minY = minX, maxY = -minX;
};

// Depth towards the viewer (larger is nearer) and shade (negative: background) per sample.
struct SampleBuffer {
  std::vector<float> depth, shade;
  void reset(std::size_t samples) {
    depth.assign(samples, -std::numeric_limits<float>::infinity());
    shade.assign(samples, -1.0f);
  }
};

// The screen transform of one picture: camera coordinates to sample coordinates (x right, y down).
struct Projection {
  double scale, cx, cy, halfW, halfH;
};

// One picture being drawn: its projection, sample grid and buffer.
struct Target {
  Projection proj;
  uint32_t sw, sh;
  SampleBuffer* buffer;
};

// Draws facets [f0, f1) into every target: a sample takes the nearest facet's shade, and among facets
// at the same depth the first one. A facet's camera coordinates and shade are worked out once for all
// targets; each target's screen coordinates are then those of its own projection, as if drawn alone.
void drawFacets(std::span<const Point3f> corners, std::size_t f0, std::size_t f1, const Camera& cam,
                const Vec3& light, std::span<const Target> targets) {
  for (std::size_t f = f0; f < f1; ++f) {
    const Point3f* c = &corners[3 * f];
    if (!finite(c[0]) || !finite(c[1]) || !finite(c[2])) continue;
    double cx[3], cy[3], sd[3];
    for (int k = 0; k < 3; ++k) {
      const Vec3 p = toVec(c[k]);
      cx[k] = dot(p, cam.right);
      cy[k] = dot(p, cam.up);
      sd[k] = dot(p, cam.toward);
    }
    float s = -1;  // the shade, once a target needs it
    for (const Target& t : targets) {
      const Projection& proj = t.proj;
      double sx[3], sy[3];
      for (int k = 0; k < 3; ++k) {
        sx[k] = proj.halfW + (cx[k] - proj.cx) * proj.scale;
        sy[k] = proj.halfH - (cy[k] - proj.cy) * proj.scale;
      }
      // Samples whose centre (x + 0.5, y + 0.5) lies within the facet's box: most facets of a fine
      // mesh hold none, and need neither their area nor their shade.
      const double loX = std::max(0.0, std::ceil(std::min({sx[0], sx[1], sx[2]}) - 0.5));
      const double hiX = std::min(t.sw - 1.0, std::floor(std::max({sx[0], sx[1], sx[2]}) - 0.5));
      if (!(loX <= hiX)) continue;
      const double loY = std::max(0.0, std::ceil(std::min({sy[0], sy[1], sy[2]}) - 0.5));
      const double hiY = std::min(t.sh - 1.0, std::floor(std::max({sy[0], sy[1], sy[2]}) - 0.5));
      if (!(loY <= hiY)) continue;
      const double area = edge(sx[0], sy[0], sx[1], sy[1], sx[2], sy[2]);
      if (!(std::abs(area) > 1e-12)) continue;
      if (s < 0) {
        Vec3 n = normalized(cross(toVec(c[1]) - toVec(c[0]), toVec(c[2]) - toVec(c[0])));
        if (dot(n, cam.toward) < 0) n = {-n.x, -n.y, -n.z};
        s = static_cast<float>(0.25 + 0.75 * std::max(0.0, dot(n, light)));
      }
      SampleBuffer& buffer = *t.buffer;
      for (double y = loY; y <= hiY; ++y) {
        const double py = y + 0.5;
        for (double x = loX; x <= hiX; ++x) {
          const double px = x + 0.5;
          const double b0 = edge(sx[1], sy[1], sx[2], sy[2], px, py) / area;
          const double b1 = edge(sx[2], sy[2], sx[0], sy[0], px, py) / area;
          const double b2 = 1 - b0 - b1;
          if (b0 < 0 || b1 < 0 || b2 < 0) continue;
          const float d = static_cast<float>(b0 * sd[0] + b1 * sd[1] + b2 * sd[2]);
          const std::size_t at = static_cast<std::size_t>(y) * t.sw + static_cast<std::size_t>(x);
          if (d > buffer.depth[at]) {
            buffer.depth[at] = d;
            buffer.shade[at] = s;
          }
        }
      }
    }
  }
}

// std::lround of a value in [0, 255.5), without the library call.
uint8_t roundChannel(double v) {
  const auto t = static_cast<uint32_t>(v);
  return static_cast<uint8_t>(t + (v - t >= 0.5 ? 1 : 0));
}

}  // namespace

void renderPreview(std::span<const Point3f> corners, uint32_t width, uint32_t height, RgbImage& out,
                   const ChunkRunner& runner) {
  const PreviewSize size{width, height};
  renderPreviews(corners, {&size, 1}, {&out, 1}, runner);
}

void renderPreviews(std::span<const Point3f> corners, std::span<const PreviewSize> sizes,
                    std::span<RgbImage> outs, const ChunkRunner& runner) {
  constexpr uint32_t kSamples = 2;             // per pixel and axis
  constexpr std::size_t kBoundsGrain = 32768;  // facets per chunk of the bounding box
  // Facets per piece drawn into its own buffers, and at most this many pieces (each holds buffers).
  constexpr std::size_t kMinPieceFacets = 32768;
  constexpr std::size_t kMaxPieces = 8;
  const std::size_t pictures = std::min(sizes.size(), outs.size());
  const Camera cam = previewCamera();
  const Point3f lf = previewLightDirection();
  const Vec3 light{lf.x, lf.y, lf.z};
  const std::size_t facets = corners.size() / 3;
  // The projected bounding box, per chunk, then combined (min and max: the same for any split).
  std::vector<ScreenBox> boxes((facets + kBoundsGrain - 1) / kBoundsGrain);
  runner.run(boxes.size(), 1, [&](std::size_t b0, std::size_t b1) {
    for (std::size_t b = b0; b < b1; ++b) {
      ScreenBox& box = boxes[b];
      const std::size_t end = std::min(facets, (b + 1) * kBoundsGrain) * 3;
      for (std::size_t i = b * kBoundsGrain * 3; i < end; ++i) {
        if (!finite(corners[i])) continue;
        const Vec3 p = toVec(corners[i]);
        const double x = dot(p, cam.right), y = dot(p, cam.up);
        box.minX = std::min(box.minX, x);
        box.maxX = std::max(box.maxX, x);
        box.minY = std::min(box.minY, y);
        box.maxY = std::max(box.maxY, y);
      }
    }
  });
  ScreenBox all;
  for (const ScreenBox& b : boxes) {
    all.minX = std::min(all.minX, b.minX);
    all.maxX = std::max(all.maxX, b.maxX);
    all.minY = std::min(all.minY, b.minY);
    all.maxY = std::max(all.maxY, b.maxY);
  }
  const bool anything = all.minX <= all.maxX;
  // Facets are split into pieces, each drawn into its own buffers; merged in piece order, a sample keeps
  // the first piece's facet among the nearest, so the pictures are the serial ones for any split.
  const std::size_t pieces =
      anything ? std::clamp<std::size_t>(std::min<std::size_t>(runner.width, facets / kMinPieceFacets), 1,
                                         kMaxPieces)
               : 1;
  std::vector<std::vector<SampleBuffer>> buffers(pictures, std::vector<SampleBuffer>(pieces));
  std::vector<Projection> projections(pictures);
  for (std::size_t i = 0; i < pictures; ++i) {
    const uint32_t sw = sizes[i].width * kSamples, sh = sizes[i].height * kSamples;
    Projection& proj = projections[i];
    proj = {0, 0, 0, 0.5 * sw, 0.5 * sh};
    if (anything) {
      const double margin = 0.06 * std::min(sw, sh);
      const double spanX = std::max(all.maxX - all.minX, 1e-12), spanY = std::max(all.maxY - all.minY, 1e-12);
      proj.scale = std::min((sw - 2 * margin) / spanX, (sh - 2 * margin) / spanY);
      proj.cx = 0.5 * (all.minX + all.maxX);
      proj.cy = 0.5 * (all.minY + all.maxY);
    }
  }
  runner.run(pieces, 1, [&](std::size_t p0, std::size_t p1) {
    std::vector<Target> targets;
    for (std::size_t p = p0; p < p1; ++p) {
      targets.clear();
      for (std::size_t i = 0; i < pictures; ++i) {
        const uint32_t sw = sizes[i].width * kSamples, sh = sizes[i].height * kSamples;
        buffers[i][p].reset(std::size_t{sw} * sh);
        targets.push_back({projections[i], sw, sh, &buffers[i][p]});
      }
      if (anything) drawFacets(corners, facets * p / pieces, facets * (p + 1) / pieces, cam, light, targets);
    }
  });
  for (std::size_t i = 0; i < pictures; ++i) {
    const uint32_t width = sizes[i].width, height = sizes[i].height, sw = width * kSamples;
    RgbImage& out = outs[i];
    out.width = width;
    out.height = height;
    out.rgb.assign(std::size_t{width} * height * 3, 0);
    std::vector<SampleBuffer>& pictureBuffers = buffers[i];
    SampleBuffer& merged = pictureBuffers[0];
    runner.run(height, 16, [&](std::size_t y0, std::size_t y1) {
      for (std::size_t at = y0 * kSamples * sw; at < y1 * kSamples * sw; ++at) {
        for (std::size_t p = 1; p < pieces; ++p) {
          if (pictureBuffers[p].depth[at] > merged.depth[at]) {
            merged.depth[at] = pictureBuffers[p].depth[at];
            merged.shade[at] = pictureBuffers[p].shade[at];
          }
        }
      }
      for (std::size_t y = y0; y < y1; ++y) {
        for (uint32_t x = 0; x < width; ++x) {
          double sum[3] = {0, 0, 0};
          for (uint32_t j = 0; j < kSamples; ++j) {
            for (uint32_t i2 = 0; i2 < kSamples; ++i2) {
              const float s = merged.shade[(y * kSamples + j) * sw + x * kSamples + i2];
              for (int k = 0; k < 3; ++k) sum[k] += s < 0 ? kPreviewBackground[k] : kPreviewModel[k] * s;
            }
          }
          uint8_t* px = &out.rgb[(y * width + x) * 3];
          for (int k = 0; k < 3; ++k) px[k] = roundChannel(std::min(255.0, sum[k] / (kSamples * kSamples)));
        }
      }
    });
  }
}

}  // namespace toposlice
