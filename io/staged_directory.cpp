#include "io/staged_directory.h"

#include <atomic>
#include <cassert>
#include <cerrno>
#include <cstdint>
#include <string>
#include <system_error>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "io/errors.h"
#include "io/output_file.h"

namespace toposlice {
namespace {

std::string reason(int err) {
  return std::generic_category().message(err);
}

std::atomic<uint64_t> gStagedCounter{0};

std::filesystem::path siblingName(const std::filesystem::path& finalPath, const char* tag) {
  std::filesystem::path p = finalPath;
  p += std::string(tag) + std::to_string(::getpid()) + "-d" +
       std::to_string(gStagedCounter.fetch_add(1, std::memory_order_relaxed));
  return p;
}

}  // namespace

StagedDirectory::StagedDirectory(std::filesystem::path finalPath, bool overwrite, std::string layerExt)
    : finalPath_(std::move(finalPath)), overwrite_(overwrite), layerExt_(std::move(layerExt)) {
  checkOutputAllowed(finalPath_, overwrite_, OutputKind::LayerFolder, layerExt_);
  transaction_ = OutputTransaction::current();
  tempPath_ = siblingName(finalPath_, ".tmp-");
  if (::mkdir(tempPath_.c_str(), 0777) != 0) throw OutputError(cannotCreateMessage(finalPath_, errno));
  registrySlot_ = registerPendingOutput(tempPath_, /*folder=*/true);
}

StagedDirectory::~StagedDirectory() {
  if (committed_) return;
  // Removed while still registered: a second signal during the removal (thousands of layer files take
  // a while) finds the folder in the registry and finishes it (it was left behind).
  std::error_code ec;
  std::filesystem::remove_all(tempPath_, ec);
  if (ec && outputPathExists(tempPath_)) noteUnremovedTemporary(tempPath_, ec.value());
  unregisterPendingOutput(registrySlot_);
}

void StagedDirectory::commit() {
  assert(!committed_);
  if (transaction_ != nullptr) {
    transaction_->stage(
        {tempPath_, finalPath_, overwrite_, OutputKind::LayerFolder, layerExt_, registrySlot_});
    committed_ = true;
    return;
  }
  unregisterPendingOutput(registrySlot_);  // renamed below, or removed by the destructor
  registrySlot_ = -1;
  const std::string temp = tempPath_.string(), final = finalPath_.string();
  if (!overwrite_) {
    if (::renameat2(AT_FDCWD, temp.c_str(), AT_FDCWD, final.c_str(), RENAME_NOREPLACE) == 0) {
      committed_ = true;
      return;
    }
    const int err = errno;
    if (err == EEXIST || ((err == EINVAL || err == ENOSYS) && outputPathExists(finalPath_))) {
      throw OutputError(outputExistsMessage(finalPath_));
    }
    if (err != EINVAL && err != ENOSYS) {
      throw OutputError(final + ": cannot rename " + temp + ": " + reason(err));
    }
  }
  if (::rename(temp.c_str(), final.c_str()) == 0) {  // no final entry yet, or an empty directory
    committed_ = true;
    return;
  }
  if (!overwrite_ || !outputPathExists(finalPath_)) {
    throw OutputError(final + ": cannot rename " + temp + ": " + reason(errno));
  }
  // Replace an existing entry: move it aside, move ours in, then delete the old one.
  checkReplaceable(finalPath_, OutputKind::LayerFolder, layerExt_);
  const std::filesystem::path old = siblingName(finalPath_, ".old-");
  if (::rename(final.c_str(), old.c_str()) != 0) {
    throw OutputError(final + ": cannot replace the existing entry: " + reason(errno));
  }
  if (::rename(temp.c_str(), final.c_str()) != 0) {
    const int err = errno;
    ::rename(old.c_str(), final.c_str());
    throw OutputError(final + ": cannot rename " + temp + ": " + reason(err));
  }
  committed_ = true;
  std::error_code ec;
  std::filesystem::remove_all(old, ec);
}

void StagedDirectory::writeFile(const std::string& name, std::span<const uint8_t> data) const {
  const std::filesystem::path file = tempPath_ / name;
  // Errors name the output and the layer's file as it would be in it, never the staged folder.
  const std::string context = finalPath_.string() + ": cannot ";
  const std::string named = (finalPath_ / name).string() + ": ";
  const int fd = ::open(file.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
  if (fd < 0) throw OutputError(context + "create " + named + reason(errno));
  const uint8_t* p = data.data();
  size_t left = data.size();
  while (left > 0) {
    const ssize_t n = ::write(fd, p, left);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int err = n < 0 ? errno : EIO;
      ::close(fd);
      throw OutputError(context + "write " + named + reason(err));
    }
    p += n;
    left -= static_cast<size_t>(n);
  }
  if (::close(fd) != 0) {
    throw OutputError(context + "write " + named + reason(errno));
  }
}

}  // namespace toposlice
