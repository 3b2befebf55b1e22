#include "io/masks/png_directory_writer.h"

#include <string>

#include "io/errors.h"
#include "io/masks/mask_png.h"
#include "io/staged_directory.h"

namespace toposlice {
namespace {

class PngDirectorySink final : public EncodingMaskSink {
 public:
  PngDirectorySink(const std::filesystem::path& path, const MaskJob& job, bool overwrite)
      : dir_(path, overwrite, ".png"), job_(job) {}

  void encodeLayer(uint32_t index, double /*z*/, const MaskImage& mask, EncodedMaskLayer& out,
                   MaskEncodeScratch& scratch) const override {
    checkMaskLayerSize(mask, job_.grid, dir_.finalPath(), index);
    encodeMaskPng(mask, out.bytes, scratch.deflate);
  }

  void writeEncodedLayer(uint32_t index, double /*z*/, const EncodedMaskLayer& layer) override {
    if (index != next_) {
      throw OutputError(dir_.finalPath().string() + ": layer " + std::to_string(index) +
                        " arrived, expected " + std::to_string(next_));
    }
    dir_.writeFile(maskLayerFileName(job_.name, index, job_.layerCount, "png"), layer.bytes);
    ++next_;
  }

  void finish(const MaskJob& /*finalJob*/) override { dir_.commit(); }

 private:
  StagedDirectory dir_;
  MaskJob job_;
  uint32_t next_ = 0;
};

}  // namespace

std::unique_ptr<MaskSink> makePngDirectorySink(const std::filesystem::path& path, const MaskJob& job,
                                               bool overwrite) {
  return std::make_unique<PngDirectorySink>(path, job, overwrite);
}

}  // namespace toposlice
