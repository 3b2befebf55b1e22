// NanoDLP plate archive (nanodlp_writer.h).
#include "io/masks/nanodlp_writer.h"

#include <algorithm>
#include <cmath>
#include <ctime>
#include <numeric>
#include <string>
#include <vector>

#include <libdeflate.h>
#include <nlohmann/json.hpp>

#include "io/coders/mask_png.h"
#include "io/coders/zip_stream.h"
#include "io/errors.h"
#include "io/output_file.h"
#include "io/preview_png.h"

namespace toposlice {
namespace {

using Json = nlohmann::ordered_json;

constexpr uint32_t kPreviewWidth = 200, kPreviewHeight = 100;

const char* architecture() {
#if defined(__x86_64__)
  return "amd64";
#elif defined(__aarch64__)
  return "arm64";
#else
  return "unknown";
#endif
}

Json infoJson(const NanoDlpLayerInfo& i) {
  Json j;
  j["TotalSolidArea"] = i.totalSolidArea;
  j["LargestArea"] = i.largestArea;
  j["SmallestArea"] = i.smallestArea;
  j["MinX"] = i.minX;
  j["MinY"] = i.minY;
  j["MaxX"] = i.maxX;
  j["MaxY"] = i.maxY;
  j["AreaCount"] = i.areaCount;
  return j;
}

// A number as readers with integer fields take it: a whole value without a decimal point (mslicer reads
// several NanoDLP fields, the waits and lift heights among them, as unsigned integers), else as it is.
Json number(double v) {
  if (std::isfinite(v) && v == std::round(v) && std::fabs(v) < 9.0e15) return Json(static_cast<int64_t>(v));
  return Json(v);
}

// Micrometres of a length in mm, to the nanometre (a layer height given in mm, shown in um).
double micrometres(double mm) {
  return std::round(mm * 1.0e6) / 1000.0;
}

uint32_t fadeLayersOf(const MaskJob& job) {
  return std::clamp<uint32_t>(job.fadeLayers, 2, 200);
}

class NanoDlpSink final : public EncodingMaskSink {
 public:
  NanoDlpSink(const std::filesystem::path& path, const MaskJob& job, bool overwrite)
      : file_(path, overwrite),
        job_(job),
        zip_(file_, std::max<std::time_t>(maskCreationTime(job), 315532800)),
        model_(job.previewModel) {
    job_.previewModel = {};
    if (!job.deferPreviews) drawPreviews();  // else beside the layers, or at finish, where 3d.png goes in
  }

  void drawPreviews() override {
    if (drawn_) return;
    preview_ = previewPng(model_, kPreviewWidth, kPreviewHeight, job_.previewRunner);
    model_ = {};
    drawn_ = true;
  }

  void encodeLayer(uint32_t index, double /*z*/, const MaskImage& mask, EncodedMaskLayer& out,
                   MaskEncodeScratch& scratch) const override {
    checkMaskLayerSize(mask, job_.grid, file_.finalPath(), index);
    encodeMaskPng(mask, out.bytes, scratch.deflate);
    out.crc32 = libdeflate_crc32(0, out.bytes.data(), out.bytes.size());
    out.text = infoJson(nanoDlpLayerInfo(mask, job_.grid.pixel)).dump();
  }

  void writeEncodedLayer(uint32_t index, double /*z*/, const EncodedMaskLayer& layer) override {
    if (index != next_) {
      throw OutputError(file_.finalPath().string() + ": layer " + std::to_string(index) +
                        " arrived, expected " + std::to_string(next_));
    }
    zip_.add(std::to_string(index + 1) + ".png", layer.bytes, layer.crc32);
    info_ += next_ == 0 ? "[" : ",";
    info_ += layer.text;
    const Json j = Json::parse(layer.text);
    totalArea_ += j["TotalSolidArea"].get<double>();
    if (j["AreaCount"].get<uint64_t>() > 0) {
      minX_ = std::min(minX_, j["MinX"].get<uint32_t>());
      minY_ = std::min(minY_, j["MinY"].get<uint32_t>());
      maxX_ = std::max(maxX_, j["MaxX"].get<uint32_t>());
      maxY_ = std::max(maxY_, j["MaxY"].get<uint32_t>());
    }
    ++next_;
  }

  void finish(const MaskJob& finalJob) override {
    const MaskJob& job = finalJob;
    info_ += next_ == 0 ? "[]" : "]";
    zip_.add("info.json", info_);
    const double p = job.grid.pixel;
    const bool lit = minX_ <= maxX_;
    // The lit bounds in mm from the display's centre, x to the right and y down the picture, as UVtools
    // and mslicer write them (NanoDLP's manual does not say); all 0 for a stack without a lit pixel.
    const double halfWidth = job.grid.width * p / 2, halfHeight = job.grid.height * p / 2;
    const auto nanometres = [](double mm) { return std::round(mm * 1.0e6) / 1.0e6; };
    Json bounds;
    bounds["XMin"] = lit ? nanometres(minX_ * p - halfWidth) : 0.0;
    bounds["XMax"] = lit ? nanometres((maxX_ + 1) * p - halfWidth) : 0.0;
    bounds["YMin"] = lit ? nanometres(minY_ * p - halfHeight) : 0.0;
    bounds["YMax"] = lit ? nanometres((maxY_ + 1) * p - halfHeight) : 0.0;
    bounds["ZMin"] = 0.0;
    bounds["ZMax"] = next_ * job.layerHeight;
    Json plate;
    plate["Processed"] = true;
    plate["LayersCount"] = next_;
    plate["TotalSolidArea"] = totalArea_;
    plate.update(bounds);
    plate["Volume"] = job.volumeMl * 1000;  // mm^3
    zip_.add("plate.json", plate.dump());
    const double depth = micrometres(job.layerHeight);
    const uint32_t transitional = std::min(fadeLayersOf(job) - 2, next_ > 0 ? next_ - 1 : 0);
    Json profile;
    profile["Title"] = "toposlice";
    profile["Depth"] = number(depth);  // layer thickness, micrometres
    profile["SupportDepth"] = number(depth);
    profile["CureTime"] = number(job.exposureTime);
    profile["SupportCureTime"] = number(job.initialExposureTime);
    profile["SupportLayerNumber"] = 1;
    // As many transition layers as the file has after its bottom layer at most.
    profile["TransitionalLayer"] = transitional;
    profile["WaitBeforePrint"] = number(job.waitBeforeExposure);
    profile["SupportWaitBeforePrint"] = number(job.waitBeforeExposure);
    profile["WaitHeight"] = number(job.liftDistance);  // NanoDLP's names of the lift heights
    profile["SupportWaitHeight"] = number(job.bottomLiftDistance);
    // toposlice's own names: NanoDLP has no fields for the speeds and the pixel grid in its profile.
    profile["LiftDistance"] = job.liftDistance;
    profile["LiftSpeed"] = job.liftSpeed;
    profile["BottomLiftDistance"] = job.bottomLiftDistance;
    profile["BottomLiftSpeed"] = job.bottomLiftSpeed;
    profile["RetractSpeed"] = job.retractSpeed;
    profile["XPixels"] = job.grid.width;
    profile["YPixels"] = job.grid.height;
    profile["PixelSize"] = p * 1000;  // micrometres
    zip_.add("profile.json", profile.dump());
    // The slicer's options: where readers (UVtools reads slicer.json, mslicer options.json or
    // slicer.json, NanoDLP options.json) take the display's pixels and pixel size from.
    Json options;
    options["PWidth"] = job.grid.width;
    options["PHeight"] = job.grid.height;
    options["Thickness"] = number(depth);
    options["SupportDepth"] = number(depth);
    options["SupportLayerNumber"] = 1;
    options["XOffset"] = job.grid.width / 2;
    options["YOffset"] = job.grid.height / 2;
    options["XPixelSize"] = p;  // mm
    options["YPixelSize"] = p;
    options["XRes"] = number(micrometres(p));
    options["YRes"] = number(micrometres(p));
    options["Boundary"] = bounds;
    options["ImageMirror"] = job.grid.mirrorX ? 1 : 0;
    options["DisplayController"] = 1;
    options["IgnoreMask"] = 1;
    options["FillColor"] = "#ffffff";
    options["BlankColor"] = "#000000";
    options["LayerCount"] = next_;
    options["PreviewWidth"] = kPreviewWidth;
    options["PreviewHeight"] = kPreviewHeight;
    const std::string optionsText = options.dump();
    zip_.add("options.json", optionsText);
    zip_.add("slicer.json", optionsText);
    Json meta;
    meta["FormatVersion"] = 1;
    meta["Distro"] = "generic";
    meta["Program"] = "toposlice";
    meta["Version"] = TOPOSLICE_VERSION_TEXT;
    meta["OS"] = "linux";
    meta["Arch"] = architecture();
    meta["Profile"] = false;  // the printer keeps its own profile; profile.json is for reference
    zip_.add("meta.json", meta.dump());
    drawPreviews();
    zip_.add("3d.png", preview_);
    zip_.close();
    file_.commit();
  }

 private:
  OutputFile file_;  // declared first: destroyed last, after zip_ has closed its handle
  MaskJob job_;
  ZipStream zip_;
  std::span<const Point3f> model_;  // until its preview is drawn
  bool drawn_ = false;
  std::vector<uint8_t> preview_;
  std::string info_;
  double totalArea_ = 0;
  uint32_t minX_ = UINT32_MAX, minY_ = UINT32_MAX, maxX_ = 0, maxY_ = 0;
  uint32_t next_ = 0;
};

uint32_t findRoot(std::vector<uint32_t>& parent, uint32_t i) {
  while (parent[i] != i) i = parent[i] = parent[parent[i]];
  return i;
}

}  // namespace

std::unique_ptr<MaskSink> makeNanoDlpSink(const std::filesystem::path& path, const MaskJob& job,
                                          bool overwrite) {
  return std::make_unique<NanoDlpSink>(path, job, overwrite);
}

NanoDlpLayerInfo nanoDlpLayerInfo(const MaskImage& mask, double pixel) {
  struct Run {
    uint32_t begin, end, id;
  };
  NanoDlpLayerInfo info;
  std::vector<Run> previous, current;
  std::vector<uint32_t> parent;
  std::vector<double> weight;  // lit fraction summed over the run, by run id
  const uint32_t w = mask.width;
  bool any = false;
  for (uint32_t row = 0; row < mask.height; ++row) {  // picture rows, top first
    const uint32_t r = mask.height - 1 - row;
    const uint8_t* px = mask.pixels.data() + std::size_t{r} * w;
    uint32_t i = 0, end = w;
    if (mask.hasExtents()) {
      i = std::min(mask.litBegin[r], w);
      end = std::min(mask.litEnd[r], w);
    }
    current.clear();
    while (i < end) {
      if (px[i] == 0) {
        ++i;
        continue;
      }
      const uint32_t begin = i;
      uint64_t sum = 0;
      while (i < end && px[i] != 0) sum += px[i++];
      const uint32_t id = static_cast<uint32_t>(parent.size());
      parent.push_back(id);
      weight.push_back(static_cast<double>(sum) / 255.0);
      current.push_back({begin, i, id});
      info.minX = any ? std::min(info.minX, begin) : begin;
      info.minY = any ? info.minY : row;
      info.maxX = any ? std::max(info.maxX, i - 1) : i - 1;
      any = true;
      info.maxY = row;
    }
    // Join runs that share a column with a run of the row above (4-connected).
    std::size_t a = 0;
    for (const Run& c : current) {
      while (a < previous.size() && previous[a].end <= c.begin) ++a;
      for (std::size_t b = a; b < previous.size() && previous[b].begin < c.end; ++b) {
        const uint32_t x = findRoot(parent, c.id), y = findRoot(parent, previous[b].id);
        if (x != y) parent[std::max(x, y)] = std::min(x, y);
      }
    }
    std::swap(previous, current);
  }
  std::vector<double> area(parent.size(), 0.0);
  for (uint32_t id = 0; id < parent.size(); ++id) area[findRoot(parent, id)] += weight[id];
  const double pixelArea = pixel * pixel;
  bool first = true;
  for (uint32_t id = 0; id < parent.size(); ++id) {
    if (parent[id] != id) continue;
    const double a = area[id] * pixelArea;
    ++info.areaCount;
    info.totalSolidArea += a;
    info.largestArea = first ? a : std::max(info.largestArea, a);
    info.smallestArea = first ? a : std::min(info.smallestArea, a);
    first = false;
  }
  return info;
}

}  // namespace toposlice
