// The OpenVDB module: io/masks/vdb_writer.cpp is built as its own shared object (libtoposlice_vdb.so, beside
// the toposlice program), loaded the first time a .vdb file is written or read. Linking OpenVDB into
// the program made every run pay for its dynamic relocations at start (about 30 ms, more than reading
// a template table); now only .vdb jobs do. The module uses the program's own io classes (OutputFile,
// the error types), which the program exports (CMAKE_ENABLE_EXPORTS).
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <vector>

#include "core/raster/mask_image.h"
#include "io/masks/mask_sink.h"
#include "io/masks/vdb_writer.h"

namespace toposlice {

inline constexpr uint32_t kVdbModuleVersion = 4;  // raised whenever VdbModule, MaskJob or MaskSink changes

struct VdbModule {
  uint32_t version;
  std::unique_ptr<MaskSink> (*makeSink)(const std::filesystem::path& path, const MaskJob& job,
                                        bool overwrite);
  std::vector<VdbSlab> (*readSlabs)(const std::filesystem::path& file);
  MaskImage (*readLayer)(const std::filesystem::path& file, uint32_t layer, uint32_t width, uint32_t height);
};

}  // namespace toposlice

// The module's one entry point, found with dlsym.
extern "C" const toposlice::VdbModule* toposlice_vdb_module();
