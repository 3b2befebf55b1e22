// StagedDirectory: the directory counterpart of OutputFile (io/output_file.h).
#pragma once

#include <cstdint>
#include <filesystem>
#include <span>
#include <string>

namespace toposlice {

// A directory that appears under its final name complete or not at all: the directory counterpart of
// OutputFile (io/output_file.h), used by the PNG and EXR sinks. It is created as
// "<final>.tmp-<pid>-<n>" beside the final path; commit() renames it into place (without overwrite,
// atomically refusing an existing final path; with it, the old entry is moved aside, replaced, then
// deleted); destroyed uncommitted, it is removed with everything in it. With overwrite, only a folder of
// layer files (<anything><digits><layerExt>) is replaced: checkReplaceable (io/output_file.h) refuses any
// other existing entry, when the directory is created and again at commit. Created while an
// OutputTransaction is current, commit() hands the folder to it instead of renaming. It is in
// OutputFile's signal-handler table: a second signal removes its files and the folder.
class StagedDirectory {
 public:
  // layerExt: the extension of the layer files it holds (".png", ".exr").
  StagedDirectory(std::filesystem::path finalPath, bool overwrite,
                  std::string layerExt);  // throws OutputError
  ~StagedDirectory();                     // never throws
  StagedDirectory(const StagedDirectory&) = delete;
  StagedDirectory& operator=(const StagedDirectory&) = delete;

  void commit();  // throws OutputError; call at most once
  // Writes a new file `name` (no separators) with `data` into the temporary directory; throws
  // OutputError naming the final path and the file.
  void writeFile(const std::string& name, std::span<const uint8_t> data) const;
  const std::filesystem::path& finalPath() const { return finalPath_; }
  const std::filesystem::path& tempPath() const { return tempPath_; }

 private:
  std::filesystem::path finalPath_;
  std::filesystem::path tempPath_;
  bool overwrite_;
  std::string layerExt_;
  class OutputTransaction* transaction_ = nullptr;
  int registrySlot_ = -1;  // its entry in the signal handler's table (io/output_file.h)
  bool committed_ = false;
};

}  // namespace toposlice
