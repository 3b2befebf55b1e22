#include "io/output_file.h"

#include <algorithm>
#include <atomic>
#include <cassert>
#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <mutex>
#include <optional>
#include <string>
#include <system_error>
#include <utility>

#include <dirent.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <sys/statvfs.h>
#include <sys/syscall.h>
#include <unistd.h>

#include "io/errors.h"

namespace toposlice {
namespace {

// Registry of live temporaries, readable from a signal handler. A slot is free (0), being filled or
// emptied by its owner (1), or live (2); only a live slot is read by removePendingOutputs(), and its path
// is complete before the release store that makes it live.
constexpr std::size_t kSlotPathSize = 4096;
struct PendingSlot {
  std::atomic<int> state{0};
  bool folder = false;  // a staged folder of layer files: its files are removed, then the folder
  char path[kSlotPathSize];
};
static_assert(std::atomic<int>::is_always_lock_free, "the signal handler needs lock-free atomics");
PendingSlot gPending[kMaxPendingOutputs];
std::atomic<std::uint64_t> gTempCounter{0};

thread_local OutputTransaction* tCurrentTransaction = nullptr;

std::filesystem::path asideName(const std::filesystem::path& finalPath) {
  static std::atomic<std::uint64_t> counter{0};
  std::filesystem::path p = finalPath;
  p += ".old-" + std::to_string(::getpid()) + "-" +
       std::to_string(counter.fetch_add(1, std::memory_order_relaxed));
  return p;
}

// Renames without replacing anything: renameat2 RENAME_NOREPLACE, or, on file systems without it, a
// check then rename (not atomic there). Returns 0 or an errno value (EEXIST when the target exists).
int renameNoReplace(const std::string& from, const std::string& to) {
  if (::renameat2(AT_FDCWD, from.c_str(), AT_FDCWD, to.c_str(), RENAME_NOREPLACE) == 0) return 0;
  if (errno != EINVAL && errno != ENOSYS) return errno;
  if (outputPathExists(to)) return EEXIST;
  return ::rename(from.c_str(), to.c_str()) == 0 ? 0 : errno;
}

// How a file of an extension starts when toposlice wrote it (`starts`, one of them), and the mark that
// its first kHeadBytes then hold somewhere (`holds`, empty: none beyond the start; a zip's mark is its
// comment, at the end). `known` false: toposlice writes no such file.
struct OwnMark {
  bool known = false;
  std::vector<std::string_view> starts;
  std::string_view holds;
};
constexpr std::size_t kHeadBytes = 4096;

OwnMark ownMarkFor(const std::string& ext) {
  using namespace std::string_view_literals;
  // The literals below spell the marks of output_file.h out with the bytes around them.
  static_assert(kCliMarkLine == "// written by toposlice //\n"sv &&
                kSvgMarkLine == "<!-- written by toposlice -->\n"sv && kSoftwareName == "toposlice"sv);
  if (ext == ".cli") return {true, {"$$HEADERSTART\n// written by toposlice //\n"sv}, {}};
  if (ext == ".svg")
    return {true, {"<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<!-- written by toposlice -->\n"sv}, {}};
  if (ext == ".3mf" || ext == ".sl1" || ext == ".sl1s" || ext == ".nanodlp")
    return {true, {"PK\x03\x04"sv}, {}};
  if (ext == ".goo") return {true, {"V3.0\x07\0\0\0DLP\0toposlice\0"sv}, {}};  // version, magic, software
  // The file metadata "creator" (a name, a type name and a value, each after its 32-bit length).
  if (ext == ".vdb") return {true, {" BDV"sv}, "\x07\0\0\0creator\x06\0\0\0string\x09\0\0\0toposlice"sv};
  // The tEXt chunk's type, its keyword and text.
  if (ext == ".png") return {true, {"\x89PNG\r\n\x1a\n"sv}, "tEXtSoftware\0toposlice"sv};
  // The header attribute: name, type, size, value.
  if (ext == ".exr") return {true, {"v/1\x01"sv}, "software\0string\0\x09\0\0\0toposlice"sv};
  if (ext == ".topo") return {true, {"TOPOSLC"sv}, {}};
  if (ext == ".csv") return {true, {"layer,z_mm,area_"sv}, {}};         // the per-layer report's header
  if (ext == ".json") return {true, {"{\n  \"toposlice\": \""sv}, {}};  // summaries and plate reports
  return {};
}

// Whether the zip at `path` ends with toposlice's archive comment: its end record ("PK\5\6", 22 bytes)
// with that comment's length, then the comment.
bool endsWithOurZipComment(const std::filesystem::path& path) {
  const std::size_t n = 22 + kZipComment.size();
  char tail[22 + kZipComment.size()];
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return false;
  struct stat st {};
  const bool read = ::fstat(fd, &st) == 0 && st.st_size >= static_cast<off_t>(n) &&
                    ::pread(fd, tail, n, st.st_size - static_cast<off_t>(n)) == static_cast<ssize_t>(n);
  ::close(fd);
  if (!read) return false;
  const std::string_view t(tail, n);
  const auto commentSize =
      static_cast<std::size_t>(static_cast<uint8_t>(t[20]) | static_cast<uint8_t>(t[21]) << 8);
  return t.starts_with(std::string_view("PK\x05\x06", 4)) && commentSize == kZipComment.size() &&
         t.substr(22) == kZipComment;
}

std::string reason(int err) {
  return std::generic_category().message(err);
}

// Whether the regular file at `path` is empty or one toposlice wrote, by `mark`. Throws OutputError when
// it cannot be read.
bool emptyOrOurs(const std::filesystem::path& path, const OwnMark& mark) {
  char head[kHeadBytes];
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw OutputError(path.string() + ": cannot read the existing file: " + reason(errno));
  std::size_t size = 0;
  while (size < sizeof head) {
    const ssize_t n = ::read(fd, head + size, sizeof head - size);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    size += static_cast<std::size_t>(n);
  }
  ::close(fd);
  const std::string_view start(head, size);
  if (start.empty()) return true;  // an empty file holds nothing to lose
  for (const std::string_view sig : mark.starts) {
    if (!start.starts_with(sig)) continue;
    if (sig == "PK\x03\x04") return endsWithOurZipComment(path);
    return mark.holds.empty() || start.find(mark.holds) != std::string_view::npos;
  }
  return false;
}

bool isLayerFileName(const std::string& name, std::string_view ext) {
  if (name.size() <= ext.size() + 1) return false;
  const std::size_t dot = name.size() - ext.size();
  for (std::size_t i = 0; i < ext.size(); ++i)
    if (std::tolower(static_cast<unsigned char>(name[dot + i])) != ext[i]) return false;
  return std::isdigit(static_cast<unsigned char>(name[dot - 1])) != 0;
}

}  // namespace

int registerPendingOutput(const std::filesystem::path& temp, bool folder) {
  std::error_code ec;
  const std::filesystem::path absolute = std::filesystem::absolute(temp, ec);
  const std::string path = ec ? temp.string() : absolute.string();
  if (path.size() + 1 > kSlotPathSize) return -1;
  for (std::size_t i = 0; i < kMaxPendingOutputs; ++i) {
    int expected = 0;
    if (gPending[i].state.compare_exchange_strong(expected, 1, std::memory_order_acquire)) {
      gPending[i].folder = folder;
      std::memcpy(gPending[i].path, path.c_str(), path.size() + 1);
      gPending[i].state.store(2, std::memory_order_release);
      return static_cast<int>(i);
    }
  }
  return -1;  // table full: the file works, it is just not removed on a signal
}

void unregisterPendingOutput(int slot) noexcept {
  if (slot < 0) return;
  gPending[slot].state.store(1, std::memory_order_relaxed);
  gPending[slot].state.store(0, std::memory_order_release);
}

bool outputPathExists(const std::filesystem::path& p) {
  std::error_code ec;
  const auto st = std::filesystem::symlink_status(p, ec);
  return !ec && st.type() != std::filesystem::file_type::not_found;
}

std::filesystem::path resolvedPath(const std::filesystem::path& path) {
  std::error_code ec;
  std::filesystem::path resolved = std::filesystem::weakly_canonical(std::filesystem::absolute(path), ec);
  return ec ? std::filesystem::absolute(path).lexically_normal() : resolved;
}

namespace {
std::string gOverwriteHint = "use --force to overwrite";
std::string gForceName = "--force";
}  // namespace

void setOverwriteHint(std::string hint, std::string forceName) {
  gOverwriteHint = std::move(hint);
  gForceName = std::move(forceName);
}

std::string outputExistsMessage(const std::filesystem::path& p) {
  return p.string() + ": already exists (" + gOverwriteHint + ")";
}

void checkOutputAllowed(const std::filesystem::path& path, bool overwrite, OutputKind kind,
                        std::string_view layerExt) {
  if (!outputPathExists(path)) return;
  if (!overwrite) throw OutputError(outputExistsMessage(path));
  checkReplaceable(path, kind, layerExt);
}

namespace {

// Removes the files of a staged folder (it holds nothing else), then the folder, with system calls only
// (open, getdents64, unlinkat, close, rmdir): callable from a signal handler.
void removeFolderFromHandler(const char* path) noexcept {
  // The job's other threads go on writing layer files into the folder until the process ends: empty it
  // and remove it again until the removal holds (once it is gone, their next files cannot be created).
  for (int attempt = 0; attempt < 10000; ++attempt) {
    const int fd = ::open(path, O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0) return;  // gone
    alignas(8) char entries[8192];
    for (int pass = 0; pass < 1000; ++pass) {  // from the start again until a pass removes nothing
      bool removed = false;
      ::lseek(fd, 0, SEEK_SET);
      for (;;) {
        const long n = ::syscall(SYS_getdents64, fd, entries, sizeof entries);
        if (n <= 0) break;
        for (long at = 0; at < n;) {
          const auto* e = reinterpret_cast<const struct dirent64*>(entries + at);
          const char* name = e->d_name;
          const bool dots = name[0] == '.' && (name[1] == '\0' || (name[1] == '.' && name[2] == '\0'));
          if (!dots && ::unlinkat(fd, name, 0) == 0) removed = true;
          at += e->d_reclen;
        }
      }
      if (!removed) break;
    }
    ::close(fd);
    if (::rmdir(path) == 0 || errno == ENOENT) return;
  }
}

}  // namespace

namespace {
std::mutex gUnremovedMutex;
std::vector<std::string> gUnremoved;
}  // namespace

void noteUnremovedTemporary(const std::filesystem::path& temp, int err) noexcept {
  try {
    const std::lock_guard<std::mutex> lock(gUnremovedMutex);
    gUnremoved.push_back(temp.string() + " could not be removed (" + std::strerror(err) + ")");
  } catch (...) {  // out of memory while unwinding: nothing more to say
  }
}

std::vector<std::string> takeUnremovedTemporaries() {
  const std::lock_guard<std::mutex> lock(gUnremovedMutex);
  return std::exchange(gUnremoved, {});
}

void removePendingOutputs() noexcept {
  for (std::size_t i = 0; i < kMaxPendingOutputs; ++i) {
    if (gPending[i].state.load(std::memory_order_acquire) != 2) continue;
    if (gPending[i].folder)
      removeFolderFromHandler(gPending[i].path);
    else
      ::unlink(gPending[i].path);
  }
}

OutputFile::OutputFile(std::filesystem::path finalPath, bool overwrite)
    : finalPath_(std::move(finalPath)), overwrite_(overwrite) {
  checkOutputAllowed(finalPath_, overwrite_);
  transaction_ = OutputTransaction::current();
  const std::uint64_t counter = gTempCounter.fetch_add(1, std::memory_order_relaxed);
  tempPath_ = finalPath_;
  tempPath_ += ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(counter);
  const std::string temp = tempPath_.string();
  buffer_ = std::make_unique_for_overwrite<char[]>(kBufferSize);
  // Registered before it exists, so that no instant has a temporary on disk the handler does not know.
  registrySlot_ = registerPendingOutput(tempPath_);
  fd_ = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
  if (fd_ < 0) {
    const int err = errno;
    unregisterPendingOutput(registrySlot_);
    throw OutputError(cannotCreateMessage(finalPath_, err));
  }
}

OutputFile::~OutputFile() {
  if (committed_) return;
  if (fd_ >= 0) ::close(fd_);
  if (::unlink(tempPath_.c_str()) != 0 && errno != ENOENT) noteUnremovedTemporary(tempPath_, errno);
  unregisterPendingOutput(registrySlot_);
}

void OutputFile::fail(const char* what, int err) {
  failed_ = true;
  throw OutputError(finalPath_.string() + ": " + what + ": " + reason(err));
}

void OutputFile::writeAll(const char* data, std::size_t size) {
  while (size > 0) {
    const ssize_t n = ::write(fd_, data, size);
    if (n < 0) {
      if (errno == EINTR) continue;
      fail("cannot write", errno);
    }
    if (n == 0) fail("cannot write", EIO);
    data += n;
    size -= static_cast<std::size_t>(n);
    bytesWritten_ += static_cast<std::uint64_t>(n);
  }
}

void OutputFile::flushBuffer() {
  const std::size_t n = used_;
  used_ = 0;  // dropped on failure too: the file is abandoned then
  writeAll(buffer_.get(), n);
}

void OutputFile::write(const void* data, std::size_t size) {
  assert(!committed_ && fd_ >= 0);
  if (failed_) fail("cannot write", EIO);
  if (size == 0) return;
  const char* bytes = static_cast<const char*>(data);
  if (size <= kBufferSize - used_) {
    std::memcpy(buffer_.get() + used_, bytes, size);
    used_ += size;
    return;
  }
  flushBuffer();
  if (size >= kBufferSize) {
    writeAll(bytes, size);
  } else {
    std::memcpy(buffer_.get(), bytes, size);
    used_ = size;
  }
}

void OutputFile::rewriteAt(std::uint64_t offset, const void* data, std::size_t size) {
  assert(!committed_ && fd_ >= 0 && offset + size <= bytesWritten());
  if (failed_) fail("cannot write", EIO);
  flushBuffer();
  const char* bytes = static_cast<const char*>(data);
  while (size > 0) {
    const ssize_t n = ::pwrite(fd_, bytes, size, static_cast<off_t>(offset));
    if (n < 0) {
      if (errno == EINTR) continue;
      fail("cannot write", errno);
    }
    if (n == 0) fail("cannot write", EIO);
    bytes += n;
    offset += static_cast<std::uint64_t>(n);
    size -= static_cast<std::size_t>(n);
  }
}

void OutputFile::commit() {
  assert(!committed_ && fd_ >= 0);
  if (failed_) fail("cannot write", EIO);
  flushBuffer();
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) fail("cannot write", errno);
  if (transaction_ != nullptr) {
    transaction_->stage({tempPath_, finalPath_, overwrite_, OutputKind::File, {}, registrySlot_});
    registrySlot_ = -1;
    committed_ = true;
    return;
  }
  const std::string temp = tempPath_.string();
  const std::string final = finalPath_.string();
  bool renamed = false;
  if (!overwrite_) {
    const int err = renameNoReplace(temp, final);
    if (err == EEXIST) {
      failed_ = true;
      throw OutputError(outputExistsMessage(finalPath_));
    }
    if (err != 0) fail("cannot rename the temporary file", err);
    renamed = true;
  } else if (outputPathExists(finalPath_)) {
    failed_ = true;
    checkReplaceable(finalPath_, OutputKind::File);
    failed_ = false;
  }
  if (!renamed && ::rename(temp.c_str(), final.c_str()) != 0) fail("cannot rename the temporary file", errno);
  committed_ = true;
  unregisterPendingOutput(registrySlot_);
  registrySlot_ = -1;
}

std::string writeFailureReason(const std::filesystem::path& file, int savedErrno,
                               const std::string& libraryMessage) {
  if (savedErrno == ENOSPC || savedErrno == EDQUOT || savedErrno == EFBIG || savedErrno == EIO ||
      savedErrno == EROFS)
    return reason(savedErrno) + " (" + libraryMessage + ")";
  std::filesystem::path folder = file.parent_path();
  if (folder.empty()) folder = ".";
  struct statvfs fs {};
  if (::statvfs(folder.c_str(), &fs) == 0 && fs.f_bavail == 0)
    return reason(ENOSPC) + " (" + libraryMessage + ")";
  return libraryMessage;
}

std::string lowerExtension(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return ext;
}

std::string cannotCreateMessage(const std::filesystem::path& path, int err) {
  std::filesystem::path folder = path.parent_path();
  if (folder.empty()) folder = ".";
  if (err == ENOENT || err == ENOTDIR) {
    std::error_code ec;
    const auto st = std::filesystem::status(folder, ec);
    if (st.type() == std::filesystem::file_type::not_found)
      return path.string() + ": cannot create: folder '" + folder.string() + "' does not exist";
    if (st.type() != std::filesystem::file_type::directory)
      return path.string() + ": cannot create: '" + folder.string() + "' is not a folder";
  }
  if (err == EACCES || err == EPERM)
    return path.string() + ": cannot create: no permission to write in folder '" + folder.string() + "'";
  return path.string() + ": cannot create: " + reason(err);
}

void checkReplaceable(const std::filesystem::path& path, OutputKind kind, std::string_view layerExt) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status st = fs::symlink_status(path, ec);
  if (ec || st.type() == fs::file_type::not_found) return;
  // A link is replaced, never followed: what it points to stays as it is.
  if (st.type() == fs::file_type::symlink) return;
  const std::string refused = ", even with " + gForceName;
  if (kind == OutputKind::File) {
    if (st.type() == fs::file_type::directory)
      throw OutputError(path.string() +
                        ": is a folder; toposlice writes a file there and never replaces a folder" + refused);
    if (st.type() != fs::file_type::regular)
      throw OutputError(path.string() + ": is not a regular file; not replaced" + refused);
    const OwnMark mark = ownMarkFor(lowerExtension(path));
    if (!mark.known) {
      if (fs::file_size(path, ec) == 0 && !ec) return;  // an empty file holds nothing to lose
      throw OutputError(path.string() + ": exists, and toposlice writes no '" + lowerExtension(path) +
                        "' files, so it cannot have written it; not replaced" + refused);
    }
    if (emptyOrOurs(path, mark)) return;
    const std::string ext = lowerExtension(path);
    const bool zip = ext == ".3mf" || ext == ".sl1" || ext == ".sl1s" || ext == ".nanodlp";
    throw OutputError(path.string() + ": exists and is not a " + ext.substr(1) +
                      " file toposlice wrote (it lacks toposlice's mark" +
                      (zip ? ", the archive comment at its end, which an archive cut short loses too: delete "
                             "such a one"
                           : "") +
                      "); not replaced" + refused);
  }
  if (st.type() != fs::file_type::directory)
    throw OutputError(path.string() + ": exists and is not a folder of layers toposlice wrote; not replaced" +
                      refused);
  std::string ext(layerExt);
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  const OwnMark mark = ownMarkFor(ext);
  for (const fs::directory_entry& entry : fs::directory_iterator(path, ec)) {
    const std::string name = entry.path().filename().string();
    const fs::file_status es = entry.symlink_status(ec);
    if (es.type() == fs::file_type::directory)
      throw OutputError(path.string() + ": holds the folder '" + name +
                        "', which toposlice did not write; the folder is not replaced" + refused);
    if (es.type() != fs::file_type::regular || !isLayerFileName(name, ext) ||
        !emptyOrOurs(entry.path(), mark))
      throw OutputError(path.string() + ": holds '" + name +
                        "', which toposlice did not write; the folder is not replaced" + refused);
  }
  if (ec) throw OutputError(path.string() + ": cannot list the existing folder: " + ec.message());
}

namespace {

// The last `n` bytes of the regular file at `path` (fewer when it is shorter).
std::string tailOf(const std::filesystem::path& path, std::size_t n) {
  std::string tail;
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return tail;
  struct stat st {};
  if (::fstat(fd, &st) == 0) {
    const auto size = static_cast<std::size_t>(st.st_size);
    tail.resize(std::min(n, size));
    const ssize_t got = ::pread(fd, tail.data(), tail.size(), static_cast<off_t>(size - tail.size()));
    tail.resize(got > 0 ? static_cast<std::size_t>(got) : 0);
  }
  ::close(fd);
  return tail;
}

// The EXR file at `path` as far as a scan line file's structure tells: its header's int attribute
// `intName` (the layer count toposlice writes), and whether its last chunk ends where the file does
// (the offset table after the header points at every chunk: y, data size, data).
struct ExrShape {
  std::optional<int32_t> value;
  bool whole = false;
};
ExrShape exrShape(const std::filesystem::path& path, std::string_view intName) {
  ExrShape shape;
  std::ifstream in(path, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const auto u32 = [&](std::size_t at) {
    uint32_t v = 0;
    std::memcpy(&v, bytes.data() + at, 4);
    return v;
  };
  std::size_t at = 8;  // magic and version
  if (bytes.size() < at) return shape;
  for (;;) {  // attributes: name, type (both zero-terminated), size, value; an empty name ends them
    const std::size_t nameEnd = bytes.find('\0', at);
    if (nameEnd == std::string::npos) return shape;
    if (nameEnd == at) break;
    const std::size_t typeEnd = bytes.find('\0', nameEnd + 1);
    if (typeEnd == std::string::npos || typeEnd + 5 > bytes.size()) return shape;
    const uint32_t size = u32(typeEnd + 1);
    const std::size_t value = typeEnd + 5;
    if (size > bytes.size() - value) return shape;
    if (std::string_view(bytes).substr(at, nameEnd - at) == intName && size == 4)
      shape.value = static_cast<int32_t>(u32(value));
    at = value + size;
  }
  const std::size_t table = at + 1;  // chunk 0's offset is the table's end: the table's length
  if (table + 8 > bytes.size()) return shape;
  uint64_t first = 0;
  std::memcpy(&first, bytes.data() + table, 8);
  if (first < table + 8 || first > bytes.size() || (first - table) % 8 != 0) return shape;
  uint64_t last = 0;
  for (std::size_t e = table; e < first; e += 8) {
    uint64_t offset = 0;
    std::memcpy(&offset, bytes.data() + e, 8);
    last = std::max(last, offset);
  }
  shape.whole = last + 8 <= bytes.size() && last + 8 + u32(last + 4) == bytes.size();
  return shape;
}

// A toposlice file of its extension, whole as far as its format's end tells (not empty; the end a
// complete file has, where the format has one).
bool fileLooksWhole(const std::filesystem::path& path, const std::string& ext) {
  std::error_code ec;
  if (std::filesystem::file_size(path, ec) == 0 || ec) return false;
  using namespace std::string_view_literals;
  const auto endsWith = [&](std::string_view end) { return tailOf(path, end.size()) == end; };
  if (ext == ".3mf" || ext == ".sl1" || ext == ".sl1s" || ext == ".nanodlp")
    return endsWithOurZipComment(path);
  if (ext == ".svg") return endsWith("</svg>\n"sv);
  if (ext == ".png") return endsWith("IEND\xae\x42\x60\x82"sv);
  if (ext == ".goo") return endsWith("\0\0\0\x07\0\0\0DLP\0"sv);
  if (ext == ".csv") return endsWith("\n"sv);
  if (ext == ".json") return endsWith("}\n"sv);
  if (ext == ".cli") {  // an ASCII one ends with its geometry; a binary one holds its header's layers
    // The header (a few hundred bytes), then only the commands' heads: a polyline's points are skipped,
    // not read (a 1 um stack is hundreds of megabytes).
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) return false;
    struct stat st {};
    std::string head(std::size_t{1} << 16, '\0');  // a header with many feature labels too
    const ssize_t got = ::fstat(fd, &st) == 0 ? ::pread(fd, head.data(), head.size(), 0) : -1;
    const std::string_view text(head.data(), got > 0 ? static_cast<std::size_t>(got) : 0);
    const std::size_t end = text.find("$$HEADEREND"sv);
    const std::size_t count = text.find("$$LAYERS/"sv);
    if (end == std::string_view::npos || text.substr(0, end).find("$$ASCII"sv) != std::string_view::npos ||
        count == std::string_view::npos || count > end) {
      ::close(fd);
      return end != std::string_view::npos && endsWith("$$GEOMETRYEND\n"sv);
    }
    const uint64_t layers = std::strtoull(std::string(text.substr(count + 9, 20)).c_str(), nullptr, 10);
    // Commands: uint16 127 (a layer: float32 z) or 130 (a polyline: int32 id, dir, n, n float32 pairs).
    const auto size = static_cast<uint64_t>(st.st_size);
    uint64_t seen = 0, at = end + 11;
    bool whole = true;
    while (whole && at < size) {
      unsigned char command[14];
      const std::size_t want = static_cast<std::size_t>(std::min<uint64_t>(sizeof command, size - at));
      whole = want >= 2 && ::pread(fd, command, want, static_cast<off_t>(at)) == static_cast<ssize_t>(want);
      if (!whole) break;
      const unsigned id = command[0] | command[1] << 8;
      if (id == 127) {
        at += 6;
        ++seen;
      } else if (id == 130 && want == sizeof command) {
        uint32_t n = 0;
        std::memcpy(&n, command + 10, 4);
        at += 14 + uint64_t{8} * n;
      } else {
        whole = false;
      }
      whole = whole && at <= size;
    }
    ::close(fd);
    return whole && seen == layers;
  }
  if (ext == ".exr") return exrShape(path, "").whole;
  return true;  // .vdb, .topo: not empty
}

}  // namespace

void MadeFolders::note(const std::filesystem::path& folder) {
  if (folder.empty()) return;
  std::filesystem::path outermost;
  for (std::filesystem::path p = std::filesystem::absolute(folder).lexically_normal();
       !p.empty() && !outputPathExists(p) && p != p.parent_path(); p = p.parent_path())
    outermost = p;
  if (!outermost.empty() && std::find(made_.begin(), made_.end(), outermost) == made_.end())
    made_.push_back(outermost);
}

void MadeFolders::removeEmpty() const noexcept {
  for (const std::filesystem::path& folder : made_) {
    std::error_code ec;
    bool empty = true;  // of files: folders only
    for (auto it = std::filesystem::recursive_directory_iterator(folder, ec);
         empty && !ec && it != std::filesystem::recursive_directory_iterator(); it.increment(ec))
      empty = it->is_directory();
    if (empty && !ec) std::filesystem::remove_all(folder, ec);
  }
}

bool outputLooksWhole(const std::filesystem::path& path, std::string_view layerExt) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (ec) return false;
  if (st.type() == fs::file_type::regular) return fileLooksWhole(path, lowerExtension(path));
  if (st.type() != fs::file_type::directory) return false;
  // A folder of layers: at least one, each whole, numbered without a gap.
  std::string ext(layerExt);
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  uint64_t count = 0, lowest = UINT64_MAX, highest = 0;
  for (const fs::directory_entry& entry : fs::directory_iterator(path, ec)) {
    const std::string name = entry.path().filename().string();
    if (!isLayerFileName(name, ext) || !fileLooksWhole(entry.path(), ext)) return false;
    const std::string stem = name.substr(0, name.size() - ext.size());
    std::size_t digits = stem.size();
    while (digits > 0 && std::isdigit(static_cast<unsigned char>(stem[digits - 1]))) --digits;
    const uint64_t index = std::strtoull(stem.c_str() + digits, nullptr, 10);
    lowest = std::min(lowest, index);
    highest = std::max(highest, index);
    ++count;
  }
  if (ec || count == 0 || lowest != 0 || highest + 1 != count) return false;
  // An EXR layer says how many layers its stack has.
  if (ext == ".exr") {
    const fs::directory_iterator any(path, ec);
    if (ec || any == fs::directory_iterator()) return false;
    const std::optional<int32_t> layers = exrShape(any->path(), "layerCount").value;
    return layers && static_cast<uint64_t>(*layers) == count;
  }
  return true;
}

// -----------------------------------------------------------------------------------------------------

OutputTransaction::OutputTransaction() : previous_(tCurrentTransaction) {
  tCurrentTransaction = this;
}

OutputTransaction::~OutputTransaction() {
  if (tCurrentTransaction == this) tCurrentTransaction = previous_;
  for (const Staged& s : staged_) {
    std::error_code ec;
    if (s.kind == OutputKind::File) {
      if (::unlink(s.temp.c_str()) != 0 && errno != ENOENT) noteUnremovedTemporary(s.temp, errno);
    } else {
      std::filesystem::remove_all(s.temp, ec);
      if (ec && outputPathExists(s.temp)) noteUnremovedTemporary(s.temp, ec.value());
    }
    unregisterPendingOutput(s.registrySlot);
  }
}

OutputTransaction* OutputTransaction::current() {
  return tCurrentTransaction;
}

OutputTransaction::Adopt::Adopt(OutputTransaction* transaction) : previous_(tCurrentTransaction) {
  tCurrentTransaction = transaction;
}

OutputTransaction::Adopt::~Adopt() {
  tCurrentTransaction = previous_;
}

void OutputTransaction::stage(Staged staged) {
  staged_.push_back(std::move(staged));
}

std::vector<OutputTransaction::Staged> OutputTransaction::release() {
  return std::exchange(staged_, {});
}

void OutputTransaction::commit(const std::atomic<bool>* cancel) {
  assert(!done_);
  if (cancel != nullptr && cancel->load()) throw OutputError("interrupted");
  struct Aside {
    std::filesystem::path final, aside;
  };
  std::vector<Aside> asides;
  auto restoreAsides = [&] {
    for (auto it = asides.rbegin(); it != asides.rend(); ++it) ::rename(it->aside.c_str(), it->final.c_str());
  };
  for (const Staged& s : staged_) {
    if (!outputPathExists(s.final)) continue;
    if (!s.overwrite) {
      restoreAsides();
      throw OutputError(outputExistsMessage(s.final));
    }
    try {
      checkReplaceable(s.final, s.kind, s.layerExt);
    } catch (...) {
      restoreAsides();
      throw;
    }
    const std::filesystem::path aside = asideName(s.final);
    if (::rename(s.final.c_str(), aside.c_str()) != 0) {
      const int err = errno;
      restoreAsides();
      throw OutputError(s.final.string() + ": cannot replace the existing entry: " + reason(err));
    }
    asides.push_back({s.final, aside});
  }
  for (std::size_t i = 0; i < staged_.size(); ++i) {
    const int err = renameNoReplace(staged_[i].temp.string(), staged_[i].final.string());
    if (err == 0) continue;
    for (std::size_t j = i; j-- > 0;) ::rename(staged_[j].final.c_str(), staged_[j].temp.c_str());
    restoreAsides();
    if (err == EEXIST) throw OutputError(outputExistsMessage(staged_[i].final));
    throw OutputError(staged_[i].final.string() + ": cannot rename the temporary " +
                      staged_[i].temp.string() + ": " + reason(err));
  }
  done_ = true;
  for (const Aside& a : asides) {
    std::error_code ec;
    std::filesystem::remove_all(a.aside, ec);
  }
  for (Staged& s : staged_) {
    unregisterPendingOutput(s.registrySlot);
    committedPaths_.push_back(s.final);
  }
  staged_.clear();
}

}  // namespace toposlice
