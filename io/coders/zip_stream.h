// A zip archive streamed entry by entry into an OutputFile's temporary, for the printer files that are
// zips of PNG layers (SL1, NanoDLP). minizip writes the entries (libzip keeps every entry's data until
// zip_close, so it cannot stream): stored (method 0), names flagged UTF-8, every entry dated `created`.
// Past 65,534 entries the Zip64 end records are added after minizip closes the archive (Debian's minizip
// 1.1 only adds them past 4 GiB, leaving an archive that libzip, unzip and .NET reject). Memory: the
// central directory minizip keeps until the end, about 80 bytes per entry.
#pragma once

#include <cstdint>
#include <ctime>
#include <optional>
#include <span>
#include <string>

#include "io/output_file.h"

namespace toposlice {

// minizip's zipOpen64 on an OutputFile's temporary, which the OutputFile has just created empty, opened
// without truncating it ("r+b" instead of minizip's "wb"). On ext4 a file truncated to zero length is
// written back as it is closed (auto_da_alloc): for an SL1 archive of 130 MB that is 0.09 s of kernel work
// in the closing thread, after every layer is done. Returns the zipFile, or null (errno set).
void* openZipOnTemporary(const std::filesystem::path& temp);

class ZipStream {
 public:
  // Creates the archive on `file`'s temporary. `file` never writes a byte itself; it keeps the name,
  // removes the temporary when abandoned and renames it at its commit(), after close(). Entry times are
  // `created` (UTC, at least 1980-01-01). Throws OutputError when the temporary cannot be opened.
  ZipStream(OutputFile& file, std::time_t created);
  ~ZipStream();  // an archive not closed is closed without checks (the OutputFile then removes it)
  ZipStream(const ZipStream&) = delete;
  ZipStream& operator=(const ZipStream&) = delete;

  // Adds an entry. With its CRC-32 given, `data` is written raw (not checksummed again). Throws
  // OutputError naming the entry.
  void add(const std::string& name, std::span<const uint8_t> data,
           std::optional<uint32_t> crc = std::nullopt);
  void add(const std::string& name, const std::string& text) {
    add(name, {reinterpret_cast<const uint8_t*>(text.data()), text.size()});
  }

  // Writes the central directory (and the Zip64 end records where needed). Call once, before the
  // OutputFile's commit().
  void close();

 private:
  OutputFile& file_;
  void* zip_ = nullptr;  // minizip's zipFile
  std::tm date_{};
  uint64_t entries_ = 0;
};

}  // namespace toposlice
