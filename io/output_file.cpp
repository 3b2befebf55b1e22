#include "io/output_file.h"

#include <atomic>
#include <cassert>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <string>
#include <system_error>

#include <fcntl.h>
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
  char path[kSlotPathSize];
};
static_assert(std::atomic<int>::is_always_lock_free, "the signal handler needs lock-free atomics");
PendingSlot gPending[kMaxPendingOutputs];
std::atomic<std::uint64_t> gTempCounter{0};

int registerPending(const std::string& path) {
  if (path.size() + 1 > kSlotPathSize) return -1;
  for (std::size_t i = 0; i < kMaxPendingOutputs; ++i) {
    int expected = 0;
    if (gPending[i].state.compare_exchange_strong(expected, 1, std::memory_order_acquire)) {
      std::memcpy(gPending[i].path, path.c_str(), path.size() + 1);
      gPending[i].state.store(2, std::memory_order_release);
      return static_cast<int>(i);
    }
  }
  return -1;  // table full: the file works, it is just not removed on a signal
}

void unregisterPending(int slot) {
  if (slot < 0) return;
  gPending[slot].state.store(1, std::memory_order_relaxed);
  gPending[slot].state.store(0, std::memory_order_release);
}

std::string reason(int err) {
  return std::generic_category().message(err);
}

}  // namespace

bool outputPathExists(const std::filesystem::path& p) {
  std::error_code ec;
  const auto st = std::filesystem::symlink_status(p, ec);
  return !ec && st.type() != std::filesystem::file_type::not_found;
}

std::string outputExistsMessage(const std::filesystem::path& p) {
  return p.string() + ": already exists (use --force to overwrite)";
}

void removePendingOutputs() noexcept {
  for (std::size_t i = 0; i < kMaxPendingOutputs; ++i) {
    if (gPending[i].state.load(std::memory_order_acquire) == 2) ::unlink(gPending[i].path);
  }
}

OutputFile::OutputFile(std::filesystem::path finalPath, bool overwrite)
    : finalPath_(std::move(finalPath)), overwrite_(overwrite) {
  if (!overwrite_ && outputPathExists(finalPath_)) throw OutputError(outputExistsMessage(finalPath_));
  const std::uint64_t counter = gTempCounter.fetch_add(1, std::memory_order_relaxed);
  tempPath_ = finalPath_;
  tempPath_ += ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(counter);
  const std::string temp = tempPath_.string();
  buffer_ = std::make_unique_for_overwrite<char[]>(kBufferSize);
  // Registered before it exists, so that no instant has a temporary on disk the handler does not know;
  // absolute, so that a later change of the working directory does not matter.
  std::error_code ec;
  const std::filesystem::path absolute = std::filesystem::absolute(tempPath_, ec);
  registrySlot_ = registerPending(ec ? temp : absolute.string());
  fd_ = ::open(temp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
  if (fd_ < 0) {
    const int err = errno;
    unregisterPending(registrySlot_);
    throw OutputError(finalPath_.string() + ": cannot create " + temp + ": " + reason(err));
  }
}

OutputFile::~OutputFile() {
  if (committed_) return;
  if (fd_ >= 0) ::close(fd_);
  ::unlink(tempPath_.c_str());
  unregisterPending(registrySlot_);
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

void OutputFile::commit() {
  assert(!committed_ && fd_ >= 0);
  if (failed_) fail("cannot write", EIO);
  flushBuffer();
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) fail("cannot write", errno);
  const std::string temp = tempPath_.string();
  const std::string final = finalPath_.string();
  bool renamed = false;
  if (!overwrite_) {
    if (::renameat2(AT_FDCWD, temp.c_str(), AT_FDCWD, final.c_str(), RENAME_NOREPLACE) == 0) {
      renamed = true;
    } else if (errno == EEXIST) {
      failed_ = true;
      throw OutputError(outputExistsMessage(finalPath_));
    } else if (errno != EINVAL && errno != ENOSYS) {
      fail("cannot rename the temporary file", errno);
    } else if (outputPathExists(finalPath_)) {  // file system without RENAME_NOREPLACE
      failed_ = true;
      throw OutputError(outputExistsMessage(finalPath_));
    }
  }
  if (!renamed && ::rename(temp.c_str(), final.c_str()) != 0) fail("cannot rename the temporary file", errno);
  committed_ = true;
  unregisterPending(registrySlot_);
  registrySlot_ = -1;
}

}  // namespace toposlice
