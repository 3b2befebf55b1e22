// GOO writer (goo_writer.h). Field numbers in the comments are the specification's header indices.
#include "io/masks/goo_writer.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <string>
#include <string_view>

#include "core/raster/preview.h"
#include "io/errors.h"
#include "io/output_file.h"

namespace toposlice {
namespace {

constexpr uint8_t kDelimiter[2] = {0x0D, 0x0A};
constexpr uint8_t kEnding[11] = {0x00, 0x00, 0x00, 0x07, 0x00, 0x00, 0x00, 0x44, 0x4C, 0x50, 0x00};
constexpr uint8_t kLayerMagic = 0x55;
constexpr std::size_t kLayerDefinitionSize = 2 + 15 * 4 + 2 + 2;  // through the delimiter
constexpr std::size_t kChunksAt = kLayerDefinitionSize + 4 + 1;   // data size, 0x55

// Appends big-endian fields to a byte vector.
class BigEndian {
 public:
  explicit BigEndian(std::vector<uint8_t>& out) : out_(out) {}
  void u8(uint8_t v) { out_.push_back(v); }
  void u16(uint16_t v) { bytes(v, 2); }
  void u32(uint32_t v) { bytes(v, 4); }
  void f32(double v) { u32(std::bit_cast<uint32_t>(static_cast<float>(v))); }
  void raw(const uint8_t* p, std::size_t n) { out_.insert(out_.end(), p, p + n); }
  // A fixed-size string field: the text cut to size - 1 bytes, then zeros.
  void text(std::string_view s, std::size_t size) {
    const std::size_t n = std::min(s.size(), size - 1);
    out_.insert(out_.end(), s.begin(), s.begin() + static_cast<std::ptrdiff_t>(n));
    out_.insert(out_.end(), size - n, 0);
  }

 private:
  void bytes(uint32_t v, int n) {
    for (int i = n - 1; i >= 0; --i) out_.push_back(static_cast<uint8_t>(v >> (8 * i)));
  }
  std::vector<uint8_t>& out_;
};

uint32_t fadeLayersOf(const MaskJob& job) {
  return std::clamp<uint32_t>(job.fadeLayers, 2, 200);
}

double machineHeight(const MaskJob& job, uint32_t layers) {
  return std::max(150.0, std::ceil(layers * job.layerHeight));
}

// Seconds for one layer: exposure, the wait before it, lift and retract at their speeds.
double layerSeconds(const MaskJob& job, uint32_t index) {
  const bool bottom = index == 0;
  const double lift = bottom ? job.bottomLiftDistance : job.liftDistance;
  const double liftSpeed = bottom ? job.bottomLiftSpeed : job.liftSpeed;
  double s = gooLayerExposure(job, index) + job.waitBeforeExposure;
  if (liftSpeed > 0) s += lift / liftSpeed * 60;
  if (job.retractSpeed > 0) s += lift / job.retractSpeed * 60;
  return s;
}

// RGB565, red in the high bits, stored big-endian.
void appendRgb565(BigEndian& out, const RgbImage& image) {
  for (std::size_t i = 0; i < image.rgb.size(); i += 3) {
    const uint16_t r = image.rgb[i] >> 3, g = image.rgb[i + 1] >> 2, b = image.rgb[i + 2] >> 3;
    out.u16(static_cast<uint16_t>(r << 11 | g << 5 | b));
  }
}

// The whole header; `layers`, the volume and the print time are placeholders (0) until finish().
std::vector<uint8_t> gooHeader(const MaskJob& job, uint32_t layers, const std::vector<uint8_t>& previews) {
  std::vector<uint8_t> bytes;
  bytes.reserve(kGooHeaderSize);
  BigEndian h(bytes);
  constexpr uint8_t kVersion[4] = {'V', '3', '.', '0'};
  h.raw(kVersion, 4);  // 0
  constexpr uint8_t kMagic[8] = {0x07, 0x00, 0x00, 0x00, 0x44, 0x4C, 0x50, 0x00};
  h.raw(kMagic, 8);                    // 1
  h.text(kSoftwareName, 32);           // 2: how --force knows the file (checkReplaceable)
  h.text(TOPOSLICE_VERSION_TEXT, 24);  // 3
  const std::time_t created = maskCreationTime(job);
  std::tm t{};
  gmtime_r(&created, &t);
  char stamp[32];
  std::strftime(stamp, sizeof stamp, "%Y-%m-%d %H:%M:%S", &t);
  h.text(stamp, 24);                                                      // 4
  h.text(job.printerModel.empty() ? "toposlice" : job.printerModel, 32);  // 5
  h.text("MSLA", 32);                                                     // 6
  h.text("toposlice", 32);                                                // 7
  h.u16(job.antiAliased ? 8 : 1);                                         // 8 anti-aliasing level
  h.u16(1);                                                               // 9 grey level
  h.u16(0);                                                               // 10 blur level
  const std::size_t small = std::size_t{kGooSmallPreview} * kGooSmallPreview * 2;
  h.raw(previews.data(), small);                            // 11
  h.raw(kDelimiter, 2);                                     // 12
  h.raw(previews.data() + small, previews.size() - small);  // 13
  h.raw(kDelimiter, 2);                                     // 14
  h.u32(layers);                                            // 15
  h.u16(static_cast<uint16_t>(job.grid.width));             // 16
  h.u16(static_cast<uint16_t>(job.grid.height));            // 17
  h.u8(job.grid.mirrorX ? 1 : 0);                           // 18
  h.u8(job.grid.mirrorY ? 1 : 0);                           // 19
  h.f32(job.grid.width * job.grid.pixel);                   // 20
  h.f32(job.grid.height * job.grid.pixel);                  // 21
  h.f32(machineHeight(job, layers));                        // 22
  h.f32(job.layerHeight);                                   // 23
  h.f32(job.exposureTime);                                  // 24
  h.u8(1);                                                  // 25 delay mode: static waits
  h.f32(0);                                                 // 26 turn-off time
  h.f32(0);                                                 // 27 bottom before lift
  h.f32(0);                                                 // 28 bottom after lift
  h.f32(job.waitBeforeExposure);                            // 29 bottom after retract
  h.f32(0);                                                 // 30 before lift
  h.f32(0);                                                 // 31 after lift
  h.f32(job.waitBeforeExposure);                            // 32 after retract
  h.f32(job.initialExposureTime);                           // 33
  h.u32(1);                                                 // 34 bottom layers
  h.f32(job.bottomLiftDistance);                            // 35
  h.f32(job.bottomLiftSpeed);                               // 36
  h.f32(job.liftDistance);                                  // 37
  h.f32(job.liftSpeed);                                     // 38
  h.f32(job.bottomLiftDistance);                            // 39 bottom retract
  h.f32(job.retractSpeed);                                  // 40
  h.f32(job.liftDistance);                                  // 41 retract
  h.f32(job.retractSpeed);                                  // 42
  for (int field = 43; field <= 50; ++field) h.f32(0);      // 43-50 no second stage
  h.u16(job.lightPwm);                                      // 51
  h.u16(job.lightPwm);                                      // 52
  h.u8(0);                                                  // 53 normal mode
  double seconds = 0;
  for (uint32_t i = 0; i < layers; ++i) seconds += layerSeconds(job, i);
  h.u32(static_cast<uint32_t>(std::lround(seconds)));  // 54
  h.f32(job.volumeMl * 1000);                          // 55 mm^3
  h.f32(job.volumeMl * job.resinDensity);              // 56 g
  h.f32(0);                                            // 57 price
  h.text("$", 8);                                      // 58
  h.u32(static_cast<uint32_t>(kGooHeaderSize));        // 59
  h.u8(1);                                             // 60 grey values 0..255
  // 61 transition layers: the fade's, as many as the file has after its bottom layer at most
  h.u16(static_cast<uint16_t>(std::min(fadeLayersOf(job) - 2, layers > 0 ? layers - 1 : 0)));
  return bytes;
}

// Collects pixels into runs and hands finished runs to appendGooRun.
class RunBuilder {
 public:
  explicit RunBuilder(std::vector<uint8_t>& out) : out_(out) {}
  void add(uint8_t value, uint32_t length) {
    if (length == 0) return;
    if (value != value_ || uint64_t{length_} + length > kGooMaxRun) flush();
    value_ = value;
    length_ += length;
  }
  void flush() {
    if (length_ > 0) appendGooRun(out_, value_, length_);
    length_ = 0;
  }

 private:
  std::vector<uint8_t>& out_;
  uint8_t value_ = 0;
  uint32_t length_ = 0;
};

void appendPixels(RunBuilder& runs, const uint8_t* p, uint32_t n) {
  uint32_t i = 0;
  while (i < n) {
    const uint8_t v = p[i];
    uint32_t j = i + 1;
    while (j < n && p[j] == v) ++j;
    runs.add(v, j - i);
    i = j;
  }
}

class GooSink final : public EncodingMaskSink {
 public:
  GooSink(const std::filesystem::path& path, const MaskJob& job, bool overwrite)
      : file_(path, overwrite), job_(job) {
    job_.previewModel = {};
    if (job.grid.width > 0xFFFF || job.grid.height > 0xFFFF)
      throw OutputError(path.string() + ": a GOO file holds at most 65535 x 65535 pixels");
    // Deferred, the previews are drawn beside the layers and go in with the header at finish, which
    // rewrites it anyway; until then the header holds dark previews of the same size.
    preview_ = job.previewModel;
    if (job.deferPreviews)
      previews_.assign(
          (std::size_t{kGooSmallPreview} * kGooSmallPreview + std::size_t{kGooBigPreview} * kGooBigPreview) *
              2,
          0);
    else
      drawPreviews();
    const std::vector<uint8_t> header = gooHeader(job_, 0, previews_);
    file_.write(header.data(), header.size());
  }

  void drawPreviews() override {
    if (drawn_) return;
    const PreviewSize sizes[2] = {{kGooSmallPreview, kGooSmallPreview}, {kGooBigPreview, kGooBigPreview}};
    RgbImage pictures[2];
    renderPreviews(preview_, sizes, pictures, job_.previewRunner);
    std::vector<uint8_t> previews;
    BigEndian out(previews);
    appendRgb565(out, pictures[0]);
    appendRgb565(out, pictures[1]);
    previews_ = std::move(previews);
    preview_ = {};
    drawn_ = true;
  }

  void encodeLayer(uint32_t index, double /*z*/, const MaskImage& mask, EncodedMaskLayer& out,
                   MaskEncodeScratch& /*scratch*/) const override {
    checkMaskLayerSize(mask, job_.grid, file_.finalPath(), index);
    std::vector<uint8_t>& bytes = out.bytes;
    bytes.resize(kChunksAt);
    RunBuilder runs(bytes);
    const uint32_t w = mask.width;
    const bool extents = mask.hasExtents();
    for (uint32_t r = mask.height; r-- > 0;) {  // the top row first
      const uint8_t* row = mask.pixels.data() + std::size_t{r} * w;
      if (!extents) {
        appendPixels(runs, row, w);
        continue;
      }
      const uint32_t begin = std::min(mask.litBegin[r], w), end = std::min(mask.litEnd[r], w);
      if (begin >= end) {
        runs.add(0, w);
        continue;
      }
      runs.add(0, begin);
      appendPixels(runs, row + begin, end - begin);
      runs.add(0, w - end);
    }
    runs.flush();
    const std::size_t chunks = bytes.size() - kChunksAt;
    const uint8_t checksum = gooChecksum(bytes.data() + kChunksAt, chunks);
    bytes.push_back(checksum);
    bytes.insert(bytes.end(), kDelimiter, kDelimiter + 2);

    std::vector<uint8_t> definition;
    definition.reserve(kChunksAt);
    BigEndian d(definition);
    const bool bottom = index == 0;
    const double lift = bottom ? job_.bottomLiftDistance : job_.liftDistance;
    d.u16(0);                                               // pause flag
    d.f32(machineHeight(job_, job_.layerCount));            // pause position z
    d.f32((index + 1.0) * job_.layerHeight);                // layer position z: the platform's height
    d.f32(gooLayerExposure(job_, index));                   // exposure
    d.f32(0);                                               // off time (delay mode 0 only)
    d.f32(0);                                               // before lift
    d.f32(0);                                               // after lift
    d.f32(job_.waitBeforeExposure);                         // after retract
    d.f32(lift);                                            // lift distance
    d.f32(bottom ? job_.bottomLiftSpeed : job_.liftSpeed);  // lift speed
    d.f32(0);                                               // second lift distance
    d.f32(0);                                               // second lift speed
    d.f32(lift);                                            // retract distance
    d.f32(job_.retractSpeed);                               // retract speed
    d.f32(0);                                               // second retract distance
    d.f32(0);                                               // second retract speed
    d.u16(job_.lightPwm);                                   // light PWM
    d.raw(kDelimiter, 2);
    d.u32(static_cast<uint32_t>(chunks + 2));  // data size: 0x55, chunks, checksum
    d.u8(kLayerMagic);
    std::memcpy(bytes.data(), definition.data(), kChunksAt);
    out.width = mask.width;
    out.height = mask.height;
  }

  void writeEncodedLayer(uint32_t index, double /*z*/, const EncodedMaskLayer& layer) override {
    if (index != next_) {
      throw OutputError(file_.finalPath().string() + ": layer " + std::to_string(index) +
                        " arrived, expected " + std::to_string(next_));
    }
    file_.write(layer.bytes.data(), layer.bytes.size());
    ++next_;
  }

  void finish(const MaskJob& finalJob) override {
    drawPreviews();
    file_.write(kEnding, sizeof kEnding);
    MaskJob job = finalJob;
    job.previewModel = {};
    const std::vector<uint8_t> header = gooHeader(job, next_, previews_);
    file_.rewriteAt(0, header.data(), header.size());
    file_.commit();
  }

 private:
  OutputFile file_;
  MaskJob job_;
  std::span<const Point3f> preview_;  // the model, until its previews are drawn
  bool drawn_ = false;
  std::vector<uint8_t> previews_;  // small then big, RGB565 big-endian
  uint32_t next_ = 0;
};

}  // namespace

std::unique_ptr<MaskSink> makeGooSink(const std::filesystem::path& path, const MaskJob& job, bool overwrite) {
  return std::make_unique<GooSink>(path, job, overwrite);
}

void appendGooRun(std::vector<uint8_t>& out, uint8_t value, uint32_t length) {
  while (length > 0) {
    const uint32_t n = std::min(length, kGooMaxRun);
    length -= n;
    const uint8_t type = value == 0 ? 0x00 : value == 0xFF ? 0xC0 : 0x40;
    const int extra = n <= 0xF ? 0 : n <= 0xFFF ? 1 : n <= 0xFFFFF ? 2 : 3;
    out.push_back(static_cast<uint8_t>(type | extra << 4 | (n & 0xF)));
    if (type == 0x40) out.push_back(value);
    for (int i = extra; i >= 1; --i) out.push_back(static_cast<uint8_t>(n >> (4 + 8 * (i - 1))));
  }
}

uint8_t gooChecksum(const uint8_t* chunks, std::size_t size) {
  uint8_t sum = 0;
  for (std::size_t i = 0; i < size; ++i) sum = static_cast<uint8_t>(sum + chunks[i]);
  return static_cast<uint8_t>(~sum);
}

double gooLayerExposure(const MaskJob& job, uint32_t index) {
  const uint32_t fade = fadeLayersOf(job);
  if (index + 1 >= fade) return job.exposureTime;
  const double step = (job.initialExposureTime - job.exposureTime) / (fade - 1);
  return job.initialExposureTime - index * step;
}

}  // namespace toposlice
