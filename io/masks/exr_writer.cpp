// OpenEXR mask stack writer (OpenEXR 3.1 C++ API: Imf::Header, Imf::OutputFile, Imf::FrameBuffer).
#include "io/masks/exr_writer.h"

#include <algorithm>
#include <array>
#include <cstddef>
#include <exception>

#include <Imath/half.h>
#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFloatAttribute.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfIntAttribute.h>
#include <OpenEXR/ImfOutputFile.h>
#include <OpenEXR/ImfStringAttribute.h>
#include <OpenEXR/ImfThreading.h>
#include <OpenEXR/ImfVecAttribute.h>

#include "io/errors.h"

namespace toposlice {
namespace {

constexpr const char* kChannel = "Y";

class ExrSink final : public MaskSink {
 public:
  ExrSink(const std::filesystem::path& path, const MaskJob& job, bool overwrite)
      : dir_(path, overwrite, ".exr"), job_(job), rows_(size_t{job.grid.width} * job.grid.height) {
    for (int v = 0; v < 256; ++v) toHalf_[v] = Imath::half(static_cast<float>(v) / 255.0f);
  }

  void writeLayer(uint32_t index, double z, const MaskImage& mask,
                  std::span<const uint8_t> /*png*/) override {
    const std::string where = dir_.finalPath().string() + ": layer " + std::to_string(index);
    if (index != next_) throw OutputError(where + " arrived, expected " + std::to_string(next_));
    const uint32_t width = job_.grid.width, height = job_.grid.height;
    if (mask.width != width || mask.height != height || mask.pixels.size() != size_t{width} * height) {
      throw OutputError(where + " does not match the job's image size");
    }
    for (uint32_t r = 0; r < height; ++r) {  // top-down
      const uint8_t* src = mask.pixels.data() + size_t{height - 1 - r} * width;
      Imath::half* dst = rows_.data() + size_t{r} * width;
      for (uint32_t i = 0; i < width; ++i) dst[i] = toHalf_[src[i]];
    }
    const std::string name = maskLayerFileName(job_.name, index, job_.layerCount, "exr");
    try {
      Imf::Header header(static_cast<int>(width), static_cast<int>(height));
      header.compression() = Imf::ZIP_COMPRESSION;
      header.zipCompressionLevel() = kExrZipLevel;
      header.channels().insert(kChannel, Imf::Channel(Imf::HALF));
      header.insert("z", Imf::FloatAttribute(static_cast<float>(z)));
      header.insert("layer", Imf::IntAttribute(static_cast<int>(index)));
      header.insert("layerCount", Imf::IntAttribute(static_cast<int>(job_.layerCount)));
      header.insert("layerHeight", Imf::FloatAttribute(static_cast<float>(job_.layerHeight)));
      header.insert("pixelSize", Imf::FloatAttribute(static_cast<float>(job_.grid.pixel)));
      header.insert("origin", Imf::V2fAttribute(Imath::V2f(static_cast<float>(job_.grid.x0),
                                                           static_cast<float>(job_.grid.y0))));
      header.insert("mirrorX", Imf::IntAttribute(job_.grid.mirrorX ? 1 : 0));
      header.insert("mirrorY", Imf::IntAttribute(job_.grid.mirrorY ? 1 : 0));
      for (const auto& [key, value] : job_.settings)  // the printer and material settings (mask_sink.h)
        header.insert("toposlice:" + key, Imf::StringAttribute(value));
      Imf::OutputFile file((dir_.tempPath() / name).c_str(), header);
      Imf::FrameBuffer frame;
      frame.insert(kChannel, Imf::Slice(Imf::HALF, reinterpret_cast<char*>(rows_.data()), sizeof(Imath::half),
                                        sizeof(Imath::half) * width));
      file.setFrameBuffer(frame);
      file.writePixels(static_cast<int>(height));
    } catch (const std::exception& e) {
      throw OutputError(dir_.finalPath().string() + ": cannot write " + name + ": " + e.what());
    }
    ++next_;
  }

  void finish(const MaskJob& /*finalJob*/) override { dir_.commit(); }

 private:
  StagedDirectory dir_;
  MaskJob job_;
  std::vector<Imath::half> rows_;  // one layer, top-down
  std::array<Imath::half, 256> toHalf_{};
  uint32_t next_ = 0;
};

}  // namespace

std::unique_ptr<MaskSink> makeExrSink(const std::filesystem::path& path, const MaskJob& job, bool overwrite) {
  return std::make_unique<ExrSink>(path, job, overwrite);
}

void setExrThreadCount(int threads) {
  Imf::setGlobalThreadCount(threads);
}

ExrMaskLayer readExrMaskLayer(const std::filesystem::path& file) {
  ExrMaskLayer layer;
  try {
    Imf::InputFile in(file.c_str());
    const Imf::Header& header = in.header();
    const Imath::Box2i window = header.dataWindow();
    const Imf::ChannelList& channels = header.channels();
    if (channels.begin() == channels.end()) throw InputError(file.string() + ": no channel");
    layer.channel = channels.begin().name();
    const auto* z = header.findTypedAttribute<Imf::FloatAttribute>("z");
    const auto* index = header.findTypedAttribute<Imf::IntAttribute>("layer");
    if (z == nullptr || index == nullptr) throw InputError(file.string() + ": no z or layer attribute");
    layer.z = z->value();
    layer.layer = index->value();
    if (const auto* p = header.findTypedAttribute<Imf::FloatAttribute>("pixelSize"))
      layer.pixelSize = p->value();
    if (const auto* h = header.findTypedAttribute<Imf::FloatAttribute>("layerHeight")) {
      layer.layerHeight = h->value();
    }
    layer.width = static_cast<uint32_t>(window.max.x - window.min.x + 1);
    layer.height = static_cast<uint32_t>(window.max.y - window.min.y + 1);
    std::vector<float> topDown(size_t{layer.width} * layer.height);
    // Slice base addresses pixel (0, 0) of the file's coordinate system.
    char* base =
        reinterpret_cast<char*>(topDown.data()) - (static_cast<std::ptrdiff_t>(window.min.x) +
                                                   static_cast<std::ptrdiff_t>(window.min.y) * layer.width) *
                                                      static_cast<std::ptrdiff_t>(sizeof(float));
    Imf::FrameBuffer frame;
    frame.insert(layer.channel, Imf::Slice(Imf::FLOAT, base, sizeof(float), sizeof(float) * layer.width));
    in.setFrameBuffer(frame);
    in.readPixels(window.min.y, window.max.y);
    layer.values.resize(topDown.size());
    for (uint32_t r = 0; r < layer.height; ++r) {
      std::copy_n(topDown.data() + size_t{r} * layer.width, layer.width,
                  layer.values.data() + size_t{layer.height - 1 - r} * layer.width);
    }
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    throw InputError(file.string() + ": " + e.what());
  }
  return layer;
}

}  // namespace toposlice
