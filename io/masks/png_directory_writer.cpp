#include "io/masks/png_directory_writer.h"

#include <string>

#include "io/coders/mask_png.h"
#include "io/errors.h"
#include "io/staged_directory.h"

namespace toposlice {
namespace {

class PngDirectorySink final : public LayerFolderSink {
 public:
  PngDirectorySink(const std::filesystem::path& path, const MaskJob& job, bool overwrite)
      : LayerFolderSink(path, job, overwrite, ".png") {}

 protected:
  void encodeLayerBytes(uint32_t index, double /*z*/, const MaskImage& mask, std::vector<uint8_t>& out,
                        MaskEncodeScratch& scratch) const override {
    checkMaskLayerSize(mask, job().grid, finalPath(), index);
    encodeMaskPng(mask, out, scratch.deflate);
  }

  std::string layerFileName(uint32_t index) const override {
    return maskLayerFileName(job().name, index, job().layerCount, "png");
  }
};

}  // namespace

std::unique_ptr<MaskSink> makePngDirectorySink(const std::filesystem::path& path, const MaskJob& job,
                                               bool overwrite) {
  return std::make_unique<PngDirectorySink>(path, job, overwrite);
}

}  // namespace toposlice
