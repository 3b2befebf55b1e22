// makeVdbSink, readVdbSlabs and readVdbLayer, forwarded to the OpenVDB module (io/masks/vdb_module.h), which
// is loaded on first use: from the running program's folder, else from where this build put it.
#include <dlfcn.h>

#include <string>

#include "io/errors.h"
#include "io/masks/vdb_module.h"
#include "io/masks/vdb_writer.h"

namespace toposlice {
namespace {

constexpr const char* kModuleName = "libtoposlice_vdb.so";

const VdbModule& vdbModule() {
  static const VdbModule* const module = [] {
    std::vector<std::filesystem::path> candidates;
    std::error_code error;
    const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", error);
    if (!error) candidates.push_back(self.parent_path() / kModuleName);
    const std::filesystem::path built = TOPOSLICE_VDB_MODULE_PATH;
    if (candidates.empty() || candidates.front() != built) candidates.push_back(built);
    std::string reasons;
    for (const auto& path : candidates) {
      void* handle = ::dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
      if (handle == nullptr) {
        reasons += std::string("\n  ") + ::dlerror();
        continue;
      }
      using Entry = const VdbModule* (*)();
      const auto entry = reinterpret_cast<Entry>(::dlsym(handle, "toposlice_vdb_module"));
      const VdbModule* found = entry ? entry() : nullptr;
      if (found != nullptr && found->version == kVdbModuleVersion) return found;
      reasons += "\n  " + path.string() + ": not a toposlice OpenVDB module of this version";
      ::dlclose(handle);
    }
    throw OutputError(std::string("OpenVDB support (") + kModuleName + ") could not be loaded:" + reasons);
  }();
  return *module;
}

}  // namespace

std::unique_ptr<MaskSink> makeVdbSink(const std::filesystem::path& path, const MaskJob& job, bool overwrite) {
  return vdbModule().makeSink(path, job, overwrite);
}

std::vector<VdbSlab> readVdbSlabs(const std::filesystem::path& file) {
  return vdbModule().readSlabs(file);
}

MaskImage readVdbLayer(const std::filesystem::path& file, uint32_t layer, uint32_t width, uint32_t height) {
  return vdbModule().readLayer(file, layer, width, height);
}

}  // namespace toposlice
