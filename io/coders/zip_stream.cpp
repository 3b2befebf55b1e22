// ZipStream (zip_stream.h): minizip, then the Zip64 end records minizip 1.1 leaves out.
#include "io/coders/zip_stream.h"

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <memory>
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
  constexpr std::size_t kComment = kZipComment.size();
  uint8_t end[20 + 22 + kComment];  // possible Zip64 locator, then the classic end record and our comment
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
  const uint64_t zip64At = static_cast<uint64_t>(st.st_size) - 22 - kComment;
  uint8_t tail[56 + 20 + 22 + kComment] = {};
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
  putLE(e + 20, kComment, 2);
  std::memcpy(e + 22, kZipComment.data(), kComment);
  if (::pwrite(fd, tail, sizeof tail, static_cast<off_t>(zip64At)) != static_cast<ssize_t>(sizeof tail)) {
    ::close(fd);
    fail("cannot write the Zip64 end record");
  }
  if (::close(fd) != 0) fail("cannot write the Zip64 end record");
}

std::string errorText(int code) {
  return code == ZIP_ERRNO ? std::generic_category().message(errno) : "zip error " + std::to_string(code);
}

// minizip's file functions over a 1 MiB buffer. Stdio would write each entry in several system calls:
// minizip seeks back to patch every local header with the entry's sizes and CRC, which flushes a FILE's
// buffer (and glibc then reads a block back on the read/write stream). Here a write lands in the buffer
// when it falls within or right after it, so a patch of a header still buffered is a copy in memory and
// the archive goes out in whole MiB writes. Anything else flushes and writes in place (pwrite). The
// bytes are the ones minizip writes either way.
struct BufferedZipFile {
  static constexpr std::size_t kCapacity = std::size_t{1} << 20;
  int fd = -1;
  std::unique_ptr<char[]> buffer = std::make_unique_for_overwrite<char[]>(kCapacity);
  uint64_t bufferAt = 0;  // file offset of buffer[0]
  std::size_t used = 0;   // bytes of the buffer to write at bufferAt
  uint64_t position = 0;  // where minizip reads or writes next
  uint64_t end = 0;       // the file's length, counting what is buffered
  int error = 0;          // errno of the first failure

  bool writeAt(const char* data, std::size_t size, uint64_t at) {
    while (size > 0) {
      const ssize_t n = ::pwrite(fd, data, size, static_cast<off_t>(at));
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        error = n < 0 ? errno : EIO;
        return false;
      }
      data += n;
      size -= static_cast<std::size_t>(n);
      at += static_cast<uint64_t>(n);
    }
    return true;
  }
  bool flush() {
    const std::size_t n = used;
    used = 0;
    return error == 0 && writeAt(buffer.get(), n, bufferAt);
  }
};

voidpf ZCALLBACK openBuffered(voidpf, const void* filename, int) {
  // Opened without truncating: see openZipOnTemporary.
  auto file = std::make_unique<BufferedZipFile>();
  file->fd = ::open(static_cast<const char*>(filename), O_RDWR | O_CLOEXEC);
  if (file->fd < 0) return nullptr;
  struct stat st {};
  if (::fstat(file->fd, &st) == 0) file->end = static_cast<uint64_t>(st.st_size);
  return file.release();
}

uLong ZCALLBACK writeBuffered(voidpf, voidpf stream, const void* data, uLong size) {
  auto& f = *static_cast<BufferedZipFile*>(stream);
  if (f.error != 0) {
    errno = f.error;
    return 0;
  }
  const char* bytes = static_cast<const char*>(data);
  const bool inBuffer = f.position >= f.bufferAt && f.position <= f.bufferAt + f.used;
  if (!inBuffer || f.position - f.bufferAt + size > BufferedZipFile::kCapacity) {
    if (!f.flush()) {
      errno = f.error;
      return 0;
    }
    f.bufferAt = f.position;
    if (size >= BufferedZipFile::kCapacity) {
      if (!f.writeAt(bytes, size, f.position)) {
        errno = f.error;
        return 0;
      }
      f.position += size;
      f.bufferAt = f.position;
      f.end = std::max(f.end, f.position);
      return size;
    }
  }
  const std::size_t at = f.position - f.bufferAt;
  std::memcpy(f.buffer.get() + at, bytes, size);
  f.used = std::max(f.used, at + size);
  f.position += size;
  f.end = std::max(f.end, f.position);
  return size;
}

uLong ZCALLBACK readBuffered(voidpf, voidpf stream, void* data, uLong size) {
  auto& f = *static_cast<BufferedZipFile*>(stream);
  if (!f.flush()) {
    errno = f.error;
    return 0;
  }
  const ssize_t n = ::pread(f.fd, data, size, static_cast<off_t>(f.position));
  if (n < 0) {
    f.error = errno;
    return 0;
  }
  f.position += static_cast<uint64_t>(n);
  return static_cast<uLong>(n);
}

ZPOS64_T ZCALLBACK tellBuffered(voidpf, voidpf stream) {
  return static_cast<BufferedZipFile*>(stream)->position;
}

long ZCALLBACK seekBuffered(voidpf, voidpf stream, ZPOS64_T offset, int origin) {
  auto& f = *static_cast<BufferedZipFile*>(stream);
  switch (origin) {
    case ZLIB_FILEFUNC_SEEK_SET:
      f.position = offset;
      return 0;
    case ZLIB_FILEFUNC_SEEK_CUR:
      f.position += offset;
      return 0;
    case ZLIB_FILEFUNC_SEEK_END:
      f.position = f.end + offset;
      return 0;
    default:
      return -1;
  }
}

int ZCALLBACK closeBuffered(voidpf, voidpf stream) {
  std::unique_ptr<BufferedZipFile> f(static_cast<BufferedZipFile*>(stream));
  const bool flushed = f->flush();
  const bool closed = ::close(f->fd) == 0;
  if (!flushed || !closed) {
    errno = flushed ? errno : f->error;
    return EOF;
  }
  return 0;
}

int ZCALLBACK errorBuffered(voidpf, voidpf stream) {
  return static_cast<BufferedZipFile*>(stream)->error;
}

}  // namespace

void* openZipOnTemporary(const std::filesystem::path& temp) {
  zlib_filefunc64_def functions{openBuffered, readBuffered,  writeBuffered, tellBuffered,
                                seekBuffered, closeBuffered, errorBuffered, nullptr};
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
  const int rc = zipClose(static_cast<zipFile>(zip_), kZipComment.data());  // how --force knows it
  zip_ = nullptr;
  if (rc != ZIP_OK) throw OutputError(file_.finalPath().string() + ": cannot write: " + errorText(rc));
  addZip64EndRecords(file_.tempPath(), entries_);
}

}  // namespace toposlice
