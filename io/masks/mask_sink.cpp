// The sink factory, layer file names, and the default two-step path of MaskSink (mask_sink.h).
#include "io/masks/mask_sink.h"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstdlib>

#include "core/number_text.h"
#include "core/raster/mask_runs.h"
#include "io/errors.h"
#include "io/masks/exr_writer.h"
#include "io/masks/goo_writer.h"
#include "io/masks/nanodlp_writer.h"
#include "io/masks/png_directory_writer.h"
#include "io/masks/sl1_writer.h"
#include "io/masks/vdb_writer.h"
#include "io/output_file.h"

namespace toposlice {

void MaskSink::encodeLayer(uint32_t /*index*/, double /*z*/, const MaskImage& mask, EncodedMaskLayer& out,
                           MaskEncodeScratch& /*scratch*/) const {
  encodeMaskRuns(mask, out.bytes);
  out.crc32 = 0;
  out.width = mask.width;
  out.height = mask.height;
}

void MaskSink::writeEncodedLayer(uint32_t index, double z, const EncodedMaskLayer& layer) {
  decoded_.width = layer.width;
  decoded_.height = layer.height;
  decoded_.forgetLayout();
  if (!decodeMaskRuns(layer.bytes, decoded_)) {
    throw OutputError("layer " + std::to_string(index) + ": malformed mask runs");
  }
  writeLayer(index, z, decoded_);
}

void EncodingMaskSink::writeLayer(uint32_t index, double z, const MaskImage& mask) {
  encodeLayer(index, z, mask, layer_, scratch_);
  writeEncodedLayer(index, z, layer_);
}

std::time_t maskCreationTime(const MaskJob& job) {
  if (const char* epoch = std::getenv("SOURCE_DATE_EPOCH")) {
    char* end = nullptr;
    errno = 0;
    const long long v = std::strtoll(epoch, &end, 10);
    if (errno == 0 && end != epoch && *end == '\0' && v >= 0) return static_cast<std::time_t>(v);
  }
  return job.created > 0 ? static_cast<std::time_t>(job.created) : 0;
}

void checkMaskLayerSize(const MaskImage& mask, const PixelGrid& grid, const std::filesystem::path& output,
                        uint32_t index) {
  if (mask.width != grid.width || mask.height != grid.height ||
      mask.pixels.size() != size_t{grid.width} * grid.height) {
    throw OutputError(output.string() + ": layer " + std::to_string(index) +
                      " does not match the job's image size");
  }
}

std::unique_ptr<MaskSink> makeMaskSink(const std::filesystem::path& path, const MaskJob& job,
                                       bool overwrite) {
  const std::string ext = lowerExtension(path);
  if (ext == ".sl1" || ext == ".sl1s") return makeSl1Sink(path, job, overwrite);
  if (ext == ".goo") return makeGooSink(path, job, overwrite);
  if (ext == ".nanodlp") return makeNanoDlpSink(path, job, overwrite);
  if (ext == ".exr") return makeExrSink(path, job, overwrite);
  if (ext == ".vdb") {
    // OpenVDB refuses a transform whose scale's determinant is under 3e-15 ("Non-zero scale values
    // required"): a voxel of pixel x pixel x layer height (mm) that small is said here, in our terms.
    const double voxel = job.grid.pixel * job.grid.pixel * job.layerHeight;
    if (!(voxel >= 1e-14))
      throw InputError(path.string() + ": a VDB voxel of " + readableNumber(job.grid.pixel) + " x " +
                       readableNumber(job.grid.pixel) + " x " + readableNumber(job.layerHeight) +
                       " mm is too small for OpenVDB's transform (pixel^2 x layer height must be at least "
                       "1e-14 mm^3): use larger pixels or layers");
    return makeVdbSink(path, job, overwrite);
  }
  return makePngDirectorySink(path, job, overwrite);
}

void checkMaskOutputAllowed(const std::filesystem::path& path, bool overwrite) {
  const std::string ext = lowerExtension(path);
  if (ext.empty() || ext == ".exr")
    checkOutputAllowed(path, overwrite, OutputKind::LayerFolder, ext.empty() ? ".png" : ".exr");
  else
    checkOutputAllowed(path, overwrite);
}

std::string maskFilePrefix(const std::string& name) {
  if (name.empty()) return "layer";
  std::string prefix = name;
  for (char& c : prefix) {
    if (c == '/' || c == '\\' || static_cast<unsigned char>(c) < 0x20 || c == 0x7F) c = '_';
  }
  return prefix;
}

std::string maskLayerNumber(uint32_t index, uint32_t layerCount) {
  int digits = 5;
  for (uint64_t limit = 100000; layerCount > limit; limit *= 10) ++digits;
  char number[16];
  std::snprintf(number, sizeof number, "%0*u", digits, index);
  return number;
}

std::string maskLayerFileName(const std::string& name, uint32_t index, uint32_t layerCount, const char* ext) {
  return maskFilePrefix(name) + maskLayerNumber(index, layerCount) + "." + ext;
}

LayerFolderSink::LayerFolderSink(const std::filesystem::path& path, const MaskJob& job, bool overwrite,
                                 std::string layerExt)
    : dir_(path, overwrite, std::move(layerExt)), job_(job) {}

void LayerFolderSink::encodeLayer(uint32_t index, double z, const MaskImage& mask, EncodedMaskLayer& out,
                                  MaskEncodeScratch& scratch) const {
  encodeLayerBytes(index, z, mask, out.bytes, scratch);
  dir_.writeFile(layerFileName(index), out.bytes);  // out keeps the bytes; the in-order stage needs none
}

void LayerFolderSink::writeEncodedLayer(uint32_t index, double /*z*/, const EncodedMaskLayer& /*layer*/) {
  if (index != next_) {
    throw OutputError(dir_.finalPath().string() + ": layer " + std::to_string(index) + " arrived, expected " +
                      std::to_string(next_));
  }
  ++next_;
}

void LayerFolderSink::finish(const MaskJob& /*finalJob*/) {
  dir_.commit();
}

}  // namespace toposlice
