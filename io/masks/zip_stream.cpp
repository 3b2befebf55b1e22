// ZipStream (zip_stream.h): minizip, then the Zip64 end records minizip 1.1 leaves out.
#include "io/masks/zip_stream.h"

#include <cerrno>
#include <cstdio>
#include <system_error>

#include <fcntl.h>
#include <minizip/zip.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

#include "io/errors.h"

namespace toposlice {
namespace {

uint32_t getLE32(const uint8_t* p) {
  return uint32_t{p[0]} | uint32_t{p[1]} << 8 | uint32_t{p[2]} << 16 | uint32_t{p[3]} << 24;
}

void putLE(uint8_t* p, uint64_t v, int bytes) {
  for (int i = 0; i < bytes; ++i) p[i] = static_cast<uint8_t>(v >> (8 * i));
}

// minizip 1.1 as shipped by Debian 12 writes the Zip64 end records only past 4 GiB; with 65,535 entries
// or more it writes 0xFFFF counts into the classic end record and no Zip64 record, which strict readers
// (libzip, unzip, .NET's ZipArchive used by UVtools) reject. This replaces the classic end record by a
// Zip64 end record, its locator and a classic record pointing to them (APPNOTE 4.3.14-4.3.16). A
// no-op when minizip already wrote them or the count fits.
void addZip64EndRecords(const std::filesystem::path& file, uint64_t entries) {
  if (entries < 0xFFFF) return;
  const auto fail = [&file](const char* what) {
    throw OutputError(file.string() + ": " + what + ": " + std::generic_category().message(errno));
  };
  const int fd = ::open(file.c_str(), O_RDWR | O_CLOEXEC);
  if (fd < 0) fail("cannot reopen");
  struct stat st {};
  uint8_t end[22 + 20];  // possible Zip64 locator, then the classic end record (no comment)
  if (::fstat(fd, &st) != 0 || st.st_size < static_cast<off_t>(sizeof end) ||
      ::pread(fd, end, sizeof end, st.st_size - static_cast<off_t>(sizeof end)) !=
          static_cast<ssize_t>(sizeof end)) {
    ::close(fd);
    fail("cannot read the end record");
  }
  const uint8_t* eocd = end + 20;
  if (getLE32(eocd) != 0x06054b50u || getLE32(end) == 0x07064b50u) {
    ::close(fd);
    if (getLE32(eocd) != 0x06054b50u) throw OutputError(file.string() + ": unexpected zip end record");
    return;  // Zip64 records present
  }
  const uint64_t cdSize = getLE32(eocd + 12), cdOffset = getLE32(eocd + 16);
  const uint64_t zip64At = static_cast<uint64_t>(st.st_size) - 22;
  uint8_t tail[56 + 20 + 22] = {};
  uint8_t* z = tail;  // Zip64 end of central directory record
  putLE(z, 0x06064b50u, 4);
  putLE(z + 4, 56 - 12, 8);   // size of the rest of the record
  putLE(z + 12, 45, 2);       // version made by: 4.5 (Zip64)
  putLE(z + 14, 45, 2);       // version needed
  putLE(z + 24, entries, 8);  // entries on this disk (disk numbers stay 0)
  putLE(z + 32, entries, 8);  // entries in total
  putLE(z + 40, cdSize, 8);
  putLE(z + 48, cdOffset, 8);
  uint8_t* l = tail + 56;  // Zip64 end of central directory locator
  putLE(l, 0x07064b50u, 4);
  putLE(l + 8, zip64At, 8);
  putLE(l + 16, 1, 4);     // total number of disks
  uint8_t* e = tail + 76;  // classic end record, counts deferring to the Zip64 record
  putLE(e, 0x06054b50u, 4);
  putLE(e + 8, 0xFFFF, 2);
  putLE(e + 10, 0xFFFF, 2);
  putLE(e + 12, cdSize, 4);
  putLE(e + 16, cdOffset, 4);
  if (::pwrite(fd, tail, sizeof tail, static_cast<off_t>(zip64At)) != static_cast<ssize_t>(sizeof tail)) {
    ::close(fd);
    fail("cannot write the Zip64 end record");
  }
  if (::close(fd) != 0) fail("cannot write the Zip64 end record");
}

std::string errorText(int code) {
  return code == ZIP_ERRNO ? std::generic_category().message(errno) : "zip error " + std::to_string(code);
}

voidpf ZCALLBACK openWithoutTruncating(voidpf, const void* filename, int) {
  return std::fopen(static_cast<const char*>(filename), "r+b");
}

}  // namespace

void* openZipOnTemporary(const std::filesystem::path& temp) {
  zlib_filefunc64_def functions;
  fill_fopen64_filefunc(&functions);
  functions.zopen64_file = openWithoutTruncating;
  return zipOpen2_64(temp.c_str(), APPEND_STATUS_CREATE, nullptr, &functions);
}

ZipStream::ZipStream(OutputFile& file, std::time_t created) : file_(file) {
  zip_ = openZipOnTemporary(file_.tempPath());
  if (zip_ == nullptr) {
    throw OutputError(file_.finalPath().string() + ": cannot create " + file_.tempPath().string() + ": " +
                      std::generic_category().message(errno));
  }
  gmtime_r(&created, &date_);
}

ZipStream::~ZipStream() {
  if (zip_ != nullptr) zipClose(static_cast<zipFile>(zip_), nullptr);
}

void ZipStream::add(const std::string& name, std::span<const uint8_t> data, std::optional<uint32_t> crc) {
  // Stored (method 0), names flagged UTF-8 (general purpose bit 11). Entries are far below 4 GiB, so no
  // per-entry Zip64 fields; minizip adds them for offsets past 4 GiB.
  constexpr uLong kUtf8Names = 1u << 11;
  zip_fileinfo info{};
  info.tmz_date.tm_sec = static_cast<uInt>(date_.tm_sec);
  info.tmz_date.tm_min = static_cast<uInt>(date_.tm_min);
  info.tmz_date.tm_hour = static_cast<uInt>(date_.tm_hour);
  info.tmz_date.tm_mday = static_cast<uInt>(date_.tm_mday);
  info.tmz_date.tm_mon = static_cast<uInt>(date_.tm_mon);
  info.tmz_date.tm_year = static_cast<uInt>(date_.tm_year + 1900);
  zipFile zip = static_cast<zipFile>(zip_);
  const int raw = crc ? 1 : 0;
  int rc =
      zipOpenNewFileInZip4_64(zip, name.c_str(), &info, nullptr, 0, nullptr, 0, nullptr, 0, 0, raw,
                              -MAX_WBITS, DEF_MEM_LEVEL, Z_DEFAULT_STRATEGY, nullptr, 0, 0, kUtf8Names, 0);
  if (rc == ZIP_OK) rc = zipWriteInFileInZip(zip, data.data(), static_cast<unsigned>(data.size()));
  if (rc == ZIP_OK) rc = crc ? zipCloseFileInZipRaw64(zip, data.size(), *crc) : zipCloseFileInZip(zip);
  if (rc != ZIP_OK) {
    throw OutputError(file_.finalPath().string() + ": cannot write " + name + ": " + errorText(rc));
  }
  ++entries_;
}

void ZipStream::close() {
  const int rc = zipClose(static_cast<zipFile>(zip_), nullptr);
  zip_ = nullptr;
  if (rc != ZIP_OK) throw OutputError(file_.finalPath().string() + ": cannot write: " + errorText(rc));
  addZip64EndRecords(file_.tempPath(), entries_);
}

}  // namespace toposlice
