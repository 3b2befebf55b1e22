// SL1 archive writer. Keys follow what the readers actually parse: PrusaSlicer's SL1 import
// (get_raster_params needs display_pixels_x/y, display_width/height, display_mirror_x/y and
// display_orientation in prusaslicer.ini; layer_height falls back to config.ini's layerHeight), UVtools'
// SL1File (config.ini and prusaslicer.ini must both exist; layer count = numSlow + numFast; resolution
// from display_pixels_x/y) and the SL1 firmware's project config (jobDir is the PNG name prefix,
// numFade >= 2 because the fade divides by numFade - 1, printerModel must match the printer,
// layerHeightFirst defaults to 0.05 mm when absent).
#include "io/masks/sl1_writer.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <map>
#include <vector>

#include <libdeflate.h>

#include "io/coders/mask_png.h"
#include "io/coders/zip_stream.h"
#include "io/errors.h"
#include "io/output_file.h"
#include "io/preview_png.h"

namespace toposlice {
namespace {

using IniMap = std::map<std::string, std::string>;

std::string number(double v) {
  char buf[512];  // the longest fixed double (a denormal) has about 330 characters
  const auto result = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::fixed);  // never "1e+05"
  return std::string(buf, result.ptr);
}

std::string number(uint64_t v) {
  return std::to_string(v);
}

// A setting's text with a number in exponent form ("1e-05", the shortest form that reads back) written in
// fixed notation, as every number of the .ini files is; other text as it is.
std::string fixedNotation(const std::string& value) {
  if (value.find_first_of("eE") == std::string::npos) return value;
  double v = 0;
  const auto [end, ec] = std::from_chars(value.data(), value.data() + value.size(), v);
  return ec == std::errc() && end == value.data() + value.size() ? number(v) : value;
}

std::string toIni(const IniMap& m) {
  std::string text;
  for (const auto& [key, value] : m) text += key + " = " + value + "\n";
  return text;
}

std::string modelOf(const MaskJob& job) {
  return job.printerModel.empty() ? "SL1" : job.printerModel;
}

uint32_t fadeLayersOf(const MaskJob& job) {
  return std::clamp<uint32_t>(job.fadeLayers, 2, 200);
}

// Exposure of layer i, as the firmware computes it: the first layer gets initialExposureTime, the
// following fade - 2 layers step linearly towards exposureTime, the rest get exposureTime.
double estimatedPrintTime(const MaskJob& job, uint32_t layers) {
  const uint32_t fade = fadeLayersOf(job);
  const double step = (job.initialExposureTime - job.exposureTime) / (fade - 1);
  double total = 0;
  for (uint32_t i = 0; i < layers && i + 1 < fade; ++i) total += job.initialExposureTime - i * step;
  if (layers + 1 > fade) total += (layers - (fade - 1)) * job.exposureTime;
  return total + layers * kSl1LayerOverheadS;
}

std::time_t creationTime(const MaskJob& job) {
  constexpr std::time_t kZipEpoch = 315532800;  // 1980-01-01 00:00:00 UTC, the earliest zip time
  return std::max(maskCreationTime(job), kZipEpoch);
}

class Sl1Sink final : public EncodingMaskSink {
 public:
  Sl1Sink(const std::filesystem::path& path, const MaskJob& job, bool overwrite)
      : file_(path, overwrite), job_(job), created_(creationTime(job)), zip_(file_, created_) {
    if (job.layerCount > kSl1MaxLayers) {
      throw OutputError(path.string() + ": an SL1 archive holds at most " + std::to_string(kSl1MaxLayers) +
                        " layers (5-digit layer names); this job has " + std::to_string(job.layerCount));
    }
    job_.previewModel = {};
    if (!job.previewModel.empty()) {
      preview_ = job.previewModel;
      if (!job.deferPreviews) addThumbnails();
    }
  }

  bool previewsBeforeLayers() const override { return true; }  // the thumbnails are the first entries

  // PrusaSlicer's two thumbnails, as it names them, drawn together.
  void drawPreviews() override {
    if (preview_.empty() || drawn_) return;
    const PreviewSize sizes[2] = {{400, 400}, {800, 480}};
    RgbImage pictures[2];
    renderPreviews(preview_, sizes, pictures, job_.previewRunner);
    encodeRgbPng(pictures[0], thumbnails_[0]);
    encodeRgbPng(pictures[1], thumbnails_[1]);
    drawn_ = true;
  }

  // The layer's PNG and its CRC-32: the zip entry is then written raw, without a second pass over it.
  void encodeLayer(uint32_t index, double /*z*/, const MaskImage& mask, EncodedMaskLayer& out,
                   MaskEncodeScratch& scratch) const override {
    checkMaskLayerSize(mask, job_.grid, file_.finalPath(), index);
    encodeMaskPng(mask, out.bytes, scratch.deflate);
    out.crc32 = libdeflate_crc32(0, out.bytes.data(), out.bytes.size());
  }

  void writeEncodedLayer(uint32_t index, double /*z*/, const EncodedMaskLayer& layer) override {
    if (index != next_ || index >= kSl1MaxLayers) {
      throw OutputError(file_.finalPath().string() + ": layer " + std::to_string(index) +
                        " arrived, expected " + std::to_string(next_));
    }
    addThumbnails();
    zip_.add(maskLayerFileName(job_.name, index, kSl1MaxLayers, "png"), layer.bytes, layer.crc32);
    ++next_;
  }

  void finish(const MaskJob& finalJob) override {
    addThumbnails();
    MaskJob job = finalJob;
    job.name = job_.name;  // the PNG names already written fix jobDir
    const std::string config = sl1ConfigIni(job, next_, created_);
    const std::string profile = sl1PrusaSlicerIni(job, next_);
    zip_.add("config.ini", {reinterpret_cast<const uint8_t*>(config.data()), config.size()});
    zip_.add("prusaslicer.ini", {reinterpret_cast<const uint8_t*>(profile.data()), profile.size()});
    zip_.close();
    file_.commit();
  }

 private:
  OutputFile file_;  // declared first: destroyed last, after zip_ has closed its handle
  MaskJob job_;
  std::time_t created_;
  ZipStream zip_;
  uint32_t next_ = 0;
  std::span<const Point3f> preview_;  // the model, until its thumbnails are in the archive
  bool drawn_ = false;
  std::vector<uint8_t> thumbnails_[2];

  // The thumbnails as the archive's first entries (drawn now if drawPreviews was not called), once.
  void addThumbnails() {
    if (preview_.empty()) return;
    drawPreviews();
    zip_.add("thumbnail/thumbnail400x400.png", thumbnails_[0]);
    zip_.add("thumbnail/thumbnail800x480.png", thumbnails_[1]);
    preview_ = {};
    thumbnails_[0] = {};
    thumbnails_[1] = {};
  }
};

}  // namespace

std::unique_ptr<MaskSink> makeSl1Sink(const std::filesystem::path& path, const MaskJob& job, bool overwrite) {
  return std::make_unique<Sl1Sink>(path, job, overwrite);
}

std::string sl1ConfigIni(const MaskJob& job, uint32_t layers, std::time_t created) {
  std::tm t{};
  gmtime_r(&created, &t);
  char stamp[64];
  std::strftime(stamp, sizeof stamp, "%Y-%m-%d at %H:%M:%S UTC", &t);
  IniMap m;
  m["action"] = "print";
  m["jobDir"] = maskFilePrefix(job.name);
  m["expTime"] = number(job.exposureTime);
  m["expTimeFirst"] = number(job.initialExposureTime);
  m["expUserProfile"] = "0";
  m["fileCreationTimestamp"] = stamp;
  m["hollow"] = "0";
  m["layerHeight"] = number(job.layerHeight);
  m["layerHeightFirst"] = number(job.layerHeight);
  m["materialName"] = job.materialName.empty() ? "toposlice" : job.materialName;
  m["numFade"] = number(uint64_t{fadeLayersOf(job)});
  m["numFast"] = number(uint64_t{layers});
  m["numSlow"] = "0";
  m["printProfile"] = "toposlice";
  m["printTime"] = number(std::round(estimatedPrintTime(job, layers)));
  m["printerModel"] = modelOf(job);
  m["printerProfile"] = job.printerProfile.empty() ? "toposlice" : job.printerProfile;
  m["printerVariant"] = "default";
  m["prusaSlicerVersion"] = "toposlice";
  m["usedMaterial"] = number(std::round(job.volumeMl * 1000) / 1000);
  return toIni(m);
}

std::string sl1PrusaSlicerIni(const MaskJob& job, uint32_t layers) {
  // Display sizes are products (pixels x pitch): rounded to a nanometre, so 2560 x 0.04725 prints as the
  // 120.96 a user reads on the printer, not 120.96000000000001.
  const auto nanometres = [](double mm) { return std::round(mm * 1e6) / 1e6; };
  // The display in PrusaSlicer's terms: a portrait grid (PixelGrid::transposed) is the display's
  // pixels_y wide and pixels_x tall, mirrored by (!display_mirror_x, display_mirror_y).
  const bool portrait = job.grid.transposed;
  const uint32_t pixelsX = portrait ? job.grid.height : job.grid.width,
                 pixelsY = portrait ? job.grid.width : job.grid.height;
  const double width = nanometres(pixelsX * job.grid.pixel), height = nanometres(pixelsY * job.grid.pixel);
  // The printer's max_print_height when it has one (the job refused a taller model), else 150 mm as
  // PrusaSlicer's SL1 profile says; never below the stack, which PrusaSlicer would refuse.
  double printerHeight = 0;
  for (const auto& [key, value] : job.settings)
    if (key == "max_print_height") printerHeight = std::strtod(value.c_str(), nullptr);
  const double printHeight =
      std::max(printerHeight > 0 ? printerHeight : 150.0, std::ceil(layers * job.layerHeight));
  IniMap m;
  m["absolute_correction"] = "0";
  m["area_fill"] = "50";
  m["bed_shape"] =
      "0x0," + number(width) + "x0," + number(width) + "x" + number(height) + ",0x" + number(height);
  m["display_height"] = number(height);
  m["display_mirror_x"] = job.grid.mirrorX != portrait ? "1" : "0";
  m["display_mirror_y"] = job.grid.mirrorY ? "1" : "0";
  m["display_orientation"] = portrait ? "portrait" : "landscape";
  m["display_pixels_x"] = number(uint64_t{pixelsX});
  m["display_pixels_y"] = number(uint64_t{pixelsY});
  m["display_width"] = number(width);
  m["elefant_foot_compensation"] = "0";
  m["exposure_time"] = number(job.exposureTime);
  m["faded_layers"] = number(uint64_t{fadeLayersOf(job)});
  m["gamma_correction"] = job.antiAliased ? "1" : "0";
  m["hollowing_enable"] = "0";
  m["initial_exposure_time"] = number(job.initialExposureTime);
  m["initial_layer_height"] = number(job.layerHeight);
  m["layer_height"] = number(job.layerHeight);
  m["material_print_speed"] = "fast";
  m["max_print_height"] = number(printHeight);
  m["pad_enable"] = "0";
  m["printer_model"] = modelOf(job);
  m["printer_settings_id"] = "toposlice";
  m["printer_technology"] = "SLA";
  m["printer_variant"] = "default";
  m["sla_material_settings_id"] = "toposlice";
  m["sla_print_settings_id"] = "toposlice";
  m["supports_enable"] = "0";
  // The printer's and material's settings as chosen (exposure, corrections, density), by PrusaSlicer's
  // keys; the display keys and the print height above stay as the images were written, and toposlice's
  // own keys (light_map, elefant_foot_layers, the motion and light keys) stay out.
  for (const auto& [key, value] : job.settings)
    if (!key.starts_with("display_") && key != "printer_model" && key != "max_print_height" &&
        key != "light_map" && key != "elefant_foot_layers" && key.find("lift") == std::string::npos &&
        key != "retract_speed" && key != "wait_before_exposure" && key != "light_pwm" && !value.empty())
      m[key] = fixedNotation(value);
  if (!job.printerProfile.empty()) m["printer_settings_id"] = job.printerProfile;
  if (!job.materialName.empty()) m["sla_material_settings_id"] = job.materialName;
  return toIni(m);
}

}  // namespace toposlice
